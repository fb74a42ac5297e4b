// SPDX-License-Identifier: Apache-2.0
// The Ptex reader on the real files of scenes/ptex/ (written by Disney's Ptex library): headers,
// decoded texels checked against what the files themselves store (their reductions and constant
// blocks, the same texture at two resolutions, the pictures' content), face ids and adjacency
// against the project's own topology of the meshes they belong to, and filtered lookups.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "ptex_test_util.h"
#include "texcache/ptex/info.h"
#include "texcache/ptex/texture.h"

namespace texcache {
namespace {

using ptex::Texture;

struct KnownFile {
    const char* path;
    int faces, levels, channels;
    const char* mesh;
};

// Header facts as the files hold them (read with an independent script of the format page).
const KnownFile kFiles[] = {
    {"cube/text/cube.ptx", 72, 8, 1, "cube/cube.obj"},
    {"flatsphere/cellnoise.ptx", 306, 7, 3, "flatsphere/ptex_test_object.obj"},
    {"flatsphere/pPyramid1.ptx", 306, 8, 3, "flatsphere/ptex_test_object.obj"},
    {"nonquad/evblur/pPlane1.ptx", 66, 1, 3, "nonquad/tritestsub.obj"},
    {"nonquad/test/pPlane1.ptx", 66, 5, 3, "nonquad/tritestsub.obj"},
    {"nonquad/test/pPlane1Unsub.ptx", 21, 6, 3, "nonquad/tritest.obj"},
};

const Texture& Load(const std::string& rel) {
    static std::map<std::string, Texture> cache;
    auto it = cache.find(rel);
    if (it == cache.end()) it = cache.emplace(rel, Texture::Open(test::PtexPath(rel))).first;
    return it->second;
}

TEST(PtexReader, ReadsEveryBundledFile) {
    for (const KnownFile& k : kFiles) {
        SCOPED_TRACE(k.path);
        const Texture& t = Load(k.path);
        const ptex::Header& h = t.GetHeader();
        EXPECT_EQ(h.numFaces, k.faces);
        EXPECT_EQ(h.numLevels, k.levels);
        EXPECT_EQ(h.numChannels, k.channels);
        EXPECT_EQ(h.dataType, ptex::DataType::UInt8);
        EXPECT_EQ(h.meshType, ptex::MeshType::Quad);
        EXPECT_EQ(h.alphaChannel, -1);
        // Files from before format 1.3: no extended header, so clamp borders.
        EXPECT_EQ(h.uBorder, ptex::BorderMode::Clamp);
        EXPECT_TRUE(t.MetaData().empty());
        // The JSON summary has every face with a mean per channel.
        const nlohmann::json j = nlohmann::json::parse(ptex::ToJson(ptex::Summarize(t)));
        ASSERT_EQ(j["faces"].size(), size_t(k.faces));
        EXPECT_EQ(j["faces"][0]["mean"].size(), size_t(k.channels));
        EXPECT_EQ(j["header"]["data_type"], "uint8");
        EXPECT_EQ(j["border"]["v"], "clamp");
    }
    // The cube's 512x512 faces are tiled; cellnoise's largest faces too, the rest zipped.
    EXPECT_EQ(Load("cube/text/cube.ptx").LevelRes(0, 0), (ptex::Res{9, 9}));
    EXPECT_EQ(Load("cube/text/cube.ptx").LevelRes(0, 7), (ptex::Res{2, 2}));
    EXPECT_TRUE(Load("nonquad/test/pPlane1Unsub.ptx").Face(5).subface);
}

// Ptex reduces uint8 levels as (a + b + c + d) >> 2 of the level above; the files store every
// reduction. Reproducing them exactly from our decoded level 0 (diff-zipped, tiled) checks the
// decoding against data the file holds independently. pPyramid1 (the cells of cellnoise, tiled
// like the cube) is left to the other tests: it is a third of the time of all files here.
TEST(PtexReader, StoredReductionsAreThePtexReductionOfTheLevelAbove) {
    for (const KnownFile& k : kFiles) {
        if (std::string(k.path) == "flatsphere/pPyramid1.ptx") continue;
        SCOPED_TRACE(k.path);
        const Texture& t = Load(k.path);
        const int nc = t.NumChannels();
        std::vector<float> p(static_cast<size_t>(nc)), q(static_cast<size_t>(nc));
        long checked = 0, differ = 0;
        const int step = t.NumFaces() > 50 ? 5 : 1;  // a spread of the bigger files' faces
        for (int f = 0; f < t.NumFaces(); f += step)
            for (int lv = 1; lv < t.NumLevels(f); ++lv) {
                ASSERT_TRUE(t.LevelStored(f, lv));
                const ptex::Res r = t.LevelRes(f, lv);
                for (int y = 0; y < r.V(); ++y)
                    for (int x = 0; x < r.U(); ++x) {
                        t.Texel(f, lv, x, y, q.data());
                        int sum[4] = {0, 0, 0, 0};
                        for (int j = 0; j < 4; ++j) {
                            t.Texel(f, lv - 1, 2 * x + (j & 1), 2 * y + (j >> 1), p.data());
                            for (int c = 0; c < nc; ++c) sum[c] += int(std::lround(p[c] * 255));
                        }
                        for (int c = 0; c < nc; ++c, ++checked)
                            differ += (sum[c] >> 2) != int(std::lround(q[c] * 255));
                    }
            }
        EXPECT_EQ(differ, 0) << "of " << checked;
        if (k.levels > 1) {
            EXPECT_GT(checked, 10000);
        }
    }
}

// The constant block holds each face's average, taken by Ptex from its smallest reduction: the
// integer reductions above truncate (about -0.4/255 per level, up to 8 levels here), so it lies
// at most 3/255 below the mean of the level-0 texels computed here, never above by more than
// rounding.
TEST(PtexReader, ConstantBlockIsTheMeanOfTheTexels) {
    for (const KnownFile& k : kFiles) {
        SCOPED_TRACE(k.path);
        const ptex::Info info = ptex::Summarize(Load(k.path));
        for (const ptex::FaceSummary& s : info.faces)
            for (size_t c = 0; c < s.mean.size(); ++c) {
                EXPECT_LE(s.mean[c] - s.constValue[c], 3.0f / 255.0f);
                EXPECT_GE(s.mean[c] - s.constValue[c], -0.6f / 255.0f);
            }
    }
    // evblur's faces are all constant: two white faces (the grey patch of its preview, blurred)
    // on black.
    const ptex::Info ev = ptex::Summarize(Load("nonquad/evblur/pPlane1.ptx"));
    int white = 0;
    for (const ptex::FaceSummary& s : ev.faces) {
        EXPECT_TRUE(s.info.constant);
        EXPECT_TRUE(s.mean[0] == 0.0f || s.mean[0] == 1.0f);
        white += s.mean[0] == 1.0f && s.mean[1] == 1.0f && s.mean[2] == 1.0f;
    }
    EXPECT_EQ(white, 2);
}

// cellnoise.ptx and pPyramid1.ptx are the same cell colours on the flat sphere at different
// resolutions (cellnoise: 16 to 256 texels a side; pPyramid1: 64 to 512, tiled), so a face's
// colours agree. Each cell covers a large part of a face, so the face means agree closely
// (measured: median 0.0005, 90th percentile 0.002, worst 0.03, where a cell border is a
// larger share of a small face's texels) and texels at the same (u, v) agree on most of it.
TEST(PtexReader, FlatSphereTexturesAgreeAcrossResolutions) {
    const Texture& a = Load("flatsphere/cellnoise.ptx");
    const Texture& b = Load("flatsphere/pPyramid1.ptx");
    const ptex::Info ia = ptex::Summarize(a), ib = ptex::Summarize(b);
    std::vector<float> diffs;
    long same = 0, total = 0;
    std::mt19937 gen(7);
    std::uniform_real_distribution<float> U(0.0f, 1.0f);
    float pa[3], pb[3];
    for (int f = 0; f < a.NumFaces(); ++f) {
        float d = 0;
        for (int c = 0; c < 3; ++c)
            d = std::max(d, std::abs(ia.faces[size_t(f)].mean[size_t(c)] -
                                     ib.faces[size_t(f)].mean[size_t(c)]));
        diffs.push_back(d);
        for (int i = 0; i < 20; ++i, ++total) {
            const float u = U(gen), v = U(gen);
            const ptex::Res ra = a.LevelRes(f, 0), rb = b.LevelRes(f, 0);
            a.Texel(f, 0, int(u * float(ra.U())), int(v * float(ra.V())), pa);
            b.Texel(f, 0, int(u * float(rb.U())), int(v * float(rb.V())), pb);
            same +=
                std::abs(pa[0] - pb[0]) + std::abs(pa[1] - pb[1]) + std::abs(pa[2] - pb[2]) < 0.05f;
        }
    }
    std::sort(diffs.begin(), diffs.end());
    EXPECT_LT(diffs[diffs.size() * 9 / 10], 0.005f);
    EXPECT_LT(diffs.back(), 0.05f);
    EXPECT_GT(double(same) / double(total), 0.9);
    // Per-face colour: neighbouring faces differ (the preview's patchwork).
    int differ = 0;
    for (int f = 0; f < a.NumFaces(); ++f) {
        const int n = a.Face(f).adjFaces[1];
        if (n < 0) continue;
        float d = 0;
        for (int c = 0; c < 3; ++c)
            d +=
                std::abs(ia.faces[size_t(f)].mean[size_t(c)] - ia.faces[size_t(n)].mean[size_t(c)]);
        differ += d > 0.05f;
    }
    EXPECT_GT(differ, a.NumFaces() / 2);
}

/// Fractions of a face set's level-0 texels by a predicate.
template <class Pred>
double Fraction(const Texture& t, Pred pred) {
    std::vector<float> p(size_t(t.NumChannels()));
    long n = 0, hit = 0;
    for (int f = 0; f < t.NumFaces(); ++f) {
        const ptex::Res r = t.LevelRes(f, 0);
        for (int y = 0; y < r.V(); ++y)
            for (int x = 0; x < r.U(); ++x, ++n) {
                t.Texel(f, 0, x, y, p.data());
                hit += pred(p.data());
            }
    }
    return double(hit) / double(n);
}

// The cube's text: dark glyphs on white paper. Thresholds from the decoded data (76% of
// texels above 0.9, 9% below 0.2), with margin.
TEST(PtexReader, CubeHoldsDarkTextOnWhite) {
    const Texture& t = Load("cube/text/cube.ptx");
    EXPECT_GT(Fraction(t, [](const float* p) { return p[0] > 0.9f; }), 0.65);
    EXPECT_GT(Fraction(t, [](const float* p) { return p[0] < 0.2f; }), 0.04);
    // Every face has text on it.
    const ptex::Info info = ptex::Summarize(t);
    for (const ptex::FaceSummary& s : info.faces) {
        EXPECT_GT(s.mean[0], 0.6f);
        EXPECT_LT(s.mean[0], 0.95f);
    }
}

// The non-quad plane's stripes: soft red, green and blue lines on black (measured: 46% of the
// texels below 0.1 in every channel, 14% with a channel above 0.9).
TEST(PtexReader, NonQuadPlaneHoldsColouredStripesOnBlack) {
    for (const char* path : {"nonquad/test/pPlane1Unsub.ptx", "nonquad/test/pPlane1.ptx"}) {
        SCOPED_TRACE(path);
        const Texture& t = Load(path);
        EXPECT_GT(Fraction(t,
                           [](const float* p) {
                               return std::max({p[0], p[1], p[2]}) < 0.1f;
                           }),
                  0.4);
        EXPECT_GT(Fraction(t,
                           [](const float* p) {
                               return std::max({p[0], p[1], p[2]}) > 0.9f;
                           }),
                  0.1);
        for (int c = 0; c < 3; ++c)
            EXPECT_GT(Fraction(t,
                               [c](const float* p) {
                                   return p[c] > 0.7f && p[(c + 1) % 3] < 0.3f &&
                                          p[(c + 2) % 3] < 0.3f;
                               }),
                      0.005)
                << "channel " << c;
    }
}

// Face ids and adjacency: the files' against the project's topology of their meshes (one quad
// per Ptex face, an n-gon as n sub-faces in order). They agree on all four sets.
//
// Which wins when they disagree: the file's adjacency, inside the reader. Its texels were
// painted and its borders filtered against that adjacency, its sub-face resolutions follow it,
// and a texture must filter the same on any renderer; the reader has no mesh anyway. A
// disagreement means the texture belongs to another mesh: a face count that differs from the
// mesh's is an error for whoever binds the texture to the mesh.
TEST(PtexReader, FaceIdsAndAdjacencyMatchTheCageTopology) {
    const std::pair<const char*, const char*> sets[] = {
        {"cube/text/cube.ptx", "cube/cube.obj"},
        {"flatsphere/cellnoise.ptx", "flatsphere/ptex_test_object.obj"},
        {"nonquad/test/pPlane1.ptx", "nonquad/tritestsub.obj"},
        {"nonquad/test/pPlane1Unsub.ptx", "nonquad/tritest.obj"},
    };
    for (const auto& [ptx, obj] : sets) {
        SCOPED_TRACE(ptx);
        std::vector<std::string> warnings;
        const ControlCage cage = LoadObj(test::PtexPath(obj), &warnings);
        const PtexTopology topo(cage);
        const Texture& t = Load(ptx);
        ASSERT_EQ(topo.NumPtexFaces(), t.NumFaces());
        int mismatches = 0;
        for (int f = 0; f < t.NumFaces(); ++f) {
            const ptex::FaceInfo& fi = t.Face(f);
            EXPECT_EQ(fi.subface, !topo.IsQuad(topo.CoarseFace(f))) << "face " << f;
            for (int e = 0; e < 4; ++e) {
                const std::array<int, 2> n = test::FileNeighbour(topo, f, e);
                const bool same =
                    n[0] == fi.adjFaces[size_t(e)] && (n[0] < 0 || n[1] == fi.adjEdges[size_t(e)]);
                mismatches += !same;
                EXPECT_TRUE(same) << "face " << f << " edge " << e << ": file "
                                  << fi.adjFaces[size_t(e)] << "/" << int(fi.adjEdges[size_t(e)])
                                  << ", topology " << n[0] << "/" << n[1];
                if (mismatches > 5) return;
            }
        }
    }
}

// At a texel centre of level 0 with no filter width the lookup is that texel (bilinear weights
// 1, 0, 0, 0), tiled or not.
TEST(PtexReader, LookupAtTexelCentresIsTheTexel) {
    std::mt19937 gen(3);
    for (const char* path : {"cube/text/cube.ptx", "flatsphere/cellnoise.ptx"}) {
        const Texture& t = Load(path);
        std::uniform_int_distribution<int> F(0, t.NumFaces() - 1);
        std::vector<float> a(size_t(t.NumChannels())), b(size_t(t.NumChannels()));
        for (int i = 0; i < 2000; ++i) {
            const int f = F(gen);
            const ptex::Res r = t.LevelRes(f, 0);
            const int s = std::uniform_int_distribution<int>(0, r.U() - 1)(gen);
            const int tt = std::uniform_int_distribution<int>(0, r.V() - 1)(gen);
            t.Texel(f, 0, s, tt, a.data());
            t.Lookup(f, (float(s) + 0.5f) / float(r.U()), (float(tt) + 0.5f) / float(r.V()), 0.0f,
                     b.data());
            for (size_t c = 0; c < a.size(); ++c) ASSERT_NEAR(a[c], b[c], 1e-5f);
        }
    }
}

// Filtering across edges on real data, including quad / n-gon sub-face edges: a point on a
// shared edge looked up from either face blends the same texels (the two faces' texel rows at
// the edge), so the values agree. Tolerance: the stripes are sharp (a texel's step is up to
// 1.0); along the edge each side interpolates its own texel grid, which match here, so the
// difference stays within 3% of that (measured: 1%).
TEST(PtexReader, LookupsAgreeAcrossEveryEdge) {
    const Texture& t = Load("nonquad/test/pPlane1Unsub.ptx");
    float a[3], b[3], worst = 0;
    int edges = 0;
    for (int f = 0; f < t.NumFaces(); ++f)
        for (int e = 0; e < 4; ++e) {
            const ptex::FaceInfo& fi = t.Face(f);
            const int n = fi.adjFaces[size_t(e)];
            if (n < 0) continue;
            if (fi.subface != t.Face(n).subface && !fi.subface) continue;  // seen from the sub-face
            ++edges;
            for (int i = 1; i < 20; ++i) {
                // Our point just inside the edge, and the same point just inside the neighbour.
                const float along = float(i) / 20.0f, eps = 1e-4f;
                float u, v, nu, nv;
                EdgeToUv(e, along, eps, &u, &v);
                test::AcrossEdge(t, f, e, along, eps, &nu, &nv);
                t.Lookup(f, u, v, 0.0f, a);
                t.Lookup(n, nu, nv, 0.0f, b);
                for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(a[c] - b[c]));
            }
        }
    EXPECT_GT(edges, 20);
    EXPECT_LT(worst, 0.03f);
}

}  // namespace
}  // namespace texcache
