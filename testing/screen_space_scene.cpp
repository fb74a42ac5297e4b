// SPDX-License-Identifier: Apache-2.0
// The synthetic frames' ray caster (screen_space_scene.h says what it renders).
#include "testing/screen_space_scene.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace texcache::test {

FrameBuffers SynthRender(const SynthScene& sc, int frame, uint32_t seed, int spp) {
    using namespace synth;
    FrameBuffers f;
    const int w = sc.width, h = sc.height;
    const size_t n = size_t(w) * size_t(h);
    f.width = w, f.height = h;
    f.camera = SynthCamera(sc, float(frame));
    f.time = float(frame) / 30.0f;
    const glm::vec3 nanv(kNaNf);
    f.emitted.assign(n, glm::vec3(0.0f));
    f.shading.assign(n, glm::vec3(0.0f));
    f.visibility.assign(n, 0.0f);
    if (sc.glossy) f.glossy.assign(n, glm::vec3(0.0f));
    if (sc.indirect) f.indirect.assign(n, glm::vec3(0.0f));
    f.position.assign(n, nanv), f.normal.assign(n, nanv);
    f.depth.assign(n, kInf), f.roughness.assign(n, 0.0f);
    f.albedo.assign(n, glm::vec3(0.0f)), f.specular.assign(n, glm::vec3(0.0f));
    f.objectId.assign(n, -1);
    f.prevPosition.assign(n, nanv), f.prevNormal.assign(n, nanv);
    f.blocker.assign(n, nanv), f.prevBlocker.assign(n, nanv);
    f.lightSample.assign(n, nanv), f.prevLightSample.assign(n, nanv);
    f.glossyHit.assign(n, nanv), f.prevGlossyHit.assign(n, nanv);
    if (sc.cones && sc.indirect) f.cones.assign(n * screen::kNumCones, glm::vec3(0.0f));
    const glm::mat4 inv = glm::inverse(f.camera.worldToClip);
    const float fr = float(frame);
    const glm::vec3 light = sc.light + sc.lightVelocity * fr;

    tbb::parallel_for(tbb::blocked_range<int>(0, h, 4), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y)
            for (int x = 0; x < w; ++x) {
                const size_t i = size_t(y) * size_t(w) + size_t(x);
                const glm::vec2 ndc((float(x) + 0.5f) / float(w) * 2.0f - 1.0f,
                                    1.0f - (float(y) + 0.5f) / float(h) * 2.0f);
                glm::vec4 a = inv * glm::vec4(ndc, -1.0f, 1.0f),
                          b = inv * glm::vec4(ndc, 1.0f, 1.0f);
                const glm::vec3 org = f.camera.position;
                const glm::vec3 dir = glm::normalize(glm::vec3(b) / b.w - glm::vec3(a) / a.w);
                const Hit hit = Trace(sc, fr, org, dir, 0.0f);
                if (hit.obj < 0) {
                    f.emitted[i] = Sky(sc, dir);
                    continue;
                }
                const SynthObject& o = sc.objects[size_t(hit.obj)];
                const glm::vec3 p = hit.p, nrm = hit.n;
                f.position[i] = p, f.normal[i] = nrm, f.depth[i] = hit.t;
                f.objectId[i] = o.id, f.albedo[i] = o.albedo, f.specular[i] = o.f0;
                const float rough = Roughness(o, p, fr);
                f.roughness[i] = glm::length(o.f0) > 0.0f ? rough : 0.0f;
                f.prevPosition[i] = p - o.velocity, f.prevNormal[i] = nrm;
                const bool isGlossy = glm::length(o.f0) > 0.0f;
                glm::vec3 shading(0.0f), gl(0.0f), ind(0.0f);
                float vis = 0.0f;
                glm::vec3 cones[screen::kNumCones] = {};
                const auto axes = screen::ConeAxes(nrm);
                glm::vec3 t1, t2;
                screen::ConeFrame(nrm, &t1, &t2);
                const glm::vec3 wo = -dir;
                const glm::vec3 wol(glm::dot(wo, t1), glm::dot(wo, t2), glm::dot(wo, nrm));
                for (int s = 0; s < spp; ++s) {
                    Rng rng(uint32_t(i) * 9781u + uint32_t(frame) * 6271u + seed * 7919u +
                            uint32_t(s) * 104729u);
                    // Direct light: one sample on the light's sphere (a point when radius 0).
                    glm::vec3 ls = light;
                    if (sc.lightRadius > 0.0f) {
                        const float z = 1.0f - 2.0f * rng.Uniform(),
                                    ph = 2.0f * kPi * rng.Uniform();
                        const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
                        ls += sc.lightRadius * glm::vec3(r * std::cos(ph), r * std::sin(ph), z);
                    }
                    const glm::vec3 tol = ls - p;
                    const float dist = glm::length(tol);
                    const glm::vec3 wl = tol / dist;
                    const float cosl = std::max(0.0f, glm::dot(nrm, wl));
                    if (!isGlossy)
                        shading += o.albedo / kPi * sc.lightIntensity * cosl / (dist * dist);
                    const Hit sh = Trace(sc, fr, p + 1e-4f * nrm, wl);
                    const bool blocked = sh.obj >= 0 && sh.t < dist - 1e-4f;
                    vis += blocked ? 0.0f : 1.0f;
                    if (s == 0) {
                        f.lightSample[i] = ls, f.prevLightSample[i] = ls - sc.lightVelocity;
                        if (blocked) {
                            f.blocker[i] = sh.p;
                            f.prevBlocker[i] = sh.p - sc.objects[size_t(sh.obj)].velocity;
                        }
                    }
                    if (isGlossy && sc.glossy) {
                        const glm::vec3 m =
                            SampleVndf(wol, std::max(rough, 1e-3f), rng.Uniform(), rng.Uniform());
                        const glm::vec3 wil = 2.0f * glm::dot(wol, m) * m - wol;
                        if (wil.z > 0.0f) {
                            const glm::vec3 wi = wil.x * t1 + wil.y * t2 + wil.z * nrm;
                            const Hit gh = Trace(sc, fr, p + 1e-4f * nrm, wi);
                            const glm::vec3 L = gh.obj >= 0 ? sc.objects[size_t(gh.obj)].albedo *
                                                                  sc.objects[size_t(gh.obj)].ambient
                                                            : Sky(sc, wi);
                            const float a = std::max(rough, 1e-3f);
                            const float lo = Lambda(wol.z, a), li = Lambda(wil.z, a);
                            const float g = (1.0f + lo) / (1.0f + lo + li);
                            const float om = std::max(0.0f, glm::dot(wol, m));
                            const float fc = std::pow(1.0f - om, 5.0f);
                            gl += (o.f0 + (1.0f - o.f0) * fc) * g * L;
                            if (s == 0 && gh.obj >= 0) {
                                f.glossyHit[i] = gh.p;
                                f.prevGlossyHit[i] = gh.p - sc.objects[size_t(gh.obj)].velocity;
                            }
                        }
                    }
                    if (!isGlossy && sc.indirect) {
                        const float u1 = rng.Uniform(), u2 = rng.Uniform();
                        const float r = std::sqrt(u1), ph = 2.0f * kPi * u2;
                        const glm::vec3 wi = r * std::cos(ph) * t1 + r * std::sin(ph) * t2 +
                                             std::sqrt(std::max(0.0f, 1.0f - u1)) * nrm;
                        const Hit ih = Trace(sc, fr, p + 1e-4f * nrm, wi);
                        const glm::vec3 L = ih.obj >= 0 ? sc.objects[size_t(ih.obj)].albedo *
                                                              sc.objects[size_t(ih.obj)].ambient
                                                        : Sky(sc, wi);
                        ind += o.albedo * L;
                        screen::AddConeSample(axes, wi, L, cones);
                    }
                }
                const float inv = 1.0f / float(spp);
                f.shading[i] = shading * inv;
                f.visibility[i] = vis * inv;
                if (sc.glossy) f.glossy[i] = gl * inv;
                if (sc.indirect) f.indirect[i] = ind * inv;
                if (!f.cones.empty())
                    for (int k = 0; k < screen::kNumCones; ++k)
                        f.cones[i * screen::kNumCones + size_t(k)] = cones[k] * inv;
            }
    });
    return f;
}

}  // namespace texcache::test
