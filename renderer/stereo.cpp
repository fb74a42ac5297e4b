// SPDX-License-Identifier: Apache-2.0
#include "renderer/stereo.h"

#include <chrono>
#include <cmath>
#include <ctime>
#include <memory>

#include "texcache/error.h"

namespace texcache {

namespace {

/// Adds a render of more samples of an eye into what that eye has so far (images weighted by
/// their sample counts; statistics summed).
void AddSamples(RenderResult* eye, RenderResult&& part) {
    RenderStats& s = eye->stats;
    const RenderStats& p = part.stats;
    if (s.sppDone == 0) {
        *eye = std::move(part);
        return;
    }
    const float wOld = float(s.sppDone) / float(s.sppDone + p.sppDone);
    for (size_t i = 0; i < eye->beauty.data.size(); ++i)
        eye->beauty.data[i] += (part.beauty.data[i] - eye->beauty.data[i]) * (1.0f - wOld);
    s.seconds += p.seconds;
    s.cpuSeconds += p.cpuSeconds;
    s.sppDone += p.sppDone;
    s.cameraRays += p.cameraRays;
    s.shadowRays += p.shadowRays;
    s.bounceRays += p.bounceRays;
    s.cache.Merge(p.cache);
    s.psr.Merge(p.psr);
    s.psrBytes = std::max(s.psrBytes, p.psrBytes);
}

}  // namespace

StereoRig StereoRigOf(const Camera& camera) {
    return {camera.eyeSeparation, camera.convergence};
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
                          TextureSpaceCache* cache) {
    using Clock = std::chrono::steady_clock;
    CheckStereoRig(rig, "stereo rig");
    std::unique_ptr<TextureSpaceCache> own;
    if (opt.texture.enabled && !cache) {
        own = std::make_unique<TextureSpaceCache>(rs, opt.texture);
        cache = own.get();
    }
    if (!opt.texture.enabled) cache = nullptr;
    StereoResult out;
    RenderResult* eyes[2] = {&out.left, &out.right};
    auto render = [&](int eye, int s0, int s1, float seconds) {
        RenderOptions o = opt;
        o.firstSample = s0;
        o.spp = s1;
        o.seconds = seconds;
        o.eyeOffset = (eye == 0 ? -0.5f : 0.5f) * rig.eyeSeparation;
        o.eyeConvergence = rig.convergence;
        RenderResult r = Render(rs, o, cache);
        if (eyes[eye]->stats.sppDone > 0) r.aovs.clear();
        AddSamples(eyes[eye], std::move(r));
    };
    const int spp = std::max(opt.spp, 1);
    const bool progressive = cache && cache->Progressive() && opt.texture.passSpp > 0 &&
                             opt.texture.constantTerm < 0.0f && spp > opt.texture.passSpp;
    if (!progressive) {
        render(0, 0, spp, opt.seconds > 0.0f ? 0.5f * opt.seconds : 0.0f);
        render(1, 0, out.left.stats.sppDone, 0.0f);
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
        const int s1 = std::min(spp, s0 + passSpp);
        render(0, s0, s1, 0.0f);
        render(1, s0, s1, 0.0f);
        if (opt.seconds > 0.0f) {
            const auto now = Clock::now();
            const double pair = std::chrono::duration<double>(now - pairStart).count();
            const double left = opt.seconds - std::chrono::duration<double>(now - start).count();
            if (left < pair) break;  // the next pair would not fit
        }
    }
    return out;
}

}  // namespace texcache
