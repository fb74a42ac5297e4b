// SPDX-License-Identifier: Apache-2.0
// `texcache experiment cpis`: Munkberg et al. 2016, Sec. 6 / Fig. 8: convergence of MIS, product
// importance sampling per hit (PIS) and cached product importance sampling (CPIS) on a cage in
// brushed metal under an environment map (scenes/brushed.json, direct lighting), against a
// high-sample MIS reference: relMSE against render CPU time and against rays, and the time each
// method needs to reach relMSE 0.01.
#include <cmath>
#include <filesystem>
#include <iterator>
#include <vector>

#include "experiment_util.h"
#include "renderer/image/metrics.h"

namespace texcache::experiments {

namespace {

namespace fs = std::filesystem;

/// Where a convergence curve reaches `target`: the least-squares line through (log x, log y) of
/// its points, solved for y = target (Monte Carlo error falls as a power of the cost, ~1/x, so
/// the fit uses every point and the noise of single renders averages out). `slope` is the
/// fitted exponent.
double PowerLawCrossing(const std::vector<double>& xs, const std::vector<double>& ys, double target,
                        double* slope) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double n = double(xs.size());
    for (size_t i = 0; i < xs.size(); ++i) {
        const double lx = std::log(xs[i]), ly = std::log(ys[i]);
        sx += lx, sy += ly, sxx += lx * lx, sxy += lx * ly;
    }
    const double b = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    const double a = (sy - b * sx) / n;
    *slope = b;
    return std::exp((std::log(target) - a) / b);
}

/// A sweep's points from its third render (4 spp) on: the first renders carry fixed costs (e.g.
/// the record cache's allocation) that a power law of the cost does not model.
std::vector<double> FromFourSpp(const std::vector<double>& v) {
    const size_t from = std::min<size_t>(2, v.size() - 2);
    return std::vector<double>(v.begin() + long(from), v.end());
}

/// Where a convergence curve first reaches `target`: log-log interpolation between the two
/// renders around it, or the power-law fit when no render reached it (`fitted` says so).
double Crossing(const std::vector<double>& xs, const std::vector<double>& ys, double target,
                bool* fitted) {
    for (size_t i = 1; i < ys.size(); ++i)
        if (ys[i] <= target && ys[i - 1] > target) {
            bool extrapolated;
            *fitted = false;
            return InterpolateLogLog({ys[i], ys[i - 1]}, {xs[i], xs[i - 1]}, target, &extrapolated);
        }
    double slope;
    *fitted = true;
    return PowerLawCrossing(FromFourSpp(xs), FromFourSpp(ys), target, &slope);
}

struct Method {
    const char* name;
    LightSampling sampling;
    int maxSpp;  ///< the sweep's last render
};

}  // namespace

int Cpis(const Setup& s) {
    if (s.checkOnly) return 0;  // no options of its own
    const auto lsp = LoadForExperiment(s, "brushed.json", true);
    LoadedScene& ls = *lsp;
    const int W = s.quick ? 64 : 256, H = s.quick ? 48 : 192;
    const int refSpp = s.quick ? 512 : 4096;
    constexpr double kTarget = 0.01;

    RenderOptions base = BaseOptions(ls.scene, IntegratorKind::Direct, W, H);
    RenderOptions refOpt = base;
    refOpt.spp = refSpp;
    refOpt.seed = 0x5eed;  // independent of the measured renders' noise
    const Image ref = Reference(s, Format("brushed_%dx%d_%dspp", W, H, refSpp), *ls.rs, refOpt);

    // PIS costs ~15x MIS per sample: its sweep stops earlier (its last point still reaches
    // relMSE 0.01 at the full size).
    const Method methods[] = {{"mis", LightSampling::Mis, s.quick ? 64 : 1024},
                              {"pis", LightSampling::Pis, s.quick ? 8 : 128},
                              {"cpis", LightSampling::Cpis, s.quick ? 64 : 512}};
    Table t({"method", "spp", "seconds", "rays", "relmse", "cpu_seconds", "psr_built", "psr_hits"});
    struct Curve {
        std::vector<double> seconds, rays, relmse;
        std::vector<std::vector<double>> rows;  // the CSV's numbers, written method by method
    };
    // The methods take turns at each sample count, so a change of the machine's load falls on
    // all three alike.
    std::vector<Curve> curves(std::size(methods));
    RenderQueue queue(s);
    for (int spp = 1; spp <= methods[0].maxSpp; spp *= 2)
        for (size_t k = 0; k < std::size(methods); ++k) {
            const Method& m = methods[k];
            if (spp > m.maxSpp) continue;
            RenderOptions o = base;
            o.lightSampling = m.sampling;
            o.spp = spp;
            queue.Add(Format("%s %d spp", m.name, spp), ls, o, 1, spp == 1, [&, k, spp](Run& r) {
                const Method& m = methods[k];
                const double e = RelMSE(r.image, ref);
                const double rays = double(r.stats.TotalRays());
                Curve& c = curves[k];
                c.rows.push_back({double(spp), r.seconds, rays, e, r.cpuSeconds,
                                  double(r.stats.psr.built), double(r.stats.psr.hits)});
                c.seconds.push_back(r.cpuSeconds), c.rays.push_back(rays), c.relmse.push_back(e);
                Say("[cpis] %s %4d spp: %.3f s CPU%s, %.3g rays, relMSE %.5f", m.name, spp,
                    r.cpuSeconds, queue.RankOf(r).c_str(), rays, e);
                if (spp == m.maxSpp)
                    WriteImage((fs::path(s.outDir) / Format("cpis_%s.png", m.name)).string(),
                               r.image);
            });
        }
    queue.Flush();
    if (!queue.Root()) return 0;  // rank 0 writes the files
    // One method's rows together: gnuplot draws a series' line through consecutive rows only.
    for (size_t k = 0; k < curves.size(); ++k)
        for (const std::vector<double>& row : curves[k].rows) {
            t.Row().Add(methods[k].name);
            for (double v : row) t.Add(v);
        }
    const std::string csv = (fs::path(s.outDir) / "cpis.csv").string();
    t.Write(csv);

    for (const char* axis : {"seconds", "rays"}) {
        Plot p;
        p.png = (fs::path(s.outDir) / Format("cpis_%s.png", axis)).string();
        p.title = Format("brushed metal torus, direct light, %dx%d", W, H);
        p.xLabel = std::string(axis) == "seconds" ? "render CPU seconds" : "rays";
        p.yLabel = "relMSE";
        p.logX = p.logY = true;
        const int col = std::string(axis) == "seconds" ? 6 : 4;
        for (const Method& m : methods)
            p.series.push_back({m.name, csv, col, 5, Format("strcol(1) eq '%s'", m.name)});
        p.extra = {Format("set arrow from graph 0, first %g to graph 1, first %g nohead dt 2",
                          kTarget, kTarget)};
        Draw(p);
    }

    // Time and rays to relMSE 0.01: interpolated between the renders around it; beside it the
    // power-law fit of the points from 4 spp on.
    std::string md = "# Cached product importance sampling\n\n";
    if (s.quick) md += "**Quick mode: test-size image; not for conclusions.**\n\n";
    md += Format(
        "`scenes/brushed.json`: the torus cage in brushed metal (anisotropic GGX, roughness "
        "[0.6, 0.25] along/across the Ptex u direction, F0 0.95) under `studio.exr`, direct "
        "lighting, %dx%d, one light sample and one BSDF sample per camera sample (MIS with the "
        "power heuristic in every method). Reference: MIS at %d spp (another seed). Cost: "
        "render CPU time (all threads), renders of 1, 2, 4, ... spp.\n\n",
        W, H, refSpp);
    md +=
        "| method | CPU seconds to relMSE 0.01 | rays to relMSE 0.01 | power-law fit: seconds "
        "(slope) | last point |\n|---|---|---|---|---|\n";
    std::vector<double> tTarget;
    for (size_t k = 0; k < curves.size(); ++k) {
        const Curve& c = curves[k];
        double slopeT;
        bool fitT, fitR;
        const double tt = Crossing(c.seconds, c.relmse, kTarget, &fitT);
        const double rr = Crossing(c.rays, c.relmse, kTarget, &fitR);
        const double tFit =
            PowerLawCrossing(FromFourSpp(c.seconds), FromFourSpp(c.relmse), kTarget, &slopeT);
        tTarget.push_back(tt);
        md += Format("| %s | %.3g%s | %.3g%s | %.3g (%.2f) | %.3g s, relMSE %.4f |\n",
                     methods[k].name, tt, fitT ? " (fit)" : "", rr, fitR ? " (fit)" : "", tFit,
                     slopeT, c.seconds.back(), c.relmse.back());
    }
    const double cpisVsPis = tTarget[1] / tTarget[2], cpisVsMis = tTarget[0] / tTarget[2];
    md += Format(
        "\nAt relMSE 0.01: CPIS is **%.2fx** faster than PIS and **%.2fx** faster than MIS "
        "(PIS is %.2fx %s than MIS).\n\n",
        cpisVsPis, cpisVsMis,
        tTarget[0] > tTarget[1] ? tTarget[0] / tTarget[1] : tTarget[1] / tTarget[0],
        tTarget[0] > tTarget[1] ? "faster" : "slower");
    md +=
        "Paper (Fig. 8, Toad in brushed metal): at relMSE 0.01, CPIS is 4x faster than PIS and "
        "2.5x faster than MIS; PIS converges fastest per ray but is ~7x slower than MIS at an "
        "equal number of rays.\n\n![relMSE vs time](cpis_seconds.png) ![relMSE vs "
        "rays](cpis_rays.png)\n\n| MIS | PIS | CPIS |\n|---|---|---|\n| ![](cpis_mis.png) | "
        "![](cpis_pis.png) | ![](cpis_cpis.png) |\n\n(last render of each sweep)\n";
    md += queue.RanksSection();
    WriteText((fs::path(s.outDir) / "cpis.md").string(), md);
    Say("[cpis] CPIS %.2fx faster than PIS, %.2fx faster than MIS at relMSE %.2g; wrote %s, "
        "cpis.md, cpis_seconds.png, cpis_rays.png",
        cpisVsPis, cpisVsMis, kTarget, csv.c_str());
    return 0;
}

}  // namespace texcache::experiments
