// SPDX-License-Identifier: Apache-2.0
// Anisotropic GGX (against the isotropic functions, furnace) and product sampling records
// (renderer/integrators/product_sampling.h): the inverse warp, pdf normalisation, chi-square of
// samples against the pdf, and the fallbacks (black environment, mirror lobe, non-finite input).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <vector>

#include "renderer/image/image.h"
#include "renderer/integrators/bsdf.h"
#include "renderer/integrators/product_sampling.h"
#include "renderer/integrators/sampling.h"
#include "renderer/render.h"
#include "renderer/scene/envmap.h"
#include "renderer/scene/scene_loader.h"

namespace texcache {
namespace {

const glm::vec3 kN(0.0f, 1.0f, 0.0f);  // +Y up, as the environment's convention

EnvironmentMap StudioMap() {
    return EnvironmentMap::Load(std::string(TEXCACHE_SOURCE_DIR) + "/scenes/envmaps/studio.exr",
                                1.0f, 0.0f);
}

// A random outgoing direction above the +Y surface, at least about `lift` above its horizon.
glm::vec3 RandomWo(Rng& rng, float lift) {
    const glm::vec3 w =
        glm::normalize(SampleCosineHemisphere(rng.Next2D()) + glm::vec3(0, 0, lift));
    return {w.x, w.z, w.y};  // local +Z to +Y
}

// A brushed-metal lobe on a surface facing +Y, tangent along +X.
Bsdf BrushedLobe(glm::vec2 roughness) {
    return Bsdf(kN, kN, glm::vec3(0.0f), true, roughness, glm::vec3(0.9f), glm::vec3(1, 0, 0));
}

TEST(AnisotropicGgx, ReducesToIsotropicWhenAlphasAreEqual) {
    Rng rng(1, 0);
    for (float a : {0.02f, 0.1f, 0.4f, 1.0f}) {
        const glm::vec2 aa(a);
        for (int k = 0; k < 2000; ++k) {
            const glm::vec3 wo =
                glm::normalize(SampleCosineHemisphere(rng.Next2D()) + glm::vec3(0, 0, 0.05f));
            const glm::vec3 wi = SampleCosineHemisphere(rng.Next2D());
            const glm::vec3 m = glm::normalize(wo + wi);
            const glm::vec2 u = rng.Next2D();
            // D's isotropic form (a^2 / (pi (c^2 (a^2 - 1) + 1)^2)) cancels at small alpha: 1e-3.
            auto near = [](float x, float y) {
                return std::abs(x - y) <= 1e-3f * std::abs(y) + 1e-6f;
            };
            ASSERT_TRUE(near(GgxD(m, aa), GgxD(m, a))) << a;
            ASSERT_TRUE(near(GgxG(wo, wi, aa), GgxG(wo, wi, a))) << a;
            ASSERT_TRUE(near(GgxG1(wo, aa), GgxG1(wo, a))) << a;
            ASSERT_TRUE(near(GgxPdfReflect(wo, wi, aa), GgxPdfReflect(wo, wi, a))) << a;
            const glm::vec3 ma = GgxSampleVisibleNormal(wo, aa, u),
                            mi = GgxSampleVisibleNormal(wo, a, u);
            ASSERT_LT(glm::length(ma - mi), 1e-5f) << a;
        }
    }
}

// White furnace: a GGX lobe with F0 = 1 and no diffuse part reflects at most all the light,
// and (single scattering) loses only a little at moderate roughness: its albedo, estimated with
// 2^16 visible-normal samples per case, is within [0.85, 1.005] for roughness <= 0.6 per axis
// (measured 0.93-1.0) and the anisotropic estimate lies between its two axes' isotropic ones.
TEST(AnisotropicGgx, WhiteFurnace) {
    auto albedo = [](glm::vec2 r, glm::vec3 wo) {
        const Bsdf b(kN, kN, glm::vec3(0.0f), true, r, glm::vec3(1.0f), glm::vec3(1, 0, 0));
        Rng rng(3, 0);
        double sum = 0.0;
        const int n = 1 << 16;
        for (int i = 0; i < n; ++i) {
            glm::vec3 wi, w;
            float pdf;
            if (b.SampleSpecular(wo, rng.Next2D(), &wi, &w, &pdf)) sum += w.x;
        }
        return sum / n;
    };
    for (const glm::vec3 wo : {kN, glm::normalize(glm::vec3(0.6f, 0.5f, 0.2f))}) {
        for (glm::vec2 r : {glm::vec2(0.2f), glm::vec2(0.6f, 0.25f), glm::vec2(0.25f, 0.6f)}) {
            const double a = albedo(r, wo);
            EXPECT_GE(a, 0.85) << r.x << " " << r.y;
            EXPECT_LE(a, 1.005) << r.x << " " << r.y;
            if (r.x != r.y) {
                const double lo = std::min(albedo(glm::vec2(r.x), wo), albedo(glm::vec2(r.y), wo));
                const double hi = std::max(albedo(glm::vec2(r.x), wo), albedo(glm::vec2(r.y), wo));
                EXPECT_GE(a, lo - 0.005);
                EXPECT_LE(a, hi + 0.005);
            }
        }
    }
    // Eval agrees with the sampler's weight: E[f cos / pdf] over BSDF samples = albedo.
    const Bsdf b = BrushedLobe(glm::vec2(0.6f, 0.25f));
    const glm::vec3 wo = glm::normalize(glm::vec3(0.3f, 0.8f, -0.2f));
    Rng rng(4, 0);
    double viaEval = 0.0, viaWeight = 0.0;
    const int n = 1 << 16;
    for (int i = 0; i < n; ++i) {
        glm::vec3 wi, w;
        float pdf;
        if (!b.SampleSpecular(wo, rng.Next2D(), &wi, &w, &pdf)) continue;
        viaWeight += w.x;
        viaEval += b.Eval(wo, wi).x * glm::dot(wi, kN) / b.PdfSpecular(wo, wi);
    }
    EXPECT_NEAR(viaEval / n, viaWeight / n, 1e-3 * viaWeight / n);
}

// Integrates a record's pdf over the sphere and counts how often its draws fail: the two must
// add up to 1.
struct RecordCheck {
    double integral = 0.0, failed = 0.0;
};
RecordCheck CheckRecord(const EnvironmentMap& env, const ProductRecord& r) {
    // The density is constant over each texel of the map in (u, v), times 1 / sin(theta), and
    // d(omega) = 2 pi^2 sin(theta) du dv: one point per texel integrates it exactly.
    RecordCheck c;
    const auto& base = env.Pyramid().levels.front();
    for (int y = 0; y < base.height; ++y)
        for (int x = 0; x < base.width; ++x) {
            const glm::vec2 uv((x + 0.5f) / base.width, (y + 0.5f) / base.height);
            c.integral += double(r.Pdf(env, env.UvToDir(uv))) * 2.0 * kPiF * kPiF *
                          std::sin(kPiF * uv.y) / (double(base.width) * base.height);
        }
    Rng rng(5, 0);
    const int m = 1 << 16;
    for (int i = 0; i < m; ++i) {
        glm::vec3 wi;
        float pdf;
        if (!r.Sample(env, rng.Next2D(), rng.Next1D(), &wi, &pdf)) c.failed += 1.0 / m;
    }
    return c;
}

TEST(ProductRecord, PdfIntegratesToOne) {
    const EnvironmentMap env = StudioMap();
    for (glm::vec2 rough : {glm::vec2(0.6f, 0.25f), glm::vec2(0.15f)})
        for (const glm::vec3 wo : {glm::normalize(glm::vec3(0.0f, 0.7f, 0.7f)),
                                   glm::normalize(glm::vec3(0.5f, 0.2f, -0.1f))}) {
            ProductRecord r;
            ASSERT_TRUE(BuildProductRecord(env, BrushedLobe(rough), wo, &r));
            const RecordCheck c = CheckRecord(env, r);
            EXPECT_NEAR(c.integral + c.failed, 1.0, 1e-3) << rough.x << " " << wo.y;
            EXPECT_LT(c.failed, 1e-3);
        }
}

// Chi-square: 2^18 draws of a record, counted per window cell, against the record's cell
// probabilities (cells expecting >= 5 draws), below the 0.999 quantile of chi-square at that many
// degrees of freedom; and each draw's reported density is the record's Pdf there.
TEST(ProductRecord, SamplesFollowThePdf) {
    const EnvironmentMap env = StudioMap();
    const glm::vec3 wo = glm::normalize(glm::vec3(0.2f, 0.6f, 0.5f));
    ProductRecord r;
    ASSERT_TRUE(BuildProductRecord(env, BrushedLobe(glm::vec2(0.6f, 0.25f)), wo, &r));
    constexpr int N = ProductRecord::kN;
    const auto& base = env.Pyramid().levels.front();
    std::vector<double> counts(N * N, 0.0);
    Rng rng(6, 0);
    const int draws = 1 << 18;
    int ok = 0, inconsistent = 0;
    for (int i = 0; i < draws; ++i) {
        glm::vec3 wi;
        float pdf;
        if (!r.Sample(env, rng.Next2D(), rng.Next1D(), &wi, &pdf)) continue;
        ++ok;
        // The density reported with a draw is the record's pdf there (but for draws on a texel
        // border, which float rounding can put in the neighbour).
        if (std::abs(pdf - r.Pdf(env, wi)) > 1e-3f * pdf) ++inconsistent;
        const glm::vec2 uv = env.DirToUv(wi);
        const int cx = std::min(int(uv.x * base.width), base.width - 1) >> r.level;
        const int cy = std::min(int(uv.y * base.height), base.height - 1) >> r.level;
        const int ci = (cx - r.x0 + r.width) % r.width, cj = cy - r.y0;
        ASSERT_TRUE(ci >= 0 && ci < N && cj >= 0 && cj < N);
        counts[size_t(cj) * N + ci] += 1.0;
    }
    EXPECT_LT(inconsistent, draws / 1000);
    double chi2 = 0.0;
    int dof = -1;
    for (int j = 0; j < N; ++j)
        for (int i = 0; i < N; ++i) {
            const double p = r.CellProbability(i, j);
            const double expected = p * ok;
            if (expected < 5.0) continue;
            const double d = counts[size_t(j) * N + i] - expected;
            chi2 += d * d / expected;
            ++dof;
        }
    EXPECT_GT(ok, draws - draws / 1000);
    EXPECT_GT(dof, 20);
    // Wilson-Hilferty: the 0.999 quantile of chi-square(dof) ~ dof (1 - 2/(9 dof) + 3.09 sqrt(2/(9
    // dof)))^3.
    const double k = dof,
                 q = k * std::pow(1.0 - 2.0 / (9.0 * k) + 3.09 * std::sqrt(2.0 / (9.0 * k)), 3.0);
    EXPECT_LT(chi2, q) << "dof " << dof;
}

TEST(ProductRecord, FallsBackCleanly) {
    const glm::vec3 wo = glm::normalize(glm::vec3(0.2f, 0.6f, 0.5f));
    ProductRecord r;
    // Black environment: nothing to sample, no record.
    EXPECT_FALSE(BuildProductRecord(EnvironmentMap::Constant(glm::vec3(0.0f)),
                                    BrushedLobe(glm::vec2(0.5f)), wo, &r));
    EXPECT_EQ(r.valid, 0u);
    const EnvironmentMap env = StudioMap();
    // Zero roughness (alpha clamps to 1e-3): a mirror gets no record.
    EXPECT_FALSE(BuildProductRecord(env, BrushedLobe(glm::vec2(0.0f)), wo, &r));
    EXPECT_EQ(r.valid, 0u);
    // wo below the surface, NaN wo, NaN normal: no record.
    EXPECT_FALSE(BuildProductRecord(env, BrushedLobe(glm::vec2(0.5f)), -wo, &r));
    EXPECT_FALSE(BuildProductRecord(env, BrushedLobe(glm::vec2(0.5f)), glm::vec3(NAN), &r));
    const Bsdf nanLobe(glm::vec3(NAN), kN, glm::vec3(0.0f), true, glm::vec2(0.5f), glm::vec3(0.9f));
    EXPECT_FALSE(BuildProductRecord(env, nanLobe, wo, &r));
    EXPECT_EQ(r.valid, 0u);
    // A diffuse material is not product sampled.
    EXPECT_FALSE(WantsProductSampling(
        Bsdf(kN, kN, glm::vec3(0.5f), false, glm::vec2(1.0f), glm::vec3(0.04f))));
    EXPECT_TRUE(WantsProductSampling(BrushedLobe(glm::vec2(0.5f))));
}

// NaN and Inf texels in a map (Load clamps them to 0) and extreme radiance never leave a
// non-finite number in a record.
TEST(ProductRecord, NanNeverEntersARecord) {
    const std::string path = ::testing::TempDir() + "product_nan_env.exr";
    Image img(64, 32, 3, 0.5f);
    img.At(10, 5)[0] = NAN;
    img.At(11, 5)[1] = INFINITY;
    img.At(40, 8)[2] = 3e38f;
    img.At(41, 8)[0] = -INFINITY;
    WriteImage(path, img);
    const EnvironmentMap env = EnvironmentMap::Load(path, 1.0f, 0.0f);
    Rng rng(7, 0);
    for (int k = 0; k < 200; ++k) {
        const glm::vec3 woW = RandomWo(rng, 0.01f);
        ProductRecord r;
        if (!BuildProductRecord(env, BrushedLobe(glm::vec2(0.5f, 0.1f)), woW, &r)) continue;
        for (int j = 0; j < ProductRecord::kN; ++j) {
            for (int i = 0; i < ProductRecord::kN; ++i) {
                const float pc = r.CellProbability(i, j);
                ASSERT_TRUE(std::isfinite(pc) && pc >= 0.0f && pc <= 1.0f);
            }
            ASSERT_EQ(r.marginal[ProductRecord::kN - 1], uint16_t(ProductRecord::kOne));
        }
        glm::vec3 wi;
        float pdf;
        if (r.Sample(env, rng.Next2D(), rng.Next1D(), &wi, &pdf)) {
            ASSERT_TRUE(std::isfinite(pdf));
        }
    }
    std::filesystem::remove(path);
}

// One shading point, no occlusion: the direct light integral of f cos L by MIS (light + BSDF
// sampling) and by product sampling (SampleProductLight + BSDF sampling) agree within 4 sigma of
// 2^15 samples each; the variances are printed (product sampling's: 0.14-0.35x MIS's at these
// six points).
TEST(ProductRecord, EstimatorAgreesWithMis) {
    const EnvironmentMap env = StudioMap();
    const Bsdf b = BrushedLobe(glm::vec2(0.6f, 0.25f));
    Rng rng(9, 0);
    for (int k = 0; k < 6; ++k) {
        const glm::vec3 wo = RandomWo(rng, 0.1f);
        ProductRecord r;
        ASSERT_TRUE(BuildProductRecord(env, b, wo, &r));
        const int n = 1 << 15;
        double mis = 0, pis = 0, mis2 = 0, pis2 = 0;
        for (int i = 0; i < n; ++i) {
            double em = 0, ep = 0;
            // light samples
            {
                glm::vec3 wi;
                float pdf;
                const glm::vec2 u = rng.Next2D();
                const glm::vec3 L = env.Sample(kN, u, &wi, &pdf);
                if (pdf > 0) {
                    const float w = PowerHeuristic(1, pdf, 1, b.Pdf(wo, wi));
                    em += Luminance(b.Eval(wo, wi) * L) * std::max(0.f, glm::dot(wi, kN)) * w / pdf;
                }
                float pp;
                glm::vec3 Li;
                if (SampleProductLight(r, env, kN, u, rng.Next1D(), &wi, &pp, &Li)) {
                    const float w = PowerHeuristic(1, pp, 1, b.Pdf(wo, wi));
                    ep += Luminance(b.Eval(wo, wi) * env.Eval(wi)) *
                          std::max(0.f, glm::dot(wi, kN)) * w / pp;
                }
            }
            {
                glm::vec3 wi, weight;
                float pdf;
                if (b.Sample(wo, rng.Next1D(), rng.Next2D(), &wi, &weight, &pdf)) {
                    const float L = Luminance(weight * env.Eval(wi));
                    em += L * PowerHeuristic(1, pdf, 1, env.Pdf(kN, wi));
                    ep += L * PowerHeuristic(1, pdf, 1, ProductLightPdf(r, env, kN, wi));
                }
            }
            mis += em, mis2 += em * em, pis += ep, pis2 += ep * ep;
        }
        mis /= n, pis /= n;
        const double vm = mis2 / n - mis * mis, vp = pis2 / n - pis * pis;
        printf("k %d mis %g (var %g) pis %g (var %g)\n", k, mis, vm, pis, vp);
        EXPECT_NEAR(pis, mis, 4.0 * std::sqrt((vm + vp) / n));
    }
}
// The three light samplings render the same image: on brushed.json (direct light, 24x18 pixels,
// 16 spp) each method's image mean is within 4 standard errors of MIS's. The standard error of a
// mean comes from two renders of different seeds: per pixel, (a - b)^2 / 2 estimates the
// variance of one render's pixel, and pixels are independent.
TEST(ProductSampling, MethodsAgreeOnTheImageMean) {
    std::vector<std::string> warnings;
    const Scene scene =
        LoadScene(std::string(TEXCACHE_SOURCE_DIR) + "/scenes/brushed.json", &warnings);
    RenderScene rs(scene, {});
    struct Estimate {
        double mean, var;
    };
    auto estimate = [&](LightSampling m) {
        RenderOptions o = RenderOptionsFrom(scene.settings);
        o.width = 24, o.height = 18, o.spp = 16, o.progress = false;
        o.lightSampling = m;
        double sum = 0.0, d2 = 0.0;
        Image img[2];
        for (int k = 0; k < 2; ++k) {
            o.seed = 100 + k;
            const RenderResult r = Render(rs, o);
            img[k] = r.beauty;
            if (m == LightSampling::Cpis) {
                EXPECT_GT(r.stats.psr.built, 0u);
                EXPECT_GT(r.stats.psr.hits, r.stats.psr.built);
                EXPECT_GT(r.stats.psrBytes, 0u);
            } else {
                EXPECT_EQ(r.stats.psrBytes, 0u);  // no record memory unless cached
            }
        }
        const size_t n = img[0].data.size();
        for (size_t i = 0; i < n; ++i) {
            sum += 0.5 * (img[0].data[i] + img[1].data[i]);
            d2 += 0.5 * double(img[0].data[i] - img[1].data[i]) * (img[0].data[i] - img[1].data[i]);
        }
        // Mean of the two renders: variance of one render's mean / 2.
        return Estimate{sum / double(n), d2 / double(n) / double(n) / 2.0};
    };
    const Estimate mis = estimate(LightSampling::Mis);
    EXPECT_GT(mis.mean, 0.01);
    for (LightSampling m : {LightSampling::Pis, LightSampling::Cpis}) {
        const Estimate e = estimate(m);
        EXPECT_NEAR(e.mean, mis.mean, 4.0 * std::sqrt(e.var + mis.var)) << LightSamplingName(m);
    }
}

}  // namespace
}  // namespace texcache
