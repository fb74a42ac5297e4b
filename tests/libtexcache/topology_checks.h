// SPDX-License-Identifier: Apache-2.0
// GoogleTest checks of a PtexTopology, shared by footprint_test and topology_test.
#pragma once
#include <string>

#include <gtest/gtest.h>

#include "texcache/topology.h"

namespace texcache::test {

/// Every link has its way back: face f's edge e sees g, and g's edge sees f on e.
inline void ExpectSymmetricAdjacency(const PtexTopology& topo, const std::string& name = "") {
    for (int f = 0; f < topo.NumPtexFaces(); ++f)
        for (int e = 0; e < 4; ++e) {
            const auto& link = topo.Edge(f, e);
            for (int j = 0; j < link.count; ++j) {
                const auto& back = topo.Edge(link.face[j], link.edge[j]);
                bool found = false;
                for (int k = 0; k < back.count; ++k)
                    found |= back.face[k] == f && back.edge[k] == e;
                EXPECT_TRUE(found)
                    << name << " face " << f << " edge " << e << " -> " << link.face[j];
            }
        }
}

}  // namespace texcache::test
