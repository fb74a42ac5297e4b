// SPDX-License-Identifier: Apache-2.0
// The temporal passes of the screen-space stage (see denoiser_state.h).
//
// Design note. Each pass is one loop over a row that does everything a pixel needs at once (3x3
// neighbourhood statistics of the current frame, the bilinear history gathered over the taps the
// motion field allows, clamping, the blend, moments), written without branches (selects and
// zero weights instead) so that GCC vectorizes it, with AVX2 gathers for the history; whether a
// history exists at all is a template parameter, not a per-pixel test. The cone pass is the
// exception: 18 floats per pixel and a 6x6 transfer whose weights depend on the two normals are
// done per pixel, vectorized across the cones' channels.
#include <algorithm>
#include <cmath>
#include <cstring>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "screen_space/denoiser_state.h"
#include "screen_space/internal.h"

namespace texcache::screen::internal {
namespace {

constexpr float kMaxLen = 255.0f;           // history lengths only select alpha and the variance
constexpr int kConeFloats = 3 * kNumCones;  // a pixel's cones in FrameBuffers

// Rows y-1, y, y+1 of a plane, with factor 0 for a row outside the image (then the centre row
// is read in its place).
struct Rows3 {
    int r[3];
    float f[3];
    Rows3(int y, int h) {
        r[0] = y > 0 ? y - 1 : y, r[1] = y, r[2] = y + 1 < h ? y + 1 : y;
        f[0] = y > 0 ? 1.0f : 0.0f, f[1] = 1.0f, f[2] = y + 1 < h ? 1.0f : 0.0f;
    }
};

// Sums over the usable samples of a 3x3 neighbourhood: count, per channel and of the
// luminance (the channel itself for NC = 1), and of their squares.
struct Stats3x3 {
    float cnt = 0.0f, s1[3] = {0, 0, 0}, s2[3] = {0, 0, 0}, sl = 0.0f, sl2 = 0.0f;
};
template <int NC>
inline __attribute__((always_inline)) Stats3x3 Neighbourhood(const float* const (&cur)[3][3],
                                                             const float* const (&valid)[3],
                                                             const float (&rowF)[3], int x) {
    Stats3x3 st;
#pragma GCC unroll 3
    for (int r = 0; r < 3; ++r)
#pragma GCC unroll 3
        for (int dx = -1; dx <= 1; ++dx) {
            const float ok = valid[r][x + dx] * rowF[r];
            float v[3] = {0, 0, 0};
#pragma GCC unroll 3
            for (int c = 0; c < NC; ++c) v[c] = cur[c][r][x + dx];
            st.cnt += ok;
#pragma GCC unroll 3
            for (int c = 0; c < NC; ++c) st.s1[c] += ok * v[c], st.s2[c] += ok * v[c] * v[c];
            if constexpr (NC == 3) {
                const float l = Luma(v[0], v[1], v[2]);
                st.sl += ok * l, st.sl2 += ok * l * l;
            }
        }
    if constexpr (NC == 1) st.sl = st.s1[0], st.sl2 = st.s2[0];
    return st;
}

// ---- The history of a chunk of pixels ---------------------------------------------------------
//
// A temporal pass first fetches, for every pixel of a chunk, the bilinear history of each plane
// it reads (BilinearTaps: 4 taps, weights renormalized over the usable ones) into local arrays,
// and then runs its per-pixel arithmetic over the chunk in one loop. Motion is smooth, so
// along a run of consecutive pixels the taps' column offset (tap index - x) is usually a single
// value: such a run reads each plane with contiguous vector loads at x + d00 (+1) and x + d01
// (+1). A run where the offset changes (the motion crosses a pixel boundary) is tried again in
// shorter pieces, and only the pieces with the change load tap by tap, where a vector loop
// would have to assemble each vector lane by lane (on the AMD Zen 4 machines a 16-lane gather
// costs about as much as the rest of a temporal kernel's arithmetic). Every path evaluates the
// same expression in the same order, so a pixel's history does not depend on the path.

constexpr int kChunk = 256;  // pixels per chunk of a row
constexpr int kRun = 64;     // pixels per run (RunOffsets)
constexpr int kSubRun = 16;  // pieces of a run that is not uniform

// The taps of a chunk's pixels (chunk position i, pixel x = x0 + i), and for RunTaps the taps'
// offsets relative to the chunk position (tap 00 of position i is at e00 + i) as the bounds of
// a run's minimum and maximum: a pixel without a usable tap has zero weights and takes any
// offset, so it widens neither (lo = +inf, hi = -inf).
struct ChunkTaps {
    alignas(64) int i00[kChunk], i01[kChunk];  // indices of taps 00 and 01
    alignas(64) float w00[kChunk], w10[kChunk], w01[kChunk], w11[kChunk], ok[kChunk];
    alignas(64) int lo0[kChunk], hi0[kChunk], lo1[kChunk], hi1[kChunk];
};

// Fills `t` for pixels x0 .. x0 + n - 1 of a row whose motion is (mx, my, mt).
inline __attribute__((always_inline)) void MakeChunkTaps(const float* mx, const float* my,
                                                         const uint8_t* mt, int x0, int n,
                                                         int width, int height, int stride,
                                                         ChunkTaps* t) {
    constexpr int kBig = 1 << 30;
    for (int i = 0; i < n; ++i) {
        const int x = x0 + i;
        const Bilinear b = BilinearTaps(mx[x], my[x], int(mt[x]), width, height, stride);
        t->i00[i] = b.i00, t->i01[i] = b.i01;
        t->w00[i] = b.w00, t->w10[i] = b.w10, t->w01[i] = b.w01, t->w11[i] = b.w11;
        t->ok[i] = b.ok;
        const bool has = mt[x] != 0;
        const int e0 = b.i00 - i, e1 = b.i01 - i;
        t->lo0[i] = has ? e0 : kBig, t->hi0[i] = has ? e0 : -kBig;
        t->lo1[i] = has ? e1 : kBig, t->hi1[i] = has ? e1 : -kBig;
    }
}

// Whether chunk positions [i0, i1) share their tap offsets, and those offsets. Uniform only if
// every address the run implies lies inside a plane of `size` floats.
struct RunOffsets {
    int e00 = 0, e01 = 0;
    bool uniform = false;
};
inline __attribute__((always_inline)) RunOffsets RunTaps(const ChunkTaps& t, int i0, int i1,
                                                         size_t size) {
    int lo0 = 1 << 30, hi0 = -(1 << 30), lo1 = 1 << 30, hi1 = -(1 << 30);
    for (int i = i0; i < i1; ++i) lo0 = std::min(lo0, t.lo0[i]), hi0 = std::max(hi0, t.hi0[i]);
    for (int i = i0; i < i1; ++i) lo1 = std::min(lo1, t.lo1[i]), hi1 = std::max(hi1, t.hi1[i]);
    RunOffsets r;
    if (lo0 > hi0) {  // no usable tap: any address inside the plane will do
        r.e00 = r.e01 = -i0;
        r.uniform = true;
        return r;
    }
    r.e00 = lo0, r.e01 = lo1;
    r.uniform = lo0 == hi0 && lo1 == hi1 && lo0 + i0 >= 0 && lo1 + i0 >= 0 &&
                size_t(std::max(lo0, lo1) + i1) < size;
    return r;
}

// out[i] for chunk positions [i0, i1): the bilinear history of the plane at `base`.
inline __attribute__((always_inline)) void FetchUniform(const ChunkTaps& t, const RunOffsets& r,
                                                        const float* base, int i0, int i1,
                                                        float* out) {
    const float* p0 = base + r.e00;
    const float* p1 = base + r.e01;
    for (int i = i0; i < i1; ++i)
        out[i] = t.w00[i] * p0[i] + t.w10[i] * p0[i + 1] + t.w01[i] * p1[i] + t.w11[i] * p1[i + 1];
}
// The same tap by tap. A pixel's taps 00 and 10 are adjacent, and so are 01 and 11: each pair is
// read as one 16-byte load (BilinearTaps keeps the two floats after it inside the plane's row
// padding) and four pixels are transposed at a time, half the loads of the scalar code. GCC would
// vectorize the plain loop with a lane-by-lane gather, about twice the instructions of scalar loads
// (the empty asm keeps the remainder scalar).
inline __attribute__((always_inline)) void FetchTaps(const ChunkTaps& t, const float* base, int i0,
                                                     int i1, float* out) {
    int i = i0;
    for (; i + 4 <= i1; i += 4) {
        __m128 a0 = _mm_loadu_ps(base + t.i00[i]), a1 = _mm_loadu_ps(base + t.i00[i + 1]);
        __m128 a2 = _mm_loadu_ps(base + t.i00[i + 2]), a3 = _mm_loadu_ps(base + t.i00[i + 3]);
        __m128 b0 = _mm_loadu_ps(base + t.i01[i]), b1 = _mm_loadu_ps(base + t.i01[i + 1]);
        __m128 b2 = _mm_loadu_ps(base + t.i01[i + 2]), b3 = _mm_loadu_ps(base + t.i01[i + 3]);
        _MM_TRANSPOSE4_PS(a0, a1, a2, a3);  // a0: tap 00 of the four pixels, a1: tap 10
        _MM_TRANSPOSE4_PS(b0, b1, b2, b3);  // b0: tap 01, b1: tap 11
        const __m128 w00 = _mm_loadu_ps(&t.w00[i]), w10 = _mm_loadu_ps(&t.w10[i]);
        const __m128 w01 = _mm_loadu_ps(&t.w01[i]), w11 = _mm_loadu_ps(&t.w11[i]);
        // The scalar expression, in its order, so that both paths give the same value.
        _mm_storeu_ps(out + i, w00 * a0 + w10 * a1 + w01 * b0 + w11 * b1);
    }
    for (; i < i1; ++i) {
        int a = t.i00[i], b = t.i01[i];
        asm("" : "+r"(a), "+r"(b));
        out[i] = t.w00[i] * base[a] + t.w10[i] * base[a + 1] + t.w01[i] * base[b] +
                 t.w11[i] * base[b + 1];
    }
}

// out[p][i]: the bilinear history of planes[p] (np of them, bases of planes of `size` floats)
// for chunk positions [0, n).
template <int NP>
inline __attribute__((always_inline)) void FetchHistory(const ChunkTaps& t, int n, size_t size,
                                                        const float* const (&planes)[NP],
                                                        float (*out)[kChunk]) {
    for (int i0 = 0; i0 < n; i0 += kRun) {
        const int i1 = std::min(n, i0 + kRun);
        const RunOffsets r = RunTaps(t, i0, i1, size);
        if (r.uniform) {
            for (int p = 0; p < NP; ++p) FetchUniform(t, r, planes[p], i0, i1, out[p]);
            continue;
        }
        for (int j0 = i0; j0 < i1; j0 += kSubRun) {
            const int j1 = std::min(i1, j0 + kSubRun);
            const RunOffsets sub = RunTaps(t, j0, j1, size);
            for (int p = 0; p < NP; ++p) {
                if (sub.uniform)
                    FetchUniform(t, sub, planes[p], j0, j1, out[p]);
                else
                    FetchTaps(t, planes[p], j0, j1, out[p]);
            }
        }
    }
}

// Whether any of n pixels has a usable sample (valid > 0) or, with `taps`, a history tap.
inline __attribute__((always_inline)) bool AnySampleOrHistory(const float* valid,
                                                              const uint8_t* taps, int n) {
    float v = 0.0f;
    for (int i = 0; i < n; ++i) v = std::max(v, valid[i]);
    int t = 0;
    if (taps)
        for (int i = 0; i < n; ++i) t |= taps[i];
    return v > 0.0f || t != 0;
}

struct SvgfArgs {
    int w, h, stride;
    const float* cur[3][3];  // [channel][row] at x = 0
    const float* valid[3];   // [row]
    float rowF[3];
    const float* mx;
    const float* my;
    const uint8_t* mt;
    const float* hc[3];  // history bases
    const float* hm1;
    const float* hm2;
    const float* hlen;
    float alpha, clampK;
    float varPerAlpha;       // variance scale per unit of blend weight (large: unscaled)
    const float* clampKRow;  // per-pixel k of the row (Clamp == kClampPerPixel)
    float* out[3];
    float* outVar;
    float* m1;
    float* m2;
    float* len;
};

// How SvgfRowImpl clamps the history: not at all, with one k, or with a k per pixel.
constexpr int kClampNone = 0, kClampUniform = 1, kClampPerPixel = 2;

template <int NC, bool Hist, int Clamp>
inline __attribute__((always_inline)) void SvgfRowImpl(const SvgfArgs& args) {
    // Everything the loop reads is copied to locals and its results go to local arrays: then the
    // compiler sees no possible aliasing and needs no run-time checks to vectorize.
    const SvgfArgs a = args;
    // Written planes plus read ones (the current values and validity; with history, its NC + 3
    // planes and the motion): see AtrousRowImpl in kernels.cpp.
    const bool stream = StreamPlanes(a.w, a.h, (NC + 4) + (NC + 1) + (Hist ? NC + 5 : 0));
    const size_t size = size_t(a.stride) * size_t(a.h);
    constexpr int kC = kChunk;
    alignas(64) float o[3][kC], ovar[kC], om1[kC], om2[kC], olen[kC];
    alignas(64) float fetched[NC + 3][kC];  // colour, m1, m2, length
    ChunkTaps taps;
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        if (!AnySampleOrHistory(a.valid[1] + x0, Hist ? a.mt + x0 : nullptr, n)) {
            // Neither a sample nor a history tap (background): no history, length 0, unusable.
            for (int c = 0; c < NC; ++c) std::fill_n(a.out[c] + x0, n, 0.0f);
            std::fill_n(a.outVar + x0, n, -1.0f);
            for (float* p : {a.m1, a.m2, a.len}) std::fill_n(p + x0, n, 0.0f);
            continue;
        }
        if constexpr (Hist) {
            MakeChunkTaps(a.mx, a.my, a.mt, x0, n, a.w, a.h, a.stride, &taps);
            const float* planes[NC + 3];
            for (int c = 0; c < NC; ++c) planes[c] = a.hc[c];
            planes[NC] = a.hm1, planes[NC + 1] = a.hm2, planes[NC + 2] = a.hlen;
            FetchHistory(taps, n, size, planes, fetched);
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            // 3x3 statistics of the current frame (valid samples only).
            const Stats3x3 st = Neighbourhood<NC>(a.cur, a.valid, a.rowF, x);
            const float cnt = st.cnt, sl = st.sl, sl2 = st.sl2;
            const float* s1 = st.s1;
            const float* s2 = st.s2;
            const float in = cnt > 0.0f ? 1.0f / cnt : 0.0f;
            const float lm = sl * in;
            const float spVar = std::max(0.0f, sl2 * in - lm * lm);

            // Validity as 0/1 floats and arithmetic blends rather than bools: GCC 12 gives up
            // on loops mixing boolean widths.
            const float cv = a.valid[1][x];
            float v[3] = {0, 0, 0};
#pragma GCC unroll 3
            for (int c = 0; c < NC; ++c) v[c] = a.cur[c][1][x];
            const float l = NC == 3 ? Luma(v[0], v[1], v[2]) : v[0];

            float hv[3] = {0, 0, 0}, hm1 = 0.0f, hm2 = 0.0f, hl = 0.0f, hf = 0.0f;
            if constexpr (Hist) {
#pragma GCC unroll 3
                for (int c = 0; c < NC; ++c) hv[c] = fetched[c][i];
                hm1 = fetched[NC][i], hm2 = fetched[NC + 1][i], hl = fetched[NC + 2][i];
                hf = taps.ok[i] * (hl >= 0.5f ? 1.0f : 0.0f);
                if constexpr (Clamp != kClampNone) {
                    const float k = Clamp == kClampPerPixel ? a.clampKRow[x] : a.clampK;
#pragma GCC unroll 3
                    for (int c = 0; c < NC; ++c) {
                        const float mu = s1[c] * in;
                        const float sg = std::sqrt(std::max(0.0f, s2[c] * in - mu * mu));
                        const float cl = std::min(std::max(hv[c], mu - k * sg), mu + k * sg);
                        hv[c] = k > 0.0f ? cl : hv[c];  // per pixel, k = 0: not clamped
                    }
                }
#pragma GCC unroll 3
                for (int c = 0; c < NC; ++c) hv[c] *= hf;
                hm1 *= hf, hm2 *= hf, hl *= hf;
            }
            // len: +1 with a new sample; al: max(alpha, 1/len) with history, 1 without, 0
            // without a new sample.
            const float len =
                cv * (hf * std::min(hl + 1.0f, kMaxLen) + (1.0f - hf)) + (1.0f - cv) * hl;
            const float al = cv * (hf * std::max(a.alpha, 1.0f / std::max(len, 1.0f)) + 1.0f - hf);
#pragma GCC unroll 3
            for (int c = 0; c < NC; ++c) o[c][i] = hv[c] + al * (v[c] - hv[c]);
            const float m1 = hm1 + al * (l - hm1), m2 = hm2 + al * (l * l - hm2);
            om1[i] = m1, om2[i] = m2, olen[i] = len;
            // The moments give a sample's variance; a still view's running mean is worth more
            // samples than the moving blend, so its variance (the a-trous' edge stop) falls
            // with the blend's weight and the filter blurs less as the view converges.
            const float vs = std::min(1.0f, std::max(al, 1.0f / kMaxLen) * a.varPerAlpha);
            const float tv = len >= 4.0f ? vs * std::max(0.0f, m2 - m1 * m1) : spVar;
            ovar[i] = std::max(cv, hf) > 0.0f ? tv : -1.0f;
        }
        for (int c = 0; c < NC; ++c) StoreRow(o[c], n, a.out[c] + x0, stream);
        StoreRow(ovar, n, a.outVar + x0, stream);
        StoreRow(om1, n, a.m1 + x0, stream), StoreRow(om2, n, a.m2 + x0, stream);
        StoreRow(olen, n, a.len + x0, stream);
    }
}

#define TEXCACHE_SVGF(name, NC, H, C)                     \
    TEXCACHE_SCREEN_CLONES void name(const SvgfArgs& a) { \
        SvgfRowImpl<NC, H, C>(a);                         \
    }
TEXCACHE_SVGF(Svgf1, 1, false, kClampNone)
TEXCACHE_SVGF(Svgf1H, 1, true, kClampNone)
TEXCACHE_SVGF(Svgf1HC, 1, true, kClampUniform)
TEXCACHE_SVGF(Svgf1HP, 1, true, kClampPerPixel)
TEXCACHE_SVGF(Svgf3, 3, false, kClampNone)
TEXCACHE_SVGF(Svgf3H, 3, true, kClampNone)
TEXCACHE_SVGF(Svgf3HC, 3, true, kClampUniform)
#undef TEXCACHE_SVGF

struct ReliableArgs {
    int w, h, stride;
    const float* sp[3][3];  // [channel][row]
    const float* spVar[3];  // [row]
    float rowF[3];
    const float* mx;
    const float* my;
    const uint8_t* mt;
    const float* alphaV;  // null: alpha
    const float* hc[3];
    const float* hlen;
    float alpha, clampK;
    float* out[3];
    float* outValid;
    float* sigma;
    float* len;
};

template <int NC, bool Hist, bool AlphaV>
inline __attribute__((always_inline)) void ReliableRowImpl(const ReliableArgs& args) {
    const ReliableArgs a = args;  // locals + local results: see SvgfRowImpl
    const bool stream = StreamPlanes(a.w, a.h, NC + 3);
    const size_t size = size_t(a.stride) * size_t(a.h);
    constexpr int kC = kChunk;
    alignas(64) float o[3][kC], ovalid[kC], osigma[kC], olen[kC];
    alignas(64) float fetched[NC + 1][kC];  // colour, length
    ChunkTaps taps;
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        if constexpr (Hist) {
            MakeChunkTaps(a.mx, a.my, a.mt, x0, n, a.w, a.h, a.stride, &taps);
            const float* planes[NC + 1];
            for (int c = 0; c < NC; ++c) planes[c] = a.hc[c];
            planes[NC] = a.hlen;
            FetchHistory(taps, n, size, planes, fetched);
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            float cnt = 0.0f, s1[3] = {0, 0, 0}, s2[3] = {0, 0, 0};
#pragma GCC unroll 3
            for (int r = 0; r < 3; ++r)
#pragma GCC unroll 3
                for (int dx = -1; dx <= 1; ++dx) {
                    const float ok = a.spVar[r][x + dx] >= 0.0f ? a.rowF[r] : 0.0f;
                    cnt += ok;
#pragma GCC unroll 3
                    for (int c = 0; c < NC; ++c) {
                        const float v = a.sp[c][r][x + dx];
                        s1[c] += ok * v, s2[c] += ok * v * v;
                    }
                }
            const float in = cnt > 0.0f ? 1.0f / cnt : 0.0f;
            const float cv = a.spVar[1][x] >= 0.0f ? 1.0f : 0.0f;  // 0/1: see SvgfRowImpl
            const float av = AlphaV ? a.alphaV[x] : a.alpha;
            float hv[3] = {0, 0, 0}, hl = 0.0f, hf = 0.0f, sigma = 0.0f;
            if constexpr (Hist) {
                hl = fetched[NC][i];
                hf = taps.ok[i] * (hl >= 0.5f ? 1.0f : 0.0f);
                float before = 0.0f, after = 0.0f;
#pragma GCC unroll 3
                for (int c = 0; c < NC; ++c) {
                    const float h = fetched[c][i];
                    const float mu = s1[c] * in;
                    const float sg = std::sqrt(std::max(0.0f, s2[c] * in - mu * mu));
                    hv[c] = std::min(std::max(h, mu - a.clampK * sg), mu + a.clampK * sg);
                    before += h, after += hv[c];
                    hv[c] *= hf;
                }
                hl *= hf;
                // eq. 8 on the channel sum, eq. 7, and the clean-up std.
                const float wc = std::fabs(after - before) / (std::fabs(before) + 1e-3f);
                const float wa = (av - a.alpha) * (av - a.alpha);
                sigma = hf * std::min(wa + wc, 5.0f);
            }
            const float len =
                cv * (hf * std::min(hl + 1.0f, kMaxLen) + (1.0f - hf)) + (1.0f - cv) * hl;
            const float al = cv * (hf * std::max(av, 1.0f / std::max(len, 1.0f)) + 1.0f - hf);
#pragma GCC unroll 3
            for (int c = 0; c < NC; ++c) o[c][i] = hv[c] + al * (a.sp[c][1][x] - hv[c]);
            ovalid[i] = std::max(cv, hf);
            osigma[i] = sigma;
            olen[i] = len;
        }
        for (int c = 0; c < NC; ++c) StoreRow(o[c], n, a.out[c] + x0, stream);
        StoreRow(ovalid, n, a.outValid + x0, stream);
        StoreRow(osigma, n, a.sigma + x0, stream), StoreRow(olen, n, a.len + x0, stream);
    }
}

#define TEXCACHE_RELIABLE(name, NC, H, AV)                    \
    TEXCACHE_SCREEN_CLONES void name(const ReliableArgs& a) { \
        ReliableRowImpl<NC, H, AV>(a);                        \
    }
TEXCACHE_RELIABLE(Reliable1, 1, false, false)
TEXCACHE_RELIABLE(Reliable1H, 1, true, false)
TEXCACHE_RELIABLE(Reliable1HA, 1, true, true)
TEXCACHE_RELIABLE(Reliable3, 3, false, false)
TEXCACHE_RELIABLE(Reliable3H, 3, true, false)
#undef TEXCACHE_RELIABLE

}  // namespace

void SvgfTemporal(ScreenSpaceDenoiser::State& s, int ci, const MotionField* mf, float clampK,
                  const Plane* clampKPerPixel) {
    ComponentPlanes& cp = s.comp[ci];
    ComponentScratch& sc = s.scratch[ci];
    History& hc = s.hist[ci][s.cur];
    const History* hp = mf && s.hist[ci][s.cur ^ 1].valid ? &s.hist[ci][s.cur ^ 1] : nullptr;
    const int nc = cp.nc;
    ForRowBlocks(s.h, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            const Rows3 r3(y, s.h);
            SvgfArgs a;
            a.w = s.w, a.h = s.h, a.stride = int(cp.valid.Stride());
            for (int r = 0; r < 3; ++r) {
                for (int c = 0; c < nc; ++c) a.cur[c][r] = cp.v[c].Row(r3.r[r]);
                a.valid[r] = cp.valid.Row(r3.r[r]);
                a.rowF[r] = r3.f[r];
            }
            if (hp) {
                a.mx = mf->x.Row(y), a.my = mf->y.Row(y), a.mt = mf->taps.Row(y);
                for (int c = 0; c < nc; ++c) a.hc[c] = hp->c[c].Base();
                a.hm1 = hp->m1.Base(), a.hm2 = hp->m2.Base(), a.hlen = hp->len.Base();
            }
            // A component the renderer accumulates over a still view keeps the moving blend.
            a.alpha = ci == kIndirect && s.indirectAccumulates ? std::max(s.blendAlpha, s.set.alpha)
                                                               : s.blendAlpha;
            a.clampK = clampK;
            a.varPerAlpha = s.stillFrames >= 0 ? 1.0f / s.set.alpha : 1e6f;
            a.clampKRow = clampKPerPixel ? clampKPerPixel->Row(y) : nullptr;
            for (int c = 0; c < nc; ++c) a.out[c] = sc.t[c].Row(y);
            a.outVar = sc.tVar.Row(y);
            a.m1 = hc.m1.Row(y), a.m2 = hc.m2.Row(y), a.len = hc.len.Row(y);
            if (nc == 3)
                !hp ? Svgf3(a) : clampK > 0.0f ? Svgf3HC(a) : Svgf3H(a);
            else if (hp && clampKPerPixel)
                Svgf1HP(a);
            else
                !hp ? Svgf1(a) : clampK > 0.0f ? Svgf1HC(a) : Svgf1H(a);
        }
    });
}

void ReliableTemporal(ScreenSpaceDenoiser::State& s, int ci, Plane* const* sp, const Plane& spVar,
                      const MotionField* mf, const Plane* alphaV) {
    ComponentPlanes& cp = s.comp[ci];
    ComponentScratch& sc = s.scratch[ci];
    History& hc = s.hist[ci][s.cur];
    const History* hp = mf && s.hist[ci][s.cur ^ 1].valid ? &s.hist[ci][s.cur ^ 1] : nullptr;
    const int nc = cp.nc;
    ForRowBlocks(s.h, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            const Rows3 r3(y, s.h);
            ReliableArgs a;
            a.w = s.w, a.h = s.h, a.stride = int(spVar.Stride());
            for (int r = 0; r < 3; ++r) {
                for (int c = 0; c < nc; ++c) a.sp[c][r] = sp[c]->Row(r3.r[r]);
                a.spVar[r] = spVar.Row(r3.r[r]);
                a.rowF[r] = r3.f[r];
            }
            a.alphaV = hp && alphaV ? alphaV->Row(y) : nullptr;
            if (hp) {
                a.mx = mf->x.Row(y), a.my = mf->y.Row(y), a.mt = mf->taps.Row(y);
                for (int c = 0; c < nc; ++c) a.hc[c] = hp->c[c].Base();
                a.hlen = hp->len.Base();
            }
            a.alpha = s.set.alpha, a.clampK = s.set.reliableClampK;
            for (int c = 0; c < nc; ++c) a.out[c] = sc.t[c].Row(y);
            a.outValid = sc.tVar.Row(y);
            a.sigma = s.sigma.Row(y);
            a.len = hc.len.Row(y);
            if (nc == 3)
                hp ? Reliable3H(a) : Reliable3(a);
            else
                !hp ? Reliable1(a) : a.alphaV ? Reliable1HA(a) : Reliable1H(a);
        }
    });
}

void CachedWhereNoHistory(ScreenSpaceDenoiser::State& s, bool svgf) {
    ComponentPlanes& cp = s.comp[kVis];
    ComponentScratch& sc = s.scratch[kVis];
    History& hc = s.hist[kVis][s.cur];
    ForRows(s.h, [&](int y) {
        const float* cached = s.cachedVis.Row(y);
        const float* valid = cp.valid.Row(y);
        const float* len = hc.len.Row(y);
        float* t = sc.t[0].Row(y);
        float* var = sc.tVar.Row(y);
        float* m1 = hc.m1.Row(y);
        float* m2 = hc.m2.Row(y);
        for (int x = 0; x < s.w; ++x) {
            // len 1 with a usable sample: blended with weight 1, i.e. no history was found.
            const bool use = cached[x] >= 0.0f && valid[x] > 0.0f && len[x] == 1.0f;
            if (!use) continue;
            t[x] = cached[x];
            if (svgf) var[x] = 0.0f, m1[x] = cached[x], m2[x] = cached[x] * cached[x];
        }
    });
}

// ---- Cones ---------------------------------------------------------------------------------
//
// History layout: per pixel 3 vectors of 8 floats, one per colour channel, lanes 0..5 the 6 cones
// (lanes 6, 7 zero), so the bilinear fetch, the overlap transfer and the blend are 8-wide vector
// operations (GCC vector extensions: AVX2/AVX-512 clones, split in two on the baseline).

namespace {

typedef float V8 __attribute__((vector_size(32)));
// V8 values are passed between internal functions that are inlined into each ISA clone, so the
// baseline clone's different vector ABI (-Wpsabi) never matters.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
constexpr int kConeStride = 24;  // floats per pixel in the history

inline V8 Load8(const float* p) {
    V8 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
inline void Store8(float* p, V8 v) {
    std::memcpy(p, &v, sizeof v);
}
inline float Sum6(V8 v, V8 w) {
    const V8 m = v * w;
    return m[0] + m[1] + m[2] + m[3] + m[4] + m[5];
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

// The overlap transfer (eqs. 9-10) of history cones recorded in the cone frame of normal np into
// the cone frame of n: cone k takes the overlap-weighted mean of the history cones. Returned as
// 6 columns: out = sum_j col[j] * raw[j] (per channel), and `cover`, how much of its usual
// overlap cone k found (1 for the same frame; less where the hemispheres only partly overlap,
// so the blend leans on the current frame there).
struct ConeTransfer {
    V8 col[kNumCones];
    V8 cover;
};
inline void SameFrameTransfer(const ConeOverlapTable& t, ConeTransfer* tr) {
    for (int j = 0; j < kNumCones; ++j) {
        V8 c = {};
        for (int k = 0; k < kNumCones; ++k) c[k] = t.SameFrame(k, j) / t.SameFrameRowSum(k);
        tr->col[j] = c;
    }
    tr->cover = V8{1, 1, 1, 1, 1, 1, 0, 0};
}
inline void GeneralTransfer(const ConeOverlapTable& t, glm::vec3 n, glm::vec3 np,
                            ConeTransfer* tr) {
    glm::vec3 a[kNumCones], ap[kNumCones];
    FastConeAxes(n, a);
    FastConeAxes(np, ap);
    float w[kNumCones][kNumCones], sum[kNumCones];
    for (int k = 0; k < kNumCones; ++k) {
        sum[k] = 0.0f;
        for (int j = 0; j < kNumCones; ++j) {
            w[k][j] = t.Overlap(glm::dot(a[k], ap[j]));
            sum[k] += w[k][j];
        }
    }
    for (int j = 0; j < kNumCones; ++j) {
        V8 c = {};
        for (int k = 0; k < kNumCones; ++k) c[k] = sum[k] > 0.0f ? w[k][j] / sum[k] : 0.0f;
        tr->col[j] = c;
    }
    V8 cv = {};
    for (int k = 0; k < kNumCones; ++k) cv[k] = std::min(1.0f, sum[k] / t.SameFrameRowSum(k));
    tr->cover = cv;
}

struct ConeArgs {
    int w, h, stride;
    const float* ec[3][3];  // current shading [channel][row]
    const float* valid[3];  // [row]
    float rowF[3];
    const uint8_t* guideValid;
    const float* mx;
    const float* my;
    const uint8_t* mt;
    const float* hm1;
    const float* hm2;
    const float* hlen;
    const float* curCones;   // this frame's cones of the row: [cone][rgb], 18 floats per pixel
    const float* histCones;  // previous history, padded pixel index x kConeStride
    float* outCones;         // this frame's history of the row
    const float* nx;         // this frame's normals of the row
    const float* ny;
    const float* nz;
    const float* pnx;  // previous normals, bases
    const float* pny;
    const float* pnz;
    const ConeOverlapTable* table;
    const ConeTransfer* same;
    float alpha, clampK;
    const float* clampKRow;  // per-pixel k of the row (Clamp == kClampPerPixel)
    float* out[3];
    float* outVar;
    float* m1;
    float* m2;
    float* len;
};

template <bool Hist>
inline __attribute__((always_inline)) void ConeRowImpl(const ConeArgs& a) {
    const bool stream = StreamPlanes(a.w, a.h, 7);
    const size_t size = size_t(a.stride) * size_t(a.h);
    constexpr int kC = kChunk;
    alignas(64) float mu[3][kC], sg[3][kC], spv[kC], hf[kC], hm1[kC], hm2[kC], hl[kC];
    alignas(64) float fetched[3][kC];  // length, m1, m2
    alignas(64) float oe[3][kC], om1[kC], om2[kC], olen[kC], ovar[kC];
    ChunkTaps taps;
    const V8 shade = {kConeShadeWeight[0],
                      kConeShadeWeight[1],
                      kConeShadeWeight[2],
                      kConeShadeWeight[3],
                      kConeShadeWeight[4],
                      kConeShadeWeight[5],
                      0,
                      0};
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        if constexpr (Hist) {
            MakeChunkTaps(a.mx, a.my, a.mt, x0, n, a.w, a.h, a.stride, &taps);
            const float* planes[3] = {a.hlen, a.hm1, a.hm2};
            FetchHistory(taps, n, size, planes, fetched);
        }
        // Pass 1 (vectorized across pixels): 3x3 statistics of the current shading, the history
        // moments.
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const Stats3x3 st = Neighbourhood<3>(a.ec, a.valid, a.rowF, x);
            const float cnt = st.cnt, sl = st.sl, sl2 = st.sl2;
            const float* s1 = st.s1;
            const float* s2 = st.s2;
            const float in = cnt > 0.0f ? 1.0f / cnt : 0.0f;
#pragma GCC unroll 3
            for (int c = 0; c < 3; ++c) {
                mu[c][i] = s1[c] * in;
                sg[c][i] = std::sqrt(std::max(0.0f, s2[c] * in - mu[c][i] * mu[c][i]));
            }
            spv[i] = std::max(0.0f, sl2 * in - sl * in * sl * in);
            if constexpr (Hist) {
                const float l = fetched[0][i];
                hf[i] = taps.ok[i] * (l >= 0.5f ? 1.0f : 0.0f);
                hm1[i] = hf[i] * fetched[1][i];
                hm2[i] = hf[i] * fetched[2][i];
                hl[i] = hf[i] * l;
            } else {
                hf[i] = hm1[i] = hm2[i] = hl[i] = 0.0f;
            }
        }
        // Pass 2: the cones, pixel by pixel, 8-wide across the cones of a channel.
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            float* lo = a.outCones + size_t(x) * kConeStride;
            const float cv = a.valid[1][x];
            const bool hist = Hist && hf[i] > 0.0f;
            if (!a.guideValid[x]) {
                std::fill_n(lo, kConeStride, 0.0f);
                oe[0][i] = oe[1][i] = oe[2][i] = 0.0f;
                om1[i] = om2[i] = olen[i] = 0.0f, ovar[i] = -1.0f;
                continue;
            }
            V8 hc[3] = {V8{}, V8{}, V8{}};
            V8 cover = {1, 1, 1, 1, 1, 1, 0, 0};
            if (hist) {
                V8 raw[3] = {V8{}, V8{}, V8{}};
                const int idx[4] = {taps.i00[i], taps.i00[i] + 1, taps.i01[i], taps.i01[i] + 1};
                const float wt[4] = {taps.w00[i], taps.w10[i], taps.w01[i], taps.w11[i]};
                int dom = 0;
                for (int k = 0; k < 4; ++k) {
                    const float wk = wt[k];
                    const float* src = a.histCones + size_t(idx[k]) * kConeStride;
                    for (int c = 0; c < 3; ++c) raw[c] += wk * Load8(src + 8 * c);
                    dom = wk > wt[dom] ? k : dom;
                }
                const glm::vec3 nc(a.nx[x], a.ny[x], a.nz[x]);
                const int id = idx[dom];
                const glm::vec3 np(a.pnx[id], a.pny[id], a.pnz[id]);
                ConeTransfer general;
                const ConeTransfer* tr = a.same;
                if (!(glm::dot(nc, np) > 0.9999f && (nc.z >= 0.0f) == (np.z >= 0.0f))) {
                    GeneralTransfer(*a.table, nc, np, &general);
                    tr = &general;
                }
                cover = tr->cover;
                for (int c = 0; c < 3; ++c)
                    for (int j = 0; j < kNumCones; ++j) hc[c] += tr->col[j] * raw[c][j];
                // Clamp the history's shading to mu +- k sigma of the current shading; the
                // cones are scaled alike (k = 0: no clamping).
                for (int c = 0; c < 3 && a.clampK > 0.0f; ++c) {
                    const float sh = Sum6(hc[c], shade);
                    const float cl = std::clamp(sh, mu[c][i] - a.clampK * sg[c][i],
                                                mu[c][i] + a.clampK * sg[c][i]);
                    hc[c] *= sh > 1e-12f ? cl / sh : 1.0f;
                }
            }
            const float len =
                cv * (hist ? std::min(hl[i] + 1.0f, kMaxLen) : 1.0f) + (1.0f - cv) * hl[i];
            const float al = cv * (hist ? std::max(a.alpha, 1.0f / std::max(len, 1.0f)) : 1.0f);
            // A cone only partly covered by the history's cones leans on the current frame.
            const V8 ak = 1.0f - (1.0f - al) * cover;
            const float* cur = a.curCones + size_t(x) * kConeFloats;
            for (int c = 0; c < 3; ++c) {
                V8 cu = {};
                if (cv > 0.0f)
                    for (int k = 0; k < kNumCones; ++k) cu[k] = cur[3 * k + c];
                const V8 r = cv > 0.0f ? hc[c] + ak * (cu - hc[c]) : hc[c];
                Store8(lo + 8 * c, r);
                oe[c][i] = Sum6(r, shade);
            }
            const float l = Luma(a.ec[0][1][x], a.ec[1][1][x], a.ec[2][1][x]);
            const float m1 = hm1[i] + al * (l - hm1[i]), m2 = hm2[i] + al * (l * l - hm2[i]);
            om1[i] = m1, om2[i] = m2, olen[i] = len;
            const bool any = cv > 0.0f || hist;
            ovar[i] = any ? (len >= 4.0f ? std::max(0.0f, m2 - m1 * m1) : spv[i]) : -1.0f;
        }
        for (int c = 0; c < 3; ++c) StoreRow(oe[c], n, a.out[c] + x0, stream);
        StoreRow(ovar, n, a.outVar + x0, stream);
        StoreRow(om1, n, a.m1 + x0, stream), StoreRow(om2, n, a.m2 + x0, stream);
        StoreRow(olen, n, a.len + x0, stream);
    }
}

TEXCACHE_SCREEN_CLONES void ConeRow(const ConeArgs& a) {
    ConeRowImpl<false>(a);
}
TEXCACHE_SCREEN_CLONES void ConeRowH(const ConeArgs& a) {
    ConeRowImpl<true>(a);
}
#pragma GCC diagnostic pop

}  // namespace

void ConesTemporal(ScreenSpaceDenoiser::State& s, const FrameBuffers& f, const MotionField* mf) {
    ComponentPlanes& cp = s.comp[kIndirect];
    ComponentScratch& sc = s.scratch[kIndirect];
    History& hc = s.hist[kIndirect][s.cur];
    const History& prev = s.hist[kIndirect][s.cur ^ 1];
    const int stride = int(cp.valid.Stride());
    const size_t nCones = size_t(stride) * size_t(s.h) * kConeStride;
    const History* hp = mf && prev.valid && prev.cones.size() == nCones ? &prev : nullptr;
    if (hc.cones.size() != nCones) hc.cones.Assign(nCones, 0.0f);
    ConeTransfer same;
    SameFrameTransfer(s.coneTable, &same);
    const Guides& g = s.G();
    const Guides& pg = s.PrevG();
    ForRowBlocks(s.h, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            const Rows3 r3(y, s.h);
            ConeArgs a;
            a.w = s.w, a.h = s.h, a.stride = stride;
            for (int r = 0; r < 3; ++r) {
                for (int c = 0; c < 3; ++c) a.ec[c][r] = cp.v[c].Row(r3.r[r]);
                a.valid[r] = cp.valid.Row(r3.r[r]);
                a.rowF[r] = r3.f[r];
            }
            a.guideValid = g.valid.Row(y);
            if (hp) {
                a.mx = mf->x.Row(y), a.my = mf->y.Row(y), a.mt = mf->taps.Row(y);
                a.hm1 = hp->m1.Base(), a.hm2 = hp->m2.Base(), a.hlen = hp->len.Base();
                a.histCones = hp->cones.data();
                a.pnx = pg.nx.Base(), a.pny = pg.ny.Base(), a.pnz = pg.nz.Base();
            }
            a.curCones = &f.cones[size_t(y) * size_t(s.w) * kNumCones].x;
            a.outCones = hc.cones.data() + (size_t(y) * size_t(stride) + kPad) * kConeStride;
            a.nx = g.nx.Row(y), a.ny = g.ny.Row(y), a.nz = g.nz.Row(y);
            a.table = &s.coneTable;
            a.same = &same;
            a.alpha = s.blendAlpha, a.clampK = s.set.reliableIndirectClampK;
            for (int c = 0; c < 3; ++c) a.out[c] = sc.t[c].Row(y);
            a.outVar = sc.tVar.Row(y);
            a.m1 = hc.m1.Row(y), a.m2 = hc.m2.Row(y), a.len = hc.len.Row(y);
            hp ? ConeRowH(a) : ConeRow(a);
        }
    });
}

}  // namespace texcache::screen::internal
