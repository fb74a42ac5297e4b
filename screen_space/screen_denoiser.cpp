// SPDX-License-Identifier: Apache-2.0
// The screen-space stage (see screen_denoiser.h for what each method does).
//
// Design note. A frame goes through: Prepare (one sweep over the frame's AoS buffers into padded
// SoA planes: guides, demodulated components, remodulation factors) -> motion vectors -> the
// temporal passes (temporal.cpp) -> the fused a-trous levels (kernels.cpp) -> Compose. Two orders
// are used:
//   SVGF order (every component; the Reliable visibility unless VisibilityOrder::Zeng): the
//     noisy input is accumulated with the history first (along the method's motion vectors,
//     clamped to mu +- k sigma when the method clamps), its luminance moments give the variance
//     that steers the a-trous iterations, and the output of the first iteration is the next
//     history (for the Reliable indirect with cones the history is the cones). The Reliable
//     visibility goes along the shadow vectors; where one is within a quarter pixel of the
//     traditional vector, the traditional vector and its taps are used, unclamped, so that where
//     no shadow moves over its receiver the visibility is exactly the baseline's; elsewhere the
//     history is clamped at 3 sigma (TrustAgreeingShadowVectors). A frame in which only the
//     camera moved (FrameBuffers::shadowsStill) has every shadow vector on the traditional one
//     by construction: the traditional vectors are taken as they are, without eq. 3's passes.
//   Zeng order (VisibilityOrder::Zeng): the current frame is filtered spatially first (c~_i, the
//     a-trous with a spatial variance, as SpatialOnly), the history fetched with the shadow
//     vector is clamped to mu +- 3 sigma of c~_i and blended (eq. 2 with alpha^V), then the
//     clean-up runs with std min(w_A + w_C, 5) (eqs. 7-8); its output is the next history.
//     It is not the default: on a camera flying over a static scene (shadow vectors =
//     traditional ones) it keeps Reliable above the plain baseline, because a spatial filter
//     that only ever sees 1 spp keeps its blur however many frames are averaged (see glossy
//     below). Elsewhere the two orders are within a few percent (docs/screen-space.md and
//     results/temporal.md have the figures).
//     Zeng et al. use a 31x31 joint bilateral sized by the penumbra (after Liu et al.) for
//     c~_i; ours is the variance-guided a-trous of SpatialOnly, because a penumbra-sized filter
//     on geometry guides alone does worse than the a-trous with no history at all where an
//     environment light's visibility is noisy everywhere, not only in penumbrae, which leaves
//     Reliable worse than the baseline before any history exists (docs/screen-space.md). The
//     paper's point is the motion vectors, and its Sec. 7 names the spatial filter as orthogonal.
// Why not Zeng's order for glossy too: a spatial filter that only ever sees 1 spp keeps its bias
// however many frames are averaged, while accumulating first lets the a-trous sharpen as the
// temporal variance drops (ctest -R ScreenSpaceTemporal.StaticNoisySceneConverges; figures in
// docs/screen-space.md); Zeng et al. use a BRDF-lobe-sized glossy filter we do not have.
// The glossy component keeps the stochastic glossy vectors; its a-trous, which runs after the
// blend, takes the clean-up's place. Glossy and indirect histories are not clamped by default:
// in this order the clamp is against 1-spp samples, not against Zeng's filtered c~_i, and it
// makes Reliable worse than the unclamped baseline where the vectors are right
// (results/temporal_ablation.md; reliableGlossyClampK / reliableIndirectClampK turn it on).
// All a-trous work of a frame runs as one pass per level over every component that needs it, so
// the depth/normal weights are computed once per tap. With indirectCones (off by default: its
// raw cone history is noisier than SVGF's filtered colour history on every scene of the
// temporal experiment, results/temporal_ablation.md) the Reliable indirect keeps incident
// radiance in 6 cones per pixel as its history (Sec. 4.3): history cones are moved into the
// current pixel's cone frame with Mazonka overlap weights and blended per cone; the a-trous then
// runs on their diffuse shading (ShadeCones), 3 channels instead of 18 (filtering every cone
// spatially would cost about as much as the whole stage's filtering at 1080p).
#include "screen_space/screen_denoiser.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <limits>
#include <random>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "screen_space/denoiser_state.h"
#include "screen_space/internal.h"
#include "texcache/enum_names.h"
#include "texcache/error.h"

namespace texcache::screen {

using namespace internal;

const char* MethodName(Method m) {
    switch (m) {
        case Method::SpatialOnly:
            return "spatial";
        case Method::Baseline:
            return "baseline";
        case Method::BaselineClamp:
            return "baseline+clamp";
        case Method::Reliable:
            return "reliable";
    }
    return "?";
}

namespace {
constexpr EnumName<Method> kMethodKeys[] = {{"spatial", Method::SpatialOnly},
                                            {"baseline", Method::Baseline},
                                            {"clamp", Method::BaselineClamp},
                                            {"reliable", Method::Reliable}};
}  // namespace

std::string MethodKeys() {
    return EnumNames(kMethodKeys);
}

Method ParseMethodKey(std::string_view key, const std::string& where) {
    return ParseEnum(kMethodKeys, key, where, "denoise method");
}

const char* MethodKey(Method m) {
    return EnumToName(kMethodKeys, m);
}

namespace {

// Below this a remodulation factor (F_beta, albedo) is not divided out: nothing to recover
// (the indirect light's albedo: PrepIndirectImpl says what such a channel takes instead).
constexpr float kMinRemod = 1e-3f;

using Clock = std::chrono::steady_clock;

double CpuMs() {
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

// Charges the wall-clock and process-CPU time since the last lap to one pass.
class PassClock {
public:
    PassClock(StageTimings* wall, StageTimings* cpu) : wall_(wall), cpu_(cpu) {
        *wall = StageTimings{}, *cpu = StageTimings{};
        t0_ = last_ = Clock::now(), c0_ = lastCpu_ = CpuMs();
    }
    void Lap(double StageTimings::*pass) {
        const auto now = Clock::now();
        const double c = CpuMs();
        wall_->*pass += std::chrono::duration<double, std::milli>(now - last_).count();
        cpu_->*pass += c - lastCpu_;
        last_ = now, lastCpu_ = c;
    }
    /// Charges a nested stage's passes (timed by itself) to the same passes.
    void Charge(const StageTimings& wall, const StageTimings& cpu) {
        AddPasses(wall_, wall), AddPasses(cpu_, cpu);
        last_ = Clock::now(), lastCpu_ = CpuMs();
    }
    void Finish() {
        wall_->total = std::chrono::duration<double, std::milli>(last_ - t0_).count();
        cpu_->total = lastCpu_ - c0_;
    }

private:
    static void AddPasses(StageTimings* to, const StageTimings& t) {
        for (double StageTimings::*p :
             {&StageTimings::prepare, &StageTimings::traditionalMotion,
              &StageTimings::reliableMotion, &StageTimings::temporal, &StageTimings::spatial,
              &StageTimings::cleanup, &StageTimings::compose})
            to->*p += t.*p;
    }
    StageTimings* wall_;
    StageTimings* cpu_;
    Clock::time_point t0_, last_;
    double c0_, lastCpu_;
};

}  // namespace

void ScreenSpaceDenoiser::State::Resize(int width, int height) {
    w = width, h = height;
    for (Guides& g : guides) g.Resize(w, h);
    for (ComponentPlanes& c : comp) {
        for (int k = 0; k < 3; ++k) c.v[k].Resize(w, h), c.remod[k].Resize(w, h, 1.0f);
        c.valid.Resize(w, h);
        for (const Plane*& r : c.res) r = nullptr;
    }
    for (auto& hc : hist)
        for (History& hh : hc) {
            for (Plane& p : hh.c) p.Resize(w, h);
            hh.m1.Resize(w, h), hh.m2.Resize(w, h), hh.len.Resize(w, h);
            hh.cones.Assign(0, 0.0f);
            hh.valid = false;
        }
    for (ComponentScratch& sc : scratch) {
        for (int k = 0; k < 3; ++k)
            sc.t[k].Resize(w, h), sc.a[k].Resize(w, h), sc.b[k].Resize(w, h),
                sc.out[k].Resize(w, h);
        sc.tVar.Resize(w, h), sc.aVar.Resize(w, h), sc.bVar.Resize(w, h), sc.outVar.Resize(w, h);
    }
    for (MotionField* m : {&trad, &shadow, &glossy, &occl}) m->Resize(w, h);
    shadowAlpha.Resize(w, h), sigma.Resize(w, h), visClampK.Resize(w, h), cachedVis.Resize(w, h);
    occluder.Resize(w, h, -1);
    for (Plane& p : splat) p.Resize(w, h);
    zeroRow.assign(size_t(w) + 2 * kPad, 0);
    hasPrev = false;
}

// ---- Construction ----------------------------------------------------------------------------

namespace {

void CheckSettings(const DenoiserSettings& s) {
    const std::string where = "DenoiserSettings";
    auto fail = [&](const std::string& what) { throw InputError(where, what); };
    if (!(s.alpha > 0.0f && s.alpha <= 1.0f))
        fail("alpha must be in (0, 1], got " + std::to_string(s.alpha));
    if (!(s.baselineClampK > 0.0f) || !(s.reliableClampK > 0.0f))
        fail("clamping k must be positive");
    if (!(s.reliableGlossyClampK >= 0.0f) || !(s.reliableIndirectClampK >= 0.0f))
        fail("reliableGlossyClampK and reliableIndirectClampK must be non-negative (0: none)");
    if (s.atrousLevels < 1 || s.atrousLevels > 5)
        fail("atrousLevels must be in 1..5 (steps up to 16), got " +
             std::to_string(s.atrousLevels));
    if (!(s.sigmaLuminance > 0.0f) || !(s.sigmaDepth > 0.0f) || !(s.normalPower >= 0.0f))
        fail("sigmaLuminance and sigmaDepth must be positive, normalPower non-negative");
    if (s.shadowSplatRadius < 0 || s.shadowSplatRadius > 64)
        fail("shadowSplatRadius must be in 0..64, got " + std::to_string(s.shadowSplatRadius));
    if (!(s.shadowFalloffSigma > 0.0f)) fail("shadowFalloffSigma must be positive");
    if (s.shadowFalloff && s.reliableVisibilityOrder != VisibilityOrder::Zeng)
        fail(
            "shadowFalloff (eq. 4's alpha^V) weights Zeng's visibility blend: it needs "
            "reliableVisibilityOrder = Zeng");
    if (!(s.glossyLobeScale >= 0.0f) || !(s.maxGlossyJitter >= 0.0f))
        fail("glossyLobeScale and maxGlossyJitter must be non-negative");
    if (s.brdfSamples < 1) fail("brdfSamples must be at least 1");
    if (s.halfResolutionRows < 0)
        fail("halfResolutionRows must be non-negative (0: never), got " +
             std::to_string(s.halfResolutionRows));
}

}  // namespace

ScreenSpaceDenoiser::ScreenSpaceDenoiser(const DenoiserSettings& settings)
    : ScreenSpaceDenoiser(settings, nullptr) {}

ScreenSpaceDenoiser::ScreenSpaceDenoiser(const DenoiserSettings& settings,
                                         std::shared_ptr<const BrdfPreintegration> brdf)
    : s_(std::make_unique<State>()) {
    CheckSettings(settings);
    s_->set = settings;
    s_->brdf = std::move(brdf);
    std::mt19937 rng(settings.seed);
    std::normal_distribution<float> nd(0.0f, 1.0f);
    s_->gauss.resize(2 * 4096);
    for (float& g : s_->gauss) g = nd(rng);
}

ScreenSpaceDenoiser::~ScreenSpaceDenoiser() = default;

void ScreenSpaceDenoiser::Reset() {
    if (s_->half) s_->half->Reset();
    s_->hasPrev = false;
    for (auto& hc : s_->hist)
        for (History& hh : hc) hh.valid = false;
}

void ScreenSpaceDenoiser::SetStillView(bool still) {
    if (s_->half) s_->half->SetStillView(still);
    if (!still)
        s_->stillFrames = -1;
    else if (s_->stillFrames < 0)
        s_->stillFrames = 0;
}

const StageTimings& ScreenSpaceDenoiser::Timings() const {
    return s_->timings;
}

const StageTimings& ScreenSpaceDenoiser::CpuTimings() const {
    return s_->cpuTimings;
}

const BrdfPreintegration& ScreenSpaceDenoiser::Brdf() {
    if (!s_->brdf) s_->brdf = std::make_shared<BrdfPreintegration>(s_->set.brdfSamples);
    return *s_->brdf;
}

// ---- Input checks and preparation ------------------------------------------------------------

namespace {

void CheckInputs(const FrameBuffers& f, Method m, Demodulation d, VisibilityOrder order) {
    const std::string where = "ScreenSpaceDenoiser::Denoise";
    auto need = [&](size_t size, const char* buffer, const char* why) {
        if (size == 0)
            throw InputError(where, std::string("buffer '") + buffer + "' is missing (" + why +
                                        ", method '" + MethodName(m) + "')");
    };
    if (d == Demodulation::On) {
        if (!f.glossy.empty()) {
            need(f.specular.size(), "specular", "BRDF demodulation of glossy");
            need(f.roughness.size(), "roughness", "BRDF demodulation of glossy");
        }
        if (!f.indirect.empty()) need(f.albedo.size(), "albedo", "albedo demodulation");
    }
    if (m == Method::SpatialOnly) return;
    // Left empty where nothing but the camera moved: the current frame's then.
    if (!f.shadowsStill) {
        need(f.prevPosition.size(), "prevPosition", "motion vectors");
        need(f.prevNormal.size(), "prevNormal", "motion vectors");
    }
    if (m != Method::Reliable) return;
    // With the shadows where they were, the SVGF order takes the traditional vectors.
    if (!f.shadowsStill || order != VisibilityOrder::Svgf) {
        need(f.prevBlocker.size(), "prevBlocker", "shadow motion vectors");
        need(f.prevLightSample.size(), "prevLightSample", "shadow motion vectors");
    }
    if (!f.glossy.empty()) {
        need(f.glossyHit.size(), "glossyHit", "glossy motion vectors");
        if (!f.shadowsStill) need(f.prevGlossyHit.size(), "prevGlossyHit", "glossy motion vectors");
        need(f.roughness.size(), "roughness", "glossy motion vectors");
    }
    if (!f.indirect.empty() && !f.cones.empty())
        need(f.albedo.size(), "albedo", "shading the indirect cones");
}

// ---- Preparation kernels: one row each, everything read through plain pointers and written
// to local arrays first, so that GCC vectorizes them (the frame's vec3 buffers become strided
// loads, the BRDF table lookups gathers); validity is carried as 0/1 floats (GCC 12 gives up on
// loops that mix boolean widths).

constexpr int kPrepChunk = 256;

// Guides and visibility of one row.
struct GuideRow {
    int w;
    bool stream;       // StoreRow
    const float* pos;  // xyz interleaved
    const float* nrm;
    const float* depth;
    const int32_t* id;
    const float* vis;
    // The first group (PrepGuidesRest) or the second (PrepGuidesDepth) alone at half
    // resolution: it keeps only the depth and validity as planes (DepthTolRow reads them on
    // the rows above and below) and prepares the rest row by row where it is used
    // (UpsampleCompose).
    float *px, *py, *pz, *nx, *ny, *nz, *vv, *vok;
    int32_t* oid;
    float* dz;
    uint8_t* ok;
};
// Rest: the first group (px .. oid); Depth: dz and ok. Each variant computes only what it
// writes: half resolution's depth pass needs the validity, not the normalized normal.
template <bool Rest, bool Depth>
inline __attribute__((always_inline)) void PrepGuidesImpl(const GuideRow& args) {
    const GuideRow a = args;
    constexpr int kC = kPrepChunk;
    alignas(64) float px[kC], py[kC], pz[kC], nx[kC], ny[kC], nz[kC], dz[kC], vv[kC], vok[kC],
        okf[kC];
    alignas(64) int oid[kC];
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float p0 = a.pos[3 * x], p1 = a.pos[3 * x + 1], p2 = a.pos[3 * x + 2];
            const float n0 = a.nrm[3 * x], n1 = a.nrm[3 * x + 1], n2 = a.nrm[3 * x + 2];
            const float z = a.depth[x];
            const float nl2 = n0 * n0 + n1 * n1 + n2 * n2;
            const float good = Fin(p0 + p1 + p2) * Fin(nl2) * (nl2 > 0.0f ? 1.0f : 0.0f) * Fin(z) *
                               (z > 0.0f ? 1.0f : 0.0f);
            if constexpr (Rest) {
                const float inl = good > 0.0f ? 1.0f / std::sqrt(nl2) : 0.0f;
                px[i] = good > 0.0f ? p0 : 0.0f, py[i] = good > 0.0f ? p1 : 0.0f;
                pz[i] = good > 0.0f ? p2 : 0.0f;
                nx[i] = n0 * inl, ny[i] = n1 * inl, nz[i] = n2 * inl;
                oid[i] = good > 0.0f ? a.id[x] : -2;
                const float v = a.vis[x];
                const float vg = good * Fin(v);
                vv[i] = vg > 0.0f ? v : 0.0f, vok[i] = vg;
            }
            if constexpr (Depth) dz[i] = good > 0.0f ? z : 0.0f, okf[i] = good;
        }
        if constexpr (Rest) {
            StoreRow(px, n, a.px + x0, a.stream), StoreRow(py, n, a.py + x0, a.stream),
                StoreRow(pz, n, a.pz + x0, a.stream);
            StoreRow(nx, n, a.nx + x0, a.stream), StoreRow(ny, n, a.ny + x0, a.stream),
                StoreRow(nz, n, a.nz + x0, a.stream);
            StoreRow(vv, n, a.vv + x0, a.stream), StoreRow(vok, n, a.vok + x0, a.stream);
            StoreRow(oid, n, a.oid + x0, a.stream);
        }
        if constexpr (Depth) {
            StoreRow(dz, n, a.dz + x0, a.stream);
            for (int i = 0; i < n; ++i) a.ok[x0 + i] = okf[i] > 0.0f ? 1 : 0;
        }
    }
}
TEXCACHE_SCREEN_CLONES void PrepGuides(const GuideRow& a) {
    PrepGuidesImpl<true, true>(a);
}
TEXCACHE_SCREEN_CLONES void PrepGuidesRest(const GuideRow& a) {
    PrepGuidesImpl<true, false>(a);
}
TEXCACHE_SCREEN_CLONES void PrepGuidesDepth(const GuideRow& a) {
    PrepGuidesImpl<false, true>(a);
}

// Glossy of one row, divided by F_beta = F0 A + B at (n.v, alpha) (bilinear in the table) when
// demodulating.
struct GlossyRow {
    int w;
    bool stream;
    const float* c;   // glossy, xyz interleaved
    const float* f0;  // specular
    const float* rough;
    const float* table;                        // (A, B) pairs, 256 x 256, alpha-major
    const float *px, *py, *pz, *nx, *ny, *nz;  // this frame's guides (planes)
    const uint8_t* ok;
    float cam[3];
    float *v[3], *r[3], *valid;
};
// The table's (A, B) pairs at (iu, it), (iu + 1, it), (iu, it + 1), (iu + 1, it + 1) for each
// pixel of a chunk, e00[i] being the first one's index: q[0..3][i] = A, B at iu and A, B at
// iu + 1 of row it, q[4..7][i] the same of row it + 1. Each row's four floats are adjacent, so
// they are read as one 16-byte load and four pixels transposed at a time: GCC tunes AVX-512
// code for CPUs whose gather instructions are slow and emulates the 8 gathers per pixel of the
// plain lookup with scalar loads and inserts, which took about 40% of PrepGlossyDemod.
inline __attribute__((always_inline)) void FetchBrdfQuads(const float* tb, const int* e00, int n,
                                                          float (*q)[kPrepChunk]) {
    constexpr int kRow = 2 * BrdfPreintegration::kSize;
    int i = 0;
    for (; i + 4 <= n; i += 4)
        for (int r = 0; r < 2; ++r) {
            __m128 v0 = _mm_loadu_ps(tb + e00[i] + r * kRow);
            __m128 v1 = _mm_loadu_ps(tb + e00[i + 1] + r * kRow);
            __m128 v2 = _mm_loadu_ps(tb + e00[i + 2] + r * kRow);
            __m128 v3 = _mm_loadu_ps(tb + e00[i + 3] + r * kRow);
            _MM_TRANSPOSE4_PS(v0, v1, v2, v3);
            _mm_storeu_ps(&q[4 * r][i], v0), _mm_storeu_ps(&q[4 * r + 1][i], v1);
            _mm_storeu_ps(&q[4 * r + 2][i], v2), _mm_storeu_ps(&q[4 * r + 3][i], v3);
        }
    for (; i < n; ++i)
        for (int k = 0; k < 8; ++k) q[k][i] = tb[e00[i] + (k >> 2) * kRow + (k & 3)];
}

template <bool Demod>
inline __attribute__((always_inline)) void PrepGlossyImpl(const GlossyRow& args) {
    const GlossyRow a = args;
    constexpr int kC = kPrepChunk;
    constexpr int kT = BrdfPreintegration::kSize;
    alignas(64) float gv[3][kC], gr[3][kC], gok[kC];
    alignas(64) float fu[kC], ft[kC], cosT[kC], q[Demod ? 8 : 1][kC];
    alignas(64) int e00[kC];
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        if constexpr (Demod) {
            // The table coordinates (cos theta, alpha) of each pixel; the lookup itself below.
            for (int i = 0; i < n; ++i) {
                const int x = x0 + i;
                const float f0 = a.f0[3 * x], f1 = a.f0[3 * x + 1], f2 = a.f0[3 * x + 2];
                const float ro = a.rough[x];
                const float good = a.ok[x] ? 1.0f : 0.0f;
                const float vx = a.cam[0] - a.px[x], vy = a.cam[1] - a.py[x],
                            vz = a.cam[2] - a.pz[x];
                const float vl2 = vx * vx + vy * vy + vz * vz;
                const float ct =
                    (a.nx[x] * vx + a.ny[x] * vy + a.nz[x] * vz) / std::sqrt(std::max(vl2, 1e-30f));
                const float use = good * Fin(f0 + f1 + f2) * Fin(ro) * Fin(ct);
                constexpr float kS = float(kT - 1);
                const float u = std::min(std::max(use > 0.0f ? ct : 0.0f, 0.0f), 1.0f) * kS;
                const float t = std::min(std::max(use > 0.0f ? ro : 0.0f, 0.0f), 1.0f) * kS;
                const int iu = std::min(int(u), kT - 2), it = std::min(int(t), kT - 2);
                fu[i] = u - float(iu), ft[i] = t - float(it);
                e00[i] = 2 * (it * kT + iu);
                cosT[i] = ct;
            }
            FetchBrdfQuads(a.table, e00, n, q);
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float c0 = a.c[3 * x], c1 = a.c[3 * x + 1], c2 = a.c[3 * x + 2];
            const float good = a.ok[x] ? 1.0f : 0.0f;
            float r0 = 1.0f, r1 = 1.0f, r2 = 1.0f;
            if constexpr (Demod) {
                const float f0 = a.f0[3 * x], f1 = a.f0[3 * x + 1], f2 = a.f0[3 * x + 2];
                const float use = good * Fin(f0 + f1 + f2) * Fin(a.rough[x]) * Fin(cosT[i]);
                const float u = fu[i], t = ft[i];
                const float sa = (1.0f - t) * ((1.0f - u) * q[0][i] + u * q[2][i]) +
                                 t * ((1.0f - u) * q[4][i] + u * q[6][i]);
                const float sb = (1.0f - t) * ((1.0f - u) * q[1][i] + u * q[3][i]) +
                                 t * ((1.0f - u) * q[5][i] + u * q[7][i]);
                const float b0 = f0 * sa + sb, b1 = f1 * sa + sb, b2 = f2 * sa + sb;
                r0 = use > 0.0f && b0 > kMinRemod ? b0 : 1.0f;
                r1 = use > 0.0f && b1 > kMinRemod ? b1 : 1.0f;
                r2 = use > 0.0f && b2 > kMinRemod ? b2 : 1.0f;
            }
            const float cg = good * Fin(c0 + c1 + c2);
            gv[0][i] = cg > 0.0f ? c0 / r0 : 0.0f, gv[1][i] = cg > 0.0f ? c1 / r1 : 0.0f;
            gv[2][i] = cg > 0.0f ? c2 / r2 : 0.0f;
            gr[0][i] = r0, gr[1][i] = r1, gr[2][i] = r2, gok[i] = cg;
        }
        for (int c = 0; c < 3; ++c)
            StoreRow(gv[c], n, a.v[c] + x0, a.stream), StoreRow(gr[c], n, a.r[c] + x0, a.stream);
        StoreRow(gok, n, a.valid + x0, a.stream);
    }
}
TEXCACHE_SCREEN_CLONES void PrepGlossy(const GlossyRow& a) {
    PrepGlossyImpl<false>(a);
}
TEXCACHE_SCREEN_CLONES void PrepGlossyDemod(const GlossyRow& a) {
    PrepGlossyImpl<true>(a);
}

// Indirect of one row: colour (divided by the albedo when demodulating) or, on the cones path,
// the cones' diffuse shading (the albedo multiplies it back in any mode).
struct IndirectRow {
    int w;
    bool stream;
    const float* c;       // indirect, xyz interleaved (colour path)
    const float* cones;   // 18 floats per pixel (cones path)
    const float* albedo;  // xyz interleaved (null on the colour path without demodulation)
    const uint8_t* ok;
    float *v[3], *r[3], *valid;
};
enum class IndMode { Colour, ColourDemod, Cones };

// The shading of one pixel's cones (kConeShadeWeight per cone, per channel) and whether all 18
// floats are finite (1 / 0). Plain scalar multiply-adds: GCC vectorizes them across pixels
// (strided loads), where an 8-wide-per-pixel form spends most of its time in horizontal sums
// (a profile of build/bin/screen_space_benchmark --benchmark_filter=reliable, prepare_ms, where
// the cones are shaded).
inline __attribute__((always_inline)) void ConeShade(const float* q, float* c0, float* c1,
                                                     float* c2, float* finite) {
    float o[3] = {0.0f, 0.0f, 0.0f}, sum = 0.0f;
#pragma GCC unroll 6
    for (int k = 0; k < kNumCones; ++k) {
#pragma GCC unroll 3
        for (int c = 0; c < 3; ++c) o[c] += kConeShadeWeight[k] * q[3 * k + c], sum += q[3 * k + c];
    }
    *c0 = o[0], *c1 = o[1], *c2 = o[2];
    *finite = Fin(sum);
}
template <IndMode M>
inline __attribute__((always_inline)) void PrepIndirectImpl(const IndirectRow& args) {
    const IndirectRow a = args;
    constexpr int kC = kPrepChunk;
    alignas(64) float iv[3][kC], ir[3][kC], iok[kC];
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float good = a.ok[x] ? 1.0f : 0.0f;
            float c0, c1, c2, r0 = 1.0f, r1 = 1.0f, r2 = 1.0f, cg;
            if constexpr (M == IndMode::Cones) {
                // ShadeCones on the pixel's 18 floats (6 cones x RGB) as 8-wide vectors: GCC
                // does not vectorize across pixels with a stride of 18.
                ConeShade(a.cones + size_t(x) * 18, &c0, &c1, &c2, &cg);
                cg *= good;
                const float a0 = a.albedo[3 * x], a1 = a.albedo[3 * x + 1],
                            a2 = a.albedo[3 * x + 2];
                // No cones (no diffuse ray: the shading normal faces away, where the BSDF is 0):
                // the pixel's indirect light is 0, not its neighbours' radiance times the albedo.
                const float af = Fin(a0 + a1 + a2) * cg;
                r0 = af > 0.0f ? a0 : 0.0f, r1 = af > 0.0f ? a1 : 0.0f, r2 = af > 0.0f ? a2 : 0.0f;
            } else {
                c0 = a.c[3 * x], c1 = a.c[3 * x + 1], c2 = a.c[3 * x + 2];
                cg = good * Fin(c0 + c1 + c2);
                if constexpr (M == IndMode::ColourDemod) {
                    const float a0 = a.albedo[3 * x], a1 = a.albedo[3 * x + 1],
                                a2 = a.albedo[3 * x + 2];
                    const float af = Fin(a0 + a1 + a2);
                    // A channel whose albedo is below kMinRemod says nothing about its light
                    // (it is about 0 whatever the light): it takes the mean of the pixel's
                    // other channels' light, so that it neither pulls its neighbours' light
                    // down in the filter, and the albedo multiplies it back, so that what the
                    // filter carries in from the neighbours stays about 0 (left undivided with a
                    // factor of 1, a red texel's edges took its grey neighbours' green light).
                    // With no such channel the pixel says nothing about the light: unusable,
                    // and its result is 0 times what its neighbours give it.
                    const float k0 = af * (a0 > kMinRemod ? 1.0f : 0.0f);
                    const float k1 = af * (a1 > kMinRemod ? 1.0f : 0.0f);
                    const float k2 = af * (a2 > kMinRemod ? 1.0f : 0.0f);
                    const float e0 = k0 > 0.0f ? c0 / a0 : 0.0f, e1 = k1 > 0.0f ? c1 / a1 : 0.0f,
                                e2 = k2 > 0.0f ? c2 / a2 : 0.0f;
                    const float kn = k0 + k1 + k2;
                    const float fill = kn > 0.0f ? (e0 + e1 + e2) / kn : 0.0f;
                    // An albedo that is not finite: undivided, as without demodulation.
                    const bool use = af > 0.0f;
                    c0 = use ? (k0 > 0.0f ? e0 : fill) : c0;
                    c1 = use ? (k1 > 0.0f ? e1 : fill) : c1;
                    c2 = use ? (k2 > 0.0f ? e2 : fill) : c2;
                    r0 = use ? std::max(a0, 0.0f) : 1.0f;
                    r1 = use ? std::max(a1, 0.0f) : 1.0f;
                    r2 = use ? std::max(a2, 0.0f) : 1.0f;
                    cg *= use && kn == 0.0f ? 0.0f : 1.0f;
                }
            }
            iv[0][i] = cg > 0.0f ? c0 : 0.0f, iv[1][i] = cg > 0.0f ? c1 : 0.0f;
            iv[2][i] = cg > 0.0f ? c2 : 0.0f;
            ir[0][i] = r0, ir[1][i] = r1, ir[2][i] = r2, iok[i] = cg;
        }
        for (int c = 0; c < 3; ++c)
            StoreRow(iv[c], n, a.v[c] + x0, a.stream), StoreRow(ir[c], n, a.r[c] + x0, a.stream);
        StoreRow(iok, n, a.valid + x0, a.stream);
    }
}
#define TEXCACHE_PREP_IND(name, M)                           \
    TEXCACHE_SCREEN_CLONES void name(const IndirectRow& a) { \
        PrepIndirectImpl<M>(a);                              \
    }
TEXCACHE_PREP_IND(PrepIndirect, IndMode::Colour)
TEXCACHE_PREP_IND(PrepIndirectDemod, IndMode::ColourDemod)
TEXCACHE_PREP_IND(PrepIndirectCones, IndMode::Cones)
#undef TEXCACHE_PREP_IND

// Depth tolerance of the edge-stopping weights: 1 / (the larger of the per-axis depth steps +
// 0.1% of the depth), each step the smaller one-sided step to a usable neighbour (so an edge
// does not widen its own tolerance).
TEXCACHE_SCREEN_CLONES void DepthTolRow(int w, const float* z, const float* zu, const float* zd,
                                        const uint8_t* ok, const uint8_t* oku, const uint8_t* okd,
                                        float* out) {
    constexpr float kBig = 3.0e38f;
    for (int x = 0; x < w; ++x) {
        // Padding columns have ok = 0 (the guides' valid plane is padded with 0).
        const float l = ok[x - 1] ? std::fabs(z[x] - z[x - 1]) : kBig;
        const float r = ok[x + 1] ? std::fabs(z[x] - z[x + 1]) : kBig;
        const float u = oku[x] ? std::fabs(z[x] - zu[x]) : kBig;
        const float d = okd[x] ? std::fabs(z[x] - zd[x]) : kBig;
        float gx = std::min(l, r), gy = std::min(u, d);
        gx = gx < kBig ? gx : 0.0f, gy = gy < kBig ? gy : 0.0f;
        out[x] = ok[x] ? 1.0f / (std::max(gx, gy) + 1e-3f * z[x]) : 0.0f;
    }
}

// The glossy and indirect inputs of row y (those present), demodulated, with their
// remodulation factors and validity: gl / ind = {v0, v1, v2, factor0, factor1, factor2, valid},
// rows of w floats. Reads this frame's guides of the row (`gv`, PrepGuides).
void PrepComponentRows(const ScreenSpaceDenoiser::State& s, const FrameBuffers& f,
                       const BrdfPreintegration* brdf, bool demod, int y, const GuideRowView& gv,
                       bool stream, float* const* gl, float* const* ind) {
    const Guides& g = s.guides[s.cur];
    const int w = s.w;
    const size_t row = size_t(y) * size_t(w);
    if (s.comp[kGlossy].present) {
        GlossyRow b;
        b.w = w, b.stream = stream, b.c = &f.glossy[row].x;
        const bool dm = demod && brdf;
        b.f0 = dm ? &f.specular[row].x : nullptr, b.rough = dm ? &f.roughness[row] : nullptr;
        b.table = dm ? &brdf->Data()->x : nullptr;
        b.px = gv.px, b.py = gv.py, b.pz = gv.pz;
        b.nx = gv.nx, b.ny = gv.ny, b.nz = gv.nz;
        b.ok = g.valid.Row(y);
        b.cam[0] = f.camera.position.x, b.cam[1] = f.camera.position.y;
        b.cam[2] = f.camera.position.z;
        for (int c = 0; c < 3; ++c) b.v[c] = gl[c], b.r[c] = gl[3 + c];
        b.valid = gl[6];
        dm ? PrepGlossyDemod(b) : PrepGlossy(b);
    }
    if (s.comp[kIndirect].present) {
        IndirectRow c;
        c.w = w, c.stream = stream, c.c = &f.indirect[row].x;
        c.cones = s.conesPath ? &f.cones[row * kNumCones].x : nullptr;
        c.albedo = f.albedo.empty() ? nullptr : &f.albedo[row].x;
        c.ok = g.valid.Row(y);
        for (int k = 0; k < 3; ++k) c.v[k] = ind[k], c.r[k] = ind[3 + k];
        c.valid = ind[6];
        if (s.conesPath)
            PrepIndirectCones(c);
        else
            demod ? PrepIndirectDemod(c) : PrepIndirect(c);
    }
}

// The frame's buffers of row y that PrepGuides reads; its outputs are left null.
GuideRow GuideInputs(const FrameBuffers& f, int w, int y, bool stream) {
    const size_t row = size_t(y) * size_t(w);
    GuideRow a;
    a.w = w, a.stream = stream;
    a.pos = &f.position[row].x, a.nrm = &f.normal[row].x;
    a.depth = &f.depth[row], a.id = &f.objectId[row], a.vis = &f.visibility[row];
    a.px = a.py = a.pz = a.nx = a.ny = a.nz = a.vv = a.vok = a.dz = nullptr;
    a.oid = nullptr, a.ok = nullptr;
    return a;
}

// The depth tolerance plane of this frame's guides (DepthTolRow), from its depth and validity.
void DepthTolerance(ScreenSpaceDenoiser::State& s) {
    Guides& g = s.G();
    ForRows(s.h, [&](int y) {
        const int yu = y > 0 ? y - 1 : y, yd = y + 1 < s.h ? y + 1 : y;
        // A neighbour row outside the image gets validity flags that are all 0.
        DepthTolRow(s.w, g.depth.Row(y), g.depth.Row(yu), g.depth.Row(yd), g.valid.Row(y),
                    y > 0 ? g.valid.Row(yu) : s.zeroRow.data() + kPad,
                    y + 1 < s.h ? g.valid.Row(yd) : s.zeroRow.data() + kPad, g.invDz.Row(y));
    });
}

// One sweep over the frame's buffers: guides and visibility as planes, the demodulated glossy
// and indirect inputs and the cached visibility. Half resolution does not take this path: it
// prepares the depth and validity planes inside the reduction's pass (DownsampleFrame's row
// hook) and the rest row by row where it is used (UpsampleCompose).
void Prepare(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, const BrdfPreintegration* brdf,
             bool demod) {
    Guides& g = s.G();
    const int w = s.w;
    ComponentPlanes& vis = s.comp[kVis];
    ComponentPlanes& gl = s.comp[kGlossy];
    ComponentPlanes& ind = s.comp[kIndirect];
    // Guides, visibility and its validity; each further component's 3 values, 3 factors,
    // validity.
    const int planes = 11 + (gl.present ? 7 : 0) + (ind.present ? 7 : 0);
    const bool stream = StreamPlanes(s.w, s.h, planes);
    ForRows(s.h, [&](int y) {
        const size_t row = size_t(y) * size_t(w);
        GuideRow a = GuideInputs(f, w, y, stream);
        a.dz = g.depth.Row(y), a.ok = g.valid.Row(y);
        a.px = g.px.Row(y), a.py = g.py.Row(y), a.pz = g.pz.Row(y);
        a.nx = g.nx.Row(y), a.ny = g.ny.Row(y), a.nz = g.nz.Row(y);
        a.oid = g.objectId.Row(y), a.vv = vis.v[0].Row(y), a.vok = vis.valid.Row(y);
        PrepGuides(a);
        if (s.hasCachedVis) {
            // -1 where there is none or the pixel's geometry is unusable.
            const float* cv = &f.cachedVisibility[row];
            const uint8_t* ok = g.valid.Row(y);
            float* out = s.cachedVis.Row(y);
            for (int x = 0; x < w; ++x) out[x] = ok[x] && cv[x] >= 0.0f ? cv[x] : -1.0f;
        }
        float *glr[7], *indr[7];
        for (int c = 0; c < 3; ++c) {
            glr[c] = gl.v[c].Row(y), glr[3 + c] = gl.remod[c].Row(y);
            indr[c] = ind.v[c].Row(y), indr[3 + c] = ind.remod[c].Row(y);
        }
        glr[6] = gl.valid.Row(y), indr[6] = ind.valid.Row(y);
        const GuideRowView gv{g.px.Row(y), g.py.Row(y), g.pz.Row(y),      g.nx.Row(y),
                              g.ny.Row(y), g.nz.Row(y), g.objectId.Row(y)};
        PrepComponentRows(s, f, brdf, demod, y, gv, stream, glr, indr);
    });
    DepthTolerance(s);
}

// Half resolution's first pass: the frame reduced to the half frame (DownsampleFrame) and, for
// each full row while the reduction has it in the caches, the row's depth and validity, the
// only full-resolution guide planes; then their depth tolerance.
void PrepareHalf(ScreenSpaceDenoiser::State& s, const FrameBuffers& f) {
    Guides& g = s.G();
    const bool stream = StreamPlanes(s.w, s.h, 2);
    DownsampleFrame(f, s.conesPath, &s.halfFrame, &s.halfSource, [&](int y) {
        GuideRow a = GuideInputs(f, s.w, y, stream);
        a.dz = g.depth.Row(y), a.ok = g.valid.Row(y);
        PrepGuidesDepth(a);
    });
    DepthTolerance(s);
}

// ---- Filters -------------------------------------------------------------------------------

PassArgs BaseArgs(const ScreenSpaceDenoiser::State& s, int nc) {
    PassArgs a;
    a.nc = nc;
    a.g = &s.guides[s.cur];
    a.normalPower = s.set.normalPower;
    a.depthSigma = s.set.sigmaDepth;
    return a;
}

// One a-trous job: a component's input (planes + variance) and where its levels go.
struct AtrousJob {
    int ci = -1;
    bool luminance = true;
    Plane* feedback[3] = {nullptr, nullptr, nullptr};  // SVGF: the first level's output
    bool resultVar = false;  // the last level writes its variance (scratch[ci].outVar)
};

// The a-trous iterations of up to 3 components together: inputs in scratch[ci].t / tVar,
// results in scratch[ci].out (and outVar for a job with resultVar: nothing else reads the last
// level's variance, so it is not computed); levels ping-pong through scratch[ci].a / b.
void RunAtrous(ScreenSpaceDenoiser::State& s, const AtrousJob* jobs, int njobs) {
    const int levels = s.set.atrousLevels;
    for (int level = 0; level < levels; ++level) {
        AtrousArgs a;
        a.g = &s.G();
        a.step = 1 << level;
        a.normalPower = s.set.normalPower;
        a.depthSigma = s.set.sigmaDepth;
        a.luminanceSigma = s.set.sigmaLuminance;
        const bool last = level == levels - 1;
        for (int j = 0; j < njobs; ++j) {
            ComponentScratch& sc = s.scratch[jobs[j].ci];
            AtrousComponent& c = a.comp[j];
            c.nc = s.comp[jobs[j].ci].nc;
            c.luminance = jobs[j].luminance;
            // Level l reads what level l-1 wrote: t -> (feedback or a) -> b -> a -> ... -> out.
            auto src = [&](int l, int k) -> Plane* {
                if (l < 0) return &sc.t[k];
                if (l == 0 && jobs[j].feedback[0]) return jobs[j].feedback[k];
                return (l & 1) ? &sc.b[k] : &sc.a[k];
            };
            auto srcVar = [&](int l) -> Plane* {
                if (l < 0) return &sc.tVar;
                return (l & 1) ? &sc.bVar : &sc.aVar;
            };
            for (int k = 0; k < c.nc; ++k) {
                c.in[k] = src(level - 1, k);
                c.out[k] = last ? &sc.out[k] : src(level, k);
            }
            c.var = srcVar(level - 1);
            c.outVar = !last ? srcVar(level) : jobs[j].resultVar ? &sc.outVar : nullptr;
        }
        AtrousLevel(a);
        if (last) break;
    }
    for (int j = 0; j < njobs; ++j) {
        ComponentScratch& sc = s.scratch[jobs[j].ci];
        // With a single level the output is also the feedback.
        if (levels == 1 && jobs[j].feedback[0])
            for (int k = 0; k < s.comp[jobs[j].ci].nc; ++k)
                ForRows(s.h, [&](int y) {
                    std::copy_n(sc.out[k].Row(y), s.w, jobs[j].feedback[k]->Row(y));
                });
        for (int k = 0; k < 3; ++k) s.comp[jobs[j].ci].res[k] = &sc.out[k];
    }
}

// `from` into `to` (the same size): the shadow vectors of a frame whose shadows stayed where they
// were (FrameBuffers::shadowsStill).
void CopyMotion(const MotionField& from, MotionField* to) {
    ForRows(from.x.Height(), [&](int y) {
        const int w = from.x.Width();
        CopyRow(from.x.Row(y), w, to->x.Row(y));
        CopyRow(from.y.Row(y), w, to->y.Row(y));
        CopyRow(from.taps.Row(y), w, to->taps.Row(y));
    });
}

// VisibilityOrder::Svgf: where a shadow vector lands within a quarter pixel of the
// traditional one (no shadow moved over its receiver; in a static scene the two are the same
// reprojection computed two ways), the traditional vector and its taps replace it and the
// history is not clamped (k 0 in `clampK`); elsewhere the history is clamped with `k`. The taps
// matter as much as the position: the shadow vectors' plane test and the disocclusion test keep
// different taps at edges, and a history averaged over other taps than the baseline's makes a
// static scene's visibility drift from the baseline's.
void TrustAgreeingShadowVectors(const MotionField& trad, float k, MotionField* shadow,
                                Plane* clampK) {
    constexpr float kTol = 0.25f;
    ForRows(trad.x.Height(), [&](int y) {
        float *sx = shadow->x.Row(y), *sy = shadow->y.Row(y);
        uint8_t* sm = shadow->taps.Row(y);
        const float *tx = trad.x.Row(y), *ty = trad.y.Row(y);
        const uint8_t* tm = trad.taps.Row(y);
        float* o = clampK->Row(y);
        const int w = trad.x.Width();
        for (int x = 0; x < w; ++x) {
            // NaN (no vector) fails the comparisons: clamped.
            const bool agree = std::fabs(sx[x] - tx[x]) <= kTol && std::fabs(sy[x] - ty[x]) <= kTol;
            sx[x] = agree ? tx[x] : sx[x], sy[x] = agree ? ty[x] : sy[x];
            sm[x] = agree ? tm[x] : sm[x];
            o[x] = agree ? 0.0f : k;
        }
    });
}

// Zeng's clean-up: separable joint bilateral 9x9 with the per-pixel std in s.sigma, from
// scratch[ci].t (validity in tVar) into this frame's history colour.
void Cleanup(ScreenSpaceDenoiser::State& s, int ci) {
    ComponentScratch& sc = s.scratch[ci];
    History& hc = s.hist[ci][s.cur];
    const int nc = s.comp[ci].nc;
    PassArgs a = BaseArgs(s, nc);
    a.taps = 9;
    for (int k = 0; k < 9; ++k) a.offset[k] = k - 4;
    a.sigma = &s.sigma;
    for (int c = 0; c < nc; ++c) a.in[c] = &sc.t[c], a.out[c] = &sc.a[c];
    a.valid = &sc.tVar, a.outValid = &sc.aVar;
    FilterPlanes(a);
    a.vertical = true;
    for (int c = 0; c < nc; ++c) a.in[c] = &sc.a[c], a.out[c] = &hc.c[c];
    a.valid = &sc.aVar, a.outValid = nullptr;
    FilterPlanes(a);
    for (int c = 0; c < 3; ++c) s.comp[ci].res[c] = &hc.c[c];
    hc.valid = true;
}

// The final sum of one row, written like the preparation kernels (plain pointers, local result
// arrays, 0/1 floats) so that it vectorizes: a per-pixel glm version with Finite() tests and
// plane accessors costs several times this at 1080p (build/bin/screen_space_benchmark
// --benchmark_filter=reliable, compose_ms).
struct ComposeRowArgs {
    int w;
    const float* emitted;   // xyz interleaved, or null
    const float* shading;   // xyz interleaved
    const float* vis;       // denoised visibility (plane row)
    const float* rm[2][3];  // glossy / indirect remodulation factors (null: component absent)
    const float* res[2][3];
    float* out;  // xyz interleaved
    bool stream;
};
TEXCACHE_SCREEN_CLONES void ComposeRow(const ComposeRowArgs& args) {
    const ComposeRowArgs a = args;
    constexpr int kC = kPrepChunk;
    alignas(64) float o[3][kC], local[3 * kC];
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float s0 = a.shading[3 * x], s1 = a.shading[3 * x + 1], s2 = a.shading[3 * x + 2];
            // 0 when any channel is NaN/Inf (as Finite(vec3)).
            const float sf = (std::fabs(s0) < 3.0e38f ? 1.0f : 0.0f) *
                             (std::fabs(s1) < 3.0e38f ? 1.0f : 0.0f) *
                             (std::fabs(s2) < 3.0e38f ? 1.0f : 0.0f);
            const float v = a.vis[x];
            float c0 = sf > 0.0f ? s0 * v : 0.0f, c1 = sf > 0.0f ? s1 * v : 0.0f,
                  c2 = sf > 0.0f ? s2 * v : 0.0f;
            if (a.emitted) {
                const float e0 = a.emitted[3 * x], e1 = a.emitted[3 * x + 1],
                            e2 = a.emitted[3 * x + 2];
                const float ef = (std::fabs(e0) < 3.0e38f ? 1.0f : 0.0f) *
                                 (std::fabs(e1) < 3.0e38f ? 1.0f : 0.0f) *
                                 (std::fabs(e2) < 3.0e38f ? 1.0f : 0.0f);
                // Emitted first, as the reference order: (e + s v) + ...
                c0 = ef > 0.0f ? e0 + c0 : c0, c1 = ef > 0.0f ? e1 + c1 : c1;
                c2 = ef > 0.0f ? e2 + c2 : c2;
            }
            o[0][i] = c0, o[1][i] = c1, o[2][i] = c2;
        }
        for (int k = 0; k < 2; ++k) {
            if (!a.rm[k][0]) continue;
            for (int c = 0; c < 3; ++c) {
                const float* rm = a.rm[k][c] + x0;
                const float* rs = a.res[k][c] + x0;
                for (int i = 0; i < n; ++i) o[c][i] += rm[i] * rs[i];
            }
        }
        // Interleaved into a local row first only to stream it (StoreRow).
        float* rgb = a.stream ? local : a.out + 3 * x0;
        for (int i = 0; i < n; ++i)
            rgb[3 * i] = o[0][i], rgb[3 * i + 1] = o[1][i], rgb[3 * i + 2] = o[2][i];
        if (a.stream) StoreRow(local, 3 * n, a.out + 3 * x0, true);
    }
}

void Compose(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, std::vector<glm::vec3>* out) {
    out->resize(size_t(s.w) * size_t(s.h));
    const ComponentPlanes* parts[2] = {&s.comp[kGlossy], &s.comp[kIndirect]};
    const bool stream = StreamPlanes(s.w, s.h, 3);  // the RGB image
    ForRows(s.h, [&](int y) {
        const size_t row = size_t(y) * size_t(s.w);
        ComposeRowArgs a;
        a.w = s.w;
        a.emitted = f.emitted.empty() ? nullptr : &f.emitted[row].x;
        a.shading = &f.shading[row].x;
        a.vis = s.comp[kVis].res[0]->Row(y);
        for (int k = 0; k < 2; ++k)
            for (int c = 0; c < 3; ++c) {
                a.rm[k][c] = parts[k]->present ? parts[k]->remod[c].Row(y) : nullptr;
                a.res[k][c] = parts[k]->present ? parts[k]->res[c]->Row(y) : nullptr;
            }
        a.out = &(*out)[row].x;
        a.stream = stream;
        ComposeRow(a);
    });
}

// Half resolution's last full-resolution pass, one row at a time: the row's guides (PrepGuides)
// and its own glossy and indirect inputs and factors (PrepComponentRows), into per-thread rows
// rather than planes, the
// upsample of `half`'s results (UpsampleRow) and the composition. Nothing of the full-resolution
// components goes through memory but what the accessors (Visibility(), Glossy(), Indirect())
// read: the visibility and the remodulated components, in s.scratch[ci].out.
void UpsampleCompose(ScreenSpaceDenoiser::State& s, const ScreenSpaceDenoiser::State& half,
                     const FrameBuffers& f, const BrdfPreintegration* brdf, bool demod,
                     std::vector<glm::vec3>* out) {
    out->resize(size_t(s.w) * size_t(s.h));
    const int np = UpsampledPlanes(s, half);
    const bool part[2] = {s.comp[kGlossy].present, s.comp[kIndirect].present};
    // Rows per thread: each part's 7 inputs (PrepComponentRows), the up to 7 results and the
    // row's guides (position, normal, visibility and its validity); one float past the row's
    // end is read (UpsampleRow).
    constexpr int kRows = 29;
    const size_t stride = (size_t(s.w) + 16) / 16 * 16;
    const size_t slot = kRows * stride;
    const size_t threads = size_t(tbb::this_task_arena::max_concurrency());
    if (s.rowScratch.size() < threads * slot) s.rowScratch.assign(threads * slot, 0.0f);
    if (s.rowIds.size() < threads * stride) s.rowIds.assign(threads * stride, 0);
    const bool stream = StreamPlanes(s.w, s.h, 3 + np);  // the RGB image and the results
    ForRows(s.h, [&](int y) {
        const size_t t = size_t(tbb::this_task_arena::current_thread_index());
        float* base = s.rowScratch.data() + t * slot;
        auto buf = [&](int k) { return base + size_t(k) * stride; };
        const size_t row = size_t(y) * size_t(s.w);
        GuideRow gr = GuideInputs(f, s.w, y, false);
        gr.px = buf(21), gr.py = buf(22), gr.pz = buf(23);
        gr.nx = buf(24), gr.ny = buf(25), gr.nz = buf(26), gr.vv = buf(27), gr.vok = buf(28);
        gr.oid = s.rowIds.data() + t * stride;  // the depth and validity are planes
        PrepGuidesRest(gr);
        const GuideRowView gv{gr.px, gr.py, gr.pz, gr.nx, gr.ny, gr.nz, gr.oid};
        float* in[2][7];
        for (int k = 0; k < 7; ++k) in[0][k] = buf(k), in[1][k] = buf(7 + k);
        PrepComponentRows(s, f, brdf, demod, y, gv, false, in[0], in[1]);
        const float* own[7];
        float* res[7];
        int first[2] = {-1, -1}, k = 0;
        own[k] = gr.vv, res[k] = buf(14), ++k;
        for (int p = 0; p < 2; ++p) {
            if (!part[p]) continue;
            first[p] = k;
            for (int c = 0; c < 3; ++c, ++k) own[k] = in[p][c], res[k] = buf(14 + k);
        }
        UpsampleRow(s, half, y, gv, own, res);
        ComposeRowArgs a;
        a.w = s.w;
        a.emitted = f.emitted.empty() ? nullptr : &f.emitted[row].x;
        a.shading = &f.shading[row].x;
        a.vis = res[0];
        for (int p = 0; p < 2; ++p)
            for (int c = 0; c < 3; ++c) {
                a.rm[p][c] = part[p] ? in[p][3 + c] : nullptr;
                a.res[p][c] = part[p] ? res[first[p] + c] : nullptr;
            }
        a.out = &(*out)[row].x;
        a.stream = stream;
        ComposeRow(a);
        StoreRow(res[0], s.w, s.scratch[kVis].out[0].Row(y), stream);
        for (int p = 0; p < 2; ++p) {
            if (!part[p]) continue;
            for (int c = 0; c < 3; ++c) {
                float* r = res[first[p] + c];
                const float* rm = in[p][3 + c];
                for (int x = 0; x < s.w; ++x) r[x] *= rm[x];
                StoreRow(r, s.w, s.scratch[p ? kIndirect : kGlossy].out[c].Row(y), stream);
            }
        }
    });
    for (int ci = 0; ci < 3; ++ci)
        for (int c = 0; c < 3; ++c)
            s.comp[ci].res[c] =
                s.comp[ci].present && c < s.comp[ci].nc ? &s.scratch[ci].out[c] : nullptr;
}

// The weight of the current frame in the temporal blends. Moving: alpha, an exponential average
// worth about 1 / alpha frames. Still for `stillFrames` frames: a running mean that takes the
// history as those 1 / alpha frames, so the weight starts at alpha (no jump when the view stops)
// and falls as 1 / (1 / alpha + frames) down to 1 / kStillMaxFrames, the history's longest
// length. Pixels whose history is shorter still take 1 / length (the temporal passes).
constexpr float kStillMaxFrames = 255.0f;
float BlendAlpha(float alpha, int stillFrames) {
    if (stillFrames < 0) return alpha;
    return std::max(1.0f / kStillMaxFrames, 1.0f / (1.0f / alpha + float(stillFrames)));
}

// What every frame ends with, at either resolution.
void FinishFrame(ScreenSpaceDenoiser::State& s, const FrameBuffers& frame, PassClock& clock) {
    s.prevCam = frame.camera;
    s.cur ^= 1;
    s.hasPrev = true;
    ++s.frameIndex;
    if (s.stillFrames >= 0) ++s.stillFrames;
    clock.Lap(&StageTimings::compose);
    clock.Finish();
}

}  // namespace

// ---- Denoise -------------------------------------------------------------------------------

std::vector<glm::vec3> ScreenSpaceDenoiser::Denoise(const FrameBuffers& frame, Method method,
                                                    Demodulation demodulation) {
    std::vector<glm::vec3> image;
    Denoise(frame, method, demodulation, &image);
    return image;
}

void ScreenSpaceDenoiser::Denoise(const FrameBuffers& frame, Method method,
                                  Demodulation demodulation, std::vector<glm::vec3>* image) {
    State& s = *s_;
    PassClock clock(&s.timings, &s.cpuTimings);
    frame.Validate("ScreenSpaceDenoiser::Denoise");
    CheckInputs(frame, method, demodulation, s.set.reliableVisibilityOrder);
    if (frame.width != s.w || frame.height != s.h)
        s.Resize(frame.width, frame.height);
    else if (method != s.method || demodulation != s.demod)
        Reset();
    s.method = method, s.demod = demodulation;
    const bool reliable = method == Method::Reliable;
    // Without history by design, SpatialOnly stays the spatial filter alone.
    s.hasCachedVis = !frame.cachedVisibility.empty() && method != Method::SpatialOnly;
    const bool demod = demodulation == Demodulation::On;
    s.comp[kVis].nc = 1, s.comp[kVis].present = true;
    s.comp[kGlossy].nc = 3, s.comp[kGlossy].present = !frame.glossy.empty();
    s.comp[kIndirect].nc = 3, s.comp[kIndirect].present = !frame.indirect.empty();
    s.conesPath =
        reliable && s.set.indirectCones && !frame.indirect.empty() && !frame.cones.empty();
    // The indirect history's format (cones or colour) must match this frame's path.
    if (s.conesPath != s.prevConesPath) s.hist[kIndirect][s.cur ^ 1].valid = false;
    s.prevConesPath = s.conesPath;
    for (int c = 0; c < 3; ++c) {
        if (!s.comp[c].present) s.hist[c][s.cur].valid = false;
        for (const Plane*& r : s.comp[c].res) r = nullptr;
    }
    const BrdfPreintegration* brdf = demod && s.comp[kGlossy].present ? &Brdf() : nullptr;
    const bool half = s.set.halfResolutionRows > 0 && frame.height >= s.set.halfResolutionRows;
    if (!half) {
        Prepare(s, frame, brdf, demod);
        clock.Lap(&StageTimings::prepare);
    } else {
        if (!s.half) {
            DenoiserSettings hs = s.set;
            hs.halfResolutionRows = 0;
            // The same footprint in full-resolution pixels: a half-resolution step is two.
            hs.atrousLevels = std::max(1, s.set.atrousLevels - 1);
            Brdf();  // one table for both
            s.half = std::make_unique<ScreenSpaceDenoiser>(hs, s.brdf);
            s.half->s_->composes = false;
            if (s.stillFrames >= 0) s.half->SetStillView(true);
        }
        PrepareHalf(s, frame);
        clock.Lap(&StageTimings::prepare);
        s.halfFrame.indirectAccumulates = frame.indirectAccumulates;
        s.halfFrame.shadowsStill = frame.shadowsStill;
        s.half->Denoise(s.halfFrame, method, demodulation, &s.halfImage);
        clock.Charge(s.half->Timings(), s.half->CpuTimings());
        s.lastHalf = true;
        UpsampleCompose(s, *s.half->s_, frame, brdf, demod, image);
        FinishFrame(s, frame, clock);
        return;
    }

    s.lastHalf = false;
    s.blendAlpha = BlendAlpha(s.set.alpha, s.stillFrames);
    s.indirectAccumulates = frame.indirectAccumulates;
    const bool temporal = method != Method::SpatialOnly && s.hasPrev;
    std::fill(std::begin(s.motionValid), std::end(s.motionValid), false);
    if (temporal) {
        const PrevFrame pf{&s.PrevG(), s.prevCam};
        TraditionalMotion(frame, s.G(), pf, &s.trad);
        s.motionValid[int(MotionKind::Traditional)] = true;
        clock.Lap(&StageTimings::traditionalMotion);
        if (reliable) {
            // Zeng's order reads eq. 4's alpha^V besides the vectors: always computed there.
            if (frame.shadowsStill && s.set.reliableVisibilityOrder == VisibilityOrder::Svgf)
                CopyMotion(s.trad, &s.shadow);
            else
                ShadowMotion(frame, s.G(), pf, s.trad, s.set.alpha, s.set.shadowFalloffSigma,
                             s.set.shadowSplatRadius, &s.shadow, &s.shadowAlpha, s.splat);
            s.motionValid[int(MotionKind::Shadow)] = true;
            if (s.comp[kGlossy].present) {
                GlossyMotion(frame, s.G(), pf, s.trad, s.set.glossyLobeScale, s.set.maxGlossyJitter,
                             s.set.seed * 0x9E3779B9u ^ s.frameIndex, s.gauss.data(), &s.glossy);
                s.motionValid[int(MotionKind::Glossy)] = true;
            }
            if (s.comp[kIndirect].present) {
                OcclusionMotion(frame, s.G(), pf, s.trad, &s.occluder, &s.occl);
                s.motionValid[int(MotionKind::Occlusion)] = true;
            }
            clock.Lap(&StageTimings::reliableMotion);
        }
    }

    const bool hasGl = s.comp[kGlossy].present, hasInd = s.comp[kIndirect].present;
    AtrousJob jobs[3];
    int njobs = 0;
    if (!reliable) {
        const float k = method == Method::BaselineClamp ? s.set.baselineClampK : 0.0f;
        const MotionField* mf = temporal ? &s.trad : nullptr;
        for (int c = 0; c < 3; ++c) {
            if (!s.comp[c].present) continue;
            SvgfTemporal(s, c, mf, k);
            if (c == kVis && s.hasCachedVis) CachedWhereNoHistory(s, true);
            AtrousJob& j = jobs[njobs++];
            j.ci = c;
            for (int k3 = 0; k3 < 3; ++k3) j.feedback[k3] = &s.hist[c][s.cur].c[k3];
        }
        clock.Lap(&StageTimings::temporal);
        RunAtrous(s, jobs, njobs);
        for (int j = 0; j < njobs; ++j) s.hist[jobs[j].ci][s.cur].valid = true;
        clock.Lap(&StageTimings::spatial);
    } else {
        // Indirect: temporal first (cones, or colour along the occlusion vectors).
        if (hasInd) {
            const MotionField* occl = temporal ? &s.occl : nullptr;
            if (s.conesPath) {
                ConesTemporal(s, frame, occl);
            } else {
                SvgfTemporal(s, kIndirect, occl, s.set.reliableIndirectClampK);
                for (int k3 = 0; k3 < 3; ++k3)
                    jobs[njobs].feedback[k3] = &s.hist[kIndirect][s.cur].c[k3];
            }
            jobs[njobs++].ci = kIndirect;
            s.hist[kIndirect][s.cur].valid = true;
        }
        // Glossy: temporal first too, along the stochastic glossy vectors (see the design note).
        if (hasGl) {
            SvgfTemporal(s, kGlossy, temporal ? &s.glossy : nullptr, s.set.reliableGlossyClampK);
            for (int k3 = 0; k3 < 3; ++k3) jobs[njobs].feedback[k3] = &s.hist[kGlossy][s.cur].c[k3];
            jobs[njobs++].ci = kGlossy;
            s.hist[kGlossy][s.cur].valid = true;
        }
        if (s.set.reliableVisibilityOrder == VisibilityOrder::Svgf) {
            // Visibility accumulated first along the shadow vectors, clamped only where they
            // part from the traditional ones, then filtered with the other components.
            if (temporal)
                TrustAgreeingShadowVectors(s.trad, s.set.reliableClampK, &s.shadow, &s.visClampK);
            SvgfTemporal(s, kVis, temporal ? &s.shadow : nullptr, s.set.reliableClampK,
                         temporal ? &s.visClampK : nullptr);
            if (s.hasCachedVis) CachedWhereNoHistory(s, true);
            for (int k3 = 0; k3 < 3; ++k3) jobs[njobs].feedback[k3] = &s.hist[kVis][s.cur].c[k3];
            jobs[njobs++].ci = kVis;
            s.hist[kVis][s.cur].valid = true;
            clock.Lap(&StageTimings::temporal);
            RunAtrous(s, jobs, njobs);
            clock.Lap(&StageTimings::spatial);
        } else {
            // Visibility: c~_i is the a-trous of this frame alone (spatial variance).
            SvgfTemporal(s, kVis, nullptr, 0.0f);
            jobs[njobs].resultVar = true;  // ReliableTemporal's validity
            jobs[njobs++].ci = kVis;
            clock.Lap(&StageTimings::temporal);
            RunAtrous(s, jobs, njobs);
            clock.Lap(&StageTimings::spatial);
            // Zeng's temporal step and clean-up for visibility.
            ComponentScratch& vs = s.scratch[kVis];
            const MotionField* sm = temporal ? &s.shadow : nullptr;
            Plane* vb[3] = {&vs.out[0], &vs.out[1], &vs.out[2]};
            ReliableTemporal(s, kVis, vb, vs.outVar, sm,
                             temporal && s.set.shadowFalloff ? &s.shadowAlpha : nullptr);
            if (s.hasCachedVis) CachedWhereNoHistory(s, false);
            clock.Lap(&StageTimings::temporal);
            Cleanup(s, kVis);
            clock.Lap(&StageTimings::cleanup);
        }
    }

    if (s.composes) Compose(s, frame, image);
    FinishFrame(s, frame, clock);
}

// ---- Accessors -----------------------------------------------------------------------------

namespace {

template <class T, class Get>
std::vector<T> Collect(const ScreenSpaceDenoiser::State& s, Get&& get) {
    std::vector<T> v(size_t(s.w) * size_t(s.h));
    for (int y = 0; y < s.h; ++y)
        for (int x = 0; x < s.w; ++x) v[size_t(y) * size_t(s.w) + size_t(x)] = get(x, y);
    return v;
}

std::vector<glm::vec3> Remodulated(const ScreenSpaceDenoiser::State& s, int ci) {
    const ComponentPlanes& cp = s.comp[ci];
    if (!cp.present || !cp.res[0]) return {};
    // Half resolution keeps the remodulated result (UpsampleCompose).
    if (s.lastHalf)
        return Collect<glm::vec3>(s, [&](int x, int y) {
            return glm::vec3(cp.res[0]->At(x, y), cp.res[1]->At(x, y), cp.res[2]->At(x, y));
        });
    return Collect<glm::vec3>(s, [&](int x, int y) {
        glm::vec3 c;
        for (int k = 0; k < 3; ++k) c[k] = cp.remod[k].At(x, y) * cp.res[k]->At(x, y);
        return c;
    });
}

}  // namespace

std::vector<float> ScreenSpaceDenoiser::Visibility() const {
    const State& s = *s_;
    if (!s.comp[kVis].res[0]) return {};
    return Collect<float>(s, [&](int x, int y) { return s.comp[kVis].res[0]->At(x, y); });
}

std::vector<glm::vec3> ScreenSpaceDenoiser::Glossy() const {
    return Remodulated(*s_, kGlossy);
}

std::vector<glm::vec3> ScreenSpaceDenoiser::Indirect() const {
    return Remodulated(*s_, kIndirect);
}

std::vector<glm::vec2> ScreenSpaceDenoiser::LastMotion(MotionKind kind) const {
    const State& s = *s_;
    if (s.lastHalf) {
        // The block's vector, scaled to full resolution, moved by the pixel's offset from the
        // block's centre.
        const std::vector<glm::vec2> hm = s.half->LastMotion(kind);
        const int hw = s.half->s_->w;
        return Collect<glm::vec2>(s, [&](int x, int y) {
            const glm::vec2 from = hm[size_t(y / 2) * size_t(hw) + size_t(x / 2)];
            return 2.0f * from + glm::vec2(float(x % 2) - 0.5f, float(y % 2) - 0.5f);
        });
    }
    const MotionField* m[4] = {&s.trad, &s.shadow, &s.glossy, &s.occl};
    const bool ok = s.motionValid[int(kind)];
    const MotionField& f = *m[int(kind)];
    return Collect<glm::vec2>(s, [&](int x, int y) {
        if (!ok || !f.taps.At(x, y)) return glm::vec2(kNaN);
        return glm::vec2(f.x.At(x, y), f.y.At(x, y));
    });
}

}  // namespace texcache::screen
