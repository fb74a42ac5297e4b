// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene_loader.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include "renderer/obj_loader.h"
#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

const char* kIntegrators[] = {"normal", "ptex", "uv", "eyelight", "ao", "direct", "path"};

std::string TypeName(const json& j) {
    if (j.is_number()) return "a number";
    if (j.is_string()) return "a string";
    if (j.is_array()) return "an array";
    if (j.is_object()) return "an object";
    if (j.is_boolean()) return "a boolean";
    return "null";
}

/// A JSON value with its key path, for errors like "scene.json: key 'camera.fov': ...".
class Node {
public:
    Node(const json& j, std::string path, const std::string& file)
        : j_(j), path_(std::move(path)), file_(file) {}

    [[noreturn]] void Fail(const std::string& what) const {
        throw InputError(file_ + ": key '" + path_ + "'", what);
    }
    const json& raw() const { return j_; }
    const std::string& path() const { return path_; }
    /// "file: key 'path'" for messages raised outside Node.
    std::string Where() const { return file_ + ": key '" + path_ + "'"; }

    void Object(std::initializer_list<const char*> allowed) const {
        if (!j_.is_object()) Fail("expected an object, got " + TypeName(j_));
        for (const auto& [k, v] : j_.items()) {
            bool ok = false;
            for (const char* a : allowed) ok |= k == a;
            if (!ok) {
                std::string list;
                for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
                throw InputError(file_ + ": key '" + Join(k) + "'",
                                 "unknown key (expected one of: " + list + ")");
            }
        }
    }
    bool Has(const char* k) const { return j_.is_object() && j_.contains(k); }
    Node operator[](const char* k) const { return Node(j_.at(k), Join(k), file_); }
    Node At(size_t i) const { return Node(j_.at(i), path_ + "[" + std::to_string(i) + "]", file_); }
    size_t ArraySize() const {
        if (!j_.is_array()) Fail("expected an array, got " + TypeName(j_));
        return j_.size();
    }

    float Number(float lo = -1e30f, float hi = 1e30f) const {
        if (!j_.is_number()) Fail("expected a number, got " + TypeName(j_) + " " + j_.dump());
        const double v = j_.get<double>();
        if (!std::isfinite(v)) Fail("expected a finite number");
        if (v < lo || v > hi)
            Fail("value " + j_.dump() + " is out of range [" + Fmt(lo) + ", " + Fmt(hi) + "]");
        return float(v);
    }
    int Int(long lo, long hi) const {
        if (!j_.is_number_integer())
            Fail("expected an integer, got " + TypeName(j_) + " " + j_.dump());
        const long v = j_.get<long>();
        if (v < lo || v > hi)
            Fail("value " + std::to_string(v) + " is out of range [" + std::to_string(lo) + ", " +
                 std::to_string(hi) + "]");
        return int(v);
    }
    bool Bool() const {
        if (!j_.is_boolean()) Fail("expected true or false, got " + TypeName(j_));
        return j_.get<bool>();
    }
    std::string String() const {
        if (!j_.is_string()) Fail("expected a string, got " + TypeName(j_) + " " + j_.dump());
        return j_.get<std::string>();
    }
    glm::vec3 Vec3(float lo = -1e30f, float hi = 1e30f) const {
        if (!j_.is_array() || j_.size() != 3)
            Fail("expected an array of 3 numbers, got " + j_.dump());
        return {At(0).Number(lo, hi), At(1).Number(lo, hi), At(2).Number(lo, hi)};
    }

private:
    std::string Join(const std::string& k) const { return path_.empty() ? k : path_ + "." + k; }
    static std::string Fmt(float v) {
        std::ostringstream o;
        o << v;
        return o.str();
    }
    const json& j_;
    std::string path_;
    const std::string& file_;
};

std::string Resolve(const fs::path& base, const std::string& rel) {
    fs::path p(rel);
    if (p.is_relative()) p = base / p;
    return p.lexically_normal().string();
}

glm::quat RotationFromAxisAngle(const Node& n) {
    if (!n.raw().is_array() || n.raw().size() != 4)
        n.Fail("expected [angle_degrees, axis_x, axis_y, axis_z], got " + n.raw().dump());
    const float a = n.At(0).Number();
    const glm::vec3 axis(n.At(1).Number(), n.At(2).Number(), n.At(3).Number());
    if (glm::length(axis) < 1e-12f) n.Fail("rotation axis is zero");
    return glm::angleAxis(glm::radians(a), glm::normalize(axis));
}

Keyframe ParseRigid(const Node& n, bool allowTime) {
    if (allowTime)
        n.Object({"time", "translate", "rotate", "scale"});
    else
        n.Object({"translate", "rotate", "scale"});
    Keyframe k;
    if (allowTime) k.time = n["time"].Number();
    if (n.Has("translate")) k.translation = n["translate"].Vec3();
    if (n.Has("rotate")) k.rotation = RotationFromAxisAngle(n["rotate"]);
    if (n.Has("scale")) {
        const Node s = n["scale"];
        k.scale = s.raw().is_number() ? glm::vec3(s.Number(1e-12f, 1e12f)) : s.Vec3(1e-12f, 1e12f);
    }
    return k;
}

void CheckIncreasing(const Node& n, const std::vector<Keyframe>& keys) {
    for (size_t i = 1; i < keys.size(); ++i)
        if (!(keys[i].time > keys[i - 1].time))
            n.At(i)["time"].Fail("keyframe times must increase (" + std::to_string(keys[i].time) +
                                 " follows " + std::to_string(keys[i - 1].time) + ")");
}

TransformTrack ParseTrack(const Node& obj) {
    TransformTrack t;
    if (obj.Has("keyframes")) {
        const Node ks = obj["keyframes"];
        for (size_t i = 0; i < ks.ArraySize(); ++i) t.keys.push_back(ParseRigid(ks.At(i), true));
        CheckIncreasing(ks, t.keys);
        if (obj.Has("transform"))
            obj["transform"].Fail("give either 'transform' or 'keyframes', not both");
    } else if (obj.Has("transform")) {
        t.keys.push_back(ParseRigid(obj["transform"], false));
    }
    return t;
}

}  // namespace

Keyframe CameraLookAt(glm::vec3 position, glm::vec3 target, glm::vec3 up,
                      const std::string& where) {
    const glm::vec3 f = target - position;
    if (!(glm::length(f) >= 1e-9f)) throw InputError(where, "look_at equals position");
    const glm::vec3 fn = glm::normalize(f);
    const glm::vec3 r = glm::cross(fn, up);
    if (glm::length(r) < 1e-6f * glm::length(up) || glm::length(up) == 0.0f)
        throw InputError(where, "up is parallel to the view direction");
    const glm::vec3 rn = glm::normalize(r);
    const glm::vec3 u = glm::cross(rn, fn);
    Keyframe k;
    k.translation = position;
    k.rotation = glm::quat_cast(glm::mat3(rn, u, -fn));
    return k;
}

namespace {

void ParseCamera(const Node& n, Camera* cam) {
    n.Object({"position", "look_at", "up", "fov", "lens_radius", "focus_distance", "shutter",
              "keyframes"});
    if (n.Has("fov")) cam->fovYDegrees = n["fov"].Number(1e-3f, 179.0f);
    if (n.Has("lens_radius")) cam->lensRadius = n["lens_radius"].Number(0.0f, 1e6f);
    if (n.Has("focus_distance")) cam->focusDistance = n["focus_distance"].Number(1e-6f, 1e12f);
    if (n.Has("shutter")) {
        const Node s = n["shutter"];
        if (s.ArraySize() != 2) s.Fail("expected [open, close]");
        cam->shutterOpen = s.At(0).Number();
        cam->shutterClose = s.At(1).Number();
        if (cam->shutterClose < cam->shutterOpen) s.Fail("shutter closes before it opens");
    }
    const glm::vec3 defUp = n.Has("up") ? n["up"].Vec3() : glm::vec3(0, 1, 0);
    if (n.Has("keyframes")) {
        const Node ks = n["keyframes"];
        for (size_t i = 0; i < ks.ArraySize(); ++i) {
            const Node k = ks.At(i);
            k.Object({"time", "position", "look_at", "up"});
            Keyframe kf = CameraLookAt(k["position"].Vec3(), k["look_at"].Vec3(),
                                       k.Has("up") ? k["up"].Vec3() : defUp, k.Where());
            kf.time = k["time"].Number();
            cam->pose.keys.push_back(kf);
        }
        CheckIncreasing(ks, cam->pose.keys);
        if (cam->pose.keys.empty()) ks.Fail("needs at least one keyframe");
    } else {
        if (!n.Has("position") || !n.Has("look_at"))
            n.Fail("camera needs 'position' and 'look_at' (or 'keyframes')");
        cam->pose.keys.push_back(
            CameraLookAt(n["position"].Vec3(), n["look_at"].Vec3(), defUp, n.Where()));
    }
}

int ParseTexture(const Node& n, const fs::path& base, Scene* scene) {
    n.Object({"texture", "colors", "scale"});
    Texture t;
    const std::string name = n["texture"].String();
    if (name == "checker") {
        t.kind = Texture::Kind::Checker;
        if (n.Has("colors")) {
            const Node c = n["colors"];
            if (c.ArraySize() != 2) c.Fail("expected two colours");
            t.colorA = c.At(0).Vec3(0.0f, 1e6f);
            t.colorB = c.At(1).Vec3(0.0f, 1e6f);
        }
        if (n.Has("scale")) t.scale = n["scale"].Number(1e-6f, 1e6f);
    } else {
        t.kind = Texture::Kind::Image;
        t.path = Resolve(base, name);
        if (!fs::exists(t.path)) n["texture"].Fail("texture file '" + t.path + "' does not exist");
    }
    scene->textures.push_back(t);
    return int(scene->textures.size()) - 1;
}

void ParseMaterial(const Node& n, const std::string& name, const fs::path& base, Scene* scene) {
    n.Object({"type", "albedo", "roughness", "specular", "filter", "filter_radius"});
    Material m;
    m.name = name;
    const std::string type = n.Has("type") ? n["type"].String() : "diffuse";
    if (type == "diffuse")
        m.type = Material::Type::Diffuse;
    else if (type == "ggx")
        m.type = Material::Type::GGX;
    else
        n["type"].Fail("unknown material type '" + type + "' (valid: diffuse, ggx)");
    if (n.Has("albedo")) {
        const Node a = n["albedo"];
        if (a.raw().is_object())
            m.albedo.texture = ParseTexture(a, base, scene);
        else
            m.albedo.value = a.Vec3(0.0f, 1.0f);
    }
    if (n.Has("roughness")) {
        const Node r = n["roughness"];
        if (r.raw().is_object())
            m.roughness.texture = ParseTexture(r, base, scene);
        else
            m.roughness.value = r.Number(0.0f, 1.0f);
    }
    if (n.Has("specular")) m.specular = n["specular"].Vec3(0.0f, 1.0f);
    if (n.Has("filter")) {
        m.cacheFilter = n["filter"].String();
        static const std::set<std::string> kFilters = {"none", "normal", "gaussian"};
        if (!kFilters.count(m.cacheFilter))
            n["filter"].Fail("unknown filter '" + m.cacheFilter +
                             "' (valid: none, normal, gaussian)");
    }
    if (n.Has("filter_radius")) m.cacheRadius = n["filter_radius"].Int(0, 32);
    scene->materials.push_back(m);
}

void ParseLight(const Node& n, const fs::path& base, Scene* scene) {
    if (!n.raw().is_object() || !n.Has("type"))
        n.Fail("a light needs a 'type' (environment, quad, distant)");
    const std::string type = n["type"].String();
    if (type == "environment") {
        n.Object({"type", "file", "constant", "intensity", "rotation"});
        EnvironmentLight e;
        if (n.Has("file") == n.Has("constant"))
            n.Fail("an environment light needs exactly one of 'file' or 'constant'");
        if (n.Has("file")) {
            e.path = Resolve(base, n["file"].String());
            if (!fs::exists(e.path))
                n["file"].Fail("environment map '" + e.path + "' does not exist");
        } else {
            e.constant = n["constant"].Vec3(0.0f, 1e9f);
        }
        if (n.Has("intensity")) e.intensity = n["intensity"].Number(0.0f, 1e9f);
        if (n.Has("rotation")) e.rotationDegrees = n["rotation"].Number();
        if (!scene->environments.empty()) n.Fail("only one environment light is supported");
        scene->environments.push_back(e);
    } else if (type == "quad") {
        n.Object({"type", "corner", "edge1", "edge2", "radiance", "two_sided", "transform",
                  "keyframes"});
        QuadLight q;
        q.corner = n["corner"].Vec3();
        q.edge1 = n["edge1"].Vec3();
        q.edge2 = n["edge2"].Vec3();
        if (glm::length(glm::cross(q.edge1, q.edge2)) < 1e-12f)
            n["edge2"].Fail("quad light has zero area");
        q.radiance = n["radiance"].Vec3(0.0f, 1e9f);
        if (n.Has("two_sided")) q.twoSided = n["two_sided"].Bool();
        q.transform = ParseTrack(n);
        scene->quadLights.push_back(q);
    } else if (type == "distant") {
        n.Object({"type", "direction", "irradiance", "transform", "keyframes"});
        DistantLight d;
        d.direction = n["direction"].Vec3();
        if (glm::length(d.direction) < 1e-12f) n["direction"].Fail("direction is zero");
        d.direction = glm::normalize(d.direction);
        d.irradiance = n["irradiance"].Vec3(0.0f, 1e9f);
        d.transform = ParseTrack(n);
        scene->distantLights.push_back(d);
    } else {
        n["type"].Fail("unknown light type '" + type + "' (valid: environment, quad, distant)");
    }
}

void ParseRender(const Node& n, RenderSettings* s) {
    n.Object({"resolution", "spp", "seconds", "integrator", "max_depth", "seed",
              "tessellation_rate", "ao_samples", "ao_distance", "time"});
    if (n.Has("resolution")) {
        const Node r = n["resolution"];
        if (r.ArraySize() != 2) r.Fail("expected [width, height]");
        s->width = r.At(0).Int(1, 16384);
        s->height = r.At(1).Int(1, 16384);
    }
    if (n.Has("spp")) s->spp = n["spp"].Int(1, 1 << 20);
    if (n.Has("seconds")) s->seconds = n["seconds"].Number(0.0f, 1e6f);
    if (n.Has("integrator")) {
        s->integrator = n["integrator"].String();
        bool ok = false;
        for (const char* i : kIntegrators) ok |= s->integrator == i;
        if (!ok)
            n["integrator"].Fail("unknown integrator '" + s->integrator +
                                 "' (valid: normal, ptex, uv, eyelight, ao, direct, path)");
    }
    if (n.Has("max_depth")) s->maxDepth = n["max_depth"].Int(0, 1000);
    if (n.Has("seed")) s->seed = uint64_t(n["seed"].Int(0, 2147483647));
    if (n.Has("tessellation_rate"))
        s->tessellationRate = n["tessellation_rate"].Number(1.0f, 64.0f);
    if (n.Has("ao_samples")) s->aoSamples = n["ao_samples"].Int(1, 1 << 16);
    if (n.Has("ao_distance")) s->aoDistance = n["ao_distance"].Number(1e-6f, 1e30f);
    if (n.Has("time")) s->time = n["time"].Number();
}

}  // namespace

Scene LoadScene(const std::string& path, std::vector<std::string>* warnings) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path, "cannot open scene file");
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string text = ss.str();
    json j;
    try {
        j = json::parse(text);
    } catch (const json::parse_error& e) {
        // Turn the byte offset into line:column.
        size_t line = 1, col = 1;
        for (size_t i = 0; i + 1 < e.byte && i < text.size(); ++i) {
            if (text[i] == '\n')
                ++line, col = 1;
            else
                ++col;
        }
        std::string msg = e.what();
        const size_t p = msg.find("syntax error");
        throw InputError(path + ":" + std::to_string(line) + ":" + std::to_string(col),
                         "JSON " + (p == std::string::npos ? msg : msg.substr(p)));
    }
    Scene scene;
    scene.path = path;
    const fs::path base = fs::path(path).parent_path();
    const Node root(j, "", path);
    root.Object({"camera", "materials", "objects", "lights", "render"});
    if (!root.Has("camera")) throw InputError(path, "missing key 'camera'");
    ParseCamera(root["camera"], &scene.camera);

    std::map<std::string, int> materialIds;
    if (root.Has("materials")) {
        const Node ms = root["materials"];
        if (!ms.raw().is_object()) ms.Fail("expected an object of named materials");
        for (const auto& [name, value] : ms.raw().items()) {
            ParseMaterial(Node(value, "materials." + name, path), name, base, &scene);
            materialIds[name] = int(scene.materials.size()) - 1;
        }
    }
    if (!root.Has("objects")) throw InputError(path, "missing key 'objects'");
    const Node objs = root["objects"];
    if (objs.ArraySize() == 0) objs.Fail("needs at least one object");
    std::map<std::string, int> meshIds;
    for (size_t i = 0; i < objs.ArraySize(); ++i) {
        const Node o = objs.At(i);
        o.Object({"name", "mesh", "material", "transform", "keyframes"});
        Object obj;
        obj.name = o.Has("name") ? o["name"].String() : "object" + std::to_string(i);
        obj.objPath = Resolve(base, o["mesh"].String());
        if (!fs::exists(obj.objPath))
            o["mesh"].Fail("mesh file '" + obj.objPath + "' does not exist");
        auto it = meshIds.find(obj.objPath);
        if (it == meshIds.end()) {
            scene.meshes.push_back(LoadObj(obj.objPath, warnings));
            it = meshIds.emplace(obj.objPath, int(scene.meshes.size()) - 1).first;
        }
        obj.mesh = it->second;
        if (o.Has("material")) {
            const std::string m = o["material"].String();
            const auto mit = materialIds.find(m);
            if (mit == materialIds.end()) o["material"].Fail("unknown material '" + m + "'");
            obj.material = mit->second;
        } else {
            if (!materialIds.count("")) {
                scene.materials.push_back(Material{});
                materialIds[""] = int(scene.materials.size()) - 1;
            }
            obj.material = materialIds[""];
        }
        obj.transform = ParseTrack(o);
        scene.objects.push_back(obj);
    }
    if (root.Has("lights")) {
        const Node ls = root["lights"];
        for (size_t i = 0; i < ls.ArraySize(); ++i) ParseLight(ls.At(i), base, &scene);
    }
    if (root.Has("render")) ParseRender(root["render"], &scene.settings);
    return scene;
}

Scene SceneFromObj(const std::string& objPath, const std::string& defaultEnvPath,
                   std::vector<std::string>* warnings) {
    Scene scene;
    scene.path = objPath;
    scene.meshes.push_back(LoadObj(objPath, warnings));
    Object o;
    o.name = fs::path(objPath).stem().string();
    o.objPath = objPath;
    o.mesh = 0;
    scene.objects.push_back(o);
    Material m;
    m.name = "default";
    m.albedo.value = glm::vec3(0.6f);
    scene.materials.push_back(m);
    EnvironmentLight env;
    env.path = defaultEnvPath;
    scene.environments.push_back(env);

    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : scene.meshes[0].positions) {
        lo = glm::min(lo, glm::vec3(p[0], p[1], p[2]));
        hi = glm::max(hi, glm::vec3(p[0], p[1], p[2]));
    }
    const glm::vec3 centre = 0.5f * (lo + hi);
    const float radius = std::max(0.5f * glm::length(hi - lo), 1e-6f);
    // Fit the bounding sphere in the vertical field of view with a 10% margin, from a 3/4 view
    // above the object.
    const float fov = 40.0f;
    const float dist = 1.1f * radius / std::sin(glm::radians(fov) * 0.5f);
    const glm::vec3 dir = glm::normalize(glm::vec3(1.0f, 0.7f, 1.4f));
    scene.camera.fovYDegrees = fov;
    scene.camera.pose.keys.push_back(CameraLookAt(centre + dir * dist, centre, {0, 1, 0}, objPath));
    return scene;
}

}  // namespace texcache
