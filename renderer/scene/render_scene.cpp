// SPDX-License-Identifier: Apache-2.0
// RenderScene: the Embree device and the scene's two levels (one Embree scene per mesh, built
// by embree_mesh.cpp; an instance per object, posed over the shutter; quad lights as geometry),
// the environment and the textures; and the queries every renderer makes of it: rays traced one
// at a time or in packets, a hit turned into a shading point (SurfaceInteraction) with its
// limit-surface derivatives and ray differentials, the limit surface at a Ptex location.
#include "renderer/scene/render_scene.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>

#include <embree3/rtcore.h>

#include "renderer/scene/embree_mesh.h"
#include "renderer/scene/envmap.h"
#include "renderer/scene/texture.h"
#include "texcache/error.h"

namespace texcache {

using namespace internal;

namespace {

// Steps of an instance's motion over the shutter: enough for slerped rotations to look round.
constexpr int kMotionSteps = 5;

void EmbreeError(void*, RTCError code, const char* str) {
    // Called from inside Embree's C code, where no exception may pass: report and go on.
    if (code != RTC_ERROR_NONE)
        std::fprintf(stderr, "texcache: Embree error %d: %s\n", int(code), str ? str : "");
}

/// Bytes Embree holds now, and at most so far, from its memory monitor callback (atomics: Embree's
/// build threads allocate concurrently).
struct EmbreeMemory {
    std::atomic<int64_t> now{0}, peak{0};

    static bool Count(void* self, ssize_t bytes, bool /*post*/) {
        auto* m = static_cast<EmbreeMemory*>(self);
        const int64_t n = m->now.fetch_add(bytes, std::memory_order_relaxed) + bytes;
        int64_t p = m->peak.load(std::memory_order_relaxed);
        while (n > p && !m->peak.compare_exchange_weak(p, n, std::memory_order_relaxed)) {
        }
        return true;  // never refuse an allocation
    }
    size_t Bytes() const { return size_t(std::max<int64_t>(now.load(), 0)); }
    size_t PeakBytes() const { return size_t(std::max<int64_t>(peak.load(), 0)); }
};

}  // namespace

struct RenderScene::Impl {
    RTCDevice device = nullptr;
    EmbreeMemory embreeMemory;
    RTCScene top = nullptr;

    using Mesh = internal::EmbreeMesh;
    std::vector<Mesh> meshes;  // by Scene::meshes index; unused meshes stay empty
    TessellationStats tessellation;
    BuildSeconds build;

    struct Instance {
        int mesh = -1;
        std::vector<glm::mat4> steps;  // 1 (static) or kMotionSteps over the shutter
        glm::mat3 linear{1.0f};        // of steps[0]
        glm::mat3 normalMatrix{1.0f};  // of steps[0]
        glm::mat4 inverse{1.0f};       // of steps[0]
    };
    std::vector<Instance> objects;  // by Scene::objects index
    // Top-level geomID -> object or quad light (-1: not that kind); geomIDs are small and dense.
    std::vector<int> geomToObject, geomToLight;
    // The point and spot lights with a radius, as one geometry of spheres: its geomID, and per
    // sphere its Hit::light (after the quad lights).
    unsigned sphereGeom = RTC_INVALID_GEOMETRY_ID;
    std::vector<int> sphereToLight;
    static void Map(std::vector<int>& v, unsigned id, int value) {
        if (v.size() <= id) v.resize(id + 1, -1);
        v[id] = value;
    }
    std::vector<std::unique_ptr<TextureImage>> textures;
    // Rays are handed to Embree only when Traceable: starting within `reach` (render units; in
    // every object's space that is within Embree's range) and otherwise well formed.
    float reach = 0.0f;
    mutable std::atomic<uint64_t> untraced{0};

    /// Embree's own ray.valid() and tnear >= 0 (asserted by its kernels, also in the objects'
    /// spaces the instances map rays into), and a shutter time in [0, 1] (asserted on motion
    /// blur). Sums, not maxima, so that a NaN anywhere fails.
    bool Traceable(const Ray& r) const {
        const float o = std::abs(r.org.x) + std::abs(r.org.y) + std::abs(r.org.z);
        const float d = std::abs(r.dir.x) + std::abs(r.dir.y) + std::abs(r.dir.z);
        if (o <= reach && d <= 1e18f && r.tnear >= 0.0f && r.tfar == r.tfar && r.time >= 0.0f &&
            r.time <= 1.0f)
            return true;
        untraced.fetch_add(1, std::memory_order_relaxed);
        return false;
    }

    /// How far from the origin (render units, as a sum of |x|, |y|, |z|) a ray may start so that
    /// it stays within Embree's range (FLT_LARGE, 1.8e18; 2^59 with a margin) in every object's
    /// space too: inverse(M) maps an origin o to inverse(M) o, at most |inverse(M)|_inf |o| + |its
    /// translation| there.
    static float RayReach(const std::vector<Instance>& objects) {
        constexpr double kEmbreeRange = 576460752303423488.0;  // 2^59
        double reach = kEmbreeRange;
        for (const auto& inst : objects)
            for (const glm::mat4& step : inst.steps) {
                const glm::dmat4 inv = glm::inverse(glm::dmat4(step));
                double norm = 0.0;
                for (int r = 0; r < 3; ++r)
                    norm = std::max(
                        norm, std::abs(inv[0][r]) + std::abs(inv[1][r]) + std::abs(inv[2][r]));
                const double t = std::abs(inv[3][0]) + std::abs(inv[3][1]) + std::abs(inv[3][2]);
                reach = std::min(reach, std::max(kEmbreeRange - t, 0.0) / std::max(norm, 1e-300));
            }
        return float(reach);
    }

    ~Impl() {
        for (auto& m : meshes)
            if (m.scene) rtcReleaseScene(m.scene);
        if (top) rtcReleaseScene(top);
        if (device) rtcReleaseDevice(device);
    }

    /// Linear part of Transform(object, time): what maps object-space derivatives to world space.
    glm::mat3 Linear(int object, float time) const {
        const Instance& inst = objects[object];
        return inst.steps.size() == 1 ? inst.linear : glm::mat3(Transform(object, time));
    }

    /// World-space geometric normal of a hit on an object (Embree gives it in object space).
    glm::vec3 WorldNormal(int object, float time, glm::vec3 Ng) const {
        const Instance& inst = objects[object];
        const glm::mat3 N = inst.steps.size() == 1
                                ? inst.normalMatrix
                                : glm::transpose(glm::inverse(glm::mat3(Transform(object, time))));
        return N * Ng;
    }

    /// A hit from Embree's fields (geomID valid), as Intersect and Intersect16 report it.
    void ToHit(float tfar, unsigned geomID, unsigned instID, unsigned primID, float u, float v,
               glm::vec3 Ng, float time, Hit* hit) const {
        hit->t = tfar;
        hit->primID = primID;
        hit->U = u;
        hit->V = v;
        if (instID != RTC_INVALID_GEOMETRY_ID) {
            hit->object = geomToObject[instID];
            hit->light = -1;
            hit->Ng = WorldNormal(hit->object, time, Ng);
        } else {
            hit->object = -1;
            hit->light = geomID == sphereGeom ? sphereToLight[primID] : geomToLight[geomID];
            hit->Ng = Ng;
        }
    }

    /// The point and spot lights with a radius, posed at `time`, as spheres that camera and BSDF
    /// rays see (lights without one are points: nothing to hit).
    void AddSphereLights(const Scene& scene, float time) {
        std::vector<glm::vec4> spheres;
        for (size_t l = 0; l < scene.pointLights.size(); ++l) {
            const PointLight& p = scene.pointLights[l];
            if (!(p.radius > 0.0f)) continue;
            const glm::vec3 c(p.transform.Eval(time) * glm::vec4(p.position, 1.0f));
            spheres.emplace_back(c, p.radius);
            sphereToLight.push_back(int(scene.quadLights.size() + l));
        }
        if (spheres.empty()) return;
        RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
        auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
            g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float), spheres.size()));
        for (size_t i = 0; i < spheres.size(); ++i)
            for (int k = 0; k < 4; ++k) v[4 * i + k] = spheres[i][k];
        rtcCommitGeometry(g);
        sphereGeom = rtcAttachGeometry(top, g);
        rtcReleaseGeometry(g);
    }

    glm::mat4 Transform(int object, float time) const {
        const auto& steps = objects[object].steps;
        if (steps.size() == 1) return steps[0];
        // Embree interpolates instance matrices linearly between time steps; match it exactly.
        const float x = glm::clamp(time, 0.0f, 1.0f) * float(steps.size() - 1);
        const int i = std::min(int(x), int(steps.size()) - 2);
        const float f = x - float(i);
        return steps[i] * (1.0f - f) + steps[i + 1] * f;
    }
};

/// Adds the seconds since the last call (or construction) to a stage of the scene build.
class StageClock {
public:
    void Charge(double* stage) {
        const auto now = std::chrono::steady_clock::now();
        *stage += std::chrono::duration<double>(now - last_).count();
        last_ = now;
    }

private:
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

/// The texture indices a material's parameters look up (-1: a constant).
static std::array<int, 4> MaterialTextures(const Material& m) {
    return {m.albedo.texture, m.roughness.texture, m.specular.texture, m.emission.texture};
}

static bool ObjectUsesTextures(const Scene& scene, const Object& o) {
    for (const int m : o.Materials())
        for (const int t : MaterialTextures(scene.materials[size_t(m)]))
            if (t >= 0) return true;
    return false;
}

RenderScene::RenderScene(const Scene& scene, const RenderSceneOptions& options)
    : scene_(scene), impl_(std::make_unique<Impl>()) {
    Impl& I = *impl_;
    StageClock clock;
    std::string config = options.threads > 0 ? "threads=" + std::to_string(options.threads) : "";
    I.device = rtcNewDevice(config.c_str());
    if (!I.device) throw std::runtime_error("cannot create Embree device");
    rtcSetDeviceErrorFunction(I.device, EmbreeError, nullptr);
    rtcSetDeviceMemoryMonitorFunction(I.device, EmbreeMemory::Count, &I.embreeMemory);
    I.top = rtcNewScene(I.device);

    // Which meshes are used, and which of them need face-varying uvs (textured materials only),
    // are plain meshes or emit light.
    const size_t numMeshes = scene.meshes.size();
    std::vector<char> used(numMeshes, 0), needUv(numMeshes, 0), plain(numMeshes, 0),
        emissive(numMeshes, 0);
    for (const Object& o : scene.objects) {
        if (used[o.mesh] && plain[o.mesh] != !o.subdivide)
            throw InputError(scene.path, "object '" + o.name +
                                             "' shares its mesh with an object of the other "
                                             "subdivision (give each form its own mesh)");
        used[o.mesh] = 1;
        plain[o.mesh] = !o.subdivide;
        emissive[o.mesh] |= o.Emissive();
        if (options.needTextures && ObjectUsesTextures(scene, o)) needUv[o.mesh] = 1;
    }

    I.meshes.resize(numMeshes);
    clock.Charge(&I.build.other);
    for (size_t m = 0; m < numMeshes; ++m) {
        if (!used[m]) continue;
        const ControlCage& cage = scene.meshes[m];
        Impl::Mesh& mesh = I.meshes[m];
        CageTopology t = BuildCageTopology(cage);
        mesh.topo = std::make_shared<const PtexTopology>(std::move(t.ptex));
        mesh.regular = std::make_unique<RegularPatches>(std::move(t.regular));
        const size_t beyond = plain[m] ? 0 : FacesBeyondEmbree(cage, *mesh.topo);
        // An emissive subdivision surface is rendered as its limit tessellation, the surface its
        // light samples are taken on (lights.h, MeshEmitter).
        const bool tessellate = !plain[m] && (beyond > 0 || options.tessellateAll || emissive[m]);
        if (!tessellate && !plain[m] && options.irregularPatches) {
            // rtcInterpolate re-derives a face's patch on every call (about a microsecond): a
            // large share of a path-traced frame's CPU time when many faces are off the fast
            // path, as most of the car's are. OpenSubdiv's patches at isolation level 6 evaluate
            // the same surface (normals within 1e-5 RMSE of rtcInterpolate's; level 4 is 3e-3
            // off) for a small build cost (single-crease patches: isolating the creases costs
            // several times the time and memory). Each part keeps its own copy of the cage's
            // points (LimitSurface): a cost on huge irregular cages.
            BuildIrregularPatches(cage, OffFastPathFaces(cage, *mesh.topo, *mesh.regular), &mesh);
        }
        clock.Charge(&I.build.opensubdiv);
        mesh.scene = rtcNewScene(I.device);
        const bool wantUv = needUv[m] && !cage.uvs.empty();
        RTCGeometry g;
        if (plain[m]) {
            g = NewPlainQuadGeometry(I.device, cage, wantUv, &mesh);
            // Watertight: neighbouring quads share corners (see the limit quads below).
            rtcSetSceneFlags(mesh.scene, RTC_SCENE_FLAG_ROBUST);
        } else if (tessellate) {
            g = NewLimitQuadGeometry(I.device, cage, scene.settings.tessellationRate, wantUv,
                                     &mesh);
            clock.Charge(&I.build.opensubdiv);
            // Watertight quads: a ray through a shared vertex of the tessellation otherwise
            // may slip between its quads (ctest -R EmbreeLimits.ClosedCagesHaveNoHoles aims
            // rays at the limit points on the n-gons' edges).
            rtcSetSceneFlags(mesh.scene, RTC_SCENE_FLAG_ROBUST);
            if (beyond > 0 || options.tessellateAll) {  // not counted: emitters' (by choice)
                ++I.tessellation.meshes;
                I.tessellation.cageFaces += size_t(cage.numFaces());
                I.tessellation.beyondEmbree += beyond;
            }
        } else {
            g = NewSubdivisionGeometry(I.device, cage, scene.settings.tessellationRate, wantUv,
                                       &mesh);
        }
        rtcCommitGeometry(g);
        rtcAttachGeometry(mesh.scene, g);
        mesh.geom = g;  // owned by mesh.scene from here on
        rtcReleaseGeometry(g);
        clock.Charge(&I.build.embreeGeometry);
        rtcCommitScene(mesh.scene);
        clock.Charge(&I.build.embreeBvh);
    }

    // Objects become instances; only animated objects with an open shutter get motion steps.
    const Camera& cam = scene.camera;
    const bool blur = cam.shutterClose > cam.shutterOpen;
    I.objects.resize(scene.objects.size());
    for (size_t o = 0; o < scene.objects.size(); ++o) {
        const Object& obj = scene.objects[o];
        Impl::Instance& inst = I.objects[o];
        inst.mesh = obj.mesh;
        const int steps = blur && obj.transform.IsAnimated() ? kMotionSteps : 1;
        RTCGeometry g = rtcNewGeometry(I.device, RTC_GEOMETRY_TYPE_INSTANCE);
        rtcSetGeometryInstancedScene(g, I.meshes[obj.mesh].scene);
        rtcSetGeometryTimeStepCount(g, unsigned(steps));
        for (int s = 0; s < steps; ++s) {
            const float t = steps == 1 ? options.frameTime
                                       : options.frameTime + (cam.shutterClose - cam.shutterOpen) *
                                                                 float(s) / float(steps - 1);
            inst.steps.push_back(obj.transform.Eval(t));
            rtcSetGeometryTransform(g, unsigned(s), RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR,
                                    &inst.steps.back()[0][0]);
        }
        rtcCommitGeometry(g);
        Impl::Map(I.geomToObject, rtcAttachGeometry(I.top, g), int(o));
        // Static instances keep their linear part and normal matrix (per hit, the linear part
        // otherwise takes a 4x4 copy, the normal matrix a 3x3 inverse).
        inst.linear = glm::mat3(inst.steps[0]);
        inst.normalMatrix = glm::transpose(glm::inverse(glm::mat3(inst.steps[0])));
        inst.inverse = glm::inverse(inst.steps[0]);
        rtcReleaseGeometry(g);
    }
    I.reach = Impl::RayReach(I.objects);
    clock.Charge(&I.build.embreeGeometry);

    // Quad lights are real geometry so camera and BSDF rays see them (posed at the frame time).
    if (options.needLights) {
        for (size_t l = 0; l < scene.quadLights.size(); ++l) {
            const QuadLight& ql = scene.quadLights[l];
            const glm::mat4 M = ql.transform.Eval(options.frameTime);
            RTCGeometry g = rtcNewGeometry(I.device, RTC_GEOMETRY_TYPE_QUAD);
            auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
                g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 4));
            const glm::vec3 c[4] = {ql.corner, ql.corner + ql.edge1,
                                    ql.corner + ql.edge1 + ql.edge2, ql.corner + ql.edge2};
            for (int i = 0; i < 4; ++i) {
                glm::vec3 w = glm::vec3(M * glm::vec4(c[i], 1.0f));
                v[3 * i] = w.x, v[3 * i + 1] = w.y, v[3 * i + 2] = w.z;
            }
            auto* q = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
                g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(unsigned), 1));
            q[0] = 0, q[1] = 1, q[2] = 2, q[3] = 3;
            rtcCommitGeometry(g);
            Impl::Map(I.geomToLight, rtcAttachGeometry(I.top, g), int(l));
            rtcReleaseGeometry(g);
        }
        I.AddSphereLights(scene, options.frameTime);
        if (options.needEnvironment && !scene.environments.empty()) {
            const EnvironmentLight& e = scene.environments.front();
            env_ = e.path.empty() ? std::make_shared<const EnvironmentMap>(
                                        EnvironmentMap::Constant(e.constant * e.intensity))
                                  : EnvironmentMap::Shared(e.path, e.intensity, e.rotationDegrees);
        }
    }
    clock.Charge(&I.build.other);
    rtcCommitScene(I.top);
    clock.Charge(&I.build.embreeBvh);

    if (options.needTextures) {
        // Only textures some object's material references are loaded.
        std::vector<char> texUsed(scene.textures.size(), 0);
        for (const Object& o : scene.objects)
            for (const int m : o.Materials())
                for (const int t : MaterialTextures(scene.materials[size_t(m)]))
                    if (t >= 0) texUsed[size_t(t)] = 1;
        I.textures.resize(scene.textures.size());
        for (size_t t = 0; t < scene.textures.size(); ++t) {
            if (!texUsed[t]) continue;
            try {
                I.textures[t] = std::make_unique<TextureImage>(scene.textures[t]);
            } catch (const InputError& e) {
                // The image's own error names the file; add the scene key that refers to it.
                if (scene.textures[t].where.empty()) throw;
                throw InputError(scene.textures[t].where, e.what());
            }
        }
        CheckPtexFaceCounts(scene, I);
    }
    clock.Charge(&I.build.other);
}

void RenderScene::CheckPtexFaceCounts(const Scene& scene, const Impl& I) {
    // A Ptex file holds one texel grid per Ptex face of the mesh it was painted on: another
    // count means another mesh, whose faces would get unrelated texels (or none).
    for (const Object& o : scene.objects)
        for (const int m : o.Materials())
            for (const int t : MaterialTextures(scene.materials[size_t(m)])) {
                if (t < 0 || !I.textures[size_t(t)]) continue;
                const int faces = I.textures[size_t(t)]->PtexFaces();
                const int meshFaces = I.meshes[size_t(o.mesh)].topo->NumPtexFaces();
                if (faces >= 0 && faces != meshFaces)
                    throw InputError(
                        scene.textures[size_t(t)].where,
                        "'" + scene.textures[size_t(t)].path + "' has " + std::to_string(faces) +
                            " faces, but object '" + o.name + "' (mesh '" + o.objPath + "') has " +
                            std::to_string(meshFaces) + " Ptex faces (a quad is one, an n-gon n)");
            }
}

RenderScene::~RenderScene() = default;

void* RenderScene::EmbreeScene() const {
    return impl_->top;
}

const PtexTopology& RenderScene::Topology(int object) const {
    return *impl_->meshes[impl_->objects[object].mesh].topo;
}

std::shared_ptr<const PtexTopology> RenderScene::SharedTopology(int object) const {
    return impl_->meshes[impl_->objects[object].mesh].topo;
}

size_t RenderScene::MeshBytes() const {
    size_t n = 0;
    for (const auto& m : impl_->meshes) {
        if (!m.topo) continue;
        for (const auto& part : m.irregular) n += part->Bytes();
        n += m.topo->Bytes() + m.regular->Bytes() + m.irregularPart.capacity() +
             m.isHole.capacity() + m.squares.capacity() * sizeof(m.squares[0]) +
             m.cornerUvs.capacity() * sizeof(m.cornerUvs[0]);
    }
    return n;
}

RenderScene::TessellationStats RenderScene::LimitTessellated() const {
    return impl_->tessellation;
}

std::string RenderScene::Describe(const TessellationStats& t) {
    std::string s = std::to_string(t.beyondEmbree) + " cage faces past Embree's limits";
    if (t.meshes > 0)
        s += " (" + std::to_string(t.meshes) + (t.meshes == 1 ? " mesh, " : " meshes, ") +
             std::to_string(t.cageFaces) +
             " cage faces tessellated from OpenSubdiv's limit surface)";
    return s;
}

RenderScene::BuildSeconds RenderScene::BuildTimes() const {
    return impl_->build;
}

size_t RenderScene::EmbreeBytes() const {
    return impl_->embreeMemory.Bytes();
}

size_t RenderScene::EmbreePeakBytes() const {
    return impl_->embreeMemory.PeakBytes();
}

bool RenderScene::StaticBounds(glm::vec3* lo, glm::vec3* hi) const {
    for (const Impl::Instance& inst : impl_->objects)
        if (inst.steps.size() > 1) return false;
    RTCBounds b;
    rtcGetSceneBounds(impl_->top, &b);
    *lo = glm::vec3(b.lower_x, b.lower_y, b.lower_z);
    *hi = glm::vec3(b.upper_x, b.upper_y, b.upper_z);
    return lo->x <= hi->x && lo->y <= hi->y && lo->z <= hi->z &&
           std::isfinite(lo->x + lo->y + lo->z + hi->x + hi->y + hi->z);
}

uint64_t RenderScene::UntracedRays() const {
    return impl_->untraced.load();
}

size_t RenderScene::NumPtexFaces() const {
    size_t n = 0;
    for (const auto& m : impl_->meshes)
        if (m.topo) n += size_t(m.topo->NumPtexFaces());
    return n;
}

glm::mat4 RenderScene::ObjectToWorld(int object, float time) const {
    return impl_->Transform(object, time);
}

static void ToRtcRay(const Ray& ray, RTCRay* r) {
    r->org_x = ray.org.x, r->org_y = ray.org.y, r->org_z = ray.org.z;
    r->dir_x = ray.dir.x, r->dir_y = ray.dir.y, r->dir_z = ray.dir.z;
    r->tnear = ray.tnear;
    r->tfar = ray.tfar;
    r->time = ray.time;
    r->mask = 0xFFFFFFFFu;
    r->id = 0;
    r->flags = 0;
}

bool RenderScene::Intersect(const Ray& ray, Hit* hit) const {
    if (!impl_->Traceable(ray)) return false;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    ToRtcRay(ray, &rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(impl_->top, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
    impl_->ToHit(rh.ray.tfar, rh.hit.geomID, rh.hit.instID[0], rh.hit.primID, rh.hit.u, rh.hit.v,
                 glm::vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z), ray.time, hit);
    return true;
}

void RenderScene::Intersect16(const Ray* rays, int n, Hit* hits, bool* found) const {
    alignas(64) int valid[16];
    alignas(64) RTCRayHit16 rh;
    for (int i = 0; i < 16; ++i) {
        valid[i] = i < n && impl_->Traceable(rays[i]) ? -1 : 0;
        const Ray& r = rays[i < n ? i : 0];  // idle lanes hold a copy, masked off by `valid`
        rh.ray.org_x[i] = r.org.x, rh.ray.org_y[i] = r.org.y, rh.ray.org_z[i] = r.org.z;
        rh.ray.dir_x[i] = r.dir.x, rh.ray.dir_y[i] = r.dir.y, rh.ray.dir_z[i] = r.dir.z;
        rh.ray.tnear[i] = r.tnear, rh.ray.tfar[i] = r.tfar, rh.ray.time[i] = r.time;
        rh.ray.mask[i] = 0xFFFFFFFFu, rh.ray.id[i] = unsigned(i), rh.ray.flags[i] = 0;
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcIntersect16(valid, impl_->top, &ctx, &rh);
    for (int i = 0; i < n; ++i) {
        found[i] = valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
        if (found[i])
            impl_->ToHit(rh.ray.tfar[i], rh.hit.geomID[i], rh.hit.instID[0][i], rh.hit.primID[i],
                         rh.hit.u[i], rh.hit.v[i],
                         glm::vec3(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]), rays[i].time,
                         &hits[i]);
    }
}

bool RenderScene::IntersectObject(int object, const Ray& ray, Hit* hit) const {
    const Impl& I = *impl_;
    if (!I.Traceable(ray)) return false;
    // Static instances keep their inverse: every cached sample's snap ray comes here.
    const glm::mat4 inv = I.objects[object].steps.size() == 1
                              ? I.objects[object].inverse
                              : glm::inverse(I.Transform(object, ray.time));
    Ray local = ray;
    local.org = glm::vec3(inv * glm::vec4(ray.org, 1.0f));
    local.dir = glm::mat3(inv) * ray.dir;  // not normalized: t stays the world-space parameter
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    ToRtcRay(local, &rh.ray);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(I.meshes[I.objects[object].mesh].scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
    hit->t = rh.ray.tfar;
    hit->object = object;
    hit->light = -1;
    hit->primID = rh.hit.primID;
    hit->U = rh.hit.u;
    hit->V = rh.hit.v;
    hit->Ng = I.WorldNormal(object, ray.time, glm::vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z));
    return true;
}

bool RenderScene::Occluded(const Ray& ray) const {
    if (!impl_->Traceable(ray)) return true;  // no light through a ray nobody can trace
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay r;
    ToRtcRay(ray, &r);
    rtcOccluded1(impl_->top, &ctx, &r);
    return r.tfar < 0.0f;
}

namespace {
/// rtcOccluded4/8/16 (`occludedN`) on rays[0, n), n <= N; idle lanes are masked off.
template <int N, typename RayN, typename OccludedN, typename TraceableF>
void OccludedPacket(RTCScene top, const Ray* rays, int n, bool* occluded, OccludedN occludedN,
                    TraceableF&& traceable) {
    alignas(64) int valid[N];
    alignas(64) RayN r;
    for (int i = 0; i < N; ++i) {
        valid[i] = i < n && traceable(rays[i]) ? -1 : 0;
        const Ray& q = rays[i < n ? i : 0];
        r.org_x[i] = q.org.x, r.org_y[i] = q.org.y, r.org_z[i] = q.org.z;
        r.dir_x[i] = q.dir.x, r.dir_y[i] = q.dir.y, r.dir_z[i] = q.dir.z;
        r.tnear[i] = q.tnear, r.tfar[i] = q.tfar, r.time[i] = q.time;
        r.mask[i] = 0xFFFFFFFFu, r.id[i] = unsigned(i), r.flags[i] = 0;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    occludedN(valid, top, &ctx, &r);
    for (int i = 0; i < n; ++i) occluded[i] = !valid[i] || r.tfar[i] < 0.0f;
}
}  // namespace

void RenderScene::Occluded16(const Ray* rays, int n, bool* occluded) const {
    if (n <= 0) return;
    const auto traceable = [this](const Ray& r) { return impl_->Traceable(r); };
    if (n == 1) {
        occluded[0] = Occluded(rays[0]);
    } else if (n <= 4) {
        OccludedPacket<4, RTCRay4>(impl_->top, rays, n, occluded, rtcOccluded4, traceable);
    } else if (n <= 8) {
        OccludedPacket<8, RTCRay8>(impl_->top, rays, n, occluded, rtcOccluded8, traceable);
    } else {
        OccludedPacket<16, RTCRay16>(impl_->top, rays, std::min(n, 16), occluded, rtcOccluded16,
                                     traceable);
    }
}

namespace {
/// Least squares in the tangent basis (X, Y) = (dP/du, dP/dv): the (a, b) with a X + b Y ~= D,
/// from the normal equations of the 3x2 system. Their matrix is the basis's alone, so it is
/// formed once per hit for both pixel steps.
class TangentSolver {
public:
    TangentSolver(glm::vec3 X, glm::vec3 Y)
        : X_(X), Y_(Y), xx_(glm::dot(X, X)), xy_(glm::dot(X, Y)), yy_(glm::dot(Y, Y)) {
        det_ = xx_ * yy_ - xy_ * xy_;
        ok_ = std::abs(det_) > 1e-20f * xx_ * yy_ && std::isfinite(det_);
    }
    void Solve(glm::vec3 D, float* a, float* b) const {
        if (!ok_) {
            *a = *b = 0.0f;
            return;
        }
        const float dx = glm::dot(D, X_), dy = glm::dot(D, Y_);
        *a = (yy_ * dx - xy_ * dy) / det_;
        *b = (xx_ * dy - xy_ * dx) / det_;
    }

private:
    glm::vec3 X_, Y_;
    float xx_, xy_, yy_, det_;
    bool ok_;
};
}  // namespace

SurfaceInteraction RenderScene::Interact(const Ray& ray, const Hit& hit,
                                         const RayDifferentials* diff) const {
    const Impl& I = *impl_;
    const Impl::Mesh& mesh = I.meshes[I.objects[hit.object].mesh];
    SurfaceInteraction si;
    si.object = hit.object;
    si.P = ray.org + hit.t * ray.dir;

    si.ptex = mesh.ToPtex(hit.primID, hit.U, hit.V);
    si.material = scene_.objects[hit.object].MaterialOfFace(mesh.topo->CoarseFace(si.ptex.face));
    // Only the derivatives: the hit point itself comes from the ray (tessellated surface).
    alignas(16) float du[4] = {0, 0, 0, 0}, dv[4] = {0, 0, 0, 0};
    mesh.Eval(si.ptex, hit.primID, hit.U, hit.V, nullptr, du, dv);
    const glm::mat3 L = I.Linear(hit.object, ray.time);
    si.dPdu = L * glm::vec3(du[0], du[1], du[2]);
    si.dPdv = L * glm::vec3(dv[0], dv[1], dv[2]);

    si.Ng = glm::normalize(hit.Ng);
    if (glm::dot(si.Ng, ray.dir) > 0.0f) si.Ng = -si.Ng;
    glm::vec3 n = glm::cross(si.dPdu, si.dPdv);
    const float len = glm::length(n);
    // Limit derivatives can be parallel at a few extraordinary points: fall back to Ng there.
    si.N = len > 1e-12f && std::isfinite(len) ? n / len : si.Ng;
    si.backFacing = glm::dot(si.N, si.Ng) < 0.0f;
    if (si.backFacing) si.N = -si.N;

    si.uv = mesh.hasUv ? mesh.Uv(hit.primID, hit.U, hit.V) : glm::vec2(si.ptex.u, si.ptex.v);

    if (diff) {
        // Igehy: move the offset rays to the tangent plane at the hit, then express the offsets
        // in the (dP/du, dP/dv) basis.
        const float d = glm::dot(si.N, si.P);
        auto planeOffset = [&](glm::vec3 dO, glm::vec3 dD) {
            const glm::vec3 o = ray.org + dO, dir = ray.dir + dD;
            const float denom = glm::dot(si.N, dir);
            if (std::abs(denom) < 1e-12f) return glm::vec3(0.0f);
            const float t = (d - glm::dot(si.N, o)) / denom;
            return o + t * dir - si.P;
        };
        glm::vec3 dPdx = planeOffset(diff->dOdx, diff->dDdx);
        glm::vec3 dPdy = planeOffset(diff->dOdy, diff->dDdy);
        // Defocus: the camera samples of a pixel reach the surface anywhere in the circle of
        // confusion, and the image averages them over it; a footprint narrower than its radius
        // picked texels finer than the image shows (a pixel's differential is taken with the
        // lens point fixed). The footprint is widened to the circle's radius: texels the size
        // of the blur come near the best error at equal time for hardly any bias (wider
        // footprints save a little more time, at the price of bias).
        if (diff->lensRadius > 0.0f && diff->focusT > 0.0f) {
            const float coc = diff->lensRadius * std::abs(1.0f - hit.t / diff->focusT);
            auto widen = [&](glm::vec3& d) {
                const float l = glm::length(d);
                if (l > 0.0f && l < coc) d *= coc / l;
            };
            widen(dPdx), widen(dPdy);
        }
        const TangentSolver tangent(si.dPdu, si.dPdv);
        tangent.Solve(dPdx, &si.dudx, &si.dvdx);
        tangent.Solve(dPdy, &si.dudy, &si.dvdy);
    }
    return si;
}

std::vector<glm::vec3> RenderScene::QuadCorners(int object) const {
    const Impl& I = *impl_;
    const Impl::Mesh& mesh = I.meshes[size_t(I.objects[size_t(object)].mesh)];
    std::vector<glm::vec3> corners;
    if (!mesh.plain && !mesh.tessellated) return corners;
    const auto* v =
        static_cast<const float*>(rtcGetGeometryBufferData(mesh.geom, RTC_BUFFER_TYPE_VERTEX, 0));
    const auto* idx =
        static_cast<const unsigned*>(rtcGetGeometryBufferData(mesh.geom, RTC_BUFFER_TYPE_INDEX, 0));
    const size_t quads = mesh.plain ? size_t(mesh.topo->NumPtexFaces()) : mesh.squares.size();
    const glm::mat4 M = I.Transform(object, 0.0f);
    corners.reserve(4 * quads);
    for (size_t i = 0; i < 4 * quads; ++i) {
        const float* p = v + 4 * size_t(idx[i]);
        corners.emplace_back(M * glm::vec4(p[0], p[1], p[2], 1.0f));
    }
    return corners;
}

PtexCoord RenderScene::HitPtex(const Hit& hit) const {
    return impl_->meshes[impl_->objects[hit.object].mesh].ToPtex(hit.primID, hit.U, hit.V);
}

bool RenderScene::EvalSurface(int object, const PtexCoord& c, float time,
                              SurfaceSample* out) const {
    const Impl& I = *impl_;
    const Impl::Mesh& mesh = I.meshes[I.objects[object].mesh];
    if (c.face < 0 || c.face >= mesh.topo->NumPtexFaces()) return false;
    unsigned prim = 0;
    float U = c.u, V = c.v;
    if (!mesh.tessellated && !mesh.plain) PtexToEmbree(*mesh.topo, c, &prim, &U, &V);
    alignas(16) float P[4], du[4], dv[4];
    if (!mesh.Eval(c, prim, U, V, P, du, dv)) return false;
    const glm::mat4 M = I.Transform(object, time);
    const glm::mat3 L(M);
    out->P = glm::vec3(M * glm::vec4(P[0], P[1], P[2], 1.0f));
    out->dPdu = L * glm::vec3(du[0], du[1], du[2]);
    out->dPdv = L * glm::vec3(dv[0], dv[1], dv[2]);
    const glm::vec3 n = glm::cross(out->dPdu, out->dPdv);
    const float len = glm::length(n);
    out->N = len > 1e-12f && std::isfinite(len) ? n / len : glm::vec3(0.0f, 1.0f, 0.0f);
    return true;
}

namespace {
/// A shading point's texture lookup: Ptex filter width from its footprint (the larger extent
/// of a pixel in u or v; 0 without differentials).
TextureQuery QueryOf(const SurfaceInteraction& si) {
    const float w =
        std::max({std::abs(si.dudx), std::abs(si.dudy), std::abs(si.dvdx), std::abs(si.dvdy)});
    return {si.uv, si.ptex.face, si.ptex.u, si.ptex.v, std::isfinite(w) ? w : 0.0f};
}
}  // namespace

glm::vec3 RenderScene::ColorAt(const ColorParam& p, const TextureQuery& q) const {
    if (p.texture >= 0 && impl_->textures[size_t(p.texture)])
        return impl_->textures[size_t(p.texture)]->Color(q);
    return p.value;
}

glm::vec3 RenderScene::Albedo(const SurfaceInteraction& si) const {
    // Clamped: a float texture above 1 would create energy.
    return glm::clamp(ColorAt(scene_.materials[si.material].albedo, QueryOf(si)), 0.0f, 1.0f);
}

glm::vec3 RenderScene::Specular(const SurfaceInteraction& si) const {
    return glm::clamp(ColorAt(scene_.materials[si.material].specular, QueryOf(si)), 0.0f, 1.0f);
}

float RenderScene::Roughness(const SurfaceInteraction& si) const {
    const FloatParam& r = scene_.materials[si.material].roughness;
    if (r.texture >= 0 && impl_->textures[size_t(r.texture)])
        return glm::clamp(impl_->textures[size_t(r.texture)]->Scalar(QueryOf(si)), 0.0f, 1.0f);
    return r.value;
}

glm::vec3 RenderScene::Emission(const Hit& hit) const {
    if (hit.object < 0) return glm::vec3(0.0f);
    const Impl::Mesh& mesh = impl_->meshes[size_t(impl_->objects[size_t(hit.object)].mesh)];
    const PtexCoord c = mesh.ToPtex(hit.primID, hit.U, hit.V);
    const Object& o = scene_.objects[size_t(hit.object)];
    const ColorParam& e =
        scene_.materials[size_t(o.MaterialOfFace(mesh.topo->CoarseFace(c.face)))].emission;
    if (e.texture < 0) return e.value;
    const glm::vec2 uv = mesh.hasUv ? mesh.Uv(hit.primID, hit.U, hit.V) : glm::vec2(c.u, c.v);
    return glm::max(ColorAt(e, {uv, c.face, c.u, c.v, 0.0f}), glm::vec3(0.0f));
}

glm::vec3 RenderScene::AlbedoAt(int object, const PtexCoord& c, float width) const {
    const Object& o = scene_.objects[size_t(object)];
    const Impl::Mesh& mesh = impl_->meshes[size_t(impl_->objects[size_t(object)].mesh)];
    const Material& m = scene_.materials[size_t(o.MaterialOfFace(mesh.topo->CoarseFace(c.face)))];
    // A Ptex location carries no cage uv: image textures read at the Ptex (u,v) here, as on
    // cages without uvs.
    return glm::clamp(ColorAt(m.albedo, {glm::vec2(c.u, c.v), c.face, c.u, c.v, width}), 0.0f,
                      1.0f);
}

bool RenderScene::PtexTextured() const {
    for (const auto& t : impl_->textures)
        if (t && t->PtexFaces() >= 0) return true;
    return false;
}

bool RenderScene::Emissive() const {
    for (const Object& o : scene_.objects)
        for (const int m : o.Materials()) {
            const ColorParam& e = scene_.materials[size_t(m)].emission;
            if (e.texture >= 0 || e.value != glm::vec3(0.0f)) return true;
        }
    return false;
}

}  // namespace texcache
