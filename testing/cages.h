// SPDX-License-Identifier: Apache-2.0
// Small control cages built in code for the cache library's tests and benchmarks (no file loading
// needed).
#pragma once
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "texcache/cage.h"

namespace texcache::test {

/// n x n quads in the XZ plane spanning [0, n] (open boundary).
inline ControlCage GridCage(int n) {
    ControlCage c;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) c.positions.push_back({float(i), 0.0f, float(j)});
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const int a = j * (n + 1) + i;
            c.faceVertexCounts.push_back(4);
            c.faceVertexIndices.insert(c.faceVertexIndices.end(), {a, a + n + 1, a + n + 2, a + 1});
        }
    c.boundary = BoundaryInterpolation::EdgeAndCorner;
    c.sourcePath = "grid";
    return c;
}

/// The unit cube: closed, every vertex of valence 3.
inline ControlCage CubeCage() {
    ControlCage c;
    c.positions = {{-1, -1, 1}, {1, -1, 1}, {-1, 1, 1},   {1, 1, 1},
                   {-1, 1, -1}, {1, 1, -1}, {-1, -1, -1}, {1, -1, -1}};
    c.faceVertexCounts = {4, 4, 4, 4, 4, 4};
    c.faceVertexIndices = {0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4};
    c.sourcePath = "cube";
    return c;
}

/// k quads around one interior vertex of valence k (a disc with a boundary).
inline ControlCage FanCage(int k) {
    ControlCage c;
    c.positions.push_back({0, 0, 0});
    for (int i = 0; i < 2 * k; ++i) {
        const float a = 2.0f * 3.14159265f * float(i) / float(2 * k);
        const float r = (i % 2) ? 1.4f : 1.0f;
        c.positions.push_back({r * std::cos(a), 0.0f, r * std::sin(a)});
    }
    for (int i = 0; i < k; ++i) {
        const int a = 1 + 2 * i, b = 1 + 2 * i + 1, d = 1 + (2 * i + 2) % (2 * k);
        c.faceVertexCounts.push_back(4);
        c.faceVertexIndices.insert(c.faceVertexIndices.end(), {0, d, b, a});
    }
    c.boundary = BoundaryInterpolation::EdgeAndCorner;
    c.sourcePath = "fan";
    return c;
}

/// A pentagon with a quad on one of its edges and a triangle on another (n-gon sub-faces,
/// quad <-> sub-face half edges, boundaries).
inline ControlCage PentagonCage() {
    ControlCage c;
    for (int i = 0; i < 5; ++i) {
        const float a = 2.0f * 3.14159265f * float(i) / 5.0f;
        c.positions.push_back({std::cos(a), 0.0f, -std::sin(a)});
    }
    // Quad on edge (0,1) and triangle on edge (2,3), both consistently oriented (CCW from +Y).
    c.positions.push_back({2.0f * std::cos(0.0f), 0.0f, -2.0f * std::sin(0.0f)});        // 5
    c.positions.push_back({2.0f * std::cos(1.2566f), 0.0f, -2.0f * std::sin(1.2566f)});  // 6
    c.positions.push_back({-1.6f, 0.0f, 0.0f});                                          // 7
    c.faceVertexCounts = {5, 4, 3};
    c.faceVertexIndices = {0, 1, 2, 3, 4, /*quad*/ 1, 0, 5, 6, /*tri*/ 3, 2, 7};
    c.boundary = BoundaryInterpolation::EdgeAndCorner;
    c.sourcePath = "pentagon";
    return c;
}

/// Reverses every face loop (turns the surface's orientation around).
inline void ReverseFaces(ControlCage* c) {
    auto* idx = c->faceVertexIndices.data();
    for (int n : c->faceVertexCounts) {
        std::reverse(idx, idx + n);
        idx += n;
    }
}

/// An open tube around +Y: rings of n vertices at heights y0 (indices 0..n-1) and y1 (n..2n-1)
/// joined by n quads, wound clockwise seen from outside (ReverseFaces turns it around once the
/// caps are added the same way).
inline ControlCage TubeCage(int n, float y0, float y1) {
    ControlCage c;
    for (float y : {y0, y1})
        for (int i = 0; i < n; ++i) {
            const float a = 2.0f * 3.14159265f * float(i) / float(n);
            c.positions.push_back({std::cos(a), y, std::sin(a)});
        }
    for (int i = 0; i < n; ++i) {
        const int j = (i + 1) % n;
        c.faceVertexCounts.push_back(4);
        c.faceVertexIndices.insert(c.faceVertexIndices.end(), {i, j, n + j, n + i});
    }
    return c;
}

/// A closed prism of height 1 around +Y: an n-gon on top and at the bottom, n quads around (for
/// n >= 16, faces past Embree's limits).
inline ControlCage PrismCage(int n) {
    ControlCage c = TubeCage(n, -0.5f, 0.5f);
    c.faceVertexCounts.push_back(n);
    for (int i = 0; i < n; ++i) c.faceVertexIndices.push_back(n + i);
    c.faceVertexCounts.push_back(n);
    for (int i = n - 1; i >= 0; --i) c.faceVertexIndices.push_back(i);
    ReverseFaces(&c);  // counter-clockwise seen from outside, as OBJ cages are
    c.sourcePath = "prism" + std::to_string(n);
    return c;
}

/// A closed spindle around +Y: a pole of valence k at each end (k triangles around it) and a
/// ring of k quads between (for k >= 65, vertices past Embree's limits).
inline ControlCage PoleCage(int k) {
    ControlCage c = TubeCage(k, -0.4f, 0.4f);
    const int south = 2 * k, north = 2 * k + 1;
    c.positions.push_back({0.0f, -1.0f, 0.0f});
    c.positions.push_back({0.0f, 1.0f, 0.0f});
    for (int i = 0; i < k; ++i) {
        const int j = (i + 1) % k;
        c.faceVertexCounts.insert(c.faceVertexCounts.end(), {3, 3});
        c.faceVertexIndices.insert(c.faceVertexIndices.end(), {north, k + i, k + j, south, j, i});
    }
    ReverseFaces(&c);  // counter-clockwise seen from outside, as OBJ cages are
    c.sourcePath = "pole" + std::to_string(k);
    return c;
}

/// k faces of m vertices each around one interior vertex (an open flower): for k (m - 2) > 128,
/// a 1-ring past Embree's limits although no face or valence is.
inline ControlCage FlowerCage(int k, int m) {
    ControlCage c;
    c.positions.push_back({0.0f, 0.0f, 0.0f});
    for (int i = 0; i < k; ++i) {
        const float a = 2.0f * 3.14159265f * float(i) / float(k);
        c.positions.push_back({std::cos(a), 0.0f, std::sin(a)});
    }
    for (int i = 0; i < k; ++i) {
        // Outer vertices between spoke i + 1 and spoke i, on an arc bulging outwards.
        const int first = int(c.positions.size());
        for (int e = 0; e < m - 3; ++e) {
            const float a =
                2.0f * 3.14159265f * (float(i + 1) - float(e + 1) / float(m - 2)) / float(k);
            c.positions.push_back({1.3f * std::cos(a), 0.0f, 1.3f * std::sin(a)});
        }
        c.faceVertexCounts.push_back(m);
        c.faceVertexIndices.insert(c.faceVertexIndices.end(), {0, 1 + (i + 1) % k});
        for (int e = 0; e < m - 3; ++e) c.faceVertexIndices.push_back(first + e);
        c.faceVertexIndices.push_back(1 + i);
    }
    c.boundary = BoundaryInterpolation::EdgeAndCorner;
    c.sourcePath = "flower" + std::to_string(k) + "x" + std::to_string(m);
    return c;
}

/// The cages past Embree's subdivision limits, by name: "prism16" and "prism20" (16- and 20-gon
/// caps), "fan70" (an interior vertex of valence 70), "pole65" (two poles of valence 65 among
/// triangles), "flower10x15" (ten 15-gons around a vertex: 130 vertices in its 1-ring).
inline const std::vector<std::string>& BeyondEmbreeCages() {
    static const std::vector<std::string> names = {"prism16", "prism20", "fan70", "pole65",
                                                   "flower10x15"};
    return names;
}
inline ControlCage BeyondEmbreeCage(const std::string& name) {
    if (name == "prism16") return PrismCage(16);
    if (name == "prism20") return PrismCage(20);
    if (name == "fan70") return FanCage(70);
    if (name == "pole65") return PoleCage(65);
    return FlowerCage(10, 15);
}

}  // namespace texcache::test
