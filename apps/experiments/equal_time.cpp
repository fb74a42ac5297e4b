// SPDX-License-Identifier: Apache-2.0
// `texcache experiment equal-time`: per-hit shading against texture-space shading as a user gets
// it (`--shading texture` and nothing else), at equal CPU time, on a set of scenes that no
// setting was chosen on (validation/ by default). Each scene renders with its own integrator at a
// ladder of camera samples per pixel, both methods at every rung, and every image is compared
// with a high-sample per-hit reference of the same scene. The per-hit curve (relMSE against CPU
// seconds) is interpolated in log-log at each texture-space point's cost: the gain is per hit's
// error at that cost over texture space's.
//
// CPU time rather than wall time: on a shared machine wall time also counts other processes'
// work, and CPU time on 2 threads is about twice the wall time of an idle machine, so the
// ladder's CPU seconds double as the budgets `--seconds` would be given.
#include <algorithm>
#include <filesystem>
#include <map>

#include "experiment_util.h"
#include "renderer/image/metrics.h"
#include "renderer/integrators/integrator_kind.h"
#include "renderer/render_policy.h"
#include "texcache/error.h"

namespace texcache::experiments {

namespace {

namespace fs = std::filesystem;

struct Point {
    int spp;
    double cpu, seconds, relmse;
};

/// What `texcache render SCENE --shading texture` does with no other texture-space option: the
/// same policy functions the command line calls, so this experiment follows its defaults.
RenderOptions TextureDefaults(const Scene& scene, RenderOptions o) {
    o.texture = TextureSpaceOptions{};
    o.texture.enabled = true;
    o.texture.samples = AutoTextureSamples(false);
    const CachedDirect direct =
        CachedDirectLight(CachedLight::Auto, SceneLightKinds(scene), o.texture.samples);
    o.texture.cacheDirect = direct.cacheDirect;
    o.texture.deltaDirectPerHit = direct.deltaDirectPerHit;
    SizeTextureCaches(&o, 1, {}, "equal-time");
    return o;
}

std::vector<std::string> SceneFiles(const std::string& dir, const std::string& only) {
    if (!fs::is_directory(dir)) throw InputError("--set", "no scene directory '" + dir + "'");
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(dir))
        if (e.path().extension() == ".json") files.push_back(e.path().filename().string());
    std::sort(files.begin(), files.end());
    if (!only.empty()) {
        const std::string list = "," + only + ",";
        std::vector<std::string> kept;
        for (const std::string& f : files)
            if (list.find("," + fs::path(f).stem().string() + ",") != std::string::npos)
                kept.push_back(f);
        if (kept.empty())
            throw InputError("--only", "names no scene of '" + dir + "' (got '" + only + "')");
        files = kept;
    }
    if (files.empty()) throw InputError("--set", "no .json scene in '" + dir + "'");
    return files;
}

}  // namespace

int EqualTime(const Setup& s) {
    Setup set = s;
    set.scenesDir = s.sceneSet;
    const std::vector<std::string> files = SceneFiles(set.scenesDir, s.only);
    if (s.checkOnly) return 0;
    const int W = s.quick ? 80 : 320, H = s.quick ? 45 : 180;
    const int refSpp = s.quick ? 64 : 1024, repeats = s.quick ? 1 : 2;
    const std::vector<int> ladder =
        s.quick ? std::vector<int>{1, 2, 4} : std::vector<int>{1, 2, 4, 8, 16, 32, 64};
    const std::string csv = (fs::path(s.outDir) / "equal_time.csv").string();
    Table table({"scene", "integrator", "method", "spp", "cpu_seconds", "seconds", "relmse"});
    std::string md = Format(
        "# Equal time: per hit against texture space outside scenes/\n\n"
        "`texcache experiment equal-time%s --set %s`: each scene at %dx%d with its own "
        "integrator, camera samples per pixel %d to %d, both methods at every rung (best of %d "
        "by CPU time, of up to 5 for a render under a second), relMSE (eps = 0.001) against a "
        "%d-spp per-hit reference. *per hit at "
        "equal time* interpolates the per-hit curve in log-log at the texture-space point's CPU "
        "seconds (an asterisk: extrapolated beyond the per-hit rungs). Gain = per hit / texture "
        "space; CPU seconds on 2 threads are about twice the wall seconds of an idle machine.\n\n"
        "Paper (Munkberg et al. 2016), Sec. 7: shading cached in texture space is shared by the "
        "pixels and samples that see it; here that sharing has to pay for itself at equal time "
        "on scenes no setting was chosen on.\n\n%s",
        s.quick ? " --quick" : "", fs::path(s.sceneSet).filename().c_str(), W, H, ladder.front(),
        ladder.back(), repeats, refSpp,
        s.quick ? "Quick mode: test size, tiny images and few samples; not for conclusions.\n\n"
                : "");
    RenderQueue queue(s);
    std::string verdicts;
    int below = 0, points = 0;
    double worstGain = 1e30;
    std::string worstWhere;
    for (const std::string& file : files) {
        auto ls = LoadForExperiment(set, file, true);
        const RenderOptions scene = RenderOptionsFrom(ls->scene.settings);
        const IntegratorKind integrator = scene.integrator;
        const char* integratorName = IntegratorName(integrator);
        if (queue.Root()) Say("%s (%s)", ls->name.c_str(), integratorName);
        RenderOptions perHit = BaseOptions(ls->scene, integrator, W, H);
        perHit.texture.enabled = false;
        RenderOptions ref = perHit;
        ref.spp = refSpp;
        const Image reference =
            Reference(set, Format("eqt_%s_%dx%d", ls->name.c_str(), W, H), *ls->rs, ref);
        const RenderOptions texture = TextureDefaults(ls->scene, perHit);
        std::map<std::string, std::vector<Point>> curves;
        bool warm = true;
        for (int spp : ladder)
            for (const auto& [name, base] :
                 {std::pair<const char*, const RenderOptions*>{"per-hit", &perHit},
                  {"texture", &texture}}) {
                RenderOptions o = *base;
                o.spp = spp;
                queue.Add(
                    Format("%s %s %d spp", ls->name.c_str(), name, spp), *ls, o, repeats, warm,
                    [&, name = name, spp](Run& r) {
                        const Point p{spp, r.cpuSeconds, r.seconds, RelMSE(r.image, reference)};
                        curves[name].push_back(p);
                        Say("  %-8s %3d spp: %.3f CPU s%s, relMSE %.5f", name, spp, p.cpu,
                            queue.RankOf(r).c_str(), p.relmse);
                    });
                warm = false;
            }
        // Over many ranks the scene's renders run here, spread; rank 0 goes on with them.
        queue.Flush();
        if (!queue.Root()) continue;
        // A method's rows together: gnuplot joins the points of consecutive rows only.
        for (const auto& [name, points] : curves)
            for (const Point& p : points)
                table.Row()
                    .Add(ls->name)
                    .Add(integratorName)
                    .Add(name)
                    .Add(double(p.spp))
                    .Add(p.cpu)
                    .Add(p.seconds)
                    .Add(p.relmse);
        table.Write(csv);  // after every scene: a long run that stops keeps what it measured

        std::vector<double> hitCpu, hitErr;
        for (const Point& p : curves["per-hit"])
            hitCpu.push_back(p.cpu), hitErr.push_back(p.relmse);
        md += Format(
            "## %s (%s)\n\n| spp | texture CPU s | texture relMSE | per hit at equal "
            "time | gain |\n|---|---|---|---|---|\n",
            ls->name.c_str(), integratorName);
        double sceneWorst = 1e30;
        for (const Point& p : curves["texture"]) {
            bool extrapolated = false;
            const double ph = InterpolateLogLog(hitCpu, hitErr, p.cpu, &extrapolated);
            const double gain = ph / std::max(p.relmse, 1e-30);
            md += Format("| %d | %.3f | %.5f | %.5f%s | %.2fx |\n", p.spp, p.cpu, p.relmse, ph,
                         extrapolated ? "*" : "", gain);
            ++points;
            below += gain >= 1.0;
            sceneWorst = std::min(sceneWorst, gain);
            if (gain < worstGain) {
                worstGain = gain;
                worstWhere = Format("%s at %d spp", ls->name.c_str(), p.spp);
            }
        }
        bool extrapolated = false;
        const double first = curves["texture"].front().relmse;
        const double last = curves["texture"].back().relmse;
        verdicts += Format(
            "| %s | %s | %.2fx | %.2fx | %.1fx |\n", ls->name.c_str(), integratorName, sceneWorst,
            InterpolateLogLog(hitCpu, hitErr, curves["texture"].front().cpu, &extrapolated) /
                std::max(first, 1e-30),
            first / std::max(last, 1e-30));
        Plot plot;
        plot.png = (fs::path(s.outDir) / Format("equal_time_%s.png", ls->name.c_str())).string();
        plot.title = ls->name + " (" + integratorName + "): relMSE against CPU time";
        plot.xLabel = "render CPU time (s)";
        plot.yLabel = "relMSE";
        plot.logX = plot.logY = true;
        for (const char* m : {"per-hit", "texture"})
            plot.series.push_back(
                {m, csv, 5, 7,
                 Format("strcol(1) eq '%s' && strcol(3) eq '%s'", ls->name.c_str(), m)});
        Draw(plot);
        md += Format("\n![%s](%s)\n\n", plot.title.c_str(), fs::path(plot.png).filename().c_str());
    }
    if (!queue.Root()) return 0;  // rank 0 writes the files
    md = md.substr(0, md.find("## ")) +
         Format(
             "## Summary\n\nTexture space at or below per hit at %d of %d points; the worst "
             "gain is %.2fx (%s).\n\n| scene | integrator | worst gain | gain at the "
             "smallest budget | error, smallest / largest budget |\n|---|---|---|---|---|\n",
             below, points, worstGain, worstWhere.c_str()) +
         verdicts + "\n" + md.substr(md.find("## ")) + queue.RanksSection();
    WriteText((fs::path(s.outDir) / "equal_time.md").string(), md);
    Say("wrote %s, plots and equal_time.md in %s", csv.c_str(), s.outDir.c_str());
    return 0;
}

}  // namespace texcache::experiments
