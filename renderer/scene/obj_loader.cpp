// SPDX-License-Identifier: Apache-2.0
// OBJ control cages. One pass over the text with string_views and std::from_chars (no per-token
// allocation: the 100 KB car parses in about a millisecond, which ctest -R
// ObjLoader.CarParsesInAFewMilliseconds records as car_parse_ms); tags are collected while
// reading and applied after the last face, because a tag may name faces and edges defined
// further down.
#include "renderer/scene/obj_loader.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <unordered_map>

#include "texcache/error.h"

namespace texcache {

namespace {

bool IsSpace(char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

/// Whitespace-separated tokens of one line.
struct Cursor {
    std::string_view s;
    size_t pos = 0;
    void SkipSpace() {
        while (pos < s.size() && IsSpace(s[pos])) ++pos;
    }
    bool AtEnd() {
        SkipSpace();
        return pos >= s.size();
    }
    std::string_view Token() {
        SkipSpace();
        const size_t b = pos;
        while (pos < s.size() && !IsSpace(s[pos])) ++pos;
        return s.substr(b, pos - b);
    }
};

/// A token quoted for a message, cut to an Excerpt (a token may be an 8 MB line).
std::string Quoted(std::string_view t) {
    return "'" + Excerpt(t) + "'";
}

/// Cage coordinates beyond this are rejected: Embree's bounds are limited to about +-1.8e18
/// (its FLT_LARGE), and a cage that large cannot be framed by a camera in float either.
constexpr float kMaxCoordinate = 1e18f;

/// OpenSubdiv's limit on face sizes and vertex valences (Far::VALENCE_LIMIT).
constexpr int kMaxValence = (1 << 16) - 1;

/// Largest coordinates in [2^kMinUnscaledExponent, 2^kMaxUnscaledExponent) keep their units
/// (ScalePositions): the bundled cages, and anything a float holds with room to spare.
constexpr int kMinUnscaledExponent = -8, kMaxUnscaledExponent = 24;

/// Shortest round-trip form of a number, for messages.
std::string Fmt(double v) {
    char buf[32];
    return std::string(buf, std::to_chars(buf, buf + sizeof buf, float(v)).ptr);
}

class Parser {
public:
    Parser(const std::string& name, std::vector<std::string>* warnings, ObjFaceTags* tags)
        : name_(name), warnings_(warnings), faceTags_(tags) {}

    ControlCage Parse(std::string_view text) {
        cage_.sourcePath = name_;
        // A UTF-8 byte order mark would otherwise glue itself to the first keyword.
        if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
        size_t start = 0;
        while (start < text.size()) {
            size_t end = text.find('\n', start);
            if (end == std::string_view::npos) end = text.size();
            ++line_;
            // Trailing comments ("f 1 2 3 # top") would otherwise read as one more index.
            std::string_view line = text.substr(start, end - start);
            line = line.substr(0, line.find('#'));
            Cursor c{line};
            start = end + 1;
            const std::string_view kw = c.Token();
            if (kw.empty()) continue;
            if (kw == "v") {
                // `v x y z [w]`: w (and the colours some exporters append) are ignored.
                std::array<float, 3> p;
                std::array<double, 3> exact;
                for (int k = 0; k < 3; ++k) {
                    const std::string_view t = c.Token();
                    exact[k] = Coordinate(t, &p[k]);
                    if (std::abs(float(exact[k])) > kMaxCoordinate)
                        Fail("vertex coordinate " + Quoted(t) +
                             " is beyond +-1e18, the range the ray tracer (Embree) handles");
                }
                cage_.positions.push_back(p);
                exact_.push_back(exact);
            } else if (kw == "vt") {
                std::array<float, 2> uv;
                for (float& x : uv) x = Float(c.Token(), "texture coordinate needs 2 values");
                cage_.uvs.push_back(uv);
            } else if (kw == "vn") {
                // Facet normals: the limit surface defines the normals. Counted only to validate
                // the indices faces give.
                ++numNormals_;
            } else if (kw == "f") {
                ParseFace(c);
            } else if (kw == "t") {
                ParseTag(c);
            } else if (kw == "o" || kw == "g" || kw == "usemtl" || kw == "mtllib") {
                // Names and materials do not change the cage; they are kept when asked for.
                if (faceTags_) Tag(kw, c);
            } else if (kw == "s") {
                // Smoothing groups: the limit surface defines the normals.
            } else {
                // Warn once per keyword: a file full of `l` lines should not bury other warnings.
                auto it = unknownStatements_.find(kw);
                if (it == unknownStatements_.end())
                    it = unknownStatements_.emplace(std::string(kw), std::pair{line_, 0}).first;
                ++it->second.second;
            }
        }
        if (cage_.faceVertexCounts.empty()) {
            line_ = std::max(line_, 1);  // an empty file still gets a line to point at
            Fail("no faces in the file (" + std::to_string(cage_.numVertices()) +
                 " vertices): an empty cage cannot be rendered");
        }
        ScalePositions();
        for (const auto& [kw, at] : unknownStatements_) {
            std::string w = "unknown statement " + Quoted(kw) + " skipped";
            if (at.second > 1) w += " (" + std::to_string(at.second) + " lines)";
            WarnAt(at.first, w);
        }
        // Face-varying uvs are only usable when every corner has one. A face mixing corners with
        // and without uvs is an error (ParseFace); faces that disagree with each other drop the
        // uvs with a warning, because the geometry itself is still fine.
        if (firstUvFaceLine_ > 0 && firstNoUvFaceLine_ > 0) {
            WarnAt(std::max(firstUvFaceLine_, firstNoUvFaceLine_),
                   "faces with texture coordinates (first on line " +
                       std::to_string(firstUvFaceLine_) + ") and without (first on line " +
                       std::to_string(firstNoUvFaceLine_) + "): uvs dropped");
        }
        if (firstUvFaceLine_ > 0 && firstNoUvFaceLine_ == 0) {
            cage_.faceUvIndices = std::move(faceUv_);
        } else {
            cage_.uvs.clear();
            cage_.faceUvIndices.clear();
        }
        ResolveTags();
        CheckSomethingRenders();
        return std::move(cage_);
    }

private:
    [[noreturn]] void Fail(const std::string& what) const {
        throw InputError(name_ + ":" + std::to_string(line_), what);
    }
    void WarnAt(int line, const std::string& what) const {
        if (warnings_) warnings_->push_back(name_ + ":" + std::to_string(line) + ": " + what);
    }

    /// A finite float; `missing` is the message when the token is absent.
    float Float(std::string_view t, const char* missing) const { return Number<float>(t, missing); }
    /// A finite T (float or double); `missing` is the message when the token is absent.
    template <typename T>
    T Number(std::string_view t, const char* missing) const {
        if (t.empty()) Fail(missing);
        std::string_view digits = t;
        if (digits.size() > 1 && digits[0] == '+') digits.remove_prefix(1);  // from_chars says no
        T v = 0;
        const auto r = std::from_chars(digits.data(), digits.data() + digits.size(), v);
        if (r.ec == std::errc::result_out_of_range)
            Fail("number " + Quoted(t) + " is out of the float range");
        if (r.ec != std::errc() || r.ptr != digits.data() + digits.size())
            Fail("malformed number " + Quoted(t));
        // from_chars accepts "nan" and "inf"; a cage with them cannot be subdivided.
        if (!std::isfinite(v)) Fail("non-finite number " + Quoted(t));
        return v;
    }
    /// A vertex coordinate: exactly (in double, for ScalePositions) and as the nearest float in
    /// `*f` (what the cage keeps when it needs no scaling; 0 below the float range).
    double Coordinate(std::string_view t, float* f) const {
        const double v = Number<double>(t, "vertex needs 3 coordinates");
        const size_t plus = t.size() > 1 && t[0] == '+';
        *f = 0.0f;
        std::from_chars(t.data() + plus, t.data() + t.size(), *f);
        return v;
    }

    /// Cages far larger or smaller than a unit (a CAD part in micrometres, a model in light
    /// years, down to coordinates below the float range) keep their shape in float only scaled
    /// by a power of two: the positions are stored in units of 2^unitExponent, exactly (a
    /// power of two changes no digit), and a scene puts the factor back into the object's
    /// transform. Cages whose largest coordinate is in [2^-8, 2^24) stay as they are.
    void ScalePositions() {
        double largest = 0.0;
        for (const auto& p : exact_)
            for (const double x : p) largest = std::max(largest, std::abs(x));
        if (!(largest > 0.0)) return;  // every vertex at the origin: CheckSomethingRenders says so
        const int e = std::ilogb(largest);
        if (e >= kMinUnscaledExponent && e < kMaxUnscaledExponent) return;
        cage_.unitExponent = e;
        for (size_t i = 0; i < exact_.size(); ++i)
            for (int k = 0; k < 3; ++k) cage_.positions[i][k] = float(std::ldexp(exact_[i][k], -e));
    }

    /// A cage whose every face is a hole, or whose other faces have no area at all (every vertex
    /// on one point or one line, in float), renders nothing: an error rather than a blank image.
    void CheckSomethingRenders() {
        line_ = firstFaceLine_;
        if (cage_.holes.size() == cage_.faceVertexCounts.size())
            Fail("every face of the cage is a hole (t hole): nothing would render");
        // Twice the area of each face (Newell's vector area) against its own bounding box: zero
        // (to rounding) when the face is degenerate, whatever the cage's scale.
        std::vector<char> hole(cage_.faceVertexCounts.size(), 0);
        for (const int h : cage_.holes) hole[size_t(h)] = 1;
        bool someArea = false;
        size_t at = 0;
        for (size_t f = 0; f < cage_.faceVertexCounts.size() && !someArea; ++f) {
            const int n = cage_.faceVertexCounts[f];
            const size_t first = at;
            at += size_t(n);
            if (hole[f]) continue;
            double a[3] = {0.0, 0.0, 0.0}, lo[3], hi[3];
            for (int k = 0; k < 3; ++k)
                lo[k] = hi[k] = cage_.positions[size_t(cage_.faceVertexIndices[first])][k];
            for (int i = 0; i < n; ++i) {
                const auto& p = cage_.positions[size_t(cage_.faceVertexIndices[first + size_t(i)])];
                const auto& q =
                    cage_.positions[size_t(cage_.faceVertexIndices[first + size_t((i + 1) % n)])];
                a[0] += (double(p[1]) - q[1]) * (double(p[2]) + q[2]);
                a[1] += (double(p[2]) - q[2]) * (double(p[0]) + q[0]);
                a[2] += (double(p[0]) - q[0]) * (double(p[1]) + q[1]);
                for (int k = 0; k < 3; ++k)
                    lo[k] = std::min(lo[k], double(p[k])), hi[k] = std::max(hi[k], double(p[k]));
            }
            double diagonal2 = 0.0;
            for (int k = 0; k < 3; ++k) diagonal2 += (hi[k] - lo[k]) * (hi[k] - lo[k]);
            someArea = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]) > 1e-10 * diagonal2;
        }
        // Coordinates keep 7 significant digits in float: a small cage far from the origin has its
        // vertices rounded onto each other, or far off its shape (by more than 5% of its size:
        // past that the image is not the cage any more; a unit cube at 1e6 moves by 0.8%).
        double reach = 0.0, moved = 0.0;
        std::array<double, 3> exactLo = exact_.front(), exactHi = exact_.front();
        for (size_t i = 0; i < exact_.size(); ++i)
            for (int k = 0; k < 3; ++k) {
                const double x = exact_[i][k];
                reach = std::max(reach, std::abs(x));
                exactLo[k] = std::min(exactLo[k], x), exactHi[k] = std::max(exactHi[k], x);
                moved = std::max(
                    moved,
                    std::abs(std::ldexp(double(cage_.positions[i][k]), cage_.unitExponent) - x));
            }
        const double exactExtent =
            std::max({exactHi[0] - exactLo[0], exactHi[1] - exactLo[1], exactHi[2] - exactLo[2]});
        if (moved > 0.05 * exactExtent)
            Fail("the cage is " + Fmt(exactExtent) + " across but " + Fmt(reach) +
                 " from the origin: in float (7 significant digits) its vertices move by up to " +
                 Fmt(moved) +
                 ", out of shape (move it nearer the origin, and place it with a scene "
                 "file's transform)");
        if (!someArea)
            Fail("the cage has no area: the vertices of every face lie on one point or one line");
    }

    /// An integer; `what` names it in the message ("tag integer", "vertex index").
    long Int(std::string_view t, const char* what, const char* what2 = "") const {
        long v = 0;
        const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
        if (t.empty() || r.ec != std::errc() || r.ptr != t.data() + t.size())
            Fail("malformed " + std::string(what) + what2 + " " + Quoted(t) +
                 " (expected an integer)");
        return v;
    }
    /// OBJ index (1-based, or negative = relative: -1 is the last defined so far) -> 0-based.
    int Index(std::string_view t, size_t count, const char* what) const {
        const long i = Int(t, what, " index");
        const long r = i > 0 ? i - 1 : long(count) + i;
        if (i == 0 || r < 0 || r >= long(count))
            Fail(std::string(what) + " index " + Excerpt(t) + " is out of range (" +
                 std::to_string(count) + " defined so far" +
                 (i == 0 ? "; OBJ indices start at 1)" : ")"));
        return int(r);
    }

    void ParseFace(Cursor& c) {
        const size_t first = cage_.faceVertexIndices.size();
        int withUv = 0, n = 0;
        while (!c.AtEnd()) {
            const std::string_view t = c.Token();
            // v, v/vt, v//vn or v/vt/vn
            const size_t s1 = t.find('/');
            cage_.faceVertexIndices.push_back(
                Index(t.substr(0, s1), cage_.positions.size(), "vertex"));
            int vt = -1;
            if (s1 != std::string_view::npos) {
                const size_t s2 = t.find('/', s1 + 1);
                const std::string_view tt =
                    t.substr(s1 + 1, s2 == std::string_view::npos ? t.npos : s2 - s1 - 1);
                if (!tt.empty()) vt = Index(tt, cage_.uvs.size(), "texture coordinate");
                if (s2 != std::string_view::npos) {
                    const std::string_view tn = t.substr(s2 + 1);
                    if (tn.find('/') != std::string_view::npos)
                        Fail("face corner " + Quoted(t) + " has more than v/vt/vn");
                    // Normals are ignored, so a dangling one only earns a warning (once).
                    const long ni = Int(tn, "normal", " index");
                    const long nr = ni > 0 ? ni - 1 : long(numNormals_) + ni;
                    if ((ni == 0 || nr < 0 || nr >= long(numNormals_)) && !warnedNormal_) {
                        warnedNormal_ = true;
                        WarnAt(line_, "normal index " + Excerpt(tn) + " is out of range (" +
                                          std::to_string(numNormals_) +
                                          " defined so far); normals are ignored anyway");
                    }
                } else if (tt.empty()) {
                    Fail("face corner " + Quoted(t) + " ends with '/'");
                }
            }
            withUv += vt >= 0;
            faceUv_.push_back(vt);
            ++n;
        }
        if (n < 3) Fail("face has " + std::to_string(n) + " vertices (at least 3 needed)");
        if (n > kMaxValence)
            Fail("face has " + std::to_string(n) + " vertices; OpenSubdiv takes at most " +
                 std::to_string(kMaxValence));
        if (withUv != 0 && withUv != n)
            Fail("face gives texture coordinates for " + std::to_string(withUv) + " of its " +
                 std::to_string(n) + " corners (all or none needed)");
        // A repeated vertex makes a degenerate face Embree and OpenSubdiv both reject. Faces are
        // small, so a quadratic scan beats any set; long n-gons sort a scratch copy instead.
        const int* v = cage_.faceVertexIndices.data() + first;
        int repeated = -1;
        if (n <= 32) {
            for (int i = 0; i < n && repeated < 0; ++i)
                for (int j = i + 1; j < n; ++j)
                    if (v[i] == v[j]) {
                        repeated = v[i];
                        break;
                    }
        } else {
            scratch_.assign(v, v + n);
            std::sort(scratch_.begin(), scratch_.end());
            const auto it = std::adjacent_find(scratch_.begin(), scratch_.end());
            if (it != scratch_.end()) repeated = *it;
        }
        if (repeated >= 0)
            Fail("degenerate face: it repeats vertex " + std::to_string(repeated + 1));
        if (facesAt_.size() < cage_.positions.size()) facesAt_.resize(cage_.positions.size(), 0);
        for (int i = 0; i < n; ++i)
            if (++facesAt_[size_t(v[i])] >= kMaxValence)
                Fail("vertex " + std::to_string(v[i] + 1) + " is in " +
                     std::to_string(kMaxValence) +
                     " faces; OpenSubdiv takes a valence of at most " +
                     std::to_string(kMaxValence) + " edges");
        int& firstLine = withUv ? firstUvFaceLine_ : firstNoUvFaceLine_;
        if (firstLine == 0) firstLine = line_;
        if (firstFaceLine_ == 0) firstFaceLine_ = line_;
        cage_.faceVertexCounts.push_back(n);
        if (faceTags_) {
            faceTags_->faceMaterial.push_back(material_);
            faceTags_->faceGroup.push_back(group_);
        }
    }

    /// `mtllib a.mtl [b.mtl ...]`, `usemtl name`, `g name`, `o name` (names may hold spaces).
    void Tag(std::string_view kw, Cursor& c) {
        if (kw == "mtllib") {
            for (std::string_view t = c.Token(); !t.empty(); t = c.Token())
                faceTags_->libraries.push_back({std::string(t), line_});
            return;
        }
        c.SkipSpace();
        std::string_view name = c.s.substr(c.pos);
        while (!name.empty() && IsSpace(name.back())) name.remove_suffix(1);
        const bool isMaterial = kw == "usemtl";
        std::vector<ObjFaceTags::Named>& names =
            isMaterial ? faceTags_->materials : faceTags_->groups;
        // `g` alone, or `usemtl` with no name: back to none.
        int id = -1;
        if (!name.empty()) {
            // A hash per kind: a file may name a new material on every face.
            auto& index = isMaterial ? materialIds_ : groupIds_;
            const auto [it, added] = index.emplace(std::string(name), int(names.size()));
            if (added) names.push_back({it->first, line_});
            id = it->second;
        }
        (isMaterial ? material_ : group_) = id;
    }

    struct PendingTag {
        int line;
        std::string_view name;
        std::vector<long> ints;
        std::vector<float> floats;
    };

    /// `t NAME nInts/nFloats/nStrings ints... floats... strings...`: checks the counts now (a
    /// mismatch is a syntax error), interprets the values in ResolveTags.
    void ParseTag(Cursor& c) {
        PendingTag tag;
        tag.line = line_;
        tag.name = c.Token();
        if (tag.name.empty()) Fail("tag line without a tag name");
        const std::string name = Excerpt(tag.name);
        const std::string_view counts = c.Token();
        long n[3] = {-1, -1, -1};
        const char* p = counts.data();
        const char* end = counts.data() + counts.size();
        for (int k = 0; k < 3; ++k) {
            const auto r = std::from_chars(p, end, n[k]);
            const bool sepOk = k == 2 ? r.ptr == end : (r.ptr != end && *r.ptr == '/');
            if (r.ec != std::errc() || !sepOk || n[k] < 0 || n[k] > (1 << 24)) {
                Fail("tag '" + name + "' needs counts as nInts/nFloats/nStrings, got " +
                     Quoted(counts));
            }
            p = r.ptr + 1;
        }
        const auto need = [&](long count, const char* kind) {
            return "tag '" + name + "' declares " + std::to_string(count) + " " + kind +
                   " but has fewer";
        };
        tag.ints.reserve(size_t(n[0]));
        for (long i = 0; i < n[0]; ++i) {
            const std::string_view t = c.Token();
            if (t.empty()) Fail(need(n[0], "integers"));
            tag.ints.push_back(Int(t, "tag integer"));
        }
        tag.floats.reserve(size_t(n[1]));
        for (long i = 0; i < n[1]; ++i) {
            const std::string_view t = c.Token();
            if (t.empty()) Fail(need(n[1], "floats"));
            tag.floats.push_back(Float(t, "missing float"));
        }
        for (long i = 0; i < n[2]; ++i)
            if (c.Token().empty()) Fail(need(n[2], "strings"));
        if (!c.AtEnd())
            Fail("tag '" + name + "' has more values than its counts " + Quoted(counts) +
                 " declare");
        tags_.push_back(std::move(tag));
    }

    static uint64_t EdgeKey(long a, long b) {
        return uint64_t(std::min(a, b)) << 32 | uint64_t(std::max(a, b));
    }

    /// Applies the tags to the finished face list. Tags that name missing edges, vertices or faces
    /// are skipped with a warning (Embree fails on creases of non-edges); malformed tags throw.
    void ResolveTags() {
        // The sorted edge list only for crease tags to check against: on a 1,000,000-quad cage
        // without creases it would take 32 MB and ~0.35 s of sorting (a twentieth of a 1-thread
        // `texcache render` of it, perf).
        std::vector<uint64_t> edges;
        const bool creased = std::any_of(tags_.begin(), tags_.end(),
                                         [](const PendingTag& t) { return t.name == "crease"; });
        if (creased) {
            edges.reserve(cage_.faceVertexIndices.size());
            size_t off = 0;
            for (const int n : cage_.faceVertexCounts) {
                for (int i = 0; i < n; ++i)
                    edges.push_back(EdgeKey(cage_.faceVertexIndices[off + i],
                                            cage_.faceVertexIndices[off + (i + 1) % n]));
                off += size_t(n);
            }
            std::sort(edges.begin(), edges.end());
        }
        const auto isEdge = [&](long a, long b) {
            return std::binary_search(edges.begin(), edges.end(), EdgeKey(a, b));
        };
        // Ordered maps keep the output deterministic (sorted by vertex) whatever the tag order.
        std::map<uint64_t, float> creases;
        std::map<int, float> corners;
        std::vector<bool> hole(size_t(cage_.numFaces()), false);
        const long nv = cage_.numVertices(), nf = cage_.numFaces();
        for (const PendingTag& t : tags_) {
            line_ = t.line;
            if (t.name == "crease") {
                // `2k/1/0`: k edges sharing one sharpness; `2k/k/0`: one sharpness per edge.
                const size_t pairs = t.ints.size() / 2;
                if (t.ints.empty() || t.ints.size() % 2 != 0 ||
                    (t.floats.size() != 1 && t.floats.size() != pairs))
                    Fail("crease needs 2k/1/0 (k edges, one sharpness) or 2k/k/0, got " +
                         std::to_string(t.ints.size()) + "/" + std::to_string(t.floats.size()));
                for (size_t i = 0; i < pairs; ++i) {
                    const long a = t.ints[2 * i], b = t.ints[2 * i + 1];
                    const float s = t.floats[t.floats.size() == 1 ? 0 : i];
                    if (s < 0.0f) Fail("negative crease sharpness " + std::to_string(s));
                    if (a < 0 || b < 0 || a >= nv || b >= nv || a == b || !isEdge(a, b)) {
                        WarnAt(line_, "crease names (" + std::to_string(a) + ", " +
                                          std::to_string(b) +
                                          "), which is not an edge of any face: ignored");
                        continue;
                    }
                    // A repeated edge keeps its largest sharpness, whatever the order.
                    auto [it, fresh] = creases.try_emplace(EdgeKey(a, b), s);
                    if (!fresh) it->second = std::max(it->second, s);
                }
            } else if (t.name == "corner") {
                // `k/1/0` (one sharpness for all) or `k/k/0`.
                if (t.ints.empty() || (t.floats.size() != 1 && t.floats.size() != t.ints.size()))
                    Fail("corner needs k/1/0 (k vertices, one sharpness) or k/k/0, got " +
                         std::to_string(t.ints.size()) + "/" + std::to_string(t.floats.size()));
                for (size_t i = 0; i < t.ints.size(); ++i) {
                    const long v = t.ints[i];
                    const float s = t.floats[t.floats.size() == 1 ? 0 : i];
                    if (s < 0.0f) Fail("negative corner sharpness " + std::to_string(s));
                    if (v < 0 || v >= nv) {
                        WarnAt(line_, "corner names vertex " + std::to_string(v) +
                                          ", but there are " + std::to_string(nv) + ": ignored");
                        continue;
                    }
                    auto [it, fresh] = corners.try_emplace(int(v), s);
                    if (!fresh) it->second = std::max(it->second, s);
                }
            } else if (t.name == "hole") {
                if (t.ints.empty() || !t.floats.empty())
                    Fail("hole needs N/0/0 followed by N face indices");
                for (const long f : t.ints) {
                    if (f < 0 || f >= nf) {
                        WarnAt(line_, "hole names face " + std::to_string(f) + ", but there are " +
                                          std::to_string(nf) + ": ignored");
                        continue;
                    }
                    hole[size_t(f)] = true;
                }
            } else if (t.name == "interpolateboundary") {
                if (t.ints.size() != 1 || !t.floats.empty())
                    Fail("interpolateboundary needs 1/0/0 and one integer");
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
                        Fail(
                            "interpolateboundary must be 0 (none), 1 (edge and corner) or 2 "
                            "(edge only), got " +
                            std::to_string(t.ints[0]));
                }
            } else {
                WarnAt(line_, "unknown tag " + Quoted(t.name) + " skipped");
            }
        }
        for (const auto& [e, s] : creases) {
            cage_.creaseEdges.push_back({int(e >> 32), int(e & 0xffffffffu)});
            cage_.creaseWeights.push_back(s);
        }
        for (const auto& [v, s] : corners) {
            cage_.cornerVertices.push_back(v);
            cage_.cornerWeights.push_back(s);
        }
        for (int f = 0; f < cage_.numFaces(); ++f)
            if (hole[size_t(f)]) cage_.holes.push_back(f);
    }

    std::string name_;
    std::vector<std::string>* warnings_;
    int line_ = 0;
    ControlCage cage_;
    size_t numNormals_ = 0;
    ObjFaceTags* faceTags_;
    int material_ = -1, group_ = -1;  ///< the current usemtl and g/o (into faceTags_)
    std::unordered_map<std::string, int> materialIds_, groupIds_;
    bool warnedNormal_ = false;
    std::vector<int> faceUv_;                   ///< parallel to faceVertexIndices, -1 = no vt
    std::vector<int> scratch_;                  ///< long n-gons' duplicate check
    std::vector<int> facesAt_;                  ///< per vertex, the faces using it so far
    std::vector<std::array<double, 3>> exact_;  ///< the positions as written (ScalePositions)
    int firstFaceLine_ = 0;
    int firstUvFaceLine_ = 0, firstNoUvFaceLine_ = 0;
    std::map<std::string, std::pair<int, int>, std::less<>>
        unknownStatements_;         ///< first line, count
    std::vector<PendingTag> tags_;  ///< names view the text, which outlives the parse
};

}  // namespace

ControlCage ParseObj(std::string_view text, const std::string& name,
                     std::vector<std::string>* warnings, ObjFaceTags* tags) {
    if (tags) *tags = ObjFaceTags();
    return Parser(name, warnings, tags).Parse(text);
}

ControlCage LoadObj(const std::string& path, std::vector<std::string>* warnings,
                    ObjFaceTags* tags) {
    // A directory opens as a stream on Linux and reports a nonsense size: rule it out first.
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw InputError(path, "is a directory, not an OBJ file");
    std::ifstream f(path, std::ios::binary | std::ios::ate);
    if (!f) throw InputError(path, "cannot open OBJ file (missing or unreadable)");
    const std::streamoff size = f.tellg();
    if (size < 0) throw InputError(path, "cannot read OBJ file (not a regular file?)");
    std::string text(size_t(size), '\0');
    f.seekg(0);
    if (!f.read(text.data(), size)) throw InputError(path, "cannot read OBJ file");
    return ParseObj(text, path, warnings, tags);
}

}  // namespace texcache
