// SPDX-License-Identifier: Apache-2.0
// Shading at the camera's hits, phase 2 of a pass: each camera sample's value read back from the
// bins phase 1 (hit_binning.cpp) filled, by a bilinear reconstruction over the 2x2 bins around
// its hit, across face edges through the Ptex adjacency, blended towards the level above by the
// two levels' difference and the finer one's noise (the note at the top of texture_space.h).
// Neighbouring samples read mostly the same bins: each thread keeps the cells it read last; a
// material filter's values at bin centres are the store's texel level, shared by the threads.
#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <vector>

#include "renderer/render_internal.h"

namespace texcache::internal {

namespace {

/// The bilinear reconstruction of hit-binned shading at a camera sample: the 2x2 bins around its
/// (u,v) at one of its bin levels, across face edges through the Ptex adjacency, each weighted
/// by its bilinear weight and its count.
///
/// Neighbouring samples mostly read the same 2x2 bins, so a sample whose cell is one its level
/// kept (CellSet) reuses its values (BinCell); other cells' bins are found through a small memo
/// of the thread's (BinMemo, kept from tile to tile: ThreadCells), keyed by the bin's
/// coordinates before any edge crossing: a hit there saves the crossing and the probe of the
/// shared table.
template <typename Bin>
struct BinMemo {
    static constexpr int kLog2 = 8;
    struct Entry {  // the value is uninitialised until the key is set (see HitBins::Batch)
        Entry() {}
        uint64_t key = TexelKey::kEmpty;
        union {
            typename Bin::Value n;
        };
    } at[1 << kLog2];
};
template <typename Bin>
struct BinCell {
    int32_t mesh = -1, face = -1, level = -1, i0 = 0, j0 = 0;
    typename Bin::Value n[4];  ///< bins (i0, j0), (i0 + 1, j0), (i0, j0 + 1), (i0 + 1, j0 + 1)
    float w[4];                ///< the current sample's bilinear weights
};
/// Memo keys shift bin coordinates by this much: a filtered reconstruction's window reaches up to
/// kPad - 2 bins beyond the 2x2 cell around a sample, itself up to a bin beyond a face's edge.
constexpr int kPad = 8;
/// The value of bin (i, j) of `face` at `level` (res a side), in the face's grid extended across
/// its edges: a bin beyond an edge is the neighbour's bin at that point (through the Ptex
/// adjacency); none at a boundary, diagonally across a vertex, or, for a window's bin more than
/// one bin out, past the neighbour face. Through the thread's `memo`.
template <typename Bin>
typename Bin::Value FindBin(const MeshGrids& g, const BinTable<Bin>& bins, int face, int level,
                            int res, int i, int j, BinMemo<Bin>& memo) {
    const bool outU = i < 0 || i >= res, outV = j < 0 || j >= res;
    if (outU && outV) return {};  // a corner bin: diagonal across a vertex
    const uint64_t local = TexelKey{g.FaceOffset() + uint32_t(face), uint8_t(level),
                                    uint16_t(i + kPad), uint16_t(j + kPad)}
                               .Pack();
    auto& m = memo.at[(local * 0x9E3779B97F4A7C15ull) >> (64 - BinMemo<Bin>::kLog2)];
    if (m.key == local) return m.n;
    TexelKey key;
    if (!outU && !outV) {
        key = {g.FaceOffset() + uint32_t(face), uint8_t(level), uint16_t(i), uint16_t(j)};
    } else {
        const int edge = j < 0 ? 0 : i >= res ? 1 : j >= res ? 2 : 3;
        float along, inward;
        UvToEdge(edge, (float(i) + 0.5f) / float(res), (float(j) + 0.5f) / float(res), &along,
                 &inward);
        int nf, ne;
        float nu, nv, scale;
        const bool far = i < -1 || i > res || j < -1 || j > res;
        if (!g.Topology().Cross(face, edge, along, -inward, &nf, &nu, &nv, &ne, &scale) ||
            (far && !(nu >= 0.0f && nu <= 1.0f && nv >= 0.0f && nv <= 1.0f))) {
            m.key = local, m.n = {};  // no bin
            return {};
        }
        const int nl = g.ClampMip(nf, level);
        const int nres = g.Res(nf, nl);
        key = {g.FaceOffset() + uint32_t(nf), uint8_t(nl), uint16_t(QuantizeCoord(nu, nres)),
               uint16_t(QuantizeCoord(nv, nres))};
    }
    m.key = local, m.n = bins.Find(key);
    return m.n;
}
/// The values of the 2x2 bins from (i0, j0) of a face at `level` (res a side) into `cell`.
template <typename Bin>
void FetchCell(const MeshGrids& g, const BinTable<Bin>& bins, int face, int level, int res, int i0,
               int j0, BinMemo<Bin>& memo, BinCell<Bin>* cell) {
    for (int k = 0; k < 4; ++k)
        cell->n[k] = FindBin(g, bins, face, level, res, i0 + (k & 1), j0 + (k >> 1), memo);
}
/// The cells a level keeps between samples, one per parity of the cell's corner (i0, j0): the
/// four cells around a bin centre. A pixel's jittered samples straddle cell edges when bins are
/// a few pixels wide: with one cell kept, a large share of the reads would fetch it again.
template <typename Bin>
using CellSet = std::array<BinCell<Bin>, 4>;
/// The 2x2 bins around point (u,v) of `face` at `level` of mesh `mesh` (grids `g`) in the cell of
/// `cells` for their corner's parity (fetched unless they are that cell's already), and the
/// point's bilinear weights in its w.
template <typename Bin>
const BinCell<Bin>& CellAt(const MeshGrids& g, const BinTable<Bin>& bins, int mesh, int face,
                           int level, float u, float v, BinMemo<Bin>& memo, CellSet<Bin>& cells) {
    const int res = g.Res(face, level);
    const float x = u * float(res) - 0.5f, y = v * float(res) - 0.5f;
    // floor() by hand: std::floor is a libm call on baseline x86-64 (no SSE4.1 roundss), a
    // visible share of this function's time; x and y lie in [-0.5, res).
    int i0 = int(x), j0 = int(y);
    i0 -= float(i0) > x ? 1 : 0, j0 -= float(j0) > y ? 1 : 0;
    const float fx = x - float(i0), fy = y - float(j0);
    BinCell<Bin>& cell = cells[size_t((i0 & 1) | ((j0 & 1) << 1))];
    if (cell.mesh != mesh || cell.face != face || cell.level != level || cell.i0 != i0 ||
        cell.j0 != j0) {
        FetchCell(g, bins, face, level, res, i0, j0, memo, &cell);
        cell.mesh = mesh, cell.face = face, cell.level = level, cell.i0 = i0, cell.j0 = j0;
    }
    cell.w[0] = (1.0f - fx) * (1.0f - fy), cell.w[1] = fx * (1.0f - fy);
    cell.w[2] = (1.0f - fx) * fy, cell.w[3] = fx * fy;
    return cell;
}
/// What a thread's reconstructions keep between samples: the cells of a record's level and of the
/// one above it, each level with its own memo (in a shared one, the two levels' bins would evict
/// each other).
/// The filtered values at the 2x2 bin centres around a sample (FilteredReconstruct), kept for
/// the next sample as CellSet keeps bins: a pixel's samples mostly read the same four, and the
/// store's texel level costs a shared cache line per centre.
struct FilteredCell {
    int32_t mesh = -1, face = -1, level = -1, i0 = 0, j0 = 0;
    FilteredValue f[4];
};
template <typename Bin>
struct LevelCells {
    BinMemo<Bin> fineMemo, coarseMemo;
    CellSet<Bin> fine, coarse;
    std::array<FilteredCell, 4> filtered;  ///< objects whose material sets a filter
};
/// The calling thread's LevelCells for reading `bins`: kept from tile to tile while the table
/// holds the same bins (its Generation), so that a tile finds the bins its neighbours, read
/// before on this thread, fetched already; emptied when the table changed.
template <typename Bin>
LevelCells<Bin>& ThreadCells(const BinTable<Bin>& bins) {
    thread_local uint64_t generation = 0;
    thread_local std::unique_ptr<LevelCells<Bin>> cells;
    if (!cells || generation != bins.Generation()) {
        if (cells)
            *cells = LevelCells<Bin>();
        else
            cells = std::make_unique<LevelCells<Bin>>();
        generation = bins.Generation();
    }
    return *cells;
}
/// A cell's bilinear estimate: the weighted mean of its bins, the weighted count (sum w n) and
/// the squared-weight count (sum w^2 n): its variance is a sample's variance x count2 / count^2.
struct CellEstimate {
    glm::vec3 mean{0.0f};
    float count = 0.0f, count2 = 0.0f;
};
CellEstimate EstimateOf(const BinCell<CountBin>& c) {
    CellEstimate e;
    float num = 0.0f;
    for (int k = 0; k < 4; ++k) {
        const float w = c.w[k], n = float(c.n[k].trials);
        num += w * float(c.n[k].successes), e.count += w * n, e.count2 += w * w * n;
    }
    e.mean = glm::vec3(e.count > 0.0f ? num / e.count : 0.0f);
    return e;
}
CellEstimate EstimateOf(const BinCell<RadianceBin>& c) {
    CellEstimate e;
    glm::dvec3 num(0.0);  // fixed-point sums: up to 2^64, beyond a float's precision
    for (int k = 0; k < 4; ++k) {
        const RadianceBin::Value& n = c.n[k];
        const double w = double(c.w[k]);
        num += w * glm::dvec3(double(n.sum[0]), double(n.sum[1]), double(n.sum[2]));
        e.count += c.w[k] * float(n.count), e.count2 += c.w[k] * c.w[k] * float(n.count);
    }
    if (e.count > 0.0f) e.mean = glm::vec3(num / (double(e.count) * RadianceBin::kScale));
    return e;
}
/// A bin's sum and count in common units: AO's escaped rays out of the rays traced, the light's
/// fixed-point sums in radiance.
double BinCount(const CountBin::Value& n) {
    return double(n.trials);
}
glm::dvec3 BinSum(const CountBin::Value& n) {
    return glm::dvec3(double(n.successes));
}
double BinCount(const RadianceBin::Value& n) {
    return double(n.count);
}
glm::dvec3 BinSum(const RadianceBin::Value& n) {
    return glm::dvec3(double(n.sum[0]), double(n.sum[1]), double(n.sum[2])) *
           (1.0 / RadianceBin::kScale);
}
/// A material filter over the bins of one level (the note at the top of texture_space.h): its
/// kind, its window's radius in bins, and the Gaussian's 1 / (2 sigma^2) in bins^-2.
struct BinWindow {
    TextureFilterKind kind;
    int radius;
    float inv2Sigma2;
};
/// The window of an object whose material sets `kind` with pass radius `r` texels, its bins
/// HitFilterLevels(kind, r) levels above its texels: the footprint of radius r in bins (the
/// Gaussian's sigma is r / 2 texels).
BinWindow WindowOf(TextureFilterKind kind, int r) {
    const float side = float(1 << std::max(HitFilterLevels(kind, r), 0));
    const float sigma = 0.5f * float(r) / side;
    return {kind, std::min(int(std::ceil(float(r) / side)), kPad - 2),
            sigma > 0.0f ? 0.5f / (sigma * sigma) : 0.0f};
}
/// The filtered value at the centre of bin (i, j) of `face` at `level` (res a side, the face's
/// grid extended across its edges as FindBin does). Gaussian: the mean of the window's bins
/// weighted by count x exp(-d^2 / (2 sigma^2)). Regression: the value at the centre of a plane
/// fitted to the bins' means, count-weighted, in bin coordinates; a direction the window barely
/// spans (an edge's bins on a boundary, a row of bins on a thin face) is dropped from the fit
/// by the same relative bound as the grid's regression filter's truncated SVD (singular values
/// below 1e-2 of the largest), so a rank-deficient window falls back to a line or the mean; the
/// result is held to the range of the bins' means and is the mean where not finite.
template <typename Bin>
FilteredValue FilterAt(const MeshGrids& g, const BinTable<Bin>& bins, int face, int level, int res,
                       int i, int j, const BinWindow& w, BinMemo<Bin>& memo) {
    const int R = w.radius;
    double total = 0.0;
    glm::dvec3 sum(0.0);
    if (w.kind == TextureFilterKind::Gaussian) {
        double wsum = 0.0;
        for (int dj = -R; dj <= R; ++dj)
            for (int di = -R; di <= R; ++di) {
                const typename Bin::Value n =
                    FindBin(g, bins, face, level, res, i + di, j + dj, memo);
                const double count = BinCount(n);
                if (!(count > 0.0)) continue;
                const double k = std::exp(-double(di * di + dj * dj) * double(w.inv2Sigma2));
                sum += k * BinSum(n), wsum += k * count, total += count;
            }
        if (!(wsum > 0.0)) return {};
        return {glm::vec3(sum / wsum), float(total)};
    }
    // Regression: moments of the bins' positions p and means y, weighted by count.
    double sp[2] = {0.0, 0.0}, spp[3] = {0.0, 0.0, 0.0};
    glm::dvec3 spy[2] = {glm::dvec3(0.0), glm::dvec3(0.0)};
    glm::dvec3 lo(INFINITY), hi(-INFINITY);
    for (int dj = -R; dj <= R; ++dj)
        for (int di = -R; di <= R; ++di) {
            const typename Bin::Value n = FindBin(g, bins, face, level, res, i + di, j + dj, memo);
            const double count = BinCount(n);
            if (!(count > 0.0)) continue;
            const glm::dvec3 s = BinSum(n), y = s / count;
            const double x = di, z = dj;
            total += count, sum += s;
            sp[0] += count * x, sp[1] += count * z;
            spp[0] += count * x * x, spp[1] += count * x * z, spp[2] += count * z * z;
            spy[0] += x * s, spy[1] += z * s;
            lo = glm::min(lo, y), hi = glm::max(hi, y);
        }
    if (!(total > 0.0)) return {};
    const glm::dvec3 mean = sum / total;
    const double mx = sp[0] / total, mz = sp[1] / total;
    // Covariance of the positions and their covariance with the values.
    const double cxx = spp[0] / total - mx * mx, cxz = spp[1] / total - mx * mz,
                 czz = spp[2] / total - mz * mz;
    const glm::dvec3 bx = spy[0] / total - mx * mean, bz = spy[1] / total - mz * mean;
    // Eigen-decomposition of the 2x2 covariance; the gradient is its truncated pseudo-inverse
    // applied to (bx, bz).
    const double tr = cxx + czz, det = cxx * czz - cxz * cxz;
    const double disc = std::sqrt(std::max(0.25 * tr * tr - det, 0.0));
    const double l1 = 0.5 * tr + disc, l2 = 0.5 * tr - disc;
    glm::dvec3 value = mean;
    if (l1 > 1e-8) {
        // Unit eigenvectors: e1 for l1, e2 orthogonal to it.
        double ex = cxz, ez = l1 - cxx;
        if (std::abs(ex) + std::abs(ez) < 1e-12) ex = cxx >= czz ? 1.0 : 0.0, ez = 1.0 - ex;
        const double len = std::sqrt(ex * ex + ez * ez);
        ex /= len, ez /= len;
        // The bounds on singular values (square roots of eigenvalues): 1e-2 of the largest,
        // and 1e-4.
        const bool both = l2 > 1e-4 * l1 && l2 > 1e-8;
        const glm::dvec3 along1 = (ex * bx + ez * bz) / l1;
        const glm::dvec3 along2 = both ? (-ez * bx + ex * bz) / l2 : glm::dvec3(0.0);
        // The plane at the centre (0, 0): mean + gradient . (0 - mean position).
        const double p1 = -(ex * mx + ez * mz), p2 = -(-ez * mx + ex * mz);
        value = glm::clamp(mean + along1 * p1 + along2 * p2, lo, hi);
        if (!std::isfinite(value.x + value.y + value.z)) value = mean;
    }
    return {glm::vec3(value), float(total)};
}
/// The reconstruction at record `h` of an object whose material sets filter `kind` (pass radius
/// `r`), from its bins at its record's level: none reads the hit's own bin; gaussian and
/// regression read the filtered values at the 2x2 bin centres around it (FilterAt), bilinearly,
/// skipping centres whose window holds no bin. The filtered values are the store's texel level:
/// computed once, by whichever thread needs one first, for every thread.
template <typename Bin>
glm::vec3 FilteredReconstruct(const TextureSpaceCache& tsc,
                              const TextureStore<Bin, FilteredValue>& store, const HitRecord& h,
                              LevelCells<Bin>& cells, TextureFilterKind kind, int r) {
    const BinTable<Bin>& bins = store.Samples();
    const MeshGrids& g = tsc.Grids(h.mesh);
    const int face = h.Face(), level = h.Level();
    const int res = g.Res(face, level);
    const float u = h.U(), v = h.V();
    if (kind == TextureFilterKind::None) {
        const typename Bin::Value n = FindBin(g, bins, face, level, res, QuantizeCoord(u, res),
                                              QuantizeCoord(v, res), cells.fineMemo);
        const double count = BinCount(n);
        return count > 0.0 ? glm::vec3(BinSum(n) / count) : glm::vec3(0.0f);
    }
    const float x = u * float(res) - 0.5f, y = v * float(res) - 0.5f;
    const int i0 = int(std::floor(x)), j0 = int(std::floor(y));
    const float fx = x - float(i0), fy = y - float(j0);
    FilteredCell& cell = cells.filtered[size_t((i0 & 1) | ((j0 & 1) << 1))];
    if (cell.mesh != h.mesh || cell.face != face || cell.level != level || cell.i0 != i0 ||
        cell.j0 != j0) {
        const BinWindow window = WindowOf(kind, r);
        // Centres lie in [-1, res] (a sample's cell reaches half a bin past the face's edge):
        // keys shifted by one, on a grid of res + 2 a side, which a face at the finest
        // resolution would overflow (its centres are filtered uncached).
        const int side = res + 2;
        for (int k = 0; k < 4; ++k) {
            const int i = i0 + (k & 1), j = j0 + (k >> 1);
            auto filter = [&] {
                return FilterAt(g, bins, face, level, res, i, j, window, cells.fineMemo);
            };
            cell.f[k] =
                side <= TexelKey::kMaxResolution
                    ? store.Filtered(TexelKey{g.FaceOffset() + uint32_t(face), uint8_t(level),
                                              uint16_t(i + 1), uint16_t(j + 1)},
                                     side, filter)
                    : filter();
        }
        cell.mesh = h.mesh, cell.face = face, cell.level = level, cell.i0 = i0, cell.j0 = j0;
    }
    glm::vec3 sum(0.0f);
    float wsum = 0.0f;
    for (int k = 0; k < 4; ++k) {
        const float w = ((k & 1) ? fx : 1.0f - fx) * ((k >> 1) ? fy : 1.0f - fy);
        if (cell.f[k].weight > 0.0f) sum += w * cell.f[k].value, wsum += w;
    }
    return wsum > 0.0f ? sum / wsum : glm::vec3(0.0f);
}
/// The reconstruction at record `h` from its level's bins and the level above (the note at the
/// top of texture_space.h): fine + alpha (coarse - fine), alpha = CoarseWeight of their
/// luminance difference and of the fine estimate's variance, `variance(fine, coarse)`. With
/// k = 0, h's level alone (its record then names the level of a stochastic blend); the same
/// where h's level is its face's coarsest (both levels' bins were clamped to it).
template <typename Bin, typename Variance>
glm::vec3 Reconstruct(const TextureSpaceCache& tsc, const TextureStore<Bin, FilteredValue>& store,
                      const HitRecord& h, LevelCells<Bin>& cells, double k, Variance&& variance,
                      bool frameStore = false) {
    // An object whose material sets a filter the bins serve reads them through it.
    const int object = tsc.ObjectOfMesh(h.mesh);
    const TextureFilterKind kind = tsc.FilterOf(object);
    if ((frameStore ? StoreFilterLevels(kind, 0) : HitFilterLevels(kind, 0)) >= 0)
        return FilteredReconstruct(tsc, store, h, cells, kind, tsc.PassRadiusOf(object));
    const BinTable<Bin>& bins = store.Samples();
    const MeshGrids& g = tsc.Grids(h.mesh);
    const int face = h.Face(), level = h.Level();
    const float u = h.U(), v = h.V();
    const CellEstimate fine =
        EstimateOf(CellAt(g, bins, h.mesh, face, level, u, v, cells.fineMemo, cells.fine));
    const int up = g.ClampMip(face, level + 1);
    if (!(k > 0.0) || up == level) return fine.mean;
    const CellEstimate coarse =
        EstimateOf(CellAt(g, bins, h.mesh, face, up, u, v, cells.coarseMemo, cells.coarse));
    if (!(coarse.count > 0.0f)) return fine.mean;
    if (!(fine.count > 0.0f)) return coarse.mean;
    const glm::vec3 d = coarse.mean - fine.mean;
    return fine.mean + float(CoarseWeight(Luminance(d), variance(fine, coarse), k)) * d;
}
float ReconstructAo(const TextureSpaceCache& tsc, const AoHitStore& store, const HitRecord& h,
                    LevelCells<CountBin>& cells) {
    return Reconstruct(tsc, store, h, cells, kAoCoarseWeightK,
                       [unit = double(tsc.HitUnit())](const CellEstimate& fine,
                                                      const CellEstimate& coarse) {
                           // Binomial, with the coarse level's steadier mean (kept off 0 and 1,
                           // where one bin's count would claim no noise at all).
                           // Counts in HitUnit() units: the variance of a count's worth.
                           const double p = std::clamp(double(coarse.mean.x), 0.02, 0.98);
                           return p * (1.0 - p) * double(fine.count2) * unit /
                                  (double(fine.count) * double(fine.count));
                       })
        .x;
}
/// `relativeVariance`: one binned sample's variance over its mean squared, measured over the
/// pass (PathHitsTrace); 0 when not measured.
glm::vec3 ReconstructRadiance(const TextureSpaceCache& tsc, const LightHitStore& store,
                              const HitRecord& h, LevelCells<RadianceBin>& cells,
                              double relativeVariance, bool frameStore = false) {
    return Reconstruct(
        tsc, store, h, cells, relativeVariance > 0.0 ? kLightCoarseWeightK : 0.0,
        [&](const CellEstimate& fine, const CellEstimate& coarse) {
            const double y = Luminance(coarse.mean);
            return relativeVariance * y * y * double(fine.count2) * double(tsc.HitUnit()) /
                   (double(fine.count) * double(fine.count));
        },
        frameStore);
}

/// A camera sample's reconstruction and its own per-hit estimate.
struct ResolvedSample {
    glm::dvec3 recon, own;
};
/// Phase 2 of hit binning for one tile: each pixel's sum, from `start(pixel)` on, of
/// `shade(i).recon` for the records i of its spp camera samples of the pass, in sample order,
/// added to the frame's sums `sum` once; and of `shade(i).own` with the squared luminance of own
/// minus recon added to `own` (FrameSums::own).
template <typename Start, typename Shade>
void ResolveTile(const Context& c, const tbb::blocked_range2d<int>& r, int spp, double* sum,
                 double* own, Start&& start, Shade&& shade) {
    for (int y = r.rows().begin(); y < r.rows().end(); ++y)
        for (int x = r.cols().begin(); x < r.cols().end(); ++x) {
            const size_t pixel = size_t(y) * size_t(c.opt.width) + size_t(x);
            glm::dvec3 acc = start(pixel), accOwn = acc;
            double diff2 = 0.0;
            for (int s = 0; s < spp; ++s) {
                const ResolvedSample v = shade(pixel * size_t(spp) + size_t(s));
                const double d = Luminance(v.own - v.recon);
                acc += v.recon, accOwn += v.own, diff2 += d * d;
            }
            double* px = &sum[3 * pixel];
            px[0] += acc.x, px[1] += acc.y, px[2] += acc.z;
            double* o = &own[4 * pixel];
            o[0] += accOwn.x, o[1] += accOwn.y, o[2] += accOwn.z, o[3] += diff2;
        }
}

}  // namespace

/// Hit-binned AO, phase 2 of a pass, for one tile: each camera sample's reconstruction, added to
/// its pixel in sample order.
void AoHitsResolve(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                   const HitRecord* records, const float* ownAo, const AoHitStore& store,
                   double* sum, double* own) {
    LevelCells<CountBin>& cells = ThreadCells(store.Samples());
    ResolveTile(
        c, r, s1 - s0, sum, own, [](size_t) { return glm::dvec3(0.0); },
        [&](size_t i) {
            const HitRecord& h = records[i];
            if (h.mesh < 0) {
                const glm::dvec3 v(h.mesh == PassTexels::kMiss ? 0.0 : 1.0);
                return ResolvedSample{v, v};
            }
            return ResolvedSample{glm::dvec3(double(ReconstructAo(*c.tsc, store, h, cells))),
                                  glm::dvec3(double(ownAo[i]))};
        });
}

/// Hit-binned diffuse light, phase 2 of a pass, for one tile: each pixel's per-hit part, then
/// albedo x the reconstruction of each binned camera sample, in sample order
/// (`relativeVariance`: see ReconstructRadiance).
void PathHitsResolve(const Context& c, const tbb::blocked_range2d<int>& r, int s0, int s1,
                     const HitRecord* records, const BinnedHit* binnedHits,
                     const glm::dvec3* perHit, const LightHitStore& store, double relativeVariance,
                     double* sum, double* own) {
    LevelCells<RadianceBin>& cells = ThreadCells(store.Samples());
    ResolveTile(
        c, r, s1 - s0, sum, own, [&](size_t pixel) { return perHit[pixel]; },
        [&](size_t i) {
            if (records[i].mesh < 0) return ResolvedSample{glm::dvec3(0.0), glm::dvec3(0.0)};
            const BinnedHit& b = binnedHits[i];
            return ResolvedSample{
                glm::dvec3(b.albedo *
                           ReconstructRadiance(*c.tsc, store, records[i], cells, relativeVariance)),
                glm::dvec3(b.albedo * b.light)};
        });
}

glm::vec3 StoreLightAt(const TextureSpaceCache& tsc, const LightHitStore& store,
                       const HitRecord& h) {
    return ReconstructRadiance(tsc, store, h, ThreadCells(store.Samples()), 0.0, true);
}

double StoreCountAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h) {
    LevelCells<RadianceBin>& cells = ThreadCells(store.Samples());
    return double(EstimateOf(CellAt(tsc.Grids(h.mesh), store.Samples(), h.mesh, h.Face(), h.Level(),
                                    h.U(), h.V(), cells.fineMemo, cells.fine))
                      .count);
}

namespace {
/// The key of the bin that record `h` falls in at its level. Inlined, as JitteredBinKey: a key
/// returned through the stack field by field stalls its caller's load of the whole key.
inline __attribute__((always_inline)) TexelKey RecordBinKey(const TextureSpaceCache& tsc,
                                                            const HitRecord& h) {
    const MeshGrids& g = tsc.Grids(h.mesh);
    const int face = h.Face(), level = h.Level(), res = g.Res(face, level);
    return {g.FaceOffset() + uint32_t(face), uint8_t(level), uint16_t(QuantizeCoord(h.U(), res)),
            uint16_t(QuantizeCoord(h.V(), res))};
}
/// The coordinates, at record `h`'s level (`res` a side), of the bin that holds its point moved
/// by `jitter` bins (each component in [-0.5, 0.5)): up to a bin past the face's edges. With a
/// uniform jitter, bin i0 + 1 of the 2x2 around the point comes out with probability fx, its
/// bilinear weight (CellAt).
inline __attribute__((always_inline)) glm::ivec2 JitteredBin(const HitRecord& h, int res,
                                                             glm::vec2 jitter) {
    const float x = h.U() * float(res) + jitter.x, y = h.V() * float(res) + jitter.y;
    return {x >= 0.0f ? int(x) : -1, y >= 0.0f ? int(y) : -1};
}
/// JitteredBin's key, held inside the face (a hint for Prefetch).
inline __attribute__((always_inline)) TexelKey JitteredBinKey(const TextureSpaceCache& tsc,
                                                              const HitRecord& h,
                                                              glm::vec2 jitter) {
    const MeshGrids& g = tsc.Grids(h.mesh);
    const int face = h.Face(), level = h.Level(), res = g.Res(face, level);
    const glm::ivec2 b = glm::clamp(JitteredBin(h, res, jitter), 0, res - 1);
    return {g.FaceOffset() + uint32_t(face), uint8_t(level), uint16_t(b.x), uint16_t(b.y)};
}
/// The bin JitteredBin names: inside the face, one lookup; past its edge, the neighbour's bin
/// there through the Ptex adjacency, as the bilinear read's cells cross (none at a boundary or
/// diagonally across a vertex).
RadianceBin::Value JitteredBinValue(const TextureSpaceCache& tsc, const RadianceBins& bins,
                                    const HitRecord& h, glm::vec2 jitter) {
    const MeshGrids& g = tsc.Grids(h.mesh);
    const int face = h.Face(), level = h.Level(), res = g.Res(face, level);
    const glm::ivec2 b = JitteredBin(h, res, jitter);
    if (b.x >= 0 && b.x < res && b.y >= 0 && b.y < res)
        return bins.Find(
            {g.FaceOffset() + uint32_t(face), uint8_t(level), uint16_t(b.x), uint16_t(b.y)});
    return FindBin(g, bins, face, level, res, b.x, b.y, ThreadCells(bins).fineMemo);
}
}  // namespace

void PrefetchStoreAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h) {
    store.Samples().Prefetch(RecordBinKey(tsc, h));
}

void PrefetchStoreAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                     glm::vec2 jitter) {
    store.Samples().Prefetch(JitteredBinKey(tsc, h, jitter));
}

double StoreCountAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                    glm::vec2 jitter, double enough, glm::vec3* light) {
    const RadianceBin::Value v = JitteredBinValue(tsc, store.Samples(), h, jitter);
    if (v.count > 0 && double(v.count) >= enough) {
        *light = glm::vec3(BinSum(v) / double(v.count));
        return double(v.count);
    }
    *light = StoreLightAt(tsc, store, h);
    return StoreCountAt(tsc, store, h);
}

glm::vec3 StoreLightAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                       glm::vec2 jitter, double enough) {
    if (StoreFilterLevels(tsc.FilterOf(tsc.ObjectOfMesh(h.mesh)), 0) < 0) {
        const RadianceBin::Value v = JitteredBinValue(tsc, store.Samples(), h, jitter);
        if (v.count > 0 && double(v.count) >= enough) return glm::vec3(BinSum(v) / double(v.count));
    }
    return StoreLightAt(tsc, store, h);
}

double StoreBlockAt(const TextureSpaceCache& tsc, const LightHitStore& store, const HitRecord& h,
                    glm::vec3* light) {
    const RadianceBin::Value v = store.Samples().FindBlock(RecordBinKey(tsc, h));
    *light = v.count > 0 ? glm::vec3(BinSum(v) / double(v.count)) : glm::vec3(0.0f);
    return double(v.count);
}

void CombineWithOwnSamples(const double* rgb, const double* own, int width, int y0, int y1, int n,
                           float* out, CombineScratch* scratch) {
    if (n < 2 || y1 <= y0 || width <= 0) return;  // no spread to weigh: the reconstruction
    const size_t W = size_t(width), rows = size_t(y1 - y0), pixels = W * rows;
    const double invN = 1.0 / double(n);
    // Per pixel: the variance of its mean difference (own - reconstruction, luminance) and the
    // squared mean difference, then each summed over the window (a box, rows then columns).
    // Every entry is written below before it is read: no clearing.
    CombineScratch local;
    CombineScratch& cs = scratch ? *scratch : local;
    for (std::vector<double>* v : {&cs.var, &cs.d2, &cs.tmp})
        if (v->size() < pixels) v->resize(pixels);
    if (cs.odd.size() < pixels) cs.odd.resize(pixels);
    std::vector<double>&var = cs.var, &d2 = cs.d2, &tmp = cs.tmp;
    std::vector<uint8_t>& odd = cs.odd;  // sums not finite: the pixel keeps its reconstruction
    for (size_t p = 0; p < pixels; ++p) {
        const size_t q = size_t(y0) * W + p;
        const double* o = &own[4 * q];
        const double d = Luminance(
            glm::dvec3(o[0] - rgb[3 * q], o[1] - rgb[3 * q + 1], o[2] - rgb[3 * q + 2]) * invN);
        const double v = (o[3] - double(n) * d * d) / (double(n - 1) * double(n));
        const bool ok = std::isfinite(d) && std::isfinite(v);
        var[p] = ok ? std::max(v, 0.0) : 0.0, d2[p] = ok ? d * d : 0.0, odd[p] = !ok;
    }
    const int R = kOwnWindowRadius;
    const double k = OwnWeightK(n);
    for (std::vector<double>* a : {&var, &d2}) {
        for (size_t y = 0; y < rows; ++y)
            for (int x = 0; x < width; ++x) {
                double s = 0.0;
                for (int i = std::max(0, x - R); i <= std::min(width - 1, x + R); ++i)
                    s += (*a)[y * W + size_t(i)];
                tmp[y * W + size_t(x)] = s;
            }
        for (size_t y = 0; y < rows; ++y)
            for (size_t x = 0; x < W; ++x) {
                double s = 0.0;
                const size_t lo = y > size_t(R) ? y - size_t(R) : 0;
                for (size_t j = lo; j <= std::min(rows - 1, y + size_t(R)); ++j)
                    s += tmp[j * W + x];
                (*a)[y * W + x] = s;
            }
    }
    for (size_t p = 0; p < pixels; ++p) {
        const size_t q = size_t(y0) * W + p;
        const double alpha = CoarseWeight(std::sqrt(d2[p]), var[p], k);
        for (int ch = 0; ch < 3; ++ch) {
            const double recon = rgb[3 * q + size_t(ch)] * invN;
            const double mine = own[4 * q + size_t(ch)] * invN;
            const double v = mine + alpha * (recon - mine);
            out[3 * q + size_t(ch)] = float(std::isfinite(v) && !odd[p] ? v : recon);
        }
    }
}

void AddOwnLight(PixelOwnLight& px, glm::vec3 light) {
    if (!std::isfinite(light.x + light.y + light.z)) return;
    const double before = Luminance(px.mean), y = Luminance(light);
    ++px.n;
    px.mean += (light - px.mean) / float(px.n);
    px.m2 += (y - before) * (y - double(Luminance(px.mean)));
}

void PrepareOwnLight(PixelOwnLight& px, glm::vec3 bin) {
    px.bin = bin, px.var = 0.0f, px.d2 = 0.0f;
    if (px.n < 2) return;
    const double n = double(px.n);
    const float var = float(std::max(px.m2, 0.0) / ((n - 1.0) * n));
    const double d = double(Luminance(bin)) - double(Luminance(px.mean));
    const float d2 = float(d * d);
    if (!std::isfinite(var) || !std::isfinite(d2)) return;  // no estimate: the bin
    px.var = var, px.d2 = d2;
}

glm::vec3 BlendWithOwnLight(const PixelOwnLight* px, int width, int height, int x, int y) {
    const PixelOwnLight& me = px[size_t(y) * size_t(width) + size_t(x)];
    if (me.n < 2) return me.bin;
    const int R = kOwnWindowRadius;
    double var = 0.0, d2 = 0.0;
    for (int j = std::max(0, y - R); j <= std::min(height - 1, y + R); ++j)
        for (int i = std::max(0, x - R); i <= std::min(width - 1, x + R); ++i) {
            const PixelOwnLight& q = px[size_t(j) * size_t(width) + size_t(i)];
            var += double(q.var), d2 += double(q.d2);
        }
    const double alpha =
        CoarseWeight(std::sqrt(d2), var, OwnWeightK(int(std::min(me.n, 1u << 20))));
    const glm::dvec3 mine(me.mean);
    const glm::dvec3 v = mine + alpha * (glm::dvec3(me.bin) - mine);
    return std::isfinite(v.x + v.y + v.z) ? glm::vec3(v) : me.bin;
}

}  // namespace texcache::internal
