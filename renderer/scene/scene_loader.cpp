// SPDX-License-Identifier: Apache-2.0
// JSON scene files (format: scenes/README.md). Every value is read through a Node that knows its
// key path, so each error names the file and the key ("car.json: key 'camera.fov': ...");
// unknown and duplicate keys are errors because a typo would otherwise silently use a default.
#include "renderer/scene/scene_loader.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <unordered_set>

#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include "filters/texture_filters.h"
#include "renderer/scene/obj_loader.h"
#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr float kBig = 1e30f;  // finite values beyond this are almost certainly typos
/// Scene files nest 5 levels deep (lights[0].keyframes[0].rotate); deeper input is rejected as
/// soon as it opens level 65, before it costs more than its own bytes.
constexpr size_t kMaxJsonDepth = 64;

/// nlohmann's messages quote the token they stopped at ("last read: '/* ...'"), which may be
/// megabytes long: the quoted part is cut to an Excerpt.
std::string ExcerptQuoted(const std::string& msg) {
    const size_t q0 = msg.find('\''), q1 = msg.rfind('\'');
    if (q0 == std::string::npos || q1 <= q0) return msg;
    return msg.substr(0, q0 + 1) + Excerpt(std::string_view(msg).substr(q0 + 1, q1 - q0 - 1)) +
           msg.substr(q1);
}

std::string TypeName(const json& j) {
    if (j.is_number()) return "the number " + j.dump();
    if (j.is_string()) return "the string " + Excerpt(j.dump());
    if (j.is_array()) return "an array";
    if (j.is_object()) return "an object";
    if (j.is_boolean()) return j.dump();
    return "null";
}

/// Shortest round-trip form: a value just outside a bound does not print as the bound itself.
template <typename T>
std::string Fmt(T v) {
    char buf[64];
    return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

std::string List(std::initializer_list<const char*> names) {
    std::string s;
    for (const char* n : names) s += (s.empty() ? "" : ", ") + std::string(n);
    return s;
}

/// A JSON value with its key path, for errors like "scene.json: key 'camera.fov': ...".
class Node {
public:
    Node(const json& j, std::string path, const std::string& file)
        : j_(&j), path_(std::move(path)), file_(&file) {}

    /// "file: key 'a.b'" (just "file" at the root), the `where` of InputError.
    std::string Where() const { return path_.empty() ? *file_ : *file_ + ": key '" + path_ + "'"; }
    [[noreturn]] void Fail(const std::string& what) const { throw InputError(Where(), what); }
    const json& raw() const { return *j_; }

    /// Requires an object whose keys are all in `allowed`.
    void Keys(std::initializer_list<const char*> allowed) const {
        if (!j_->is_object()) Fail("expected an object, got " + TypeName(*j_));
        for (const auto& [k, v] : j_->items()) {
            bool ok = false;
            for (const char* a : allowed) ok |= k == a;
            if (!ok)
                Node(v, Join(k), *file_)
                    .Fail("unknown key (expected one of: " + List(allowed) + ")");
        }
    }
    bool Has(const char* k) const { return j_->is_object() && j_->contains(k); }
    /// A required member.
    Node operator[](const char* k) const {
        if (!j_->is_object()) Fail("expected an object, got " + TypeName(*j_));
        const auto it = j_->find(k);
        if (it == j_->end()) Node(*j_, Join(k), *file_).Fail("missing (required)");
        return Node(*it, Join(k), *file_);
    }
    Node At(size_t i) const {
        return Node(j_->at(i), path_ + "[" + std::to_string(i) + "]", *file_);
    }
    size_t ArraySize() const {
        if (!j_->is_array()) Fail("expected an array, got " + TypeName(*j_));
        return j_->size();
    }

    /// A finite number in [lo, hi] (bounds in double: 1e12 is within [1e-12, 1e12], though the
    /// float nearest 1e12 is below it).
    float Number(double lo = -kBig, double hi = kBig) const {
        if (!j_->is_number()) Fail("expected a number, got " + TypeName(*j_));
        const double v = j_->get<double>();
        if (!std::isfinite(v)) Fail("expected a finite number");
        if (v < lo || v > hi)
            Fail("value " + Fmt(v) + " is out of range [" + Fmt(lo) + ", " + Fmt(hi) + "]");
        return float(v);
    }
    /// A finite number in the open interval (lo, hi).
    float NumberOpen(double lo, double hi) const {
        const float v = Number();
        if (!(v > lo && v < hi))
            Fail("value " + Fmt(v) + " is out of range (" + Fmt(lo) + ", " + Fmt(hi) + ")");
        return v;
    }
    /// An integer in [lo, hi] (lo >= 0).
    int64_t Int(int64_t lo, int64_t hi) const {
        const char* kind = lo >= 1 ? "a positive integer" : "a non-negative integer";
        if (!j_->is_number_integer())
            Fail(std::string("expected ") + kind + ", got " + TypeName(*j_));
        // Unsigned JSON integers above INT64_MAX would wrap in get<int64_t>.
        if (j_->is_number_unsigned() && j_->get<uint64_t>() > uint64_t(hi))
            Fail("value " + j_->dump() + " is out of range [" + std::to_string(lo) + ", " +
                 std::to_string(hi) + "]");
        const int64_t v = j_->get<int64_t>();
        if (v < 0) Fail(std::string("expected ") + kind + ", got " + TypeName(*j_));
        if (v < lo || v > hi)
            Fail("value " + std::to_string(v) + " is out of range [" + std::to_string(lo) + ", " +
                 std::to_string(hi) + "]");
        return v;
    }
    bool Bool() const {
        if (!j_->is_boolean()) Fail("expected true or false, got " + TypeName(*j_));
        return j_->get<bool>();
    }
    std::string String() const {
        if (!j_->is_string()) Fail("expected a string, got " + TypeName(*j_));
        return j_->get<std::string>();
    }
    glm::vec3 Vec3(double lo = -kBig, double hi = kBig) const {
        if (!j_->is_array() || j_->size() != 3)
            Fail("expected an array of 3 numbers, got " +
                 (j_->is_array() ? "an array of " + std::to_string(j_->size()) : TypeName(*j_)));
        return {At(0).Number(lo, hi), At(1).Number(lo, hi), At(2).Number(lo, hi)};
    }

private:
    std::string Join(const std::string& k) const {
        return path_.empty() ? Excerpt(k) : path_ + "." + Excerpt(k);
    }
    const json* j_;
    std::string path_;
    const std::string* file_;
};

/// Absolute, normalised path of `rel` relative to the directory `base`.
std::string Resolve(const fs::path& base, const std::string& rel) {
    fs::path p(rel);
    if (p.is_relative()) p = base / p;
    return fs::absolute(p).lexically_normal().string();
}

/// Fails unless `path` is an existing regular file (a directory would pass fs::exists).
void RequireFile(const Node& n, const std::string& path, const char* what) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec))
        n.Fail(std::string(what) + " '" + path + "' " +
               (fs::exists(path, ec) ? "is not a regular file" : "does not exist"));
}

glm::quat RotationFromAxisAngle(const Node& n) {
    if (!n.raw().is_array() || n.raw().size() != 4)
        n.Fail("expected [angle_degrees, axis_x, axis_y, axis_z], got " + TypeName(n.raw()));
    const float a = n.At(0).Number();
    const glm::vec3 axis(n.At(1).Number(), n.At(2).Number(), n.At(3).Number());
    if (!(glm::length(axis) > 1e-12f)) n.Fail("rotation axis is zero");
    return glm::angleAxis(glm::radians(a), glm::normalize(axis));
}

Keyframe ParseRigid(const Node& n, bool keyed) {
    if (keyed)
        n.Keys({"time", "translate", "rotate", "scale"});
    else
        n.Keys({"translate", "rotate", "scale"});
    Keyframe k;
    if (keyed) k.time = n["time"].Number();
    if (n.Has("translate")) k.translation = n["translate"].Vec3();
    if (n.Has("rotate")) k.rotation = RotationFromAxisAngle(n["rotate"]);
    if (n.Has("scale")) {
        const Node s = n["scale"];
        // A zero or negative scale collapses or mirrors the cage (inside-out normals).
        k.scale = s.raw().is_number() ? glm::vec3(s.Number(1e-12, 1e12)) : s.Vec3(1e-12, 1e12);
    }
    return k;
}

void CheckIncreasing(const Node& keys, const std::vector<Keyframe>& k) {
    if (k.empty()) keys.Fail("needs at least one keyframe");
    for (size_t i = 1; i < k.size(); ++i)
        if (!(k[i].time > k[i - 1].time))
            keys.At(i)["time"].Fail("keyframe times must increase (" + Fmt(k[i].time) +
                                    " follows " + Fmt(k[i - 1].time) + ")");
}

/// `transform` (one static pose) or `keyframes` (animated) of an object or light.
TransformTrack ParseTrack(const Node& owner) {
    TransformTrack t;
    if (owner.Has("keyframes") && owner.Has("transform"))
        owner["transform"].Fail("give either 'transform' or 'keyframes', not both");
    if (owner.Has("keyframes")) {
        const Node ks = owner["keyframes"];
        for (size_t i = 0; i < ks.ArraySize(); ++i) t.keys.push_back(ParseRigid(ks.At(i), true));
        CheckIncreasing(ks, t.keys);
    } else if (owner.Has("transform")) {
        t.keys.push_back(ParseRigid(owner["transform"], false));
    }
    return t;
}

/// "stereo": {"eye_separation": d >= 0, "convergence": c > 0} (renderer/texture_space/stereo.h).
void ParseStereo(const Node& n, Camera* cam) {
    n.Keys({"eye_separation", "convergence"});
    cam->eyeSeparation = n["eye_separation"].Number(0.0, kBig);
    if (n.Has("convergence")) cam->convergence = n["convergence"].NumberOpen(0.0, kBig);
}

void ParseCamera(const Node& n, Camera* cam) {
    n.Keys({"position", "look_at", "up", "fov", "lens_radius", "focus_distance", "shutter",
            "keyframes", "stereo"});
    if (n.Has("fov")) cam->fovYDegrees = n["fov"].NumberOpen(0.0f, 180.0f);
    if (n.Has("lens_radius")) cam->lensRadius = n["lens_radius"].Number(0.0f, 1e6f);
    if (n.Has("focus_distance")) cam->focusDistance = n["focus_distance"].NumberOpen(0.0f, kBig);
    if (n.Has("shutter")) {
        const Node s = n["shutter"];
        if (s.ArraySize() != 2) s.Fail("expected [open, close] (seconds)");
        cam->shutterOpen = s.At(0).Number();
        cam->shutterClose = s.At(1).Number();
        if (cam->shutterClose < cam->shutterOpen) s.Fail("the shutter closes before it opens");
    }
    const glm::vec3 up = n.Has("up") ? n["up"].Vec3() : glm::vec3(0, 1, 0);
    if (n.Has("keyframes")) {
        for (const char* k : {"position", "look_at"})
            if (n.Has(k)) n[k].Fail("give either 'position'/'look_at' or 'keyframes', not both");
        const Node ks = n["keyframes"];
        for (size_t i = 0; i < ks.ArraySize(); ++i) {
            const Node k = ks.At(i);
            k.Keys({"time", "position", "look_at", "up"});
            const float time = k["time"].Number();
            Keyframe kf = CameraLookAt(k["position"].Vec3(), k["look_at"].Vec3(),
                                       k.Has("up") ? k["up"].Vec3() : up, k.Where());
            kf.time = time;
            cam->pose.keys.push_back(kf);
        }
        CheckIncreasing(ks, cam->pose.keys);
    } else {
        if (!n.Has("position") || !n.Has("look_at"))
            n.Fail("the camera needs 'position' and 'look_at' (or 'keyframes')");
        cam->pose.keys.push_back(
            CameraLookAt(n["position"].Vec3(), n["look_at"].Vec3(), up, n.Where()));
    }
    // Stereo renders converge at the look-at point unless the rig says otherwise.
    const Node at = n.Has("keyframes") ? n["keyframes"].At(0) : n;
    cam->convergence = glm::length(at["look_at"].Vec3() - at["position"].Vec3());
    if (n.Has("stereo")) ParseStereo(n["stereo"], cam);
}

/// TEXTURE: {"texture": "checker", "colors": [[..],[..]], "scale": s} or {"texture": "file"}.
int ParseTexture(const Node& n, const fs::path& base, Scene* scene) {
    Texture t;
    const std::string name = n["texture"].String();
    if (name == "checker") {
        n.Keys({"texture", "colors", "scale"});
        t.kind = Texture::Kind::Checker;
        if (n.Has("colors")) {
            const Node c = n["colors"];
            if (c.ArraySize() != 2) c.Fail("expected two colours [[r,g,b], [r,g,b]]");
            t.colorA = c.At(0).Vec3(0.0f, 1.0f);
            t.colorB = c.At(1).Vec3(0.0f, 1.0f);
        }
        if (n.Has("scale")) t.scale = n["scale"].NumberOpen(0.0f, 1e6f);
    } else {
        // Not a kind we know: an image file, which has an extension and takes no parameters. A
        // name without one ("noise") is a texture kind we do not have, whatever keys follow.
        if (fs::path(name).extension().empty())
            n["texture"].Fail("unknown texture kind '" + Excerpt(name) +
                              "' (valid: checker, or the path of an image file)");
        for (const auto& [k, v] : n.raw().items())
            if (k != "texture")
                n["texture"].Fail("the image texture '" + Excerpt(name) +
                                  "' takes no parameters, but '" + Excerpt(k) +
                                  "' is given (only the checker texture has colors and scale)");
        t.kind = Texture::Kind::Image;
        t.path = Resolve(base, name);
        RequireFile(n["texture"], t.path, "texture file");
        t.where = n["texture"].Where();
    }
    scene->textures.push_back(t);
    return int(scene->textures.size()) - 1;
}

void ParseMaterial(const Node& n, const std::string& name, const fs::path& base, Scene* scene,
                   std::vector<std::string>* warnings) {
    n.Keys({"type", "albedo", "roughness", "specular", "filter", "filter_radius"});
    Material m;
    m.name = name;
    const std::string type = n.Has("type") ? n["type"].String() : "diffuse";
    if (type == "diffuse")
        m.type = Material::Type::Diffuse;
    else if (type == "ggx")
        m.type = Material::Type::GGX;
    else
        n["type"].Fail("unknown material type '" + Excerpt(type) + "' (valid: diffuse, ggx)");
    if (n.Has("albedo")) {
        const Node a = n["albedo"];
        if (a.raw().is_object())
            m.albedo.texture = ParseTexture(a, base, scene);
        else
            m.albedo.value = a.Vec3(0.0f, 1.0f);  // > 1 would create energy
    }
    if (n.Has("roughness")) {
        const Node r = n["roughness"];
        if (r.raw().is_object()) {
            m.roughness.texture = ParseTexture(r, base, scene);
        } else if (r.raw().is_array()) {
            // [along Ptex u, across it]: anisotropic GGX (brushed metal).
            if (r.ArraySize() != 2)
                r.Fail(
                    "expected a number or an array of 2 numbers [along u, across u], got an "
                    "array of " +
                    std::to_string(r.ArraySize()));
            m.roughness.value = r.At(0).Number(0.0f, 1.0f);
            m.roughnessV = r.At(1).Number(0.0f, 1.0f);
            m.anisotropic = m.roughness.value != m.roughnessV;
        } else {
            m.roughness.value = r.Number(0.0f, 1.0f);
        }
    }
    if (n.Has("specular")) m.specular = n["specular"].Vec3(0.0f, 1.0f);
    if (m.type == Material::Type::Diffuse && warnings)
        for (const char* k : {"roughness", "specular"})
            if (n.Has(k))
                warnings->push_back(n[k].Where() + ": ignored by a diffuse material (type ggx?)");
    if (n.Has("filter")) {
        m.cacheFilter = n["filter"].String();
        ParseTextureFilter(m.cacheFilter, n["filter"].Where());  // throws listing valid names
    }
    if (n.Has("filter_radius")) m.cacheRadius = int(n["filter_radius"].Int(0, 32));
    scene->materials.push_back(m);
}

/// A non-zero direction, normalised.
glm::vec3 UnitDirection(const Node& n) {
    const glm::vec3 d = n.Vec3();
    if (!(glm::length(d) > 1e-12f)) n.Fail("direction is zero");
    return glm::normalize(d);
}

void ParseLight(const Node& n, const fs::path& base, Scene* scene) {
    if (!n.raw().is_object()) n.Fail("expected a light object, got " + TypeName(n.raw()));
    const std::string type = n["type"].String();
    if (type == "environment") {
        n.Keys({"type", "file", "constant", "intensity", "rotation"});
        EnvironmentLight e;
        if (n.Has("file") == n.Has("constant"))
            n.Fail("an environment light needs exactly one of 'file' or 'constant'");
        if (n.Has("file")) {
            e.path = Resolve(base, n["file"].String());
            RequireFile(n["file"], e.path, "environment map");
        } else {
            e.constant = n["constant"].Vec3(0.0f, kBig);
        }
        if (n.Has("intensity")) e.intensity = n["intensity"].Number(0.0f, kBig);
        if (n.Has("rotation")) e.rotationDegrees = n["rotation"].Number();
        if (!scene->environments.empty()) n.Fail("only one environment light is supported");
        scene->environments.push_back(e);
    } else if (type == "quad") {
        n.Keys({"type", "corner", "edge1", "edge2", "radiance", "two_sided", "transform",
                "keyframes"});
        QuadLight q;
        q.corner = n["corner"].Vec3();
        q.edge1 = n["edge1"].Vec3();
        q.edge2 = n["edge2"].Vec3();
        if (!(glm::length(glm::cross(q.edge1, q.edge2)) > 1e-12f))
            n["edge2"].Fail("the quad light has zero area (edge1 and edge2 are parallel)");
        q.radiance = n["radiance"].Vec3(0.0f, kBig);
        if (n.Has("two_sided")) q.twoSided = n["two_sided"].Bool();
        q.transform = ParseTrack(n);
        scene->quadLights.push_back(q);
    } else if (type == "distant" || type == "sun") {
        n.Keys({"type", "direction", "irradiance", "angle", "transform", "keyframes"});
        DistantLight d;
        d.direction = UnitDirection(n["direction"]);
        d.irradiance = n["irradiance"].Vec3(0.0f, kBig);
        // The sun's disc is 0.53 degrees across; "distant" stays the delta light it always was.
        d.angleDegrees = type == "sun" ? 0.53f : 0.0f;
        if (n.Has("angle")) d.angleDegrees = n["angle"].Number(0.0, 90.0);
        d.transform = ParseTrack(n);
        scene->distantLights.push_back(d);
    } else if (type == "point" || type == "spot") {
        const bool spot = type == "spot";
        if (spot)
            n.Keys({"type", "position", "intensity", "radius", "direction", "inner_angle",
                    "outer_angle", "transform", "keyframes"});
        else
            n.Keys({"type", "position", "intensity", "radius", "transform", "keyframes"});
        PointLight p;
        p.spot = spot;
        p.position = n["position"].Vec3();
        p.intensity = n["intensity"].Vec3(0.0f, kBig);
        if (n.Has("radius")) p.radius = n["radius"].Number(0.0, kBig);
        if (spot) {
            p.direction = UnitDirection(n["direction"]);
            if (n.Has("outer_angle")) p.outerDegrees = n["outer_angle"].NumberOpen(0.0, 180.0);
            // Without an inner angle the falloff takes the outer sixth of the cone.
            p.innerDegrees = n.Has("inner_angle") ? n["inner_angle"].Number(0.0, 180.0)
                                                  : p.outerDegrees * (5.0f / 6.0f);
            if (p.innerDegrees > p.outerDegrees)
                n["inner_angle"].Fail("the inner angle " + Fmt(p.innerDegrees) +
                                      " is larger than the outer angle " + Fmt(p.outerDegrees));
        }
        p.transform = ParseTrack(n);
        scene->pointLights.push_back(p);
    } else {
        n["type"].Fail("unknown light type '" + Excerpt(type) +
                       "' (valid: environment, quad, distant, sun, point, spot)");
    }
}

/// An object's "emission": [r,g,b] radiance, or {"radiance": [r,g,b], "scale": s,
/// "two_sided": b}.
void ParseEmission(const Node& n, Object* obj) {
    if (n.raw().is_array()) {
        obj->emission = n.Vec3(0.0f, kBig);
        return;
    }
    n.Keys({"radiance", "scale", "two_sided"});
    const float scale = n.Has("scale") ? n["scale"].Number(0.0, kBig) : 1.0f;
    obj->emission = n["radiance"].Vec3(0.0f, kBig) * scale;
    if (!std::isfinite(obj->emission.x + obj->emission.y + obj->emission.z))
        n["scale"].Fail("radiance x scale overflows a float");
    if (n.Has("two_sided")) obj->emissionTwoSided = n["two_sided"].Bool();
}

void ParseRender(const Node& n, RenderSettings* s) {
    n.Keys({"resolution", "spp", "seconds", "integrator", "max_depth", "seed", "tessellation_rate",
            "ao_samples", "ao_distance", "time"});
    if (n.Has("resolution")) {
        const Node r = n["resolution"];
        if (r.ArraySize() != 2) r.Fail("expected [width, height] in pixels");
        s->width = int(r.At(0).Int(1, 16384));
        s->height = int(r.At(1).Int(1, 16384));
    }
    if (n.Has("spp")) s->spp = int(n["spp"].Int(1, 1 << 20));
    if (n.Has("seconds")) s->seconds = n["seconds"].Number(0.0f, 1e6f);
    if (n.Has("integrator")) {
        const Node i = n["integrator"];
        try {
            s->integrator = ParseIntegrator(i.String(), "");
        } catch (const InputError& e) {
            i.Fail(e.what());
        }
    }
    if (n.Has("max_depth")) s->maxDepth = int(n["max_depth"].Int(0, 1000));
    if (n.Has("seed")) s->seed = uint64_t(n["seed"].Int(0, INT64_MAX));
    // Embree accepts rates in [1, 64]: below 1 the surface is not even one quad per patch.
    if (n.Has("tessellation_rate"))
        s->tessellationRate = n["tessellation_rate"].Number(1.0f, 64.0f);
    if (n.Has("ao_samples")) s->aoSamples = int(n["ao_samples"].Int(1, 1 << 16));
    if (n.Has("ao_distance")) s->aoDistance = n["ao_distance"].NumberOpen(0.0f, kBig);
    if (n.Has("time")) s->time = n["time"].Number();
}

/// Builds the JSON document from nlohmann's SAX events, rejecting duplicate keys (nlohmann keeps
/// the last silently, which would hide a typo'd override) and nesting beyond kMaxJsonDepth. Not
/// nlohmann's parser callback: its DOM builder scans the parent object for a discarded value at
/// every object end, quadratic in the number of sibling objects (100,000 materials take minutes).
/// Here time and memory stay proportional to the text: each open container keeps its own
/// current key (the key path is built only for a message) and its keys in a hash set.
class JsonBuilder {
public:
    explicit JsonBuilder(const std::string& file) : file_(file) {}
    json Take() { return std::move(root_); }

    bool null() { return Add(nullptr); }
    bool boolean(bool v) { return Add(v); }
    bool number_integer(json::number_integer_t v) { return Add(v); }
    bool number_unsigned(json::number_unsigned_t v) { return Add(v); }
    bool number_float(json::number_float_t v, const std::string&) { return Add(v); }
    bool string(json::string_t& v) { return Add(std::move(v)); }
    bool binary(json::binary_t& v) { return Add(std::move(v)); }
    bool start_object(size_t) { return Open(json::object()); }
    bool start_array(size_t) { return Open(json::array()); }
    bool end_object() { return Close(); }
    bool end_array() { return Close(); }
    bool key(json::string_t& k) {
        Frame& f = stack_.back();
        if (!f.keys.insert(k).second) {
            f.key = k;
            throw InputError(file_ + ": key '" + Path(stack_.size()) + "'",
                             "duplicate key (given twice in the same object)");
        }
        f.key = std::move(k);
        return true;
    }
    template <class Exception>
    bool parse_error(size_t, const std::string&, const Exception& e) {
        throw e;  // the parse_error or out_of_range (number overflow) ParseJson reports
    }

private:
    struct Frame {
        json* value;
        std::string key;                       // objects: the current key
        std::unordered_set<std::string> keys;  // objects: keys seen so far
    };
    /// "a.b[2].c": the path of the current value in the first `depth` open containers.
    std::string Path(size_t depth) const {
        std::string p;
        for (size_t i = 0; i < depth; ++i) {
            const Frame& f = stack_[i];
            if (f.value->is_array())  // open ancestors hold their open child already
                p += "[" + std::to_string(f.value->size() - (i + 1 < stack_.size())) + "]";
            else
                p += (p.empty() ? "" : ".") + Excerpt(f.key);
        }
        return p;
    }
    /// Puts `v` where the parse is: the root, the end of the open array or the current key.
    json* Place(json&& v) {
        if (stack_.empty()) return &(root_ = std::move(v));
        json& top = *stack_.back().value;
        if (top.is_array()) return &top.emplace_back(std::move(v));
        return &(top[stack_.back().key] = std::move(v));
    }
    bool Open(json&& container) {
        if (stack_.size() >= kMaxJsonDepth)
            throw InputError(file_ + ": key '" + Path(std::min<size_t>(stack_.size(), 8)) +
                                 (stack_.size() > 8 ? "...'" : "'"),
                             "JSON nested deeper than " + std::to_string(kMaxJsonDepth) +
                                 " levels (scene files need fewer than 10)");
        json* v = Place(std::move(container));
        stack_.push_back({v, {}, {}});
        return true;
    }
    bool Close() {
        stack_.pop_back();
        return true;
    }
    template <class T>
    bool Add(T&& v) {
        Place(json(std::forward<T>(v)));
        return true;
    }

    const std::string& file_;
    json root_;
    std::vector<Frame> stack_;
};

/// Parses with comments allowed (JsonBuilder: duplicate keys and deep nesting rejected); syntax
/// errors become "file:line:col: ...".
json ParseJson(const std::string& text, const std::string& file) {
    // Editors want line:column, nlohmann gives a byte offset (1-based: the offending character).
    const auto lineCol = [&](size_t byte) {
        size_t line = 1, col = 1;
        for (size_t i = 0; i + 1 < byte && i < text.size(); ++i) {
            if (text[i] == '\n')
                ++line, col = 1;
            else
                ++col;
        }
        return file + ":" + std::to_string(line) + ":" + std::to_string(col);
    };
    try {
        JsonBuilder builder(file);
        json::sax_parse(text, &builder, json::input_format_t::json, /*strict=*/true,
                        /*ignore_comments=*/true);
        return builder.Take();
    } catch (const json::parse_error& e) {
        const std::string msg = e.what();
        const size_t p = msg.find("syntax error");
        throw InputError(lineCol(e.byte),
                         "JSON " + ExcerptQuoted(p == std::string::npos ? msg : msg.substr(p)));
    } catch (const json::out_of_range& e) {
        // "number overflow parsing '1e999'" carries no position: point at the literal instead.
        const std::string msg = e.what();
        const size_t q0 = msg.find('\''), q1 = msg.rfind('\'');
        const size_t at = q0 < q1 ? text.find(msg.substr(q0 + 1, q1 - q0 - 1)) : std::string::npos;
        const size_t p = msg.find(']');
        throw InputError(at == std::string::npos ? file : lineCol(at + 1),
                         "JSON " + ExcerptQuoted(p == std::string::npos ? msg : msg.substr(p + 2)));
    }
}

/// World-space bounding box of every object's cage at `time`.
void SceneBounds(const Scene& scene, float time, glm::vec3* lo, glm::vec3* hi) {
    *lo = glm::vec3(kBig);
    *hi = glm::vec3(-kBig);
    for (const Object& o : scene.objects) {
        const glm::mat4 m = o.transform.Eval(time);
        for (const auto& p : scene.meshes[size_t(o.mesh)].positions) {
            const glm::vec3 w(m * glm::vec4(p[0], p[1], p[2], 1.0f));
            *lo = glm::min(*lo, w);
            *hi = glm::max(*hi, w);
        }
    }
}

/// A default camera looks at the box's centre: stereo renders converge there.
void DefaultConvergence(glm::vec3 lo, glm::vec3 hi, Camera* cam) {
    cam->convergence = glm::length(0.5f * (lo + hi) - cam->pose.keys.front().translation);
}

/// A camera pose that fits the box's bounding sphere into the narrower of the two fields of view
/// with a 10% margin, seen from a 3/4 view above (+Y up). Objects placed beyond +-1e18 (OBJ
/// coordinates are limited to that, transforms may move them further) cannot be framed in float:
/// the error names the scene's objects, not the camera.
Keyframe FrameBounds(glm::vec3 lo, glm::vec3 hi, float fovYDegrees, float aspect,
                     const std::string& scenePath) {
    const glm::vec3 far = glm::max(glm::abs(lo), glm::abs(hi));
    const float reach = std::max({far.x, far.y, far.z});
    if (!(reach <= 1e18f))
        throw InputError(scenePath, "the objects reach " + Fmt(reach) +
                                        " from the origin (beyond +-1e18): too large to frame "
                                        "with the default camera or to ray trace");
    const glm::vec3 centre = 0.5f * (lo + hi);
    const float radius = std::max(0.5f * glm::length(hi - lo), 1e-6f);
    const float halfY = 0.5f * glm::radians(fovYDegrees);
    const float halfX = std::atan(std::tan(halfY) * aspect);
    const float dist = 1.1f * radius / std::sin(std::min(halfX, halfY));
    const glm::vec3 dir = glm::normalize(glm::vec3(1.0f, 0.7f, 1.4f));
    return CameraLookAt(centre + dir * dist, centre, {0, 1, 0}, "default camera");
}

}  // namespace

Keyframe CameraLookAt(glm::vec3 position, glm::vec3 target, glm::vec3 up,
                      const std::string& where) {
    const glm::vec3 f = target - position;
    if (!(glm::length(f) > 1e-9f)) throw InputError(where, "look_at equals position");
    if (!(glm::length(up) > 1e-12f)) throw InputError(where, "up is zero");
    const glm::vec3 fn = glm::normalize(f);
    const glm::vec3 r = glm::cross(fn, glm::normalize(up));
    if (!(glm::length(r) > 1e-6f))
        throw InputError(where, "up is parallel to the view direction (look_at - position)");
    // Columns: camera +X (right), +Y (the part of `up` orthogonal to the view), +Z (backwards).
    const glm::vec3 rn = glm::normalize(r);
    Keyframe k;
    k.translation = position;
    k.rotation = glm::normalize(glm::quat_cast(glm::mat3(rn, glm::cross(rn, fn), -fn)));
    return k;
}

Scene LoadScene(const std::string& path, std::vector<std::string>* warnings) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, not a scene file");
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path, "cannot open scene file (missing or unreadable)");
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string text = ss.str();
    const json j = ParseJson(text, path);

    Scene scene;
    scene.path = path;
    const fs::path base = fs::absolute(path).parent_path();
    const Node root(j, "", path);
    root.Keys({"camera", "materials", "objects", "lights", "render"});
    // Render settings first: a default camera (no 'camera' key) needs the aspect ratio and the
    // frame time, and is made once the objects are loaded.
    if (root.Has("render")) ParseRender(root["render"], &scene.settings);
    if (root.Has("camera")) ParseCamera(root["camera"], &scene.camera);

    std::map<std::string, int> materialIds;
    if (root.Has("materials")) {
        const Node ms = root["materials"];
        if (!ms.raw().is_object())
            ms.Fail("expected an object of named materials, got " + TypeName(ms.raw()));
        for (const auto& [name, value] : ms.raw().items()) {
            ParseMaterial(Node(value, "materials." + name, path), name, base, &scene, warnings);
            materialIds[name] = int(scene.materials.size()) - 1;
        }
    }
    const Node objs = root["objects"];
    if (objs.ArraySize() == 0) objs.Fail("needs at least one object");
    std::map<std::string, int> meshIds;
    int defaultMaterial = -1;
    for (size_t i = 0; i < objs.ArraySize(); ++i) {
        const Node o = objs.At(i);
        o.Keys({"name", "mesh", "material", "transform", "keyframes", "subdivision", "emission"});
        Object obj;
        obj.name = o.Has("name") ? o["name"].String() : "object" + std::to_string(i);
        obj.objPath = Resolve(base, o["mesh"].String());
        if (o.Has("subdivision")) {
            const std::string sub = o["subdivision"].String();
            if (sub != "catmull-clark" && sub != "none")
                o["subdivision"].Fail("unknown subdivision '" + Excerpt(sub) +
                                      "' (valid: catmull-clark, none)");
            obj.subdivide = sub == "catmull-clark";
        }
        if (o.Has("emission")) ParseEmission(o["emission"], &obj);
        // A mesh is one Embree geometry of one form: a file used both ways gets two copies.
        const auto key = [&](bool subdivide) { return (subdivide ? "s:" : "p:") + obj.objPath; };
        auto it = meshIds.find(key(obj.subdivide));
        if (it == meshIds.end()) {
            const auto other = meshIds.find(key(!obj.subdivide));
            if (other != meshIds.end()) {
                ControlCage copy = scene.meshes[size_t(other->second)];
                scene.meshes.push_back(std::move(copy));
            } else {
                RequireFile(o["mesh"], obj.objPath, "mesh file");
                scene.meshes.push_back(LoadObj(obj.objPath, warnings));  // errors name the line
            }
            it = meshIds.emplace(key(obj.subdivide), int(scene.meshes.size()) - 1).first;
        }
        obj.mesh = it->second;
        if (o.Has("material")) {
            const std::string m = o["material"].String();
            const auto mit = materialIds.find(m);
            if (mit == materialIds.end()) {
                std::string known;
                for (const auto& [k, v] : materialIds) known += (known.empty() ? "" : ", ") + k;
                o["material"].Fail("unknown material '" + Excerpt(m) + "' (defined: " +
                                   (known.empty() ? "none" : Excerpt(known, 200)) + ")");
            }
            obj.material = mit->second;
        } else {
            if (defaultMaterial < 0) {
                Material grey;
                grey.name = "default";
                scene.materials.push_back(grey);
                defaultMaterial = int(scene.materials.size()) - 1;
            }
            obj.material = defaultMaterial;
        }
        obj.transform = ParseTrack(o);
        scene.objects.push_back(obj);
    }
    if (root.Has("lights")) {
        const Node ls = root["lights"];
        for (size_t i = 0; i < ls.ArraySize(); ++i) ParseLight(ls.At(i), base, &scene);
    }
    bool lit = !scene.environments.empty() || !scene.quadLights.empty() ||
               !scene.distantLights.empty() || !scene.pointLights.empty();
    for (const Object& o : scene.objects) lit |= o.Emissive();
    if (!lit && warnings && IntegratorUsesLights(scene.settings.integrator))
        warnings->push_back(path + ": no lights: the '" +
                            std::string(IntegratorName(scene.settings.integrator)) +
                            "' integrator will render black");
    if (!root.Has("camera")) {
        glm::vec3 lo, hi;
        SceneBounds(scene, scene.settings.time, &lo, &hi);
        scene.camera.pose.keys.push_back(
            FrameBounds(lo, hi, scene.camera.fovYDegrees,
                        float(scene.settings.width) / float(scene.settings.height), scene.path));
        DefaultConvergence(lo, hi, &scene.camera);
    }
    return scene;
}

Scene LoadSceneFile(const std::string& path, const std::string& defaultEnvPath,
                    std::vector<std::string>* warnings) {
    if (!fs::exists(path)) throw InputError(path, "no such file");
    std::string ext = fs::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".obj") return SceneFromObj(path, defaultEnvPath, warnings);
    if (ext == ".json") return LoadScene(path, warnings);
    throw InputError(path, "unknown scene type '" + ext + "' (expected .json or .obj)");
}

Scene SceneFromObj(const std::string& objPath, const std::string& defaultEnvPath,
                   std::vector<std::string>* warnings) {
    Scene scene;
    scene.path = objPath;
    scene.meshes.push_back(LoadObj(objPath, warnings));
    Object o;
    o.name = fs::path(objPath).stem().string();
    o.objPath = fs::absolute(objPath).lexically_normal().string();
    o.mesh = 0;
    scene.objects.push_back(o);
    Material m;
    m.name = "default";
    m.albedo.value = glm::vec3(0.6f);
    scene.materials.push_back(m);
    EnvironmentLight env;
    std::error_code ec;
    if (fs::is_regular_file(defaultEnvPath, ec)) {
        env.path = defaultEnvPath;
    } else {
        // A missing install file should not stop a quick look at a cage: light it evenly.
        env.constant = glm::vec3(1.0f);
        if (warnings)
            warnings->push_back(defaultEnvPath +
                                ": default environment map not found; using constant white");
    }
    scene.environments.push_back(env);
    glm::vec3 lo, hi;
    SceneBounds(scene, 0.0f, &lo, &hi);
    scene.camera.pose.keys.push_back(
        FrameBounds(lo, hi, scene.camera.fovYDegrees,
                    float(scene.settings.width) / float(scene.settings.height), scene.path));
    DefaultConvergence(lo, hi, &scene.camera);
    return scene;
}

}  // namespace texcache
