// SPDX-License-Identifier: Apache-2.0
// The frame buffers' EXR files: one multi-layer file per frame (see WriteFrameBuffers).
#include "renderer/frame_buffers/frame_buffers_render.h"

#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <type_traits>

#include "renderer/image/atomic_files.h"
#include "renderer/image/image.h"
#include "renderer/image/image_file.h"
#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;
using internal::ImageAttribute;

namespace {

/// One EXR layer of a buffer: its channel names and where its floats live.
template <typename Float>
struct Layer {
    std::string name;
    std::vector<std::string> channels;
    Float* data;                  // channels.size() floats per pixel, `stride` floats apart
    size_t stride;                // floats from one pixel's entry to the next
    size_t count;                 // entries in the buffer (0: empty, not written)
    std::function<void()> clear;  // empties the buffer (reading: the layer is missing)
};

const char* const kRgb[] = {"R", "G", "B"};
const char* const kXyz[] = {"X", "Y", "Z"};

/// The layers of `fb` in file order (FB is FrameBuffers or const FrameBuffers); object ids go
/// through `ids` as floats (exact up to 2^24). With `resize` (reading) every buffer is first
/// sized for the frame.
template <typename FB>
auto Layers(FB& fb, bool resize, std::vector<float>* ids) {
    using Float = std::conditional_t<std::is_const_v<FB>, const float, float>;
    const size_t n = fb.NumPixels();
    std::vector<Layer<Float>> layers;
    // Reading empties the buffer of a missing layer; writing never clears.
    auto clearer = [](auto& v) -> std::function<void()> {
        if constexpr (std::is_const_v<FB>)
            return [] {};
        else
            return [&v] { v.clear(); };
    };
    auto vec3 = [&](const char* name, auto& v, const char* const* ch) {
        if constexpr (!std::is_const_v<FB>)
            if (resize) v.assign(n, glm::vec3(0.0f));
        // An empty buffer (glossy in a scene without glossy materials) has no data to point into.
        layers.push_back({name,
                          {ch[0], ch[1], ch[2]},
                          v.empty() ? nullptr : &v.data()->x,
                          3,
                          v.size(),
                          clearer(v)});
    };
    auto scalar = [&](const char* name, auto& v, const char* ch) {
        if constexpr (!std::is_const_v<FB>)
            if (resize) v.assign(n, 0.0f);
        layers.push_back({name, {ch}, v.data(), 1, v.size(), clearer(v)});
    };
    vec3("emitted", fb.emitted, kRgb);
    vec3("shading", fb.shading, kRgb);
    scalar("visibility", fb.visibility, "Y");
    scalar("cachedVisibility", fb.cachedVisibility, "Y");
    vec3("glossy", fb.glossy, kRgb);
    vec3("indirect", fb.indirect, kRgb);
    vec3("position", fb.position, kXyz);
    vec3("normal", fb.normal, kXyz);
    scalar("depth", fb.depth, "Z");
    scalar("roughness", fb.roughness, "Y");
    vec3("albedo", fb.albedo, kRgb);
    vec3("specular", fb.specular, kRgb);
    ids->assign(resize ? n : fb.objectId.size(), 0.0f);
    for (size_t i = 0; i < ids->size() && !resize; ++i) (*ids)[i] = float(fb.objectId[i]);
    scalar("objectId", *ids, "Y");
    vec3("prevPosition", fb.prevPosition, kXyz);
    vec3("prevNormal", fb.prevNormal, kXyz);
    vec3("blocker", fb.blocker, kXyz);
    vec3("prevBlocker", fb.prevBlocker, kXyz);
    vec3("lightSample", fb.lightSample, kXyz);
    vec3("prevLightSample", fb.prevLightSample, kXyz);
    vec3("glossyHit", fb.glossyHit, kXyz);
    vec3("prevGlossyHit", fb.prevGlossyHit, kXyz);
    if constexpr (!std::is_const_v<FB>)
        if (resize) fb.cones.assign(n * screen::kNumCones, glm::vec3(0.0f));
    // Cone k of pixel p is cones[p * kNumCones + k]: one strided layer per cone.
    for (int k = 0; k < screen::kNumCones; ++k)
        layers.push_back({"cone" + std::to_string(k),
                          {"R", "G", "B"},
                          fb.cones.empty() ? nullptr : &fb.cones[size_t(k)].x,
                          size_t(3 * screen::kNumCones),
                          fb.cones.size() / screen::kNumCones,
                          clearer(fb.cones)});
    return layers;
}

}  // namespace

void WriteFrameBuffers(const std::string& path, const screen::FrameBuffers& fbIn,
                       AtomicFiles* group) {
    fbIn.Validate(path);
    const fs::path dir = fs::path(path).parent_path();
    if (!dir.empty() && !fs::is_directory(dir))
        throw InputError(
            path, "cannot write frame buffers: directory '" + dir.string() + "' does not exist");
    // A frame that left its previous points out (RenderOptions::frameBufferPrevPoints: nothing
    // but the camera moved) is written with the current ones in their place, so that the file
    // does not depend on how it was rendered.
    screen::FrameBuffers filled;
    const bool fill = fbIn.shadowsStill && fbIn.prevPosition.empty() && !fbIn.position.empty();
    if (fill) {
        filled = fbIn;
        filled.prevPosition = filled.position, filled.prevNormal = filled.normal;
        filled.prevGlossyHit = filled.glossyHit;
    }
    const screen::FrameBuffers& fb = fill ? filled : fbIn;
    std::vector<float> ids;
    const auto layers = Layers(fb, false, &ids);
    const std::vector<glm::vec3> beauty = fb.Compose();
    const size_t n = fb.NumPixels();

    internal::ImageFile f;
    f.width = fb.width, f.height = fb.height;
    f.channelNames = {"R", "G", "B"};
    for (const auto& l : layers)
        if (l.count > 0)
            for (const std::string& ch : l.channels) f.channelNames.push_back(l.name + "." + ch);
    f.channels = int(f.channelNames.size());
    const float* m = &fb.camera.worldToClip[0][0];
    const glm::vec3& cam = fb.camera.position;
    f.attributes = {
        {ImageAttribute::Kind::Matrix44, "texcache:worldToClip", {m, m + 16}, false},
        {ImageAttribute::Kind::Vec3, "texcache:cameraPosition", {cam.x, cam.y, cam.z}, false},
        {ImageAttribute::Kind::Float, "texcache:time", {fb.time}, false}};

    const size_t total = size_t(f.channels);
    f.pixels.resize(n * total);
    for (size_t p = 0; p < n; ++p) {
        float* o = &f.pixels[p * total];
        for (int k = 0; k < 3; ++k) *o++ = beauty[p][k];
        for (const auto& l : layers) {
            if (l.count == 0) continue;
            const float* src = l.data + p * l.stride;
            for (size_t k = 0; k < l.channels.size(); ++k) *o++ = src[k];
        }
    }

    // A temporary file renamed by the group's (or our own) Commit(), as WriteImage: readers
    // never see a partial file.
    AtomicFiles own;
    const std::string tmp = (group ? *group : own).Stage(path);
    try {
        internal::WriteImageFile(tmp, "openexr", f);
    } catch (const std::exception& e) {
        throw InputError(path, std::string("cannot write frame buffers: ") + e.what());
    }
    if (!group) own.Commit();
}

screen::FrameBuffers ReadFrameBuffers(const std::string& path) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec))
        throw InputError(path, "cannot read frame buffers: no such file");
    std::vector<ImageAttribute> attrs(3);
    attrs[0].kind = ImageAttribute::Kind::Matrix44, attrs[0].name = "texcache:worldToClip";
    attrs[1].kind = ImageAttribute::Kind::Vec3, attrs[1].name = "texcache:cameraPosition";
    attrs[2].kind = ImageAttribute::Kind::Float, attrs[2].name = "texcache:time";
    screen::FrameBuffers fb;
    std::vector<float> px;
    std::map<std::string, int> index;
    int nchannels = 0;
    try {
        internal::ImageReader in(path, &attrs);
        const internal::ImageHeader& h = in.Header();
        CheckImageSizeClaim(path, h.width, h.height, h.channels, h.rawBytes);
        for (const ImageAttribute& a : attrs)
            if (!a.found)
                throw InputError(path,
                                 "cannot read frame buffers: no texcache camera attributes (not "
                                 "written by WriteFrameBuffers?)");
        fb.width = h.width;
        fb.height = h.height;
        nchannels = h.channels;
        px.resize(fb.NumPixels() * size_t(nchannels));
        in.Read(nchannels, px.data());
        for (int c = 0; c < nchannels; ++c) index[h.channelNames[size_t(c)]] = c;
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(path, std::string("cannot read frame buffers: ") + e.what());
    }
    std::copy(attrs[0].values.begin(), attrs[0].values.end(), &fb.camera.worldToClip[0][0]);
    fb.camera.position = {attrs[1].values[0], attrs[1].values[1], attrs[1].values[2]};
    fb.camera.width = fb.width;
    fb.camera.height = fb.height;
    fb.time = attrs[2].values[0];

    std::vector<float> ids;
    const auto layers = Layers(fb, true, &ids);
    const size_t n = fb.NumPixels(), total = size_t(nchannels);
    // All columns first: a missing layer's buffer is emptied only after every copy (the cone
    // layers share one buffer).
    std::vector<std::vector<int>> cols(layers.size());
    for (size_t li = 0; li < layers.size(); ++li)
        for (const std::string& ch : layers[li].channels) {
            auto it = index.find(layers[li].name + "." + ch);
            if (it == index.end()) break;
            cols[li].push_back(it->second);
        }
    bool idsPresent = true;
    for (size_t li = 0; li < layers.size(); ++li) {
        const auto& l = layers[li];
        if (cols[li].size() != l.channels.size()) continue;
        for (size_t p = 0; p < n; ++p)
            for (size_t k = 0; k < cols[li].size(); ++k)
                l.data[p * l.stride + k] = px[p * total + size_t(cols[li][k])];
    }
    // Missing layers are empty buffers, as the stage expects of optional inputs.
    for (size_t li = 0; li < layers.size(); ++li)
        if (cols[li].size() != layers[li].channels.size()) {
            if (layers[li].name == "objectId") idsPresent = false;
            layers[li].clear();
        }
    if (idsPresent) {
        fb.objectId.resize(n);
        for (size_t i = 0; i < n; ++i) fb.objectId[i] = int32_t(std::lround(ids[i]));
    }
    return fb;
}

}  // namespace texcache
