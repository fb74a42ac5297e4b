// SPDX-License-Identifier: Apache-2.0
// Stereo rendering (renderer/texture_space/stereo.h): the off-axis eyes, the second eye's reuse of
// the first eye's texture-space cache, convergence to per-eye references, and the command line's
// errors and outputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <ostream>

#include <tbb/task_arena.h>

#include "cli_run.h"
#include "renderer/image/metrics.h"
#include "renderer/scene/camera.h"
#include "renderer/texture_space/stereo.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {

// GoogleTest's name for a reuse mode (found by argument-dependent lookup in this namespace).
void PrintTo(StereoReuse r, std::ostream* os) {
    *os << (r == StereoReuse::Texels ? "texels" : "neighbour");
}

namespace {

namespace fs = std::filesystem;

/// A cube standing on a ground plane under a white sky: the cube hides ground that one eye sees
/// and the other does not.
Scene CubeOnGround() {
    Scene s = test::OneObjectScene(test::LoadMesh("catmark_cube"));
    s.meshes.push_back(test::PlaneCage(3.0f));
    Object ground;
    ground.mesh = 1;
    ground.material = 0;
    Keyframe k;
    k.translation = glm::vec3(0.0f, -1.0f, 0.0f);
    ground.transform.keys.push_back(k);
    s.objects.push_back(ground);
    s.camera.pose.keys = {test::LookAt({2.0f, 1.5f, 3.0f}, {0, 0, 0})};
    s.camera.fovYDegrees = 40.0f;
    EnvironmentLight env;
    env.constant = glm::vec3(1.0f);
    s.environments.push_back(env);
    return s;
}

RenderOptions AoOptions(int spp) {
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    o.width = 48;
    o.height = 32;
    o.spp = spp;
    o.aoSamples = 4;
    o.progress = false;
    o.texture.enabled = true;
    o.texture.cache.sampleCacheBytes = o.texture.cache.texelCacheBytes = size_t(4) << 20;
    return o;
}

double MaxAbsDiff(const Image& a, const Image& b) {
    double m = 0.0;
    for (size_t i = 0; i < a.data.size(); ++i)
        m = std::max(m, double(std::abs(a.data[i] - b.data[i])));
    return m;
}

// Off-axis eyes: a point on the convergence plane projects to the same pixel in both eyes (zero
// parallax), a distant point has the disparity separation / convergence * focal length in
// pixels, and each eye's ray through a point's pixel passes through the point (1e-3 relative).
TEST(Stereo, EyesAgreeOnTheConvergencePlane) {
    Camera cam;
    cam.pose.keys = {test::LookAt({0.0f, 0.0f, 5.0f}, {0, 0, 0})};
    const int W = 64, H = 48;
    const float sep = 0.3f, conv = 5.0f;
    CameraModel left(cam, 0.0f, W, H), right(cam, 0.0f, W, H);
    left.SetEye(-0.5f * sep, conv);
    right.SetEye(0.5f * sep, conv);
    for (glm::vec3 p : {glm::vec3(0.0f), glm::vec3(1.0f, 0.5f, 0.0f), glm::vec3(-1.2f, -0.7f, 0)}) {
        glm::vec2 fl, fr;
        ASSERT_TRUE(left.Project(p, &fl) && right.Project(p, &fr));
        EXPECT_NEAR(fl.x, fr.x, 1e-3f);
        EXPECT_NEAR(fl.y, fr.y, 1e-3f);
        for (const CameraModel* eye : {&left, &right}) {
            const Ray r = eye->Generate(fl.x, fl.y, glm::vec2(0.5f), nullptr);
            const glm::vec3 toP = p - r.org;
            EXPECT_LT(glm::length(glm::cross(r.dir, toP)), 1e-3f * glm::length(toP));
        }
    }
    // Far away (behind the zero-parallax plane): the right eye sees the point further right, by
    // sep / conv * focal pixels (uncrossed parallax).
    glm::vec2 fl, fr;
    ASSERT_TRUE(left.Project({0, 0, -1e5f}, &fl) && right.Project({0, 0, -1e5f}, &fr));
    const float focal = 0.5f * float(H) / std::tan(glm::radians(cam.fovYDegrees) * 0.5f);
    EXPECT_NEAR(fr.x - fl.x, sep / conv * focal, 1e-2f);
    EXPECT_NEAR(fl.y, fr.y, 1e-3f);
}

// Both reuse modes of the second eye (StereoReuse).
class StereoReuseModes : public ::testing::TestWithParam<StereoReuse> {};

// With zero separation the right eye traces the left eye's camera rays and finds every texel in
// the cache: no sample or texel is shaded anew, in either of the two progressive passes, and its
// image is the left eye's (1e-6: the same lookups). Unbounded caches, so that no collision
// evicts what the second eye would reuse.

TEST_P(StereoReuseModes, ZeroSeparationShadesNothingAndRepeatsTheFirstEye) {
    const Scene s = CubeOnGround();
    const RenderScene rs(s, {});
    RenderOptions o = AoOptions(8);
    o.texture.passSpp = 4;
    o.texture.cache.referenceMode = true;
    const StereoResult r = RenderStereo(rs, o, {0.0f, 4.0f}, nullptr, GetParam());
    EXPECT_GT(r.left.stats.cache.samplesShaded, 0u);
    EXPECT_EQ(r.right.stats.cache.samplesShaded, 0u);
    EXPECT_EQ(r.right.stats.cache.texelMisses, 0u);
    EXPECT_EQ(r.right.stats.sppDone, 8);
    EXPECT_LE(MaxAbsDiff(r.left.beauty, r.right.beauty), 1e-6);
}

// A static diffuse scene in stereo converges to each eye's own per-hit reference (128 spp):
// relMSE of both eyes falls from 4 to 32 camera samples (progressive passes) and ends below
// 0.03 (measured 0.013-0.017, the reference's own noise included); and the right eye, though it
// reuses the left eye's cache, is within 1.5x the relMSE of the right eye rendered alone with
// the same samples.
TEST_P(StereoReuseModes, EyesConvergeToPerEyeReferences) {
    const Scene s = CubeOnGround();
    const RenderScene rs(s, {});
    const StereoRig rig{0.25f, 3.9f};
    Image ref[2];
    for (int eye = 0; eye < 2; ++eye) {
        RenderOptions o = AoOptions(128);
        o.texture.enabled = false;
        o.eyeOffset = (eye == 0 ? -0.5f : 0.5f) * rig.eyeSeparation;
        o.eyeConvergence = rig.convergence;
        ref[eye] = Render(rs, o).beauty;
    }
    const StereoResult coarse = RenderStereo(rs, AoOptions(4), rig, nullptr, GetParam());
    const StereoResult fine = RenderStereo(rs, AoOptions(32), rig, nullptr, GetParam());
    const double coarseErr[2] = {RelMSE(coarse.left.beauty, ref[0]),
                                 RelMSE(coarse.right.beauty, ref[1])};
    const double fineErr[2] = {RelMSE(fine.left.beauty, ref[0]), RelMSE(fine.right.beauty, ref[1])};
    for (int eye = 0; eye < 2; ++eye) {
        RecordProperty(eye ? "rightRelMse" : "leftRelMse", std::to_string(fineErr[eye]));
        EXPECT_LT(fineErr[eye], 0.5 * coarseErr[eye]) << "eye " << eye;
        EXPECT_LT(fineErr[eye], 0.03) << "eye " << eye;
    }
    // The eyes differ (the cube moves against the ground), and the right eye is not the left.
    EXPECT_GT(RelMSE(ref[1], ref[0]), 10.0 * fineErr[1]);
    RenderOptions alone = AoOptions(32);
    alone.eyeOffset = 0.5f * rig.eyeSeparation;
    alone.eyeConvergence = rig.convergence;
    EXPECT_LT(fineErr[1], 1.5 * RelMSE(Render(rs, alone).beauty, ref[1]));
    EXPECT_LT(fine.right.stats.cache.samplesShaded, fine.left.stats.cache.samplesShaded);
}

// Path-traced diffuse light with full-window footprints and a sample cache too small for the
// frame: the eyes take turns band by band (renderer/texture_space/stereo.h), and the second eye
// shades fewer than 3/4 of the samples it shades when the first eye renders its whole frame first
// (measured: 0.36-0.44 of it), while the left eye's image stays exactly its mono render (1e-6), for
// one thread and for two. Texels reuse: the second eye's new samples are then fixed by the two
// eyes' texels and the cache's evictions (with Neighbour, the texels the second eye filters serve
// its later lookups, so the count follows the threads' order).
TEST(Stereo, BandsKeepTheFirstEyesSamplesForTheSecond) {
    const Scene s = CubeOnGround();
    const RenderScene rs(s, {});
    const StereoRig rig{0.25f, 3.9f};
    RenderOptions o = AoOptions(4);
    o.integrator = IntegratorKind::Path;
    o.maxDepth = 2;
    o.width = 64;
    o.height = 48;
    o.texture.cache.sampleCacheBytes = size_t(256) << 10;
    RenderOptions leftAlone = o;
    leftAlone.eyeOffset = -0.5f * rig.eyeSeparation;
    leftAlone.eyeConvergence = rig.convergence;
    const Image mono = Render(rs, leftAlone).beauty;
    for (int threads : {1, 2}) {
        tbb::task_arena arena(threads);
        arena.execute([&] {
            const StereoResult bands =
                RenderStereo(rs, o, rig, nullptr, StereoReuse::Texels, StereoOrder::Bands);
            const StereoResult frames =
                RenderStereo(rs, o, rig, nullptr, StereoReuse::Texels, StereoOrder::Frames);
            const double b = double(bands.right.stats.cache.samplesShaded),
                         f = double(frames.right.stats.cache.samplesShaded);
            RecordProperty("rightSamples" + std::to_string(threads),
                           std::to_string(b) + " / " + std::to_string(f));
            EXPECT_LT(b, 0.75 * f) << threads << " threads";
            EXPECT_LE(MaxAbsDiff(bands.left.beauty, mono), 1e-6) << threads << " threads";
            EXPECT_LE(MaxAbsDiff(frames.left.beauty, mono), 1e-6) << threads << " threads";
        });
    }
}

// Shading at the hits (TextureSamples::Hits): both eyes' hits go into one store and each eye is
// read back from the shared bins. AO and path-traced diffuse light on the cube, 4 spp: each
// eye's relMSE against its own 256-spp per-hit reference is at most 1.1x that of the eye rendered
// alone (mono, its own store) with the same camera samples (the stated tolerance: the shared bins
// hold twice the samples of the surfaces both eyes see: measured 0.98-0.99x); the
// image is the same on 1 and 2 threads (1e-6: the bins' sums are integers).
TEST(Stereo, HitsOfBothEyesShareOneStore) {
    const Scene s = CubeOnGround();
    const RenderScene rs(s, {});
    const StereoRig rig{0.25f, 3.9f};
    for (IntegratorKind k : {IntegratorKind::AO, IntegratorKind::Path}) {
        RenderOptions o = AoOptions(4);
        o.integrator = k;
        o.maxDepth = 2;
        o.texture.samples = TextureSamples::Hits;
        StereoResult stereo[2];
        for (int threads : {1, 2}) {
            tbb::task_arena arena(threads);
            arena.execute([&] { stereo[threads - 1] = RenderStereo(rs, o, rig); });
        }
        const Image* eyes[2][2] = {{&stereo[0].left.beauty, &stereo[0].right.beauty},
                                   {&stereo[1].left.beauty, &stereo[1].right.beauty}};
        for (int eye = 0; eye < 2; ++eye) {
            RenderOptions e = o;
            e.eyeOffset = (eye == 0 ? -0.5f : 0.5f) * rig.eyeSeparation;
            e.eyeConvergence = rig.convergence;
            const Image alone = Render(rs, e).beauty;
            e.texture.enabled = false;
            e.spp = 256;
            const Image ref = Render(rs, e).beauty;
            const double errStereo = RelMSE(*eyes[0][eye], ref), errAlone = RelMSE(alone, ref);
            const std::string what = std::string(k == IntegratorKind::AO ? "ao" : "path") +
                                     (eye == 0 ? "Left" : "Right");
            RecordProperty(what, std::to_string(errStereo) + " / " + std::to_string(errAlone));
            EXPECT_LE(errStereo, 1.1 * errAlone) << what;
            EXPECT_LE(MaxAbsDiff(*eyes[0][eye], *eyes[1][eye]), 1e-6) << what;
            EXPECT_GT(MaxAbsDiff(*eyes[0][eye], alone), 1e-4) << what << ": not a mono render";
        }
        EXPECT_EQ(stereo[0].right.stats.sppDone, 4);
    }
}

// A render of a band of rows (RenderOptions::rowBegin/rowEnd) has the whole frame's pixels in
// those rows (per-hit shading, the same random streams: identical) and black elsewhere; a band that
// is not inside the image is an InputError.
TEST(Stereo, ABandRendersItsRowsOfTheFrame) {
    const Scene s = CubeOnGround();
    const RenderScene rs(s, {});
    RenderOptions o = AoOptions(2);
    o.texture.enabled = false;  // per hit: a pixel depends only on its own random streams
    const Image whole = Render(rs, o).beauty;
    o.rowBegin = 8, o.rowEnd = 20;
    const Image band = Render(rs, o).beauty;
    ASSERT_EQ(band.data.size(), whole.data.size());
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x)
            for (int c = 0; c < 3; ++c) {
                const float expected = y >= 8 && y < 20 ? whole.At(x, y)[c] : 0.0f;
                ASSERT_EQ(band.At(x, y)[c], expected) << x << "," << y;
            }
    for (auto [b, e] : {std::pair{20, 8}, {-1, 4}, {0, o.height + 1}, {o.height, 0}}) {
        o.rowBegin = b, o.rowEnd = e;
        EXPECT_THROW(Render(rs, o), InputError) << b << ", " << e;
    }
}

INSTANTIATE_TEST_SUITE_P(Stereo, StereoReuseModes,
                         ::testing::Values(StereoReuse::Texels, StereoReuse::Neighbour),
                         [](const ::testing::TestParamInfo<StereoReuse>& i) {
                             return ::testing::PrintToString(i.param);
                         });

// The command line: both eyes' EXR and PNG and the per-eye --stats; bad rigs (scene file and
// options) and --stereo with --frame-buffers are one-line errors with exit code 2 that write
// nothing.
class StereoCli : public ::testing::Test {
protected:
    void SetUp() override {
        // One directory per test: ctest -j runs the tests of this fixture at once.
        dir_ = fs::path(::testing::TempDir()) /
               ("texcache_stereo_" +
                std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    std::string Scene(const std::string& name, const std::string& stereo) {
        const fs::path p = dir_ / name;
        std::ofstream(p) << R"({"camera": {"position": [2, 1.5, 3], "look_at": [0, 0, 0])" << stereo
                         << R"(}, "objects": [{"mesh": ")" << test::MeshPath("catmark_cube")
                         << R"("}],
            "render": {"resolution": [32, 18], "spp": 1, "integrator": "ao"}})";
        return p.string();
    }
    fs::path dir_;
};

TEST_F(StereoCli, WritesBothEyesAndTheirStatistics) {
    const std::string scene =
        Scene("s.json", R"(, "stereo": {"eye_separation": 0.1, "convergence": 3.5})");
    const test::CliRun r =
        test::Texcache("render " + scene + " --stereo --shading texture -q -o " +
                       (dir_ / "v.exr").string() + " --stats " + (dir_ / "v.json").string());
    ASSERT_EQ(r.code, 0) << r.out;
    for (const char* f : {"v_left.exr", "v_left.png", "v_right.exr", "v_right.png"})
        EXPECT_TRUE(fs::exists(dir_ / f)) << f;
    EXPECT_FALSE(fs::exists(dir_ / "v.exr"));
    // At the hits both eyes' passes interleave through one store: one time for both.
    EXPECT_NE(r.out.find("both eyes, hits in one store:"), std::string::npos) << r.out;
    // The grid's second eye reuses the first eye's cache: each eye's share is printed.
    const test::CliRun grid =
        test::Texcache("render " + scene + " --stereo --shading texture --ts-samples grid -q -o " +
                       (dir_ / "g.exr").string());
    ASSERT_EQ(grid.code, 0) << grid.out;
    EXPECT_NE(grid.out.find("right eye:"), std::string::npos) << grid.out;
    std::ifstream js(dir_ / "v.json");
    const std::string stats((std::istreambuf_iterator<char>(js)), {});
    for (const char* key : {"\"stereo\"", "\"eye_separation\": 0.1", "\"left\"", "\"right\"",
                            "\"samples_shaded\"", "\"texels_shaded\""})
        EXPECT_NE(stats.find(key), std::string::npos) << key << "\n" << stats;
}

/// Runs `texcache render SCENE ARGS` expecting exit code 2, one line naming `expect`, and no
/// output written.
void ExpectOneLineError(const std::string& args, const std::string& expect,
                        const fs::path& output) {
    const test::CliRun r = test::Texcache("render " + args + " -q -o " + output.string());
    EXPECT_EQ(r.code, 2) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(expect), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
    const fs::path stem = output.parent_path() / output.stem();
    EXPECT_FALSE(fs::exists(stem.string() + "_left.exr"));
}

TEST_F(StereoCli, NegativeOrNanSeparationOnTheCommandLineExitsTwo) {
    const std::string plain = Scene("plain.json", "");
    ExpectOneLineError(plain + " --stereo --eye-separation -0.5", "--eye-separation",
                       dir_ / "a.exr");
    ExpectOneLineError(plain + " --stereo --eye-separation nan", "--eye-separation",
                       dir_ / "a.exr");
    ExpectOneLineError(plain + " --stereo --convergence 0", "--convergence", dir_ / "a.exr");
}

TEST_F(StereoCli, NegativeSeparationInTheSceneAndFrameBuffersExitTwo) {
    const std::string negative = Scene("negative.json", R"(, "stereo": {"eye_separation": -0.1})");
    ExpectOneLineError(negative + " --stereo", "camera.stereo.eye_separation", dir_ / "b.exr");
    const std::string plain = Scene("plain.json", "");
    ExpectOneLineError(plain + " --eye-separation 0.1", "give --stereo", dir_ / "b.exr");
    ExpectOneLineError(plain + " --stereo --visibility-filter layered", "--visibility-filter",
                       dir_ / "b.exr");
    const test::CliRun r =
        test::Texcache("render " + plain + " --stereo --frame-buffers " + (dir_ / "fb").string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("--stereo: cannot be combined with --frame-buffers"), std::string::npos)
        << r.out;
    EXPECT_FALSE(fs::exists(dir_ / "fb"));
}

}  // namespace
}  // namespace texcache
