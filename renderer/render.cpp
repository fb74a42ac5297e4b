// SPDX-License-Identifier: Apache-2.0
// The frame loop: a frame's passes over its tiles (TBB threads), each pass a run of whole sample
// indices, sized to a time budget when there is one; per pass, the stages that pass needs
// (render_internal.h lists them: shading at the hits, a visibility prepass, per-hit shading,
// two-phase AO), then the frame's sums turned into an image, its AOV layers and statistics.
// What a sample computes is the path tracer's (integrators/path_tracer.h) or, with texture-space
// shading, the cache's (texture_space/cached_shading.h).
#include "renderer/render.h"

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <climits>
#include <cmath>
#include <ctime>
#include <memory>

#include <tbb/blocked_range2d.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "renderer/progress.h"
#include "renderer/render_internal.h"
#include "texcache/error.h"

namespace texcache {

using namespace internal;

namespace {

/// Renders passes of whole sample indices from opt.firstSample until opt.spp samples are done
/// or, with a time budget (counted from `start`), until the next pass would not fit in it;
/// returns the sample index reached. A pixel's result depends only on its sample indices and the
/// passes (first bounces are a net per pass: PixelSequence), so the image is the same for any
/// thread count.
int RunPasses(const Context& c, FrameCache& fc, FrameSums& sums,
              tbb::enumerable_thread_specific<RayCounts>& counts,
              std::chrono::steady_clock::time_point start) {
    using Clock = std::chrono::steady_clock;
    const RenderOptions& opt = c.opt;
    const int W = opt.width, y0 = opt.rowBegin, y1 = opt.rowEnd > 0 ? opt.rowEnd : opt.height;
    auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
    // Per-hit AO traces a tile's camera rays first, then its AO rays (see AoTileTwoPhase).
    const bool twoPhaseAo = opt.integrator == IntegratorKind::AO && sums.aovs.empty();
    const int sppCap = std::max(opt.spp, 1);
    std::atomic<uint64_t> pixelSamplesDone{0};
    const double totalWork = double(W) * double(y1 - y0) * (sppCap - opt.firstSample);
    const Progress progress(opt.progress, [&] {
        if (opt.seconds > 0.0f)
            return std::max(elapsed() / opt.seconds, double(pixelSamplesDone) / totalWork);
        return double(pixelSamplesDone.load()) / totalWork;
    });
    auto forTiles = [&](auto&& tile) {
        tbb::parallel_for(tbb::blocked_range2d<int>(y0, y1, 8, 0, W, 8),
                          [&](const tbb::blocked_range2d<int>& r) {
                              // Denormals off in every worker: Embree wants it and it saves
                              // stalls in shading.
                              _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                              _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                              tile(r, counts.local());
                          });
    };
    // Progressive texture space: passes of opt.texture.passSpp camera samples, each after the
    // first starting a new pass of the cache (fresh shading, jittered sample positions, smaller
    // footprints: see texture_space.h), whether the budget is samples or seconds.
    const bool progressive =
        c.tsc && c.tsc->Progressive() && opt.texture.passSpp > 0 && opt.texture.constantTerm < 0.0f;
    int done = opt.firstSample;
    int passSpp = progressive ? opt.texture.passSpp : opt.seconds > 0.0f ? 1 : sppCap;
    int passesRun = 0;
    bool extending = false;  // progressive: camera samples against the last pass's cache
    // Texture-space AO with a prepass shades from the prepass's texels (see PassTexels), when a
    // pass's texels fit in 256 MB (a pass of 4 spp at 1920x1080 takes 200 MB); a longer pass
    // (a render without progressive passes, or a time budget's growing ones) traces its camera
    // rays again instead.
    const bool prepassAo = twoPhaseAo && fc.Visible() != nullptr;
    constexpr size_t kMaxPassTexelBytes = size_t(256) << 20;
    PassTexels passTexels;
    const bool hits = c.tsc && ShadesAtHits(opt);
    // Light binned at the hits: the path integrator's, or the direct one's (PathHitsTrace).
    const bool pathHits = hits && opt.integrator != IntegratorKind::AO;
    // Hit bins: no table grows past 256 MiB (a frame's bins take a few MiB at most sizes).
    constexpr size_t kMaxBinBytes = size_t(256) << 20;
    constexpr size_t kMaxHitRecordBytes = size_t(256) << 20;
    size_t binBlocksUsed = 0;
    // Hit binning keeps a record per camera sample of a pass (and for diffuse light its
    // albedo): a pass holds at most 256 MiB of them (1920x1080, AO: 10 samples a pixel), and a
    // longer one runs as several.
    const size_t framePixels = std::max<size_t>(1, size_t(W) * size_t(opt.height));
    const size_t recordBytes = sizeof(HitRecord) + (pathHits ? sizeof(BinnedHit) : 0);
    const int hitSpp = int(
        std::clamp<size_t>(kMaxHitRecordBytes / (recordBytes * framePixels), 1, size_t(INT_MAX)));
    // Hit-binned diffuse light: each pixel's per-hit part of a pass (misses, lights, glossy
    // hits, unbinned direct light), written by the binning phase, added by the resolve.
    std::vector<glm::dvec3> perHit(pathHits ? framePixels : 0);
    std::vector<glm::dvec2> pixelNoise(pathHits ? framePixels : 0);  // see PathHitsTrace
    while (done < sppCap) {
        const int s0 = done,
                  s1 = std::min(sppCap, done + (hits ? std::min(passSpp, hitSpp) : passSpp));
        const size_t passSamples = size_t(W) * size_t(opt.height) * size_t(s1 - s0);
        const bool fromPrepass = !hits && opt.visibilityPrepass != VisibilityPrepass::Only &&
                                 prepassAo &&
                                 passSamples * PassTexels::kBytesPerSample <= kMaxPassTexelBytes;
        if (fromPrepass) {
            PassScratch& store = c.tsc->PassTexelScratch();
            if (passSamples > store.texels.size()) store.texels.resize(passSamples);
            const size_t pixels = size_t(W) * size_t(opt.height);
            if (pixels > store.added.size()) store.added.resize(pixels);
            passTexels.at = store.texels.data(), passTexels.added = store.added.data();
            passTexels.sum = sums.rgb.data(), passTexels.width = W;
            passTexels.s0 = s0, passTexels.s1 = s1;
        }
        const auto passStart = Clock::now();
        // The pass count saturates: a wrap to 0 would repeat pass 0's random numbers.
        const bool newPass =
            progressive && !extending && done > opt.firstSample && c.tsc->Pass() < UINT32_MAX;
        if (newPass) c.tsc->BeginPass(c.tsc->Pass() + 1);
        // A pass's footprints keep the texels its own camera samples see, so that a pass costs
        // what the first did. A set kept over the passes would grow with every pass (each
        // pass's jittered and lens rays reach new texels), and every sample of it would be
        // shaded again each pass: its extra taps lower a pass's error, but at a cost that grows
        // with the pass's index, unknown to the time budget.
        if (newPass && fc.Visible() && opt.visibilityPrepass == VisibilityPrepass::Own)
            fc.Visible()->Clear();
        // Nothing to find in a cache emptied by this pass or not used since it was emptied.
        passTexels.cacheEmptied =
            newPass || !c.tsc || !c.tsc->MayHoldTexels();  // per hit: no cache
        if (hits) {
            // Hit binning (TextureSamples::Hits): bin every hit of the pass, then read the bins
            // back at every camera sample. A table too small for the pass's bins (an add found no
            // room) is doubled and the pass binned again, so no hit is ever lost; the bins, and
            // so the image, do not depend on the table's size.
            HitRecord* const records = c.tsc->HitRecords(passSamples);
            BinnedHit* const binnedHits = pathHits ? c.tsc->BinnedHits(passSamples) : nullptr;
            // Diffuse light: every hit shaded first, its bins' level then picked from the pass's
            // noise (the variance of the binned light among each pixel's samples, summed over
            // the pixels in order, so the same for any thread count, over their means squared).
            double noiseVar = 0.0, noiseMean2 = 0.0;
            if (pathHits) {
                forTiles([&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                    PathHitsTrace(c, r, s0, s1, records, binnedHits, perHit.data(),
                                  pixelNoise.data(), rc);
                });
                for (size_t p = size_t(y0) * size_t(W); p < size_t(y1) * size_t(W); ++p)
                    noiseVar += pixelNoise[p].x, noiseMean2 += pixelNoise[p].y;
            }
            // The direct integrator's light at AO's levels: its noise is AO's kind (a shadow
            // ray per sample), and bins one level finer than paths' keep its soft shadows'
            // detail at a lower error than paths' levels give it.
            const float levels =
                opt.integrator == IntegratorKind::Path
                    ? TextureSpaceCache::HitLightLevels(
                          noiseVar, noiseMean2, std::max(opt.hitSamples, 1), s1 - s0, c.tsc->Pass())
                    : TextureSpaceCache::HitBinLevels(
                          pathHits ? std::max(opt.hitSamples, 1) : opt.aoSamples, s1 - s0,
                          c.tsc->Pass());
            // The bins lie floor(levels) and one more levels up. Each sample reads the finer
            // and moves towards the coarser by their difference and its noise (Reconstruct),
            // AO's noise from its counts, the light's from the pass's V; light whose noise was
            // not measured reads one of the two at random, the coarser with probability
            // frac(levels).
            const double relativeVariance = noiseMean2 > 0.0 && std::isfinite(noiseVar / noiseMean2)
                                                ? noiseVar / noiseMean2
                                                : 0.0;
            const int bias = int(std::floor(levels));
            const float blend = relativeVariance > 0.0 ? 0.0f : levels - float(bias);
            // At most half full: twice the blocks the last pass used, or a first guess of four
            // per Ptex face (a face seen at a few levels, two bin levels each) plus the pixels'
            // bins, 16 to a block; a guess too small costs one more binning of the pass.
            const size_t pixels = size_t(W) * size_t(y1 - y0);
            const size_t guess =
                4 * c.tsc->NumFaces() + 2 * pixels / (size_t(16) << (2 * std::clamp(bias, 0, 8)));
            // Bins one phase, reads them back in the next; `table(blocks)` is the cache's table
            // of the pass's kind.
            auto binAndResolve = [&](auto&& table, auto&& bin, auto&& resolve) {
                using Table = std::remove_reference_t<decltype(table(size_t(0)))>;
                const size_t maxBlocks = kMaxBinBytes / Table::BytesFor(1);
                size_t blocks =
                    std::clamp(2 * std::max(guess, binBlocksUsed), size_t(1024), maxBlocks);
                for (;;) {
                    Table& bins = table(blocks);
                    bins.Clear();
                    forTiles([&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                        bin(r, bins, rc);
                    });
                    if (bins.Dropped() == 0 || bins.NumBlocks() >= maxBlocks) break;
                    blocks = 2 * bins.NumBlocks();
                }
                const Table& bins = table(blocks);
                binBlocksUsed = bins.BlocksUsed();
                sums.hitBinsDropped += bins.Dropped();
                sums.hitBinBytes = bins.BytesUsed();
                forTiles([&](const tbb::blocked_range2d<int>& r, RayCounts&) {
                    resolve(r, bins);
                    pixelSamplesDone +=
                        uint64_t(r.rows().size()) * r.cols().size() * uint64_t(s1 - s0);
                });
            };
            if (pathHits)
                binAndResolve(
                    [&](size_t blocks) -> RadianceBins& { return c.tsc->LightBins(blocks); },
                    [&](const tbb::blocked_range2d<int>& r, RadianceBins& bins, RayCounts&) {
                        PathHitsAdd(c, r, s0, s1, bias, blend, records, binnedHits, bins);
                    },
                    [&](const tbb::blocked_range2d<int>& r, const RadianceBins& bins) {
                        PathHitsResolve(c, r, s0, s1, records, binnedHits, perHit.data(), bins,
                                        relativeVariance, sums.rgb.data());
                    });
            else
                binAndResolve(
                    [&](size_t blocks) -> HitBins& { return c.tsc->Bins(blocks); },
                    [&](const tbb::blocked_range2d<int>& r, HitBins& bins, RayCounts& rc) {
                        AoHitsBin(c, r, s0, s1, bias, records, bins, rc);
                    },
                    [&](const tbb::blocked_range2d<int>& r, const HitBins& bins) {
                        AoHitsResolve(c, r, s0, s1, records, bins, sums.rgb.data());
                    });
        } else if (VisibleTexels* visible = fc.Visible())
            forTiles([&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                MarkVisibleTexels(c, *visible, r, s0, s1, fromPrepass ? &passTexels : nullptr, rc);
            });
        if (!hits)
            forTiles([&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                if (opt.visibilityPrepass == VisibilityPrepass::Only) return;  // marks only
                if (fromPrepass) {
                    AoTileFromPrepass(c, r, passTexels, rc);
                } else if (twoPhaseAo) {
                    AoTileTwoPhase(c, r.rows().begin(), r.rows().end(), r.cols().begin(),
                                   r.cols().end(), s0, s1, sums.rgb, rc);
                } else {
                    // The thread's cache counters, read around each pixel for its heat-map counts.
                    CacheStats* pixelStats = c.pixelCache ? &fc.Stats().local() : nullptr;
                    ShadeTile(c, r, s0, s1, sums, pixelStats, rc);
                }
                pixelSamplesDone += uint64_t(r.rows().size()) * r.cols().size() * uint64_t(s1 - s0);
            });
        if (c.tsc && opt.visibilityPrepass != VisibilityPrepass::Only) c.tsc->NoteLookups();
        done = s1;
        ++passesRun;
        if (opt.seconds > 0.0f) {
            const double passTime = std::chrono::duration<double>(Clock::now() - passStart).count();
            const double left = opt.seconds - elapsed();
            if (left <= 0.0) break;
            if (progressive) {
                const BudgetStep step =
                    NextBudgetStep(extending, passesRun, left, passTime, s1 - s0);
                if (step == BudgetStep::Stop) break;
                if (step == BudgetStep::Extend) extending = true, passSpp = 1;
                continue;
            }
            // Size the next pass to fit the remaining budget (at most doubling).
            const double perSample = passTime / double(s1 - s0);
            passSpp = std::clamp(int(left / std::max(perSample, 1e-9)), 0, 2 * (s1 - s0));
            if (passSpp == 0) break;
        }
    }
    return done;
}

}  // namespace

BudgetStep internal::NextBudgetStep(bool extending, int passesRun, double left, double lastTime,
                                    int lastSpp) {
    if (!(left > 0.0)) return BudgetStep::Stop;
    if (extending) return left >= lastTime ? BudgetStep::Extend : BudgetStep::Stop;
    if (left >= lastTime) return BudgetStep::Pass;  // another pass fits
    // A first pass that leaves less than itself: the rest of the budget goes to camera samples
    // against its cache rather than to nothing. Such a sample costs a lookup, not the pass's
    // re-shading (a texture-space pass is mostly shading: a pass of 4 spp costs well under 4
    // passes of 1), so a budget of about two first passes still lowers the error instead of
    // ending after one. A camera sample costs at most the pass's time over its samples, so one
    // is tried when that fits. After two passes or more the budget left is under a third of
    // it, and extra samples would weigh the last pass's shading above the others'.
    if (passesRun > 1 || left < lastTime / double(std::max(lastSpp, 1))) return BudgetStep::Stop;
    return BudgetStep::Extend;
}

RenderResult Render(const RenderScene& rs, const RenderOptions& opt, TextureSpaceCache* cache) {
    using Clock = std::chrono::steady_clock;
    const auto start = Clock::now();
    const std::clock_t cpuStart = std::clock();
    const int rowEnd = opt.rowEnd > 0 ? opt.rowEnd : opt.height;
    if (opt.rowBegin < 0 || opt.rowEnd < 0 || opt.rowBegin >= rowEnd || rowEnd > opt.height)
        throw InputError("render options", "rows [" + std::to_string(opt.rowBegin) + ", " +
                                               std::to_string(opt.rowEnd) +
                                               ") are not a band of an image of " +
                                               std::to_string(opt.height) + " rows");
    Context ctx(rs, opt);
    FrameCache frameCache(ctx, opt, cache, FrameCache::Prepass::Allowed);
    // Cached product sampling: the records of this frame (none unless asked for).
    std::unique_ptr<ProductRecordCache> psrCache;
    tbb::enumerable_thread_specific<RecordStats> psrStats;
    if (ctx.lightSampling == LightSampling::Cpis && AnyProductSampled(rs.scene()) &&
        (opt.integrator == IntegratorKind::Direct || opt.integrator == IntegratorKind::Path)) {
        psrCache = std::make_unique<ProductRecordCache>(rs, opt.psrCacheBytes, opt.psrLodBias);
        ctx.psrCache = psrCache.get();
        ctx.psrStats = &psrStats;
    }
    const int W = opt.width, H = opt.height;
    const size_t numPixels = size_t(W) * H;
    if (opt.pixelCache) {
        // Only this render's rows start from zero: a band (stereo) keeps the other bands' counts.
        if (opt.pixelCache->size() != numPixels)
            opt.pixelCache->assign(numPixels, PixelCacheCounts{});
        else
            std::fill(opt.pixelCache->begin() + ptrdiff_t(size_t(opt.rowBegin) * W),
                      opt.pixelCache->begin() + ptrdiff_t(size_t(rowEnd) * W), PixelCacheCounts{});
        if (ctx.tsc) ctx.pixelCache = opt.pixelCache->data();
    }
    FrameSums sums{std::vector<double>(numPixels * 3, 0.0),
                   std::vector<PixelAovs>(opt.aovs.Any() ? numPixels : 0)};
    tbb::enumerable_thread_specific<RayCounts> counts;
    const int done = RunPasses(ctx, frameCache, sums, counts, start) - opt.firstSample;

    RenderResult result;
    result.beauty = Image(W, H, 3);
    for (size_t p = 0; p < numPixels * 3; ++p) result.beauty.data[p] = float(sums.rgb[p] / done);
    result.aovs = AovLayers(sums.aovs, opt.aovs, W, H, done);
    for (const RayCounts& rc : counts) {
        result.stats.cameraRays += rc.camera;
        result.stats.cameraRaysCulled += rc.cameraCulled;
        result.stats.shadowRays += rc.shadow;
        result.stats.bounceRays += rc.bounce;
    }
    for (const CacheStats& cs : frameCache.Stats()) result.stats.cache.Merge(cs);
    for (const RecordStats& ps : psrStats) result.stats.psr.Merge(ps);
    result.stats.psrBytes = psrCache ? psrCache->BytesUsed() : 0;
    result.stats.sppDone = done;
    result.stats.hitBinsDropped = sums.hitBinsDropped;
    result.stats.hitBinBytes = sums.hitBinBytes;
    result.stats.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    result.stats.cpuSeconds = double(std::clock() - cpuStart) / CLOCKS_PER_SEC;
    return result;
}

}  // namespace texcache
