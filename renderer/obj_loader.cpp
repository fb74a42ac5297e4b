// SPDX-License-Identifier: Apache-2.0
#include "renderer/obj_loader.h"

#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "texcache/error.h"

namespace texcache {

namespace {

struct Cursor {
    std::string_view s;
    size_t pos = 0;
    void SkipSpace() {
        while (pos < s.size() && (s[pos] == ' ' || s[pos] == '\t' || s[pos] == '\r')) ++pos;
    }
    bool AtEnd() {
        SkipSpace();
        return pos >= s.size();
    }
    std::string_view Token() {
        SkipSpace();
        const size_t b = pos;
        while (pos < s.size() && s[pos] != ' ' && s[pos] != '\t' && s[pos] != '\r') ++pos;
        return s.substr(b, pos - b);
    }
};

class Parser {
public:
    Parser(const std::string& name, std::vector<std::string>* warnings)
        : name_(name), warnings_(warnings) {}

    [[noreturn]] void Fail(const std::string& what) const {
        throw InputError(name_ + ":" + std::to_string(line_), what);
    }
    void Warn(const std::string& what) const {
        if (warnings_) warnings_->push_back(name_ + ":" + std::to_string(line_) + ": " + what);
    }

    float Float(std::string_view t) const {
        float v;
        const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
        if (r.ec != std::errc() || r.ptr != t.data() + t.size()) {
            // from_chars rejects "inf"/"nan" spellings in some forms; report them as non-finite.
            std::string low(t);
            for (char& ch : low) ch = char(std::tolower(ch));
            if (low.find("nan") != std::string::npos || low.find("inf") != std::string::npos)
                Fail("non-finite coordinate '" + std::string(t) + "'");
            Fail("malformed number '" + std::string(t) + "'");
        }
        if (!std::isfinite(v)) Fail("non-finite coordinate '" + std::string(t) + "'");
        return v;
    }
    long Int(std::string_view t) const {
        long v;
        const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
        if (r.ec != std::errc() || r.ptr != t.data() + t.size())
            Fail("malformed integer '" + std::string(t) + "'");
        return v;
    }
    // OBJ index (1-based, or negative = relative to the count so far) -> 0-based.
    int Index(std::string_view t, size_t count, const char* what) const {
        const long i = Int(t);
        long r = i > 0 ? i - 1 : long(count) + i;
        if (i == 0 || r < 0 || r >= long(count))
            Fail(std::string(what) + " index " + std::string(t) + " is out of range (" +
                 std::to_string(count) + " defined so far)");
        return int(r);
    }

    ControlCage Parse(std::string_view text) {
        cage_.sourcePath = name_;
        size_t start = 0;
        bool anyFaceUv = false, anyFaceNoUv = false;
        while (start <= text.size()) {
            size_t end = text.find('\n', start);
            if (end == std::string_view::npos) end = text.size();
            ++line_;
            Cursor c{text.substr(start, end - start)};
            start = end + 1;
            const std::string_view kw = c.Token();
            if (kw.empty() || kw[0] == '#') {
                if (end == text.size()) break;
                continue;
            }
            if (kw == "v") {
                std::array<float, 3> p;
                for (float& x : p) {
                    const auto t = c.Token();
                    if (t.empty()) Fail("vertex needs 3 coordinates");
                    x = Float(t);
                }
                cage_.positions.push_back(p);
            } else if (kw == "vt") {
                std::array<float, 2> uv;
                for (float& x : uv) {
                    const auto t = c.Token();
                    if (t.empty()) Fail("texture coordinate needs 2 values");
                    x = Float(t);
                }
                cage_.uvs.push_back(uv);
            } else if (kw == "vn" || kw == "o" || kw == "g" || kw == "s" || kw == "usemtl" ||
                       kw == "mtllib") {
                // Facet normals are ignored (the limit surface defines normals); groups too.
            } else if (kw == "f") {
                int n = 0;
                bool hasUv = false, noUv = false;
                std::set<int> seen;
                while (!c.AtEnd()) {
                    const std::string_view t = c.Token();
                    const size_t s1 = t.find('/');
                    const int v = Index(t.substr(0, s1), cage_.positions.size(), "vertex");
                    if (!seen.insert(v).second)
                        Fail("face repeats vertex " + std::to_string(v + 1));
                    cage_.faceVertexIndices.push_back(v);
                    int vt = -1;
                    if (s1 != std::string_view::npos) {
                        const size_t s2 = t.find('/', s1 + 1);
                        const std::string_view tt =
                            t.substr(s1 + 1, s2 == std::string_view::npos ? t.npos : s2 - s1 - 1);
                        if (!tt.empty()) vt = Index(tt, cage_.uvs.size(), "texture coordinate");
                    }
                    (vt >= 0 ? hasUv : noUv) = true;
                    faceUv_.push_back(vt);
                    ++n;
                }
                if (n < 3) Fail("face has " + std::to_string(n) + " vertices (at least 3 needed)");
                if (hasUv && noUv)
                    Fail("face gives texture coordinates for some corners but not others");
                anyFaceUv |= hasUv;
                anyFaceNoUv |= noUv;
                cage_.faceVertexCounts.push_back(n);
                faceLines_.push_back(line_);
            } else if (kw == "t") {
                ParseTag(c);
            } else {
                Warn("unknown statement '" + std::string(kw) + "' skipped");
            }
            if (end == text.size()) break;
        }
        if (cage_.faceVertexCounts.empty()) {
            line_ = 0;
            throw InputError(name_, "no faces");
        }
        if (anyFaceUv && !anyFaceNoUv) {
            cage_.faceUvIndices = faceUv_;
        } else {
            if (anyFaceUv) Warn("texture coordinates on some faces only: uvs dropped");
            cage_.uvs.clear();
        }
        ResolveTags();
        return std::move(cage_);
    }

private:
    struct PendingTag {
        int line;
        std::string name;
        std::vector<long> ints;
        std::vector<float> floats;
    };

    void ParseTag(Cursor& c) {
        PendingTag tag;
        tag.line = line_;
        tag.name = std::string(c.Token());
        const std::string_view counts = c.Token();
        int ni, nf, ns;
        if (std::sscanf(std::string(counts).c_str(), "%d/%d/%d", &ni, &nf, &ns) != 3 || ni < 0 ||
            nf < 0 || ns < 0)
            Fail("tag '" + tag.name + "' needs counts as nInts/nFloats/nStrings, got '" +
                 std::string(counts) + "'");
        for (int i = 0; i < ni; ++i) {
            const auto t = c.Token();
            if (t.empty())
                Fail("tag '" + tag.name + "' declares " + std::to_string(ni) +
                     " integers but has fewer");
            tag.ints.push_back(Int(t));
        }
        for (int i = 0; i < nf; ++i) {
            const auto t = c.Token();
            if (t.empty())
                Fail("tag '" + tag.name + "' declares " + std::to_string(nf) +
                     " floats but has fewer");
            tag.floats.push_back(Float(t));
        }
        for (int i = 0; i < ns; ++i) c.Token();
        if (!c.AtEnd()) Fail("tag '" + tag.name + "' has more values than its counts declare");
        tags_.push_back(std::move(tag));
    }

    // Tags are applied after all faces are read: they may name edges of faces defined later.
    void ResolveTags() {
        std::set<std::pair<int, int>> edges;
        size_t off = 0;
        for (int n : cage_.faceVertexCounts) {
            for (int i = 0; i < n; ++i) {
                const int a = cage_.faceVertexIndices[off + i],
                          b = cage_.faceVertexIndices[off + (i + 1) % n];
                edges.insert({std::min(a, b), std::max(a, b)});
            }
            off += n;
        }
        std::map<std::pair<int, int>, float> creases;
        std::map<int, float> corners;
        std::set<int> holes;
        const int nv = cage_.numVertices(), nfaces = cage_.numFaces();
        for (const PendingTag& t : tags_) {
            line_ = t.line;
            if (t.name == "crease") {
                if (t.ints.size() % 2 != 0 || t.ints.empty() || t.floats.empty())
                    Fail("crease needs vertex pairs and a sharpness");
                const size_t pairs = t.ints.size() / 2;
                if (t.floats.size() != 1 && t.floats.size() != pairs)
                    Fail("crease needs one sharpness, or one per edge");
                for (size_t i = 0; i < pairs; ++i) {
                    const long a = t.ints[2 * i], b = t.ints[2 * i + 1];
                    const float s = t.floats[t.floats.size() == 1 ? 0 : i];
                    const std::pair<int, int> e{int(std::min(a, b)), int(std::max(a, b))};
                    if (a < 0 || b < 0 || a >= nv || b >= nv || !edges.count(e)) {
                        Warn("crease names edge (" + std::to_string(a) + ", " + std::to_string(b) +
                             ") that no face has: ignored");
                        continue;
                    }
                    if (s < 0.0f) Fail("negative crease sharpness");
                    // A repeated edge keeps its largest sharpness.
                    auto [it, fresh] = creases.try_emplace(e, s);
                    if (!fresh) it->second = std::max(it->second, s);
                }
            } else if (t.name == "corner") {
                if (t.ints.empty() || (t.floats.size() != 1 && t.floats.size() != t.ints.size()))
                    Fail("corner needs vertices and a sharpness (one, or one per vertex)");
                for (size_t i = 0; i < t.ints.size(); ++i) {
                    const long v = t.ints[i];
                    if (v < 0 || v >= nv) {
                        Warn("corner names missing vertex " + std::to_string(v) + ": ignored");
                        continue;
                    }
                    const float s = t.floats[t.floats.size() == 1 ? 0 : i];
                    if (s < 0.0f) Fail("negative corner sharpness");
                    corners[int(v)] = std::max(corners[int(v)], s);
                }
            } else if (t.name == "hole") {
                for (long f : t.ints) {
                    if (f < 0 || f >= nfaces) {
                        Warn("hole names missing face " + std::to_string(f) + ": ignored");
                        continue;
                    }
                    holes.insert(int(f));
                }
            } else if (t.name == "interpolateboundary") {
                if (t.ints.size() != 1) Fail("interpolateboundary needs one integer");
                switch (t.ints[0]) {
                    case 0:
                        cage_.boundary = BoundaryInterpolation::None;
                        break;
                    case 1:
                        cage_.boundary = BoundaryInterpolation::EdgeAndCorner;
                        break;
                    case 2:
                        cage_.boundary = BoundaryInterpolation::EdgeOnly;
                        break;
                    default:
                        Fail("interpolateboundary must be 0, 1 or 2");
                }
            } else {
                Warn("unknown tag '" + t.name + "' skipped");
            }
        }
        for (const auto& [e, s] : creases) {
            cage_.creaseEdges.push_back({e.first, e.second});
            cage_.creaseWeights.push_back(s);
        }
        for (const auto& [v, s] : corners) {
            cage_.cornerVertices.push_back(v);
            cage_.cornerWeights.push_back(s);
        }
        cage_.holes.assign(holes.begin(), holes.end());
    }

    std::string name_;
    std::vector<std::string>* warnings_;
    int line_ = 0;
    ControlCage cage_;
    std::vector<int> faceUv_;
    std::vector<int> faceLines_;
    std::vector<PendingTag> tags_;
};

}  // namespace

ControlCage ParseObj(std::string_view text, const std::string& name,
                     std::vector<std::string>* warnings) {
    return Parser(name, warnings).Parse(text);
}

ControlCage LoadObj(const std::string& path, std::vector<std::string>* warnings) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path, "cannot open file");
    std::stringstream ss;
    ss << f.rdbuf();
    if (f.bad()) throw InputError(path, "cannot read file");
    return ParseObj(ss.str(), path, warnings);
}

}  // namespace texcache
