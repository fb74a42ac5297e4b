// SPDX-License-Identifier: Apache-2.0
// A material's "filter" on the default texture-space path (hit binning, TextureSamples::Hits): it
// changes that object's image, each filter stays finite and near per hit on the cages with hard
// features, and a filter the render cannot apply is refused naming the scene file and material.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "renderer/image/metrics.h"
#include "renderer/render.h"
#include "renderer/render_policy.h"
#include "test_util.h"
#include "texcache/error.h"
#include "torus_scene.h"

namespace texcache {
namespace {

const char* const kBinFilters[] = {"none", "gaussian", "regression"};

double MeanAbsoluteDifference(const Image& a, const Image& b) {
    double sum = 0.0;
    for (size_t i = 0; i < a.data.size(); ++i) sum += std::abs(a.data[i] - b.data[i]);
    return sum / double(a.data.size());
}

// The torus on its plane, its torus's material given `filter` ("" for no key).
Scene TorusWithFilter(const std::string& filter) {
    Scene s = test::TorusOnPlane();
    Material m = s.materials[0];
    m.cacheFilter = filter;
    s.materials.push_back(m);
    s.objects[0].material = int(s.materials.size()) - 1;
    return s;
}

// A filter key on the torus's material changes the default texture-space image (mean absolute
// difference above 1e-3 on AO values in [0, 1]; measured 0.005-0.008), and "normal" is what no
// key gives (below 1e-6: the same reconstruction).
TEST(MaterialFilter, ChangesTheDefaultTextureSpaceImage) {
    RenderSceneOptions ro;
    ro.needLights = false;
    const Scene plain = TorusWithFilter("");
    const Image base = Render(RenderScene(plain, ro), test::HitsAo(4, 4)).beauty;
    for (const char* f : {"normal", "none", "gaussian", "regression"}) {
        SCOPED_TRACE(f);
        const Scene s = TorusWithFilter(f);
        const Image img = Render(RenderScene(s, ro), test::HitsAo(4, 4)).beauty;
        const double d = MeanAbsoluteDifference(img, base);
        std::printf("%s: mean absolute difference to no key %.5f\n", f, d);
        if (std::string(f) == "normal")
            EXPECT_LT(d, 1e-6);
        else
            EXPECT_GT(d, 1e-3);
    }
}

// The filtered reconstructions read integer bins in a fixed order (the store's texel level keeps
// what any thread filtered from them, the same value whichever thread it was): the same image on
// 1 and 2 threads, bit for bit, over 4 passes, AO and light.
TEST(MaterialFilter, DeterministicAcrossThreadCounts) {
    for (const char* f : {"none", "gaussian", "regression"}) {
        SCOPED_TRACE(f);
        Scene s = TorusWithFilter(f);
        EnvironmentLight env;
        env.constant = glm::vec3(1.0f);
        s.environments.push_back(env);
        const RenderScene rs(s, {});
        for (const RenderOptions& o : {test::HitsAo(16, 2), test::PathOptions(16, 1, true, true)})
            EXPECT_EQ(test::RenderOnThreads(rs, o, 1).data, test::RenderOnThreads(rs, o, 2).data);
    }
}

// Each filter on each hard cage, AO and binned light: finite, in range, and its relMSE against a
// per-hit reference (256 AO rays, or 64 paths per hit) at most 2x per hit's own at the same camera
// samples, plus 1e-4 where both are about 0 (an evenly lit cage). Measured: none at 0.7-1.0x per
// hit (it bins at the hit's texel), gaussian and regression at 0.01-0.15x.
TEST(MaterialFilter, EveryFilterFiniteAndNearPerHitOnHardCages) {
    for (const char* name : test::kHardCages) {
        for (const bool path : {false, true}) {
            Scene s = test::OneObjectScene(test::LoadMesh(name));
            if (path) {
                EnvironmentLight env;
                env.constant = glm::vec3(1.0f);
                s.environments.push_back(env);
            }
            RenderSceneOptions ro;
            ro.needLights = path;
            const RenderOptions refOpt =
                path ? test::PathOptions(4, 64, false, true) : test::AoOptions(4, 256);
            const RenderOptions perHitOpt =
                path ? test::PathOptions(4, 1, false, true) : test::AoOptions(4, 4);
            const RenderOptions hitsOpt =
                path ? test::PathOptions(4, 1, true, true) : test::HitsAo(4, 4);
            const RenderScene rs0(s, ro);
            const Image ref = Render(rs0, refOpt).beauty;
            const double perHit = RelMSE(Render(rs0, perHitOpt).beauty, ref);
            for (const char* f : kBinFilters) {
                SCOPED_TRACE(std::string(name) + (path ? " path " : " ao ") + f);
                Scene sf = s;
                sf.materials[0].cacheFilter = f;
                const RenderScene rs(sf, ro);
                const RenderResult r = Render(rs, hitsOpt);
                EXPECT_TRUE(test::AllFiniteIn(r.beauty, 0.0f, path ? 1e3f : 1.0f));
                const double e = RelMSE(r.beauty, ref);
                std::printf("%s %s %s: relMSE %.4f, per hit %.4f\n", name, path ? "path" : "ao", f,
                            e, perHit);
                EXPECT_LE(e, 2.0 * perHit + 1e-4);
                EXPECT_EQ(r.stats.hitBinsDropped, 0u);
            }
        }
    }
}

// Every filter x integrator: the ones the render cannot apply are refused, naming the scene file
// and the material; the others pass. softshadow applies to the direct integrator on the grid
// only; the other filters to ao and path anywhere, and to direct at the hits only.
TEST(MaterialFilter, InapplicableCombinationsAreRefused) {
    Scene s = TorusWithFilter("");
    s.path = "scene.json";
    s.materials.back().name = "clay";
    struct Case {
        IntegratorKind k;
        bool hits;
    };
    const Case cases[] = {{IntegratorKind::AO, true},     {IntegratorKind::AO, false},
                          {IntegratorKind::Path, true},   {IntegratorKind::Path, false},
                          {IntegratorKind::Direct, true}, {IntegratorKind::Direct, false}};
    for (const char* f : {"none", "normal", "gaussian", "regression", "softshadow"}) {
        s.materials.back().cacheFilter = f;
        for (const Case& c : cases) {
            RenderOptions o;
            o.integrator = c.k;
            o.texture.enabled = true;
            o.texture.samples = c.hits ? TextureSamples::Hits : TextureSamples::Grid;
            o.texture.cacheDirect = true;  // direct light binned at the hits
            const bool soft = std::string(f) == "softshadow";
            const bool applies = soft ? c.k == IntegratorKind::Direct && !c.hits
                                      : c.k != IntegratorKind::Direct || c.hits;
            SCOPED_TRACE(std::string(f) + " " + IntegratorName(c.k) + (c.hits ? " hits" : " grid"));
            if (applies) {
                EXPECT_NO_THROW(CheckMaterialFilters(s, o));
                continue;
            }
            try {
                CheckMaterialFilters(s, o);
                ADD_FAILURE() << "not refused";
            } catch (const InputError& e) {
                const std::string what = e.what();
                EXPECT_EQ(what.rfind("scene.json: material 'clay': filter " + std::string(f), 0),
                          0u)
                    << what;
                EXPECT_EQ(what.find('\n'), std::string::npos) << what;
            }
        }
    }
    // Without texture space, or with an integrator that caches nothing, a filter is no error.
    s.materials.back().cacheFilter = "softshadow";
    RenderOptions o;
    o.integrator = IntegratorKind::AO;
    EXPECT_NO_THROW(CheckMaterialFilters(s, o));
    o.texture.enabled = true;
    o.integrator = IntegratorKind::EyeLight;
    EXPECT_NO_THROW(CheckMaterialFilters(s, o));
}

}  // namespace
}  // namespace texcache
