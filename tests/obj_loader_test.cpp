// SPDX-License-Identifier: Apache-2.0
// OBJ cages: every OpenSubdiv tag, n-gons, index forms, the bundled meshes, and bad input.
#include <gtest/gtest.h>

#include <chrono>

#include "renderer/obj_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

const char* kQuad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

std::string ErrorOf(const std::string& text) {
    try {
        std::vector<std::string> w;
        ParseObj(text, "bad.obj", &w);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(ObjLoader, ParsesFacesInEveryIndexForm) {
    std::vector<std::string> w;
    const std::string text = std::string(kQuad) +
                             "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
                             "f 1/1/1 2/2/1 3/3/1 4/4/1\n"
                             "f -4/-4 -3/-3 -1/-1\n"  // relative indices, v/vt
                             "o name\ng group\ns 1\nusemtl x\n";
    const ControlCage c = ParseObj(text, "t.obj", &w);
    ASSERT_EQ(c.numFaces(), 2);
    EXPECT_EQ(c.faceVertexCounts[1], 3);
    EXPECT_EQ(c.faceVertexIndices[4], 0);
    EXPECT_EQ(c.faceVertexIndices[6], 3);
    ASSERT_EQ(c.uvs.size(), 4u);
    EXPECT_EQ(c.faceUvIndices[6], 3);
    EXPECT_TRUE(w.empty());
    // v//vn and plain v, CRLF line ends and trailing spaces
    const ControlCage d =
        ParseObj(std::string(kQuad) + "f 1//1 2//1 3//1 4//1  \r\nf 1 2 3\r\n", "t.obj", &w);
    EXPECT_EQ(d.numFaces(), 2);
    EXPECT_TRUE(d.uvs.empty());
}

TEST(ObjLoader, NgonsAndEveryTag) {
    std::vector<std::string> w;
    const std::string text =
        "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nv -1 0 0\n"
        "f 1 2 3 4 5\nf 1 5 6\n"
        "t crease 2/1/0 0 1 2.5\n"
        "t crease 4/1/0 1 2 2 3 10\n"  // several pairs sharing one sharpness
        "t corner 1/1/0 5 4.0\n"
        "t hole 1/0/0 1\n"
        "t interpolateboundary 1/0/0 1\n"
        "t creasemethod 0/0/1 chaikin\n";
    const ControlCage c = ParseObj(text, "tags.obj", &w);
    EXPECT_EQ(c.faceVertexCounts[0], 5);
    ASSERT_EQ(c.creaseEdges.size(), 3u);
    EXPECT_FLOAT_EQ(c.creaseWeights[0], 2.5f);
    EXPECT_FLOAT_EQ(c.creaseWeights[2], 10.0f);
    ASSERT_EQ(c.cornerVertices.size(), 1u);
    EXPECT_EQ(c.cornerVertices[0], 5);
    ASSERT_EQ(c.holes.size(), 1u);
    EXPECT_EQ(c.holes[0], 1);
    EXPECT_EQ(c.boundary, BoundaryInterpolation::EdgeAndCorner);
    ASSERT_EQ(w.size(), 1u);  // the unknown tag
    EXPECT_NE(w[0].find("tags.obj:14"), std::string::npos) << w[0];
    EXPECT_NE(w[0].find("creasemethod"), std::string::npos);
}

TEST(ObjLoader, TagsNamingMissingEdgesOrVerticesWarnAndAreIgnored) {
    std::vector<std::string> w;
    const ControlCage c =
        ParseObj(std::string(kQuad) +
                     "f 1 2 3 4\nt crease 2/1/0 0 2 3\nt corner 1/1/0 9 1\nt hole 1/0/0 7\n",
                 "m.obj", &w);
    EXPECT_TRUE(c.creaseEdges.empty());  // 0-2 is a diagonal, not an edge
    EXPECT_TRUE(c.cornerVertices.empty());
    EXPECT_TRUE(c.holes.empty());
    ASSERT_EQ(w.size(), 3u);
    EXPECT_NE(w[0].find("m.obj:6"), std::string::npos) << w[0];
    EXPECT_EQ(c.boundary,
              BoundaryInterpolation::EdgeOnly);  // absent tag: OpenSubdiv tools' default
}

TEST(ObjLoader, BadInputNamesFileLineAndProblem) {
    struct Case {
        std::string text, expect;
    };
    const std::vector<Case> cases = {
        {"v 0 0 0\nv 1 0 0\nv 1 x 0\n", "bad.obj:3"},                  // malformed number
        {"v 0 0 0\nv 1 0 nan\n", "bad.obj:2"},                         // NaN coordinate
        {"v 0 0 0\nv inf 0 0\n", "non-finite"},                        // Inf coordinate
        {std::string(kQuad) + "f 1 2 5\n", "out of range"},            // index past the end
        {std::string(kQuad) + "f 0 1 2\n", "bad.obj:5"},               // zero index
        {std::string(kQuad) + "f -9 1 2\n", "out of range"},           // relative before the start
        {std::string(kQuad) + "f 1 2\n", "at least 3"},                // too few vertices
        {std::string(kQuad) + "f 1 2 2 3\n", "repeats vertex"},        // degenerate face
        {std::string(kQuad) + "vt 0 0\nf 1/1 2 3\n", "some corners"},  // mixed uvs
        {std::string(kQuad) + "f 1 2 3\nt crease 2/1/0 0 1\n", "fewer"},  // tag count mismatch
        {std::string(kQuad) + "f 1 2 3\nt crease 2/1/0 0 1 2 3\n", "more values"},
        {std::string(kQuad) + "f 1 2 3\nt crease two 0 1 2\n", "nInts/nFloats"},
        {std::string(kQuad) + "f 1 2 3\nt interpolateboundary 1/0/0 7\n", "0, 1 or 2"},
        {"v 0 0 0\n", "no faces"},
        {"v 0 0\n", "3 coordinates"},
    };
    for (const Case& c : cases) {
        const std::string e = ErrorOf(c.text);
        EXPECT_NE(e.find("bad.obj"), std::string::npos) << c.text << " -> " << e;
        EXPECT_NE(e.find(c.expect), std::string::npos) << c.text << " -> " << e;
    }
    EXPECT_THROW(test::LoadMesh("no_such_mesh"), InputError);
}

TEST(ObjLoader, BundledMeshesHaveTheirDocumentedCounts) {
    struct Expect {
        const char* name;
        int v, f, creases;
    };
    for (const Expect& e :
         {Expect{"catmark_car", 1642, 1575, 314}, Expect{"catmark_bishop", 917, 968, 224},
          Expect{"catmark_rook", 768, 777, 280}, Expect{"catmark_pawn", 601, 588, 120},
          Expect{"catmark_helmet", 72, 58, -1}, Expect{"catmark_cube", 8, 6, 0},
          Expect{"catmark_torus", 32, 32, 0}, Expect{"catmark_pyramid", 5, 5, 0},
          Expect{"catmark_nonquads", 33, 17, -1}, Expect{"catmark_xord_interior", 151, 71, -1},
          Expect{"catmark_hole_test1", 8, 6, 0}}) {
        std::vector<std::string> w;
        const ControlCage c = LoadObj(test::MeshPath(e.name), &w);
        EXPECT_EQ(c.numVertices(), e.v) << e.name;
        EXPECT_EQ(c.numFaces(), e.f) << e.name;
        if (e.creases >= 0) {
            EXPECT_EQ(int(c.creaseEdges.size()), e.creases) << e.name;
        }
    }
    std::vector<std::string> w;
    EXPECT_EQ(LoadObj(test::MeshPath("catmark_hole_test1"), &w).holes.size(), 1u);
    EXPECT_EQ(LoadObj(test::MeshPath("catmark_helmet"), &w).boundary,
              BoundaryInterpolation::EdgeAndCorner);
}

}  // namespace
}  // namespace texcache
