// SPDX-License-Identifier: Apache-2.0
// What every `texcache experiment` shares: scenes and references, timed renders (best of n, in
// this process, so ratios compare runs made under the same machine load), CSV tables, gnuplot
// PNG plots and the markdown summary. Everything is written with a temporary file + rename.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "renderer/distributed/rank_group.h"
#include "renderer/image/image.h"
#include "renderer/render.h"
#include "renderer/scene/render_scene.h"
#include "renderer/scene/scene.h"

namespace texcache::experiments {

/// Options common to every experiment.
struct Setup {
    std::string outDir;
    std::string scenesDir;
    bool quick = false;  ///< test size: small images, few budgets, under a minute on 2 cores
    /// Comma-separated subset to run (empty: all): speed-vs-error case labels, temporal scenes.
    std::string only;
    /// speed-vs-error: comma-separated methods to run (empty: all), e.g. per-hit,ts-hits; the
    /// other methods' rows of an earlier run in the same directory are kept.
    std::string methods;
    /// speed-vs-error: camera samples per pixel (0: the experiment's default, 16).
    int cameraSpp = 0;
    /// temporal: also Reliable (demodulation on) with the paper's alpha 0.1, with the glossy
    /// jitter cap at 0 and 16 pixels and without clamping (issue 21: why Reliable trails the
    /// baseline on some scenes).
    bool ablation = false;
    /// equal-time: the directory of scenes it renders (validation/ beside scenes/ by default).
    std::string sceneSet;
    /// The ranks an experiment that spreads its renders shares them with (RenderQueue); null or
    /// of one rank: this process renders everything.
    RankGroup* ranks = nullptr;
    /// Only check the options an experiment that spreads its renders takes (and throw
    /// InputError as a run would), rendering and writing nothing: over many ranks every rank
    /// checks before any of them starts, so that bad input fails as one line, not one a rank.
    bool checkOnly = false;
};

/// A scene file loaded and built once for a given integrator family. Not movable: the
/// RenderScene refers to the Scene beside it.
struct LoadedScene {
    std::string name;  ///< file stem, e.g. "car"
    Scene scene;
    std::unique_ptr<RenderScene> rs;
    /// The texture-space cache its timed renders share (see TimedRender).
    std::unique_ptr<TextureSpaceCache> cache;
    /// This process rendered it once already (Embree tessellated the patches its rays reached).
    bool warmed = false;
    LoadedScene() = default;
    LoadedScene(const LoadedScene&) = delete;
    LoadedScene& operator=(const LoadedScene&) = delete;
};
/// Loads scenes/`file`; `edit`, if given, changes the scene (e.g. its camera) before it is built.
std::unique_ptr<LoadedScene> LoadForExperiment(const Setup& s, const std::string& file,
                                               bool needLights,
                                               const std::function<void(Scene*)>& edit = {});

/// Render options from a scene's settings at a given size and integrator.
RenderOptions BaseOptions(const Scene& scene, IntegratorKind integrator, int width, int height);

/// The cache of `ls` emptied for a render with options `o`: Reconfigure clears it (a memset of
/// its two tables), or a new cache is made when the layout changed. Null without texture space.
TextureSpaceCache* FreshCache(LoadedScene& ls, const RenderOptions& o);

/// One timed render: the image, its render seconds (best of `repeats`) and statistics.
struct Run {
    Image image;
    double seconds = 0.0;     ///< wall clock of the render with the least CPU time
    double cpuSeconds = 0.0;  ///< its CPU time (all threads): the cost measure of the experiments
    RenderStats stats;
    int rank = 0;  ///< the rank that rendered and timed it (RenderQueue)
};
/// With `warmUp`, one untimed render first: Embree tessellates subdivision patches lazily on
/// first hit, and the first render of a scene would pay for it. Texture-space renders start
/// from an empty cache every time, but reuse the scene's cache storage when its layout allows
/// (TextureSpaceCache::Reconfigure): mapping fresh cache memory is a one-time set-up cost of a
/// process, like building the BVH, and is not counted. The best of `repeats` renders by CPU
/// time, and with more than one, of up to 5 while the best is under a second.
Run TimedRender(LoadedScene& ls, const RenderOptions& o, int repeats = 1, bool warmUp = false);

/// The timed renders of an experiment spread over the ranks of a job (Setup::ranks): each render
/// runs whole on one rank, which times it (CPU seconds of its own process), and its result
/// reaches rank 0, which alone goes on to write the experiment's files. Alone (no ranks, or
/// one), a render runs as it is added, exactly as TimedRender. Every rank adds the same renders
/// in the same order and calls Flush at the same points.
class RenderQueue {
public:
    explicit RenderQueue(const Setup& s);
    /// Whether this process goes on with the results and writes the files (rank 0, or alone).
    bool Root() const { return !ranks_ || ranks_->Rank() == 0; }
    /// TimedRender(ls, o, repeats, warmUp) named `label`; `done` receives it on rank 0 (alone:
    /// at once). Over many ranks a rank also warms up before its first render of a scene.
    void Add(const std::string& label, LoadedScene& ls, const RenderOptions& o, int repeats,
             bool warmUp, std::function<void(Run&)> done);
    /// Over many ranks: renders the ones added since the last Flush, dealt over the ranks back
    /// and forth (0, 1, ..., N-1, N-1, ..., 0, 0, 1, ...), then calls their `done` on rank 0 in
    /// the order they were added. Every rank calls it; the scenes and whatever `done` refers to
    /// must live until then.
    void Flush();
    /// " on rank R" for a progress line about `r` (empty alone).
    std::string RankOf(const Run& r) const;
    /// Markdown naming the rank that timed each render (empty alone).
    std::string RanksSection() const;

private:
    struct Pending {
        std::string label;
        LoadedScene* scene;
        RenderOptions options;
        int repeats;
        bool warmUp;
        std::function<void(Run&)> done;
    };
    RankGroup* ranks_ = nullptr;
    std::vector<Pending> pending_;
    std::string timed_;  ///< RanksSection's rows, as the results arrive
};

/// A high-sample reference, cached as OUT/ref_<tag>.exr and reused when it exists at this size
/// (references cost minutes; re-running an experiment should not). Over many ranks
/// (Setup::ranks) it is one render over all of them, written by rank 0; the other ranks get an
/// empty image.
Image Reference(const Setup& s, const std::string& tag, const RenderScene& rs,
                const RenderOptions& o);

/// A CSV table built row by row; numbers printed with 6 significant digits.
class Table {
public:
    explicit Table(std::vector<std::string> columns) : columns_(std::move(columns)) {}
    Table& Row();
    Table& Add(const std::string& v);
    Table& Add(double v);
    void Write(const std::string& path) const;
    size_t NumRows() const { return rows_.size(); }
    const std::vector<std::string>& RowAt(size_t i) const { return rows_[i]; }
    /// Reads a CSV that Write() made with these columns; throws InputError naming the file and
    /// line when the header differs or a row has the wrong number of values.
    static Table Read(const std::string& path, std::vector<std::string> columns);

private:
    std::vector<std::string> columns_;
    std::vector<std::vector<std::string>> rows_;
};

/// A line plot drawn by gnuplot (pngcairo) from a CSV written beside it.
struct Series {
    std::string title;
    std::string csv;       ///< data file (comma separated, with a header line)
    int xColumn, yColumn;  ///< 1-based columns
    std::string filter;    ///< optional gnuplot condition on the row, e.g. "strcol(2) eq 'car'"
};
struct Plot {
    std::string png, title, xLabel, yLabel;
    bool logX = false, logY = false;
    std::vector<Series> series;
    std::vector<std::string> extra;  ///< further gnuplot commands (e.g. reference lines)
};
/// Writes the gnuplot script beside the PNG and runs gnuplot; throws if it is missing or fails.
void Draw(const Plot& p);

/// Writes text atomically.
void WriteText(const std::string& path, const std::string& text);
/// printf into a std::string.
std::string Format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
/// Progress line on stdout (flushed: experiments run for minutes).
void Say(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

/// Log-log interpolation of y at x along a curve of increasing x (extrapolated linearly in
/// log-log outside the range; `extrapolated` says so).
double InterpolateLogLog(const std::vector<double>& xs, const std::vector<double>& ys, double x,
                         bool* extrapolated);

/// A pixel rectangle of an image.
struct Rect {
    int x = 0, y = 0, w = 0, h = 0;
};
/// The crop `r` of each image, magnified `scale` times (nearest neighbour: pixels stay visible),
/// side by side with a white 2-pixel gap.
Image SideBySide(const std::vector<const Image*>& images, Rect r, int scale);
/// The crop `r` of an image.
Image Crop(const Image& img, Rect r);

// The experiments (each returns a process exit code).
int SpeedVsError(const Setup& s);
int CacheSize(const Setup& s);
int FilterSize(const Setup& s);
int Threads(const Setup& s);
int LodBias(const Setup& s);
int Temporal(const Setup& s);
int Disocclusion(const Setup& s);
int Cpis(const Setup& s);
int Stereo(const Setup& s);
int StereoStore(const Setup& s);

/// A case of the stereo experiments (stereo, stereo-store): its label, scene file and integrator.
struct StereoCase {
    const char* label;
    const char* scene;
    IntegratorKind integrator;
};
/// The stereo experiments' cases: AO on the car, path-traced diffuse light on sunlit.
std::vector<StereoCase> StereoCases();
/// A stereo case's scene, loaded for the experiment (its lights unless AO).
std::unique_ptr<LoadedScene> LoadStereoCase(const Setup& s, const StereoCase& c);
/// The stereo experiments' options for a case: 4 spp, 16 AO rays, two bounces, texture space.
RenderOptions StereoOptions(const Scene& scene, IntegratorKind integrator, int width, int height);
int Blur(const Setup& s);
int EqualTime(const Setup& s);

}  // namespace texcache::experiments
