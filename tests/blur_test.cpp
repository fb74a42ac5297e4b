// SPDX-License-Identifier: Apache-2.0
// Motion and defocus blur with texture-space shading: the primary-visibility filter
// (filters/visibility_filter.h) leaves sharp pixels alone and contains NaN/Inf; a moving object's
// camera hits at different shutter times share its texels; the shadow a moving object casts is
// smeared in the cache as in the per-hit render; bad settings are clear errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include <glm/gtc/quaternion.hpp>

#include "cli_run.h"
#include "filters/visibility_filter.h"
#include "renderer/render.h"
#include "renderer/scene/camera.h"
#include "renderer/texture_space/texture_space.h"
#include "renderer/texture_space/visibility_pass.h"
#include "test_util.h"

namespace texcache {
namespace {

/// Pixel buffers of a width x height frame for the filter.
struct Frame {
    int w, h;
    std::vector<float> color, depth, blur;
    Frame(int w_, int h_) : w(w_), h(h_), color(3 * w_ * h_), depth(w_ * h_), blur(3 * w_ * h_) {}
    VisibilityBuffers In() const { return {w, h, color.data(), depth.data(), blur.data()}; }
    void SetBlur(size_t p, glm::vec3 c) {
        blur[3 * p] = c.x, blur[3 * p + 1] = c.y, blur[3 * p + 2] = c.z;
    }
};

Frame Noisy(int w, int h, uint32_t seed) {
    Frame f(w, h);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (float& c : f.color) c = u(rng);
    for (float& z : f.depth) z = 1.0f + 9.0f * u(rng);
    return f;
}

// Sharp pixels (no blur anywhere) are copied: the output equals the input exactly (tolerance 0),
// whatever their colours and depths.
TEST(VisibilityFilter, NoBlurLeavesTheImageUnchanged) {
    const Frame f = Noisy(40, 30, 1);
    std::vector<float> out;
    FilterVisibility(f.In(), {}, &out);
    ASSERT_EQ(out.size(), f.color.size());
    for (size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out[i], f.color[i]) << i;
}

// A render of a scene without lens or shutter through the whole pass (guide rays, blur from the
// camera, filter): the beauty is unchanged within 1e-6 (sharp pixels are copied; the tolerance
// only allows for the copy), and the guides see the object with no blur.
TEST(VisibilityFilter, StaticRenderIsUnchanged) {
    Scene s = test::OneObjectScene(test::LoadMesh("catmark_torus"));
    s.camera.pose.keys.push_back(test::LookAt({0.0f, 2.0f, 3.0f}, {0.0f, 0.0f, 0.0f}));
    const RenderScene rs(s, {});
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    o.width = 32, o.height = 24, o.spp = 4, o.progress = false;
    const RenderResult plain = Render(rs, o);
    Image filtered = plain.beauty;
    ApplyVisibilityFilter(VisibilityFilterKind::Layered, rs, o, &filtered);
    ASSERT_EQ(filtered.data.size(), plain.beauty.data.size());
    for (size_t i = 0; i < filtered.data.size(); ++i)
        ASSERT_NEAR(filtered.data[i], plain.beauty.data[i], 1e-6f) << i;
    const VisibilityGuides g = TraceVisibilityGuides(rs, o);
    int hits = 0;
    for (size_t p = 0; p < g.depth.size(); ++p) {
        hits += std::isfinite(g.depth[p]);
        for (int k = 0; k < 3; ++k) ASSERT_EQ(g.blur[3 * p + k], 0.0f);
    }
    EXPECT_GT(hits, 50);
}

// Blurred pixels (circle of confusion 8 px) of a constant 0.5 plus uniform noise of std 0.115:
// the filter keeps the mean within 0.01 and divides the variance by more than 5 (a Gaussian of
// std 0.6 * 4 px averages ~70 pixels; 5 leaves room for the borders' smaller windows).
TEST(VisibilityFilter, AveragesNoiseInBlurredRegions) {
    Frame f = Noisy(48, 48, 2);
    for (size_t p = 0; p < f.depth.size(); ++p) {
        for (int c = 0; c < 3; ++c) f.color[3 * p + c] = 0.3f + 0.4f * f.color[3 * p + c];
        f.depth[p] = 5.0f;
        f.SetBlur(p, BlurCovariance(glm::vec2(0.0f), 8.0f));
    }
    std::vector<float> out;
    FilterVisibility(f.In(), {}, &out);
    auto stats = [](const std::vector<float>& v, double* mean) {
        double s = 0.0, s2 = 0.0;
        for (float x : v) s += x, s2 += double(x) * x;
        *mean = s / double(v.size());
        return s2 / double(v.size()) - *mean * *mean;
    };
    double m0, m1;
    const double v0 = stats(f.color, &m0), v1 = stats(out, &m1);
    EXPECT_NEAR(m1, m0, 0.01);
    EXPECT_LT(v1, v0 / 5.0);
}

// Layers: a sharp foreground (depth 1) beside a blurred background (depth 10, CoC 10 px) keeps
// every pixel exactly (it gathers nothing from behind it), while the background is filtered; a
// motion blur along x leaves rows of different colours apart (the kernel is a segment along x).
TEST(VisibilityFilter, SharpForegroundAndAnisotropicKernelsKeepEdges) {
    Frame f = Noisy(40, 40, 3);
    for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 40; ++x) {
            const size_t p = size_t(y) * 40 + x;
            const bool fg = x < 20;
            f.depth[p] = fg ? 1.0f : 10.0f;
            f.SetBlur(p, fg ? glm::vec3(0.0f) : BlurCovariance(glm::vec2(0.0f), 10.0f));
        }
    std::vector<float> out;
    FilterVisibility(f.In(), {}, &out);
    int changed = 0;
    for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 40; ++x)
            for (int c = 0; c < 3; ++c) {
                const size_t i = 3 * (size_t(y) * 40 + x) + c;
                if (x < 20) {
                    ASSERT_EQ(out[i], f.color[i]) << x << "," << y;
                }
                changed += out[i] != f.color[i];
            }
    EXPECT_GT(changed, 20 * 40 * 3 * 9 / 10);

    // Rows alternate 0 and 1, every pixel blurred by 12 px of motion along x.
    Frame m(32, 32);
    for (size_t p = 0; p < m.depth.size(); ++p) {
        const float v = float((p / 32) % 2);
        for (int c = 0; c < 3; ++c) m.color[3 * p + c] = v;
        m.depth[p] = 3.0f;
        m.SetBlur(p, BlurCovariance({12.0f, 0.0f}, 0.0f));
    }
    FilterVisibility(m.In(), {}, &out);
    for (size_t p = 0; p < m.depth.size(); ++p)
        ASSERT_NEAR(out[3 * p], m.color[3 * p], 1e-3f) << p;  // across: exp(-32) leaks
}

// NaN and Inf colours are never gathered: in a blurred region they are replaced by their
// neighbours' average, in a sharp one they stay where they are, and no other pixel turns
// non-finite. NaN depth and blur are read as sharp pixels at infinity.
TEST(VisibilityFilter, NanAndInfStayContained) {
    Frame f = Noisy(32, 32, 4);
    for (size_t p = 0; p < f.depth.size(); ++p)
        f.SetBlur(p, (p % 32) < 16 ? BlurCovariance({6.0f, 2.0f}, 4.0f) : glm::vec3(0.0f));
    const size_t blurredNan = 10 * 32 + 5, blurredInf = 20 * 32 + 8, sharpNan = 12 * 32 + 25;
    f.color[3 * blurredNan] = NAN;
    f.color[3 * blurredInf + 1] = INFINITY;
    f.color[3 * sharpNan + 2] = -INFINITY;
    f.depth[7 * 32 + 3] = NAN;
    f.blur[3 * (9 * 32 + 9)] = NAN;
    f.depth[15 * 32 + 15] = INFINITY;
    std::vector<float> out;
    FilterVisibility(f.In(), {}, &out);
    for (size_t p = 0; p < f.depth.size(); ++p) {
        const bool finite = std::isfinite(out[3 * p]) && std::isfinite(out[3 * p + 1]) &&
                            std::isfinite(out[3 * p + 2]);
        EXPECT_EQ(finite, p != sharpNan) << p;
    }
}

// A torus that moves and turns in the image plane while the shutter is open.
Scene MovingTorusScene(glm::vec3 from, glm::vec3 to, float turnDegrees, float scale) {
    Scene s = test::OneObjectScene(test::LoadMesh("catmark_torus"));
    Keyframe k0, k1;
    k0.time = 0.0f, k1.time = 1.0f;
    k0.translation = from, k1.translation = to;
    k0.scale = k1.scale = glm::vec3(scale);
    k0.rotation = glm::angleAxis(glm::radians(90.0f), glm::vec3(1, 0, 0));
    k1.rotation = glm::angleAxis(glm::radians(turnDegrees), glm::vec3(0, 0, 1)) * k0.rotation;
    s.objects[0].transform.keys = {k0, k1};
    s.camera.shutterOpen = 0.0f, s.camera.shutterClose = 1.0f;
    return s;
}

// The texel of a point of the moving torus, hit by camera rays at several shutter times, is the
// same cache entry: the key is the object's own (face, mip, texel), not a world position. As the
// torus turns its footprint may change the mip level (eq. 1); the texels are then the same
// grid's parent and child. Every visible point keeps its face, and its texel within one (the
// rays meet the tessellation, not the limit surface), at all 5 times, and most of a point's hits
// land on one and the same texel.
TEST(MotionBlur, MovingObjectSamplesShareTexels) {
    Scene s = MovingTorusScene({-0.5f, 0.0f, 0.0f}, {0.5f, 0.0f, 0.0f}, 10.0f, 1.0f);
    const glm::vec3 eye(0.0f, 0.0f, 6.0f);
    s.camera.pose.keys.push_back(test::LookAt(eye, {0.0f, 0.0f, 0.0f}));
    const RenderScene rs(s, {});
    TextureSpaceOptions to;
    to.enabled = true;
    const TextureSpaceCache cache(rs, to);
    const int W = 160, H = 120;
    const CameraModel cam(s.camera, 0.0f, W, H);
    int points = 0, sharedHits = 0;
    for (int face = 0; face < int(rs.NumPtexFaces()); ++face)
        for (const glm::vec2 uv : {glm::vec2(0.3f, 0.6f), glm::vec2(0.7f, 0.2f)}) {
            std::vector<TexelKey> keys;
            for (const float t : {0.0f, 0.25f, 0.5f, 0.8f, 1.0f}) {
                SurfaceSample ss;
                ASSERT_TRUE(rs.EvalSurface(0, {face, uv.x, uv.y}, t, &ss));
                glm::vec2 film;
                if (glm::dot(ss.N, eye - ss.P) <= 0.0f || !cam.Project(ss.P, &film)) break;
                RayDifferentials diff;
                Ray ray = cam.Generate(film.x, film.y, {0.5f, 0.5f}, &diff);
                ray.time = t;
                Hit hit;
                // Another part of the torus in front is not this point's hit (the hit is on the
                // tessellation, within a few % of a face's size of the limit surface).
                if (!rs.Intersect(ray, &hit) || std::abs(hit.t - glm::length(ss.P - eye)) > 0.05f)
                    break;
                const SampleRequest texel = cache.TexelOf(rs.Interact(ray, hit, &diff));
                ASSERT_EQ(texel.mesh, cache.MeshOf(0));
                keys.push_back(texel.key);
            }
            if (keys.size() < 5) continue;  // hidden at some time
            ++points;
            for (const TexelKey& k : keys) {
                // The same texel of the object's grid at k's level (the finer key's parent).
                const TexelKey& fine = k.mip < keys[0].mip ? k : keys[0];
                const TexelKey& coarse = k.mip < keys[0].mip ? keys[0] : k;
                const int d = coarse.mip - fine.mip;
                EXPECT_EQ(k.face, keys[0].face);
                EXPECT_LE(d, 1) << "face " << face;
                // Within a texel: the rays meet the tessellation, not the limit surface, at
                // slightly different (u,v) as the torus turns.
                EXPECT_LE(std::abs((fine.iu >> d) - coarse.iu), 1) << "face " << face;
                EXPECT_LE(std::abs((fine.iv >> d) - coarse.iv), 1) << "face " << face;
            }
            // Hits of this point that land on its most common texel.
            int mode = 0;
            for (const TexelKey& a : keys)
                mode = std::max(mode, int(std::count(keys.begin(), keys.end(), a)));
            sharedHits += mode;
        }
    EXPECT_GE(points, 10);  // enough visible points for the test to mean something
    // Measured 0.86 (mip or texel flips near a level or texel boundary are the rest).
    EXPECT_GE(sharedHits, 0.75 * 5 * points);
}

/// Columns' mean over the rows of `mask` (pixels that see the ground all through the shutter).
std::vector<double> ColumnProfile(const Image& img, const std::vector<char>& mask) {
    std::vector<double> sum(size_t(img.width), 0.0), n(size_t(img.width), 0.0);
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x)
            if (mask[size_t(y) * img.width + x]) sum[x] += img.At(x, y)[0], n[x] += 1.0;
    for (size_t x = 0; x < sum.size(); ++x) sum[x] = n[x] > 0 ? sum[x] / n[x] : 0.0;
    return sum;
}

double L1(const std::vector<double>& a, const std::vector<double>& b) {
    double d = 0.0;
    for (size_t i = 0; i < a.size(); ++i) d += std::abs(a[i] - b[i]);
    return d / double(a.size());
}

// A torus sweeping low over the ground during the shutter casts a smeared AO shadow. The ground's
// column profile (mean over the rows that see the ground at every time) from the texture-space
// cache must be as close to the per-hit render's as noise allows (within a third of the distance
// between the per-hit blurred and sharp shadows): when the cache shaded the ground at shutter open
// only, its profile was the sharp one. AO with 4 rays per sample; 64 x 40 pixels.
TEST(MotionBlur, MovingShadowBlursAsPerHit) {
    Scene s = MovingTorusScene({-0.9f, 0.12f, 0.0f}, {0.9f, 0.12f, 0.0f}, 0.0f, 0.3f);
    s.objects[0].transform.keys[0].rotation = s.objects[0].transform.keys[1].rotation =
        glm::quat(1.0f, 0.0f, 0.0f, 0.0f);  // lying flat over the ground
    s.meshes.push_back(test::PlaneCage(3.0f));
    Object ground;
    ground.mesh = 1;
    s.objects.push_back(ground);
    s.camera.pose.keys.push_back(test::LookAt({0.0f, 1.0f, 1.6f}, {0.0f, 0.0f, 0.45f}));
    s.camera.fovYDegrees = 50.0f;
    const RenderScene rs(s, {});
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    o.width = 64, o.height = 40, o.progress = false;
    o.aoSamples = 4, o.aoDistance = 1.5f;
    // Ground pixels: the pixel centre sees the ground at 9 times of the shutter.
    std::vector<char> mask(size_t(o.width) * o.height, 1);
    const CameraModel cam(s.camera, 0.0f, o.width, o.height);
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x)
            for (int k = 0; k <= 8; ++k) {
                Ray ray = cam.Generate(x + 0.5f, y + 0.5f, {0.5f, 0.5f}, nullptr);
                ray.time = float(k) / 8.0f;
                Hit hit;
                if (!rs.Intersect(ray, &hit) || hit.object != 1) mask[size_t(y) * o.width + x] = 0;
            }

    RenderOptions hit = o;
    hit.spp = 64;
    const std::vector<double> perHit = ColumnProfile(Render(rs, hit).beauty, mask);
    RenderOptions ts = o;
    ts.spp = 16;
    ts.texture.enabled = true;
    ts.texture.passSpp = 0;
    const std::vector<double> cached = ColumnProfile(Render(rs, ts).beauty, mask);
    // The same shadow without motion blur (the torus at shutter open, per hit).
    Scene sharpScene = s;
    sharpScene.camera.shutterClose = 0.0f;
    const RenderScene sharpRs(sharpScene, {});
    const std::vector<double> sharp = ColumnProfile(Render(sharpRs, hit).beauty, mask);

    const double blurVsSharp = L1(perHit, sharp), cachedVsHit = L1(cached, perHit);
    EXPECT_GT(blurVsSharp, 0.01) << "the shadow must move enough to matter";
    EXPECT_LT(cachedVsHit, blurVsSharp / 3.0);
}

// Clear errors, exit 2, one line: frame buffers cannot show a lens or an open shutter; the
// visibility filter takes known names and no frame buffers.
bool OneLine(const test::CliRun& r) {
    return std::count(r.out.begin(), r.out.end(), '\n') == 1;
}

TEST(BlurCli, FrameBuffersRefuseLensAndShutter) {
    const std::string dir = ::testing::TempDir() + "texcache_blur_fb";
    const std::string scenes = test::SceneDir();
    test::CliRun r =
        test::Texcache("render " + scenes + "/blur_defocus.json --frame-buffers " + dir);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("lens_radius"), std::string::npos) << r.out;
    EXPECT_TRUE(OneLine(r)) << r.out;
    r = test::Texcache("render " + scenes + "/blur_motion.json --denoise spatial -o " + dir +
                       "/x.png");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("shutter"), std::string::npos) << r.out;
    EXPECT_TRUE(OneLine(r)) << r.out;
}

TEST(BlurCli, BadVisibilityFilterIsAnError) {
    const std::string dir = ::testing::TempDir() + "texcache_blur_vf";
    const std::string scenes = test::SceneDir();
    test::CliRun r = test::Texcache(
        "render " + scenes + "/blur_motion.json --visibility-filter sharpen -o " + dir + "/x.png");
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("--visibility-filter"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("layered"), std::string::npos) << r.out;
    EXPECT_TRUE(OneLine(r)) << r.out;
    // --frame-buffers has no beauty to filter.
    r = test::Texcache("render " + scenes +
                       "/chess.json --visibility-filter layered "
                       "--frame-buffers " +
                       dir);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("--visibility-filter"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace texcache
