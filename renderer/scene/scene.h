// SPDX-License-Identifier: Apache-2.0
// The in-memory scene description: what a scene file (JSON) or a bare OBJ turns into. Plain data;
// the Embree scene, light distributions and textures are built from it on demand (only what the
// render actually uses).
#pragma once
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "renderer/integrators/integrator_kind.h"
#include "texcache/cage.h"

namespace texcache {

/// A rigid pose (plus a static scale) at a time.
struct Keyframe {
    float time = 0.0f;
    glm::vec3 translation{0.0f};
    glm::quat rotation{1.0f, 0.0f, 0.0f, 0.0f};  // w, x, y, z
    glm::vec3 scale{1.0f};
};

/// Keyframed rigid transform: linear translation, slerped rotation, clamped outside the key range.
struct TransformTrack {
    std::vector<Keyframe> keys;  ///< sorted by time; empty = identity

    glm::mat4 Eval(float time) const;
    bool IsAnimated() const;  ///< more than one distinct pose
    /// Whether the pose at time `b` differs from the one at time `a`.
    bool MovesBetween(float a, float b) const { return IsAnimated() && Eval(a) != Eval(b); }
};

struct Camera {
    // Pose keys: the camera looks down -Z of its local frame, +Y up (built from position/look-at/up
    // by the loader).
    TransformTrack pose;
    float fovYDegrees = 40.0f;
    float lensRadius = 0.0f;     ///< 0 = pinhole
    float focusDistance = 1.0f;  ///< used when lensRadius > 0
    float shutterOpen = 0.0f;    ///< times in the same units as keyframes (seconds)
    float shutterClose = 0.0f;   ///< == shutterOpen: no motion blur
    /// Stereo rig ("stereo": {"eye_separation", "convergence"}; renderer/texture_space/stereo.h):
    /// the eyes sit eyeSeparation apart along the camera's x axis, looking parallel, their frustums
    /// sheared so that the plane at `convergence` has zero parallax. Used by stereo renders only.
    float eyeSeparation = 0.0f;
    float convergence = 0.0f;  ///< 0: not given (the distance to the look-at point)
};

/// A texture: an image file (sRGB-decoded for colours) or a procedural checker, looked up by
/// the cage's face-varying uvs when it has them, else by the Ptex face (u,v); or a Ptex file,
/// one texel grid per Ptex face of the mesh, looked up at the hit's Ptex face and (u,v).
struct Texture {
    enum class Kind { Image, Checker, Ptex } kind = Kind::Checker;
    std::string path;                      ///< Image, Ptex
    glm::vec3 colorA{0.8f}, colorB{0.2f};  ///< Checker
    float scale = 8.0f;                    ///< Checker: squares per uv unit
    /// Ptex: the file's channel a scalar reads, or a colour's first (a colour reads three; from a
    /// file with one channel left from there, that one as grey).
    int channel = 0;
    /// Ptex: the texels are sRGB-encoded (as 8-bit paint often is; Ptex records no colour
    /// space): filtered values are decoded to linear light.
    bool srgb = false;
    /// Where the scene file names it ("scene.json: key 'materials.m.albedo.texture'"), for
    /// errors found when the image is read; empty for textures made in code.
    std::string where;
};

/// A colour or scalar that is either a constant or a texture index.
struct ColorParam {
    glm::vec3 value{0.8f};
    int texture = -1;
};
struct FloatParam {
    float value = 0.5f;
    int texture = -1;  ///< uses the texture's luminance
};

struct Material {
    std::string name;
    enum class Type { Diffuse, GGX } type = Type::Diffuse;
    ColorParam albedo;     ///< diffuse albedo (Diffuse), or diffuse base under the coat (GGX)
    FloatParam roughness;  ///< GGX alpha = roughness^2 (along the Ptex u direction)
    /// "roughness": [ru, rv] (brushed metal): roughness across the Ptex u direction; the
    /// tangent of the anisotropic lobe is the limit surface's dP/du.
    bool anisotropic = false;
    float roughnessV = 0.5f;
    ColorParam specular{glm::vec3(0.04f)};  ///< GGX Schlick F0
    /// Radiance the surface emits, on both sides: seen by camera and BSDF rays (never sampled as
    /// a light), e.g. baked shading (`texcache bake`) shown as it was baked.
    ColorParam emission{glm::vec3(0.0f)};
    /// Texture-space filter of this material's cached term ("" = the render's default).
    std::string cacheFilter;
    int cacheRadius = -1;  ///< footprint radius override (-1 = the render's default)
};

struct Object {
    std::string name;
    std::string objPath;  ///< absolute, resolved by the loader
    int mesh = -1;        ///< index into Scene::meshes (meshes may be shared)
    int material = 0;     ///< every face's, unless faceMaterials says otherwise
    /// Per cage face (OBJ usemtl), empty: `material` everywhere.
    std::vector<int> faceMaterials;
    TransformTrack transform;
    /// false ("subdivision": "none"): the cage's polygons are rendered as they are, flat (a
    /// plain mesh), each Ptex (sub-)face one Embree quad. Objects that share a mesh share this.
    bool subdivide = true;
    /// Radiance emitted from the surface (after the scene file's scale); any non-zero value makes
    /// the object a light, sampled by area (renderer/scene/lights.h).
    glm::vec3 emission{0.0f};
    /// Emits on both sides; otherwise on the side the faces' winding (counter-clockwise seen from
    /// outside) points to.
    bool emissionTwoSided = false;

    bool Emissive() const { return emission != glm::vec3(0.0f); }

    /// The material of cage face `coarseFace`.
    int MaterialOfFace(int coarseFace) const {
        return faceMaterials.empty() ? material : faceMaterials[size_t(coarseFace)];
    }
    /// Every material the object uses, each once, `material` first.
    std::vector<int> Materials() const;
};

struct EnvironmentLight {
    std::string path;  ///< lat-long image, width == 2 * height
    float intensity = 1.0f;
    float rotationDegrees = 0.0f;  ///< about the world up (+Y) axis
    glm::vec3 constant{0.0f};      ///< used when path is empty (e.g. white furnace)
};

struct QuadLight {
    // A parallelogram corner + edge1 + edge2 in the light's local frame, emitting on the side of
    // cross(edge1, edge2) (both sides when twoSided).
    glm::vec3 corner{0.0f}, edge1{1.0f, 0.0f, 0.0f}, edge2{0.0f, 0.0f, 1.0f};
    glm::vec3 radiance{1.0f};
    bool twoSided = false;
    TransformTrack transform;
};

struct DistantLight {
    glm::vec3 direction{0.0f, -1.0f, 0.0f};  ///< direction the light travels (towards the scene)
    glm::vec3 irradiance{1.0f};              ///< on a surface facing the light
    /// Angular diameter in degrees (the sun: 0.53): a disc of uniform radiance, sampled by its
    /// cone; 0 = a delta light.
    float angleDegrees = 0.0f;
    TransformTrack transform;
};

/// A point light ("point") or a spot light ("spot"): a sphere of uniform radiance
/// intensity / (pi radius^2), or a delta light when the radius is 0.
struct PointLight {
    glm::vec3 position{0.0f};   ///< in the light's frame (transform)
    glm::vec3 intensity{1.0f};  ///< W/sr (on the axis for a spot): irradiance I cos / d^2
    float radius = 0.0f;
    bool spot = false;
    glm::vec3 direction{0.0f, -1.0f, 0.0f};  ///< spot: the axis it shines along (normalised)
    /// Spot: half-angles in degrees; full intensity inside `innerDegrees`, none outside
    /// `outerDegrees`, a smoothstep in cos between.
    float innerDegrees = 25.0f, outerDegrees = 30.0f;
    TransformTrack transform;
};

struct RenderSettings {
    int width = 640, height = 360;
    int spp = 16;
    float seconds = 0.0f;  ///< > 0: time budget, spp becomes a cap
    IntegratorKind integrator = IntegratorKind::Path;
    int maxDepth = 5;
    uint64_t seed = 0;
    float tessellationRate = 2.0f;
    int aoSamples = 1;         ///< AO rays per camera sample
    float aoDistance = 1e30f;  ///< AO max distance (world units)
    float time = 0.0f;         ///< frame time (start of the shutter)
};

struct Scene {
    std::string path;  ///< file it came from (for messages)
    Camera camera;
    std::vector<ControlCage> meshes;
    std::vector<Object> objects;
    std::vector<Material> materials;
    std::vector<Texture> textures;
    std::vector<EnvironmentLight> environments;  ///< at most one is used
    std::vector<QuadLight> quadLights;
    std::vector<DistantLight> distantLights;
    std::vector<PointLight> pointLights;  ///< point and spot lights
    RenderSettings settings;
    /// Render units (renderer/scene/scene_units.h): positions here are the file's minus
    /// unitOrigin, times unitScale; the identity for scenes of ordinary size near the origin.
    glm::dvec3 unitOrigin{0.0};
    double unitScale = 1.0;

    /// Whether an object or a light (quad, distant, point or spot) has another pose at time `b`
    /// than at time `a`: the light falling on the scene's surfaces may differ between the two.
    /// The environment and the camera do not count (the map does not move; the camera changes
    /// what is seen, not the light on it).
    bool MovesBetween(float a, float b) const;
};

}  // namespace texcache
