// SPDX-License-Identifier: Apache-2.0
// The Ptex writer and the reader's lookups on files written here: a round trip per data type
// (texels, constant faces, tiles, mip levels, alpha, meta data, header fields), reductions the
// reader makes against the writer's, and filtered lookups with known answers (continuity
// across the edges of real cages, mip selection, border modes, tangent vectors, triangles).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>

#include "ptex_test_util.h"
#include "texcache/ptex/info.h"
#include "texcache/ptex/texture.h"
#include "texcache/ptex/writer.h"

namespace texcache {
namespace {

using ptex::DataType;
using ptex::FaceInfo;
using ptex::Res;
using ptex::Texture;
using ptex::WriteOptions;

/// Faces to write, owning their texels.
struct FaceSet {
    std::vector<FaceInfo> infos;
    std::vector<std::vector<float>> texels;

    std::vector<ptex::FaceTexels> View() const {
        std::vector<ptex::FaceTexels> v(infos.size());
        for (size_t f = 0; f < infos.size(); ++f) v[f] = {infos[f], texels[f]};
        return v;
    }
};

/// One face of `res` holding `texels`.
FaceSet OneFace(Res res, std::vector<float> texels) {
    FaceSet s;
    s.infos.resize(1);
    s.infos[0].res = res;
    s.texels = {std::move(texels)};
    return s;
}

/// Float texels of `nchan` channels.
WriteOptions FloatOptions(int nchan) {
    WriteOptions o;
    o.dataType = DataType::Float;
    o.numChannels = nchan;
    return o;
}

Texture Decode(const WriteOptions& o, const FaceSet& faces, const std::string& name = "mem.ptx") {
    return Texture::FromBytes(ptex::EncodeTexture(o, faces.View()), name);
}

/// Random faces: resolutions 1 to 128 texels a side, random adjacency, every fifth constant.
FaceSet RandomFaces(int n, int nchan, float lo, float hi, std::mt19937& gen) {
    FaceSet s;
    std::uniform_int_distribution<int> R(0, 7), F(-1, n - 1), E(0, 3);
    std::uniform_real_distribution<float> V(lo, hi);
    for (int f = 0; f < n; ++f) {
        FaceInfo fi;
        fi.res = {int8_t(R(gen)), int8_t(R(gen))};
        fi.subface = f % 3 == 0;
        for (int e = 0; e < 4; ++e)
            fi.adjFaces[size_t(e)] = F(gen), fi.adjEdges[size_t(e)] = uint8_t(E(gen));
        std::vector<float> t(size_t(fi.res.U()) * size_t(fi.res.V()) * size_t(nchan));
        if (f % 5 == 4) {
            std::vector<float> px(static_cast<size_t>(nchan));
            for (float& x : px) x = V(gen);
            for (size_t i = 0; i < t.size(); ++i) t[i] = px[i % size_t(nchan)];
        } else {
            for (float& x : t) x = V(gen);
        }
        s.infos.push_back(fi);
        s.texels.push_back(std::move(t));
    }
    return s;
}

/// What a stored value can differ from the float written: half a quantum for integers, half an
/// ulp of a half's 11-bit significand, nothing for floats.
float Tolerance(DataType t, float x) {
    switch (t) {
        case DataType::UInt8:
            return 0.5f / 255.0f + 1e-6f;
        case DataType::UInt16:
            return 0.5f / 65535.0f + 1e-7f;
        case DataType::Half:
            return std::abs(x) * 0.000489f + 3e-8f;
        default:
            return 0.0f;
    }
}

class PtexRoundTrip : public ::testing::TestWithParam<DataType> {};

TEST_P(PtexRoundTrip, TexelsFacesAndMetaDataComeBack) {
    const DataType type = GetParam();
    const bool integer = type == DataType::UInt8 || type == DataType::UInt16;
    std::mt19937 gen(11 + int(type));
    const int nchan = 4;
    const FaceSet faces =
        RandomFaces(24, nchan, integer ? 0.0f : -2.0f, integer ? 1.0f : 2.0f, gen);
    WriteOptions o;
    o.dataType = type;
    o.numChannels = nchan;
    o.alphaChannel = -1;
    o.uBorder = ptex::BorderMode::Periodic;
    o.vBorder = ptex::BorderMode::Black;
    o.edgeFilter = ptex::EdgeFilterMode::TangentVector;
    o.tileBytes = 512;  // tiles in the larger faces and reductions
    std::vector<double> big(400);
    for (size_t i = 0; i < big.size(); ++i) big[i] = double(i) * 3 - 500;
    o.meta = {{"PtexFaceVertCounts", ptex::MetaType::Int32, "", {4, 4, 3}},
              {"name", ptex::MetaType::String, "baked ambient occlusion", {}},
              {"scale", ptex::MetaType::Double, "", {0.125, -1e300}},
              {"bytes", ptex::MetaType::Int8, "", {-128, 127, 0}},
              {"shorts", ptex::MetaType::Int16, "", {-32768, 32767}},
              {"weights", ptex::MetaType::Float, "", {0.5, 2.25}},
              {"large", ptex::MetaType::Int32, "", big}};  // 1600 bytes: its own block
    const Texture t = Decode(o, faces);

    const ptex::Header& h = t.GetHeader();
    EXPECT_EQ(h.dataType, type);
    EXPECT_EQ(h.numChannels, nchan);
    EXPECT_EQ(h.numFaces, 24);
    EXPECT_EQ(h.uBorder, ptex::BorderMode::Periodic);
    EXPECT_EQ(h.vBorder, ptex::BorderMode::Black);
    EXPECT_EQ(h.edgeFilter, ptex::EdgeFilterMode::TangentVector);
    int maxReductions = 0;  // down to 4 texels on the shorter side of non-constant faces
    for (int f = 0; f < 24; ++f)
        if (f % 5 != 4)
            maxReductions = std::max(
                maxReductions,
                std::min(faces.infos[size_t(f)].res.ulog2, faces.infos[size_t(f)].res.vlog2) - 2);
    EXPECT_EQ(h.numLevels, 1 + maxReductions);
    ASSERT_EQ(t.MetaData().size(), o.meta.size());
    for (const ptex::MetaEntry& m : o.meta) {
        const ptex::MetaEntry* r = t.Meta(m.key);
        ASSERT_NE(r, nullptr) << m.key;
        EXPECT_EQ(r->type, m.type);
        EXPECT_EQ(r->text, m.text);
        EXPECT_EQ(r->numbers, m.numbers) << m.key;
    }

    std::vector<float> px(static_cast<size_t>(nchan));
    int constants = 0;
    for (int f = 0; f < 24; ++f) {
        const FaceInfo& in = faces.infos[size_t(f)];
        const FaceInfo& out = t.Face(f);
        EXPECT_EQ(out.res, in.res);
        EXPECT_EQ(out.adjFaces, in.adjFaces);
        EXPECT_EQ(out.adjEdges, in.adjEdges);
        EXPECT_EQ(out.subface, in.subface);
        EXPECT_EQ(out.constant, f % 5 == 4 || in.res == Res{}) << f;
        constants += out.constant;
        const ptex::Res r = t.LevelRes(f, 0);
        ASSERT_EQ(r, in.res);
        for (int y = 0; y < r.V(); ++y)
            for (int x = 0; x < r.U(); ++x) {
                t.Texel(f, 0, x, y, px.data());
                for (int c = 0; c < nchan; ++c) {
                    const float want =
                        faces.texels[size_t(f)]
                                    [(size_t(y) * size_t(r.U()) + size_t(x)) * 4 + size_t(c)];
                    ASSERT_NEAR(px[size_t(c)], want, Tolerance(type, want))
                        << "face " << f << " texel " << x << "," << y;
                }
            }
        // Mip levels: every face the writer reduces down to 4 texels on the shorter side.
        const int natural =
            out.constant ? 0 : std::max(0, std::min(in.res.ulog2, in.res.vlog2) - 2);
        EXPECT_EQ(t.NumLevels(f), 1 + natural) << f;
        for (int lv = 0; lv < t.NumLevels(f); ++lv) EXPECT_TRUE(t.LevelStored(f, lv));
    }
    EXPECT_GE(constants, 4);
}

INSTANTIATE_TEST_SUITE_P(Types, PtexRoundTrip,
                         ::testing::Values(DataType::UInt8, DataType::UInt16, DataType::Half,
                                           DataType::Float),
                         [](const auto& info) { return std::string(ptex::Name(info.param)); });

// The reader reduces the levels a file lacks as the writer does (2x2 boxes, colour
// premultiplied by alpha): the same faces written without mip maps come back with levels equal
// to the stored ones, within one quantum (each side rounds once per level from floats it
// reduced differently: the writer from floats, the reader from stored values).
TEST(PtexWriter, ReaderReductionsMatchStoredOnes) {
    for (const DataType type : {DataType::UInt8, DataType::Half, DataType::Float}) {
        SCOPED_TRACE(ptex::Name(type));
        std::mt19937 gen(5);
        const FaceSet faces = RandomFaces(12, 3, 0.0f, 1.0f, gen);
        WriteOptions o;
        o.dataType = type;
        o.alphaChannel = 2;
        const Texture stored = Decode(o, faces);
        o.mipmaps = false;
        const Texture made = Decode(o, faces);
        EXPECT_EQ(made.GetHeader().numLevels, 1);
        float a[3], b[3];
        const float quantum = type == DataType::UInt8  ? 1.01f / 255.0f
                              : type == DataType::Half ? 2e-3f
                                                       : 1e-5f;
        for (int f = 0; f < 12; ++f) {
            ASSERT_EQ(made.NumLevels(f), stored.NumLevels(f));
            for (int lv = 1; lv < made.NumLevels(f); ++lv) {
                EXPECT_FALSE(made.LevelStored(f, lv));
                const Res r = made.LevelRes(f, lv);
                for (int y = 0; y < r.V(); ++y)
                    for (int x = 0; x < r.U(); ++x) {
                        stored.Texel(f, lv, x, y, a);
                        made.Texel(f, lv, x, y, b);
                        for (int c = 0; c < 3; ++c) ASSERT_NEAR(a[c], b[c], quantum * float(lv));
                    }
            }
        }
    }
}

TEST(PtexWriter, WritesThroughATemporaryFile) {
    std::mt19937 gen(1);
    const FaceSet faces = RandomFaces(5, 3, 0.0f, 1.0f, gen);
    const std::string dir = ::testing::TempDir() + "ptex_writer";
    std::filesystem::create_directories(dir);
    const std::string path = dir + "/out.ptx";
    WriteOptions o;
    ptex::WriteTexture(path, o, faces.View());
    ptex::WriteTexture(path, o, faces.View());  // over an existing file
    const Texture t = Texture::Open(path);
    EXPECT_EQ(t.NumFaces(), 5);
    EXPECT_EQ(t.FileBytes(), std::filesystem::file_size(path));
    int files = 0;
    for (const auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file();
    EXPECT_EQ(files, 1);  // no temporary left behind
    // Inconsistent input is refused before anything is written.
    FaceSet bad = faces;
    bad.texels[2].pop_back();
    EXPECT_THROW(ptex::EncodeTexture(o, bad.View()), std::invalid_argument);
}

/// A float texture whose texels hold the cage point at their centre (the bilinear face, or the
/// n-gon's sub-face quad), with the topology's adjacency or (`alone`) none.
Texture PositionTexture(const ControlCage& cage, const PtexTopology& topo, bool alone) {
    FaceSet faces;
    faces.infos = test::PtexFaces(topo, Res{4, 4}, Res{3, 3});
    for (int f = 0; f < topo.NumPtexFaces(); ++f) {
        const Res r = faces.infos[size_t(f)].res;
        std::vector<float> t;
        for (int y = 0; y < r.V(); ++y)
            for (int x = 0; x < r.U(); ++x) {
                const auto p = test::CagePoint(cage, topo, f, (float(x) + 0.5f) / float(r.U()),
                                               (float(y) + 0.5f) / float(r.V()));
                t.insert(t.end(), p.begin(), p.end());
            }
        faces.texels.push_back(std::move(t));
        if (alone) faces.infos[size_t(f)].adjFaces = {-1, -1, -1, -1};
    }
    return Decode(FloatOptions(3), faces);
}

float Distance(const float* a, const std::array<float, 3>& b) {
    return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                     (a[2] - b[2]) * (a[2] - b[2]));
}

// Filtering across edges, on textures of a smooth field (each texel the surface point at its
// centre), on the three bundled cages: rotated face frames (the cube), n-gon sub-faces next to
// quads and to each other (the non-quad plane), many faces (the flat sphere). At a point on an
// edge, both faces' lookups blend the same texels (their rows along the edge, the sub-faces'
// grids as dense as the quads'), so they agree; without adjacency each side clamps to its own
// row and they differ by about a texel step. On edges between coplanar faces of the cube, the
// lookup also lands on the field's value, where clamping misses by half a step. (Across a fold
// or between differently skewed faces no filter in parameter space reproduces a 3D field, so
// the accuracy check keeps to flat, regular pairs.)
TEST(PtexLookup, IsContinuousAcrossTheEdgesOfRealCages) {
    for (const char* mesh :
         {"cube/cube.obj", "nonquad/tritest.obj", "flatsphere/ptex_test_object.obj"}) {
        SCOPED_TRACE(mesh);
        std::vector<std::string> warnings;
        const ControlCage cage = LoadObj(test::PtexPath(mesh), &warnings);
        const PtexTopology topo(cage);
        const Texture joined = PositionTexture(cage, topo, false);
        const Texture clamped = PositionTexture(cage, topo, true);
        const bool cube = std::string(mesh) == "cube/cube.obj";
        double gapJoined = 0, gapClamped = 0, errJoined = 0, errClamped = 0, step = 0;
        int n = 0, flat = 0;
        for (int f = 0; f < topo.NumPtexFaces(); ++f)
            for (int e = 0; e < 4; ++e) {
                const ptex::FaceInfo& fi = joined.Face(f);
                const int nb = fi.adjFaces[size_t(e)];
                if (nb < 0) continue;
                const int ne = fi.adjEdges[size_t(e)];
                if (fi.subface != joined.Face(nb).subface && !fi.subface)
                    continue;  // sub-face side
                // Coplanar neighbours: the point a texel inside each, mirrored across the edge.
                float u, v, nu, nv;
                EdgeToUv(e, 0.5f, 0.25f, &u, &v);
                EdgeToUv(ne, 0.5f, 0.25f, &nu, &nv);
                const auto mid = test::CagePoint(cage, topo, f, u, v);
                const auto nmid = test::CagePoint(cage, topo, nb, nu, nv);
                EdgeToUv(e, 0.5f, 0.0f, &u, &v);
                const auto on = test::CagePoint(cage, topo, f, u, v);
                float m[3] = {0.5f * (mid[0] + nmid[0]), 0.5f * (mid[1] + nmid[1]),
                              0.5f * (mid[2] + nmid[2])};
                const bool coplanar = cube && Distance(m, on) < 1e-4f;
                flat += coplanar;
                for (int i = 0; i < 16; ++i, ++n) {
                    const float along = (float(i) + 0.5f) / 16.0f;
                    EdgeToUv(e, along, 0.0f, &u, &v);
                    test::AcrossEdge(joined, f, e, along, 0.0f, &nu, &nv);
                    const auto want = test::CagePoint(cage, topo, f, u, v);
                    EdgeToUv(e, along, 1.0f / 16, &u, &v);  // a texel inside: the step
                    step += Distance(&test::CagePoint(cage, topo, f, u, v)[0], want);
                    EdgeToUv(e, along, 0.0f, &u, &v);
                    float a[3], b[3], c[3], d[3];
                    joined.Lookup(f, u, v, 0.0f, a);
                    joined.Lookup(nb, nu, nv, 0.0f, b);
                    clamped.Lookup(f, u, v, 0.0f, c);
                    clamped.Lookup(nb, nu, nv, 0.0f, d);
                    gapJoined += Distance(a, {b[0], b[1], b[2]});
                    gapClamped += Distance(c, {d[0], d[1], d[2]});
                    if (coplanar) errJoined += Distance(a, want), errClamped += Distance(c, want);
                }
            }
        ASSERT_GT(n, 0);
        step /= n;
        EXPECT_GT(gapClamped / n, 0.5 * step);
        EXPECT_LT(gapJoined / n, 0.02 * step);
        if (cube) {
            ASSERT_GT(flat, 50);
            EXPECT_GT(errClamped, 0.3 * step * flat * 16);
            EXPECT_LT(errJoined, 0.01 * step * flat * 16);
        }
    }
}

// The level follows the filter width: a one-texel checker of 0 and 1 is itself at width 0 or
// one texel, its 0.5 average one level down and at the constant value; a ramp in u is itself
// at every width up to where the constant value takes over.
TEST(PtexLookup, SelectsMipLevelsFromTheFilterWidth) {
    FaceSet s;
    FaceInfo fi;
    fi.res = {6, 6};
    s.infos = {fi, fi};
    std::vector<float> checker, ramp;
    for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) {
            checker.push_back(float((x + y) & 1));
            ramp.push_back((float(x) + 0.5f) / 64.0f);
        }
    s.texels = {checker, ramp};
    const Texture t = Decode(FloatOptions(1), s);
    ASSERT_EQ(t.NumLevels(0), 5);
    float r;
    const float u = 10.5f / 64.0f, v = 20.5f / 64.0f;
    t.Lookup(0, u, v, 0.0f, &r);
    EXPECT_FLOAT_EQ(r, 0.0f);
    t.Lookup(0, u, v, 1.0f / 64.0f, &r);
    EXPECT_FLOAT_EQ(r, 0.0f);
    t.Lookup(0, u, v, 1.0f / 32.0f, &r);
    EXPECT_NEAR(r, 0.5f, 1e-6f);
    t.Lookup(0, u, v, 1.0f / 45.0f, &r);  // between levels 0 and 1
    EXPECT_GT(r, 0.1f);
    EXPECT_LT(r, 0.4f);
    t.Lookup(0, u, v, 1.0f, &r);
    EXPECT_NEAR(r, 0.5f, 1e-6f);
    for (const float width : {0.0f, 1.0f / 64, 1.0f / 20, 1.0f / 8}) {
        for (const float x : {0.3f, 0.5f, 0.7f}) {
            t.Lookup(1, x, 0.4f, width, &r);
            EXPECT_NEAR(r, x, 1e-5f) << "width " << width;
        }
    }
}

// Beyond a face edge with no neighbour: clamp repeats the edge texel, black fades to 0, periodic
// wraps round to the other side of the face. At u = 0 the bilinear taps sit half a texel on
// either side of the edge, weights 1/2.
TEST(PtexLookup, BorderModesApplyAtMeshBorders) {
    std::vector<float> t;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) t.push_back(float(1 + x + 4 * y));
    const FaceSet s = OneFace({2, 2}, t);
    auto at = [&](int x, int y) { return float(1 + x + 4 * y); };
    const float v = 1.5f / 4.0f;  // the centre of row 1
    for (const ptex::BorderMode m :
         {ptex::BorderMode::Clamp, ptex::BorderMode::Black, ptex::BorderMode::Periodic}) {
        SCOPED_TRACE(ptex::Name(m));
        WriteOptions o = FloatOptions(1);
        o.uBorder = o.vBorder = m;
        const Texture tex = Decode(o, s);
        float r;
        tex.Lookup(0, 0.0f, v, 0.0f, &r);
        const float across = m == ptex::BorderMode::Clamp   ? at(0, 1)
                             : m == ptex::BorderMode::Black ? 0.0f
                                                            : at(3, 1);
        EXPECT_FLOAT_EQ(r, 0.5f * (at(0, 1) + across));
        tex.Lookup(0, 0.0f, 0.0f, 0.0f, &r);  // the corner: three taps outside
        const float corner = m == ptex::BorderMode::Clamp ? at(0, 0)
                             : m == ptex::BorderMode::Black
                                 ? 0.25f * at(0, 0)
                                 : 0.25f * (at(0, 0) + at(3, 0) + at(0, 3) + at(3, 3));
        EXPECT_FLOAT_EQ(r, corner);
    }
}

// Tangent vectors: face 1 lies right of face 0 but turned a quarter (its edge 0 on our edge
// 1), so a vector field that is +x everywhere reads (1, 0) in face 0 and (0, 1) in face 1.
// Across the edge, tanvec mode turns the neighbour's values into our frame.
TEST(PtexLookup, TangentVectorsTurnAcrossEdges) {
    FaceSet s;
    FaceInfo a, b;
    a.res = b.res = {2, 2};
    a.adjFaces = {-1, 1, -1, -1}, a.adjEdges = {0, 0, 0, 0};
    b.adjFaces = {0, -1, -1, -1}, b.adjEdges = {1, 0, 0, 0};
    s.infos = {a, b};
    std::vector<float> ta, tb;
    for (int i = 0; i < 16; ++i) {
        ta.insert(ta.end(), {1.0f, 0.0f, float(i)});  // a third channel that is not turned
        tb.insert(tb.end(), {0.0f, 1.0f, float(i)});
    }
    s.texels = {ta, tb};
    WriteOptions o = FloatOptions(3);
    o.edgeFilter = ptex::EdgeFilterMode::TangentVector;
    const Texture t = Decode(o, s);
    float r[3];
    t.Lookup(0, 1.0f, 0.5f, 0.0f, r);
    EXPECT_NEAR(r[0], 1.0f, 1e-6f);
    EXPECT_NEAR(r[1], 0.0f, 1e-6f);
    t.Lookup(1, 0.5f, 0.0f, 0.0f, r);
    EXPECT_NEAR(r[0], 0.0f, 1e-6f);
    EXPECT_NEAR(r[1], 1.0f, 1e-6f);
    o.edgeFilter = ptex::EdgeFilterMode::None;
    Decode(o, s).Lookup(0, 1.0f, 0.5f, 0.0f, r);
    EXPECT_NEAR(r[0], 0.5f, 1e-6f);
    EXPECT_NEAR(r[1], 0.5f, 1e-6f);
    // A channel subset: the third channel alone.
    t.Lookup(0, 0.375f, 0.375f, 0.0f, r, 2, 1);
    EXPECT_NEAR(r[0], 5.0f, 1e-5f);
}

// Triangle textures: Ptex's packed square of triangular texels. Even texel (i, j), i + j < n,
// sits at (i, j); the odd (upside-down) one of the same cell at (n-1-j, n-1-i).
TEST(PtexLookup, TrianglesLookUpTheirTriangularTexels) {
    const int n = 8;
    std::vector<float> t(size_t(n) * size_t(n));
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const bool even = i + j < n;
            const int ci = even ? i : n - 1 - j, cj = even ? j : n - 1 - i;  // the cell
            t[size_t(j) * size_t(n) + size_t(i)] = float(10 * ci + cj) + (even ? 0.0f : 100.0f);
        }
    const FaceSet s = OneFace({3, 3}, t);
    WriteOptions o = FloatOptions(1);
    o.meshType = ptex::MeshType::Triangle;
    const Texture tex = Decode(o, s);
    EXPECT_EQ(tex.GetHeader().meshType, ptex::MeshType::Triangle);
    float r;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i + j < n; ++i) {
            tex.Lookup(0, (float(i) + 0.3f) / n, (float(j) + 0.3f) / n, 0.0f, &r);
            EXPECT_EQ(r, float(10 * i + j));
            if (i + j < n - 1) {
                tex.Lookup(0, (float(i) + 0.7f) / n, (float(j) + 0.7f) / n, 0.0f, &r);
                EXPECT_EQ(r, float(100 + 10 * i + j));
            }
        }
    // Its reduction: the corner's three even texels and the odd one between them.
    ASSERT_EQ(tex.NumLevels(0), 2);
    tex.Texel(0, 1, 0, 0, &r);
    EXPECT_FLOAT_EQ(r, 0.25f * (0 + 10 + 1 + 100));
    o.mipmaps = false;  // the reader's own reduction is the same
    float m;
    Decode(o, s).Texel(0, 1, 0, 0, &m);
    EXPECT_FLOAT_EQ(m, r);
}

// With an alpha channel, levels blend premultiplied colour: a face half transparent white
// (alpha 0) and half opaque grey 0.5 averages to colour 0.25, alpha 0.5 at every level and at
// the constant value (stored straight: 0.5).
TEST(PtexLookup, AlphaBlendsPremultipliedColour) {
    std::vector<float> t;
    for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 16; ++x) t.insert(t.end(), {x < 8 ? 1.0f : 0.5f, x < 8 ? 0.0f : 1.0f});
    const FaceSet s = OneFace({4, 4}, t);
    WriteOptions o = FloatOptions(2);
    o.dataType = DataType::Half;
    o.alphaChannel = 1;
    const Texture tex = Decode(o, s);
    float c[2];
    tex.ConstValue(0, c);
    EXPECT_NEAR(c[0], 0.5f, 1e-3f);
    EXPECT_NEAR(c[1], 0.5f, 1e-3f);
    for (const float width : {1.0f / 4, 1.0f / 2, 1.0f}) {
        float r[2];
        tex.Lookup(0, 0.5f, 0.5f, width, r);
        EXPECT_NEAR(r[0], 0.25f, 2e-3f) << width;
        EXPECT_NEAR(r[1], 0.5f, 2e-3f) << width;
    }
    float r[2];
    tex.Lookup(0, 0.75f, 0.5f, 0.0f, r);  // opaque half at level 0
    EXPECT_NEAR(r[0], 0.5f, 1e-3f);
}

}  // namespace
}  // namespace texcache
