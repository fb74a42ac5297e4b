// SPDX-License-Identifier: Apache-2.0
// `texcache experiment stereo-store`: stereo with shading at the camera's hits, both eyes' hits
// binned into one store (renderer/texture_space/stereo.h), against the paper's grid stereo (the
// second eye from the first eye's cache, Munkberg et al. 2016, Sec. 6.2) and against each eye
// rendered alone at its hits (two mono renders, each its own store).
//
// Cases: car-ao (ambient occlusion) and sunlit-indirect (the clay car under a sun, path traced,
// diffuse light cached), as `experiment stereo`. Per method: each eye's relMSE (eps 0.001)
// against a per-hit reference of that eye, and the CPU seconds of both eyes together (best of the
// repeats).
#include <cmath>
#include <filesystem>

#include "experiment_util.h"
#include "renderer/image/metrics.h"
#include "renderer/texture_space/stereo.h"

namespace texcache::experiments {

namespace fs = std::filesystem;

int StereoStore(const Setup& s) {
    const std::vector<StereoCase> cases = StereoCases();
    const int W = s.quick ? 64 : 320, H = s.quick ? 36 : 180;
    const int spp = 4, refSpp = s.quick ? 16 : 256, repeats = s.quick ? 1 : 3;
    Table t(
        {"scene", "case", "method", "cpu_seconds", "wall_seconds", "relmse_left", "relmse_right"});
    std::string md = Format(
        "## One store for both eyes (shading at the hits)\n\n"
        "`texcache experiment stereo-store --out DIR%s`: %dx%d per eye, %d camera samples per "
        "pixel, the scene's rig, best of %d by CPU time. CPU seconds of both eyes together (all "
        "threads); relMSE (eps 0.001) of each eye against a %d-spp per-hit reference of that "
        "eye. Methods: `grid` is the paper's stereo (the second eye from the first eye's grid "
        "cache, neighbour reuse); `hits-mono` renders each eye alone at its hits (its own "
        "store); `hits-stereo` bins both eyes' hits into one store and reads each eye back from "
        "it.\n\n"
        "Paper (Sec. 6.2): texture space lets the second view reuse the first view's "
        "view-independent shading.\n\n"
        "| case | method | CPU s (both eyes) | wall s | relMSE left | relMSE right |\n"
        "|---|---|---|---|---|---|\n",
        s.quick ? " --quick" : "", W, H, spp, repeats, refSpp);
    for (const StereoCase& c : cases) {
        std::unique_ptr<LoadedScene> ls = LoadStereoCase(s, c);
        RenderOptions o = StereoOptions(ls->scene, c.integrator, W, H);
        StereoRig rig = StereoRigOf(ls->scene.camera);
        if (rig.eyeSeparation <= 0.0f) rig.eyeSeparation = DefaultEyeSeparation(rig.convergence);
        RenderOptions eye[2] = {o, o};
        Image ref[2];
        for (int e = 0; e < 2; ++e) {
            eye[e].eyeOffset = (e == 0 ? -0.5f : 0.5f) * rig.eyeSeparation;
            eye[e].eyeConvergence = rig.convergence;
            eye[e].texture.samples = TextureSamples::Hits;
            RenderOptions ro = eye[e];
            ro.texture.enabled = false;
            ro.spp = refSpp;
            ref[e] = Reference(
                s, Format("stereo_store_%s_%s_%dx%d", c.label, e == 0 ? "left" : "right", W, H),
                *ls->rs, ro);
        }
        Render(*ls->rs, o, FreshCache(*ls, o));  // warm-up: Embree tessellates lazily
        RenderOptions hits = o;
        hits.texture.samples = TextureSamples::Hits;
        for (const char* method : {"grid", "hits-mono", "hits-stereo"}) {
            const std::string m = method;
            StereoResult best;
            double bestCpu = 0.0;
            for (int i = 0; i < repeats; ++i) {
                StereoResult r;
                if (m == "grid") {
                    r = RenderStereo(*ls->rs, o, rig, FreshCache(*ls, o));
                } else if (m == "hits-stereo") {
                    r = RenderStereo(*ls->rs, hits, rig, FreshCache(*ls, hits));
                } else {
                    r.left = Render(*ls->rs, eye[0], FreshCache(*ls, eye[0]));
                    r.right = Render(*ls->rs, eye[1], FreshCache(*ls, eye[1]));
                }
                const double cpu = r.left.stats.cpuSeconds + r.right.stats.cpuSeconds;
                if (i == 0 || cpu < bestCpu) best = std::move(r), bestCpu = cpu;
            }
            const double wall = best.left.stats.seconds + best.right.stats.seconds;
            const double errL = RelMSE(best.left.beauty, ref[0]),
                         errR = RelMSE(best.right.beauty, ref[1]);
            t.Row().Add(ls->name).Add(c.label).Add(m).Add(bestCpu).Add(wall).Add(errL).Add(errR);
            md += Format("| %s | %s | %.3f | %.3f | %.5f | %.5f |\n", c.label, method, bestCpu,
                         wall, errL, errR);
            Say("[stereo-store] %s, %s: %.3f s cpu, relMSE %.5f / %.5f", c.label, method, bestCpu,
                errL, errR);
        }
    }
    t.Write((fs::path(s.outDir) / "stereo_store.csv").string());
    if (s.quick) md += "\n**Quick mode: test-size images; not for conclusions.**\n";
    WriteText((fs::path(s.outDir) / "stereo_store.md").string(), md);
    Say("wrote stereo_store.csv and stereo_store.md in %s", s.outDir.c_str());
    return 0;
}

}  // namespace texcache::experiments
