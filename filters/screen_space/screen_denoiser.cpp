// SPDX-License-Identifier: Apache-2.0
// The screen-space stage (see screen_denoiser.h for what each method does).
//
// Design note. A frame goes through: Prepare (one sweep over the frame's AoS buffers into padded
// SoA planes: guides, demodulated components, remodulation factors) -> motion vectors -> per
// component a temporal pass (per pixel, bilinear history over the taps its motion field allows)
// and the separable edge-avoiding filters of kernels.cpp -> Compose. Two orders are used:
//   SVGF order (Baseline, BaselineClamp, SpatialOnly, Reliable indirect): the noisy input is
//     accumulated with the history first, its luminance moments give the variance that steers
//     the a-trous iterations, and the output of the first iteration is the next history.
//   Zeng order (Reliable visibility and glossy): the current frame is filtered spatially first
//     (c~_i), the history fetched with the reliable vector is clamped to mu +- 3 sigma of c~_i's
//     3x3 neighbourhood and blended (eq. 2 with alpha^V), then the clean-up filter runs with std
//     min(w_A + w_C, 5) (eqs. 7-8); its output is the next history.
// The Reliable indirect path keeps incident radiance in 6 cones per pixel as its history (Sec.
// 4.3): history cones are moved into the current pixel's cone frame with Mazonka overlap weights
// and blended per cone; the a-trous filter then runs on their diffuse shading (ShadeCones), which
// costs 3 channels instead of 18 (filtering every cone spatially would be ~6x the whole stage's
// filtering time at 1080p).
//
// Ownership: the denoiser owns two sets of guides and histories (current / previous) and swaps
// them after each frame, so nothing is copied between frames. Threading: passes run on the TBB
// pool, rows in parallel; nothing is allocated per pixel.
#include "filters/screen_space/screen_denoiser.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "filters/screen_space/brdf_table.h"
#include "filters/screen_space/cone_overlap.h"
#include "filters/screen_space/motion_vectors.h"
#include "filters/screen_space/planes.h"
#include "texcache/error.h"

namespace texcache::screen {

using namespace detail;

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

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kVis = 0, kGlossy = 1, kIndirect = 2;
constexpr int kConeFloats = 3 * kNumCones;
// Below this a remodulation factor (F_beta, albedo) is not divided out: nothing to recover.
constexpr float kMinRemod = 1e-3f;
// History lengths are capped (they only select alpha = max(alpha, 1/len) and the variance).
constexpr float kMaxLen = 255.0f;

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

inline bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

template <class Body>
void ForRows(int h, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y < r.end(); ++y) body(y);
    });
}

// Bilinear history over the usable taps of a motion field: weights renormalized over them.
struct HistoryTaps {
    int n = 0;
    int x[4], y[4];
    float w[4];
};
inline bool GatherTaps(const MotionField& mf, int x, int y, HistoryTaps* t) {
    const uint8_t m = mf.taps.At(x, y);
    if (!m) return false;
    Footprint fp;
    if (!MakeFootprint(mf.x.At(x, y), mf.y.At(x, y), mf.x.Width(), mf.x.Height(), &fp))
        return false;
    float sum = 0.0f;
    t->n = 0;
    for (int k = 0; k < 4; ++k) {
        if (!(m & (1u << k)) || fp.w[k] <= 0.0f) continue;
        t->x[t->n] = fp.x0 + (k & 1), t->y[t->n] = fp.y0 + (k >> 1), t->w[t->n] = fp.w[k];
        sum += fp.w[k];
        ++t->n;
    }
    // A position whose usable taps carry almost no bilinear weight is mostly on rejected
    // surfaces: no history rather than an extrapolation.
    if (sum < 0.05f) return false;
    for (int k = 0; k < t->n; ++k) t->w[k] /= sum;
    return true;
}
inline float Fetch(const Plane& p, const HistoryTaps& t) {
    float v = 0.0f;
    for (int k = 0; k < t.n; ++k) v += t.w[k] * p.At(t.x[k], t.y[k]);
    return v;
}

// Mean and std of `nc` planes over the valid samples of the 3x3 neighbourhood of (x, y).
inline void Neighbourhood(const Plane* const* v, const Plane& valid, int nc, int x, int y,
                          float* mu, float* sigma) {
    const int h = valid.Height();
    float s1[3] = {0, 0, 0}, s2[3] = {0, 0, 0}, n = 0.0f;
    for (int dy = -1; dy <= 1; ++dy) {
        const int yy = y + dy;
        if (yy < 0 || yy >= h) continue;
        for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx;  // the padding has validity 0
            const float ok = valid.At(xx, yy);
            n += ok;
            for (int c = 0; c < nc; ++c) {
                const float s = ok * v[c]->At(xx, yy);
                s1[c] += s, s2[c] += s * v[c]->At(xx, yy);
            }
        }
    }
    for (int c = 0; c < nc; ++c) {
        mu[c] = n > 0.0f ? s1[c] / n : 0.0f;
        sigma[c] = n > 0.0f ? std::sqrt(std::max(0.0f, s2[c] / n - mu[c] * mu[c])) : 0.0f;
    }
}

}  // namespace

// ---- State ---------------------------------------------------------------------------------

struct ComponentPlanes {
    int nc = 1;
    bool present = false;
    Plane v[3];      // the input, demodulated
    Plane valid;     // 1 where the sample (and the pixel's geometry) is usable
    Plane remod[3];  // remodulation factor (1 when not demodulated)
    Plane out[3];    // denoised, demodulated (SVGF order)
    Plane outValid;
    const Plane* res[3] = {nullptr, nullptr, nullptr};  // the result: out or the history
};

struct History {
    Plane c[3], m1, m2, len;
    HugeArray<float> cones;  // Reliable indirect: kConeFloats per pixel
    bool valid = false;
};

struct ScreenSpaceDenoiser::State {
    DenoiserSettings set;
    std::shared_ptr<const BrdfPreintegration> brdf;
    ConeOverlapTable coneTable;
    std::vector<float> gauss;  // 2 x 4096 standard normal numbers (glossy vectors)
    int w = 0, h = 0;
    bool hasPrev = false;
    Method method = Method::SpatialOnly;
    Demodulation demod = Demodulation::Off;
    uint32_t frameIndex = 0;
    Guides guides[2];
    int cur = 0;  // guides[cur] and hist[..][cur] are this frame's
    FrameCamera prevCam;
    ComponentPlanes comp[3];
    History hist[3][2];
    bool conesPath = false;
    MotionField trad, shadow, glossy, occl;
    bool motionValid[4] = {false, false, false, false};
    Plane shadowAlpha;
    IntPlane occluder;
    // Scratch: ping-pong colour planes for the filters and per-pixel temporaries.
    Plane a[3], b[3], t[3], va, vb, vt, vara, varb, vart, invLum, sigma, spVar, lum;
    Plane splat[8];
    StageTimings timings;

    Guides& G() { return guides[cur]; }
    const Guides& PrevG() const { return guides[cur ^ 1]; }
    void Resize(int width, int height);
};

void ScreenSpaceDenoiser::State::Resize(int width, int height) {
    w = width, h = height;
    for (Guides& g : guides) g.Resize(w, h);
    for (ComponentPlanes& c : comp) {
        for (int k = 0; k < 3; ++k) {
            c.v[k].Resize(w, h), c.remod[k].Resize(w, h, 1.0f), c.out[k].Resize(w, h);
        }
        c.valid.Resize(w, h), c.outValid.Resize(w, h);
    }
    for (auto& hc : hist)
        for (History& hh : hc) {
            for (Plane& p : hh.c) p.Resize(w, h);
            hh.m1.Resize(w, h), hh.m2.Resize(w, h), hh.len.Resize(w, h);
            hh.cones.Assign(0, 0.0f);
            hh.valid = false;
        }
    for (MotionField* m : {&trad, &shadow, &glossy, &occl}) m->Resize(w, h);
    shadowAlpha.Resize(w, h), occluder.Resize(w, h, -1);
    for (int k = 0; k < 3; ++k) a[k].Resize(w, h), b[k].Resize(w, h), t[k].Resize(w, h);
    for (Plane* p : {&va, &vb, &vt, &vara, &varb, &vart, &invLum, &sigma, &spVar, &lum})
        p->Resize(w, h);
    for (Plane& p : splat) p.Resize(w, h);
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
    if (s.atrousLevels < 1 || s.atrousLevels > 5)
        fail("atrousLevels must be in 1..5 (steps up to 16), got " +
             std::to_string(s.atrousLevels));
    if (!(s.sigmaLuminance > 0.0f) || !(s.sigmaDepth > 0.0f) || !(s.normalPower >= 0.0f))
        fail("sigmaLuminance and sigmaDepth must be positive, normalPower non-negative");
    if (s.shadowRadius < 1 || s.shadowRadius > 16)
        fail("shadowRadius must be in 1..16, got " + std::to_string(s.shadowRadius));
    if (s.shadowSplatRadius < 0 || s.shadowSplatRadius > 64)
        fail("shadowSplatRadius must be in 0..64, got " + std::to_string(s.shadowSplatRadius));
    if (!(s.shadowFalloffSigma > 0.0f)) fail("shadowFalloffSigma must be positive");
    if (!(s.glossyLobeScale >= 0.0f) || !(s.maxGlossyJitter >= 0.0f))
        fail("glossyLobeScale and maxGlossyJitter must be non-negative");
    if (s.brdfSamples < 1) fail("brdfSamples must be at least 1");
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
    s_->hasPrev = false;
    for (auto& hc : s_->hist)
        for (History& hh : hc) hh.valid = false;
}

const StageTimings& ScreenSpaceDenoiser::Timings() const {
    return s_->timings;
}

const BrdfPreintegration& ScreenSpaceDenoiser::Brdf() {
    if (!s_->brdf) s_->brdf = std::make_shared<BrdfPreintegration>(s_->set.brdfSamples);
    return *s_->brdf;
}

// ---- Input checks and preparation ------------------------------------------------------------

namespace {

void CheckInputs(const FrameBuffers& f, Method m, Demodulation d) {
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
    need(f.prevPosition.size(), "prevPosition", "motion vectors");
    need(f.prevNormal.size(), "prevNormal", "motion vectors");
    if (m != Method::Reliable) return;
    need(f.prevBlocker.size(), "prevBlocker", "shadow motion vectors");
    need(f.prevLightSample.size(), "prevLightSample", "shadow motion vectors");
    if (!f.glossy.empty()) {
        need(f.prevGlossyHit.size(), "prevGlossyHit", "glossy motion vectors");
        need(f.roughness.size(), "roughness", "glossy motion vectors");
    }
    if (!f.indirect.empty() && !f.cones.empty())
        need(f.albedo.size(), "albedo", "shading the indirect cones");
}

// One sweep over the frame's buffers: guides and components as planes.
void Prepare(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, const BrdfPreintegration* brdf,
             bool demod) {
    Guides& g = s.G();
    const int w = s.w;
    ComponentPlanes& vis = s.comp[kVis];
    ComponentPlanes& gl = s.comp[kGlossy];
    ComponentPlanes& ind = s.comp[kIndirect];
    const bool hasGl = gl.present, hasInd = ind.present, cones = s.conesPath;
    const glm::vec3 camPos = f.camera.position;
    ForRows(s.h, [&](int y) {
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            const glm::vec3 p = f.position[i];
            glm::vec3 n = f.normal[i];
            const float z = f.depth[i];
            const float nl = glm::length(n);
            const bool ok = Finite(p) && Finite(n) && nl > 0.0f && std::isfinite(z) && z > 0.0f;
            n = ok ? n / nl : glm::vec3(0.0f);
            g.px.At(x, y) = ok ? p.x : 0.0f, g.py.At(x, y) = ok ? p.y : 0.0f;
            g.pz.At(x, y) = ok ? p.z : 0.0f;
            g.nx.At(x, y) = n.x, g.ny.At(x, y) = n.y, g.nz.At(x, y) = n.z;
            g.depth.At(x, y) = ok ? z : 0.0f;
            g.objectId.At(x, y) = ok ? f.objectId[i] : -2;
            g.valid.At(x, y) = ok ? 1 : 0;

            const float v = f.visibility[i];
            const bool vok = ok && std::isfinite(v);
            vis.v[0].At(x, y) = vok ? v : 0.0f;
            vis.valid.At(x, y) = vok ? 1.0f : 0.0f;

            if (hasGl) {
                const glm::vec3 c = f.glossy[i];
                glm::vec3 r(1.0f);
                if (demod && ok) {
                    const glm::vec3 f0 = f.specular[i];
                    const float rough = f.roughness[i];
                    const float cosT = glm::dot(n, glm::normalize(camPos - p));
                    if (Finite(f0) && std::isfinite(rough) && std::isfinite(cosT)) {
                        const glm::vec3 fb = brdf->Evaluate(f0, std::max(cosT, 0.0f), rough);
                        for (int k = 0; k < 3; ++k) r[k] = fb[k] > kMinRemod ? fb[k] : 1.0f;
                    }
                }
                const bool cok = ok && Finite(c);
                for (int k = 0; k < 3; ++k) {
                    gl.v[k].At(x, y) = cok ? c[k] / r[k] : 0.0f;
                    gl.remod[k].At(x, y) = r[k];
                }
                gl.valid.At(x, y) = cok ? 1.0f : 0.0f;
            }
            if (hasInd) {
                glm::vec3 c(0.0f), r(1.0f);
                bool cok = ok;
                if (cones) {
                    // The cones' diffuse shading; the albedo multiplies it back in any mode.
                    const glm::vec3* cp = f.cones.data() + i * kNumCones;
                    for (int k = 0; k < kNumCones; ++k) cok = cok && Finite(cp[k]);
                    if (cok) c = ShadeCones(cp);
                    const glm::vec3 al = f.albedo[i];
                    r = Finite(al) ? al : glm::vec3(0.0f);
                } else {
                    c = f.indirect[i];
                    cok = cok && Finite(c);
                    if (demod) {
                        const glm::vec3 al = f.albedo[i];
                        if (Finite(al))
                            for (int k = 0; k < 3; ++k) r[k] = al[k] > kMinRemod ? al[k] : 1.0f;
                    }
                    c /= r;
                }
                for (int k = 0; k < 3; ++k) {
                    ind.v[k].At(x, y) = cok ? c[k] : 0.0f;
                    ind.remod[k].At(x, y) = r[k];
                }
                ind.valid.At(x, y) = cok ? 1.0f : 0.0f;
            }
        }
    });
    // Depth tolerance of the edge-stopping weights: the smaller one-sided depth step to a valid
    // neighbour (so an edge does not widen its own tolerance), per axis.
    ForRows(s.h, [&](int y) {
        const float* z = g.depth.Row(y);
        const uint8_t* ok = g.valid.Row(y);
        const float* zu = y > 0 ? g.depth.Row(y - 1) : nullptr;
        const float* zd = y + 1 < s.h ? g.depth.Row(y + 1) : nullptr;
        const uint8_t* oku = y > 0 ? g.valid.Row(y - 1) : nullptr;
        const uint8_t* okd = y + 1 < s.h ? g.valid.Row(y + 1) : nullptr;
        float* ix = g.invDzX.Row(y);
        float* iy = g.invDzY.Row(y);
        constexpr float kBig = std::numeric_limits<float>::max();
        for (int x = 0; x < w; ++x) {
            if (!ok[x]) {
                ix[x] = iy[x] = 0.0f;
                continue;
            }
            float gx = kBig, gy = kBig;
            if (x > 0 && ok[x - 1]) gx = std::min(gx, std::abs(z[x] - z[x - 1]));
            if (x + 1 < w && ok[x + 1]) gx = std::min(gx, std::abs(z[x] - z[x + 1]));
            if (zu && oku[x]) gy = std::min(gy, std::abs(z[x] - zu[x]));
            if (zd && okd[x]) gy = std::min(gy, std::abs(z[x] - zd[x]));
            gx = gx == kBig ? 0.0f : gx, gy = gy == kBig ? 0.0f : gy;
            ix[x] = 1.0f / (gx + 1e-3f * z[x]);
            iy[x] = 1.0f / (gy + 1e-3f * z[x]);
        }
    });
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

// Spatial luminance variance of `nc` planes over the valid samples of a 5x5 box (SVGF's
// fallback for short histories; a box rather than its 7x7 bilateral, for speed).
void SpatialVariance(ScreenSpaceDenoiser::State& s, const Plane* const* v, const Plane& valid,
                     int nc, Plane* var) {
    ForRows(s.h, [&](int y) {
        float* l = s.lum.Row(y);
        float* l2 = s.t[0].Row(y);
        float* ok = s.t[1].Row(y);
        const float* vv = valid.Row(y);
        const float* r = v[0]->Row(y);
        const float* gg = nc == 3 ? v[1]->Row(y) : r;
        const float* b = nc == 3 ? v[2]->Row(y) : r;
        for (int x = 0; x < s.w; ++x) {
            const float lu = nc == 3 ? Luma(r[x], gg[x], b[x]) : r[x];
            l[x] = vv[x] * lu, l2[x] = vv[x] * lu * lu, ok[x] = vv[x];
        }
    });
    const Plane* in[3] = {&s.lum, &s.t[0], &s.t[1]};
    Plane* out[3] = {&s.a[0], &s.a[1], &s.a[2]};
    Plane* tmp[3] = {&s.b[0], &s.b[1], &s.b[2]};
    BoxSum(3, in, out, tmp, 2);
    ForRows(s.h, [&](int y) {
        const float* s1 = s.a[0].Row(y);
        const float* s2 = s.a[1].Row(y);
        const float* n = s.a[2].Row(y);
        float* o = var->Row(y);
        for (int x = 0; x < s.w; ++x) {
            const float m = n[x] > 0.0f ? s1[x] / n[x] : 0.0f;
            o[x] = n[x] > 0.0f ? std::max(0.0f, s2[x] / n[x] - m * m) : 0.0f;
        }
    });
}

// SVGF's luminance edge-stopping scale from the 3x3-blurred variance: 1 / (sigma_l sqrt(var) +
// eps); 0 (no luminance stopping) where the sample is unusable.
void InvLuminance(ScreenSpaceDenoiser::State& s, const Plane& var, const Plane& valid) {
    const float sl = s.set.sigmaLuminance;
    ForRows(s.h, [&](int y) {
        const float* r0 = var.Row(std::max(0, y - 1));
        const float* r1 = var.Row(y);
        const float* r2 = var.Row(std::min(s.h - 1, y + 1));
        const float* ok = valid.Row(y);
        float* o = s.invLum.Row(y);
        for (int x = 0; x < s.w; ++x) {
            const float b = (r0[x - 1] + 2.0f * r0[x] + r0[x + 1]) +
                            2.0f * (r1[x - 1] + 2.0f * r1[x] + r1[x + 1]) +
                            (r2[x - 1] + 2.0f * r2[x] + r2[x + 1]);
            o[x] = ok[x] > 0.0f
                       ? 1.0f / (sl * std::sqrt(std::max(0.0f, b * (1.0f / 16.0f))) + 1e-6f)
                       : 0.0f;
        }
    });
}

// `levels` a-trous iterations (separable 5-tap B3 passes, steps 1, 2, 4, ...) of `nc` planes
// with variance; the result lands in `out`/`outValid`. After the first iteration its output is
// copied to `feedback` (SVGF's colour history) when given.
void Atrous(ScreenSpaceDenoiser::State& s, int nc, Plane* const* in, const Plane& inValid,
            const Plane& inVar, Plane* const* out, Plane* outValid, Plane* const* feedback) {
    static constexpr float kB3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};
    const int levels = s.set.atrousLevels;
    Plane* src[3] = {in[0], in[1], in[2]};
    const Plane* srcValid = &inValid;
    const Plane* srcVar = &inVar;
    for (int level = 0; level < levels; ++level) {
        const int step = 1 << level;
        const bool last = level == levels - 1;
        Plane* dst[3];
        Plane* dstValid;
        Plane* dstVar = (level & 1) ? &s.vara : &s.varb;
        if (last) {
            for (int c = 0; c < 3; ++c) dst[c] = out[c];
            dstValid = outValid;
        } else {
            for (int c = 0; c < 3; ++c) dst[c] = (level & 1) ? &s.a[c] : &s.b[c];
            dstValid = (level & 1) ? &s.va : &s.vb;
        }
        InvLuminance(s, *srcVar, *srcValid);
        PassArgs a = BaseArgs(s, nc);
        a.taps = 5;
        for (int k = 0; k < 5; ++k) a.offset[k] = (k - 2) * step, a.weight[k] = kB3[k];
        a.invLum = &s.invLum;
        // horizontal: src -> t
        for (int c = 0; c < nc; ++c) a.in[c] = src[c], a.out[c] = &s.t[c];
        a.valid = srcValid, a.outValid = &s.vt, a.var = srcVar, a.outVar = &s.vart;
        FilterPlanes(a);
        // vertical: t -> dst
        a.vertical = true;
        for (int c = 0; c < nc; ++c) a.in[c] = &s.t[c], a.out[c] = dst[c];
        a.valid = &s.vt, a.outValid = dstValid, a.var = &s.vart, a.outVar = dstVar;
        FilterPlanes(a);
        if (level == 0 && feedback)
            for (int c = 0; c < nc; ++c)
                ForRows(s.h, [&](int y) { std::copy_n(dst[c]->Row(y), s.w, feedback[c]->Row(y)); });
        for (int c = 0; c < 3; ++c) src[c] = dst[c];
        srcValid = dstValid, srcVar = dstVar;
    }
}

// Separable joint bilateral (depth + normal guides, Gaussian of std radius / 2): Zeng's shadow
// filter.
void Bilateral(ScreenSpaceDenoiser::State& s, int nc, Plane* const* in, const Plane& inValid,
               int radius, Plane* const* out, Plane* outValid) {
    PassArgs a = BaseArgs(s, nc);
    a.taps = 2 * radius + 1;
    const float sig = std::max(0.5f, 0.5f * float(radius));
    for (int k = 0; k < a.taps; ++k) {
        const float d = float(k - radius);
        a.offset[k] = k - radius, a.weight[k] = std::exp(-d * d / (2.0f * sig * sig));
    }
    for (int c = 0; c < nc; ++c) a.in[c] = in[c], a.out[c] = &s.t[c];
    a.valid = &inValid, a.outValid = &s.vt;
    FilterPlanes(a);
    a.vertical = true;
    for (int c = 0; c < nc; ++c) a.in[c] = &s.t[c], a.out[c] = out[c];
    a.valid = &s.vt, a.outValid = outValid;
    FilterPlanes(a);
}

// Zeng's clean-up: separable joint bilateral 9x9 with the per-pixel std in s.sigma.
void Cleanup(ScreenSpaceDenoiser::State& s, int nc, Plane* const* in, const Plane& inValid,
             Plane* const* out) {
    PassArgs a = BaseArgs(s, nc);
    a.taps = 9;
    for (int k = 0; k < 9; ++k) a.offset[k] = k - 4, a.weight[k] = 1.0f;
    a.sigma = &s.sigma;
    for (int c = 0; c < nc; ++c) a.in[c] = in[c], a.out[c] = &s.t[c];
    a.valid = &inValid, a.outValid = &s.vt;
    FilterPlanes(a);
    a.vertical = true;
    for (int c = 0; c < nc; ++c) a.in[c] = &s.t[c], a.out[c] = out[c];
    a.valid = &s.vt, a.outValid = nullptr;
    FilterPlanes(a);
}

// ---- Per-component pipelines ---------------------------------------------------------------

// SVGF order. `mf` null: no history (first frame, SpatialOnly). clampK 0: no clamping.
void SvgfComponent(ScreenSpaceDenoiser::State& s, int ci, const MotionField* mf, float clampK) {
    ComponentPlanes& cp = s.comp[ci];
    const int nc = cp.nc;
    History& hc = s.hist[ci][s.cur];
    const History* hp = mf && s.hist[ci][s.cur ^ 1].valid ? &s.hist[ci][s.cur ^ 1] : nullptr;
    const float alpha = s.set.alpha;
    auto t0 = Clock::now();
    const Plane* inPlanes[3] = {&cp.v[0], &cp.v[1], &cp.v[2]};
    SpatialVariance(s, inPlanes, cp.valid, nc, &s.spVar);
    auto t1 = Clock::now();
    s.timings.spatial += Ms(t0, t1);
    // Temporal accumulation into s.a (integrated colour), s.va, s.vara (variance).
    const Guides& g = s.G();
    ForRows(s.h, [&](int y) {
        for (int x = 0; x < s.w; ++x) {
            float out[3] = {0, 0, 0}, m1 = 0, m2 = 0, len = 0, ok = 0;
            if (g.valid.At(x, y)) {
                HistoryTaps tp;
                const bool hist = hp && GatherTaps(*mf, x, y, &tp);
                float hcv[3] = {0, 0, 0}, hm1 = 0, hm2 = 0, hl = 0;
                if (hist) {
                    for (int c = 0; c < nc; ++c) hcv[c] = Fetch(hp->c[c], tp);
                    hm1 = Fetch(hp->m1, tp), hm2 = Fetch(hp->m2, tp), hl = Fetch(hp->len, tp);
                    if (clampK > 0.0f) {
                        float mu[3], sg[3];
                        Neighbourhood(inPlanes, cp.valid, nc, x, y, mu, sg);
                        for (int c = 0; c < nc; ++c)
                            hcv[c] =
                                std::clamp(hcv[c], mu[c] - clampK * sg[c], mu[c] + clampK * sg[c]);
                    }
                }
                const bool cur = cp.valid.At(x, y) > 0.0f;
                if (cur) {
                    float cv[3] = {0, 0, 0};
                    for (int c = 0; c < nc; ++c) cv[c] = cp.v[c].At(x, y);
                    const float l = nc == 3 ? Luma(cv[0], cv[1], cv[2]) : cv[0];
                    len = hist ? std::min(hl + 1.0f, kMaxLen) : 1.0f;
                    const float a = hist ? std::max(alpha, 1.0f / len) : 1.0f;
                    for (int c = 0; c < nc; ++c) out[c] = hcv[c] + a * (cv[c] - hcv[c]);
                    m1 = hm1 + a * (l - hm1), m2 = hm2 + a * (l * l - hm2);
                    ok = 1.0f;
                } else if (hist) {  // no usable sample now: keep the history
                    for (int c = 0; c < nc; ++c) out[c] = hcv[c];
                    m1 = hm1, m2 = hm2, len = hl, ok = 1.0f;
                }
            }
            for (int c = 0; c < nc; ++c) s.a[c].At(x, y) = out[c];
            s.va.At(x, y) = ok;
            hc.m1.At(x, y) = m1, hc.m2.At(x, y) = m2, hc.len.At(x, y) = len;
            s.vara.At(x, y) = len >= 4.0f ? std::max(0.0f, m2 - m1 * m1) : s.spVar.At(x, y);
        }
    });
    auto t2 = Clock::now();
    s.timings.temporal += Ms(t1, t2);
    // a-trous; the first iteration's output is the next frame's colour history. Atrous() only
    // overwrites s.a / s.va / s.vara (the input) after its first iteration has read them.
    Plane* in[3] = {&s.a[0], &s.a[1], &s.a[2]};
    Plane* out[3] = {&cp.out[0], &cp.out[1], &cp.out[2]};
    Plane* fb[3] = {&hc.c[0], &hc.c[1], &hc.c[2]};
    Atrous(s, nc, in, s.va, s.vara, out, &cp.outValid, fb);
    for (int c = 0; c < 3; ++c) cp.res[c] = &cp.out[c];
    hc.valid = true;
    s.timings.spatial += Ms(t2, Clock::now());
}

// Zeng order: spatial (joint bilateral for visibility, a-trous with a spatial variance for
// glossy) -> history clamped to mu +- k sigma of the filtered frame, blended with alpha or
// alpha^V -> clean-up of std min(w_A + w_C, 5). The result is the next history.
void ReliableComponent(ScreenSpaceDenoiser::State& s, int ci, const MotionField* mf,
                       const Plane* alphaV, bool bilateral) {
    ComponentPlanes& cp = s.comp[ci];
    const int nc = cp.nc;
    History& hc = s.hist[ci][s.cur];
    const History* hp = mf && s.hist[ci][s.cur ^ 1].valid ? &s.hist[ci][s.cur ^ 1] : nullptr;
    const float alpha = s.set.alpha, clampK = s.set.reliableClampK;
    auto t0 = Clock::now();
    Plane* in[3] = {&cp.v[0], &cp.v[1], &cp.v[2]};
    Plane* sp[3] = {&s.a[0], &s.a[1], &s.a[2]};
    if (bilateral) {
        Bilateral(s, nc, in, cp.valid, s.set.shadowRadius, sp, &s.va);
    } else {
        SpatialVariance(s, in, cp.valid, nc, &s.spVar);
        Atrous(s, nc, in, cp.valid, s.spVar, sp, &s.va, nullptr);
    }
    auto t1 = Clock::now();
    s.timings.spatial += Ms(t0, t1);
    const Guides& g = s.G();
    const Plane* spc[3] = {sp[0], sp[1], sp[2]};
    ForRows(s.h, [&](int y) {
        for (int x = 0; x < s.w; ++x) {
            float out[3] = {0, 0, 0}, len = 0, ok = 0, sigma = 0;
            if (g.valid.At(x, y)) {
                HistoryTaps tp;
                const bool hist = hp && GatherTaps(*mf, x, y, &tp);
                float hv[3] = {0, 0, 0}, hl = 0;
                const float av = alphaV ? alphaV->At(x, y) : alpha;
                if (hist) {
                    float lb = 0.0f, la = 0.0f;
                    float mu[3], sg[3];
                    Neighbourhood(spc, s.va, nc, x, y, mu, sg);
                    for (int c = 0; c < nc; ++c) {
                        const float v = Fetch(hp->c[c], tp);
                        hv[c] = std::clamp(v, mu[c] - clampK * sg[c], mu[c] + clampK * sg[c]);
                        lb += v, la += hv[c];
                    }
                    hl = Fetch(hp->len, tp);
                    // eq. 8 on the channel sum, eq. 7, and the clean-up std.
                    const float wc = std::abs(la - lb) / (std::abs(lb) + 1e-3f);
                    const float wa = (av - alpha) * (av - alpha);
                    sigma = std::min(wa + wc, 5.0f);
                }
                if (s.va.At(x, y) > 0.0f) {
                    len = hist ? std::min(hl + 1.0f, kMaxLen) : 1.0f;
                    const float a = hist ? std::max(av, 1.0f / len) : 1.0f;
                    for (int c = 0; c < nc; ++c) out[c] = hv[c] + a * (sp[c]->At(x, y) - hv[c]);
                    ok = 1.0f;
                } else if (hist) {
                    for (int c = 0; c < nc; ++c) out[c] = hv[c];
                    len = hl, ok = 1.0f;
                }
            }
            for (int c = 0; c < nc; ++c) s.b[c].At(x, y) = out[c];
            s.vb.At(x, y) = ok;
            s.sigma.At(x, y) = sigma;
            hc.len.At(x, y) = len;
        }
    });
    auto t2 = Clock::now();
    s.timings.temporal += Ms(t1, t2);
    Plane* bl[3] = {&s.b[0], &s.b[1], &s.b[2]};
    Plane* res[3] = {&hc.c[0], &hc.c[1], &hc.c[2]};
    Cleanup(s, nc, bl, s.vb, res);
    for (int c = 0; c < 3; ++c) cp.res[c] = &hc.c[c];
    hc.valid = true;
    s.timings.cleanup += Ms(t2, Clock::now());
}

// Cone axes with the azimuths' sines and cosines as constants (ConeAxes() evaluates them).
inline void FastConeAxes(glm::vec3 n, glm::vec3* axes) {
    static constexpr float kC[5] = {1.0f, 0.30901699f, -0.80901699f, -0.80901699f, 0.30901699f};
    static constexpr float kS[5] = {0.0f, 0.95105652f, 0.58778525f, -0.58778525f, -0.95105652f};
    glm::vec3 t1, t2;
    ConeFrame(n, &t1, &t2);
    axes[0] = n;
    for (int k = 1; k < kNumCones; ++k)
        axes[k] = 0.86602540f * (kC[k - 1] * t1 + kS[k - 1] * t2) + 0.5f * n;
}

// History cones `hp` (recorded in the frame of normal np) as seen by cone frame of n: cone k
// takes the overlap-weighted mean of the history cones (eqs. 9-10) and `cover[k]` says how much
// of its usual overlap it found (1 for the same frame; less when the hemispheres only partly
// overlap, so the blend leans on the current frame there).
inline void TransferCones(const ConeOverlapTable& t, glm::vec3 n, glm::vec3 np, const float* hp,
                          float* h, float* cover) {
    if (glm::dot(n, np) > 0.9999f && (n.z >= 0.0f) == (np.z >= 0.0f)) {
        for (int k = 0; k < kNumCones; ++k) {
            float acc[3] = {0, 0, 0};
            for (int j = 0; j < kNumCones; ++j) {
                const float wkj = t.SameFrame(k, j);
                for (int c = 0; c < 3; ++c) acc[c] += wkj * hp[3 * j + c];
            }
            const float inv = 1.0f / t.SameFrameRowSum(k);
            for (int c = 0; c < 3; ++c) h[3 * k + c] = acc[c] * inv;
            cover[k] = 1.0f;
        }
        return;
    }
    glm::vec3 a[kNumCones], ap[kNumCones];
    FastConeAxes(n, a);
    FastConeAxes(np, ap);
    for (int k = 0; k < kNumCones; ++k) {
        float acc[3] = {0, 0, 0}, sum = 0.0f;
        for (int j = 0; j < kNumCones; ++j) {
            const float wkj = t.Overlap(glm::dot(a[k], ap[j]));
            sum += wkj;
            for (int c = 0; c < 3; ++c) acc[c] += wkj * hp[3 * j + c];
        }
        const float inv = sum > 0.0f ? 1.0f / sum : 0.0f;
        for (int c = 0; c < 3; ++c) h[3 * k + c] = acc[c] * inv;
        cover[k] = std::min(1.0f, sum / t.SameFrameRowSum(k));
    }
}

// Reliable diffuse indirect with cones (Sec. 4.3): per-cone temporal reuse along the occlusion
// vectors, SVGF moments of the shaded result, a-trous on the shading. The cones are the history.
void ConesComponent(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, const MotionField* mf) {
    ComponentPlanes& cp = s.comp[kIndirect];
    History& hc = s.hist[kIndirect][s.cur];
    const History& prev = s.hist[kIndirect][s.cur ^ 1];
    const size_t np = size_t(s.w) * size_t(s.h);
    const History* hp = mf && prev.valid && prev.cones.size() == np * kConeFloats ? &prev : nullptr;
    if (hc.cones.size() != np * kConeFloats) hc.cones.Assign(np * kConeFloats, 0.0f);
    const float alpha = s.set.alpha, clampK = s.set.reliableClampK;
    auto t0 = Clock::now();
    const Plane* in[3] = {&cp.v[0], &cp.v[1], &cp.v[2]};
    SpatialVariance(s, in, cp.valid, 3, &s.spVar);
    auto t1 = Clock::now();
    s.timings.spatial += Ms(t0, t1);
    const Guides& g = s.G();
    const Guides& pg = s.PrevG();
    const ConeOverlapTable& table = s.coneTable;
    ForRows(s.h, [&](int y) {
        for (int x = 0; x < s.w; ++x) {
            const size_t i = size_t(y) * size_t(s.w) + size_t(x);
            float* lo = hc.cones.data() + i * kConeFloats;
            float e[3] = {0, 0, 0}, m1 = 0, m2 = 0, len = 0, ok = 0;
            std::fill_n(lo, kConeFloats, 0.0f);
            if (g.valid.At(x, y)) {
                HistoryTaps tp;
                const bool hist = hp && GatherTaps(*mf, x, y, &tp);
                float hcones[kConeFloats], cover[kNumCones], hm1 = 0, hm2 = 0, hl = 0;
                if (hist) {
                    float hraw[kConeFloats] = {};
                    int dom = 0;
                    for (int k = 0; k < tp.n; ++k) {
                        const float* src =
                            hp->cones.data() +
                            (size_t(tp.y[k]) * size_t(s.w) + size_t(tp.x[k])) * kConeFloats;
                        for (int c = 0; c < kConeFloats; ++c) hraw[c] += tp.w[k] * src[c];
                        if (tp.w[k] > tp.w[dom]) dom = k;
                    }
                    const glm::vec3 n(g.nx.At(x, y), g.ny.At(x, y), g.nz.At(x, y));
                    const glm::vec3 nprev(pg.nx.At(tp.x[dom], tp.y[dom]),
                                          pg.ny.At(tp.x[dom], tp.y[dom]),
                                          pg.nz.At(tp.x[dom], tp.y[dom]));
                    TransferCones(table, n, nprev, hraw, hcones, cover);
                    hm1 = Fetch(hp->m1, tp), hm2 = Fetch(hp->m2, tp), hl = Fetch(hp->len, tp);
                    // Clamp the history's shading to mu +- k sigma of the current shading; scale
                    // the cones alike.
                    float mu[3], sg[3], sh[3] = {0, 0, 0};
                    Neighbourhood(in, cp.valid, 3, x, y, mu, sg);
                    for (int k = 0; k < kNumCones; ++k)
                        for (int c = 0; c < 3; ++c)
                            sh[c] += kConeShadeWeight[k] * hcones[3 * k + c];
                    for (int c = 0; c < 3; ++c) {
                        const float cl =
                            std::clamp(sh[c], mu[c] - clampK * sg[c], mu[c] + clampK * sg[c]);
                        const float fct = sh[c] > 1e-12f ? cl / sh[c] : 1.0f;
                        for (int k = 0; k < kNumCones; ++k) hcones[3 * k + c] *= fct;
                    }
                }
                if (cp.valid.At(x, y) > 0.0f) {
                    const glm::vec3* cur = f.cones.data() + i * kNumCones;
                    const float l = Luma(cp.v[0].At(x, y), cp.v[1].At(x, y), cp.v[2].At(x, y));
                    len = hist ? std::min(hl + 1.0f, kMaxLen) : 1.0f;
                    const float a = hist ? std::max(alpha, 1.0f / len) : 1.0f;
                    for (int k = 0; k < kNumCones; ++k) {
                        const float ak = hist ? 1.0f - (1.0f - a) * cover[k] : 1.0f;
                        for (int c = 0; c < 3; ++c) {
                            const float hv = hist ? hcones[3 * k + c] : 0.0f;
                            lo[3 * k + c] = hv + ak * (cur[k][c] - hv);
                        }
                    }
                    m1 = hm1 + a * (l - hm1), m2 = hm2 + a * (l * l - hm2);
                    ok = 1.0f;
                } else if (hist) {
                    std::copy_n(hcones, kConeFloats, lo);
                    m1 = hm1, m2 = hm2, len = hl, ok = 1.0f;
                }
                for (int k = 0; k < kNumCones; ++k)
                    for (int c = 0; c < 3; ++c) e[c] += kConeShadeWeight[k] * lo[3 * k + c];
            }
            for (int c = 0; c < 3; ++c) s.a[c].At(x, y) = e[c];
            s.va.At(x, y) = ok;
            hc.m1.At(x, y) = m1, hc.m2.At(x, y) = m2, hc.len.At(x, y) = len;
            s.vara.At(x, y) = len >= 4.0f ? std::max(0.0f, m2 - m1 * m1) : s.spVar.At(x, y);
        }
    });
    auto t2 = Clock::now();
    s.timings.temporal += Ms(t1, t2);
    Plane* ain[3] = {&s.a[0], &s.a[1], &s.a[2]};
    Plane* out[3] = {&cp.out[0], &cp.out[1], &cp.out[2]};
    Atrous(s, 3, ain, s.va, s.vara, out, &cp.outValid, nullptr);
    for (int c = 0; c < 3; ++c) cp.res[c] = &cp.out[c];
    hc.valid = true;
    s.timings.spatial += Ms(t2, Clock::now());
}

void Compose(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, std::vector<glm::vec3>* out) {
    out->resize(size_t(s.w) * size_t(s.h));
    const ComponentPlanes& vis = s.comp[kVis];
    const ComponentPlanes& gl = s.comp[kGlossy];
    const ComponentPlanes& ind = s.comp[kIndirect];
    ForRows(s.h, [&](int y) {
        for (int x = 0; x < s.w; ++x) {
            const size_t i = size_t(y) * size_t(s.w) + size_t(x);
            glm::vec3 c(0.0f);
            if (!f.emitted.empty() && Finite(f.emitted[i])) c += f.emitted[i];
            if (Finite(f.shading[i])) c += f.shading[i] * vis.res[0]->At(x, y);
            for (const ComponentPlanes* cp : {&gl, &ind}) {
                if (!cp->present) continue;
                for (int k = 0; k < 3; ++k) c[k] += cp->remod[k].At(x, y) * cp->res[k]->At(x, y);
            }
            (*out)[i] = c;
        }
    });
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
    const auto t0 = Clock::now();
    frame.Validate("ScreenSpaceDenoiser::Denoise");
    CheckInputs(frame, method, demodulation);
    s.timings = StageTimings{};
    if (frame.width != s.w || frame.height != s.h)
        s.Resize(frame.width, frame.height);
    else if (method != s.method || demodulation != s.demod)
        Reset();
    s.method = method, s.demod = demodulation;
    const bool reliable = method == Method::Reliable;
    const bool demod = demodulation == Demodulation::On;
    s.comp[kVis].nc = 1, s.comp[kVis].present = true;
    s.comp[kGlossy].nc = 3, s.comp[kGlossy].present = !frame.glossy.empty();
    s.comp[kIndirect].nc = 3, s.comp[kIndirect].present = !frame.indirect.empty();
    const bool conesPath = reliable && !frame.indirect.empty() && !frame.cones.empty();
    if (conesPath != s.conesPath) s.hist[kIndirect][s.cur ^ 1].valid = false;  // other format
    s.conesPath = conesPath;
    for (int c = 0; c < 3; ++c)
        if (!s.comp[c].present) s.hist[c][s.cur].valid = false;
    const BrdfPreintegration* brdf = demod && s.comp[kGlossy].present ? &Brdf() : nullptr;
    Prepare(s, frame, brdf, demod);
    auto t1 = Clock::now();
    s.timings.prepare = Ms(t0, t1);

    const bool temporal = method != Method::SpatialOnly && s.hasPrev;
    std::fill(std::begin(s.motionValid), std::end(s.motionValid), false);
    if (temporal) {
        const PrevFrame pf{&s.PrevG(), s.prevCam};
        TraditionalMotion(frame, s.G(), pf, &s.trad);
        s.motionValid[int(MotionKind::Traditional)] = true;
        auto t2 = Clock::now();
        s.timings.traditionalMotion = Ms(t1, t2);
        if (reliable) {
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
            s.timings.reliableMotion = Ms(t2, Clock::now());
        }
    }

    const MotionField* trad = temporal ? &s.trad : nullptr;
    if (reliable) {
        ReliableComponent(s, kVis, temporal ? &s.shadow : nullptr,
                          temporal ? &s.shadowAlpha : nullptr, true);
        if (s.comp[kGlossy].present)
            ReliableComponent(s, kGlossy, temporal ? &s.glossy : nullptr, nullptr, false);
        if (s.comp[kIndirect].present) {
            const MotionField* occl = temporal ? &s.occl : nullptr;
            if (conesPath)
                ConesComponent(s, frame, occl);
            else
                SvgfComponent(s, kIndirect, occl, s.set.reliableClampK);
        }
    } else {
        const float k = method == Method::BaselineClamp ? s.set.baselineClampK : 0.0f;
        for (int c = 0; c < 3; ++c)
            if (s.comp[c].present) SvgfComponent(s, c, trad, k);
    }

    auto t3 = Clock::now();
    Compose(s, frame, image);
    s.prevCam = frame.camera;
    s.cur ^= 1;
    s.hasPrev = true;
    ++s.frameIndex;
    const auto t4 = Clock::now();
    s.timings.compose = Ms(t3, t4);
    s.timings.total = Ms(t0, t4);
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
    const MotionField* m[4] = {&s.trad, &s.shadow, &s.glossy, &s.occl};
    const bool ok = s.motionValid[int(kind)];
    const MotionField& f = *m[int(kind)];
    return Collect<glm::vec2>(s, [&](int x, int y) {
        if (!ok || !f.taps.At(x, y)) return glm::vec2(kNaN);
        return glm::vec2(f.x.At(x, y), f.y.At(x, y));
    });
}

}  // namespace texcache::screen
