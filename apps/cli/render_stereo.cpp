// SPDX-License-Identifier: Apache-2.0
// `texcache render --stereo`: both eyes of the camera's stereo rig through one texture-space
// cache (renderer/texture_space/stereo.h), written as NAME_left and NAME_right, with each eye's
// figures (how much the second eye took from the first's cache) printed and in --stats.
#include <cstdio>
#include <filesystem>
#include <utility>

#include "render_command.h"
#include "renderer/render_policy.h"
#include "renderer/scene/scene_units.h"
#include "renderer/texture_space/stereo.h"

namespace texcache::cli {

namespace {

/// --stereo's rig: the scene camera's, with --eye-separation / --convergence on top; without a
/// separation from either, DefaultEyeSeparation.
StereoRig StereoRigFrom(const RenderArgs& a, const Scene& scene) {
    StereoRig rig = StereoRigOf(scene.camera);
    // The options are in the scene file's units, the rig in render units (scene_units.h).
    if (a.Given("--convergence")) {
        CheckStereoRig({0.0f, a.convergence}, "--convergence");
        rig.convergence = float(std::min(double(a.convergence) * scene.unitScale, 1e30));
    }
    if (a.Given("--eye-separation")) {
        CheckStereoRig({a.eyeSeparation, 1.0f}, "--eye-separation");
        rig.eyeSeparation = float(std::min(double(a.eyeSeparation) * scene.unitScale, 1e30));
    } else if (rig.eyeSeparation == 0.0f) {
        rig.eyeSeparation = DefaultEyeSeparation(rig.convergence);
    }
    const std::string where = a.Given("--eye-separation") ? "--eye-separation"
                              : a.Given("--convergence")  ? "--convergence"
                                                          : scene.path + ": key 'camera.stereo'";
    CheckStereoRig(rig, where);
    CheckStereoShear(rig, where);
    CheckSceneReach(scene, 0.5f * rig.eyeSeparation, where);
    return rig;
}

StereoReuse ParseStereoReuse(const std::string& name) {
    if (name == "texels") return StereoReuse::Texels;
    if (name == "neighbour") return StereoReuse::Neighbour;
    throw InputError("--stereo-reuse",
                     "unknown value '" + Excerpt(name) + "' (valid: texels, neighbour)");
}

/// One eye's figures for --stats (the cache counters are what this eye shaded anew).
std::string EyeJson(const char* name, const RenderStats& s, bool last) {
    const CacheStats& c = s.cache;
    char buf[512];
    std::snprintf(
        buf, sizeof buf,
        "    \"%s\": {\"seconds\": %.10g, \"cpu_seconds\": %.10g, \"spp\": %d, \"rays\": %llu, "
        "\"camera_rays\": %llu, \"lookups\": %llu, \"texel_hit_rate\": %.10g, "
        "\"texels_shaded\": %llu, \"samples_shaded\": %llu}%s\n",
        name, s.seconds, s.cpuSeconds, s.sppDone, (unsigned long long)s.TotalRays(),
        (unsigned long long)s.cameraRays, (unsigned long long)c.lookups, c.TexelHitRate(),
        (unsigned long long)c.texelMisses, (unsigned long long)c.samplesShaded, last ? "" : ",");
    return buf;
}

/// Each eye's time and what it shaded, the right eye's relative to the left's (grid stereo:
/// the second eye reuses the first eye's cache).
void PrintEyes(const StereoResult& r) {
    const RenderStats& L = r.left.stats;
    for (const auto& [name, st] : {std::pair{"left", &r.left.stats}, {"right", &r.right.stats}}) {
        std::printf("%s eye: %.3f s (%.3f s cpu), %llu rays, %llu samples and %llu texels shaded",
                    name, st->seconds, st->cpuSeconds, (unsigned long long)st->TotalRays(),
                    (unsigned long long)st->cache.samplesShaded,
                    (unsigned long long)st->cache.texelMisses);
        if (st != &L)
            std::printf(
                " (%.1f%% of the left eye's time, %.1f%% of its samples, %.1f%% of its "
                "texels)",
                100.0 * st->seconds / std::max(L.seconds, 1e-9),
                100.0 * double(st->cache.samplesShaded) /
                    std::max(double(L.cache.samplesShaded), 1.0),
                100.0 * double(st->cache.texelMisses) / std::max(double(L.cache.texelMisses), 1.0));
        std::printf("\n");
    }
}

}  // namespace

void CheckStereoOptions(const RenderArgs& a) {
    if (!a.stereo) {
        for (const char* o : {"--eye-separation", "--convergence", "--stereo-reuse"})
            if (a.Given(o)) throw InputError(o, "applies to stereo renders: give --stereo");
        return;
    }
    if (!a.frameBuffers.empty())
        throw InputError("--stereo", "cannot be combined with --frame-buffers (not supported yet)");
    if (!a.denoise.empty())
        throw InputError("--stereo", "cannot be combined with --denoise (not supported yet)");
    if (!a.frames.empty()) throw InputError("--stereo", "renders one frame: drop --frames");
    if (a.overshading) throw InputError("--stereo", "cannot be combined with --overshading");
}

int RunStereo(const RenderArgs& a, const Scene& scene, const RenderOptions& opt) {
    const StereoRig rig = StereoRigFrom(a, scene);
    const std::filesystem::path o(a.output);
    std::vector<OutputPaths> outs;
    for (const char* eye : {"_left", "_right"})
        outs.push_back(PlanOutputs(
            (o.parent_path() / (o.stem().string() + eye + o.extension().string())).string(),
            !a.noPng));
    CheckCombinations(a, scene.settings, opt, outs.front());
    CheckFiles(scene, outs, a.statsFile);
    const std::unique_ptr<tbb::global_control> limit = ThreadLimit(a.threads);
    const RenderScene rs(scene, SceneOptionsFor(a, opt, scene.settings.time));
    std::unique_ptr<TextureSpaceCache> cache;
    if (opt.texture.enabled) cache = MakeTextureSpaceCache(rs, opt.texture, kCacheSizeOptions);
    StereoResult r = RenderStereo(rs, opt, rig, cache.get(), ParseStereoReuse(a.stereoReuse));
    WarnUntracedRays(rs);

    AtomicFiles group;
    WriteOutputs(outs[0], r.left.beauty, r.left.aovs, a.exposure, group);
    WriteOutputs(outs[1], r.right.beauty, r.right.aovs, a.exposure, group);
    if (!a.statsFile.empty()) {
        std::string json = StatsJson(BothEyes(r), rs, cache.get(), opt, -1.0);
        json.resize(json.size() - 3);  // "\n}\n": the eyes follow
        char rigJson[160];
        std::snprintf(rigJson, sizeof rigJson,
                      ",\n  \"stereo\": {\"eye_separation\": %.10g, \"convergence\": %.10g,\n",
                      rig.eyeSeparation, rig.convergence);
        json += rigJson + EyeJson("left", r.left.stats, false) +
                EyeJson("right", r.right.stats, true) + "  }\n}\n";
        WriteText(a.statsFile, json, group);
        outs[1].written.push_back(a.statsFile);
    }
    group.Commit();

    std::printf(
        "rendered %s in stereo: %dx%d per eye, %d spp, integrator %s, eye separation %g, "
        "convergence %g\n",
        scene.path.c_str(), opt.width, opt.height, r.left.stats.sppDone,
        IntegratorName(opt.integrator), rig.eyeSeparation, rig.convergence);
    const RenderStats& L = r.left.stats;
    if (opt.texture.enabled && opt.texture.samples == TextureSamples::Hits) {
        // The eyes' passes are interleaved through one store: their time is one figure, and no
        // sample or texel is shaded for a cache (both eyes' hits are the samples).
        std::printf("both eyes, hits in one store: %.3f s (%.3f s cpu), %llu + %llu rays\n",
                    L.seconds + r.right.stats.seconds, L.cpuSeconds + r.right.stats.cpuSeconds,
                    (unsigned long long)L.TotalRays(),
                    (unsigned long long)r.right.stats.TotalRays());
    } else {
        PrintEyes(r);
    }
    std::printf("peak memory: %.1f MiB\n", PeakMemoryMiB());
    for (const OutputPaths& out : outs)
        for (const std::string& f : out.written) std::printf("wrote %s\n", f.c_str());
    return 0;
}

}  // namespace texcache::cli
