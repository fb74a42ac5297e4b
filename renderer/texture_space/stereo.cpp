// SPDX-License-Identifier: Apache-2.0
#include "renderer/texture_space/stereo.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <memory>

#include "texcache/error.h"

namespace texcache {

namespace {

/// Adds the cost of `p` (time, rays, cache traffic) to `s`.
void AddCost(RenderStats* s, const RenderStats& p) {
    s->seconds += p.seconds;
    s->cpuSeconds += p.cpuSeconds;
    s->cameraRays += p.cameraRays;
    s->cameraRaysCulled += p.cameraRaysCulled;
    s->shadowRays += p.shadowRays;
    s->bounceRays += p.bounceRays;
    s->cache.Merge(p.cache);
    s->psr.Merge(p.psr);
    s->psrBytes = std::max(s->psrBytes, p.psrBytes);
}

/// Adds a render of more samples of an eye into what that eye has so far (images weighted by
/// their sample counts, AOVs from the first render only, costs summed).
void AddSamples(RenderResult* eye, RenderResult&& part) {
    RenderStats& s = eye->stats;
    if (s.sppDone == 0) {
        const RenderStats before = s;  // a prepass may have been counted already
        *eye = std::move(part);
        AddCost(&s, before);
        return;
    }
    const float wNew = float(part.stats.sppDone) / float(s.sppDone + part.stats.sppDone);
    for (size_t i = 0; i < eye->beauty.data.size(); ++i)
        eye->beauty.data[i] += (part.beauty.data[i] - eye->beauty.data[i]) * wNew;
    s.sppDone += part.stats.sppDone;
    AddCost(&s, part.stats);
}

/// Pastes rows [y0, y1) of a band's render (beauty and AOVs) into `into`, the render of the same
/// samples of the other rows so far (empty before the first band), and adds the band's cost.
void PasteRows(RenderResult* into, RenderResult&& band, int y0, int y1) {
    if (into->beauty.data.empty()) {
        *into = std::move(band);
        return;
    }
    auto paste = [&](Image& dst, const Image& src) {
        const size_t row = size_t(src.width) * size_t(src.channels);
        std::copy(src.data.begin() + ptrdiff_t(row * size_t(y0)),
                  src.data.begin() + ptrdiff_t(row * size_t(y1)),
                  dst.data.begin() + ptrdiff_t(row * size_t(y0)));
    };
    paste(into->beauty, band.beauty);
    for (size_t l = 0; l < into->aovs.size() && l < band.aovs.size(); ++l)
        paste(into->aovs[l].image, band.aovs[l].image);
    AddCost(&into->stats, band.stats);
}

/// Whether renders with these options restrict footprints to visible texels (as FrameCache).
bool VisibleFootprints(const RenderOptions& o, const TextureSpaceCache& cache) {
    return VisibleOnly(o.texture.footprint, o.integrator) && o.texture.constantTerm < 0.0f &&
           cache.AnyFootprint();
}

}  // namespace

RenderStats BothEyes(const StereoResult& r) {
    RenderStats s = r.left.stats;
    AddCost(&s, r.right.stats);
    return s;
}

Image SideBySide(const Image& left, const Image& right) {
    Image out(left.width + right.width, std::max(left.height, right.height), 3);
    for (int y = 0; y < out.height; ++y)
        for (int x = 0; x < out.width; ++x) {
            const Image& src = x < left.width ? left : right;
            const int sx = x < left.width ? x : x - left.width;
            if (y >= src.height) continue;
            const float* p = src.At(sx, y);
            float* q = out.At(x, y);
            for (int k = 0; k < 3; ++k) q[k] = src.channels >= 3 ? p[k] : p[0];
        }
    return out;
}

StereoRig StereoRigOf(const Camera& camera) {
    return {camera.eyeSeparation, camera.convergence};
}

float DefaultEyeSeparation(float convergence) {
    return convergence / 30.0f;
}

void CheckStereoRig(const StereoRig& rig, const std::string& where) {
    if (!(std::isfinite(rig.eyeSeparation) && rig.eyeSeparation >= 0.0f))
        throw InputError(where, "the eye separation must be a finite number >= 0 (got " +
                                    std::to_string(rig.eyeSeparation) + ")");
    if (!(std::isfinite(rig.convergence) && rig.convergence > 0.0f))
        throw InputError(where, "the convergence distance must be a finite number > 0 (got " +
                                    std::to_string(rig.convergence) + ")");
}

StereoResult RenderStereo(const RenderScene& rs, const RenderOptions& opt, const StereoRig& rig,
                          TextureSpaceCache* cache, StereoReuse reuse, StereoOrder order) {
    using Clock = std::chrono::steady_clock;
    CheckStereoRig(rig, "stereo rig");
    std::unique_ptr<TextureSpaceCache> own;
    if (opt.texture.enabled && !cache) {
        own = std::make_unique<TextureSpaceCache>(rs, opt.texture);
        cache = own.get();
    }
    if (!opt.texture.enabled) cache = nullptr;
    if (cache && ShadesAtHits(opt)) {
        // Shading at the hits: both eyes' hits go into one store, pass by pass (see the note).
        RenderOptions eye[2] = {opt, opt};
        for (int e : {0, 1}) {
            eye[e].eyeOffset = (e == 0 ? -0.5f : 0.5f) * rig.eyeSeparation;
            eye[e].eyeConvergence = rig.convergence;
        }
        StereoResult out;
        RenderEyesAtHits(rs, eye[0], eye[1], cache, &out.left, &out.right);
        return out;
    }
    const int spp = std::max(opt.spp, 1);
    const bool progressive = cache && cache->Progressive() && opt.texture.passSpp > 0 &&
                             opt.texture.constantTerm < 0.0f && spp > opt.texture.passSpp;
    // Texels: the right eye's visible texels are marked before the left eye renders, so that
    // the left eye's footprints also shade the samples the right eye will look up. Neighbour
    // does without: the neighbours serve most of those texels, and the shared set would move
    // shading from the right eye into the left one rather than save it (on car AO the right
    // eye's share stays the same while the left eye's time grows; without it the left eye is
    // exactly the mono render).
    // A single pass under a time budget does not know its sample count before the left eye
    // renders: the right eye cannot mark its texels first, and the eyes keep their own sets.
    const bool shareVisibility = cache && reuse == StereoReuse::Texels &&
                                 VisibleFootprints(opt, *cache) &&
                                 (progressive || opt.seconds <= 0.0f);
    if (shareVisibility) cache->Visibility(opt.width, opt.height);  // starts empty

    // Bands (see the note at the top): the eyes take turns band of rows by band of rows, so the
    // second eye finds the first eye's samples of a band before later bands evict them. Not
    // with visible footprints (each eye's footprints need its whole frame's visible texels
    // marked first) nor for a single pass under a time budget (the left eye's time sets the
    // sample count).
    const bool banded = order == StereoOrder::Bands && cache && !VisibleFootprints(opt, *cache) &&
                        !shareVisibility && (progressive || opt.seconds <= 0.0f);

    StereoResult out;
    RenderResult* eyes[2] = {&out.left, &out.right};
    // Samples [s0, s1) of rows [y0, y1) (y1 0: to the last row) of one eye (0 left, 1 right).
    auto renderRows = [&](int eye, int s0, int s1, float seconds, VisibilityPrepass prepass, int y0,
                          int y1) {
        RenderOptions o = opt;
        o.firstSample = s0;
        o.spp = s1;
        o.seconds = seconds;
        o.rowBegin = y0, o.rowEnd = y1;
        o.eyeOffset = (eye == 0 ? -0.5f : 0.5f) * rig.eyeSeparation;
        o.eyeConvergence = rig.convergence;
        o.visibilityPrepass = shareVisibility ? prepass : VisibilityPrepass::Own;
        // The second eye's lookups may take a cached neighbour (restored however Render ends).
        struct NeighbourReuse {
            TextureSpaceCache* c;
            explicit NeighbourReuse(TextureSpaceCache* cache) : c(cache) {
                if (c) c->ReuseNeighbourTexels(true);
            }
            ~NeighbourReuse() {
                if (c) c->ReuseNeighbourTexels(false);
            }
        } guard(eye == 1 && reuse == StereoReuse::Neighbour ? cache : nullptr);
        return Render(rs, o, cache);
    };
    // Adds a render of samples [s0, s1) of every row to an eye.
    auto add = [&](int eye, RenderResult&& r) {
        if (eyes[eye]->stats.sppDone > 0) r.aovs.clear();
        AddSamples(eyes[eye], std::move(r));
    };
    auto render = [&](int eye, int s0, int s1, float seconds,
                      VisibilityPrepass prepass = VisibilityPrepass::Keep) {
        RenderResult r = renderRows(eye, s0, s1, seconds, prepass, 0, 0);
        if (prepass == VisibilityPrepass::Only) return AddCost(&eyes[eye]->stats, r.stats);
        add(eye, std::move(r));
    };
    // Band by band. A band holds about an eighth of the sample cache's slots of the left eye's
    // shading (at its rate over the bands so far): inserting n samples into m direct-mapped slots
    // evicts about n^2 / 2m of them, 1/16 of the band's own at n = m / 8.
    auto pairBands = [&](int s0, int s1) {
        const int H = opt.height;
        const double bandSamples = double(cache->SampleSlots()) / 16.0;
        RenderResult part[2];
        for (int y = 0, rows = std::min(H, 16); y < H;) {
            const int y1 = std::min(H, y + rows);
            uint64_t leftShaded = 0;
            for (int eye : {0, 1}) {
                RenderResult r = renderRows(eye, s0, s1, 0.0f, VisibilityPrepass::Own, y, y1);
                if (eye == 0) leftShaded = r.stats.cache.samplesShaded;
                PasteRows(&part[eye], std::move(r), y, y1);
            }
            // The next band at this band's rate, growing at most twofold: the rate changes down
            // the frame (sky above, the object below).
            const double perRow = std::max(double(leftShaded) / double(y1 - y), 1.0);
            rows = std::clamp(int(std::min(bandSamples / perRow, 2.0 * rows)) / 8 * 8, 8, H);
            y = y1;
        }
        for (int eye : {0, 1}) add(eye, std::move(part[eye]));
    };
    // Visible footprints: the right eye's texels are marked first (at its cost), so that the
    // left eye's footprints also shade the samples the right eye will look up.
    auto pair = [&](int s0, int s1, float leftSeconds) {
        if (banded) return pairBands(s0, s1);
        if (shareVisibility) render(1, s0, s1, 0.0f, VisibilityPrepass::Only);
        const int before = out.left.stats.sppDone;
        render(0, s0, s1, leftSeconds);
        render(1, s0, s0 + (out.left.stats.sppDone - before), 0.0f);
    };

    if (!progressive) {
        // With a time budget the left eye's half of it sets the sample count of both.
        pair(0, spp, opt.seconds > 0.0f ? 0.5f * opt.seconds : 0.0f);
        return out;
    }
    const auto start = Clock::now();
    const int passSpp = opt.texture.passSpp;
    for (int s0 = 0; s0 < spp; s0 += passSpp) {
        const auto pairStart = Clock::now();
        if (s0 > 0) {
            // The next pass re-shades the cache (texture_space.h): its cost is the left eye's,
            // as in a mono render, where Render begins it.
            const std::clock_t cpu0 = std::clock();
            if (cache->Pass() < UINT32_MAX) cache->BeginPass(cache->Pass() + 1);
            out.left.stats.seconds +=
                std::chrono::duration<double>(Clock::now() - pairStart).count();
            out.left.stats.cpuSeconds += double(std::clock() - cpu0) / CLOCKS_PER_SEC;
        }
        pair(s0, std::min(spp, s0 + passSpp), 0.0f);
        if (opt.seconds > 0.0f) {
            const auto now = Clock::now();
            const double last = std::chrono::duration<double>(now - pairStart).count();
            const double left = opt.seconds - std::chrono::duration<double>(now - start).count();
            if (left < last) break;  // the next pair would not fit
        }
    }
    return out;
}

}  // namespace texcache
