// SPDX-License-Identifier: Apache-2.0
// The Embree tutorial XML writer of `texcache bench peer` (renderer/scene/embree_xml.h): what it
// writes reads back as the same cage, and what Embree's path tracer cannot take is named.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "renderer/scene/embree_xml.h"
#include "test_util.h"

namespace texcache {
namespace {

/// The numbers between <tag ...> and </tag> (strtod reads "+inf" as Embree's loader does); empty
/// when the tag is absent.
std::vector<double> Numbers(const std::string& xml, const std::string& tag) {
    const size_t open = xml.find("<" + tag);
    if (open == std::string::npos) return {};
    const size_t begin = xml.find('>', open) + 1, end = xml.find("</" + tag + ">", begin);
    EXPECT_NE(end, std::string::npos) << tag;
    std::vector<double> v;
    const std::string body = xml.substr(begin, end - begin);
    const char* p = body.c_str();
    for (char* next = nullptr;; p = next) {
        const double x = std::strtod(p, &next);
        if (next == p) break;
        v.push_back(x);
    }
    return v;
}

TEST(EmbreeXml, CageWithCreasesCornersHolesAndNgonsReadsBack) {
    // The car's creases (some infinitely sharp), plus a cage with a hole and 3/5/6-gons.
    for (const char* name : {"catmark_car", "catmark_nonquads", "catmark_hole_test1"}) {
        SCOPED_TRACE(name);
        ControlCage cage = test::LoadMesh(name);
        cage.cornerVertices = {0, 1};
        cage.cornerWeights = {2.5f, 12.0f};
        const std::string xml = EmbreeXmlScene(cage, glm::vec3(1.0f, 0.5f, 0.25f));

        const std::vector<double> P = Numbers(xml, "positions");
        ASSERT_EQ(P.size(), 3 * cage.positions.size());
        for (size_t i = 0; i < P.size(); ++i)
            ASSERT_EQ(float(P[i]), cage.positions[i / 3][i % 3]) << i;  // exact float round trip
        const std::vector<double> idx = Numbers(xml, "position_indices");
        ASSERT_EQ(idx.size(), cage.faceVertexIndices.size());
        for (size_t i = 0; i < idx.size(); ++i) ASSERT_EQ(int(idx[i]), cage.faceVertexIndices[i]);
        const std::vector<double> faces = Numbers(xml, "faces");
        ASSERT_EQ(faces.size(), cage.faceVertexCounts.size());
        for (size_t i = 0; i < faces.size(); ++i)
            ASSERT_EQ(int(faces[i]), cage.faceVertexCounts[i]);

        const std::vector<double> ce = Numbers(xml, "edge_creases");
        const std::vector<double> cw = Numbers(xml, "edge_crease_weights");
        ASSERT_EQ(ce.size(), 2 * cage.creaseEdges.size());
        ASSERT_EQ(cw.size(), cage.creaseEdges.size());
        for (size_t i = 0; i < cw.size(); ++i) {
            EXPECT_EQ(int(ce[2 * i]), cage.creaseEdges[i][0]);
            EXPECT_EQ(int(ce[2 * i + 1]), cage.creaseEdges[i][1]);
            // OpenSubdiv's sharpness >= 10 is infinitely sharp: Embree wants +inf.
            if (cage.creaseWeights[i] >= 10.0f)
                EXPECT_TRUE(std::isinf(cw[i]) && cw[i] > 0.0) << cw[i];
            else
                EXPECT_EQ(float(cw[i]), cage.creaseWeights[i]);
        }
        EXPECT_EQ(Numbers(xml, "vertex_creases"), (std::vector<double>{0.0, 1.0}));
        const std::vector<double> vw = Numbers(xml, "vertex_crease_weights");
        ASSERT_EQ(vw.size(), 2u);
        EXPECT_EQ(vw[0], 2.5);
        EXPECT_TRUE(std::isinf(vw[1]));
        const std::vector<double> holes = Numbers(xml, "holes");
        ASSERT_EQ(holes.size(), cage.holes.size());
        for (size_t i = 0; i < holes.size(); ++i) EXPECT_EQ(int(holes[i]), cage.holes[i]);
        EXPECT_NE(xml.find("<float3 name=\"Kd\">1 0.5 0.25</float3>"), std::string::npos);
        // Smooth boundaries are the loader's default, which it has no name for.
        if (cage.boundary == BoundaryInterpolation::EdgeOnly) {
            EXPECT_NE(xml.find("<position_indices>"), std::string::npos);
        }
    }
}

TEST(EmbreeXml, BoundaryModeIsNamedAsEmbreeNamesIt) {
    ControlCage cage = test::LoadMesh("catmark_cube");
    cage.boundary = BoundaryInterpolation::EdgeOnly;
    EXPECT_NE(EmbreeXmlScene(cage, glm::vec3(1.0f)).find("<position_indices>"), std::string::npos);
    cage.boundary = BoundaryInterpolation::EdgeAndCorner;
    EXPECT_NE(EmbreeXmlScene(cage, glm::vec3(1.0f)).find("subdiv_mode=\"pin_corners\""),
              std::string::npos);
    cage.boundary = BoundaryInterpolation::None;
    EXPECT_NE(EmbreeXmlScene(cage, glm::vec3(1.0f)).find("subdiv_mode=\"no_boundary\""),
              std::string::npos);
}

TEST(EmbreeXml, PeerCheckNamesWhatEmbreeCannotTake) {
    EXPECT_TRUE(CheckEmbreePeer(test::LoadMesh("catmark_car")).cannot.empty());
    EXPECT_TRUE(CheckEmbreePeer(test::LoadMesh("catmark_nonquads")).differs.empty());
    const EmbreePeerCheck holes = CheckEmbreePeer(test::LoadMesh("catmark_hole_test1"));
    EXPECT_TRUE(holes.cannot.empty());
    ASSERT_EQ(holes.differs.size(), 1u);
    EXPECT_NE(holes.differs[0].find("hole"), std::string::npos);

    // A 16-gon fan (Embree 3 asserts on exactly 16 vertices) around a centre of valence 16.
    ControlCage big;
    for (int i = 0; i < 16; ++i)
        big.positions.push_back({std::cos(0.39f * float(i)), std::sin(0.39f * float(i)), 0.0f});
    big.faceVertexCounts = {16};
    for (int i = 0; i < 16; ++i) big.faceVertexIndices.push_back(i);
    EmbreePeerCheck c = CheckEmbreePeer(big);
    ASSERT_EQ(c.cannot.size(), 1u);
    EXPECT_NE(c.cannot[0].find("16 vertices"), std::string::npos) << c.cannot[0];
    big.faceVertexCounts = {15};  // 15 is fine
    big.faceVertexIndices.pop_back();
    EXPECT_TRUE(CheckEmbreePeer(big).cannot.empty());

    // A vertex in 65 triangles.
    ControlCage fan;
    fan.positions.push_back({0.0f, 0.0f, 0.0f});
    for (int i = 0; i < 65; ++i) {
        fan.positions.push_back({std::cos(0.0966f * float(i)), std::sin(0.0966f * float(i)), 0});
        fan.faceVertexCounts.push_back(3);
        fan.faceVertexIndices.insert(fan.faceVertexIndices.end(), {0, 1 + i, 1 + (i + 1) % 65});
    }
    c = CheckEmbreePeer(fan);
    ASSERT_EQ(c.cannot.size(), 1u);
    EXPECT_NE(c.cannot[0].find("65 faces"), std::string::npos) << c.cannot[0];
}

}  // namespace
}  // namespace texcache
