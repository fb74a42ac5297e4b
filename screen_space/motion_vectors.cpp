// SPDX-License-Identifier: Apache-2.0
// The motion vectors of the screen-space stage (Zeng et al. 2021, eqs. 1, 3-6).
//
// Every pass is one sweep over the pixels on the TBB pool, reading the frame's AoS buffers once;
// pixels a kind does not apply to (lit pixels for shadows, non-glossy pixels, pixels whose
// traditional vector is fine for occlusion) cost a NaN test and a copy.
#include "screen_space/motion_vectors.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include "screen_space/internal.h"

namespace texcache::screen::internal {
namespace {

inline glm::vec3 PrevPos(const Guides& g, int x, int y) {
    return glm::vec3(g.px.At(x, y), g.py.At(x, y), g.pz.At(x, y));
}

// Relative tolerance of the tangent-plane tests: distance to the plane < kPlaneTol * depth.
constexpr float kPlaneTol = 0.01f;
// Tolerance of the shadow test: a tap's surface may be this far off the receiver's plane.
constexpr float kShadowPlaneTol = 0.02f;
constexpr float kNormalCos = 0.9f;

inline float InRange(int v, int n) {
    return (v >= 0 ? 1.0f : 0.0f) * (v < n ? 1.0f : 0.0f);
}

// base[idx] and base[idx + 1] with one 8-byte load (x86 is little-endian: the left entry is
// the low half). A footprint's taps come in two such pairs, and in a vectorized loop each load
// from a per-pixel address is a scalar load and a lane insert (GCC's generic tuning does not use
// AVX-512 gathers, rightly: on the Zen 4 machines they are slower than the scalar loads, as
// build/bin/screen_space_benchmark's tradMV_ms and newMV_ms show), so pairing halves them.
template <class T>
struct Adjacent {
    T l, r;
};
template <class T>
inline Adjacent<T> LoadAdjacent(const T* base, int idx) {
    static_assert(sizeof(T) == 4);
    uint64_t v;
    std::memcpy(&v, base + idx, sizeof v);
    const uint32_t lo = uint32_t(v), hi = uint32_t(v >> 32);
    Adjacent<T> a;
    std::memcpy(&a.l, &lo, sizeof lo), std::memcpy(&a.r, &hi, sizeof hi);
    return a;
}

}  // namespace

namespace {

// Everything the traditional pass reads for one row, as plain pointers and values, so that the
// kernel (a target_clones function) sees no aliasing and vectorizes: AoS loads of the frame's
// vec3 buffers become strided loads, the previous frame's guides at the 4 taps become gathers.
struct TradRowArgs {
    int w, h, stride;
    const float* pp;  // prevPosition of the row, xyz interleaved
    const float* pn;  // prevNormal of the row
    const uint8_t* valid;
    const int32_t* id;
    const float* gx;  // previous guides, bases (index r * stride + kPad + x)
    const float* gy;
    const float* gz;
    const float* gnx;
    const float* gny;
    const float* gnz;
    const int32_t* gid;
    float m[16];  // previous worldToClip, column-major
    float cam[3];
    float* ox;
    float* oy;
    uint8_t* om;
};

// 1 when the previous frame's surface (position q, normal m, object qid) is the same object, on
// this pixel's previous tangent plane and facing the same way (0/1 floats throughout: GCC 12
// does not vectorize loops mixing boolean widths).
inline float TapPass(float qx, float qy, float qz, float mx, float my, float mz, int32_t qid,
                     float inside, int id, float ppx, float ppy, float ppz, float nx, float ny,
                     float nz, float tol) {
    const float plane = std::fabs((qx - ppx) * nx + (qy - ppy) * ny + (qz - ppz) * nz);
    const float cosn = mx * nx + my * ny + mz * nz;
    const float same = qid == id ? 1.0f : 0.0f;
    return inside * same * (plane < tol ? 1.0f : 0.0f) * (cosn > kNormalCos ? 1.0f : 0.0f);
}
// TapPass of the taps idx and idx + 1.
inline void TapPassPair(const TradRowArgs& a, int idx, float inL, float inR, int id, float ppx,
                        float ppy, float ppz, float nx, float ny, float nz, float tol, float* mL,
                        float* mR) {
    const auto qx = LoadAdjacent(a.gx, idx), qy = LoadAdjacent(a.gy, idx);
    const auto qz = LoadAdjacent(a.gz, idx);
    const auto mx = LoadAdjacent(a.gnx, idx), my = LoadAdjacent(a.gny, idx);
    const auto mz = LoadAdjacent(a.gnz, idx);
    const auto qid = LoadAdjacent(a.gid, idx);
    *mL =
        TapPass(qx.l, qy.l, qz.l, mx.l, my.l, mz.l, qid.l, inL, id, ppx, ppy, ppz, nx, ny, nz, tol);
    *mR =
        TapPass(qx.r, qy.r, qz.r, mx.r, my.r, mz.r, qid.r, inR, id, ppx, ppy, ppz, nx, ny, nz, tol);
}

TEXCACHE_SCREEN_CLONES void TradRow(const TradRowArgs& args) {
    const TradRowArgs a = args;
    const bool stream = StreamPlanes(a.w, a.h, 2);
    constexpr int kC = 256;
    alignas(64) int mask[kC];
    alignas(64) float ox[kC], oy[kC];  // local results: no aliasing with the gathers
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float ppx = a.pp[3 * x], ppy = a.pp[3 * x + 1], ppz = a.pp[3 * x + 2];
            float nx = a.pn[3 * x], ny = a.pn[3 * x + 1], nz = a.pn[3 * x + 2];
            const float cx = a.m[0] * ppx + a.m[4] * ppy + a.m[8] * ppz + a.m[12];
            const float cy = a.m[1] * ppx + a.m[5] * ppy + a.m[9] * ppz + a.m[13];
            const float cw = a.m[3] * ppx + a.m[7] * ppy + a.m[11] * ppz + a.m[15];
            const float nl2 = nx * nx + ny * ny + nz * nz;
            // NaN/Inf anywhere fail these comparisons (and cw > 0: in front of the camera).
            const float okf =
                (a.valid[x] != 0 ? 1.0f : 0.0f) * (cw > 0.0f ? 1.0f : 0.0f) *
                (nl2 > 0.0f ? 1.0f : 0.0f) * (nl2 < 1e30f ? 1.0f : 0.0f) *
                (std::fabs(ppx) + std::fabs(ppy) + std::fabs(ppz) < 1e30f ? 1.0f : 0.0f);
            const bool ok = okf > 0.0f;
            const float iw = ok ? 1.0f / cw : 0.0f;
            const float rx = (cx * iw * 0.5f + 0.5f) * float(a.w);
            const float ry = (0.5f - cy * iw * 0.5f) * float(a.h);
            ox[i] = ok ? rx : kNaN, oy[i] = ok ? ry : kNaN;
            const float inl = ok ? 1.0f / std::sqrt(nl2) : 0.0f;
            nx *= inl, ny *= inl, nz *= inl;
            // Footprint (clamped so far-away positions stay integers; their taps are outside).
            const float fx = std::min(std::max(rx, -4.0f), float(a.w) + 4.0f) - 0.5f;
            const float fy = std::min(std::max(ry, -4.0f), float(a.h) + 4.0f) - 0.5f;
            const int x0i = int(std::floor(fx)), y0i = int(std::floor(fy));
            const int r0 = std::min(std::max(y0i, 0), a.h - 1);
            const int r1 = std::min(std::max(y0i + 1, 0), a.h - 1);
            const int cx0 = std::min(std::max(x0i, -1), a.w - 1);
            const int i00 = r0 * a.stride + kPad + cx0, i01 = r1 * a.stride + kPad + cx0;
            const float inX0 = InRange(x0i, a.w), inX1 = InRange(x0i + 1, a.w);
            const float inY0 = InRange(y0i, a.h), inY1 = InRange(y0i + 1, a.h);
            const float dx = ppx - a.cam[0], dy = ppy - a.cam[1], dz = ppz - a.cam[2];
            const float tol = kPlaneTol * std::sqrt(dx * dx + dy * dy + dz * dz) + 1e-6f;
            const int id = a.id[x];
            float m0, m1, m2, m3;
            TapPassPair(a, i00, inX0 * inY0, inX1 * inY0, id, ppx, ppy, ppz, nx, ny, nz, tol, &m0,
                        &m1);
            TapPassPair(a, i01, inX0 * inY1, inX1 * inY1, id, ppx, ppy, ppz, nx, ny, nz, tol, &m2,
                        &m3);
            mask[i] = int(okf * (m0 + 2.0f * m1 + 4.0f * m2 + 8.0f * m3));
        }
        for (int i = 0; i < n; ++i) a.om[x0 + i] = uint8_t(mask[i]);
        StoreRow(ox, n, a.ox + x0, stream), StoreRow(oy, n, a.oy + x0, stream);
    }
}

}  // namespace

void TraditionalMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                       MotionField* out) {
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    ForRows(h, [&](int y) {
        TradRowArgs a;
        a.w = w, a.h = h, a.stride = int(pg.depth.Stride());
        a.pp = &f.PrevPositionPlane()[size_t(y) * size_t(w)].x;
        a.pn = &f.PrevNormalPlane()[size_t(y) * size_t(w)].x;
        a.valid = cur.valid.Row(y), a.id = cur.objectId.Row(y);
        a.gx = pg.px.Base(), a.gy = pg.py.Base(), a.gz = pg.pz.Base();
        a.gnx = pg.nx.Base(), a.gny = pg.ny.Base(), a.gnz = pg.nz.Base();
        a.gid = pg.objectId.Base();
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) a.m[4 * c + r] = prev.camera.worldToClip[c][r];
        a.cam[0] = prev.camera.position.x, a.cam[1] = prev.camera.position.y;
        a.cam[2] = prev.camera.position.z;
        a.ox = out->x.Row(y), a.oy = out->y.Row(y), a.om = out->taps.Row(y);
        TradRow(a);
    });
}

namespace {

// The 4 taps of a footprint as gather indices (rows clamped into the image, columns into the
// padding) and 0/1 in-image factors.
struct Foot4 {
    int i00, i01;
    float in00, in10, in01, in11;
};
inline Foot4 MakeFoot4(float rx, float ry, int w, int h, int stride) {
    const float fx = std::min(std::max(rx, -4.0f), float(w) + 4.0f) - 0.5f;
    const float fy = std::min(std::max(ry, -4.0f), float(h) + 4.0f) - 0.5f;
    const int x0 = int(std::floor(fx)), y0 = int(std::floor(fy));
    const int r0 = std::min(std::max(y0, 0), h - 1), r1 = std::min(std::max(y0 + 1, 0), h - 1);
    const int cx = std::min(std::max(x0, -1), w - 1);
    Foot4 f;
    f.i00 = r0 * stride + kPad + cx, f.i01 = r1 * stride + kPad + cx;
    const float ix0 = InRange(x0, w), ix1 = InRange(x0 + 1, w);
    const float iy0 = InRange(y0, h), iy1 = InRange(y0 + 1, h);
    f.in00 = ix0 * iy0, f.in10 = ix1 * iy0, f.in01 = ix0 * iy1, f.in11 = ix1 * iy1;
    return f;
}
inline int MaskBits(float m0, float m1, float m2, float m3) {
    return int(m0 + 2.0f * m1 + 4.0f * m2 + 8.0f * m3);
}

// 1 when the previous frame's surface at (px, py, pz) with object pid may hold this pixel's
// shadow history: the same object, or any surface within `tol` of the receiver's plane through
// `q`.
inline float ShadowTap(float px, float py, float pz, int32_t pid, float inside, int id, float qx,
                       float qy, float qz, float nx, float ny, float nz, float tol) {
    const float pl = std::fabs((px - qx) * nx + (py - qy) * ny + (pz - qz) * nz);
    const float same = pid == id ? 1.0f : 0.0f;
    const float near = pl < tol ? 1.0f : 0.0f;
    return inside * std::max(same, near);
}
// The usable-tap mask of a footprint for shadow history (ShadowTap at its 4 taps).
inline int ShadowMask(const float* gx, const float* gy, const float* gz, const int32_t* gid,
                      const Foot4& fp, int id, float qx, float qy, float qz, float nx, float ny,
                      float nz, float tol) {
    float m[4];
    for (int r = 0; r < 2; ++r) {
        const int idx = r ? fp.i01 : fp.i00;
        const auto x = LoadAdjacent(gx, idx), y = LoadAdjacent(gy, idx);
        const auto z = LoadAdjacent(gz, idx);
        const auto pid = LoadAdjacent(gid, idx);
        m[2 * r] =
            ShadowTap(x.l, y.l, z.l, pid.l, r ? fp.in01 : fp.in00, id, qx, qy, qz, nx, ny, nz, tol);
        m[2 * r + 1] =
            ShadowTap(x.r, y.r, z.r, pid.r, r ? fp.in11 : fp.in10, id, qx, qy, qz, nx, ny, nz, tol);
    }
    return MaskBits(m[0], m[1], m[2], m[3]);
}

struct ShadowRowArgs {
    int w, h, stride, y;
    const float* pb;  // prevBlocker, xyz interleaved
    const float* pl;  // prevLightSample
    const float* pp;  // prevPosition
    const float* pn;  // prevNormal
    const uint8_t* valid;
    const int32_t* id;
    const float *gx, *gy, *gz;  // previous guides, bases
    const int32_t* gid;
    const float *tx, *ty;  // traditional vectors of the row
    float pm[16], cam[3];
    float alpha, inv2s2;
    float *ox, *oy, *oa, *mask, *sdx, *sdy, *sal;
    uint8_t* om;
};

// Where a pixel's history would be if only the camera and the receiver moved: its traditional
// vector, or the pixel itself where it has none. Shadow vectors are splatted as offsets from it
// (the shadow's motion over the receiver), so that a splatted pixel keeps its own camera motion:
// splatting absolute offsets would give it its neighbours' parallax instead, which differs
// wherever the camera moves (a fly-through over a static scene).
inline float SplatBase(float t, int x) {
    return std::isfinite(t) ? t : float(x) + 0.5f;
}

// eq. 3 for one row: in-shadow pixels' vectors, eq. 4's alpha^V, and the splat inputs.
TEXCACHE_SCREEN_CLONES void ShadowRow(const ShadowRowArgs& args) {
    const ShadowRowArgs a = args;
    // The vectors are read after the splat's box sums, which pass a dozen planes through the
    // caches in between: streamed when large (StoreRow). The splat inputs are read by the very
    // next pass, while most of them are still in the L3 cache: ordinary stores.
    const bool stream = StreamPlanes(a.w, a.h, 3);
    constexpr int kC = 256;
    // Two loops per chunk (geometry, then eq. 4 and the taps): one loop with everything has too
    // many conditionals for GCC's if-conversion, and then it does not vectorize.
    alignas(64) float ok[kC], vxs[kC], vys[kC], vzs[kC], nxs[kC], nys[kC], nzs[kC], rxs[kC],
        rys[kC], pxs[kC], pys[kC], pzs[kC];
    alignas(64) float ox[kC], oy[kC], oa[kC], mk[kC], sdx[kC], sdy[kC], sal[kC];
    alignas(64) int om[kC];
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        {
            // Chunks where every pixel is lit (NaN blockers): nothing to compute.
            bool any = false;
            for (int i = 0; i < n && !any; ++i) any = std::isfinite(a.pb[3 * (x0 + i)]);
            if (!any) {
                for (int i = 0; i < n; ++i) {
                    const int x = x0 + i;
                    a.ox[x] = kNaN, a.oy[x] = kNaN, a.om[x] = 0, a.oa[x] = a.alpha;
                    a.mask[x] = a.sdx[x] = a.sdy[x] = a.sal[x] = 0.0f;
                }
                continue;
            }
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float bx = a.pb[3 * x], by = a.pb[3 * x + 1], bz = a.pb[3 * x + 2];
            const float lx = a.pl[3 * x], ly = a.pl[3 * x + 1], lz = a.pl[3 * x + 2];
            const float px = a.pp[3 * x], py = a.pp[3 * x + 1], pz = a.pp[3 * x + 2];
            float nx = a.pn[3 * x], ny = a.pn[3 * x + 1], nz = a.pn[3 * x + 2];
            const float nl2 = nx * nx + ny * ny + nz * nz;
            // Lit pixels (NaN blocker) and unusable inputs fail here.
            float okf = (a.valid[x] ? 1.0f : 0.0f) * Fin(bx + by + bz) * Fin(lx + ly + lz) *
                        Fin(px + py + pz) * Fin(nl2) * (nl2 > 0.0f ? 1.0f : 0.0f);
            const float inl = okf > 0.0f ? 1.0f / std::sqrt(nl2) : 0.0f;
            nx *= inl, ny *= inl, nz *= inl;
            // eq. 3: the previous light sample -> blocker line against the receiver's previous
            // tangent plane, parametrized from the blocker: a light at infinity is put 1e4
            // scene extents away, where a float is off by 1e-3 extents, and a point computed
            // from there (light + t d) would be off by as much: pixels on screen.
            const float dx = bx - lx, dy = by - ly, dz = bz - lz;
            const float den = dx * nx + dy * ny + dz * nz;
            const float dl = std::sqrt(dx * dx + dy * dy + dz * dz);
            okf *= std::fabs(den) > 1e-8f * dl ? 1.0f : 0.0f;
            // s = t - 1 for the line's parameter t from the light (t > 0: the plane is past
            // the light).
            const float sb =
                okf > 0.0f ? ((px - bx) * nx + (py - by) * ny + (pz - bz) * nz) / den : 0.0f;
            okf *= sb > -1.0f ? 1.0f : 0.0f;
            const float vx = bx + sb * dx, vy = by + sb * dy, vz = bz + sb * dz;
            const float cx = a.pm[0] * vx + a.pm[4] * vy + a.pm[8] * vz + a.pm[12];
            const float cy = a.pm[1] * vx + a.pm[5] * vy + a.pm[9] * vz + a.pm[13];
            const float cw = a.pm[3] * vx + a.pm[7] * vy + a.pm[11] * vz + a.pm[15];
            okf *= cw > 0.0f ? 1.0f : 0.0f;
            const float iw = okf > 0.0f ? 1.0f / cw : 0.0f;
            const float rx = (cx * iw * 0.5f + 0.5f) * float(a.w);
            const float ry = (0.5f - cy * iw * 0.5f) * float(a.h);
            okf *= (rx > -1.0f ? 1.0f : 0.0f) * (rx < float(a.w) + 1.0f ? 1.0f : 0.0f) *
                   (ry > -1.0f ? 1.0f : 0.0f) * (ry < float(a.h) + 1.0f ? 1.0f : 0.0f);
            ok[i] = okf;
            vxs[i] = vx, vys[i] = vy, vzs[i] = vz, nxs[i] = nx, nys[i] = ny, nzs[i] = nz;
            rxs[i] = okf > 0.0f ? rx : 0.5f, rys[i] = okf > 0.0f ? ry : 0.5f;
            pxs[i] = px, pys[i] = py, pzs[i] = pz;
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float rx = rxs[i], ry = rys[i];
            const float px = pxs[i], py = pys[i], pz = pzs[i];
            const float nx = nxs[i], ny = nys[i], nz = nzs[i];
            const float vx = vxs[i], vy = vys[i], vz = vzs[i];
            float okf = ok[i];
            // eq. 4: how far the surface actually seen at x^V is off the receiver's plane:
            // theta - pi/2 = -asin(cos theta), asin by its Taylor series (the Gaussian is ~0
            // beyond |theta - pi/2| = 0.5, where the series is still within 1%).
            const int qx = std::min(std::max(int(rx), 0), a.w - 1);
            const int qy = std::min(std::max(int(ry), 0), a.h - 1);
            const int qi = qy * a.stride + kPad + qx;
            okf *= a.gid[qi] != -2 ? 1.0f : 0.0f;  // -2: no usable geometry there
            const float ex = a.gx[qi] - px, ey = a.gy[qi] - py, ez = a.gz[qi] - pz;
            const float el = std::sqrt(ex * ex + ey * ey + ez * ez);
            const float ux = px - a.cam[0], uy = py - a.cam[1], uz = pz - a.cam[2];
            const float dist = std::sqrt(ux * ux + uy * uy + uz * uz);
            const float c = std::min(
                std::max((ex * nx + ey * ny + ez * nz) / std::max(el, 1e-30f), -1.0f), 1.0f);
            const float sn = c * (1.0f + c * c * (1.0f / 6.0f + c * c * (3.0f / 40.0f)));
            const float gauss = ExpNeg16(sn * sn * a.inv2s2);  // within a few % of exp
            const float g = el > 1e-6f * dist ? gauss : 1.0f;
            const float tol = kShadowPlaneTol * dist + 1e-6f;
            const Foot4 fp = MakeFoot4(rx, ry, a.w, a.h, a.stride);
            const int id = a.id[x];
            const int mask4 =
                ShadowMask(a.gx, a.gy, a.gz, a.gid, fp, id, vx, vy, vz, nx, ny, nz, tol);
            const int bits = okf > 0.0f ? mask4 : 0;
            const bool has = bits != 0;
            const float av = 1.0f - g * (1.0f - a.alpha);
            ox[i] = has ? rx : kNaN, oy[i] = has ? ry : kNaN, om[i] = bits;
            oa[i] = has ? av : a.alpha;
            mk[i] = has ? 1.0f : 0.0f;
            sdx[i] = has ? rx - SplatBase(a.tx[x], x) : 0.0f;
            sdy[i] = has ? ry - SplatBase(a.ty[x], a.y) : 0.0f;
            sal[i] = has ? av : 0.0f;
        }
        for (int i = 0; i < n; ++i) a.om[x0 + i] = uint8_t(om[i]);
        StoreRow(ox, n, a.ox + x0, stream), StoreRow(oy, n, a.oy + x0, stream),
            StoreRow(oa, n, a.oa + x0, stream);
        CopyRow(mk, n, a.mask + x0), CopyRow(sdx, n, a.sdx + x0), CopyRow(sdy, n, a.sdy + x0);
        CopyRow(sal, n, a.sal + x0);
    }
}

struct SplatRowArgs {
    int w, h, stride, y;
    const float *cnt, *sdx, *sdy, *sal;  // box sums of the row
    const float* pp;
    const float* pn;
    const uint8_t* valid;
    const int32_t* id;
    const float *gx, *gy, *gz;
    const int32_t* gid;
    const float *tx, *ty;
    const uint8_t* tm;
    float cam[3];
    float *ox, *oy, *oa;
    uint8_t* om;
};

// Pixels without a shadow vector of their own: the mean vector of the in-shadow pixels around,
// or the traditional one far from shadows.
TEXCACHE_SCREEN_CLONES void SplatRow(const SplatRowArgs& args) {
    const SplatRowArgs a = args;
    const bool stream = StreamPlanes(a.w, a.h, 3);
    constexpr int kC = 256;
    alignas(64) float ox[kC], oy[kC], oa[kC];
    alignas(64) int om[kC];
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        {
            // Chunks where no pixel lacks its own vector near a shadow: only the traditional
            // vectors of pixels without one to copy.
            bool any = false;
            for (int i = 0; i < n && !any; ++i) any = a.om[x0 + i] == 0 && a.cnt[x0 + i] > 0.5f;
            if (!any) {
                for (int i = 0; i < n; ++i) {
                    const int x = x0 + i;
                    if (a.om[x] == 0) a.ox[x] = a.tx[x], a.oy[x] = a.ty[x], a.om[x] = a.tm[x];
                }
                continue;
            }
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const int own = a.om[x];
            const float cnt = a.cnt[x];
            const float ic = cnt > 0.5f ? 1.0f / cnt : 0.0f;
            const float px = a.pp[3 * x], py = a.pp[3 * x + 1], pz = a.pp[3 * x + 2];
            float nx = a.pn[3 * x], ny = a.pn[3 * x + 1], nz = a.pn[3 * x + 2];
            const float nl2 = nx * nx + ny * ny + nz * nz;
            const float okf = (a.valid[x] ? 1.0f : 0.0f) * Fin(px + py + pz) * Fin(nl2) *
                              (nl2 > 0.0f ? 1.0f : 0.0f);
            const float inl = okf > 0.0f ? 1.0f / std::sqrt(nl2) : 0.0f;
            nx *= inl, ny *= inl, nz *= inl;
            const float sx = SplatBase(a.tx[x], x) + a.sdx[x] * ic;
            const float sy = SplatBase(a.ty[x], a.y) + a.sdy[x] * ic;
            const float ux = px - a.cam[0], uy = py - a.cam[1], uz = pz - a.cam[2];
            const float tol = kShadowPlaneTol * std::sqrt(ux * ux + uy * uy + uz * uz) + 1e-6f;
            const Foot4 fp = MakeFoot4(sx, sy, a.w, a.h, a.stride);
            const int id = a.id[x];
            const int mask4 =
                ShadowMask(a.gx, a.gy, a.gz, a.gid, fp, id, px, py, pz, nx, ny, nz, tol);
            // Loads before the selects: a load only under a condition is control flow.
            const float tx = a.tx[x], ty = a.ty[x], sal = a.sal[x];
            const float cx = a.ox[x], cy = a.oy[x], ca = a.oa[x];
            const int tm = a.tm[x];
            const bool splat = own == 0 && cnt > 0.5f;
            const bool trad = own == 0 && !(cnt > 0.5f);
            ox[i] = splat ? (okf > 0.0f ? sx : kNaN) : trad ? tx : cx;
            oy[i] = splat ? (okf > 0.0f ? sy : kNaN) : trad ? ty : cy;
            oa[i] = splat ? sal * ic : ca;
            om[i] = splat ? (okf > 0.0f ? mask4 : 0) : trad ? tm : own;
        }
        for (int i = 0; i < n; ++i) a.om[x0 + i] = uint8_t(om[i]);
        StoreRow(ox, n, a.ox + x0, stream), StoreRow(oy, n, a.oy + x0, stream),
            StoreRow(oa, n, a.oa + x0, stream);
    }
}

}  // namespace

void ShadowMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                  const MotionField& trad, float alpha, float falloffSigma, int splatRadius,
                  MotionField* out, Plane* alphaV, Plane* scratch) {
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    // scratch[0..3]: splat inputs (in-shadow mask, mask * dx, mask * dy, mask * alpha^V), then
    // their box sums; scratch[4..7]: BoxSum's temporaries.
    ForRows(h, [&](int y) {
        ShadowRowArgs a;
        const size_t row = size_t(y) * size_t(w);
        a.w = w, a.h = h, a.stride = int(pg.depth.Stride()), a.y = y;
        a.pb = &f.prevBlocker[row].x, a.pl = &f.prevLightSample[row].x;
        a.pp = &f.PrevPositionPlane()[row].x, a.pn = &f.PrevNormalPlane()[row].x;
        a.valid = cur.valid.Row(y), a.id = cur.objectId.Row(y);
        a.gx = pg.px.Base(), a.gy = pg.py.Base(), a.gz = pg.pz.Base();
        a.gid = pg.objectId.Base();
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) a.pm[4 * c + r] = prev.camera.worldToClip[c][r];
        a.cam[0] = prev.camera.position.x, a.cam[1] = prev.camera.position.y;
        a.cam[2] = prev.camera.position.z;
        a.alpha = alpha, a.inv2s2 = 1.0f / (2.0f * falloffSigma * falloffSigma);
        a.tx = trad.x.Row(y), a.ty = trad.y.Row(y);
        a.ox = out->x.Row(y), a.oy = out->y.Row(y), a.om = out->taps.Row(y);
        a.oa = alphaV->Row(y);
        a.mask = scratch[0].Row(y), a.sdx = scratch[1].Row(y), a.sdy = scratch[2].Row(y);
        a.sal = scratch[3].Row(y);
        ShadowRow(a);
    });
    // Splat: pixels near in-shadow pixels take their mean vector (Sec. 4.1: "in-shadow pixels'
    // visibilities and their shadow motion vectors are propagated into the centre of each
    // filter"), so the lit side of a moving shadow edge follows the shadow too.
    const Plane* in[4] = {&scratch[0], &scratch[1], &scratch[2], &scratch[3]};
    Plane* sums[4] = {&scratch[0], &scratch[1], &scratch[2], &scratch[3]};
    Plane* tmp[4] = {&scratch[4], &scratch[5], &scratch[6], &scratch[7]};
    BoxSum(4, in, sums, tmp, splatRadius);
    ForRows(h, [&](int y) {
        SplatRowArgs a;
        const size_t row = size_t(y) * size_t(w);
        a.w = w, a.h = h, a.stride = int(pg.depth.Stride()), a.y = y;
        a.cnt = scratch[0].Row(y), a.sdx = scratch[1].Row(y), a.sdy = scratch[2].Row(y);
        a.sal = scratch[3].Row(y);
        a.pp = &f.PrevPositionPlane()[row].x, a.pn = &f.PrevNormalPlane()[row].x;
        a.valid = cur.valid.Row(y), a.id = cur.objectId.Row(y);
        a.gx = pg.px.Base(), a.gy = pg.py.Base(), a.gz = pg.pz.Base();
        a.gid = pg.objectId.Base();
        a.tx = trad.x.Row(y), a.ty = trad.y.Row(y), a.tm = trad.taps.Row(y);
        a.cam[0] = prev.camera.position.x, a.cam[1] = prev.camera.position.y;
        a.cam[2] = prev.camera.position.z;
        a.ox = out->x.Row(y), a.oy = out->y.Row(y), a.om = out->taps.Row(y);
        a.oa = alphaV->Row(y);
        SplatRow(a);
    });
}

namespace {

struct GlossyRowArgs {
    int w, h, stride, y;
    const float* phg;  // prevGlossyHit, xyz interleaved
    const float* hg;   // glossyHit
    const float* pp;   // prevPosition
    const float* pn;   // prevNormal
    const float* rough;
    const uint8_t* valid;
    const int32_t* id;
    const float *cx, *cy, *cz, *cnx, *cny, *cnz;  // this frame's guides (planes) of the row
    const int32_t* gid;                           // previous objectId, base
    const float *tx, *ty;                         // traditional vectors of the row
    const uint8_t* tm;
    float pm[16], cm[16];  // previous / current worldToClip, column-major
    float cam[3];
    float lobe, maxJitter;
    uint32_t seed;
    const float* gauss;
    float *ox, *oy;
    uint8_t* om;
};

TEXCACHE_SCREEN_CLONES void GlossyRow(const GlossyRowArgs& args) {
    const GlossyRowArgs a = args;
    const bool stream = StreamPlanes(a.w, a.h, 2);
    constexpr int kC = 256;
    // Two loops per chunk (eq. 5's vectors, then the lobe's jitter and the taps): one loop holds
    // more live values than there are vector registers, and its spills cost more than these
    // arrays' round trip through L1 (build/bin/screen_space_benchmark
    // --benchmark_filter=reliable, cpu_newMV_ms).
    alignas(64) float oks[kC], vxs[kC], vys[kC], vzs[kC], nxs[kC], nys[kC], nzs[kC], pxs[kC],
        pys[kC], pzs[kC], muxs[kC], muys[kC];
    alignas(64) float ox[kC], oy[kC];
    alignas(64) int om[kC];
    const float hw = 0.5f * float(a.w), hh = 0.5f * float(a.h);
    for (int x0 = 0; x0 < a.w; x0 += kC) {
        const int n = std::min(kC, a.w - x0);
        {
            // Chunks without a glossy hit keep the traditional vectors (a cheap scan first).
            bool any = false;
            for (int i = 0; i < n && !any; ++i) any = std::isfinite(a.phg[3 * (x0 + i)]);
            if (!any) {
                for (int i = 0; i < n; ++i) a.om[x0 + i] = a.tm[x0 + i];
                StoreRow(a.tx + x0, n, a.ox + x0, stream),
                    StoreRow(a.ty + x0, n, a.oy + x0, stream);
                continue;
            }
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float px = a.pp[3 * x], py = a.pp[3 * x + 1], pz = a.pp[3 * x + 2];
            float nx = a.pn[3 * x], ny = a.pn[3 * x + 1], nz = a.pn[3 * x + 2];
            const float gx = a.phg[3 * x], gy = a.phg[3 * x + 1], gz = a.phg[3 * x + 2];
            const float hx = a.hg[3 * x], hy = a.hg[3 * x + 1], hz = a.hg[3 * x + 2];
            const float nl2 = nx * nx + ny * ny + nz * nz;
            float okf = (a.valid[x] ? 1.0f : 0.0f) * Fin(px + py + pz) * Fin(nl2) *
                        (nl2 > 0.0f ? 1.0f : 0.0f) * Fin(gx + gy + gz) * Fin(hx + hy + hz);
            const float inl = okf > 0.0f ? 1.0f / std::sqrt(nl2) : 0.0f;
            nx *= inl, ny *= inl, nz *= inl;
            // eq. 5: the hit's mirror image in the reflector's previous plane, projected...
            const float dp = (gx - px) * nx + (gy - py) * ny + (gz - pz) * nz;
            const float vx = gx - 2.0f * dp * nx, vy = gy - 2.0f * dp * ny,
                        vz = gz - 2.0f * dp * nz;
            const float pcx = a.pm[0] * vx + a.pm[4] * vy + a.pm[8] * vz + a.pm[12];
            const float pcy = a.pm[1] * vx + a.pm[5] * vy + a.pm[9] * vz + a.pm[13];
            const float pcw = a.pm[3] * vx + a.pm[7] * vy + a.pm[11] * vz + a.pm[15];
            // ... and its motion applied to this pixel: mu_now from this frame's hit, plane and
            // camera (see GlossyMotion).
            const float cnx = a.cnx[x], cny = a.cny[x], cnz = a.cnz[x];
            const float dc = (hx - a.cx[x]) * cnx + (hy - a.cy[x]) * cny + (hz - a.cz[x]) * cnz;
            const float wx = hx - 2.0f * dc * cnx, wy = hy - 2.0f * dc * cny,
                        wz = hz - 2.0f * dc * cnz;
            const float ccx = a.cm[0] * wx + a.cm[4] * wy + a.cm[8] * wz + a.cm[12];
            const float ccy = a.cm[1] * wx + a.cm[5] * wy + a.cm[9] * wz + a.cm[13];
            const float ccw = a.cm[3] * wx + a.cm[7] * wy + a.cm[11] * wz + a.cm[15];
            okf *= (pcw > 0.0f ? 1.0f : 0.0f) * (ccw > 0.0f ? 1.0f : 0.0f);
            const float ipw = okf > 0.0f ? 1.0f / pcw : 0.0f, icw = okf > 0.0f ? 1.0f / ccw : 0.0f;
            const float mux = (pcx * ipw - ccx * icw) * hw + float(x) + 0.5f;
            const float muy = (ccy * icw - pcy * ipw) * hh + float(a.y) + 0.5f;
            oks[i] = okf, vxs[i] = vx, vys[i] = vy, vzs[i] = vz;
            nxs[i] = nx, nys[i] = ny, nzs[i] = nz, pxs[i] = px, pys[i] = py, pzs[i] = pz;
            muxs[i] = mux, muys[i] = muy;
        }
        for (int i = 0; i < n; ++i) {
            const int x = x0 + i;
            const float vx = vxs[i], vy = vys[i], vz = vzs[i];
            const float nx = nxs[i], ny = nys[i], nz = nzs[i];
            const float px = pxs[i], py = pys[i], pz = pzs[i];
            const float mux = muxs[i], muy = muys[i], okf = oks[i];
            // s^C: where the camera ray to the virtual image crosses the plane.
            const float ex = vx - a.cam[0], ey = vy - a.cam[1], ez = vz - a.cam[2];
            const float den = ex * nx + ey * ny + ez * nz;
            const float num = (px - a.cam[0]) * nx + (py - a.cam[1]) * ny + (pz - a.cam[2]) * nz;
            const float tt = std::fabs(den) > 1e-12f ? num / den : 1.0f;
            const float sx = a.cam[0] + tt * ex, sy = a.cam[1] + tt * ey, sz = a.cam[2] + tt * ez;
            // Sigma (see GlossyMotion): rho = |hv - sc| lobeScale alpha, axes J rho t1, J rho t2.
            const float r = a.rough[x];
            const float rr = Fin(r) * (r > 0.0f ? r : 0.0f);
            const float qx = vx - sx, qy = vy - sy, qz = vz - sz;
            const float rho = std::sqrt(qx * qx + qy * qy + qz * qz) * a.lobe * rr;
            const float sg = nz >= 0.0f ? 1.0f : -1.0f;
            const float ia = -1.0f / (sg + nz), bb = nx * ny * ia;
            const float t1x = (1.0f + sg * nx * nx * ia) * rho, t1y = sg * bb * rho,
                        t1z = -sg * nx * rho;
            const float t2x = bb * rho, t2y = (sg + ny * ny * ia) * rho, t2z = -ny * rho;
            const float scx = a.pm[0] * sx + a.pm[4] * sy + a.pm[8] * sz + a.pm[12];
            const float scy = a.pm[1] * sx + a.pm[5] * sy + a.pm[9] * sz + a.pm[13];
            const float scw = a.pm[3] * sx + a.pm[7] * sy + a.pm[11] * sz + a.pm[15];
            const float isw = scw > 0.0f ? 1.0f / scw : 0.0f;
            const float d1x = a.pm[0] * t1x + a.pm[4] * t1y + a.pm[8] * t1z;
            const float d1y = a.pm[1] * t1x + a.pm[5] * t1y + a.pm[9] * t1z;
            const float d1w = a.pm[3] * t1x + a.pm[7] * t1y + a.pm[11] * t1z;
            const float d2x = a.pm[0] * t2x + a.pm[4] * t2y + a.pm[8] * t2z;
            const float d2y = a.pm[1] * t2x + a.pm[5] * t2y + a.pm[9] * t2z;
            const float d2w = a.pm[3] * t2x + a.pm[7] * t2y + a.pm[11] * t2z;
            float e1x = hw * (d1x - scx * isw * d1w) * isw,
                  e1y = -hh * (d1y - scy * isw * d1w) * isw;
            float e2x = hw * (d2x - scx * isw * d2w) * isw,
                  e2y = -hh * (d2y - scy * isw * d2w) * isw;
            const float l1 = std::sqrt(e1x * e1x + e1y * e1y),
                        l2 = std::sqrt(e2x * e2x + e2y * e2y);
            const float k1 = l1 > a.maxJitter ? a.maxJitter / l1 : 1.0f;
            const float k2 = l2 > a.maxJitter ? a.maxJitter / l2 : 1.0f;
            e1x *= k1, e1y *= k1, e2x *= k2, e2y *= k2;
            uint32_t hs = uint32_t(x) * 0x9E3779B1u ^ uint32_t(a.y) * 0x85EBCA77u ^ a.seed;
            hs ^= hs >> 16, hs *= 0x7FEB352Du, hs ^= hs >> 15, hs *= 0x846CA68Bu, hs ^= hs >> 16;
            const int gi = int(hs & 4095u) * 2;
            const float g0 = a.gauss[gi], g1 = a.gauss[gi + 1];
            const float fin = Fin(e1x + e1y + e2x + e2y);
            const float rx = mux + fin * (g0 * e1x + g1 * e2x);
            const float ry = muy + fin * (g0 * e1y + g1 * e2y);
            // Usable taps: the same reflector.
            const Foot4 fp = MakeFoot4(rx, ry, a.w, a.h, a.stride);
            const int id = a.id[x];
            const auto top = LoadAdjacent(a.gid, fp.i00), bottom = LoadAdjacent(a.gid, fp.i01);
            const float m0 = fp.in00 * (top.l == id ? 1.0f : 0.0f);
            const float m1 = fp.in10 * (top.r == id ? 1.0f : 0.0f);
            const float m2 = fp.in01 * (bottom.l == id ? 1.0f : 0.0f);
            const float m3 = fp.in11 * (bottom.r == id ? 1.0f : 0.0f);
            // Loads before the selects: a load only under a condition is control flow.
            const float tx = a.tx[x], ty = a.ty[x];
            const int tm = a.tm[x];
            const bool ok = okf > 0.0f;
            ox[i] = ok ? rx : tx, oy[i] = ok ? ry : ty;
            om[i] = ok ? MaskBits(m0, m1, m2, m3) : tm;
        }
        for (int i = 0; i < n; ++i) a.om[x0 + i] = uint8_t(om[i]);
        StoreRow(ox, n, a.ox + x0, stream), StoreRow(oy, n, a.oy + x0, stream);
    }
}

}  // namespace

void GlossyMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                  const MotionField& trad, float lobeScale, float maxJitter, uint32_t frameSeed,
                  const float* gauss, MotionField* out) {
    // Default: the reflector's own motion (no glossy hit: environment, or not glossy).
    // eq. 5: the hit's mirror image in the reflector's previous plane, projected. Its motion
    // since the previous frame is applied to this pixel (x + mu_prev - mu_now, mu_now from this
    // frame's hit, plane and camera) rather than mu_prev taken as the position itself:
    // identical for a mirror, but for a sampled glossy direction the virtual image is not at x,
    // and the absolute position would reuse a pixel up to the lobe's footprint away even in a
    // static scene (a blur that never converges).
    // Sigma: the lobe, a Gaussian of angular std sigma_t = lobeScale * alpha around the mirror
    // direction, traced from the virtual image to the plane covers a disc of radius
    // rho = |hv - sc| sigma_t (isotropic on the plane, the 1/cos elongation along the incidence
    // plane ignored); its image under the projection's Jacobian J at s^C is the ellipse with axes
    // J rho t1, J rho t2 (t1, t2 any tangent basis: the covariance rho^2 J J^T does not depend on
    // it). Each axis is capped at maxJitter pixels: farther history is unlikely to be the same
    // reflection. The sample uses a per-pixel hash of (x, y, frame) into a table of normal
    // numbers.
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    ForRows(h, [&](int y) {
        GlossyRowArgs a;
        const size_t row = size_t(y) * size_t(w);
        a.w = w, a.h = h, a.stride = int(pg.depth.Stride()), a.y = y;
        a.phg = &f.PrevGlossyHitPlane()[row].x, a.hg = &f.glossyHit[row].x;
        a.pp = &f.PrevPositionPlane()[row].x, a.pn = &f.PrevNormalPlane()[row].x;
        a.rough = &f.roughness[row];
        a.valid = cur.valid.Row(y), a.id = cur.objectId.Row(y);
        a.cx = cur.px.Row(y), a.cy = cur.py.Row(y), a.cz = cur.pz.Row(y);
        a.cnx = cur.nx.Row(y), a.cny = cur.ny.Row(y), a.cnz = cur.nz.Row(y);
        a.gid = pg.objectId.Base();
        a.tx = trad.x.Row(y), a.ty = trad.y.Row(y), a.tm = trad.taps.Row(y);
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r)
                a.pm[4 * c + r] = prev.camera.worldToClip[c][r],
                             a.cm[4 * c + r] = f.camera.worldToClip[c][r];
        a.cam[0] = prev.camera.position.x, a.cam[1] = prev.camera.position.y;
        a.cam[2] = prev.camera.position.z;
        a.lobe = lobeScale, a.maxJitter = maxJitter, a.seed = frameSeed, a.gauss = gauss;
        a.ox = out->x.Row(y), a.oy = out->y.Row(y), a.om = out->taps.Row(y);
        GlossyRow(a);
    });
}

namespace {

// Least-squares affine motion of one object, previous -> current frame, from point pairs.
struct MotionFit {
    double n = 0.0;
    glm::dvec3 sp{0.0}, sc{0.0};
    glm::dmat3 spp{0.0}, scp{0.0};  // sum p p^T, sum c p^T (glm: [column][row])
    void Add(glm::dvec3 p, glm::dvec3 c) {
        n += 1.0, sp += p, sc += c;
        spp += glm::outerProduct(p, p);
        scp += glm::outerProduct(c, p);
    }
    void Merge(const MotionFit& o) { n += o.n, sp += o.sp, sc += o.sc, spp += o.spp, scp += o.scp; }
    // c ~ A p + t. Ridge-regularized towards A = I, so planar or tiny objects (rank-deficient
    // covariance) get the identity in the directions they do not constrain; a pure translation
    // gives A = I exactly.
    void Solve(glm::dmat3* a, glm::dvec3* t) const {
        const glm::dvec3 mp = sp / n, mc = sc / n;
        const glm::dmat3 cpp = spp / n - glm::outerProduct(mp, mp);
        const glm::dmat3 ccp = scp / n - glm::outerProduct(mc, mp);
        const double lambda = 1e-4 * (cpp[0][0] + cpp[1][1] + cpp[2][2]) / 3.0 + 1e-12;
        const glm::dmat3 reg(lambda);
        *a = (ccp + reg) * glm::inverse(cpp + reg);
        *t = mc - *a * mp;
    }
};

}  // namespace

void OcclusionMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                     const MotionField& trad, IntPlane* occluder, MotionField* out) {
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    // 1. Pixels the traditional vector fails for: which previous-frame object was at y.
    const bool stream = StreamPlanes(w, h, 2);
    tbb::combinable<std::vector<int>> idsTls;
    ForRows(h, [&](int y) {
        std::vector<int>& ids = idsTls.local();
        int32_t* oc = occluder->Row(y);
        const float* tx = trad.x.Row(y);
        const float* ty = trad.y.Row(y);
        const uint8_t* tm = trad.taps.Row(y);
        const uint8_t* ok = cur.valid.Row(y);
        StoreRow(tx, w, out->x.Row(y), stream), StoreRow(ty, w, out->y.Row(y), stream);
        std::copy_n(tm, w, out->taps.Row(y));
        std::fill_n(oc, w, -1);
        for (int x = 0; x < w; ++x) {
            if (tm[x] || !ok[x]) continue;
            const float sx = tx[x], sy = ty[x];
            if (!(sx >= 0.0f && sy >= 0.0f && sx < float(w) && sy < float(h))) continue;
            const int qx = int(sx), qy = int(sy);
            if (!pg.valid.At(qx, qy) || pg.objectId.At(qx, qy) < 0) continue;
            oc[x] = pg.objectId.At(qx, qy);
            if (ids.empty() || ids.back() != oc[x]) ids.push_back(oc[x]);
        }
    });
    std::vector<int> ids;
    idsTls.combine_each(
        [&](const std::vector<int>& v) { ids.insert(ids.end(), v.begin(), v.end()); });
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    if (ids.empty()) return;

    // 2. Their motion, fitted to the current frame's own pixels of those objects. Positions are
    // taken relative to the camera so the sums stay well conditioned far from the origin.
    // An affine motion is fixed by a handful of points, so the fit samples every kFitStep-th
    // pixel of every kFitStep-th row (an occluder often covers half the image, and the full sum
    // in double precision would be a fifth of the new motion vectors' time); objects that sampling
    // leaves with fewer than kMinFit points are summed again over all their pixels.
    constexpr int kFitStep = 4;
    constexpr double kMinFit = 64.0;
    const glm::dvec3 origin(f.camera.position);
    auto fitPass = [&](int step, const std::vector<char>& want) {
        tbb::combinable<std::vector<MotionFit>> fitTls(
            [&] { return std::vector<MotionFit>(ids.size()); });
        ForRows((h + step - 1) / step, [&](int ys) {
            const int y = ys * step;
            std::vector<MotionFit>& fits = fitTls.local();
            int lastId = -3, slot = -1;
            for (int x = 0; x < w; x += step) {
                if (!cur.valid.At(x, y)) continue;
                const int id = cur.objectId.At(x, y);
                if (id != lastId) {
                    lastId = id;
                    const auto it = std::lower_bound(ids.begin(), ids.end(), id);
                    slot = it != ids.end() && *it == id && want[size_t(it - ids.begin())]
                               ? int(it - ids.begin())
                               : -1;
                }
                if (slot < 0) continue;
                const size_t i = size_t(y) * size_t(w) + size_t(x);
                const glm::vec3 p = f.PrevPositionPlane()[i], c = f.position[i];
                if (!Finite(p) || !Finite(c)) continue;
                fits[size_t(slot)].Add(glm::dvec3(p) - origin, glm::dvec3(c) - origin);
            }
        });
        std::vector<MotionFit> fits(ids.size());
        fitTls.combine_each([&](const std::vector<MotionFit>& v) {
            for (size_t k = 0; k < v.size(); ++k) fits[k].Merge(v[k]);
        });
        return fits;
    };
    std::vector<char> few(ids.size(), 1);
    std::vector<MotionFit> fits = fitPass(kFitStep, few);
    bool anyFew = false;
    for (size_t k = 0; k < ids.size(); ++k) few[k] = fits[k].n < kMinFit, anyFew |= few[k] != 0;
    if (anyFew) {
        const std::vector<MotionFit> all = fitPass(1, few);
        for (size_t k = 0; k < ids.size(); ++k)
            if (few[k]) fits[k] = all[k];
    }
    std::vector<glm::mat3> lin(ids.size());
    std::vector<glm::vec3> trans(ids.size());
    std::vector<char> known(ids.size(), 0);
    for (size_t k = 0; k < ids.size(); ++k) {
        if (fits[k].n < 1.0) continue;  // not visible now: its motion is unknown
        glm::dmat3 a;
        glm::dvec3 t;
        fits[k].Solve(&a, &t);
        // back to world: c = A (p - o) + t + o
        lin[k] = glm::mat3(a);
        trans[k] = glm::vec3(t + origin - a * origin);
        known[k] = 1;
    }

    // 3. eq. 6: x^O = y + (x - z), z = the occluder's point at y moved to the current frame.
    ForRows(h, [&](int y) {
        const int32_t* oc = occluder->Row(y);
        for (int x = 0; x < w; ++x) {
            if (oc[x] < 0) continue;
            const size_t slot =
                size_t(std::lower_bound(ids.begin(), ids.end(), oc[x]) - ids.begin());
            if (!known[slot]) continue;
            const float sx = trad.x.At(x, y), sy = trad.y.At(x, y);
            const int qx = int(sx), qy = int(sy);
            const glm::vec3 moved = lin[slot] * PrevPos(pg, qx, qy) + trans[slot];
            glm::vec2 z;
            if (!f.camera.Project(moved, &z)) continue;
            const float ox = sx + (float(x) + 0.5f - z.x), oy = sy + (float(y) + 0.5f - z.y);
            Footprint fp;
            if (!MakeFootprint(ox, oy, w, h, &fp)) continue;
            const int id = cur.objectId.At(x, y);
            out->x.At(x, y) = ox, out->y.At(x, y) = oy;
            out->taps.At(x, y) =
                TapMask(fp, pg, [&](int tx, int ty) { return pg.objectId.At(tx, ty) == id; });
        }
    });
}

}  // namespace texcache::screen::internal
