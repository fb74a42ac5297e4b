// SPDX-License-Identifier: Apache-2.0
// `texcache ptex info` and `texcache bake` end to end, and bad Ptex files through the program:
// truncated, lying about a count, a zlib stream that expands without bound, a face count that
// does not match the mesh. Each exits 2 with one line naming the file and replaces no output.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_run.h"
#include "ptex_bytes.h"
#include "ptex_test_util.h"
#include "renderer/image/image.h"
#include "texcache/ptex/info.h"
#include "texcache/ptex/texture.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

using test::CliRun;
using test::Texcache;

fs::path Dir() {
    return test::CliTempDir("texcache_ptex_cli");
}

std::vector<uint8_t> Bytes(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(f), {}};
}

std::string WriteBytes(const std::string& name, const std::vector<uint8_t>& b) {
    const fs::path p = Dir() / name;
    std::ofstream(p, std::ios::binary)
        .write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
    return p.string();
}

/// Exit code 2 and exactly one line besides warnings (the Ptex sets' OBJs hold statements the
/// loader skips with one), naming `file` and holding `part`.
void ExpectOneLineError(const CliRun& r, const std::string& file, const std::string& part) {
    EXPECT_EQ(r.code, 2) << r.out;
    std::istringstream lines(r.out);
    int other = 0;
    for (std::string line; std::getline(lines, line);)
        other += line.rfind("texcache: warning: ", 0) != 0;
    EXPECT_EQ(other, 1) << r.out;
    EXPECT_NE(r.out.find(file), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(part), std::string::npos) << r.out;
}

const char* const kBundled[] = {
    "cube/text/cube.ptx",       "flatsphere/cellnoise.ptx",      "flatsphere/pPyramid1.ptx",
    "nonquad/test/pPlane1.ptx", "nonquad/test/pPlane1Unsub.ptx", "nonquad/evblur/pPlane1.ptx"};

// --json holds the header and every face, each with the mean of its decoded level-0 texels.
TEST(PtexCli, InfoJsonHoldsEveryFaceWithItsMean) {
    for (const char* rel : kBundled) {
        SCOPED_TRACE(rel);
        const std::string path = test::PtexPath(rel);
        const CliRun r = Texcache("ptex info --json " + path);
        ASSERT_EQ(r.code, 0) << r.out;
        const nlohmann::json j = nlohmann::json::parse(r.out);
        const ptex::Texture t = ptex::Texture::Open(path);
        EXPECT_EQ(j["header"]["faces"], t.NumFaces());
        EXPECT_EQ(j["border"]["u"], ptex::Name(t.GetHeader().uBorder));
        ASSERT_EQ(j["faces"].size(), size_t(t.NumFaces()));
        std::vector<float> mean(size_t(t.NumChannels()));
        for (int f = 0; f < t.NumFaces(); f += 7) {
            const nlohmann::json& face = j["faces"][size_t(f)];
            t.Mean(f, 0, mean.data());
            ASSERT_EQ(face["mean"].size(), mean.size());
            for (size_t c = 0; c < mean.size(); ++c)
                EXPECT_NEAR(face["mean"][c].get<float>(), mean[c], 1e-6f);
            EXPECT_EQ(face["adjfaces"][1], t.Face(f).adjFaces[1]);
            EXPECT_EQ(face["constant"], t.Face(f).constant);
        }
    }
    const CliRun text =
        Texcache("ptex info --faces " + test::PtexPath("nonquad/test/pPlane1Unsub.ptx"));
    ASSERT_EQ(text.code, 0) << text.out;
    EXPECT_NE(text.out.find("border modes:  u clamp, v clamp"), std::string::npos) << text.out;
    EXPECT_NE(text.out.find("face 5: 64x64 subface"), std::string::npos) << text.out;
}

// --face N --level L -o writes the face's texels, v = 0 at the bottom row.
TEST(PtexCli, InfoWritesAFaceAsAnImage) {
    const std::string path = test::PtexPath("flatsphere/cellnoise.ptx");
    const fs::path out = Dir() / "face.exr";
    const CliRun r = Texcache("ptex info " + path + " --face 10 --level 1 -o " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    const Image img = ReadImage(out.string());
    const ptex::Texture t = ptex::Texture::Open(path);
    const ptex::Res res = t.LevelRes(10, 1);
    ASSERT_EQ(img.width, res.U());
    ASSERT_EQ(img.height, res.V());
    ASSERT_EQ(img.channels, 3);
    float px[3];
    for (int v = 0; v < res.V(); v += 3)
        for (int u = 0; u < res.U(); u += 5) {
            t.Texel(10, 1, u, v, px);
            for (int c = 0; c < 3; ++c) EXPECT_EQ(img.At(u, res.V() - 1 - v)[c], px[c]);
        }
}

// Every way of asking for what the file does not have, or a bad command line, exits 2 naming it.
TEST(PtexCli, InfoRejectsBadRequests) {
    const std::string path = test::PtexPath("nonquad/test/pPlane1Unsub.ptx");
    const fs::path out = Dir() / "kept.exr";
    std::ofstream(out) << "keep me";
    ExpectOneLineError(Texcache("ptex info " + path + " --face 21 -o " + out.string()), path,
                       "face 21: the file has 21 faces");
    ExpectOneLineError(Texcache("ptex info " + path + " --face 5 --level 9 -o " + out.string()),
                       path, "face 5 has levels 0 to 4, not 9");
    ExpectOneLineError(Texcache("ptex info " + path + " --face 5"), "--face", "needs -o");
    ExpectOneLineError(Texcache("ptex info " + path + " --level 1"), "--level", "needs --face");
    ExpectOneLineError(Texcache("ptex info " + path + " --face 1 -o " + path), path,
                       "cannot write image");
    ExpectOneLineError(Texcache("ptex info " + (Dir() / "missing.ptx").string()), "missing.ptx",
                       "");
    EXPECT_EQ(Bytes(out.string()).size(), 7u);  // "keep me", untouched
}

// Bad files through the program: one line naming the file and what is wrong, exit 2, and an
// output the command would write left as it was.
TEST(PtexCli, BadFilesExitTwoWithOneLine) {
    const std::vector<uint8_t> good = Bytes(test::PtexPath("nonquad/test/pPlane1Unsub.ptx"));
    const fs::path out = Dir() / "kept_face.exr";
    std::ofstream(out) << "keep me";

    std::vector<uint8_t> truncated(good.begin(), good.begin() + long(good.size() / 2));
    const std::string t = WriteBytes("truncated.ptx", truncated);
    ExpectOneLineError(Texcache("ptex info " + t), t, "truncated");
    ExpectOneLineError(Texcache("ptex info " + t + " --face 0 -o " + out.string()), t, "truncated");

    test::PtexBytes lying(good);
    lying.Set32(test::PtexBytes::kNumFaces, 0x7fffffff);  // two billion faces in 300 KB
    const std::string l = WriteBytes("lying.ptx", lying.b);
    ExpectOneLineError(Texcache("ptex info " + l), l, "face info");

    // A face of 1024x1024 bytes whose data is 256 MB of zeros in a quarter MB of zlib.
    const test::PtexBytes bomb = test::ZlibBombFile(256);
    const std::string b = WriteBytes("bomb.ptx", bomb.b);
    ExpectOneLineError(Texcache("ptex info --json " + b), b, "expands past");

    const std::string n = WriteBytes("notptex.ptx", {'P', 'N', 'G', 0, 1, 2});
    ExpectOneLineError(Texcache("ptex info " + n), n, "not a Ptex file");
    EXPECT_EQ(Bytes(out.string()).size(), 7u);
}

/// A scene of one Ptex set's mesh whose albedo reads `ptx`.
std::string PtexScene(const std::string& name, const std::string& obj, const std::string& ptx) {
    const fs::path p = Dir() / name;
    std::ofstream(p) << R"({"materials": {"m": {"albedo": {"ptex": ")" << ptx << R"("}}},
      "objects": [{"name": "thing", "mesh": ")"
                     << test::PtexPath(obj) << R"(", "material": "m"}],
      "lights": [{"type": "environment", "constant": [1, 1, 1]}],
      "render": {"resolution": [48, 32], "spp": 1}})";
    return p.string();
}

// A render whose texture is bad, or painted for another mesh, stops before anything is written.
TEST(PtexCli, RenderRefusesBadAndMismatchedTextures) {
    const fs::path out = Dir() / "render.exr";
    std::ofstream(out) << "keep me";
    const std::string mismatch = PtexScene("mismatch.json", "nonquad/tritest.obj",
                                           test::PtexPath("nonquad/test/pPlane1.ptx"));
    ExpectOneLineError(Texcache("render " + mismatch + " -q -o " + out.string()), "pPlane1.ptx",
                       "has 66 faces, but object 'thing'");
    const CliRun r = Texcache("render " + mismatch + " -q -o " + out.string());
    EXPECT_NE(r.out.find("has 21 Ptex faces"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("key 'materials.m.albedo.ptex'"), std::string::npos) << r.out;

    std::vector<uint8_t> good = Bytes(test::PtexPath("nonquad/test/pPlane1Unsub.ptx"));
    good.resize(good.size() - 1000);
    const std::string cut = WriteBytes("cut.ptx", good);
    ExpectOneLineError(Texcache("render " + PtexScene("cut.json", "nonquad/tritest.obj", cut) +
                                " -q -o " + out.string()),
                       cut, "truncated");
    EXPECT_EQ(Bytes(out.string()).size(), 7u);
}

// `texcache bake` writes a Ptex file per object that `ptex info` reads, with the mesh's faces;
// a bad setting exits 2 and writes nothing.
TEST(PtexCli, BakeWritesFilesPtexInfoReads) {
    const fs::path dir = Dir() / "baked";
    fs::remove_all(dir);
    const std::string scene =
        PtexScene("bake.json", "cube/cube.obj", test::PtexPath("cube/text/cube.ptx"));
    CliRun r = Texcache("bake " + scene + " --out " + dir.string() + " --resolution 8 --samples 8");
    ASSERT_EQ(r.code, 0) << r.out;
    const fs::path baked = dir / "thing.ptx";
    ASSERT_TRUE(fs::exists(baked)) << r.out;
    r = Texcache("ptex info --json " + baked.string());
    ASSERT_EQ(r.code, 0) << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["header"]["faces"], 72);
    EXPECT_EQ(j["header"]["data_type"], "half");
    EXPECT_GT(j["header"]["levels"], 1);
    // AO: the tunnels through the cube darker than its outer faces.
    float lo = 1.0f, hi = 0.0f;
    for (const auto& f : j["faces"]) {
        lo = std::min(lo, f["mean"][0].get<float>());
        hi = std::max(hi, f["mean"][0].get<float>());
    }
    EXPECT_GE(lo, 0.0f);
    EXPECT_LT(lo, 0.7f);
    EXPECT_GT(hi, 0.9f);
    EXPECT_LE(hi, 1.0f);

    const auto before = fs::last_write_time(baked);
    ExpectOneLineError(Texcache("bake " + scene + " --out " + dir.string() + " --resolution 12"),
                       "--resolution", "power of two");
    ExpectOneLineError(
        Texcache("bake " + scene + " --out " + dir.string() + " --integrator normal"),
        "--integrator", "bakes ao, direct or path");
    EXPECT_EQ(fs::last_write_time(baked), before);
}

}  // namespace
}  // namespace texcache
