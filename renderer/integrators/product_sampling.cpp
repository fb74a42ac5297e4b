// SPDX-License-Identifier: Apache-2.0
#include "renderer/integrators/product_sampling.h"

#include <cmath>

#include "renderer/texture_space/texture_space.h"

namespace texcache {

namespace {

bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

}  // namespace

bool BuildProductRecord(const EnvironmentMap& env, const Bsdf& bsdf, glm::vec3 woWorld,
                        ProductRecord* out) {
    constexpr int N = ProductRecord::kN;
    constexpr int kSub = 2;  // f cos is averaged over kSub x kSub points of a cell
    out->valid = 0;
    const Frame& f = bsdf.frame();
    const glm::vec2 alpha = bsdf.AlphaXY();
    if (!bsdf.HasSpecular() || !(std::max(alpha.x, alpha.y) >= kMinProductAlpha)) return false;
    if (!Finite(f.s) || !Finite(f.t) || !Finite(f.n) || !Finite(woWorld) ||
        !std::isfinite(alpha.x + alpha.y) || !(glm::dot(woWorld, f.n) > 0.0f))
        return false;
    const EnvironmentMap::LuminancePyramid& p = env.Pyramid();

    // The window: centred on the mirror direction, 16 cells of the finest level that spans the
    // lobe, whose radius is taken as 2 atan(2 alpha) (the reflected directions of half-vectors
    // out to 2 alpha: ~90% of a GGX lobe's mass) across the longer axis.
    const glm::vec3 mirror = glm::reflect(-woWorld, f.n);
    const float radius = std::min(2.0f * std::atan(4.0f * std::max(alpha.x, alpha.y)), kPiF);
    const glm::vec2 uvMirror = env.DirToUv(mirror);
    const float sinMirror = std::max(std::sin(kPiF * uvMirror.y), 1e-3f);
    const float spanV = 2.0f * radius / kPiF;                                       // of [0,1]
    const float spanU = std::min(2.0f * radius / sinMirror / (2.0f * kPiF), 1.0f);  // of [0,1]
    int level = p.NumLevels() - 1;
    for (int l = 0; l < p.NumLevels(); ++l) {
        const auto& lv = p.levels[size_t(l)];
        const bool fitsU = spanU >= 1.0f ? lv.width <= N : spanU * float(lv.width) <= float(N - 1);
        if (fitsU && spanV * float(lv.height) <= float(N - 1)) {
            level = l;
            break;
        }
    }
    const int W = p.levels[size_t(level)].width, H = p.levels[size_t(level)].height;
    out->level = level;
    out->width = W;
    out->height = H;
    out->x0 = W <= N ? 0 : int(std::floor(uvMirror.x * float(W) - 0.5f * float(N)));
    out->x0 = ((out->x0 % W) + W) % W;
    out->y0 =
        H <= N ? 0 : std::clamp(int(std::floor(uvMirror.y * float(H) - 0.5f * float(N))), 0, H - N);

    // A cell's solid angle is proportional to the sine of its polar angle (its rows' mean).
    float sinTheta[N];
    for (int j = 0; j < N; ++j)
        sinTheta[j] = std::sin(kPiF * (float(out->y0 + j) + 0.5f) / float(H));
    double weights[N][N], rowSums[N], total = 0.0;
    for (int j = 0; j < N; ++j) {
        const int y = out->y0 + j;
        rowSums[j] = 0.0;
        for (int i = 0; i < N; ++i) {
            float w = 0.0f;
            if (y < H && i < W) {
                const int x = (out->x0 + i) % W;
                float b = 0.0f;
                for (int sy = 0; sy < kSub; ++sy)
                    for (int sx = 0; sx < kSub; ++sx) {
                        const float u = (float(x) + (float(sx) + 0.5f) / float(kSub)) / float(W);
                        const float v = (float(y) + (float(sy) + 0.5f) / float(kSub)) / float(H);
                        const glm::vec3 d = env.UvToDir({u, v});
                        const float c = glm::dot(d, f.n);
                        if (c > 0.0f) b += Luminance(bsdf.Eval(woWorld, d)) * c;
                    }
                w = b * p.Texel(level, x, y) * sinTheta[j];
            }
            if (!(w > 0.0f) || !std::isfinite(w)) w = 0.0f;  // NaN never enters a record
            weights[j][i] = double(w);
            rowSums[j] += double(w);
        }
        total += rowSums[j];
    }
    if (!(total > 0.0) || !std::isfinite(total)) return false;
    // Cumulative sums in 16-bit units (see ProductRecord): a cell's probability is the difference
    // of two rounded values, so what Sample draws and what Pdf reports stay the same numbers.
    auto quantize = [](double cumulative, double sum) {
        return uint16_t(std::lround(std::clamp(cumulative / sum, 0.0, 1.0) * ProductRecord::kOne));
    };
    double acc = 0.0;
    for (int j = 0; j < N; ++j) {
        acc += rowSums[j];
        out->marginal[j] = quantize(acc, total);
        double rowAcc = 0.0;
        for (int i = 0; i < N; ++i) {
            rowAcc += weights[j][i];
            out->rows[j][i] = rowSums[j] > 0.0 ? quantize(rowAcc, rowSums[j])
                                               : uint16_t((i + 1) * int(ProductRecord::kOne) / N);
        }
        out->rows[j][N - 1] = uint16_t(ProductRecord::kOne);
    }
    out->marginal[N - 1] = uint16_t(ProductRecord::kOne);
    out->valid = 1;
    return true;
}

ProductRecordCache::ProductRecordCache(const RenderScene& rs, size_t bytes, float lodBias)
    : rs_(rs), cache_(bytes), lodBias_(lodBias) {
    const Scene& scene = rs.scene();
    for (size_t o = 0; o < scene.objects.size(); ++o) {
        const ControlCage& cage = scene.meshes[scene.objects[o].mesh];
        glm::vec3 lo, hi;
        CageBounds(cage, &lo, &hi);
        meshOf_.push_back(
            cache_.AddMesh(cage, MipZeroTexelSize(lo, hi), rs.SharedTopology(int(o))));
    }
}

void ProductRecordCache::Build(const SurfaceInteraction& si, const Bsdf& bsdf, glm::vec3 eye,
                               const SampleRequest& texel, ProductRecord* out) const {
    // The record of the texel's centre as the camera sees it: every hit of the texel gets the
    // same record whichever builds it (same image for any thread count). Material parameters
    // are the hit's (constant per material in the scenes that use records).
    SurfaceSample ss;
    glm::vec3 n = si.N, tangent = si.dPdu, wo = glm::normalize(eye - si.P);
    if (rs_.EvalSurface(si.object, {texel.face, texel.u, texel.v}, 0.0f, &ss) &&
        glm::dot(ss.N, ss.N) > 0.0f) {
        n = glm::normalize(ss.N);
        tangent = ss.dPdu;
        wo = glm::normalize(eye - ss.P);
        if (glm::dot(n, wo) < 0.0f) n = -n;  // the side the camera sees
    }
    const glm::vec2 roughness = glm::sqrt(bsdf.AlphaXY());
    const Bsdf lobe(n, n, glm::vec3(0.0f), true, roughness, bsdf.F0(), tangent);
    BuildProductRecord(*rs_.environment(), lobe, wo, out);
}

}  // namespace texcache
