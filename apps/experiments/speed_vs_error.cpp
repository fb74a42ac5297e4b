// SPDX-License-Identifier: Apache-2.0
// `texcache experiment speed-vs-error`: relMSE against wall-clock time and against rays, per-hit
// shading vs texture-space shading with each filter, on the default scene (car) and the chess
// scene, for ambient occlusion, diffuse indirect (path tracing) and area-light soft shadows.
//
// Budgets: see ApplyBudget. Equal-time ratios interpolate the per-hit curve in log-log at each
// texture-space point's time.
#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include "experiment_util.h"
#include "renderer/image/metrics.h"
#include "texcache/error.h"

namespace texcache::experiments {

namespace {

namespace fs = std::filesystem;

struct Method {
    std::string name;
    bool texture;
    TextureFilterKind filter;
    int radius = -1;  ///< footprint (2r+1)^2; -1: the filter's default
    /// AO: the paper's samples on texel grids, or shading at the camera hits, binned.
    TextureSamples samples = TextureSamples::Grid;
};

struct Case {
    std::string scene;  ///< file in scenes/
    IntegratorKind integrator;
    std::string label;
    std::vector<Method> methods;
    bool cacheDirect = false;    ///< path: diffuse direct light cached too (--cached-light all)
    float lensRadius = 0.0f;     ///< > 0: the scene's camera becomes a thin lens...
    float focusDistance = 0.0f;  ///< ...focused at this distance
};

struct Point {
    double seconds, rays, relmse, image;  ///< relMSE against the shading and image references
};

const Method kPerHit{"per-hit", false, TextureFilterKind::None};
const Method kNone{"ts-none", true, TextureFilterKind::None};
const Method kNormal{"ts-normal", true, TextureFilterKind::Normal};
// The paper's 13x13 blurs AO detail of the car (a bias floor near 0.007 relMSE: the ts-normal
// curve of `texcache experiment speed-vs-error --only car-ao --out DIR`); 7x7 trades some of the
// variance reduction for a quarter of that blur.
const Method kNormal7{"ts-normal-7x7", true, TextureFilterKind::Normal, 3};
const Method kGaussian{"ts-gaussian", true, TextureFilterKind::Gaussian};
const Method kRegression{"ts-regression", true, TextureFilterKind::Regression};
const Method kSoftShadow{"ts-softshadow", true, TextureFilterKind::SoftShadow};
// Shading at the camera's hits, binned per texel of a coarser level (TextureSamples::Hits, the
// default of `--shading texture` for AO, path tracing and soft direct light): AO, or a path
// tracer's (or the direct integrator's) diffuse light.
const Method kHits{"ts-hits", true, TextureFilterKind::Normal, -1, TextureSamples::Hits};
// Path cases: the per-hit terms alone. The renders of a case share their camera rays and the
// per-hit light paths of a budget, so a texture-space render whose cached term is all but
// converged (kConvergedPaths paths per cached sample) at budget 1 has the error of the terms
// that stay per hit (glossy materials, and direct light unless it is cached): no method that
// caches only the cached term can go below it at that budget.
const char* const kUncachedOnly = "uncached-only";
constexpr int kConvergedPaths = 64;

// The knob a budget turns for a method and integrator. AO: rays per shading point at 4 camera
// samples (per hit: AO rays per hit; texture space: AO rays per cached sample). Path tracing and
// direct lighting: camera samples per pixel for both (glossy materials and the unshadowed light
// stay per hit in texture space too), with 2 paths + NEE samples per cached diffuse sample and 4
// shadow rays per cached visibility sample.
// Every render of a case traces the same camera rays: CameraSpp() samples per pixel with the
// same seed (Munkberg et al. Fig. 7 fix 16 primary positions likewise). Budgets are shading
// samples: AO rays per hit or per cached sample; for the direct and path integrators, light paths
// per camera hit (--hit-samples) and per cached sample. The shading reference traces the same
// camera rays with many shading samples, so its difference to a render is shading error alone;
// the image reference (many camera samples) also counts the edge noise of the camera samples,
// which no shading method can remove.
//
// The camera sample count sets how often a texel is reused: per-hit shading pays for every
// camera sample, texture space for every texel (eq. 1 picks 1-4 texels per pixel). --camera-spp
// changes it (default 4).
int CameraSpp(const Setup& s) {
    return s.cameraSpp > 0 ? s.cameraSpp : 4;
}

void ApplyBudget(RenderOptions* o, const Method& m, int budget, int cameraSpp) {
    o->spp = cameraSpp;
    if (o->integrator == IntegratorKind::AO) {
        o->aoSamples = budget;
    } else {
        o->hitSamples = budget;
        o->texture.indirectSamples = budget;
        o->texture.shadowSamples = budget;
    }
    o->texture.enabled = m.texture;
    o->texture.filter = m.filter;
    o->texture.radius = m.radius;
    o->texture.samples = m.samples;
}

std::vector<int> Budgets(const Setup& s, bool texture) {
    if (s.quick) return {1, 4};
    if (texture) return {1, 2, 4, 8, 16};
    return {1, 2, 4, 8, 16, 32, 64};
}

/// Best equal-time ratio per-hit relMSE / method relMSE over the method's points (per-hit
/// interpolated log-log at the method's seconds).
struct Ratio {
    double best = 0.0, at = 0.0, method = 0.0, perHit = 0.0;
    bool extrapolated = false;
};
Ratio EqualTimeRatio(const std::vector<Point>& perHit, const std::vector<Point>& method,
                     bool image) {
    std::vector<double> ht, he;
    for (const Point& p : perHit) ht.push_back(p.seconds), he.push_back(image ? p.image : p.relmse);
    Ratio r;
    for (const Point& p : method) {
        bool ex;
        const double e = image ? p.image : p.relmse;
        const double h = InterpolateLogLog(ht, he, p.seconds, &ex);
        if (h / e > r.best) r = {h / e, p.seconds, e, h, ex};
    }
    return r;
}

using Curves = std::map<std::string, std::map<std::string, std::vector<Point>>>;

/// The goals, case by case: each texture-space method at or below per-hit (interpolated
/// at its CPU time) at every budget; at least 3x below it at the smallest budget on the AO and
/// diffuse cases; relMSE at the largest budget at most 1/8 of the smallest's (convergence). For
/// path cases, also the bound the per-hit terms put on any method (kUncachedOnly).
std::string GoalSection(const std::vector<std::string>& labels, Curves& curves,
                        std::map<std::string, std::vector<std::string>>& methodOrder,
                        const std::map<std::string, double>& uncachedFloor) {
    std::string md =
        "\n## The goals (issue 16)\n\n"
        "Per texture-space method: at how many of its budgets its relMSE is at or below "
        "per-hit's at the same CPU time (interpolated log-log; *x* marks an extrapolation), the "
        "ratio per-hit / method at its smallest budget (goal: at least 3x on the AO and diffuse "
        "cases), and relMSE at its largest budget over its smallest (goal: at most 1/8 = 0.125; "
        "the CPU-time span of the two in brackets).\n\n"
        "| case | method | at or below per-hit | smallest-budget ratio | largest / smallest "
        "budget relMSE |\n|---|---|---|---|---|\n";
    std::string notes;
    for (const std::string& label : labels) {
        auto& cc = curves[label];
        const std::vector<Point>& ph = cc["per-hit"];
        std::vector<double> ht, he;
        for (const Point& p : ph) ht.push_back(p.seconds), he.push_back(p.relmse);
        const bool costly = label.find("-ao") != std::string::npos ||
                            label.find("diffuse") != std::string::npos ||
                            label == "sunlit-indirect";
        double bestFirst = 0.0, bestConv = 1e30;
        int everyBudget = 0;
        for (const std::string& m : methodOrder[label]) {
            const std::vector<Point>& pts = cc[m];
            if (m == "per-hit" || pts.empty()) continue;
            int wins = 0;
            bool anyEx = false;
            for (const Point& p : pts) {
                bool ex;
                const double h = InterpolateLogLog(ht, he, p.seconds, &ex);
                anyEx |= ex;
                wins += p.relmse <= h;
            }
            bool ex;
            const double first =
                InterpolateLogLog(ht, he, pts.front().seconds, &ex) / pts.front().relmse;
            const double conv = pts.back().relmse / pts.front().relmse;
            bestFirst = std::max(bestFirst, first), bestConv = std::min(bestConv, conv);
            everyBudget += wins == int(pts.size());
            md += Format("| %s | %s | %d of %d%s | %.2fx%s | %.3f (%.1fx time) |\n", label.c_str(),
                         m.c_str(), wins, int(pts.size()), anyEx ? " x" : "", first, ex ? " x" : "",
                         conv, pts.back().seconds / pts.front().seconds);
        }
        notes += Format(
            "- %s: %s; smallest-budget ratio %.2fx%s; best convergence %.3f (%s)", label.c_str(),
            everyBudget
                ? Format("%d method(s) at or below per-hit at every budget", everyBudget).c_str()
                : "no method at or below per-hit at every budget",
            bestFirst, costly ? (bestFirst >= 3.0 ? " (goal 3x met)" : " (goal 3x NOT met)") : "",
            bestConv, bestConv <= 0.125 ? "goal met" : "goal NOT met");
        const auto f = uncachedFloor.find(label);
        if (f != uncachedFloor.end() && !ph.empty())
            notes += Format(
                "; the per-hit terms alone give relMSE %.5f at budget 1 against per-hit's %.5f: "
                "the cached term is at most %.0f%% of per-hit's error there, and no method "
                "caching it can beat per-hit by more than %.2fx at that budget",
                f->second, ph.front().relmse,
                100.0 * std::max(0.0, 1.0 - f->second / ph.front().relmse),
                ph.front().relmse / f->second);
        notes += "\n";
    }
    return md + "\n" + notes;
}

}  // namespace

int SpeedVsError(const Setup& s) {
    const std::vector<Case> cases = {
        {"car.json",
         IntegratorKind::AO,
         "car-ao",
         {kPerHit, kHits, kNone, kNormal, kNormal7, kGaussian, kRegression}},
        {"chess.json",
         IntegratorKind::AO,
         "chess-ao",
         {kPerHit, kHits, kNone, kNormal, kGaussian, kRegression}},
        {"car.json",
         IntegratorKind::Path,
         "car-indirect",
         {kPerHit, kHits, kNone, kNormal, kGaussian, kRegression}},
        {"chess.json",
         IntegratorKind::Path,
         "chess-indirect",
         {kPerHit, kHits, kNone, kNormal, kGaussian, kRegression}},
        // The same two with diffuse direct light cached and filtered too (--cached-light all).
        {"car.json",
         IntegratorKind::Path,
         "car-diffuse",
         {kPerHit, kHits, kNone, kNormal, kRegression},
         true},
        {"chess.json",
         IntegratorKind::Path,
         "chess-diffuse",
         {kPerHit, kHits, kNone, kNormal, kRegression},
         true},
        // The diffuse-indirect scene: a clay car under a sun (a delta light: direct lighting has
        // no noise but shadow-edge aliasing), so indirect light is what the budget buys.
        {"sunlit.json",
         IntegratorKind::Path,
         "sunlit-indirect",
         {kPerHit, kHits, kNone, kNormal, kGaussian, kRegression}},
        // Direct light alone, soft shadows of the area light: the paper's axis-aligned filter on
        // the grid, and the light binned at the hits (cacheDirect: the direct integrator's light
        // is all direct).
        {"chess.json",
         IntegratorKind::Direct,
         "chess-softshadow",
         {kPerHit, kHits, kSoftShadow},
         true},
        // A camera the bundled scenes do not have (issue 16: "the default car with a thin
        // lens"): camera samples land on different texels through each lens point, and the
        // blurred surfaces take texels of their circle of confusion (RenderScene::Interact).
        {"car.json",
         IntegratorKind::AO,
         "car-lens-ao",
         {kPerHit, kHits, kNone, kNormal},
         false,
         0.08f,
         4.5f},
    };
    const int repeats = s.quick ? 1 : 2;
    const std::vector<std::string> columns = {
        "case", "method", "budget",         "spp",          "rays_per_point", "seconds",
        "rays", "relmse", "samples_shaded", "relmse_image", "cpu_seconds"};
    Table table(columns);
    // Curves per case and method, in the order they were measured.
    std::map<std::string, std::map<std::string, std::vector<Point>>> curves;
    std::map<std::string, std::vector<std::string>> methodOrder;
    std::map<std::string, double> uncachedFloor;  // case -> relMSE of the per-hit terms alone
    auto addPoint = [&](const std::string& label, const std::string& method, const Point& p) {
        auto& m = curves[label];
        if (!m.count(method)) methodOrder[label].push_back(method);
        m[method].push_back(p);
    };

    std::vector<Case> selected;
    auto isSelected = [&](const std::string& label) {
        return s.only.empty() || ("," + s.only + ",").find("," + label + ",") != std::string::npos;
    };
    auto isMethodSelected = [&](const std::string& method) {
        return s.methods.empty() ||
               ("," + s.methods + ",").find("," + method + ",") != std::string::npos;
    };
    for (const Case& c : cases)
        if (isSelected(c.label)) selected.push_back(c);
    if (selected.empty()) {
        std::string valid;
        for (const Case& c : cases) valid += (valid.empty() ? "" : ", ") + c.label;
        throw InputError("--only", "no case named '" + s.only + "' (valid: " + valid + ")");
    }
    if (!s.methods.empty()) {
        std::set<std::string> valid;
        for (const Case& c : selected)
            for (const Method& m : c.methods) valid.insert(m.name);
        std::stringstream ss(s.methods);
        for (std::string name; std::getline(ss, name, ',');)
            if (!valid.count(name)) {
                std::string list;
                for (const std::string& v : valid) list += (list.empty() ? "" : ", ") + v;
                throw InputError("--methods", "no method named '" + name +
                                                  "' in these cases (valid: " + list + ")");
            }
    }
    if (s.checkOnly) return 0;
    // A run of some cases or methods keeps the other rows of an earlier run in the same
    // directory: the CSV and summary then cover everything measured so far. The per-hit terms'
    // bound (kUncachedOnly) is measured again only with every method.
    const std::string csv = (fs::path(s.outDir) / "speed_vs_error.csv").string();
    RenderQueue queue(s);
    if ((!s.only.empty() || !s.methods.empty()) && fs::exists(csv)) {
        const Table old = Table::Read(csv, columns);
        size_t kept = 0;
        for (size_t i = 0; i < old.NumRows(); ++i) {
            const std::vector<std::string>& r = old.RowAt(i);
            const bool rerun = r[1] == kUncachedOnly ? s.methods.empty() : isMethodSelected(r[1]);
            if (isSelected(r[0]) && rerun) continue;
            table.Row();
            for (const std::string& v : r) table.Add(v);
            if (r[1] == kUncachedOnly)
                uncachedFloor[r[0]] = std::stod(r[7]);
            else
                addPoint(r[0], r[1],
                         {std::stod(r[10]), std::stod(r[6]), std::stod(r[7]), std::stod(r[9])});
            ++kept;
        }
        if (kept && queue.Root())
            Say("[speed-vs-error] keeping %zu rows not rerun from %s", kept, csv.c_str());
    }

    std::map<std::string, std::unique_ptr<LoadedScene>> scenes;
    for (const Case& c : selected) {
        const bool lights = c.integrator != IntegratorKind::AO;
        const std::string key = c.scene + (lights ? "+lights" : "") +
                                (c.lensRadius > 0.0f ? Format("+lens%g", c.lensRadius) : "");
        if (!scenes.count(key))
            scenes.emplace(key, LoadForExperiment(s, c.scene, lights, [&](Scene* scene) {
                               if (c.lensRadius <= 0.0f) return;
                               scene->camera.lensRadius = c.lensRadius;
                               scene->camera.focusDistance = c.focusDistance;
                           }));
        LoadedScene& ls = *scenes.at(key);
        const bool chess = c.scene == "chess.json";  // 4:3; the others are 16:9
        const int W = s.quick ? 96 : 480, H = s.quick ? (chess ? 72 : 54) : (chess ? 360 : 270);
        RenderOptions base = BaseOptions(ls.scene, c.integrator, W, H);
        // Image reference: many camera samples. Shading reference: the renders' camera rays.
        RenderOptions imageOpt = base, shadingOpt = base;
        shadingOpt.spp = CameraSpp(s);
        if (c.integrator == IntegratorKind::AO) {
            imageOpt.spp = s.quick ? 16 : 64;
            imageOpt.aoSamples = s.quick ? 16 : 64;
            // The same shading rays per pixel at any camera sample count (8192 at full size).
            shadingOpt.aoSamples = std::max(1, (s.quick ? 1024 : 8192) / CameraSpp(s));
        } else {
            imageOpt.spp = s.quick ? 64 : 1024;
            shadingOpt.hitSamples = std::max(1, (s.quick ? 128 : 2048) / CameraSpp(s));
        }
        if (queue.Root()) Say("[speed-vs-error] %s (%dx%d)", c.label.c_str(), W, H);
        // One pair of references per scene and integrator (car-diffuse shares car-indirect's).
        const std::string kind = c.integrator == IntegratorKind::AO     ? "ao"
                                 : c.integrator == IntegratorKind::Path ? "indirect"
                                                                        : "softshadow";
        // The scene part of the label: car-diffuse shares car-indirect's references.
        const std::string refTag = c.label.substr(0, c.label.rfind('-')) + "-" + kind;
        const Image ref =
            Reference(s, Format("%s-shading_%dx%d_%dspp", refTag.c_str(), W, H, CameraSpp(s)),
                      *ls.rs, shadingOpt);
        const Image refImage =
            Reference(s, Format("%s_%dx%d", refTag.c_str(), W, H), *ls.rs, imageOpt);

        for (const Method& m : c.methods) {
            if (!isMethodSelected(m.name)) continue;
            const std::vector<int> budgets = Budgets(s, m.texture);
            for (int b : budgets) {
                RenderOptions o = base;
                ApplyBudget(&o, m, b, CameraSpp(s));
                o.texture.cacheDirect = c.cacheDirect;
                const bool last = b == budgets.back();
                queue.Add(
                    Format("%s %s budget %d", c.label.c_str(), m.name.c_str(), b), ls, o, repeats,
                    b == budgets.front(), [&, label = c.label, m, b, o, last](Run& r) {
                        const double e = RelMSE(r.image, ref), eImage = RelMSE(r.image, refImage);
                        const double rays = double(r.stats.TotalRays());
                        addPoint(label, m.name, {r.cpuSeconds, rays, e, eImage});
                        table.Row()
                            .Add(label)
                            .Add(m.name)
                            .Add(b)
                            .Add(o.spp)
                            .Add(b)
                            .Add(r.seconds)
                            .Add(rays)
                            .Add(e)
                            .Add(double(r.stats.cache.samplesShaded))
                            .Add(eImage)
                            .Add(r.cpuSeconds);
                        Say("  %-14s budget %3d: %7.3f s CPU%s, %6.1f Mrays, relMSE %.5f (image "
                            "%.5f)",
                            m.name.c_str(), b, r.cpuSeconds, queue.RankOf(r).c_str(), rays * 1e-6,
                            e, eImage);
                        if (last)
                            WriteImage((fs::path(s.outDir) /
                                        Format("sve_%s_%s.png", label.c_str(), m.name.c_str()))
                                           .string(),
                                       r.image);
                    });
            }
        }
        if (c.integrator == IntegratorKind::Path && s.methods.empty()) {
            RenderOptions o = base;
            ApplyBudget(&o, kNormal, 1, CameraSpp(s));
            o.texture.cacheDirect = c.cacheDirect;
            o.texture.indirectSamples = o.texture.shadowSamples = kConvergedPaths;
            queue.Add(Format("%s %s", c.label.c_str(), kUncachedOnly), ls, o, 1, false,
                      [&, label = c.label, o](Run& r) {
                          const double e = RelMSE(r.image, ref);
                          uncachedFloor[label] = e;
                          table.Row()
                              .Add(label)
                              .Add(kUncachedOnly)
                              .Add(1)
                              .Add(o.spp)
                              .Add(kConvergedPaths)
                              .Add(r.seconds)
                              .Add(double(r.stats.TotalRays()))
                              .Add(e)
                              .Add(double(r.stats.cache.samplesShaded))
                              .Add(RelMSE(r.image, refImage))
                              .Add(r.cpuSeconds);
                          Say("  %-14s budget   1: relMSE %.5f (the per-hit terms alone)",
                              kUncachedOnly, e);
                      });
        }
        // Over many ranks the case's renders run here, spread; alone they already ran.
        queue.Flush();
    }
    // Rank 0 writes the files: the other ranks' results are in its table.
    if (!queue.Root()) return 0;
    table.Write(csv);

    std::string md = "# Speed vs error\n\n";
    md += Format(
        "Every render of a case traces the same camera rays (%d samples per pixel, same seed, as "
        "Munkberg et al. fix the primary positions in Fig. 7); the budget is shading samples: AO "
        "rays per hit or per cached sample, or light paths per camera hit (`--hit-samples`) and "
        "per cached sample. **relMSE** (eps = 0.001) is against a reference with the same camera "
        "rays and many shading samples: shading error alone. **image relMSE** is against a "
        "converged image (many camera samples): it adds the edge noise of %d camera samples, "
        "the same for every method. Time is the render's CPU time (all threads; best of %d, "
        "of up to 5 for a render under a second, 2 threads, same process): the machine is shared, "
        "and CPU time counts only our work "
        "(on an idle machine wall time is about half of it). Footprints are the renderer's default "
        "(`--footprint auto`): the texels the camera rays reach for AO, every texel of the window "
        "for the direct and path integrators. %s\n\n",
        CameraSpp(s), CameraSpp(s), repeats,
        s.quick ? "**Quick mode: test-size images, two budgets; not for conclusions.**" : "");
    md +=
        "| case | method | equal-time relMSE ratio (per-hit / method) | at CPU seconds | method "
        "relMSE | per-hit relMSE (interpolated) | equal-time image relMSE ratio |\n"
        "|---|---|---|---|---|---|---|\n";
    // Equal-time ratios against each case's per-hit curve, cases in the list's order.
    std::vector<std::string> labels;
    for (const Case& c : cases)
        if (curves.count(c.label) && curves[c.label].count("per-hit")) labels.push_back(c.label);
    for (const std::string& label : labels) {
        auto& cc = curves[label];
        for (const std::string& m : methodOrder[label]) {
            if (m == "per-hit") continue;
            const Ratio r = EqualTimeRatio(cc["per-hit"], cc[m], false);
            const Ratio ri = EqualTimeRatio(cc["per-hit"], cc[m], true);
            md += Format("| %s | %s | **%.2fx** | %.3f | %.5f | %.5f%s | %.2fx |\n", label.c_str(),
                         m.c_str(), r.best, r.at, r.method, r.perHit,
                         r.extrapolated ? " (extrapolated)" : "", ri.best);
        }
    }
    md += GoalSection(labels, curves, methodOrder, uncachedFloor);
    md += queue.RanksSection();
    md +=
        "\nPaper (Munkberg et al. 2016): Fig. 5, the trivial 13x13 normal filter beats ARLP and "
        "adaptive manifolds at equal time on motion-blurred AO; Fig. 7, texture-space linear "
        "regression \"drastically\" lowers error against path tracing at equal rays.\n\n";
    std::string images;
    for (const std::string& label : labels) {
        for (const char* axis : {"seconds", "rays"}) {
            Plot p;
            p.png = (fs::path(s.outDir) / Format("speed_vs_error_%s_%s.png", label.c_str(), axis))
                        .string();
            p.title = label + ": relMSE vs " + axis;
            p.xLabel = std::string(axis == std::string("seconds") ? "render CPU time (s)" : "rays");
            p.yLabel = "relMSE";
            p.logX = p.logY = true;
            for (const std::string& m : methodOrder[label])
                p.series.push_back(
                    {m, csv, axis == std::string("seconds") ? 11 : 7, 8,
                     Format("strcol(1) eq '%s' && strcol(2) eq '%s'", label.c_str(), m.c_str())});
            Draw(p);
            md += Format("![%s](%s)\n", p.title.c_str(), fs::path(p.png).filename().c_str());
        }
        md += "\n";
        for (const std::string& m : methodOrder[label]) {
            const std::string png = Format("sve_%s_%s.png", label.c_str(), m.c_str());
            if (fs::exists(fs::path(s.outDir) / png))
                images += Format("| %s | %s | ![](%s) |\n", label.c_str(), m.c_str(), png.c_str());
        }
    }
    md +=
        "\n## Images at the largest budget\n\n| case | method | image |\n|---|---|---|\n" + images;
    WriteText((fs::path(s.outDir) / "speed_vs_error.md").string(), md);
    Say("wrote %s, plots and speed_vs_error.md in %s", csv.c_str(), s.outDir.c_str());
    return 0;
}

}  // namespace texcache::experiments
