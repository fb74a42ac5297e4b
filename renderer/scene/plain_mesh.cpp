// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/plain_mesh.h"

#include "renderer/scene/embree_mesh.h"

namespace texcache::internal {

namespace {

// Points and uvs as the cage stores them.
template <size_t N>
std::array<float, N> operator+(const std::array<float, N>& a, const std::array<float, N>& b) {
    std::array<float, N> r;
    for (size_t k = 0; k < N; ++k) r[k] = a[k] + b[k];
    return r;
}
template <size_t N>
std::array<float, N> operator*(const std::array<float, N>& a, float s) {
    std::array<float, N> r;
    for (size_t k = 0; k < N; ++k) r[k] = a[k] * s;
    return r;
}

/// The 4 corners of each of a polygon's Ptex faces from its n points `p` (any type with + and
/// scalar *): the polygon itself when n = 4, else its n sub-faces.
template <typename T, typename Add>
void PolygonQuads(const T* p, int n, Add&& add) {
    if (n == 4) {
        add(p[0], p[1], p[2], p[3]);
        return;
    }
    T centre = p[0];
    for (int i = 1; i < n; ++i) centre = centre + p[i];
    centre = centre * (1.0f / float(n));
    for (int i = 0; i < n; ++i) {
        const T& a = p[i];
        const T& next = p[(i + 1) % n];
        const T& prev = p[(i + n - 1) % n];
        // Both faces of an edge compute its midpoint from the same two points in the same order
        // of operands up to commutativity: the same float, so the quads meet without a crack.
        add(a, (a + next) * 0.5f, centre, (prev + a) * 0.5f);
    }
}

}  // namespace

std::vector<std::array<float, 3>> PlainQuadCorners(const ControlCage& cage,
                                                   const PtexTopology& topo,
                                                   std::vector<std::array<float, 2>>* uvs) {
    std::vector<std::array<float, 3>> corners;
    corners.reserve(4 * size_t(topo.NumPtexFaces()));
    const bool withUv = uvs && !cage.uvs.empty();
    if (withUv) uvs->clear(), uvs->reserve(corners.capacity());
    std::vector<char> hole(size_t(cage.numFaces()), 0);
    for (int h : cage.holes) hole[size_t(h)] = 1;
    std::vector<std::array<float, 3>> p;
    std::vector<std::array<float, 2>> t;
    int offset = 0;
    for (int f = 0; f < cage.numFaces(); ++f) {
        const int n = cage.faceVertexCounts[size_t(f)];
        p.clear(), t.clear();
        for (int i = 0; i < n; ++i) {
            const size_t k = size_t(offset + i);
            // A hole keeps its Ptex ids (primitive ids must stay the Ptex face ids) but no area.
            p.push_back(
                cage.positions[size_t(cage.faceVertexIndices[hole[size_t(f)] ? offset : k])]);
            if (withUv) t.push_back(cage.uvs[size_t(cage.faceUvIndices[k])]);
        }
        PolygonQuads(p.data(), n, [&](auto a, auto b, auto c, auto d) {
            corners.insert(corners.end(), {a, b, c, d});
        });
        if (withUv)
            PolygonQuads(t.data(), n, [&](auto a, auto b, auto c, auto d) {
                uvs->insert(uvs->end(), {a, b, c, d});
            });
        offset += n;
    }
    return corners;
}

RTCGeometry NewPlainQuadGeometry(RTCDevice device, const ControlCage& cage, bool withUv,
                                 EmbreeMesh* mesh) {
    std::vector<std::array<float, 2>> uvs;
    const std::vector<std::array<float, 3>> corners =
        PlainQuadCorners(cage, *mesh->topo, withUv ? &uvs : nullptr);
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_QUAD);
    // 16-byte stride with w = 0, as for the subdivision cage's vertices.
    auto* pos = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float), corners.size()));
    for (size_t i = 0; i < corners.size(); ++i) {
        for (int k = 0; k < 3; ++k) pos[4 * i + k] = corners[i][size_t(k)];
        pos[4 * i + 3] = 0.0f;
    }
    auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(unsigned), corners.size() / 4));
    for (size_t i = 0; i < corners.size(); ++i) idx[i] = unsigned(i);
    mesh->plain = true;
    mesh->plainCorners = pos;
    mesh->cornerUvs = std::move(uvs);
    mesh->hasUv = !mesh->cornerUvs.empty();
    return g;
}

}  // namespace texcache::internal
