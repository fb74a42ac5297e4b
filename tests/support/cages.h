// SPDX-License-Identifier: Apache-2.0
// Small control cages built in code for the cache library's tests and benchmarks (no file loading
// needed).
#pragma once
#include <cmath>

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

}  // namespace texcache::test
