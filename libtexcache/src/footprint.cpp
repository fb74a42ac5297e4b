// SPDX-License-Identifier: Apache-2.0
#include "texcache/footprint.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>

#include "texcache/error.h"

namespace texcache {

MeshGrids::MeshGrids(const ControlCage& cage, float texelSize, uint32_t faceOffset)
    : MeshGrids(cage, texelSize, faceOffset, std::make_shared<const PtexTopology>(cage)) {}

MeshGrids::MeshGrids(const ControlCage& cage, float texelSize, uint32_t faceOffset,
                     std::shared_ptr<const PtexTopology> topology)
    : topo_(std::move(topology)), faceOffset_(faceOffset) {
    if (!topo_ || topo_->NumCoarseFaces() != cage.numFaces())
        throw InputError(cage.sourcePath, "the shared Ptex topology is not this cage's");
    if (!(texelSize > 0.0f) || !std::isfinite(texelSize))
        throw InputError(cage.sourcePath, "texel size must be a positive number");
    if (uint64_t(faceOffset) + uint64_t(topo_->NumPtexFaces()) > TexelKey::kMaxFaces)
        throw InputError(cage.sourcePath,
                         std::to_string(uint64_t(faceOffset) + topo_->NumPtexFaces()) +
                             " Ptex faces exceed the cache key's range of " +
                             std::to_string(TexelKey::kMaxFaces));
    log2Res_ = ComputeFaceResolutions(cage, *topo_, texelSize, TexelKey::kCoordBits - 1);
}

namespace {

// Tangent (counter-clockwise) and inward normal of each Ptex edge in (u,v).
constexpr int kTangent[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
constexpr int kInward[4][2] = {{0, 1}, {-1, 0}, {0, -1}, {1, 0}};

// A walker: a face, a position in its texel units at the footprint's mip, and the footprint's
// u and v axes expressed in this face's frame (axis-aligned unit vectors).
struct Walker {
    int face, mip, res;
    float x, y;
    int axis[2][2];  // axis[0] = footprint u direction, axis[1] = footprint v direction
};

// Moves one texel along footprint axis `a`; false when a boundary ends the walk.
bool Step(const MeshGrids& g, int footprintMip, Walker* w, int a, int sign) {
    const int dx = sign * w->axis[a][0], dy = sign * w->axis[a][1];
    w->x += float(dx);
    w->y += float(dy);
    if (w->x >= 0.0f && w->x < float(w->res) && w->y >= 0.0f && w->y < float(w->res)) return true;
    // Which edge we left through (only one coordinate moved).
    const int edge = dx > 0 ? 1 : dx < 0 ? 3 : dy > 0 ? 2 : 0;
    float along, inward;
    UvToEdge(edge, w->x / float(w->res), w->y / float(w->res), &along, &inward);
    int nbFace, nbEdge;
    float u, v, scale;
    if (!g.Topology().Cross(w->face, edge, along, -inward, &nbFace, &u, &v, &nbEdge, &scale))
        return false;
    float nbAlong, nbInward;
    UvToEdge(nbEdge, u, v, &nbAlong, &nbInward);
    const int mip = g.ClampMip(nbFace, footprintMip);
    const int res = g.Res(nbFace, mip);
    // Land in the centre of the neighbour's first texel row along the shared edge.
    EdgeToUv(nbEdge, nbAlong, 0.5f / float(res), &u, &v);
    // Turn the frame: D = a T_k + b N_k in ours is -a T_k' - b N_k' in the neighbour's.
    for (auto& ax : w->axis) {
        const int ta = ax[0] * kTangent[edge][0] + ax[1] * kTangent[edge][1];
        const int nb = ax[0] * kInward[edge][0] + ax[1] * kInward[edge][1];
        ax[0] = -ta * kTangent[nbEdge][0] - nb * kInward[nbEdge][0];
        ax[1] = -ta * kTangent[nbEdge][1] - nb * kInward[nbEdge][1];
    }
    w->face = nbFace;
    w->mip = mip;
    w->res = res;
    w->x = u * float(res);
    w->y = v * float(res);
    return true;
}

FootprintSample Emit(const MeshGrids& g, const Walker& w, int dx, int dy) {
    const int iu = std::clamp(int(w.x), 0, w.res - 1), iv = std::clamp(int(w.y), 0, w.res - 1);
    FootprintSample s;
    s.key.face = g.FaceOffset() + uint32_t(w.face);
    s.key.mip = uint8_t(w.mip);
    s.key.iu = uint16_t(iu);
    s.key.iv = uint16_t(iv);
    s.dx = int16_t(dx);
    s.dy = int16_t(dy);
    s.u = TexelCenter(iu, w.res);
    s.v = TexelCenter(iv, w.res);
    return s;
}

// Which of two walks reaching the same texel to keep: the smallest |dx| + |dy|, then the
// smallest dx, then dy (a total order: the result does not depend on the walk order).
bool Closer(const FootprintSample& a, const FootprintSample& b) {
    const int da = std::abs(a.dx) + std::abs(a.dy), db = std::abs(b.dx) + std::abs(b.dy);
    if (da != db) return da < db;
    return a.dx != b.dx ? a.dx < b.dx : a.dy < b.dy;
}

// Drops all but the closest walk to each texel, in O(n) with a small open-addressing table of
// sample indices (thread-local; emptied by bumping a generation stamp rather than clearing).
// Sorting by key did the same in O(n log n) and was 9% of a 21x21 AO render (a profile of the
// 21x21 render of `texcache experiment filter-size --out DIR`; figure from 7aea17b).
void RemoveDuplicateTexels(std::vector<FootprintSample>* out) {
    const size_t n = out->size();
    thread_local std::vector<uint32_t> index, stamp;
    thread_local std::vector<char> keep;
    thread_local uint32_t generation = 0;
    size_t cap = 64;
    while (cap < 2 * n) cap <<= 1;
    if (index.size() < cap) {
        index.assign(cap, 0);
        stamp.assign(cap, 0);
        generation = 0;
    }
    if (++generation == 0) {  // wrapped: stale stamps could match again
        std::fill(stamp.begin(), stamp.end(), 0u);
        generation = 1;
    }
    const size_t mask = index.size() - 1;
    keep.assign(n, 1);
    bool duplicates = false;
    for (size_t i = 0; i < n; ++i) {
        const FootprintSample& s = (*out)[i];
        uint64_t h = s.key.Pack() * 0x9E3779B97F4A7C15ull;
        size_t slot = size_t(h >> 40) & mask;
        for (;; slot = (slot + 1) & mask) {
            if (stamp[slot] != generation) {
                stamp[slot] = generation;
                index[slot] = uint32_t(i);
                break;
            }
            const uint32_t j = index[slot];
            if (!((*out)[j].key == s.key)) continue;
            duplicates = true;
            if (Closer(s, (*out)[j])) {
                keep[j] = 0;
                index[slot] = uint32_t(i);
            } else {
                keep[i] = 0;
            }
            break;
        }
    }
    if (!duplicates) return;
    size_t w = 0;
    for (size_t i = 0; i < n; ++i)
        if (keep[i]) (*out)[w++] = (*out)[i];
    out->resize(w);
}

// Keeps the taps whose mirror offset (-dx, -dy) is also in the footprint; returns how many it
// dropped. Why: the taps a camera sees are one-sided where a surface disappears behind another
// (the ground under a car body) or where eq. 1 switches mip level, and a one-sided average of a
// shading gradient is biased by the gradient times the taps' mean offset (car AO, 13x13:
// relMSE 0.024 one-sided against 0.014 for the full window; `texcache experiment filter-size
// --out DIR`, the one-sided figure from f721c1e, before this function). A point-symmetric set
// has its mean offset at the centre, so linear gradients average out as in the full window.
int KeepSymmetric(std::vector<FootprintSample>* out, int radius) {
    const int side = 2 * radius + 1;
    thread_local std::vector<uint8_t> present;
    present.assign(size_t(side) * size_t(side), 0);
    auto at = [&](int dx, int dy) -> uint8_t& {
        return present[size_t(dy + radius) * size_t(side) + size_t(dx + radius)];
    };
    for (const FootprintSample& t : *out) at(t.dx, t.dy) = 1;
    // Copied always, kept by advancing (which taps have a mirror follows no learnable pattern).
    size_t kept = 0;
    FootprintSample* o = out->data();
    for (size_t i = 0, n = out->size(); i < n; ++i) {
        const FootprintSample t = o[i];
        o[kept] = t;
        kept += at(-t.dx, -t.dy);
    }
    const int dropped = int(out->size() - kept);
    out->resize(kept);
    return dropped;
}

}  // namespace

int GatherFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int radius,
                    std::vector<FootprintSample>* out, const VisibleTexels* visible,
                    bool symmetric) {
    out->clear();
    mip = g.ClampMip(face, mip);
    const int res = g.Res(face, mip);
    iu = std::clamp(iu, 0, res - 1);
    iv = std::clamp(iv, 0, res - 1);
    const uint32_t gface = g.FaceOffset() + uint32_t(face);
    if (iu - radius >= 0 && iu + radius < res && iv - radius >= 0 && iv + radius < res) {
        // Fast path: the window lies inside the face (written in place: this runs once per
        // texel miss for up to 21x21 taps).
        const int side = 2 * radius + 1;
        out->resize(size_t(side) * size_t(side));
        FootprintSample* o = out->data();
        const float inv = 1.0f / float(res);  // exact: res is a power of two
        if (!visible) {
            for (int dy = -radius; dy <= radius; ++dy) {
                const float v = (float(iv + dy) + 0.5f) * inv;
                for (int dx = -radius; dx <= radius; ++dx, ++o) {
                    o->key = {gface, uint8_t(mip), uint16_t(iu + dx), uint16_t(iv + dy)};
                    o->dx = int16_t(dx), o->dy = int16_t(dy);
                    o->u = (float(iu + dx) + 0.5f) * inv;
                    o->v = v;
                }
            }
            return 0;
        }
        // Visible taps only: per row, the marks of each 8x8 block it crosses, then one tap per
        // set bit (the work follows the visible taps, with no unpredictable branch per tap).
        const int x0 = iu - radius, x1 = iu + radius;
        for (int dy = -radius; dy <= radius; ++dy) {
            const int y = iv + dy;
            const float v = (float(y) + 0.5f) * inv;
            TexelKey k{gface, uint8_t(mip), 0, uint16_t(y)};
            for (int b = x0 >> 3; b <= x1 >> 3; ++b) {
                k.iu = uint16_t(b << 3);
                uint32_t m = uint32_t(visible->BlockBits(k) >> ((y & 7) * 8)) & 0xFFu;
                const int lo = std::max(x0 - (b << 3), 0), hi = std::min(x1 - (b << 3), 7);
                m &= (0xFFu << lo) & (0xFFu >> (7 - hi));
                if (dy == 0 && b == iu >> 3) m |= 1u << (iu & 7);  // the centre, always
                for (; m; m &= m - 1) {
                    const int x = (b << 3) + std::countr_zero(m);
                    o->key = {gface, uint8_t(mip), uint16_t(x), uint16_t(y)};
                    o->dx = int16_t(x - iu), o->dy = int16_t(dy);
                    o->u = (float(x) + 0.5f) * inv;
                    o->v = v;
                    ++o;
                }
            }
        }
        out->resize(size_t(o - out->data()));
        return side * side - int(out->size()) + (symmetric ? KeepSymmetric(out, radius) : 0);
    }
    // Walk: u first (a row of walkers, one per dx), then v from each of them. Unseen taps are
    // dropped as they are reached (a texel is seen or not whichever walk reaches it, so this
    // commutes with removing duplicates).
    const Walker centre{face, mip, res, float(iu) + 0.5f, float(iv) + 0.5f, {{1, 0}, {0, 1}}};
    int unseen = 0;
    for (int sign : {-1, 1}) {
        Walker row = centre;
        for (int dx = (sign < 0 ? 0 : 1); dx <= radius; ++dx) {
            if (dx > 0 && !Step(g, mip, &row, 0, sign)) break;
            for (int vs : {-1, 1}) {
                Walker col = row;
                for (int dy = (vs < 0 ? 0 : 1); dy <= radius; ++dy) {
                    if (dy > 0 && !Step(g, mip, &col, 1, vs)) break;
                    const FootprintSample t = Emit(g, col, sign * dx, vs * dy);
                    if (visible && (dx | dy) != 0 && !visible->Contains(t.key)) {
                        ++unseen;
                        continue;
                    }
                    out->push_back(t);
                }
            }
        }
    }
    // Around extraordinary vertices two walks can end in the same texel: keep the one with the
    // smallest offset.
    RemoveDuplicateTexels(out);
    return visible ? unseen + (symmetric ? KeepSymmetric(out, radius) : 0) : 0;
}

}  // namespace texcache
