// SPDX-License-Identifier: Apache-2.0
#include "experiment_util.h"

#include <unistd.h>

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <type_traits>

#include "renderer/render_policy.h"
#include "renderer/scene/scene_loader.h"
#include "texcache/error.h"

namespace texcache::experiments {

namespace fs = std::filesystem;

std::unique_ptr<LoadedScene> LoadForExperiment(const Setup& s, const std::string& file,
                                               bool needLights,
                                               const std::function<void(Scene*)>& edit) {
    auto lp = std::make_unique<LoadedScene>();
    LoadedScene& l = *lp;
    const std::string path = (fs::path(s.scenesDir) / file).string();
    std::vector<std::string> warnings;
    l.scene = LoadScene(path, &warnings);
    l.name = fs::path(file).stem().string();
    if (edit) edit(&l.scene);
    RenderSceneOptions ro;
    ro.needLights = needLights;
    ro.needEnvironment = needLights;
    l.rs = std::make_unique<RenderScene>(l.scene, ro);
    return lp;
}

RenderOptions BaseOptions(const Scene& scene, IntegratorKind integrator, int width, int height) {
    RenderOptions o = RenderOptionsFrom(scene.settings);
    o.integrator = integrator;
    o.width = width;
    o.height = height;
    o.seconds = 0.0f;  // experiments time renders of exact sample counts
    o.progress = false;
    return o;
}

TextureSpaceCache* FreshCache(LoadedScene& ls, const RenderOptions& o) {
    if (!o.texture.enabled) return nullptr;
    if (!ls.cache || !ls.cache->Reconfigure(*ls.rs, o.texture)) {
        ls.cache.reset();  // free the old tables before mapping new ones
        ls.cache = MakeTextureSpaceCache(*ls.rs, o.texture, "experiment cache sizes");
    }
    return ls.cache.get();
}

Run TimedRender(LoadedScene& ls, const RenderOptions& o, int repeats, bool warmUp) {
    const RenderScene& rs = *ls.rs;
    // Each render gets an empty cache (FreshCache): the Reconfigure's memset is timed with the
    // render, a new cache is built untimed.
    auto cache = [&] { return FreshCache(ls, o); };
    if (warmUp) Render(rs, o, cache());
    ls.warmed = true;
    // A render of under a second is timed up to kCheapRepeats times: its CPU time moves by up
    // to a quarter between two runs of the same render on a shared machine, and the smallest
    // budgets' equal-time ratios hang on those renders, which cost little to repeat.
    constexpr int kCheapRepeats = 5;
    constexpr double kCheapSeconds = 1.0;
    const int least = std::max(repeats, 1);
    Run best;
    for (int i = 0;
         i < least || (least > 1 && i < kCheapRepeats && best.cpuSeconds < kCheapSeconds); ++i) {
        TextureSpaceCache* c = cache();
        RenderResult r = Render(rs, o, c);
        // Best of the repeats by CPU time: on a shared machine wall time also counts other
        // processes' work; CPU time counts ours (2 threads: wall ~ CPU / 2 when idle).
        if (i == 0 || r.stats.cpuSeconds < best.cpuSeconds) {
            best.seconds = r.stats.seconds;
            best.cpuSeconds = r.stats.cpuSeconds;
            best.stats = r.stats;
            best.image = std::move(r.beauty);
        }
    }
    return best;
}

Image Reference(const Setup& s, const std::string& tag, const RenderScene& rs,
                const RenderOptions& o) {
    const std::string path = (fs::path(s.outDir) / ("ref_" + tag + ".exr")).string();
    RankGroup* const ranks = s.ranks && s.ranks->Size() > 1 ? s.ranks : nullptr;
    const bool root = !ranks || ranks->Rank() == 0;
    // Rank 0 alone looks for the file, and tells the others whether to render it with it.
    Image cached;
    if (root && fs::exists(path)) {
        try {
            Image img = ReadImageRGB(path);
            if (img.width == o.width && img.height == o.height) cached = std::move(img);
        } catch (const InputError&) {
            // unreadable: render it again
        }
    }
    uint64_t found = cached.width > 0;
    if (ranks) ranks->Broadcast(&found, sizeof found, 0);
    if (found) return cached;
    if (root)
        Say("  reference %s: %dx%d, %d spp%s ...", tag.c_str(), o.width, o.height, o.spp,
            ranks ? Format(" over %d ranks", ranks->Size()).c_str() : "");
    RenderOptions r = o;
    r.progress = !s.quick && root;
    r.ranks = ranks;
    RenderResult res = Render(rs, r);
    if (!root) return Image();
    WriteImage(path, res.beauty);
    WriteImage(fs::path(path).replace_extension(".png").string(), res.beauty);
    Say("  reference %s done in %.1f s", tag.c_str(), res.stats.seconds);
    return std::move(res.beauty);
}

namespace {

// A Run as bytes, rank to rank: its statistics as they lie in memory (the ranks run one build),
// then the image's size and floats.
static_assert(std::is_trivially_copyable_v<RenderStats>);
template <typename T>
void Put(std::vector<char>* out, const T& v) {
    const char* p = reinterpret_cast<const char*>(&v);
    out->insert(out->end(), p, p + sizeof v);
}
template <typename T>
T Take(const std::vector<char>& in, size_t* at) {
    if (*at + sizeof(T) > in.size()) throw std::runtime_error("a rank sent a truncated render");
    T v;
    std::memcpy(&v, in.data() + *at, sizeof v);
    *at += sizeof v;
    return v;
}

void PutRun(std::vector<char>* out, const Run& r) {
    Put(out, r.seconds), Put(out, r.cpuSeconds), Put(out, r.stats);
    Put(out, r.image.width), Put(out, r.image.height), Put(out, r.image.channels);
    const char* p = reinterpret_cast<const char*>(r.image.data.data());
    out->insert(out->end(), p, p + r.image.data.size() * sizeof(float));
}

Run TakeRun(const std::vector<char>& in, size_t* at) {
    Run r;
    r.seconds = Take<double>(in, at), r.cpuSeconds = Take<double>(in, at);
    r.stats = Take<RenderStats>(in, at);
    const int w = Take<int>(in, at), h = Take<int>(in, at), c = Take<int>(in, at);
    r.image = Image(w, h, c);
    const size_t bytes = r.image.data.size() * sizeof(float);
    if (*at + bytes > in.size()) throw std::runtime_error("a rank sent a truncated image");
    std::memcpy(r.image.data.data(), in.data() + *at, bytes);
    *at += bytes;
    return r;
}

}  // namespace

RenderQueue::RenderQueue(const Setup& s)
    : ranks_(s.ranks && s.ranks->Size() > 1 ? s.ranks : nullptr) {}

void RenderQueue::Add(const std::string& label, LoadedScene& ls, const RenderOptions& o,
                      int repeats, bool warmUp, std::function<void(Run&)> done) {
    if (!ranks_) {
        Run r = TimedRender(ls, o, repeats, warmUp);
        done(r);
        return;
    }
    pending_.push_back({label, &ls, o, repeats, warmUp, std::move(done)});
}

void RenderQueue::Flush() {
    if (!ranks_) return;
    const int rank = ranks_->Rank(), size = ranks_->Size();
    // Dealt back and forth (ranks 0, 1, ..., N-1, then N-1, ..., 0, ...): renders added in
    // turns (per hit, texture space, per hit, ...) and in rising cost (budgets) then fall on
    // every rank alike, rather than one method's on one rank, the costliest on the last.
    auto dealtTo = [size](size_t i) {
        const int at = int(i % size_t(size));
        return (i / size_t(size)) % 2 == 0 ? at : size - 1 - at;
    };
    std::vector<char> mine;
    for (size_t i = 0; i < pending_.size(); ++i) {
        if (dealtTo(i) != rank) continue;
        Pending& p = pending_[i];
        // A rank's first render of a scene pays Embree's lazy tessellation unless warmed up:
        // the render a rank is dealt first is not the one the experiment warms up for.
        PutRun(&mine, TimedRender(*p.scene, p.options, p.repeats, p.warmUp || !p.scene->warmed));
        p.scene->warmed = true;
    }
    const std::vector<std::vector<char>> all = ranks_->Gather(mine);
    std::vector<Pending> pending = std::move(pending_);
    pending_.clear();
    if (rank != 0) return;
    std::vector<size_t> at(size_t(size), 0);
    for (size_t i = 0; i < pending.size(); ++i) {
        const int from = dealtTo(i);
        Run r = TakeRun(all[size_t(from)], &at[size_t(from)]);
        r.rank = from;
        timed_ += Format("| %s | %d | %.3f |\n", pending[i].label.c_str(), from, r.cpuSeconds);
        pending[i].done(r);
    }
}

std::string RenderQueue::RankOf(const Run& r) const {
    return ranks_ ? Format(" on rank %d", r.rank) : std::string();
}

std::string RenderQueue::RanksSection() const {
    if (!ranks_) return "";
    return Format(
               "\n## Ranks\n\nThe renders were spread over %d ranks (MPI): each reference over "
               "all of them as one image, each timed render whole on one rank, which measured "
               "its CPU seconds in its own process (ranks sharing a machine's cores slow each "
               "other). Rank 0 gathered the results and wrote these files.\n\n| render | rank "
               "| CPU seconds |\n|---|---|---|\n",
               ranks_->Size()) +
           timed_;
}

Table& Table::Row() {
    rows_.emplace_back();
    return *this;
}
Table& Table::Add(const std::string& v) {
    rows_.back().push_back(v);
    return *this;
}
Table& Table::Add(double v) {
    rows_.back().push_back(std::isfinite(v) ? Format("%.6g", v) : std::string("nan"));
    return *this;
}
namespace {
// RFC 4180: a value holding a comma, quote or line break is quoted, its quotes doubled (an
// ablation label such as "reliable, no clamping" had split into two columns).
std::string CsvField(const std::string& v) {
    if (v.find_first_of(",\"\n\r") == std::string::npos) return v;
    std::string q = "\"";
    for (char ch : v) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
    return q + "\"";
}

// The values of one CSV line as CsvField wrote them; false on an unterminated quote.
bool SplitCsvLine(const std::string& line, std::vector<std::string>* out) {
    out->clear();
    std::string v;
    bool quoted = false;
    for (size_t i = 0; i < line.size(); ++i) {
        const char ch = line[i];
        if (quoted) {
            if (ch != '"') {
                v += ch;
            } else if (i + 1 < line.size() && line[i + 1] == '"') {
                v += '"', ++i;
            } else {
                quoted = false;
            }
        } else if (ch == '"') {
            quoted = true;
        } else if (ch == ',') {
            out->push_back(v), v.clear();
        } else {
            v += ch;
        }
    }
    out->push_back(v);
    return !quoted;
}
}  // namespace

void Table::Write(const std::string& path) const {
    std::string text;
    for (size_t i = 0; i < columns_.size(); ++i) text += (i ? "," : "") + CsvField(columns_[i]);
    text += "\n";
    for (const auto& row : rows_) {
        if (row.size() != columns_.size())
            throw std::logic_error("table row of " + std::to_string(row.size()) + " values for " +
                                   std::to_string(columns_.size()) + " columns in " + path);
        for (size_t i = 0; i < row.size(); ++i) text += (i ? "," : "") + CsvField(row[i]);
        text += "\n";
    }
    WriteText(path, text);
}

Table Table::Read(const std::string& path, std::vector<std::string> columns) {
    std::ifstream in(path);
    if (!in) throw InputError(path, "cannot be read");
    Table t(std::move(columns));
    std::string header;
    for (size_t i = 0; i < t.columns_.size(); ++i)
        header += (i ? "," : "") + CsvField(t.columns_[i]);
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        ++number;
        if (number == 1) {
            if (line != header)
                throw InputError(path + ":1", "header is '" + line + "', expected '" + header +
                                                  "' (written by another version?)");
            continue;
        }
        if (line.empty()) continue;
        t.Row();
        std::vector<std::string> values;
        if (!SplitCsvLine(line, &values))
            throw InputError(path + ":" + std::to_string(number), "unterminated quoted value");
        for (const std::string& v : values) t.Add(v);
        if (t.rows_.back().size() != t.columns_.size())
            throw InputError(path + ":" + std::to_string(number),
                             std::to_string(t.rows_.back().size()) + " values, expected " +
                                 std::to_string(t.columns_.size()));
    }
    return t;
}

void WriteText(const std::string& path, const std::string& text) {
    const std::string tmp = path + ".tmp-" + std::to_string(getpid());
    {
        std::ofstream f(tmp, std::ios::binary);
        f << text;
        if (!f.good()) throw InputError(path, "cannot write");
    }
    fs::rename(tmp, path);
}

void Draw(const Plot& p) {
    static const char* kColors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a",
                                    "#66a61e", "#e6ab02", "#a6761d", "#666666"};
    const std::string tmpPng = p.png + ".tmp-" + std::to_string(getpid()) + ".png";
    std::string gp;
    gp += "set terminal pngcairo size 900,600 enhanced font 'sans,11'\n";
    gp += "set output '" + tmpPng + "'\n";
    gp += "set datafile separator ','\n";
    gp += "set key outside right top\nset grid\n";
    // Names such as scene files carry underscores, which enhanced text would take as subscripts.
    gp += "set title \"" + p.title + "\" noenhanced\n";
    gp += "set xlabel \"" + p.xLabel + "\"\nset ylabel \"" + p.yLabel + "\"\n";
    if (p.logX) gp += "set logscale x\n";
    if (p.logY) gp += "set logscale y\n";
    for (const std::string& e : p.extra) gp += e + "\n";
    gp += "plot ";
    for (size_t i = 0; i < p.series.size(); ++i) {
        const Series& s = p.series[i];
        const std::string y =
            s.filter.empty() ? Format("%d", s.yColumn)
                             : Format("((%s) ? column(%d) : 1/0)", s.filter.c_str(), s.yColumn);
        gp += Format(
            "%s'%s' skip 1 using %d:%s with linespoints lw 2 pt 7 lc rgb '%s' title \"%s\" "
            "noenhanced",
            i ? ", \\\n     " : "", s.csv.c_str(), s.xColumn, y.c_str(), kColors[i % 8],
            s.title.c_str());
    }
    gp += "\n";
    const std::string script = fs::path(p.png).replace_extension(".gp").string();
    WriteText(script, gp);
    const std::string cmd = "gnuplot '" + script + "' 2>&1";
    FILE* pipe = popen(cmd.c_str(), "r");
    if (!pipe) throw InputError("gnuplot", "cannot run (install gnuplot-nox: scripts/setup.sh)");
    std::string out;
    char buf[512];
    while (fgets(buf, sizeof buf, pipe)) out += buf;
    const int status = pclose(pipe);
    if (status != 0 || !fs::exists(tmpPng)) {
        std::error_code ec;
        fs::remove(tmpPng, ec);
        throw InputError(script,
                         "gnuplot failed (is gnuplot-nox installed? scripts/setup.sh "
                         "installs it): " +
                             out);
    }
    fs::rename(tmpPng, p.png);
}

std::string Format(const char* fmt, ...) {
    va_list a, b;
    va_start(a, fmt);
    va_copy(b, a);
    const int n = std::vsnprintf(nullptr, 0, fmt, a);
    va_end(a);
    std::string s(size_t(std::max(n, 0)) + 1, '\0');
    std::vsnprintf(s.data(), s.size(), fmt, b);
    va_end(b);
    s.resize(size_t(std::max(n, 0)));
    return s;
}

void Say(const char* fmt, ...) {
    va_list a;
    va_start(a, fmt);
    std::vprintf(fmt, a);
    va_end(a);
    std::printf("\n");
    std::fflush(stdout);
}

double InterpolateLogLog(const std::vector<double>& xs, const std::vector<double>& ys, double x,
                         bool* extrapolated) {
    const size_t n = xs.size();
    if (n == 0) return NAN;
    if (n == 1) {
        *extrapolated = x != xs[0];
        return ys[0];
    }
    size_t i = 1;
    while (i + 1 < n && xs[i] < x) ++i;
    *extrapolated = x < xs.front() || x > xs.back();
    const double lx0 = std::log(xs[i - 1]), lx1 = std::log(xs[i]);
    const double ly0 = std::log(ys[i - 1]), ly1 = std::log(ys[i]);
    const double t = lx1 != lx0 ? (std::log(x) - lx0) / (lx1 - lx0) : 0.0;
    return std::exp(ly0 + t * (ly1 - ly0));
}

Image SideBySide(const std::vector<const Image*>& images, Rect r, int scale) {
    constexpr int kGap = 2;
    const int pw = r.w * scale, ph = r.h * scale;
    const int n = int(images.size());
    Image out(n * pw + (n - 1) * kGap, ph, 3, 1.0f);
    for (int i = 0; i < n; ++i)
        for (int y = 0; y < ph; ++y)
            for (int x = 0; x < pw; ++x) {
                const float* src = images[i]->At(r.x + x / scale, r.y + y / scale);
                float* dst = out.At(i * (pw + kGap) + x, y);
                for (int k = 0; k < 3; ++k) dst[k] = src[k];
            }
    return out;
}

Image Crop(const Image& img, Rect r) {
    Image out(r.w, r.h, img.channels);
    for (int y = 0; y < r.h; ++y)
        for (int x = 0; x < r.w; ++x)
            for (int k = 0; k < img.channels; ++k) out.At(x, y)[k] = img.At(r.x + x, r.y + y)[k];
    return out;
}

}  // namespace texcache::experiments
