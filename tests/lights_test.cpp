// SPDX-License-Identifier: Apache-2.0
// Point, spot, sphere, sun and emissive-object lights (renderer/scene/lights.h) against analytic
// answers: a point light's irradiance on a plane falls as I cos / d^2, a sphere light gives the
// same, a spot's cone and falloff, the sun's E cos, and an emissive enclosure around a diffuse
// object (a furnace: every point sees the emission in every direction) gives albedo x radiance,
// per hit and in texture space. Per-hit and texture-space renders of a scene lit by every kind
// converge to the same image.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "renderer/image/metrics.h"
#include "renderer/integrators/path_tracer.h"
#include "renderer/integrators/sampling.h"
#include "renderer/render.h"
#include "renderer/scene/camera.h"
#include "renderer/scene/lights.h"
#include "test_util.h"
#include "testing/cages.h"

namespace texcache {
namespace {

constexpr float kAlbedo = 0.5f;

RenderOptions Options(IntegratorKind k, int spp, int width = 48, int height = 32) {
    RenderOptions o;
    o.integrator = k;
    o.width = width;
    o.height = height;
    o.spp = spp;
    o.progress = false;
    return o;
}

/// A plain (flat) plane of half-size 4 at y = 0, albedo 0.5, seen from above at a slant.
Scene PlaneScene() {
    Scene s = test::OneObjectScene(test::PlaneCage(4.0f), glm::vec3(kAlbedo));
    s.objects[0].subdivide = false;
    s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 1.5f}, {0, 0, 0})};
    s.camera.fovYDegrees = 50.0f;
    return s;
}

/// Per pixel of `img`, the mean of `f` (radiance at a point of the y = 0 plane) over an 8x8 grid
/// of the pixel's film positions, where the render's jittered samples fall; NaN where part of
/// the pixel misses the plane or sees the sphere of radius `r` about `c` (a light) first.
Image ExpectedOnPlane(const Scene& s, int W, int H, float (*f)(glm::vec3, const void*),
                      const void* arg, glm::vec3 c = glm::vec3(0.0f), float r = 0.0f) {
    const CameraModel cam(s.camera, 0.0f, W, H);
    Image img(W, H, 1);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            double sum = 0.0;
            for (int j = 0; j < 64; ++j) {
                const Ray ray =
                    cam.Generate(float(x) + (float(j % 8) + 0.5f) / 8.0f,
                                 float(y) + (float(j / 8) + 0.5f) / 8.0f, glm::vec2(0.5f), nullptr);
                const float t = -ray.org.y / ray.dir.y;
                const glm::vec3 p = ray.org + t * ray.dir;
                // The sphere in the way: |o + s d - c| <= r for some s (its closest approach).
                const glm::vec3 oc = c - ray.org;
                const float along = glm::dot(oc, ray.dir);
                const bool sphere = r > 0.0f && glm::dot(oc, oc) - along * along <= r * r;
                sum += t > 0.0f && std::abs(p.x) < 4.0f && std::abs(p.z) < 4.0f && !sphere
                           ? f(p, arg)
                           : NAN;
            }
            img.data[size_t(y) * W + x] = float(sum / 64.0);
        }
    return img;
}

/// Radiance of the plane under a point light of intensity I (grey) at `pos`, with the spot's
/// falloff `spot` (null: a point light): albedo / pi * I falloff cos / d^2.
struct PointArgs {
    glm::vec3 pos;
    float I;
    const internal::SphereLight* spot;
};
float PointRadiance(glm::vec3 p, const void* arg) {
    const auto& a = *static_cast<const PointArgs*>(arg);
    const glm::vec3 d = a.pos - p;
    const float d2 = glm::dot(d, d);
    const glm::vec3 wi = d / std::sqrt(d2);
    const float falloff = a.spot ? a.spot->Falloff(-wi) : 1.0f;
    return kAlbedo / kPiF * a.I * falloff * std::max(wi.y, 0.0f) / d2;
}

/// Checks the image's first channel against `expected` pixel by pixel (NaN: unchecked): within
/// `relTol` relative, or `absTol` times the largest expectation where that is larger.
void ExpectClose(const Image& img, const Image& expected, float relTol, float absTol,
                 const char* what) {
    float peak = 0.0f;
    for (float v : expected.data)
        if (std::isfinite(v)) peak = std::max(peak, v);
    int checked = 0;
    float worst = 0.0f;
    for (size_t p = 0; p < expected.data.size(); ++p) {
        const float e = expected.data[p];
        if (!std::isfinite(e)) continue;
        const float v = img.data[3 * p];
        const float err = std::abs(v - e) / std::max(e, absTol * peak / relTol);
        worst = std::max(worst, err);
        ++checked;
        ASSERT_LE(err, relTol) << what << ": pixel " << p << " is " << v << ", expected " << e;
    }
    std::printf("%s: %d pixels, largest relative error %.4f\n", what, checked, worst);
    EXPECT_GT(checked, int(expected.data.size() / 2));
}

// A delta point light over a plane: L = albedo / pi * I cos / d^2 at every pixel. One light
// sample per pixel and no occluder: the only error is the pixel footprint's, over which the
// light changes by up to ~20% (the expectation is averaged over 64 film positions, the render
// over 256 jittered samples): within 2%. The same in
// texture space (hit-binned, direct light of a delta light per hit: the same image but for the
// binned indirect part, none here: the plane sees nothing).
TEST(Lights, PointLightFallsAsCosOverDistanceSquared) {
    Scene s = PlaneScene();
    PointLight l;
    l.position = {0.7f, 1.2f, -0.4f};
    l.intensity = glm::vec3(3.0f);
    s.pointLights.push_back(l);
    const RenderScene rs(s, {});
    const PointArgs args{l.position, 3.0f, nullptr};
    const Image expected = ExpectedOnPlane(s, 48, 32, PointRadiance, &args);
    ExpectClose(Render(rs, Options(IntegratorKind::Direct, 256)).beauty, expected, 0.02f, 0.002f,
                "point, direct");
    RenderOptions ts = Options(IntegratorKind::Path, 256);
    ts.maxDepth = 2;
    ts.texture.enabled = true;
    ts.texture.samples = TextureSamples::Hits;
    ts.texture.cacheDirect = true;
    ts.texture.deltaDirectPerHit = true;
    ExpectClose(Render(rs, ts).beauty, expected, 0.02f, 0.002f, "point, texture space");
}

// A sphere light of the same intensity: a Lambertian sphere lights a plane wholly above it as a
// point of its intensity at its centre does (I cos / d^2 exactly), so the same image, now with
// the noise of cone sampling (256 samples a pixel, MIS with the BSDF's rays that hit the
// sphere): within 5% per pixel, the mean within 1%.
TEST(Lights, SphereLightGivesThePointLightsIrradiance) {
    Scene s = PlaneScene();
    PointLight l;
    l.position = {0.7f, 1.2f, -0.4f};
    l.intensity = glm::vec3(3.0f);
    l.radius = 0.3f;
    s.pointLights.push_back(l);
    const RenderScene rs(s, {});
    const PointArgs args{l.position, 3.0f, nullptr};
    const Image expected = ExpectedOnPlane(s, 48, 32, PointRadiance, &args, l.position, l.radius);
    const Image img = Render(rs, Options(IntegratorKind::Direct, 256)).beauty;
    ExpectClose(img, expected, 0.05f, 0.005f, "sphere, direct");
    double a = 0.0, b = 0.0;
    for (size_t p = 0; p < expected.data.size(); ++p)
        if (std::isfinite(expected.data[p])) a += img.data[3 * p], b += expected.data[p];
    EXPECT_NEAR(a / b, 1.0, 0.01);
}

// A spot light pointing down at 20 degrees from the vertical: full intensity inside 15 degrees,
// none outside 25, the smoothstep between (a delta light, 256 jittered samples a pixel: within
// 2%, and within 2% of the peak where the falloff is steep across a pixel).
TEST(Lights, SpotLightCone) {
    Scene s = PlaneScene();
    PointLight l;
    l.position = {0.0f, 1.5f, 0.0f};
    l.intensity = glm::vec3(4.0f);
    l.spot = true;
    l.direction = glm::normalize(glm::vec3(std::sin(0.35f), -std::cos(0.35f), 0.0f));
    l.innerDegrees = 15.0f;
    l.outerDegrees = 25.0f;
    s.pointLights.push_back(l);
    const RenderScene rs(s, {});
    const internal::SphereLight spot(l, glm::mat4(1.0f));
    const PointArgs args{l.position, 4.0f, &spot};
    const Image expected = ExpectedOnPlane(s, 48, 32, PointRadiance, &args);
    const Image img = Render(rs, Options(IntegratorKind::Direct, 256)).beauty;
    ExpectClose(img, expected, 0.02f, 0.02f, "spot, direct");
    // The cone is there: dark pixels (outside) and fully lit ones (inside).
    int dark = 0, lit = 0;
    for (size_t p = 0; p < expected.data.size(); ++p) {
        dark += expected.data[p] == 0.0f;
        lit += expected.data[p] > 0.0f;
    }
    EXPECT_GT(dark, 100);
    EXPECT_GT(lit, 100);
}

// The sun (a distant light 0.53 degrees across) at angle theta: L = albedo / pi * E cos(theta)
// (its disc's radiance makes the irradiance E on a surface facing it). Over the disc cos varies
// by up to tan(theta) 4.6e-3 relative (1.7% at 75 degrees): at 64 samples a pixel, within 1%.
TEST(Lights, SunIrradianceIsECos) {
    for (float thetaDeg : {0.0f, 40.0f, 75.0f}) {
        Scene s = PlaneScene();
        DistantLight d;
        const float th = glm::radians(thetaDeg);
        d.direction = -glm::vec3(std::sin(th), std::cos(th), 0.0f);
        d.irradiance = glm::vec3(2.0f);
        d.angleDegrees = 0.53f;
        s.distantLights.push_back(d);
        const RenderScene rs(s, {});
        const Image img = Render(rs, Options(IntegratorKind::Direct, 64)).beauty;
        const float expected = kAlbedo / kPiF * 2.0f * std::cos(th);
        int checked = 0;
        for (float v : img.data)
            if (v > 0.0f) {
                ASSERT_NEAR(v, expected, 0.01f * expected) << thetaDeg;
                ++checked;
            }
        EXPECT_GT(checked, 1000);
    }
}

// The sun's disc seen along a BSDF ray is light too, MIS-weighted against the disc's light
// samples: a near-mirror (GGX alpha 0.0025, F0 = 1, no diffuse base) looking straight down at
// a sun 10 degrees across overhead reflects the disc's radiance E / (pi sin^2 5deg) ~ 41.9 at
// every pixel (the 5 degree view's reflections fall inside the disc). Light samples alone would
// almost never land in a lobe this narrow: the BSDF rays carry it. Within 10% (the lobe's
// directional albedo is ~0.99).
TEST(Lights, SunDiscFoundByBsdfRaysIsCounted) {
    Scene s = PlaneScene();
    DistantLight d;
    d.direction = glm::vec3(0.0f, -1.0f, 0.0f);
    d.irradiance = glm::vec3(1.0f);
    d.angleDegrees = 10.0f;
    s.distantLights.push_back(d);
    s.materials[0].type = Material::Type::GGX;
    s.materials[0].albedo.value = glm::vec3(0.0f);
    s.materials[0].specular.value = glm::vec3(1.0f);
    s.materials[0].roughness.value = 0.05f;
    s.camera.pose.keys = {test::LookAt({0.0f, 3.0f, 0.01f}, {0, 0, 0})};
    s.camera.fovYDegrees = 5.0f;
    const RenderScene rs(s, {});
    const Image img = Render(rs, Options(IntegratorKind::Direct, 64, 16, 16)).beauty;
    double sum = 0.0;
    for (float v : img.data) sum += v;
    const double mean = sum / double(img.data.size());
    const float sin5 = std::sin(glm::radians(5.0f));
    const float Lsun = 1.0f / (kPiF * sin5 * sin5);
    std::printf("mirror under the sun: mean %.3f, the disc's radiance %.3f\n", mean, Lsun);
    EXPECT_NEAR(mean, Lsun, 0.1 * Lsun);
}

// A BSDF ray that hits an emissive object gets the density of the triangle it hit: the
// emitter's triangle of a hit (MeshEmitter::Triangle, from Embree's quad (u,v)) is the one
// Embree hit, whose geometric normal Embree reports. On the limit tessellation of the cube
// (non-planar quads: the two triangles of a quad differ), for rays from all around, the
// emitter's density t^2 / (area |cos|) equals the one from Embree's normal within 1e-3.
TEST(Lights, EmitterDensityAtAHitIsTheSampledOne) {
    Scene s = test::OneObjectScene(test::CubeCage());
    s.objects[0].emission = glm::vec3(1.0f);
    const RenderScene rs(s, {});
    const internal::MeshEmitter e(0, rs.QuadCorners(0), glm::vec3(1.0f), false);
    ASSERT_GT(e.Area(), 0.0f);
    Rng rng(7, 0);
    int hits = 0, distinct = 0;
    for (int i = 0; i < 2000; ++i) {
        Ray r;
        r.org = 4.0f * SampleUniformSphere(rng.Next2D());
        r.dir = glm::normalize(0.6f * SampleUniformSphere(rng.Next2D()) - r.org);
        Hit h;
        if (!rs.Intersect(r, &h)) continue;
        ++hits;
        const float fromEmbree =
            h.t * h.t / (e.Area() * std::abs(glm::dot(glm::normalize(h.Ng), r.dir)));
        const float pdf = e.Pdf(internal::MeshEmitter::Triangle(h.primID, h.U, h.V), r.dir, h.t);
        ASSERT_NEAR(pdf / fromEmbree, 1.0f, 1e-3f) << i;
        // The quad's other triangle would not do.
        const int other = internal::MeshEmitter::Triangle(h.primID, h.U, h.V) ^ 1;
        distinct += std::abs(e.Pdf(other, r.dir, h.t) / fromEmbree - 1.0f) > 1e-3f;
        // Seen from outside: the front, where a one-sided emitter emits.
        EXPECT_EQ(e.Emission(internal::MeshEmitter::Triangle(h.primID, h.U, h.V), r.dir),
                  glm::vec3(1.0f));
    }
    EXPECT_GT(hits, 1500);
    EXPECT_GT(distinct, hits / 2);
}

/// A closed box, 10 units across around the origin (two-sided emission of radiance 2, black), a
/// plain mesh or a subdivision surface, and inside it the subdivided unit cube (albedo 0.5), seen
/// from inside the box.
Scene EnclosureScene(bool subdividedBox) {
    Scene s;
    s.meshes.push_back(test::CubeCage());
    s.meshes.push_back(test::CubeCage());
    Material grey;
    grey.albedo.value = glm::vec3(kAlbedo);
    Material black;
    black.albedo.value = glm::vec3(0.0f);
    s.materials = {grey, black};
    Object blob;
    blob.mesh = 0;
    blob.material = 0;
    Object box;
    box.mesh = 1;
    box.material = 1;
    box.subdivide = subdividedBox;
    box.emission = glm::vec3(2.0f);
    box.emissionTwoSided = true;
    Keyframe k;
    k.scale = glm::vec3(5.0f);
    box.transform.keys = {k};
    s.objects = {blob, box};
    s.camera.pose.keys = {test::LookAt({1.2f, 0.9f, 1.5f}, {0, 0, 0})};
    s.camera.fovYDegrees = 60.0f;
    // A 6-face cage at the default rate 2 is a coarse polyhedron whose geometric normals differ
    // from its limit normals by ~20 degrees; rate 8 keeps this a test of the lights.
    s.settings.tessellationRate = 8.0f;
    return s;
}

// A furnace for emissive objects: inside a closed box that emits radiance Le on its inside and
// reflects nothing, a convex diffuse object sees Le in every direction, so its radiance is
// albedo x Le = 1 and the box's own is Le = 2, exactly, whatever the box's shape: any mismatch
// between the density of the area samples and the density MIS assumes for a BSDF ray that hits
// the box would show. The box as a plain mesh and as a subdivision surface (sampled on its limit
// tessellation); per hit (path and direct) and in texture space (hit-binned, all light cached).
// A pixel's expectation mixes the two by the share of its camera samples that hit the object
// (from the albedo AOV of the same camera rays). 64 samples a pixel: the image mean within 1%,
// pixels within 12%.
TEST(Lights, EmissiveEnclosureFurnace) {
    for (bool subdivided : {false, true}) {
        const Scene s = EnclosureScene(subdivided);
        const RenderScene rs(s, {});
        RenderOptions base = Options(IntegratorKind::Path, 64);
        base.maxDepth = 8;
        RenderOptions withAov = base;
        withAov.aovs.albedo = true;
        const RenderResult shares = Render(rs, withAov);
        ASSERT_EQ(shares.aovs.size(), 1u);
        const Image& albedo = shares.aovs[0].image;
        for (int mode = 0; mode < 3; ++mode) {
            RenderOptions o = base;
            if (mode == 1) o.integrator = IntegratorKind::Direct;
            if (mode == 2) {
                o.texture.enabled = true;
                o.texture.samples = TextureSamples::Hits;
                o.texture.cacheDirect = true;
            }
            const Image img = Render(rs, o).beauty;
            double sum = 0.0, expectedSum = 0.0;
            float worst = 0.0f;
            for (size_t i = 0; i < img.data.size(); ++i) {
                const float onObject = albedo.data[i] / kAlbedo;  // the share of samples
                const float expected = onObject * kAlbedo * 2.0f + (1.0f - onObject) * 2.0f;
                const float v = img.data[i];
                sum += v, expectedSum += expected;
                worst = std::max(worst, std::abs(v - expected) / expected);
            }
            std::printf("%s box, %s: mean ratio %.4f, largest pixel error %.3f\n",
                        subdivided ? "subdivided" : "plain",
                        mode == 0   ? "path"
                        : mode == 1 ? "direct"
                                    : "texture space",
                        sum / expectedSum, worst);
            EXPECT_NEAR(sum / expectedSum, 1.0, 0.01) << "mode " << mode;
            EXPECT_LT(worst, 0.12f) << "mode " << mode;
        }
    }
}

// An emissive plain quad is a quad light: the same radiance, the same shape, one-sided facing
// down. Both are sampled by area (the emitter through its two triangles), so the direct
// integrator's images agree to their noise: relMSE between them below 2e-3 at 64 spp (each
// against a 1024-spp render of the quad light would be ~1e-3).
TEST(Lights, EmissiveQuadMatchesQuadLight) {
    Scene s = PlaneScene();
    ControlCage lamp;
    lamp.positions = {
        {-0.5f, 1.5f, -0.5f}, {0.5f, 1.5f, -0.5f}, {0.5f, 1.5f, 0.5f}, {-0.5f, 1.5f, 0.5f}};
    lamp.faceVertexCounts = {4};
    lamp.faceVertexIndices = {0, 1, 2, 3};  // counter-clockwise seen from below: faces down
    Scene emissive = s;
    emissive.meshes.push_back(lamp);
    Object o;
    o.mesh = 1;
    o.material = 0;
    o.subdivide = false;
    o.emission = glm::vec3(5.0f);
    emissive.objects.push_back(o);
    QuadLight q;
    q.corner = {-0.5f, 1.5f, -0.5f};
    q.edge1 = {1.0f, 0.0f, 0.0f};
    q.edge2 = {0.0f, 0.0f, 1.0f};  // edge1 x edge2 = -y: emits downwards
    q.radiance = glm::vec3(5.0f);
    s.quadLights.push_back(q);
    s.camera.pose.keys = emissive.camera.pose.keys = {test::LookAt({0.0f, 4.0f, 2.5f}, {0, 0, 0})};
    const RenderScene rsQuad(s, {}), rsMesh(emissive, {});
    const Image a = Render(rsQuad, Options(IntegratorKind::Direct, 64)).beauty;
    const Image b = Render(rsMesh, Options(IntegratorKind::Direct, 64)).beauty;
    const double e = RelMSE(b, a);
    std::printf("relMSE emissive quad vs quad light: %.5f\n", e);
    EXPECT_LT(e, 2e-3);
    EXPECT_NEAR(test::MeanRatio(b, a), 1.0, 0.02);
}

/// A subdivided cube on a plain ground under every kind of light: a point light with a radius,
/// a delta spot, a sun 2 degrees across and a small emissive subdivision surface.
Scene AllLightsScene() {
    Scene s = PlaneScene();
    s.meshes.push_back(test::CubeCage());
    s.meshes.push_back(test::CubeCage());
    Object blob;
    blob.mesh = 1;
    Keyframe k;
    k.translation = {0.0f, 0.75f, 0.0f};
    blob.transform.keys = {k};
    Object lamp;
    lamp.mesh = 2;
    lamp.emission = glm::vec3(6.0f);
    k.translation = {1.2f, 1.0f, -0.8f};
    k.scale = glm::vec3(0.2f);
    lamp.transform.keys = {k};
    s.objects.push_back(blob);
    s.objects.push_back(lamp);
    PointLight point;
    point.position = {-1.5f, 1.8f, 0.5f};
    point.intensity = glm::vec3(2.0f, 1.6f, 1.2f);
    point.radius = 0.15f;
    PointLight spot;
    spot.position = {0.5f, 2.5f, 1.5f};
    spot.intensity = glm::vec3(4.0f);
    spot.spot = true;
    spot.direction = glm::normalize(glm::vec3(-0.2f, -1.0f, -0.6f));
    s.pointLights = {point, spot};
    DistantLight sun;
    sun.direction = glm::normalize(glm::vec3(0.5f, -1.0f, 0.3f));
    sun.irradiance = glm::vec3(0.6f, 0.55f, 0.5f);
    sun.angleDegrees = 2.0f;
    s.distantLights.push_back(sun);
    s.camera.pose.keys = {test::LookAt({0.0f, 3.5f, 4.0f}, {0.0f, 0.5f, 0.0f})};
    s.settings.tessellationRate = 4.0f;
    return s;
}

// Per hit and in texture space, the path integrator converges to the same image under every
// kind of light: at 256 samples a pixel, texture space's relMSE against a 1024-sample per-hit
// render stays within twice per hit's own at 256 (hit-binned: soft lights' direct light binned,
// the delta spot's per hit; and on the grid: indirect light cached, filtered), and its mean
// within 2%.
TEST(Lights, PerHitAndTextureSpaceConverge) {
    const Scene s = AllLightsScene();
    const RenderScene rs(s, {});
    auto options = [](int spp) {
        RenderOptions o = Options(IntegratorKind::Path, spp, 64, 48);
        o.maxDepth = 3;
        return o;
    };
    const Image ref = Render(rs, options(1024)).beauty;
    const double ePerHit = RelMSE(Render(rs, options(256)).beauty, ref);
    for (bool hits : {true, false}) {
        RenderOptions o = options(256);
        o.texture.enabled = true;
        o.texture.samples = hits ? TextureSamples::Hits : TextureSamples::Grid;
        o.texture.cacheDirect = hits;
        o.texture.deltaDirectPerHit = hits;
        const RenderResult ts = Render(rs, o);
        const double e = RelMSE(ts.beauty, ref);
        std::printf("relMSE at 256 spp: per hit %.5f, texture space (%s) %.5f\n", ePerHit,
                    hits ? "hits" : "grid", e);
        EXPECT_LT(e, 2.0 * ePerHit) << (hits ? "hits" : "grid");
        EXPECT_NEAR(test::MeanRatio(ts.beauty, ref), 1.0, 0.02);
    }
}

// A table of the map's samples (Context::envTable, the frame buffers') stands in for the map's
// own sampling in SampleLight: u.x picks an entry, each once for evenly spread u.x, and the
// sample is the entry's (direction, radiance and a density with the light pick in it). An empty
// entry (pdf 0) is no sample. The entries' densities are the map's at their directions (within
// 1e-3 relative), so MIS with the BSDF's rays weighs them as the map's own.
TEST(Lights, EnvironmentTableStandsInForTheMapsSampling) {
    Scene s = test::OneObjectScene(test::PlaneCage(1.0f), glm::vec3(kAlbedo));
    EnvironmentLight env;
    env.path = std::string(TEXCACHE_SOURCE_DIR) + "/scenes/envmaps/courtyard.exr";
    s.environments.push_back(env);
    QuadLight q;  // a second light: the pick probability is 1/2
    q.corner = glm::vec3(-0.5f, 3.0f, -0.5f);
    q.edge1 = glm::vec3(1.0f, 0.0f, 0.0f);
    q.edge2 = glm::vec3(0.0f, 0.0f, 1.0f);
    s.quadLights.push_back(q);
    const RenderScene rs(s, {});
    const RenderOptions o = Options(IntegratorKind::Path, 1);
    internal::Context c(rs, o);
    ASSERT_NE(c.env, nullptr);
    ASSERT_EQ(c.numLights, 2);
    constexpr uint32_t kN = 64;
    std::vector<internal::EnvironmentSampleEntry> table(kN);
    Rng rng(3, 0);
    for (uint32_t i = 0; i < kN; ++i) {
        float pdf = 0.0f;
        table[i].Li = c.env->Sample(glm::vec3(0, 1, 0), rng.Next2D(), &table[i].wi, &pdf);
        table[i].pdf = pdf * c.PickPdf();
        ASSERT_NEAR(c.env->Pdf(glm::vec3(0, 1, 0), table[i].wi) * c.PickPdf() / table[i].pdf, 1.0f,
                    1e-3f)
            << i;
    }
    table[5].pdf = 0.0f;  // an empty entry
    c.envTable = table.data();
    c.envTableMask = kN - 1;
    const glm::vec3 p(0.0f), n(0.0f, 1.0f, 0.0f);
    std::vector<int> seen(kN, 0);
    for (uint32_t i = 0; i < kN; ++i) {
        internal::LightSample ls;
        // uPick 0.75: the environment, the last light.
        const bool ok =
            c.SampleLight(p, n, 0.75f, glm::vec2((float(i) + 0.5f) / float(kN), 0.3f), &ls);
        ASSERT_EQ(ok, i != 5) << i;
        if (!ok) continue;
        const uint32_t e = uint32_t(
            std::find_if(table.begin(), table.end(),
                         [&](const internal::EnvironmentSampleEntry& t) { return t.wi == ls.wi; }) -
            table.begin());
        ASSERT_LT(e, kN);
        ++seen[e];
        EXPECT_EQ(ls.Li, table[e].Li);
        EXPECT_EQ(ls.pdf, table[e].pdf);
        EXPECT_FALSE(ls.delta);
        EXPECT_TRUE(std::isinf(ls.dist));
    }
    for (uint32_t i = 0; i < kN; ++i) EXPECT_EQ(seen[i], i == 5 ? 0 : 1) << i;
    // The end of [0, 1) stays in the table.
    internal::LightSample last;
    ASSERT_TRUE(c.SampleLight(p, n, 0.75f, glm::vec2(std::nextafter(1.0f, 0.0f), 0.5f), &last));
    EXPECT_EQ(last.wi, table[kN - 1].wi);
}

}  // namespace
}  // namespace texcache
