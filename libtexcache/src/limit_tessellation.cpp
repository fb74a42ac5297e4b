// SPDX-License-Identifier: Apache-2.0
#include "texcache/limit_tessellation.h"

#include <stdexcept>

#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>

#include "osd_refiner.h"
#include "texcache/error.h"

namespace texcache {
namespace Far = OpenSubdiv::Far;
using internal::OsdVertex;

namespace {

// Values of one primvar at every level of a uniformly refined cage, then at the limit of the
// last level's vertices (or face-varying values).
template <class Refine, class Limit>
std::vector<OsdVertex> RefineToLimit(std::vector<OsdVertex> values, int levels,
                                     const std::vector<int>& counts, Refine refine, Limit limit) {
    for (int level = 1; level <= levels; ++level) {
        std::vector<OsdVertex> next(size_t(counts[level]));
        refine(level, values.data(), next.data());
        values.swap(next);
    }
    std::vector<OsdVertex> out(values.size());
    OsdVertex* dst = out.data();
    limit(values.data(), dst);
    return out;
}

}  // namespace

LimitTessellation TessellateLimitSurface(const ControlCage& cage, int level, bool withUvs) {
    if (level < 1) throw std::invalid_argument("TessellateLimitSurface: level must be >= 1");
    const bool uvs = withUvs && !cage.uvs.empty();
    auto refiner = internal::CreateRefiner(cage, uvs);
    Far::TopologyRefiner::UniformOptions options(level);
    options.fullTopologyInLastLevel = true;  // Limit() needs each last-level vertex's neighbours
    refiner->RefineUniform(options);

    // Child faces are numbered parent by parent, child j at the parent's vertex j (OpenSubdiv's
    // Vtr ordering); check the counts this relies on rather than trust it silently.
    const int nf = cage.numFaces();
    std::vector<int> firstChild(size_t(nf) + 1, 0);
    for (int f = 0; f < nf; ++f) firstChild[f + 1] = firstChild[f] + cage.faceVertexCounts[f];
    bool ordered = refiner->GetLevel(1).GetNumFaces() == firstChild[nf];
    for (int l = 2; l <= level; ++l)
        ordered = ordered &&
                  refiner->GetLevel(l).GetNumFaces() == 4 * refiner->GetLevel(l - 1).GetNumFaces();
    if (!ordered) throw std::logic_error("OpenSubdiv's uniform refinement skipped faces");

    Far::PrimvarRefiner primvar(*refiner);
    std::vector<int> vertexCounts(size_t(level) + 1);
    for (int l = 0; l <= level; ++l) vertexCounts[l] = refiner->GetLevel(l).GetNumVertices();
    std::vector<OsdVertex> coarse(size_t(cage.numVertices()));
    for (int i = 0; i < cage.numVertices(); ++i)
        coarse[i] = {{cage.positions[i][0], cage.positions[i][1], cage.positions[i][2]}};
    const std::vector<OsdVertex> limit = RefineToLimit(
        std::move(coarse), level, vertexCounts,
        [&](int l, const OsdVertex* src, OsdVertex* dst) { primvar.Interpolate(l, src, dst); },
        [&](const OsdVertex* src, OsdVertex*& dst) { primvar.Limit(src, dst); });

    LimitTessellation t;
    t.positions.reserve(limit.size());
    for (const OsdVertex& v : limit) t.positions.push_back({v.p[0], v.p[1], v.p[2]});

    std::vector<OsdVertex> limitUvs;
    if (uvs) {
        std::vector<int> uvCounts(size_t(level) + 1);
        for (int l = 0; l <= level; ++l) uvCounts[l] = refiner->GetLevel(l).GetNumFVarValues(0);
        std::vector<OsdVertex> coarseUvs(cage.uvs.size());
        for (size_t i = 0; i < cage.uvs.size(); ++i)
            coarseUvs[i] = {{cage.uvs[i][0], cage.uvs[i][1], 0.0f}};
        limitUvs = RefineToLimit(
            std::move(coarseUvs), level, uvCounts,
            [&](int l, const OsdVertex* src, OsdVertex* dst) {
                primvar.InterpolateFaceVarying(l, src, dst);
            },
            [&](const OsdVertex* src, OsdVertex*& dst) { primvar.LimitFaceVarying(src, dst); });
    }

    std::vector<char> hole(size_t(nf), 0);
    for (int h : cage.holes)
        if (h >= 0 && h < nf) hole[h] = 1;
    std::vector<int> coarseOfChild(static_cast<size_t>(firstChild[nf]));
    for (int f = 0; f < nf; ++f)
        for (int c = firstChild[f]; c < firstChild[f + 1]; ++c) coarseOfChild[c] = f;
    const Far::PtexIndices ptex(*refiner);

    const Far::TopologyLevel& last = refiner->GetLevel(level);
    const int digits = level - 1;  // quadrant choices below the first refinement
    for (int q = 0; q < last.GetNumFaces(); ++q) {
        const int child = q >> (2 * digits);
        const int f = coarseOfChild[child], j = child - firstChild[f];
        if (hole[f]) continue;
        LimitTessellation::Square s;
        if (cage.faceVertexCounts[f] == 4) {
            // A quad's child j is the quadrant at its corner j, oriented as the quad.
            s.face = ptex.GetFaceId(f);
            s.size = 0.5f;
            s.u0 = (j == 1 || j == 2) ? 0.5f : 0.0f;
            s.v0 = (j == 2 || j == 3) ? 0.5f : 0.0f;
        } else {
            // An n-gon's child j is its Ptex sub-face j, corner 0 at the n-gon's vertex j.
            s.face = ptex.GetFaceId(f) + j;
        }
        for (int d = digits - 1; d >= 0; --d) {
            const int k = (q >> (2 * d)) & 3;
            s.size *= 0.5f;
            s.u0 += (k == 1 || k == 2) ? s.size : 0.0f;
            s.v0 += (k == 2 || k == 3) ? s.size : 0.0f;
        }
        const Far::ConstIndexArray fv = last.GetFaceVertices(q);
        t.quads.push_back({fv[0], fv[1], fv[2], fv[3]});
        t.squares.push_back(s);
        if (uvs) {
            const Far::ConstIndexArray fuv = last.GetFaceFVarValues(q, 0);
            for (int k = 0; k < 4; ++k)
                t.cornerUvs.push_back({limitUvs[fuv[k]].p[0], limitUvs[fuv[k]].p[1]});
        }
    }
    return t;
}

}  // namespace texcache
