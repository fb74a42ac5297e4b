// SPDX-License-Identifier: Apache-2.0
// One mesh of a RenderScene as Embree geometry, and how a hit on it maps to its Ptex face, its
// limit derivatives and its texture coordinates: Embree's own subdivision surface, or, for cages
// Embree cannot take, quads on the limit surface tessellated with OpenSubdiv (the design note at
// the top of embree_mesh.cpp says why). Internal to renderer/scene/: render_scene.cpp builds the
// meshes with these functions and reads every hit through EmbreeMesh, whose per-hit members are
// inline here.
#pragma once
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <embree3/rtcore.h>
#include <glm/glm.hpp>

#include "renderer/scene/plain_mesh.h"
#include "renderer/scene/scene.h"
#include "renderer/texture_space/ptex_mapping.h"
#include "texcache/limit_tessellation.h"

namespace texcache::internal {

/// One mesh's Embree geometry and how its hits map to Ptex faces: Embree's own subdivision
/// surface, or quads on the limit surface tessellated with OpenSubdiv (`limit` set).
struct EmbreeMesh {
    RTCScene scene = nullptr;
    RTCGeometry geom = nullptr;
    std::shared_ptr<const PtexTopology> topo;  // shared with texture-space caches
    std::unique_ptr<RegularPatches> regular;   // fast path for rtcInterpolate
    // Subdivision meshes: OpenSubdiv's patches for the faces `regular` leaves out (see
    // OffFastPathFaces), in parts built in parallel; per Ptex face its part, or kNoPart.
    std::vector<std::unique_ptr<LimitSurface>> irregular;
    std::vector<uint8_t> irregularPart;
    static constexpr uint8_t kNoPart = 255;
    bool hasUv = false;
    std::vector<uint8_t> isHole;  // per coarse face, only for subdivision cages with holes
    // Limit tessellation only (`tessellated`): the general evaluator (null when every face is
    // a facet face, below), and per quad its Ptex square and uvs.
    bool tessellated = false;
    std::unique_ptr<LimitSurface> limit;
    std::vector<LimitTessellation::Square> squares;
    std::vector<std::array<float, 2>> cornerUvs;  // also a plain mesh's, per quad
    // Limit tessellation of a cage with faces too large for OpenSubdiv's patches (see
    // FacetFaces): per Ptex face, the first of its quads when it is evaluated on them, else -1
    // (empty when no face is); the quads' vertices and indices are the Embree geometry's.
    std::vector<int> facetQuad;
    int facetLevel = 0;                    // refinements of the tessellation
    const float* quadPositions = nullptr;  // 4 floats per vertex
    const unsigned* quadIndices = nullptr;
    // Plain meshes (plain_mesh.h): one Embree quad per Ptex face, whose (u,v) is the face's;
    // its 4 corners in Embree's vertex buffer (16-byte stride), which this points into.
    bool plain = false;
    const float* plainCorners = nullptr;

    /// Ptex location of a hit (Embree's primitive and hit parameters).
    PtexCoord ToPtex(unsigned prim, float U, float V) const {
        if (plain) return {int(prim), std::clamp(U, 0.0f, 1.0f), std::clamp(V, 0.0f, 1.0f)};
        if (!tessellated) return EmbreeToPtex(*topo, prim, U, V);
        const LimitTessellation::Square& s = squares[prim];
        return {s.face, std::clamp(s.u0 + s.size * U, 0.0f, 1.0f),
                std::clamp(s.v0 + s.size * V, 0.0f, 1.0f)};
    }

    /// Limit derivatives in Ptex (u,v), and the position when P is given, at `c`, which is
    /// Embree's (prim, U, V) on a subdivision mesh (16-byte aligned outputs); false on a hole.
    bool Eval(const PtexCoord& c, unsigned prim, float U, float V, float* P, float* du,
              float* dv) const {
        if (plain) return PlainQuadEval(plainCorners + 16 * size_t(c.face), c.u, c.v, P, du, dv);
        if (regular->Has(c.face)) {
            // Regular patches: our bicubic evaluation, several times cheaper than rtcInterpolate
            // (the same surface).
            regular->Eval(c.face, c.u, c.v, P, du, dv);
            return true;
        }
        // OpenSubdiv's patches: the limit tessellation's evaluator, or the irregular faces'.
        auto patches = [&](const LimitSurface& surface) {
            if (!P) return surface.EvalDerivatives(c.face, c.u, c.v, du, dv);
            LimitPoint p;
            if (!surface.Eval(c.face, c.u, c.v, &p)) return false;
            for (int k = 0; k < 3; ++k) {
                if (P) P[k] = p.P[k];
                du[k] = p.dPdu[k], dv[k] = p.dPdv[k];
            }
            return true;
        };
        if (tessellated) {
            if (!facetQuad.empty() && facetQuad[c.face] >= 0) return EvalFacet(c, P, du, dv);
            return limit && patches(*limit);
        }
        if (!irregularPart.empty() && irregularPart[c.face] != kNoPart &&
            patches(*irregular[irregularPart[c.face]]))
            return true;
        rtcInterpolate1(geom, prim, U, V, RTC_BUFFER_TYPE_VERTEX, 0, P, du, dv, 3);
        return true;
    }

    /// The limit tessellation's quad at `c` (a facet face's, facetQuad), as Embree
    /// parametrizes it: its position and its derivatives in Ptex (u,v).
    bool EvalFacet(const PtexCoord& c, float* P, float* du, float* dv) const;

    /// Texture coordinates at a hit (only when hasUv).
    glm::vec2 Uv(unsigned prim, float U, float V) const {
        if (tessellated || plain) {
            // Bilinear in the quad, whose corners carry OpenSubdiv's limit uvs.
            const auto* c = &cornerUvs[size_t(prim) * 4];
            auto at = [&](int k) { return glm::vec2(c[k][0], c[k][1]); };
            return (1.0f - V) * ((1.0f - U) * at(0) + U * at(1)) +
                   V * ((1.0f - U) * at(3) + U * at(2));
        }
        alignas(16) float uv[4];
        rtcInterpolate1(geom, prim, U, V, RTC_BUFFER_TYPE_VERTEX_ATTRIBUTE, 0, uv, nullptr, nullptr,
                        2);
        return {uv[0], uv[1]};
    }
};

/// Cage faces Embree cannot take: too many vertices, or a vertex with too large a 1-ring.
size_t FacesBeyondEmbree(const ControlCage& cage, const PtexTopology& topo);

/// The cage faces (not Ptex faces) whose limit derivatives come from OpenSubdiv's patches rather
/// than rtcInterpolate on Embree's subdivision surface.
std::vector<int> OffFastPathFaces(const ControlCage& cage, const PtexTopology& topo,
                                  const RegularPatches& regular);

/// OpenSubdiv's patches for `faces` (OffFastPathFaces) into mesh->irregular and irregularPart.
void BuildIrregularPatches(const ControlCage& cage, const std::vector<int>& faces,
                           EmbreeMesh* mesh);

/// The cage as Embree's subdivision surface at tessellation rate `rate` (face-varying uvs when
/// `withUv`); sets mesh's hole flags and hasUv.
RTCGeometry NewSubdivisionGeometry(RTCDevice device, const ControlCage& cage, float rate,
                                   bool withUv, EmbreeMesh* mesh);

/// The cage as a plain mesh (plain_mesh.h): one quad per Ptex face (mesh->topo must be set);
/// sets mesh's plain corners and uvs.
RTCGeometry NewPlainQuadGeometry(RTCDevice device, const ControlCage& cage, bool withUv,
                                 EmbreeMesh* mesh);

/// The cage as quads on its limit surface, as many per cage quad edge as Embree's grids at
/// `rate`; sets mesh's limit surface, Ptex squares and uvs.
RTCGeometry NewLimitQuadGeometry(RTCDevice device, const ControlCage& cage, float rate, bool withUv,
                                 EmbreeMesh* mesh);

}  // namespace texcache::internal
