// SPDX-License-Identifier: Apache-2.0
#include "screen_space/frame_buffers.h"

#include <cmath>

#include "texcache/error.h"

namespace texcache::screen {

std::vector<glm::vec3> FrameBuffers::Compose() const {
    const size_t n = NumPixels();
    std::vector<glm::vec3> out(n, glm::vec3(0.0f));
    for (size_t i = 0; i < n; ++i) {
        glm::vec3 c = shading[i] * visibility[i];
        if (!emitted.empty()) c += emitted[i];
        if (!glossy.empty()) c += glossy[i];
        if (!indirect.empty()) c += indirect[i];
        out[i] = c;
    }
    return out;
}

void FrameBuffers::Validate(const std::string& where) const {
    if (width <= 0 || height <= 0)
        throw InputError(where, "frame size must be positive, got " + std::to_string(width) + "x" +
                                    std::to_string(height));
    if (camera.width != width || camera.height != height)
        throw InputError(where, "the camera's raster (" + std::to_string(camera.width) + "x" +
                                    std::to_string(camera.height) + ") differs from the frame's (" +
                                    std::to_string(width) + "x" + std::to_string(height) + ")");
    const size_t n = NumPixels();
    auto check = [&](const char* name, size_t size, bool required, size_t perPixel = 1) {
        if (size == 0 && required)
            throw InputError(where, std::string("buffer '") + name + "' is missing");
        if (size != 0 && size != n * perPixel)
            throw InputError(where,
                             std::string("buffer '") + name + "' has " + std::to_string(size) +
                                 " entries, expected " + std::to_string(n * perPixel) + " (" +
                                 std::to_string(width) + "x" + std::to_string(height) +
                                 (perPixel > 1 ? " x " + std::to_string(perPixel) : "") + ")");
    };
    check("emitted", emitted.size(), false);
    check("shading", shading.size(), true);
    check("visibility", visibility.size(), true);
    check("glossy", glossy.size(), false);
    check("indirect", indirect.size(), false);
    check("position", position.size(), true);
    check("normal", normal.size(), true);
    check("depth", depth.size(), true);
    check("roughness", roughness.size(), false);
    check("albedo", albedo.size(), false);
    check("specular", specular.size(), false);
    check("objectId", objectId.size(), true);
    check("prevPosition", prevPosition.size(), false);
    check("prevNormal", prevNormal.size(), false);
    check("blocker", blocker.size(), false);
    check("prevBlocker", prevBlocker.size(), false);
    check("lightSample", lightSample.size(), false);
    check("prevLightSample", prevLightSample.size(), false);
    check("glossyHit", glossyHit.size(), false);
    check("prevGlossyHit", prevGlossyHit.size(), false);
    check("cones", cones.size(), false, kNumCones);
    check("cachedVisibility", cachedVisibility.size(), false);
    // NaN means "none here"; anything else must be a visibility.
    for (size_t i = 0; i < cachedVisibility.size(); ++i) {
        const float v = cachedVisibility[i];
        if (std::isnan(v) || (v >= 0.0f && v < INFINITY)) continue;
        throw InputError(where, "buffer 'cachedVisibility' has " + std::to_string(v) +
                                    " at pixel (" + std::to_string(i % size_t(width)) + ", " +
                                    std::to_string(i / size_t(width)) +
                                    "): expected a finite value >= 0, or NaN for none");
    }
}

}  // namespace texcache::screen
