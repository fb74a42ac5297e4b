// SPDX-License-Identifier: Apache-2.0
#include "texcache/footprint.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <string>

#include "texcache/error.h"

namespace texcache {

MeshGrids::MeshGrids(const ControlCage& cage, float texelSize, uint32_t faceOffset)
    : MeshGrids(cage, texelSize, faceOffset, std::make_shared<const PtexTopology>(cage)) {}

MeshGrids::MeshGrids(const ControlCage& cage, float texelSize, uint32_t faceOffset,
                     std::shared_ptr<const PtexTopology> topology)
    : topo_(std::move(topology)), faceOffset_(faceOffset), id_([] {
          static std::atomic<uint64_t> next{1};
          return next.fetch_add(1, std::memory_order_relaxed);
      }()) {
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
// Sorting by key would do the same in O(n log n), a visible share of a 21x21 AO render (a
// profile of the 21x21 render of `texcache experiment filter-size --out DIR`).
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
// shading gradient is biased by the gradient times the taps' mean offset (on car AO it costs a
// 13x13 window most of its gain: docs/texture-space.md, "Visible footprints"). A point-symmetric
// set has its mean offset at the centre, so linear gradients average out as in the full window.
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

// ---- Footprint pads ---------------------------------------------------------------------------
//
// Why. A window that crosses a face edge can be gathered by walking from its centre, one Step
// per tap (a Ptex edge crossing at each face boundary), then testing tap by tap against the
// visible set (a hash each): on the car, whose small faces send most 21x21 windows across edges,
// that walk is a third of the filtered render (perf, 1 thread, 21x21 render of `texcache
// experiment filter-size`). But the texels a window reaches outside its face depend only on
// where they sit relative to that face, not on the centre: a pad, the ring of r texels around a
// (face, mip), walked once, serves every window of the face. A window then reads its taps from the
// pad row by row (and the in-face ones as the interior path does).
//
// Policy (GatherFootprint's, footprint.h). Pad position (x, y) outside the face is reached from
// the nearest face texel: along u first (a row walk from (clamp x, y) when y is inside), then v.
// When every texel the ring reaches lies on a grid of the face's size (and no edge on the way
// joins sides of different lengths) this is the texel the centre's own walk reaches (steps continue
// across an edge texel for texel; test PadsMatchTheWalkOnGridsOfOneSize). Where a neighbour's grid
// is coarser or finer, a walk from the centre would step in the neighbour's texels from wherever
// it crossed, so its taps would depend on the centre; the pad's do not: a window keeps its taps at
// their distance from the face along each axis. That makes every window of a face a read of one
// pad, and every 8x8 block of windows one tile (ShadingCache::FilterBlock). Walking those faces
// per window instead would keep the centre-dependent taps for an image difference too small to
// see (relMSE 4e-5 on the car's 21x21 AO), but would send most of its texel misses down the
// slower per-texel path, because FilterBlock cannot take their tiles.
//
// Duplicates (two pad positions on one texel: around extraordinary vertices, faces smaller
// than the window that the ring wraps around) are flagged when the
// pad is built; only a window holding a flagged tap pays for removing them (the closest walk
// wins, as in GatherFootprint).
//
// Memory and threading. Each thread keeps kPadSlots pads, direct-mapped by (grids, face, mip,
// radius), each at most kMaxPadTaps entries of 24 bytes (a grid of 2048 texels at r = 10; a pad
// of a 16x16 grid at r = 10 takes 25 KiB), allocated as pads are first built; a (face, mip)
// whose ring would be larger is walked per window. All of a thread's pads together hold at most
// kMaxHeldTaps entries (24 MiB): a build that would pass it frees every pad first. The cap per
// pad is that large so that the car's 512- and 1024-texel grids (its ground) get pads at
// r = 8..10: with a smaller cap their windows are walked, and their blocks filtered texel by
// texel, a large share of the 21x21 render's misses. Pads depend only on the (immutable)
// grids, tagged by MeshGrids::Id(), so they never go stale and need no locking; the visible set
// is tested per tap through the texel's stored Probe (marks may be added between passes).
namespace {

using PadTap = internal::PaddedTexel;
constexpr uint8_t kReached = internal::PaddedTexel::kReached,
                  kDuplicate = internal::PaddedTexel::kDuplicate;
constexpr int kPadSlots = 256;
constexpr size_t kMaxPadTaps = size_t(1) << 17;
constexpr size_t kMaxHeldTaps = size_t(1) << 20;  // 24 MiB of pads per thread

// The ring of r texels around (face, mip). Rows below the face (y = -r..-1) and above it
// (y = res..res+r-1) are stored whole, (res + 2r) wide; rows of the face keep their r texels on
// the left (x = -r..-1) and r on the right (x = res..).
struct Pad {
    uint64_t grids = 0;
    int face = -1, mip = -1, radius = -1, res = 0;
    std::vector<PadTap> taps;

    static size_t Size(int res, int r) { return size_t(4) * size_t(r) * size_t(res + r); }
    // Where pad position (x, y) is stored; the taps of a row follow while x stays on one side
    // of the face.
    size_t Index(int x, int y) const {
        const size_t w = size_t(res + 2 * radius), strip = size_t(radius) * w;
        if (y < 0) return size_t(y + radius) * w + size_t(x + radius);
        if (y >= res)
            return strip + size_t(2 * radius) * size_t(res) + size_t(y - res) * w +
                   size_t(x + radius);
        const size_t row = strip + size_t(2 * radius) * size_t(y);
        return x < 0 ? row + size_t(x + radius) : row + size_t(radius) + size_t(x - res);
    }
};

void SetPadTap(const MeshGrids& g, const Walker& w, PadTap* t) {
    const FootprintSample s = Emit(g, w, 0, 0);
    t->key = s.key.Pack();
    t->u = s.u, t->v = s.v;
    t->probe = VisibleTexels::Probe(s.key);
    t->bit = uint8_t(std::countr_zero(VisibleTexels::Bit(s.key)));
    t->flags = kReached;
}

// Flags the taps whose texel the pad holds more than once, or that are texels of the face
// itself (the ring wrapped around a small face): an open-addressing table of first indices.
void FlagDuplicates(Pad* p, uint64_t faceMip, uint64_t faceMipMask) {
    thread_local std::vector<uint32_t> first;
    size_t cap = 64;
    while (cap < 2 * p->taps.size()) cap <<= 1;
    first.assign(cap, ~0u);
    for (size_t i = 0; i < p->taps.size(); ++i) {
        PadTap& t = p->taps[i];
        if (!(t.flags & kReached)) continue;
        if ((t.key & faceMipMask) == faceMip) t.flags |= kDuplicate;
        for (size_t slot = size_t((t.key * 0x9E3779B97F4A7C15ull) >> 40) & (cap - 1);;
             slot = (slot + 1) & (cap - 1)) {
            if (first[slot] == ~0u) {
                first[slot] = uint32_t(i);
                break;
            }
            PadTap& o = p->taps[first[slot]];
            if (o.key != t.key) continue;
            o.flags |= kDuplicate;
            t.flags |= kDuplicate;
            break;
        }
    }
}

void BuildPad(const MeshGrids& g, uint64_t id, int face, int mip, int radius, Pad* p) {
    const int res = g.Res(face, mip), r = radius;
    p->grids = id, p->face = face, p->mip = mip, p->radius = r, p->res = res;
    p->taps.assign(Pad::Size(res, r), PadTap{0, 0.0f, 0.0f, 0, 0, 0});
    auto texel = [&](int x, int y) {
        return Walker{face, mip, res, float(x) + 0.5f, float(y) + 0.5f, {{1, 0}, {0, 1}}};
    };
    // Left and right of every face row, then the rows below and above (u first, then v).
    for (int y = 0; y < res; ++y)
        for (int sign : {-1, 1}) {
            Walker w = texel(sign < 0 ? 0 : res - 1, y);
            for (int k = 1; k <= r && Step(g, mip, &w, 0, sign); ++k)
                SetPadTap(g, w, &p->taps[p->Index(sign < 0 ? -k : res - 1 + k, y)]);
        }
    for (int x = -r; x < res + r; ++x)
        for (int sign : {-1, 1}) {
            const int xc = std::clamp(x, 0, res - 1), yc = sign < 0 ? 0 : res - 1;
            Walker w = texel(xc, yc);
            bool reached = true;
            for (int k = 0; k < std::abs(x - xc) && reached; ++k)
                reached = Step(g, mip, &w, 0, x < xc ? -1 : 1);
            for (int k = 1; reached && k <= r && Step(g, mip, &w, 1, sign); ++k)
                SetPadTap(g, w, &p->taps[p->Index(x, sign < 0 ? -k : res - 1 + k)]);
        }
    constexpr uint64_t kFaceMipShift = 2 * TexelKey::kCoordBits;
    const TexelKey own{g.FaceOffset() + uint32_t(face), uint8_t(mip), 0, 0};
    FlagDuplicates(p, own.Pack(), ~uint64_t(0) << kFaceMipShift);
}

// The thread's pad for (face, mip, radius), built on first use; null when the ring would exceed
// kMaxPadTaps (the caller walks instead).
const Pad* PadOf(const MeshGrids& g, int face, int mip, int radius) {
    if (Pad::Size(g.Res(face, mip), radius) > kMaxPadTaps) return nullptr;
    thread_local std::vector<Pad> pads(kPadSlots);
    thread_local size_t heldTaps = 0;  // the capacity of all of this thread's pads
    uint64_t h = (g.Id() * 0x9E3779B97F4A7C15ull) ^
                 (uint64_t(face) << 12 | uint64_t(mip) << 6 | uint64_t(radius));
    h *= 0xBF58476D1CE4E5B9ull;
    Pad& p = pads[size_t(h >> 56) & (kPadSlots - 1)];
    if (p.grids != g.Id() || p.face != face || p.mip != mip || p.radius != radius) {
        const size_t need = Pad::Size(g.Res(face, mip), radius);
        heldTaps -= p.taps.capacity();
        if (heldTaps + std::max(need, p.taps.capacity()) > kMaxHeldTaps) {
            // Over the thread's budget: give every pad's memory back (they are rebuilt on use).
            for (Pad& q : pads) q = Pad{};
            heldTaps = 0;
        }
        BuildPad(g, g.Id(), face, mip, radius, &p);
        heldTaps += p.taps.capacity();
    }
    return &p;
}

// A window's taps as bits: row j (dy = j - r) holds bit p for dx = p - r, in `words` 64-bit
// words per row. Deciding which taps a window keeps on bits (visible, not a duplicate, mirror
// kept) and writing only the kept ones costs a few operations per tap: writing every visible
// tap and then compacting it (KeepSymmetric) would be most of GatherFootprint's time.
struct WindowBits {
    std::vector<uint64_t> bits;
    int words = 1;

    void Reset(int side) {
        words = (side + 63) / 64;
        bits.assign(size_t(side) * size_t(words), 0);
    }
    uint64_t* Row(int j) { return &bits[size_t(j) * size_t(words)]; }
    void Set(int j, int p) { Row(j)[p >> 6] |= uint64_t(1) << (p & 63); }
    void Unset(int j, int p) { Row(j)[p >> 6] &= ~(uint64_t(1) << (p & 63)); }
    bool Test(int j, int p) const {
        return (bits[size_t(j) * size_t(words) + size_t(p >> 6)] >> (p & 63)) & 1;
    }
    // ORs the bits of m (at most 8, all within the row) in at position p >= 0.
    void SetByte(int j, int p, uint32_t m) {
        uint64_t* row = Row(j);
        row[p >> 6] |= uint64_t(m) << (p & 63);
        // The next word only when bits spill into it (it exists then; past the last word not).
        if ((p & 63) > 56 && (uint64_t(m) >> (64 - (p & 63))) != 0)
            row[(p >> 6) + 1] |= uint64_t(m) >> (64 - (p & 63));
    }
    // Calls f(j, p) for every set bit, row by row.
    template <typename F>
    void ForEach(int side, F&& f) const {
        for (int j = 0; j < side; ++j)
            for (int w = 0; w < words; ++w)
                for (uint64_t m = bits[size_t(j) * size_t(words) + size_t(w)]; m; m &= m - 1)
                    f(j, w * 64 + std::countr_zero(m));
    }
};

// Set bits of a byte (the baseline ISA has no popcnt instruction).
constexpr auto kBitCount = [] {
    std::array<uint8_t, 256> n{};
    for (int i = 1; i < 256; ++i) n[size_t(i)] = uint8_t(n[size_t(i / 2)] + (i & 1));
    return n;
}();

using internal::DuplicateTap;

// The per-centre walk: for windows whose face has no pad (too large), and tests (`pads` false).
// Unseen taps are dropped as they are reached (a texel is seen or not whichever walk reaches it,
// so this commutes with removing duplicates).
int WalkFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int radius,
                  std::vector<FootprintSample>* out, const VisibleTexels* visible) {
    const int res = g.Res(face, mip);
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
    return unseen;
}

}  // namespace

const internal::PaddedTexel* internal::PaddedRun(const MeshGrids& g, int face, int mip, int radius,
                                                 int x, int y) {
    const Pad* p = PadOf(g, face, mip, radius);
    return p ? &p->taps[p->Index(x, y)] : nullptr;
}

int GatherFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int radius,
                    std::vector<FootprintSample>* out, const VisibleTexels* visible,
                    bool symmetric) {
    return internal::GatherFootprint(g, face, mip, iu, iv, radius, out, visible, symmetric,
                                     /*pads=*/true);
}

int internal::GatherFootprint(const MeshGrids& g, int face, int mip, int iu, int iv, int radius,
                              std::vector<FootprintSample>* out, const VisibleTexels* visible,
                              bool symmetric, bool pads) {
    out->clear();
    mip = g.ClampMip(face, mip);
    const int res = g.Res(face, mip);
    iu = std::clamp(iu, 0, res - 1);
    iv = std::clamp(iv, 0, res - 1);
    const uint32_t gface = g.FaceOffset() + uint32_t(face);
    const int side = 2 * radius + 1;
    const float inv = 1.0f / float(res);  // exact: res is a power of two
    int unseen = 0;
    const bool inside =
        iu - radius >= 0 && iu + radius < res && iv - radius >= 0 && iv + radius < res;
    if (inside && !visible) {
        // Every tap of a window inside the face: written directly, in place (the paper's
        // footprint; writing bits first would cost it a noticeable share of the render, the
        // "all" curve of `texcache experiment filter-size`).
        out->resize(size_t(side) * size_t(side));
        FootprintSample* o = out->data();
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
    const Pad* pad = inside || !pads ? nullptr : PadOf(g, face, mip, radius);
    if (inside || pad) {
        thread_local WindowBits taps, kept;
        thread_local std::vector<DuplicateTap> duplicates;
        taps.Reset(side);
        duplicates.clear();
        const int x0 = iu - radius, x1 = iu + radius;
        // Which taps are reached and seen: the face's part of a row from the visible set's
        // blocks, the rest from the pad.
        for (int j = 0; j < side; ++j) {
            const int y = iv - radius + j;
            auto padRun = [&](int xa, int xb) {
                const PadTap* t = &pad->taps[pad->Index(xa, y)];
                for (int x = xa; x <= xb; ++x, ++t) {
                    if (!(t->flags & kReached)) continue;
                    if (visible && !visible->ContainsAt(t->probe, uint64_t(1) << t->bit)) {
                        ++unseen;
                        continue;
                    }
                    taps.Set(j, x - x0);
                    if (t->flags & kDuplicate)
                        duplicates.push_back({t->key, int16_t(x - iu), int16_t(y - iv)});
                }
            };
            if (y < 0 || y >= res) {
                padRun(x0, x1);
                continue;
            }
            if (x0 < 0) padRun(x0, -1);
            const int a = std::max(x0, 0), b = std::min(x1, res - 1);
            if (visible) {
                TexelKey k{gface, uint8_t(mip), 0, uint16_t(y)};
                int seen = 0;
                for (int blk = a >> 3; blk <= b >> 3; ++blk) {
                    k.iu = uint16_t(blk << 3);
                    uint32_t m = uint32_t(visible->BlockBits(k) >> ((y & 7) * 8)) & 0xFFu;
                    const int lo = std::max(a - (blk << 3), 0), hi = std::min(b - (blk << 3), 7);
                    m &= (0xFFu << lo) & (0xFFu >> (7 - hi));
                    if (y == iv && blk == iu >> 3) m |= 1u << (iu & 7);  // the centre, always
                    seen += kBitCount[m];
                    // The block may start left of the window (its bits there are clear).
                    const int p = (blk << 3) - x0;
                    taps.SetByte(j, std::max(p, 0), p < 0 ? m >> -p : m);
                }
                unseen += b - a + 1 - seen;
            } else {
                for (int x = a; x <= b; ++x) taps.Set(j, x - x0);
            }
            if (x1 >= res) padRun(res, x1);
        }
        if (!duplicates.empty()) {
            // A pad texel of this face has its twin inside the face (the ring wrapped around).
            for (size_t i = 0, n = duplicates.size(); i < n; ++i) {
                const TexelKey t = TexelKey::Unpack(duplicates[i].key);
                const int dx = int(t.iu) - iu, dy = int(t.iv) - iv;
                if (t.face == gface && t.mip == mip && std::abs(dx) <= radius &&
                    std::abs(dy) <= radius && taps.Test(dy + radius, dx + radius))
                    duplicates.push_back({duplicates[i].key, int16_t(dx), int16_t(dy)});
            }
            internal::ForEachLosingDuplicate(
                &duplicates, [&](int dx, int dy) { taps.Unset(dy + radius, dx + radius); });
        }
        const WindowBits* keep = &taps;
        if (visible && symmetric) {
            // Kept when the mirrored offset is kept too (see KeepSymmetric).
            kept.Reset(side);
            int dropped = 0;
            taps.ForEach(side, [&](int j, int p) {
                const bool mirrored = taps.Test(side - 1 - j, side - 1 - p);
                kept.Row(j)[p >> 6] |= uint64_t(mirrored) << (p & 63);
                dropped += !mirrored;
            });
            unseen += dropped;
            keep = &kept;
        }
        out->resize(size_t(side) * size_t(side));
        FootprintSample* o = out->data();
        keep->ForEach(side, [&](int j, int p) {
            const int x = x0 + p, y = iv - radius + j;
            if (x >= 0 && x < res && y >= 0 && y < res) {
                o->key = {gface, uint8_t(mip), uint16_t(x), uint16_t(y)};
                o->u = (float(x) + 0.5f) * inv;
                o->v = (float(y) + 0.5f) * inv;
            } else {
                const PadTap& t = pad->taps[pad->Index(x, y)];
                o->key = TexelKey::Unpack(t.key);
                o->u = t.u, o->v = t.v;
            }
            o->dx = int16_t(p - radius), o->dy = int16_t(j - radius);
            ++o;
        });
        out->resize(size_t(o - out->data()));
        return visible ? unseen : 0;
    }
    unseen = WalkFootprint(g, face, mip, iu, iv, radius, out, visible);
    return visible ? unseen + (symmetric ? KeepSymmetric(out, radius) : 0) : 0;
}

}  // namespace texcache
