// SPDX-License-Identifier: Apache-2.0
// The motion vectors of the screen-space stage (Zeng et al. 2021, eqs. 1, 3-6).
//
// Every pass is one sweep over the pixels on the TBB pool, reading the frame's AoS buffers once;
// pixels a kind does not apply to (lit pixels for shadows, non-glossy pixels, pixels whose
// traditional vector is fine for occlusion) cost a NaN test and a copy.
#include "filters/screen_space/motion_vectors.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

namespace texcache::screen::detail {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

inline bool Finite(glm::vec3 v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
inline glm::vec3 PrevPos(const Guides& g, int x, int y) {
    return glm::vec3(g.px.At(x, y), g.py.At(x, y), g.pz.At(x, y));
}
inline glm::vec3 PrevNrm(const Guides& g, int x, int y) {
    return glm::vec3(g.nx.At(x, y), g.ny.At(x, y), g.nz.At(x, y));
}

template <class Body>
void ForRows(int h, Body&& body) {
    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4), [&](const tbb::blocked_range<int>& r) {
        for (int y = r.begin(); y < r.end(); ++y) body(y);
    });
}

// Relative tolerance of the tangent-plane tests: distance to the plane < kPlaneTol * depth.
constexpr float kPlaneTol = 0.01f;
// Tolerance of the shadow test: a tap's surface may be this far off the receiver's plane.
constexpr float kShadowPlaneTol = 0.02f;
constexpr float kNormalCos = 0.9f;

}  // namespace

void TraditionalMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                       MotionField* out) {
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    ForRows(h, [&](int y) {
        float* ox = out->x.Row(y);
        float* oy = out->y.Row(y);
        uint8_t* om = out->taps.Row(y);
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            ox[x] = kNaN, oy[x] = kNaN, om[x] = 0;
            if (!cur.valid.At(x, y)) continue;
            const glm::vec3 pp = f.prevPosition[i];
            glm::vec3 pn = f.prevNormal[i];
            glm::vec2 r;
            if (!Finite(pp) || !Finite(pn) || !prev.camera.Project(pp, &r)) continue;
            const float nl = glm::length(pn);
            if (!(nl > 0.0f)) continue;
            pn /= nl;
            ox[x] = r.x, oy[x] = r.y;
            Footprint fp;
            if (!MakeFootprint(r.x, r.y, w, h, &fp)) continue;
            const int id = cur.objectId.At(x, y);
            const float tol = kPlaneTol * glm::length(pp - prev.camera.position) + 1e-6f;
            om[x] = TapMask(fp, pg, [&](int tx, int ty) {
                return pg.objectId.At(tx, ty) == id &&
                       std::abs(glm::dot(PrevPos(pg, tx, ty) - pp, pn)) < tol &&
                       glm::dot(PrevNrm(pg, tx, ty), pn) > kNormalCos;
            });
        }
    });
}

void ShadowMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                  const MotionField& trad, float alpha, float falloffSigma, int splatRadius,
                  MotionField* out, Plane* alphaV, Plane* scratch) {
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    const float inv2s2 = 1.0f / (2.0f * falloffSigma * falloffSigma);
    // scratch[0..3]: splat inputs (in-shadow mask, mask * dx, mask * dy, mask * alpha^V);
    // scratch[4..7]: their box sums.
    Plane& mask = scratch[0];
    Plane& sdx = scratch[1];
    Plane& sdy = scratch[2];
    Plane& sal = scratch[3];
    ForRows(h, [&](int y) {
        float* ox = out->x.Row(y);
        float* oy = out->y.Row(y);
        uint8_t* om = out->taps.Row(y);
        float* oa = alphaV->Row(y);
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            ox[x] = kNaN, oy[x] = kNaN, om[x] = 0, oa[x] = alpha;
            mask.At(x, y) = 0.0f, sdx.At(x, y) = 0.0f, sdy.At(x, y) = 0.0f, sal.At(x, y) = 0.0f;
            if (!cur.valid.At(x, y)) continue;
            const glm::vec3 pb = f.prevBlocker[i], pl = f.prevLightSample[i];
            if (!Finite(pb) || !Finite(pl)) continue;  // lit (or no shadow ray)
            const glm::vec3 pp = f.prevPosition[i];
            glm::vec3 pn = f.prevNormal[i];
            if (!Finite(pp) || !Finite(pn)) continue;
            const float nl = glm::length(pn);
            if (!(nl > 0.0f)) continue;
            pn /= nl;
            // eq. 3: the previous light sample -> blocker line against the receiver's previous
            // tangent plane.
            const glm::vec3 d = pb - pl;
            const float denom = glm::dot(d, pn);
            if (!(std::abs(denom) > 1e-8f * glm::length(d))) continue;
            const float t = glm::dot(pp - pl, pn) / denom;
            if (!(t > 0.0f)) continue;
            const glm::vec3 sv = pl + t * d;
            glm::vec2 r;
            if (!prev.camera.Project(sv, &r)) continue;
            Footprint fp;
            if (!MakeFootprint(r.x, r.y, w, h, &fp)) continue;
            // eq. 4: how far the surface actually seen at x^V is off the receiver's plane.
            const int qx = std::clamp(int(r.x), 0, w - 1), qy = std::clamp(int(r.y), 0, h - 1);
            if (!pg.valid.At(qx, qy)) continue;
            const glm::vec3 dir = PrevPos(pg, qx, qy) - pp;
            const float dl = glm::length(dir);
            const float dist = glm::length(pp - prev.camera.position);
            float g = 1.0f;
            if (dl > 1e-6f * dist) {
                const float s = std::asin(std::clamp(glm::dot(pn, dir) / dl, -1.0f, 1.0f));
                g = std::exp(-s * s * inv2s2);  // theta - pi/2 = -asin(cos theta)
            }
            const int id = cur.objectId.At(x, y);
            const float tol = kShadowPlaneTol * dist + 1e-6f;
            const uint8_t m = TapMask(fp, pg, [&](int tx, int ty) {
                return pg.objectId.At(tx, ty) == id ||
                       std::abs(glm::dot(PrevPos(pg, tx, ty) - sv, pn)) < tol;
            });
            if (!m) continue;
            const float av = 1.0f - g * (1.0f - alpha);
            ox[x] = r.x, oy[x] = r.y, om[x] = m, oa[x] = av;
            mask.At(x, y) = 1.0f;
            sdx.At(x, y) = r.x - (float(x) + 0.5f);
            sdy.At(x, y) = r.y - (float(y) + 0.5f);
            sal.At(x, y) = av;
        }
    });
    // Splat: pixels near in-shadow pixels take their mean vector (Sec. 4.1: "in-shadow pixels'
    // visibilities and their shadow motion vectors are propagated into the centre of each
    // filter"), so the lit side of a moving shadow edge follows the shadow too.
    // The sums overwrite the inputs (BoxSum's horizontal pass finishes before its vertical one).
    const Plane* in[4] = {&scratch[0], &scratch[1], &scratch[2], &scratch[3]};
    Plane* sums[4] = {&scratch[0], &scratch[1], &scratch[2], &scratch[3]};
    Plane* tmp[4] = {&scratch[4], &scratch[5], &scratch[6], &scratch[7]};
    BoxSum(4, in, sums, tmp, splatRadius);
    ForRows(h, [&](int y) {
        float* ox = out->x.Row(y);
        float* oy = out->y.Row(y);
        uint8_t* om = out->taps.Row(y);
        float* oa = alphaV->Row(y);
        for (int x = 0; x < w; ++x) {
            if (om[x] || !cur.valid.At(x, y)) continue;  // has its own shadow vector
            const float cnt = sums[0]->At(x, y);
            if (cnt < 0.5f) {  // far from shadows: the receiver's own motion
                ox[x] = trad.x.At(x, y), oy[x] = trad.y.At(x, y), om[x] = trad.taps.At(x, y);
                continue;
            }
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            const glm::vec3 pp = f.prevPosition[i];
            glm::vec3 pn = f.prevNormal[i];
            const float sx = float(x) + 0.5f + sums[1]->At(x, y) / cnt;
            const float sy = float(y) + 0.5f + sums[2]->At(x, y) / cnt;
            Footprint fp;
            if (!Finite(pp) || !Finite(pn) || !MakeFootprint(sx, sy, w, h, &fp)) continue;
            pn = glm::normalize(pn);
            const int id = cur.objectId.At(x, y);
            const float tol = kShadowPlaneTol * glm::length(pp - prev.camera.position) + 1e-6f;
            ox[x] = sx, oy[x] = sy, oa[x] = sums[3]->At(x, y) / cnt;
            om[x] = TapMask(fp, pg, [&](int tx, int ty) {
                return pg.objectId.At(tx, ty) == id ||
                       std::abs(glm::dot(PrevPos(pg, tx, ty) - pp, pn)) < tol;
            });
        }
    });
}

void GlossyMotion(const FrameBuffers& f, const Guides& cur, const PrevFrame& prev,
                  const MotionField& trad, float lobeScale, float maxJitter, uint32_t frameSeed,
                  const float* gauss, MotionField* out) {
    const int w = f.width, h = f.height;
    const Guides& pg = *prev.g;
    const glm::mat4& m = prev.camera.worldToClip;
    const float hw = 0.5f * float(w), hh = 0.5f * float(h);
    ForRows(h, [&](int y) {
        float* ox = out->x.Row(y);
        float* oy = out->y.Row(y);
        uint8_t* om = out->taps.Row(y);
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            // Default: the reflector's own motion (no glossy hit: environment, or not glossy).
            ox[x] = trad.x.At(x, y), oy[x] = trad.y.At(x, y), om[x] = trad.taps.At(x, y);
            if (!cur.valid.At(x, y)) continue;
            const glm::vec3 hg = f.prevGlossyHit[i];
            if (!Finite(hg)) continue;
            const glm::vec3 pp = f.prevPosition[i];
            glm::vec3 pn = f.prevNormal[i];
            if (!Finite(pp) || !Finite(pn)) continue;
            const float nl = glm::length(pn);
            if (!(nl > 0.0f)) continue;
            pn /= nl;
            // eq. 5: the hit's mirror image in the reflector's previous plane, projected. Its
            // motion since the previous frame is applied to this pixel (x + mu_prev - mu_now,
            // mu_now from this frame's hit, plane and camera) rather than mu_prev taken as the
            // position itself: identical for a mirror, but for a sampled glossy direction the
            // virtual image is not at x, and the absolute position would reuse a pixel up to the
            // lobe's footprint away even in a static scene (a blur that never converges).
            const glm::vec3 hv = hg - 2.0f * glm::dot(hg - pp, pn) * pn;
            glm::vec2 mu;
            if (!prev.camera.Project(hv, &mu)) continue;
            {
                const glm::vec3 hc = f.glossyHit[i];
                const glm::vec3 pc = f.position[i];
                const glm::vec3 nc(cur.nx.At(x, y), cur.ny.At(x, y), cur.nz.At(x, y));
                glm::vec2 muNow;
                if (!Finite(hc) ||
                    !f.camera.Project(hc - 2.0f * glm::dot(hc - pc, nc) * nc, &muNow))
                    continue;
                mu += glm::vec2(float(x) + 0.5f, float(y) + 0.5f) - muNow;
            }
            // s^C: where the camera ray to the virtual image crosses the plane.
            const glm::vec3 cam = prev.camera.position;
            const float den = glm::dot(hv - cam, pn);
            glm::vec3 sc = pp;
            if (std::abs(den) > 1e-12f) sc = cam + (glm::dot(pp - cam, pn) / den) * (hv - cam);
            // Sigma: the lobe, a Gaussian of angular std sigma_t = lobeScale * alpha around the
            // mirror direction, traced from the virtual image to the plane covers a disc of
            // radius rho = |hv - sc| sigma_t (isotropic on the plane, the 1/cos elongation along
            // the incidence plane ignored); its image under the projection's Jacobian J at s^C
            // is the ellipse with axes J rho t1, J rho t2 (t1, t2 any tangent basis: the
            // covariance rho^2 J J^T does not depend on it). Each axis is capped at maxJitter
            // pixels: farther history is unlikely to be the same reflection.
            const float rough = f.roughness.empty() ? 0.0f : f.roughness[i];
            const float rho =
                glm::length(hv - sc) * lobeScale * (std::isfinite(rough) ? rough : 0.0f);
            float sx = mu.x, sy = mu.y;
            if (rho > 0.0f) {
                glm::vec3 t1, t2;
                ConeFrame(pn, &t1, &t2);
                const glm::vec4 c = m * glm::vec4(sc, 1.0f);
                if (c.w > 0.0f) {
                    const float iw = 1.0f / c.w;
                    auto axis = [&](glm::vec3 t) {
                        const glm::vec4 d = m * glm::vec4(rho * t, 0.0f);
                        glm::vec2 e(hw * (d.x - c.x * iw * d.w) * iw,
                                    -hh * (d.y - c.y * iw * d.w) * iw);
                        const float l = glm::length(e);
                        return l > maxJitter ? e * (maxJitter / l) : e;
                    };
                    const glm::vec2 e1 = axis(t1), e2 = axis(t2);
                    uint32_t s = uint32_t(x) * 0x9E3779B1u ^ uint32_t(y) * 0x85EBCA77u ^ frameSeed;
                    s ^= s >> 16, s *= 0x7FEB352Du, s ^= s >> 15, s *= 0x846CA68Bu, s ^= s >> 16;
                    const float* g = gauss + 2 * (s & 4095u);
                    sx += g[0] * e1.x + g[1] * e2.x;
                    sy += g[0] * e1.y + g[1] * e2.y;
                }
            }
            Footprint fp;
            ox[x] = sx, oy[x] = sy, om[x] = 0;
            if (!MakeFootprint(sx, sy, w, h, &fp)) continue;
            const int id = cur.objectId.At(x, y);
            om[x] = TapMask(fp, pg, [&](int tx, int ty) { return pg.objectId.At(tx, ty) == id; });
        }
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
    tbb::combinable<std::vector<int>> idsTls;
    ForRows(h, [&](int y) {
        std::vector<int>& ids = idsTls.local();
        int32_t* oc = occluder->Row(y);
        for (int x = 0; x < w; ++x) {
            oc[x] = -1;
            out->x.At(x, y) = trad.x.At(x, y), out->y.At(x, y) = trad.y.At(x, y);
            out->taps.At(x, y) = trad.taps.At(x, y);
            if (trad.taps.At(x, y) || !cur.valid.At(x, y)) continue;
            const float sx = trad.x.At(x, y), sy = trad.y.At(x, y);
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
    const glm::dvec3 origin(f.camera.position);
    tbb::combinable<std::vector<MotionFit>> fitTls(
        [&] { return std::vector<MotionFit>(ids.size()); });
    ForRows(h, [&](int y) {
        std::vector<MotionFit>& fits = fitTls.local();
        int lastId = -3, slot = -1;
        for (int x = 0; x < w; ++x) {
            if (!cur.valid.At(x, y)) continue;
            const int id = cur.objectId.At(x, y);
            if (id != lastId) {
                lastId = id;
                const auto it = std::lower_bound(ids.begin(), ids.end(), id);
                slot = it != ids.end() && *it == id ? int(it - ids.begin()) : -1;
            }
            if (slot < 0) continue;
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            const glm::vec3 p = f.prevPosition[i], c = f.position[i];
            if (!Finite(p) || !Finite(c)) continue;
            fits[size_t(slot)].Add(glm::dvec3(p) - origin, glm::dvec3(c) - origin);
        }
    });
    std::vector<MotionFit> fits(ids.size());
    fitTls.combine_each([&](const std::vector<MotionFit>& v) {
        for (size_t k = 0; k < v.size(); ++k) fits[k].Merge(v[k]);
    });
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

}  // namespace texcache::screen::detail
