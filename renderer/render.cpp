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
#include <optional>

#include <tbb/blocked_range2d.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "renderer/distributed/rank_group.h"
#include "renderer/progress.h"
#include "renderer/render_internal.h"
#include "texcache/error.h"

namespace texcache {

using namespace internal;

namespace {

/// A table of hit bins as accumulators another rank's table adds to (the bins' sums are
/// saturating integers: the same in any order).
template <typename Table>
class BinAccumulators final : public ReducibleAccumulators {
public:
    explicit BinAccumulators(Table& table) : table_(table) {}
    size_t WordsPerKey() const override { return Table::kRecordWords - 1; }
    void Export(std::vector<uint64_t>* out) const override { table_.ExportBlocks(out); }
    uint64_t Import(const uint64_t* records, size_t n) override {
        return table_.AddBlocks(records, n);
    }

private:
    Table& table_;
};

/// A visible-texel set's words as accumulators: a key is a word's index, its one "sum" the
/// word's marks, combined by a bitwise or, which like a sum does not depend on the order.
class VisibleWords final : public ReducibleAccumulators {
public:
    explicit VisibleWords(VisibleTexels& visible) : visible_(visible) {}
    size_t WordsPerKey() const override { return 1; }
    void Export(std::vector<uint64_t>* out) const override {
        for (size_t i = 0; i < visible_.NumWords(); ++i)
            if (const uint64_t marks = visible_.WordAt(i)) out->push_back(i), out->push_back(marks);
    }
    uint64_t Import(const uint64_t* records, size_t n) override {
        for (size_t i = 0; i < n; ++i)
            visible_.MarkWord(size_t(records[2 * i]), records[2 * i + 1]);
        return 0;
    }

private:
    VisibleTexels& visible_;
};

/// The right eye of a stereo render shading at the hits (RenderEyesAtHits): its context, sums
/// and rays. Its camera samples are binned into the left eye's store beside the left eye's.
struct SecondEye {
    const Context* c;
    FrameSums* sums;
    tbb::enumerable_thread_specific<RayCounts>* counts;
};

/// Renders passes of whole sample indices from opt.firstSample until opt.spp samples are done
/// or, with a time budget (counted from `start`), until the next pass would not fit in it;
/// returns the sample index reached. A pixel's result depends only on its sample indices and the
/// passes (first bounces are a net per pass: PixelSequence), so the image is the same for any
/// thread count. Over many ranks (opt.ranks) each renders its bands of rows (RowSplit) and the
/// ranks combine the pass's hit bins and noise before reading them back, so that every pixel
/// gets the value one process gives it. With a `second` eye (shading at the hits only), each pass
/// bins both eyes' camera samples into one store and reads each eye's back from it.
int RunPasses(const Context& c, FrameCache& fc, FrameSums& sums,
              tbb::enumerable_thread_specific<RayCounts>& counts,
              std::chrono::steady_clock::time_point start, const SecondEye* second = nullptr) {
    using Clock = std::chrono::steady_clock;
    const RenderOptions& opt = c.opt;
    const int W = opt.width, y0 = opt.rowBegin, y1 = opt.rowEnd > 0 ? opt.rowEnd : opt.height;
    auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
    RankGroup* const group = opt.ranks && opt.ranks->Size() > 1 ? opt.ranks : nullptr;
    const RowSplit split{y0, y1, group ? group->Rank() : 0, group ? group->Size() : 1};
    int ownRows = 0;
    for (int i = 0; i < split.OwnBands(); ++i) ownRows += split.Last(i) - split.First(i);
    // Per-hit AO traces a tile's camera rays first, then its AO rays (see AoTileTwoPhase).
    const bool twoPhaseAo = opt.integrator == IntegratorKind::AO && sums.aovs.empty();
    const int sppCap = std::max(opt.spp, 1);
    std::atomic<uint64_t> pixelSamplesDone{0};
    const double totalWork = double(W) * double(ownRows) * (sppCap - opt.firstSample);
    const Progress progress(opt.progress, [&] {
        if (opt.seconds > 0.0f)
            return std::max(elapsed() / opt.seconds, double(pixelSamplesDone) / totalWork);
        return double(pixelSamplesDone.load()) / totalWork;
    });
    const int eyes = second ? 2 : 1;
    const Context* const eyeContext[2] = {&c, second ? second->c : nullptr};
    FrameSums* const eyeSums[2] = {&sums, second ? second->sums : nullptr};
    tbb::enumerable_thread_specific<RayCounts>* const eyeCounts[2] = {
        &counts, second ? second->counts : nullptr};
    // The tiles of eye `eye`, its rays counted as its own.
    auto forEyeTiles = [&](int eye, auto&& tile) {
        auto run = [&](const tbb::blocked_range2d<int>& r) {
            // Denormals off in every worker: Embree wants it and it saves stalls in shading.
            _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
            _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
            tile(r, eyeCounts[eye]->local());
        };
        if (!group) {
            tbb::parallel_for(tbb::blocked_range2d<int>(y0, y1, 8, 0, W, 8), run);
            return;
        }
        // This rank's bands, each split into tiles of its rows.
        tbb::parallel_for(
            tbb::blocked_range2d<int>(0, split.OwnBands(), 1, 0, W, 8),
            [&](const tbb::blocked_range2d<int>& b) {
                for (int i = b.rows().begin(); i < b.rows().end(); ++i)
                    run(tbb::blocked_range2d<int>(split.First(i), split.Last(i), 8,
                                                  b.cols().begin(), b.cols().end(), 8));
            });
    };
    auto forTiles = [&](auto&& tile) { forEyeTiles(0, tile); };
    const bool hits = c.tsc && ShadesAtHits(opt);
    // Progressive texture space: passes of opt.texture.passSpp camera samples, each after the
    // first starting a new pass of the cache (fresh shading, jittered sample positions, smaller
    // footprints: see texture_space.h), whether the budget is samples or seconds. Hit binning
    // shades nothing on the grids and runs as per hit does instead: all the samples in one pass
    // (the first bounces of a pixel's samples then form one net, PixelSequence, and the bins
    // start at the level of all of them), or with a time budget passes from one sample up sized
    // to what is left.
    const bool progressive = !hits && c.tsc && c.tsc->Progressive() && opt.texture.passSpp > 0 &&
                             opt.texture.constantTerm < 0.0f;
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
    std::vector<std::atomic<uint8_t>> rowLeft(prepassAo ? size_t(opt.height) : 0);
    // Light binned at the hits: the path integrator's, or the direct one's (PathHitsTrace).
    const bool pathHits = hits && opt.integrator != IntegratorKind::AO;
    // Temporal accumulation at the hits: the stores decay by alpha between frames instead of
    // being emptied (texture_space.h, the note at the top); alpha in 1/65536.
    const bool temporalHits = hits && opt.texture.temporalAlpha > 0.0f;
    const uint32_t temporalKeep =
        uint32_t(std::lround(double(opt.texture.temporalAlpha) * 65536.0));
    // Hit bins: no table grows past 256 MiB (a frame's bins take a few MiB at most sizes).
    constexpr size_t kMaxBinBytes = size_t(256) << 20;
    constexpr size_t kMaxHitRecordBytes = size_t(256) << 20;
    size_t binBlocksUsed = 0;
    // Hit binning keeps a record per camera sample of a pass (and for diffuse light its
    // albedo, for AO its own estimate): a pass holds at most 256 MiB of them (1920x1080, AO: 8
    // samples a pixel), and a longer one runs as several.
    const size_t framePixels = std::max<size_t>(1, size_t(W) * size_t(opt.height));
    const size_t recordBytes = sizeof(HitRecord) + (pathHits ? sizeof(BinnedHit) : sizeof(float));
    const int hitSpp = int(std::clamp<size_t>(
        kMaxHitRecordBytes / (recordBytes * framePixels * size_t(eyes)), 1, size_t(INT_MAX)));
    // Hit-binned diffuse light: each pixel's per-hit part of a pass (misses, lights, glossy
    // hits, unbinned direct light), written by the binning phase, added by the resolve.
    // Each eye's frame after the other's (stereo).
    // These per-pixel and per-sample arrays are the cache's, kept from render to render
    // (PassScratch): cleared here, they are pages the process has.
    std::vector<glm::dvec3> noPerHit;
    std::vector<glm::dvec2> noPixelNoise;
    std::vector<float> noOwnAo;
    std::vector<glm::dvec3>& perHit = hits ? c.tsc->PassTexelScratch().perHit : noPerHit;
    std::vector<glm::dvec2>& pixelNoise =
        hits ? c.tsc->PassTexelScratch().pixelNoise : noPixelNoise;  // see PathHitsTrace
    perHit.assign(pathHits ? size_t(eyes) * framePixels : 0, glm::dvec3(0.0));
    pixelNoise.assign(pathHits ? size_t(eyes) * framePixels : 0, glm::dvec2(0.0));
    std::vector<double> rowNoise(pathHits ? 2 * size_t(y1 - y0) : 0);
    // Hit-binned AO: each camera sample's own estimate, written by the binning phase, added to
    // sums.own by the resolve (a pass binned again writes it again).
    std::vector<float>& ownAo = hits ? c.tsc->PassTexelScratch().ownAo : noOwnAo;
    if (hits)
        for (int e = 0; e < eyes; ++e) eyeSums[e]->own.assign(4 * framePixels, 0.0);
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
            for (auto& row : rowLeft) row.store(0, std::memory_order_relaxed);
            passTexels.rowLeft = rowLeft.data();
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
            // Stereo: each eye's records, own estimates and light after the other's.
            HitRecord* const records = c.tsc->HitRecords(size_t(eyes) * passSamples);
            if (!pathHits && ownAo.size() < size_t(eyes) * passSamples)
                ownAo.resize(size_t(eyes) * passSamples);
            BinnedHit* const binnedHits =
                pathHits ? c.tsc->BinnedHits(size_t(eyes) * passSamples) : nullptr;
            auto eyeRecords = [&](int e) { return records + size_t(e) * passSamples; };
            auto eyeBinned = [&](int e) {
                return binnedHits ? binnedHits + size_t(e) * passSamples : nullptr;
            };
            // Diffuse light: every hit shaded first, its bins' level then picked from the pass's
            // noise (the variance of the binned light among each pixel's samples, summed over
            // the pixels in order, so the same for any thread count, over their means squared).
            double noiseVar = 0.0, noiseMean2 = 0.0;
            if (pathHits) {
                for (int e = 0; e < eyes; ++e)
                    forEyeTiles(e, [&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                        PathHitsTrace(*eyeContext[e], r, s0, s1, eyeRecords(e), eyeBinned(e),
                                      perHit.data() + size_t(e) * framePixels,
                                      pixelNoise.data() + size_t(e) * framePixels, rc);
                    });
                // Summed row by row, then the rows in order: the same sum whichever rank
                // rendered each row (a row's sums come from one rank; the others add zeros).
                // Stereo: the noise of both eyes' samples, which share the bins.
                for (int y = y0; y < y1; ++y) {
                    double v = 0.0, m = 0.0;
                    if (split.Owns(y))
                        for (int e = 0; e < eyes; ++e)
                            for (size_t p = size_t(e) * framePixels + size_t(y) * W;
                                 p < size_t(e) * framePixels + size_t(y + 1) * W; ++p)
                                v += pixelNoise[p].x, m += pixelNoise[p].y;
                    rowNoise[2 * size_t(y - y0)] = v, rowNoise[2 * size_t(y - y0) + 1] = m;
                }
                if (group) group->SumDisjoint(rowNoise.data(), rowNoise.size());
                for (size_t i = 0; i < rowNoise.size(); i += 2)
                    noiseVar += rowNoise[i], noiseMean2 += rowNoise[i + 1];
            }
            // Temporal accumulation: the bins hold about 1 / (1 - alpha) frames' samples.
            // Stereo keeps one eye's levels: the surfaces both eyes see get both eyes' samples
            // in bins of the mono render's size (on car AO, levels picked for twice the samples
            // give finer bins and lose that gain: results/stereo.md).
            const int levelSpp = temporalHits
                                     ? int(std::lround(double(s1 - opt.firstSample) /
                                                       (1.0 - double(opt.texture.temporalAlpha))))
                                     : s1 - opt.firstSample;
            // The direct integrator's light at AO's levels: its noise is AO's kind (a shadow
            // ray per sample), and bins one level finer than paths' keep its soft shadows'
            // detail at a lower error than paths' levels give it.
            const float levels =
                opt.integrator == IntegratorKind::Path
                    ? TextureSpaceCache::HitLightLevels(noiseVar, noiseMean2,
                                                        std::max(opt.hitSamples, 1), levelSpp, 0)
                    : TextureSpaceCache::HitBinLevels(
                          pathHits ? std::max(opt.hitSamples, 1) : opt.aoSamples, levelSpp, 0);
            // The bins lie floor(levels) and one more levels up. Each sample reads the finer
            // and moves towards the coarser by their difference and its noise (Reconstruct),
            // AO's noise from its counts, the light's from the pass's V; light whose noise was
            // not measured reads one of the two at random, the coarser with probability
            // frac(levels).
            const double relativeVariance = noiseMean2 > 0.0 && std::isfinite(noiseVar / noiseMean2)
                                                ? noiseVar / noiseMean2
                                                : 0.0;
            // Temporal accumulation keeps its first frame's level (TemporalHitBias).
            int bias = int(std::floor(levels));
            if (temporalHits) {
                int& kept = c.tsc->TemporalHitBias();
                if (kept == INT_MIN) kept = bias;
                bias = kept;
            }
            const float blend = relativeVariance > 0.0 ? 0.0f : levels - float(bias);
            // At most half full: twice the blocks the last pass used, or a first guess of four
            // per Ptex face (a face seen at a few levels, two bin levels each) plus the pixels'
            // bins, 16 to a block; a guess too small costs one more binning of the pass.
            const size_t pixels = size_t(W) * size_t(y1 - y0);
            const size_t guess =
                4 * c.tsc->NumFaces() + 2 * pixels / (size_t(16) << (2 * std::clamp(bias, 0, 8)));
            // Bins one phase, reads them back in the next; `table(blocks)` is the cache's store
            // of the pass's kind.
            auto binAndResolve = [&](auto&& table, auto&& bin, auto&& resolve) {
                using Table =
                    typename std::remove_reference_t<decltype(table(size_t(0)))>::SampleLevel;
                // Temporal accumulation: what the store holds, decayed by alpha at a new frame
                // (exact fixed point: the same for any thread count), goes into every binning
                // of the pass, on one rank only (the ranks' tables are summed).
                std::vector<uint64_t> carried;
                if (temporalHits && c.tsc->HitStoreFrame() >= 0) {
                    table(size_t(0)).Samples().ExportBlocks(&carried);
                    if (c.tsc->HitStoreFrame() != int64_t(c.tsc->Frame()))
                        Table::ScaleRecords(&carried, temporalKeep);
                }
                const size_t carriedBlocks = carried.size() / Table::kRecordWords;
                const size_t maxBlocks = kMaxBinBytes / Table::BytesFor(1);
                size_t blocks = std::clamp(2 * std::max(guess + carriedBlocks, binBlocksUsed),
                                           size_t(1024), maxBlocks);
                for (;;) {
                    // Over many ranks every rank's table holds every rank's hits: the ranks
                    // agree on its size and on whether to bin again.
                    uint64_t agreed[2] = {blocks, 0};
                    if (group) group->MaxU64(agreed, 1);
                    auto& store = table(size_t(agreed[0]));
                    store.Clear();
                    Table& bins = store.Samples();
                    if (!group || group->Rank() == 0) bins.AddBlocks(carried.data(), carriedBlocks);
                    for (int e = 0; e < eyes; ++e)
                        forEyeTiles(e, [&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                            bin(e, r, bins, rc);
                        });
                    agreed[0] = bins.Dropped(), agreed[1] = bins.NumBlocks() >= maxBlocks;
                    if (group) {
                        BinAccumulators<Table> acc(bins);
                        AllReduce(*group, acc);
                        agreed[0] = bins.Dropped();
                        group->MaxU64(agreed, 2);
                    }
                    if (agreed[0] == 0 || agreed[1]) break;
                    blocks = 2 * bins.NumBlocks();
                }
                const auto& store = table(blocks);
                const Table& bins = store.Samples();
                if (temporalHits) c.tsc->SetHitStoreFrame(int64_t(c.tsc->Frame()));
                binBlocksUsed = bins.BlocksUsed();
                for (int e = 0; e < eyes; ++e) {
                    eyeSums[e]->hitBinsDropped += bins.Dropped();
                    eyeSums[e]->hitBinBytes = bins.BytesUsed();
                    forEyeTiles(e, [&](const tbb::blocked_range2d<int>& r, RayCounts&) {
                        resolve(e, r, store);
                        if (e == 0)
                            pixelSamplesDone +=
                                uint64_t(r.rows().size()) * r.cols().size() * uint64_t(s1 - s0);
                    });
                }
            };
            if (pathHits)
                binAndResolve(
                    [&](size_t blocks) -> LightHitStore& { return c.tsc->LightStore(blocks); },
                    [&](int e, const tbb::blocked_range2d<int>& r, RadianceBins& bins, RayCounts&) {
                        PathHitsAdd(*eyeContext[e], r, s0, s1, bias, blend, eyeRecords(e),
                                    eyeBinned(e), bins);
                    },
                    [&](int e, const tbb::blocked_range2d<int>& r, const LightHitStore& store) {
                        PathHitsResolve(*eyeContext[e], r, s0, s1, eyeRecords(e), eyeBinned(e),
                                        perHit.data() + size_t(e) * framePixels, store,
                                        relativeVariance, eyeSums[e]->rgb.data(),
                                        eyeSums[e]->own.data());
                    });
            else
                binAndResolve(
                    [&](size_t blocks) -> AoHitStore& { return c.tsc->AoStore(blocks); },
                    [&](int e, const tbb::blocked_range2d<int>& r, HitBins& bins, RayCounts& rc) {
                        AoHitsBin(*eyeContext[e], r, s0, s1, bias, eyeRecords(e),
                                  ownAo.data() + size_t(e) * passSamples, bins, rc);
                    },
                    [&](int e, const tbb::blocked_range2d<int>& r, const AoHitStore& store) {
                        AoHitsResolve(*eyeContext[e], r, s0, s1, eyeRecords(e),
                                      ownAo.data() + size_t(e) * passSamples, store,
                                      eyeSums[e]->rgb.data(), eyeSums[e]->own.data());
                    });
        } else if (VisibleTexels* visible = fc.Visible()) {
            forTiles([&](const tbb::blocked_range2d<int>& r, RayCounts& rc) {
                MarkVisibleTexels(c, *visible, r, s0, s1, fromPrepass ? &passTexels : nullptr, rc);
            });
            // Over many ranks every rank's footprints keep the texels any rank's rows see, as
            // one process's do: the ranks or their marks together before anything shades.
            if (group) {
                VisibleWords words(*visible);
                AllReduce(*group, words);
            }
        }
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
        for (int e = 0; e < eyes; ++e) eyeSums[e]->passes = passesRun;
        if (opt.seconds > 0.0f) {
            // Over many ranks rank 0's clock decides for all: the budget is the job's.
            double clock[2] = {std::chrono::duration<double>(Clock::now() - passStart).count(),
                               opt.seconds - elapsed()};
            if (group) group->Broadcast(clock, sizeof clock, 0);
            const double passTime = clock[0], left = clock[1];
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

namespace {

/// Render, or with `rightOpt` (shading at the hits) both eyes of a stereo render into one store:
/// the left eye's result returned, the right eye's in `right`.
RenderResult RenderFrame(const RenderScene& rs, const RenderOptions& opt, TextureSpaceCache* cache,
                         const RenderOptions* rightOpt = nullptr, RenderResult* right = nullptr) {
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
                   std::vector<PixelAovs>(opt.aovs.Any() ? numPixels : 0),
                   {}};
    tbb::enumerable_thread_specific<RayCounts> counts;
    const uint64_t sent0 = opt.ranks ? opt.ranks->BytesSent() : 0;
    const uint64_t received0 = opt.ranks ? opt.ranks->BytesReceived() : 0;
    // The right eye: its own camera, sums and counts, the left eye's store and product records
    // (the per-pixel cache counts are the left eye's only).
    std::optional<Context> rightCtx;
    std::optional<FrameCache> rightCache;
    FrameSums rightSums;
    tbb::enumerable_thread_specific<RayCounts> rightCounts;
    SecondEye second{};
    if (rightOpt) {
        if (!ctx.tsc || !ShadesAtHits(opt) || (opt.ranks && opt.ranks->Size() > 1))
            throw InputError("render options",
                             "both eyes into one store need texture-space shading at the hits "
                             "on one process");
        rightCtx.emplace(rs, *rightOpt);
        rightCache.emplace(*rightCtx, *rightOpt, ctx.tsc, FrameCache::Prepass::None);
        rightCtx->psrCache = ctx.psrCache, rightCtx->psrStats = ctx.psrStats;
        rightSums.rgb.assign(numPixels * 3, 0.0);
        second = {&*rightCtx, &rightSums, &rightCounts};
    }
    // Hit binning's per-pixel own sums: the cache's arrays, lent to this render (PassScratch).
    PassScratch* const scratch =
        ctx.tsc && ShadesAtHits(opt) ? &ctx.tsc->PassTexelScratch() : nullptr;
    if (scratch) sums.own.swap(scratch->own[0]), rightSums.own.swap(scratch->own[1]);
    const int done = RunPasses(ctx, frameCache, sums, counts, start, rightOpt ? &second : nullptr) -
                     opt.firstSample;
    const uint64_t passBytes =
        opt.ranks ? opt.ranks->BytesSent() + opt.ranks->BytesReceived() - sent0 - received0 : 0;
    if (opt.ranks && opt.ranks->Size() > 1) {
        // Every rank's rows to rank 0: each pixel's sums are one rank's, as one process adds
        // them (no reduction of the image).
        RankGroup& g = *opt.ranks;
        const RowSplit split{opt.rowBegin, rowEnd, g.Rank(), g.Size()};
        GatherRows(g, split, sums.rgb.data(), size_t(W) * 3 * sizeof(double));
        if (!sums.aovs.empty()) GatherRows(g, split, sums.aovs.data(), W * sizeof(PixelAovs));
        if (!sums.own.empty())
            GatherRows(g, split, sums.own.data(), size_t(W) * 4 * sizeof(double));
        if (opt.pixelCache)
            GatherRows(g, split, opt.pixelCache->data(), W * sizeof(PixelCacheCounts));
    }

    // An eye's image, AOVs, rays and hit-bin statistics from its sums.
    auto eyeResult = [&](const RenderOptions& o, const FrameSums& fs,
                         const tbb::enumerable_thread_specific<RayCounts>& rays) {
        RenderResult er;
        er.beauty = Image(W, H, 3);
        for (size_t p = 0; p < numPixels * 3; ++p) er.beauty.data[p] = float(fs.rgb[p] / done);
        // Hit binning: the pixels' own samples as the finest level (texture_space.h).
        if (!fs.own.empty())
            CombineWithOwnSamples(fs.rgb.data(), fs.own.data(), W, o.rowBegin, rowEnd, done,
                                  er.beauty.data.data(), scratch ? &scratch->combine : nullptr);
        er.aovs = AovLayers(fs.aovs, o.aovs, W, H, done);
        for (const RayCounts& rc : rays) {
            er.stats.cameraRays += rc.camera;
            er.stats.cameraRaysCulled += rc.cameraCulled;
            er.stats.shadowRays += rc.shadow;
            er.stats.bounceRays += rc.bounce;
        }
        er.stats.sppDone = done;
        er.stats.hitBinsDropped = fs.hitBinsDropped;
        er.stats.hitBinBytes = fs.hitBinBytes;
        er.stats.passes = fs.passes;
        return er;
    };
    RenderResult result = eyeResult(opt, sums, counts);
    // The other ranks' CPU time (microseconds), added to this rank's at the end: the job's work.
    uint64_t othersCpu = 0;
    if (opt.ranks && opt.ranks->Size() > 1) {
        const uint64_t cpu = uint64_t(1e6 * double(std::clock() - cpuStart) / CLOCKS_PER_SEC);
        uint64_t rays[6] = {result.stats.cameraRays, result.stats.cameraRaysCulled,
                            result.stats.shadowRays, result.stats.bounceRays,
                            sums.hitBinsDropped,     cpu};
        opt.ranks->SumU64(rays, 6);
        result.stats.cameraRays = rays[0], result.stats.cameraRaysCulled = rays[1];
        result.stats.shadowRays = rays[2], result.stats.bounceRays = rays[3];
        sums.hitBinsDropped = rays[4], othersCpu = rays[5] - cpu;
    }
    for (const CacheStats& cs : frameCache.Stats()) result.stats.cache.Merge(cs);
    for (const RecordStats& ps : psrStats) result.stats.psr.Merge(ps);
    result.stats.psrBytes = psrCache ? psrCache->BytesUsed() : 0;
    if (opt.ranks) {
        result.stats.bytesSent = opt.ranks->BytesSent() - sent0;
        result.stats.bytesReceived = opt.ranks->BytesReceived() - received0;
        result.stats.passBytes = passBytes;
    }
    result.stats.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    result.stats.cpuSeconds = double(std::clock() - cpuStart) / CLOCKS_PER_SEC + 1e-6 * othersCpu;
    if (rightOpt) {
        // The eyes' passes interleave (each pass bins both, then reads both back): each eye
        // gets half of the time, and its own rays and cache traffic.
        *right = eyeResult(*rightOpt, rightSums, rightCounts);
        for (const CacheStats& cs : rightCache->Stats()) right->stats.cache.Merge(cs);
        result.stats.seconds *= 0.5, result.stats.cpuSeconds *= 0.5;
        right->stats.seconds = result.stats.seconds,
        right->stats.cpuSeconds = result.stats.cpuSeconds;
    }
    if (scratch) sums.own.swap(scratch->own[0]), rightSums.own.swap(scratch->own[1]);
    return result;
}

}  // namespace

RenderResult Render(const RenderScene& rs, const RenderOptions& opt, TextureSpaceCache* cache) {
    return RenderFrame(rs, opt, cache);
}

void RenderEyesAtHits(const RenderScene& rs, const RenderOptions& left, const RenderOptions& right,
                      TextureSpaceCache* cache, RenderResult* leftOut, RenderResult* rightOut) {
    *leftOut = RenderFrame(rs, left, cache, &right, rightOut);
}

}  // namespace texcache
