// SPDX-License-Identifier: Apache-2.0
// Seeded mutation fuzzing of the readers of untrusted files: OBJ cages, scene files and the
// screen-space stage's frame-buffer EXRs. Each target mutates the seed files of its
// corpus (tests/fuzz/<target>/) with a fixed seed, a bounded number of times (about a second in
// Release; TEXCACHE_FUZZ_SCALE=N runs N times as many), and requires every input to either load
// into a consistent result or throw InputError: any other exception fails the test, and the
// sanitizer builds (scripts/test.sh) catch memory errors and undefined behaviour on the way. A
// failing input is written to the test's temporary directory and its path printed, to be added
// to the corpus once fixed.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/image/image.h"
#include "renderer/scene/obj_loader.h"
#include "renderer/scene/scene_loader.h"
#include "test_util.h"
#include "texcache/error.h"

namespace texcache {
namespace {

namespace fs = std::filesystem;

std::string Slurp(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

void Spit(const fs::path& p, const std::string& bytes) {
    std::ofstream(p, std::ios::binary | std::ios::trunc) << bytes;
}

fs::path WorkDir(const std::string& target) {
    const fs::path d = fs::path(::testing::TempDir()) / "texcache_fuzz" / target;
    fs::create_directories(d);
    return d;
}

/// Byte-level mutations that reach the readers' corner cases: bit flips, interesting bytes and
/// tokens (numbers at the edges of their types, separators, comments), deleted, repeated and
/// spliced ranges, truncation. Deterministic for a seed.
class Mutator {
public:
    Mutator(uint64_t seed, std::vector<std::string> corpus, std::vector<std::string> tokens)
        : rng_(seed), corpus_(std::move(corpus)), tokens_(std::move(tokens)) {}

    std::string Next() {
        std::string s = corpus_[Pick(corpus_.size())];
        const int rounds = 1 + int(Pick(4));
        for (int r = 0; r < rounds; ++r) MutateOnce(&s);
        return s;
    }

private:
    size_t Pick(size_t n) { return n == 0 ? 0 : size_t(rng_() % n); }

    void MutateOnce(std::string* s) {
        const size_t at = Pick(s->size() + 1);
        switch (Pick(7)) {
            case 0:  // flip a bit
                if (!s->empty()) (*s)[at % s->size()] ^= char(1 << Pick(8));
                break;
            case 1: {  // an interesting byte
                static const char kBytes[] = {'\0', '\xff', '\n', ' ', '"', '{', '}',   '[',
                                              ']',  ',',    ':',  '/', '-', '9', '\x80'};
                if (!s->empty()) (*s)[at % s->size()] = kBytes[Pick(sizeof kBytes)];
                break;
            }
            case 2:  // an interesting token
                s->insert(at, tokens_[Pick(tokens_.size())]);
                break;
            case 3:  // delete a range
                s->erase(at, 1 + Pick(64));
                break;
            case 4: {  // repeat a range
                const std::string part = s->substr(at, 1 + Pick(256));
                s->insert(Pick(s->size() + 1), part);
                break;
            }
            case 5: {  // splice in a range of another seed
                const std::string& o = corpus_[Pick(corpus_.size())];
                const size_t from = Pick(o.size());
                s->insert(at, o.substr(from, 1 + Pick(128)));
                break;
            }
            default:  // truncate
                s->resize(at);
                break;
        }
    }

    std::mt19937_64 rng_;
    std::vector<std::string> corpus_;
    std::vector<std::string> tokens_;
};

std::vector<std::string> Corpus(const std::string& target) {
    std::vector<std::string> seeds;
    for (const auto& e :
         fs::directory_iterator(fs::path(TEXCACHE_SOURCE_DIR) / "tests" / "fuzz" / target))
        seeds.push_back(Slurp(e.path()));
    return seeds;
}

int Iterations(int base) {
    const char* scale = std::getenv("TEXCACHE_FUZZ_SCALE");
    return base * (scale ? std::max(1, std::atoi(scale)) : 1);
}

const std::vector<std::string> kTextTokens = {"nan",
                                              "-inf",
                                              "1e999",
                                              "-1",
                                              "0",
                                              "4294967296",
                                              "18446744073709551616",
                                              "1e-45",
                                              "3.4e38",
                                              "1e18",
                                              "-2147483649",
                                              "\"\"",
                                              "\"a\"",
                                              "[]",
                                              "{}",
                                              "null",
                                              "true",
                                              "/*",
                                              "*/",
                                              "//",
                                              "\\u0000",
                                              "\n",
                                              "#",
                                              "/",
                                              "//",
                                              "f 1 2 3\n",
                                              "v 0 0 0\n",
                                              "t crease 2/1/0 0 1 1\n",
                                              "t hole 1/0/0 0\n",
                                              "t corner 99999999/1/0 ",
                                              "vt 0 0\n"};

/// Runs `load` on `iterations` mutations of the target's corpus: each must load or throw
/// InputError; anything else fails, naming the input (written to the work directory).
void Fuzz(const std::string& target, uint64_t seed, int iterations,
          const std::vector<std::string>& tokens,
          const std::function<void(const std::string&)>& load) {
    const std::vector<std::string> corpus = Corpus(target);
    ASSERT_FALSE(corpus.empty()) << target;
    for (const std::string& s : corpus) ASSERT_NO_THROW(load(s)) << target << ": a seed fails";
    Mutator m(seed, corpus, tokens);
    int rejected = 0;
    for (int i = 0; i < iterations; ++i) {
        const std::string input = m.Next();
        try {
            load(input);
        } catch (const InputError& e) {
            ++rejected;
            ASSERT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
        } catch (const std::exception& e) {
            const fs::path failing = WorkDir(target) / ("failing_" + std::to_string(i));
            Spit(failing, input);
            FAIL() << target << " iteration " << i << " (seed " << seed << "): " << e.what()
                   << "; input written to " << failing;
        }
    }
    // Both outcomes must be exercised, or the mutations miss the reader.
    EXPECT_GT(rejected, 0) << target;
    EXPECT_LT(rejected, iterations) << target;
    std::printf("%s: %d inputs, %d rejected with InputError\n", target.c_str(), iterations,
                rejected);
}

TEST(Fuzz, ObjReader) {
    Fuzz("obj", 18, Iterations(20000), kTextTokens, [](const std::string& text) {
        std::vector<std::string> warnings;
        const ControlCage c = ParseObj(text, "fuzz.obj", &warnings);
        // What loads is consistent: faces of >= 3 corners indexing existing vertices.
        size_t corners = 0;
        for (const int n : c.faceVertexCounts) {
            ASSERT_GE(n, 3);
            corners += size_t(n);
        }
        ASSERT_EQ(corners, c.faceVertexIndices.size());
        for (const int v : c.faceVertexIndices) ASSERT_TRUE(v >= 0 && v < c.numVertices());
        for (const auto& p : c.positions)
            for (const float x : p) ASSERT_TRUE(std::isfinite(x));
    });
}

TEST(Fuzz, SceneReader) {
    // The files the corpus scenes name, beside the mutated scene.
    const fs::path dir = WorkDir("scene");
    fs::copy_file(test::MeshPath("catmark_cube"), dir / "cube.obj",
                  fs::copy_options::overwrite_existing);
    WriteImage((dir / "env.exr").string(), Image(8, 4, 3, 1.0f));
    WriteImage((dir / "tex.png").string(), Image(4, 4, 3, 0.5f));
    const std::string path = (dir / "fuzz.json").string();
    Fuzz("scene", 18, Iterations(400), kTextTokens, [&](const std::string& text) {
        Spit(path, text);
        std::vector<std::string> warnings;
        const Scene s = LoadScene(path, &warnings);
        ASSERT_FALSE(s.objects.empty());
        for (const Object& o : s.objects) {
            ASSERT_TRUE(o.mesh >= 0 && size_t(o.mesh) < s.meshes.size());
            ASSERT_TRUE(o.material >= 0 && size_t(o.material) < s.materials.size());
        }
        ASSERT_FALSE(s.camera.pose.keys.empty());
    });
}

TEST(Fuzz, FrameBufferReader) {
    const std::string path = (WorkDir("frame_buffers") / "fuzz.exr").string();
    const std::vector<std::string> tokens = {std::string(4, '\0'),
                                             std::string(4, '\xff'),
                                             std::string("\x7f\xff\xff\xff", 4),
                                             "dataWindow",
                                             "box2i",
                                             "float",
                                             "zip",
                                             "channels"};
    Fuzz("frame_buffers", 18, Iterations(150), tokens, [&](const std::string& bytes) {
        Spit(path, bytes);
        const screen::FrameBuffers fb = ReadFrameBuffers(path);
        ASSERT_GT(fb.width, 0);
        ASSERT_GT(fb.height, 0);
        ASSERT_TRUE(fb.emitted.empty() || fb.emitted.size() == fb.NumPixels());
    });
}

}  // namespace
}  // namespace texcache
