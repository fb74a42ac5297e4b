// SPDX-License-Identifier: Apache-2.0
// `texcache render` of one image or of an animation (--frames), and what it reports: the time
// and memory of the render and of the scene build, the cache's traffic, the overshading against
// unbounded caches (--overshading), and --stats as JSON.
#include <cstdio>

#include "render_command.h"
#include "renderer/render_policy.h"
#include "renderer/texture_space/visibility_pass.h"

namespace texcache::cli {

std::string StatsJson(const RenderStats& s, const RenderScene& rs, const TextureSpaceCache* cache,
                      const RenderOptions& opt, double overshading) {
    const CacheStats& c = s.cache;
    std::string json = "{\n";
    auto add = [&](const char* k, double v, bool last = false) {
        char buf[128];
        std::snprintf(buf, sizeof buf, "  \"%s\": %.10g%s\n", k, v, last ? "" : ",");
        json += buf;
    };
    add("seconds", s.seconds);
    add("cpu_seconds", s.cpuSeconds);  // all threads: on a shared machine, the figure to compare
    add("spp", s.sppDone);
    add("rays", double(s.TotalRays()));
    add("camera_rays_culled", double(s.cameraRaysCulled));
    add("lookups", double(c.lookups));
    add("texel_hits", double(c.texelHits));
    add("texel_misses", double(c.texelMisses));
    add("texel_hit_rate", c.TexelHitRate());
    add("texel_evictions", double(c.texelEvictions));
    add("texels_uncached", double(c.texelUncached));
    add("sample_lookups", double(c.sampleLookups));
    add("sample_hits", double(c.sampleHits));
    add("samples_shaded", double(c.samplesShaded));
    add("sample_evictions", double(c.sampleEvictions));
    add("samples_uncached", double(c.samplesUncached));
    add("sample_memo_hits", double(c.sampleMemoHits));
    add("taps_unseen", double(c.tapsUnseen));
    add("texels_prefiltered", double(c.texelsPrefiltered));
    add("deferrals", double(c.deferrals));
    add("waits", double(c.waits));
    add("reference_mode", opt.texture.cache.referenceMode ? 1.0 : 0.0);
    if (overshading >= 0.0) add("overshading", overshading);
    add("psr_lookups", double(s.psr.lookups));
    add("psr_hits", double(s.psr.hits));
    add("psr_built", double(s.psr.built));
    add("psr_uncached", double(s.psr.uncached));
    add("psr_evictions", double(s.psr.evictions));
    add("psr_cache_bytes", double(s.psrBytes));
    add("sample_cache_bytes", cache ? double(cache->SampleCacheBytes()) : 0.0);
    add("texel_cache_bytes", cache ? double(cache->TexelCacheBytes()) : 0.0);
    add("hit_bin_bytes", double(s.hitBinBytes));  // shading at the hits (--ts-samples hits)
    add("hit_bins_dropped", double(s.hitBinsDropped));
    add("bytes_used", (cache ? double(cache->BytesUsed()) : 0.0) + double(s.psrBytes));
    // The scene: its size and the meshes Embree could not take (embree_mesh.cpp's design note).
    const RenderScene::TessellationStats t = rs.LimitTessellated();
    add("ptex_faces", double(rs.NumPtexFaces()));
    add("cage_faces_beyond_embree", double(t.beyondEmbree));
    add("limit_tessellated_meshes", double(t.meshes));
    add("limit_tessellated_cage_faces", double(t.cageFaces), true);
    json += "}\n";
    return json;
}

void PrintSceneStats(const RenderScene& rs) {
    const size_t objects = rs.scene().objects.size();
    std::printf("scene: %zu object%s, %zu Ptex faces; %s\n", objects, objects == 1 ? "" : "s",
                rs.NumPtexFaces(), RenderScene::Describe(rs.LimitTessellated()).c_str());
}

int RunAnimation(const RenderArgs& a, const Scene& scene, const RenderOptions& opt,
                 VisibilityFilterKind visibility, std::vector<OutputPaths>& outs, int first,
                 int last, float fps) {
    // Scene geometry and lights are posed per frame; the cache (and its temporal history)
    // persists, keyed by each object's own grids.
    AnimationFrames frames(scene, SceneOptionsFor(a, opt, scene.settings.time), opt, fps,
                           kCacheSizeOptions);
    double total = 0.0;
    for (int f = first; f <= last; ++f) {
        const double tf = NowSeconds();
        frames.Pose(f);
        RenderOptions& fo = frames.Options();
        fo.progress = false;
        RenderResult r = Render(frames.PosedScene(), fo, frames.Cache());
        ApplyVisibilityFilter(visibility, frames.PosedScene(), fo, &r.beauty);
        OutputPaths& out = outs[size_t(f - first)];
        AtomicFiles group;
        WriteOutputs(out, r.beauty, r.aovs, a.exposure, group);
        group.Commit();
        total += NowSeconds() - tf;
        std::printf("frame %d (%d of %d, t = %.3f): %.3f s, %.1f%% texel hits -> %s\n", f,
                    f - first + 1, last - first + 1, fo.frameTime, r.stats.seconds,
                    100.0 * r.stats.cache.TexelHitRate(), out.written.front().c_str());
        std::fflush(stdout);
    }
    std::printf("rendered %d frames of %s in %.2f s (%dx%d, %d spp, integrator %s)\n",
                last - first + 1, scene.path.c_str(), total, opt.width, opt.height, opt.spp,
                IntegratorName(opt.integrator));
    return 0;
}

int RunImage(const RenderArgs& a, const Scene& scene, const RenderOptions& opt,
             VisibilityFilterKind visibility, OutputPaths& out, double loadSeconds) {
    const double t0 = NowSeconds();
    RenderScene rs(scene, SceneOptionsFor(a, opt, scene.settings.time));
    const double buildSeconds = NowSeconds() - t0;

    // Overshading: samples shaded beyond what an unbounded cache shades for the same frame.
    double overshading = -1.0;
    uint64_t referenceShaded = 0;
    if (a.overshading) {
        if (!opt.texture.enabled) throw InputError("--overshading", "needs --shading texture");
        RenderOptions ref = opt;
        ref.texture.cache.referenceMode = true;
        ref.progress = false;
        referenceShaded = Render(rs, ref).stats.cache.samplesShaded;
    }
    std::unique_ptr<TextureSpaceCache> cache;
    const double tCache = NowSeconds();
    if (opt.texture.enabled) cache = MakeTextureSpaceCache(rs, opt.texture, kCacheSizeOptions);
    const double cacheSeconds = NowSeconds() - tCache;
    RenderResult r = Render(rs, opt, cache.get());
    const double visibilitySeconds = ApplyVisibilityFilter(visibility, rs, opt, &r.beauty);
    if (a.overshading && referenceShaded > 0)
        overshading = double(r.stats.cache.samplesShaded) / double(referenceShaded) - 1.0;
    // Every output into one group, renamed only once all are complete.
    AtomicFiles group;
    WriteOutputs(out, r.beauty, r.aovs, a.exposure, group);
    if (!a.statsFile.empty()) {
        WriteText(a.statsFile, StatsJson(r.stats, rs, cache.get(), opt, overshading), group);
        out.written.push_back(a.statsFile);
    }
    group.Commit();

    std::printf("rendered %s: %dx%d, %d spp, integrator %s\n", scene.path.c_str(), opt.width,
                opt.height, r.stats.sppDone, IntegratorName(opt.integrator));
    std::printf("time: %.3f s render + %.3f s scene build; %.2f Mrays/s (%llu rays)\n",
                r.stats.seconds, buildSeconds, double(r.stats.TotalRays()) / r.stats.seconds * 1e-6,
                (unsigned long long)r.stats.TotalRays());
    if (visibilitySeconds > 0.0) std::printf("visibility filter: %.3f s\n", visibilitySeconds);
    const RenderScene::BuildSeconds b = rs.BuildTimes();
    std::printf(
        "scene build: OpenSubdiv %.3f s, Embree geometry %.3f s, Embree BVH %.3f s, other %.3f s; "
        "%.3f s reading the scene%s",
        b.opensubdiv, b.embreeGeometry, b.embreeBvh, b.other, loadSeconds, cache ? "" : "\n");
    if (cache) std::printf(", %.3f s making the texture-space cache\n", cacheSeconds);
    std::printf(
        "scene memory: Embree %.1f MiB (%.1f MiB at most while building), Ptex topology and "
        "patches %.1f MiB\n",
        double(rs.EmbreeBytes()) / (1 << 20), double(rs.EmbreePeakBytes()) / (1 << 20),
        double(rs.MeshBytes()) / (1 << 20));
    PrintSceneStats(rs);
    if (cache) {
        const CacheStats& c = r.stats.cache;
        std::printf(
            "texture-space cache: %llu lookups, %.1f%% texel hits, %llu samples shaded "
            "(%llu evictions, %llu deferrals), %.1f MiB\n",
            (unsigned long long)c.lookups, 100.0 * c.TexelHitRate(),
            (unsigned long long)c.samplesShaded, (unsigned long long)c.sampleEvictions,
            (unsigned long long)c.deferrals, double(cache->BytesUsed()) / (1 << 20));
        if (r.stats.hitBinBytes > 0)
            std::printf(
                "hit bins (shading at the camera hits): %.1f MiB, %llu hits left out "
                "(no room)\n",
                double(r.stats.hitBinBytes) / (1 << 20),
                (unsigned long long)r.stats.hitBinsDropped);
        if (overshading >= 0.0)
            std::printf("overshading: %.2f%% more samples than an unbounded cache (%llu)\n",
                        100.0 * overshading, (unsigned long long)referenceShaded);
    }
    if (r.stats.psrBytes > 0) {
        const RecordStats& p = r.stats.psr;
        std::printf(
            "product sampling records: %llu lookups, %.1f%% hits, %llu built (%llu evictions), "
            "%.1f MiB\n",
            (unsigned long long)p.lookups,
            p.lookups ? 100.0 * double(p.hits) / double(p.lookups) : 0.0,
            (unsigned long long)p.built, (unsigned long long)p.evictions,
            double(r.stats.psrBytes) / (1 << 20));
    }
    std::printf("peak memory: %.1f MiB\n", PeakMemoryMiB());
    for (const std::string& f : out.written) std::printf("wrote %s\n", f.c_str());
    return 0;
}

}  // namespace texcache::cli
