// SPDX-License-Identifier: Apache-2.0
// `texcache preview SCENE --bench`: the preview's frame rate while orbiting, texture-space AO with
// the trivial filter and a cache kept across frames against per-hit AO at the same relMSE. Both
// run the same orbit in the same process; relMSE is measured at the orbit's last view against a
// high-sample per-hit reference of that view.
#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "orbit_camera.h"
#include "preview.h"
#include "renderer/metrics.h"
#include "renderer/render.h"
#include "renderer/render_scene.h"
#include "renderer/texture_space.h"
#include "texcache/error.h"

namespace texcache::preview {

namespace {

struct OrbitRun {
    double fps = 0.0, seconds = 0.0;
    double hitRate = 0.0;  ///< texel hit rate over the timed frames
    uint64_t samplesShaded = 0;
    Image last;  ///< the last view's image
};

}  // namespace

int RunPreviewBench(const Scene& sceneIn, const PreviewSettings& s, const PreviewArgs& args,
                    const BenchArgs& b) {
    Scene scene = sceneIn;
    scene.settings.tessellationRate = s.tessellationRate;
    const float time = scene.settings.time;
    if (const auto dir = std::filesystem::path(b.out).parent_path(); !dir.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(dir, ec);
        if (ec) throw InputError("--bench-out", "cannot create '" + dir.string() + "'");
    }
    RenderSceneOptions ro;
    ro.frameTime = time;
    ro.needLights = ro.needEnvironment = false;
    RenderScene rs(scene, ro);  // keeps a reference to `scene`: camera edits below are seen

    OrbitCamera home;
    home.FromScene(scene, time);
    const int n = b.frames;
    // View i of the orbit; view n is the last (where relMSE is measured).
    auto setView = [&](int i) {
        OrbitCamera c = home;
        c.Orbit(args.orbitDegrees * float(i) / float(n), 0.0f);
        c.ToCamera(&scene.camera);
    };

    RenderOptions base;
    base.integrator = IntegratorKind::AO;
    base.width = s.width, base.height = s.height;
    base.spp = 1;
    base.aoSamples = s.aoSamples;
    base.aoDistance = s.aoDistance;
    base.frameTime = time;
    base.progress = false;

    std::printf("preview bench: %s, %dx%d, AO, orbit of %.1f degrees in %d frames\n",
                scene.path.c_str(), base.width, base.height, args.orbitDegrees, n);

    setView(n);
    RenderOptions refOpt = base;
    refOpt.spp = b.referenceSpp;
    refOpt.aoSamples = b.referenceAoSamples;
    refOpt.seed = 0xC0FFEE;  // independent of the tested frames' seeds
    refOpt.progress = true;
    const RenderResult ref = Render(rs, refOpt);
    std::printf("reference       : per-hit AO, %d spp x %d rays, %.1f s\n", refOpt.spp,
                refOpt.aoSamples, ref.stats.seconds);

    // Views 1..n after a cold frame at view 0; frame i gets seed i, as the preview's frames do.
    auto orbit = [&](const RenderOptions& o, TextureSpaceCache* cache) {
        OrbitRun run;
        setView(0);
        Render(rs, o, cache);  // texture space: the cold frame; per hit: warms code and BVH
        CacheStats total;
        for (int i = 1; i <= n; ++i) {
            setView(i);
            RenderOptions f = o;
            f.seed = o.seed + uint64_t(i);
            RenderResult r = Render(rs, f, cache);
            run.seconds += r.stats.seconds;
            total.Merge(r.stats.cache);
            if (i == n) run.last = std::move(r.beauty);
        }
        run.fps = double(n) / run.seconds;
        run.hitRate = total.TexelHitRate();
        run.samplesShaded = total.samplesShaded / uint64_t(n);
        return run;
    };

    // Texture space: the preview's settings (trivial filter by default), one cache for the orbit.
    RenderOptions texOpt = base;
    texOpt.texture.enabled = true;
    texOpt.texture.filter = s.filter;
    texOpt.texture.radius = s.radius;
    texOpt.texture.footprint = s.footprint;
    texOpt.texture.cache.sampleCacheBytes = size_t(double(s.sampleCacheMb) * (1 << 20));
    texOpt.texture.cache.texelCacheBytes = size_t(double(s.texelCacheMb) * (1 << 20));
    texOpt.texture.cache.lodBias = s.lodBias;
    texOpt.texture.cache.Validate();
    TextureSpaceCache cache(rs, texOpt.texture);
    const OrbitRun tex = orbit(texOpt, &cache);
    const double eTex = RelMSE(tex.last, ref.beauty);
    std::printf(
        "texture space (sets the relMSE to match): filter %s r=%d, %d rays/sample, 1 spp: "
        "%.1f fps (%.1f ms/frame), "
        "hit rate %.2f %%, %llu samples shaded/frame, relMSE %.5f\n",
        args.filterName.c_str(), s.radius, s.aoSamples, tex.fps, 1e3 / tex.fps, 100.0 * tex.hitRate,
        (unsigned long long)tex.samplesShaded, eTex);

    // Per hit: the fewest AO rays per hit (1 spp: a camera ray shared by all of them is the
    // cheapest way to buy AO quality) whose relMSE at the last view is no worse.
    setView(n);
    auto hitError = [&](int rays) {
        RenderOptions o = base;
        o.aoSamples = rays;
        o.seed = uint64_t(n);
        return RelMSE(Render(rs, o).beauty, ref.beauty);
    };
    int hi = 1;
    double eHi = hitError(hi);
    while (eHi > eTex && hi < 4096) eHi = hitError(hi *= 2);
    int lo = hi / 2;  // relMSE(lo) > eTex (or lo == 0)
    while (hi - lo > 1 && hi > 8) {
        const int mid = (lo + hi) / 2;
        if (hitError(mid) <= eTex)
            hi = mid;
        else
            lo = mid;
        if (hi - lo <= std::max(1, hi / 16)) break;  // within ~6%: fine enough for a rate
    }
    RenderOptions hitOpt = base;
    hitOpt.aoSamples = hi;

    // The timed run: both orbits frame by frame in turn (a fresh cache, cold frame untimed), so
    // load from other processes on a shared machine slows both alike.
    OrbitRun tex2, hit;
    {
        TextureSpaceCache fresh(rs, texOpt.texture);
        setView(0);
        Render(rs, texOpt, &fresh);
        Render(rs, hitOpt);
        CacheStats total;
        for (int i = 1; i <= n; ++i) {
            setView(i);
            RenderOptions t = texOpt, h = hitOpt;
            t.seed = h.seed = uint64_t(i);
            RenderResult rt = Render(rs, t, &fresh);
            RenderResult rh = Render(rs, h);
            tex2.seconds += rt.stats.seconds;
            hit.seconds += rh.stats.seconds;
            total.Merge(rt.stats.cache);
            if (i == n) tex2.last = std::move(rt.beauty), hit.last = std::move(rh.beauty);
        }
        tex2.fps = double(n) / tex2.seconds;
        hit.fps = double(n) / hit.seconds;
        tex2.hitRate = total.TexelHitRate();
        tex2.samplesShaded = total.samplesShaded / uint64_t(n);
    }
    const double eTex2 = RelMSE(tex2.last, ref.beauty);
    const double eHit = RelMSE(hit.last, ref.beauty);
    std::printf("interleaved run (%d frames each):\n", n);
    std::printf("  texture space : %6.1f fps (%.1f ms/frame), hit rate %.2f %%, relMSE %.5f\n",
                tex2.fps, 1e3 / tex2.fps, 100.0 * tex2.hitRate, eTex2);
    std::printf("  per hit       : %6.1f fps (%.1f ms/frame), %d rays/hit, relMSE %.5f\n", hit.fps,
                1e3 / hit.fps, hi, eHit);
    const double ratio = tex2.fps / hit.fps;
    std::printf("texture space / per hit frame rate at equal relMSE: %.2f x (goal >= 3) %s\n",
                ratio, ratio >= 3.0 ? "ok" : "MISSED");
    std::printf("warm texture-space frame rate: %.1f fps (goal >= 10) %s\n", tex2.fps,
                tex2.fps >= 10.0 ? "ok" : "MISSED");
    WriteImage(b.out + "_ref.png", ref.beauty);
    WriteImage(b.out + "_texture.png", tex2.last);
    WriteImage(b.out + "_hit.png", hit.last);
    std::printf("wrote %s_{ref,texture,hit}.png\n", b.out.c_str());
    return 0;
}

}  // namespace texcache::preview
