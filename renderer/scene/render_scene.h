// SPDX-License-Identifier: Apache-2.0
// The ray-traceable form of a Scene: Embree subdivision geometry per mesh (object space; quads for
// plain meshes), one instance per object, quad and sphere light geometry, the environment and
// textures — each built only when the render uses it.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/scene/scene.h"
#include "renderer/texture_space/ptex_mapping.h"

namespace texcache {

class EnvironmentMap;
class TextureImage;
struct TextureQuery;

struct Ray {
    glm::vec3 org, dir;
    float tnear = 0.0f, tfar = 1e30f;
    float time = 0.0f;  ///< normalized shutter time in [0,1]
};

/// Ray differentials (Igehy 1999): origin and direction derivatives per pixel step in x and y.
struct RayDifferentials {
    glm::vec3 dOdx{0.0f}, dOdy{0.0f}, dDdx{0.0f}, dDdy{0.0f};
    /// Thin lens (0 for a pinhole): the lens radius, and the distance along the ray to the
    /// plane in focus. A hit at distance t is blurred over a circle of radius
    /// lensRadius |1 - t / focusT| (RenderScene::Interact widens the footprint to it).
    float lensRadius = 0.0f, focusT = 0.0f;
};

/// What a ray hit, before shading.
struct Hit {
    float t = 0.0f;
    int object = -1;  ///< index into Scene::objects, -1 for lights
    /// When a light was hit: an index into Scene::quadLights, or past them, the quad lights'
    /// count plus an index into Scene::pointLights (a sphere).
    int light = -1;
    unsigned primID = 0;
    float U = 0.0f, V = 0.0f;  ///< Embree's hit parameters (encoded on n-gons)
    glm::vec3 Ng{0.0f};        ///< world-space geometric normal of the tessellated surface
};

/// A shading point: everything the integrators and the cache need.
struct SurfaceInteraction {
    glm::vec3 P;           ///< hit point on the tessellated surface (spawn rays from here)
    glm::vec3 Ng;          ///< geometric normal, facing the incoming ray
    glm::vec3 N;           ///< limit-surface shading normal, facing the incoming ray
    glm::vec3 dPdu, dPdv;  ///< world-space limit derivatives in Ptex (u,v)
    PtexCoord ptex;
    glm::vec2 uv;  ///< texture coordinates (face-varying OBJ uvs, else Ptex (u,v))
    float dudx = 0, dudy = 0, dvdx = 0, dvdy = 0;  ///< Ptex-space footprint of a pixel
    int object = -1;
    int material = 0;
    bool backFacing = false;  ///< the ray sees the side opposite to cross(dPdu, dPdv)
};

/// A limit-surface sample at a Ptex location (the cache's surface query).
struct SurfaceSample {
    glm::vec3 P, N, dPdu, dPdv;  ///< world space at the queried time
};

struct RenderSceneOptions {
    float frameTime = 0.0f;    ///< scene time of shutter open
    bool needLights = true;    ///< build light geometry / env map
    bool needTextures = true;  ///< load textures and face-varying uvs
    bool needEnvironment = true;
    int threads = 0;  ///< Embree build threads (0 = all)
    /// Trace every mesh as quads on its limit surface (OpenSubdiv's uniform tessellation at the
    /// tessellation rate, embree_mesh.cpp), not only the meshes Embree cannot take. The surface
    /// of Embree's grids at a power-of-two rate, except where Embree approximates the limit
    /// (fractional and infinite creases, some extraordinary vertices: there the quads follow
    /// OpenSubdiv); its rays cost less on cages with many irregular faces (results/preview.md,
    /// "Limit quads"), for about twice the memory of Embree's on a huge cage. The preview's
    /// default where the quads fit (preview::LimitQuadsFit); `texcache render --geometry quads`.
    bool tessellateAll = false;
    /// Limit derivatives (shading normals, the cache's surface queries) of the faces off the
    /// regular fast path from OpenSubdiv's patches; false: from rtcInterpolate, Embree's own
    /// (to compare the two).
    bool irregularPatches = true;
};

/// Embree device + scene for one frame of a Scene. Thread-safe for queries after construction.
class RenderScene {
public:
    /// Builds everything the options ask for; throws InputError on bad input files.
    RenderScene(const Scene& scene, const RenderSceneOptions& options);
    ~RenderScene();
    RenderScene(const RenderScene&) = delete;
    RenderScene& operator=(const RenderScene&) = delete;

    /// Closest hit; false on a miss.
    bool Intersect(const Ray& ray, Hit* hit) const;
    /// Intersect() for up to 16 rays at once (`found[i]` for rays[i]), through Embree's packet
    /// traversal (rtcIntersect16) hinted coherent: for rays that start together and travel
    /// alike, such as a tile's camera rays, which then share most of their BVH nodes. The hits
    /// agree with Intersect() (tests/render_test.cpp checks it on the bundled cages).
    void Intersect16(const Ray* rays, int n, Hit* hits, bool* found) const;
    /// True when anything blocks the segment (tnear, tfar) along the ray.
    bool Occluded(const Ray& ray) const;
    /// Occluded() for up to 16 rays at once (`occluded[i]` for rays[i]), through Embree's packet
    /// traversal (rtcOccluded4/8/16, the narrowest that holds n): for rays that leave one point,
    /// such as a shading point's AO rays, which then share the BVH nodes near it.
    void Occluded16(const Ray* rays, int n, bool* occluded) const;
    /// Closest hit along a world-space ray against one object only (other objects are ignored);
    /// false on a miss.
    bool IntersectObject(int object, const Ray& ray, Hit* hit) const;
    /// Rays the queries above did not hand to Embree, which asserts on them (a NaN, an origin
    /// beyond its range in some object's space, a negative tnear): they missed and were
    /// occluded instead. None in a scene that passed CheckSceneReach (scene_units.h); a count
    /// here is a bug to report.
    uint64_t UntracedRays() const;
    /// Shading data at a hit (limit normal, derivatives, Ptex coordinates, uvs); the footprint
    /// fields are filled when `diff` is given.
    SurfaceInteraction Interact(const Ray& ray, const Hit& hit,
                                const RayDifferentials* diff = nullptr) const;
    /// The corners (4 per Embree quad, in primitive order) of an object rendered as quads (a
    /// plain mesh, a limit tessellation), in world space at the frame time; empty for an object
    /// that is Embree's subdivision surface. Emissive objects are sampled on these.
    std::vector<glm::vec3> QuadCorners(int object) const;
    /// Ptex location of a hit on an object (the Embree primitive's mapping of its mesh).
    PtexCoord HitPtex(const Hit& hit) const;
    /// Limit surface at (ptex face, u, v) of an object at normalized shutter time `time`.
    bool EvalSurface(int object, const PtexCoord& c, float time, SurfaceSample* out) const;

    const Scene& scene() const { return scene_; }
    const PtexTopology& Topology(int object) const;
    /// The same topology, for a texture-space cache to share rather than build again.
    std::shared_ptr<const PtexTopology> SharedTopology(int object) const;
    /// Bytes of our own per-mesh data (Ptex topology, regular patches, limit tessellation), not
    /// counting Embree's.
    size_t MeshBytes() const;
    /// Bytes Embree holds (geometry buffers, subdivision topology, tessellation, BVH), and the
    /// most it held while building.
    size_t EmbreeBytes() const;
    size_t EmbreePeakBytes() const;
    const EnvironmentMap* environment() const { return env_.get(); }
    /// Albedo at a shading point (constant or texture), in [0,1]. Ptex textures are filtered
    /// over the point's footprint (its ray differentials; the finest level without them).
    glm::vec3 Albedo(const SurfaceInteraction& si) const;
    /// Roughness at a shading point (constant, texture luminance or a Ptex channel), in [0,1].
    float Roughness(const SurfaceInteraction& si) const;
    /// GGX F0 at a shading point (constant or texture), in [0,1].
    glm::vec3 Specular(const SurfaceInteraction& si) const;
    /// Radiance a hit surface emits (its material's emission, both sides; 0 for lights).
    glm::vec3 Emission(const Hit& hit) const;
    /// Whether any object's material emits (Emission is then worth asking).
    bool Emissive() const;
    /// Whether any object's material reads a Ptex texture (filtered by the hits' footprints).
    bool PtexTextured() const;
    /// Albedo of an object at a Ptex location, Ptex textures filtered over `width` (in the
    /// face's parameter units): a texel's albedo in texture space.
    glm::vec3 AlbedoAt(int object, const PtexCoord& c, float width) const;
    /// Object-to-world transform at normalized shutter time.
    glm::mat4 ObjectToWorld(int object, float time) const;
    /// Embree scene handle (for raw-throughput benchmarks).
    void* EmbreeScene() const;
    /// Number of Ptex faces over the meshes the scene uses.
    size_t NumPtexFaces() const;
    /// World-space box of everything a ray can hit at the frame time (objects and quad
    /// lights); false when the scene has nothing to hit or moves over the shutter (motion blur).
    bool StaticBounds(glm::vec3* lo, glm::vec3* hi) const;

    /// The meshes whose limit surface OpenSubdiv tessellated because Embree cannot take them.
    struct TessellationStats {
        int meshes = 0;        ///< meshes tessellated
        size_t cageFaces = 0;  ///< their cage faces
        /// Of which past Embree's limits: 16+ vertices, or a vertex with over 64 edges or over
        /// 128 vertices in its 1-ring.
        size_t beyondEmbree = 0;
    };
    TessellationStats LimitTessellated() const;
    /// The statistics in words, e.g. "2 cage faces past Embree's limits (1 mesh, 18 cage faces
    /// tessellated from OpenSubdiv's limit surface)" (what `texcache render` and the preview say).
    static std::string Describe(const TessellationStats& t);

    /// Wall-clock seconds of each stage of the construction (where a scene build's time goes).
    struct BuildSeconds {
        double opensubdiv = 0.0;      ///< Ptex topology, regular patches, limit tessellation
        double embreeGeometry = 0.0;  ///< filling and committing Embree's geometry buffers
        double embreeBvh = 0.0;       ///< rtcCommitScene: Embree's tessellation and BVH build
        double other = 0.0;           ///< Embree device, lights, environment, textures
    };
    BuildSeconds BuildTimes() const;

private:
    struct Impl;
    /// Throws InputError when a Ptex texture's face count differs from its object's mesh's.
    static void CheckPtexFaceCounts(const Scene& scene, const Impl& I);
    glm::vec3 ColorAt(const ColorParam& p, const TextureQuery& q) const;

    const Scene& scene_;
    std::unique_ptr<Impl> impl_;
    std::shared_ptr<const EnvironmentMap> env_;  // shared by the scenes of an animation's frames
};

}  // namespace texcache
