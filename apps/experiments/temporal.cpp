// SPDX-License-Identifier: Apache-2.0
// `texcache experiment temporal`: the screen-space stage over animated sequences (issue 5). For
// each animated scene, a sequence of 1-spp frame buffers is denoised by every method (spatial
// only, SVGF baseline, baseline + clamping, Zeng et al.'s reliable motion vectors), each with and
// without demodulation, and compared frame by frame with a high-sample render of the same frame.
//
// The reference is RenderFrameBuffers at many spp, composed: the same pixel-centre camera rays as
// the 1-spp input (frame_buffers_render.h), so it lines up pixel for pixel and the error is
// shading noise and temporal artefacts only (no edge anti-aliasing the stage cannot produce).
#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>

#include "experiment_util.h"
#include "renderer/frame_buffers/frame_buffers_render.h"
#include "renderer/image/metrics.h"
#include "renderer/render_policy.h"
#include "renderer/scene/scene_loader.h"
#include "screen_space/brdf_table.h"
#include "screen_space/screen_denoiser.h"
#include "texcache/error.h"

namespace texcache::experiments {

namespace {

namespace fs = std::filesystem;
using screen::Demodulation;
using screen::Method;

const std::vector<std::string> kScenes = {"anim_shadow", "anim_light", "anim_glossy",
                                          "anim_disocclusion", "anim_flythrough"};
// Scenes where history ghosts under traditional motion vectors (goal 1); the fly-through has only
// camera motion, which traditional vectors already follow.
const std::vector<std::string> kGhosting = {"anim_shadow", "anim_light", "anim_glossy",
                                            "anim_disocclusion"};
const std::array<Method, 4> kMethods = {Method::SpatialOnly, Method::Baseline,
                                        Method::BaselineClamp, Method::Reliable};
// The scenes set no frame rate; the renderer's `--frames` default.
constexpr float kFps = 24.0f;
// Demodulation may not raise a scene's mean RMSE by more than this (goal 2): the frame-to-frame
// spread of the per-frame RMSE ratio at this sample count is of this order (the per-frame rmse
// of demodulation on / off in results/temporal.csv), so a smaller change is not distinguishable
// from the noise of one 1-spp sequence.
constexpr double kNoise = 0.02;

const char* DemodName(Demodulation d) {
    return d == Demodulation::On ? "on" : "off";
}

/// `_` escaped for gnuplot's enhanced text (where it would start a subscript).
std::string Escaped(const std::string& s) {
    std::string out;
    for (char c : s) out += c == '_' ? std::string("\\\\_") : std::string(1, c);
    return out;
}

std::vector<float> Luminance(const Image& img) {
    std::vector<float> y(img.NumPixels());
    for (size_t p = 0; p < y.size(); ++p) {
        const float* c = &img.data[3 * p];
        y[p] = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
    }
    return y;
}

/// Mean |Y_now - Y_prev| over pixels finite in both: what flickers or lags between frames.
double MeanAbsChange(const std::vector<float>& now, const std::vector<float>& prev) {
    double sum = 0.0;
    size_t n = 0;
    for (size_t p = 0; p < now.size(); ++p)
        if (std::isfinite(now[p]) && std::isfinite(prev[p])) sum += std::abs(now[p] - prev[p]), ++n;
    return n ? sum / double(n) : NAN;
}

double Mean(const std::vector<double>& v) {
    double s = 0.0;
    size_t n = 0;
    for (double x : v)
        if (std::isfinite(x)) s += x, ++n;
    return n ? s / double(n) : NAN;
}

/// One denoising variant over the whole sequence: its own history.
struct Variant {
    Method method = Method::SpatialOnly;
    Demodulation demod = Demodulation::Off;
    std::string label;  ///< ablation variants: what differs from the default settings
    std::unique_ptr<screen::ScreenSpaceDenoiser> denoiser;
    std::vector<glm::vec3> image;  // reused allocation
    std::vector<float> prevY;
    std::vector<double> rmse, ssim, change, ms, cpuMs;  // per frame
    std::array<std::vector<double>, 3> part;            // per frame: RMSE of each component
};

// The components whose errors are reported separately: shading * visibility, glossy, indirect.
const char* const kParts[3] = {"direct", "glossy", "indirect"};

/// A component as an image, 0 where it is not finite or missing (so that every component's
/// RMSE is over all pixels and their squares add up to about the image's).
Image PartImage(const std::vector<glm::vec3>& c, int w, int h) {
    Image img(w, h, 3, 0.0f);
    for (size_t p = 0; p < c.size(); ++p)
        for (int k = 0; k < 3; ++k) img.data[3 * p + k] = std::isfinite(c[p][k]) ? c[p][k] : 0.0f;
    return img;
}

/// shading * visibility per pixel.
std::vector<glm::vec3> Shadowed(const std::vector<glm::vec3>& shading,
                                const std::vector<float>& vis) {
    std::vector<glm::vec3> out(shading.size(), glm::vec3(0.0f));
    for (size_t p = 0; p < out.size() && p < vis.size(); ++p) out[p] = shading[p] * vis[p];
    return out;
}

/// One row per frame of a series; a NaN or missing value (no change on the first frame, no time
/// for the reference) is an empty cell.
void AddRows(Table* t, const std::string& scene, const std::string& method,
             const std::string& demod, const Variant& v) {
    const auto cell = [](const std::vector<double>& xs, size_t f) {
        return f < xs.size() && std::isfinite(xs[f]) ? Format("%.6g", xs[f]) : std::string();
    };
    for (size_t f = 0; f < v.rmse.size(); ++f)
        t->Row()
            .Add(scene)
            .Add(method)
            .Add(demod)
            .Add(double(f))
            .Add(v.rmse[f])
            .Add(v.ssim[f])
            .Add(cell(v.change, f))
            .Add(cell(v.ms, f))
            .Add(cell(v.cpuMs, f))
            .Add(cell(v.part[0], f))
            .Add(cell(v.part[1], f))
            .Add(cell(v.part[2], f));
}

/// The w x h window where |a - b| (luminance) sums highest: where two methods disagree most.
Rect MostDifferent(const Image& a, const Image& b, int w, int h) {
    const std::vector<float> ya = Luminance(a), yb = Luminance(b);
    const int W = a.width, H = a.height;
    // Summed-area table of the difference.
    std::vector<double> sat(size_t(W + 1) * (H + 1), 0.0);
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const size_t p = size_t(y) * W + x;
            const double d = std::isfinite(ya[p] - yb[p]) ? std::abs(ya[p] - yb[p]) : 0.0;
            sat[size_t(y + 1) * (W + 1) + x + 1] = d + sat[size_t(y) * (W + 1) + x + 1] +
                                                   sat[size_t(y + 1) * (W + 1) + x] -
                                                   sat[size_t(y) * (W + 1) + x];
        }
    Rect best{0, 0, w, h};
    double bestSum = -1.0;
    for (int y = 0; y + h <= H; ++y)
        for (int x = 0; x + w <= W; ++x) {
            const auto S = [&](int xx, int yy) { return sat[size_t(yy) * (W + 1) + xx]; };
            const double s = S(x + w, y + h) - S(x, y + h) - S(x + w, y) + S(x, y);
            if (s > bestSum) bestSum = s, best = {x, y, w, h};
        }
    return best;
}

std::vector<std::string> SelectedScenes(const Setup& s) {
    if (s.only.empty()) return kScenes;
    std::vector<std::string> out;
    std::stringstream ss(s.only);
    std::string name;
    while (std::getline(ss, name, ',')) {
        if (name.empty()) continue;
        if (std::find(kScenes.begin(), kScenes.end(), name) == kScenes.end()) {
            std::string valid;
            for (const std::string& v : kScenes) valid += (valid.empty() ? "" : ", ") + v;
            throw InputError("--only",
                             "no animated scene named '" + name + "' (valid: " + valid + ")");
        }
        if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
    }
    if (out.empty()) throw InputError("--only", "names no scene");
    return out;
}

/// Per scene: mean metrics per variant (index = method * 2 + demodulation).
struct SceneResult {
    std::string name;
    std::array<double, 8> rmse{}, ssim{}, change{}, ms{}, cpuMs{};
    std::array<double, 8> firstRmse{};  ///< frame 0: no history yet, every method filters alone
    std::array<std::array<double, 3>, 8> part{}, firstPart{};  ///< per component (kParts)
    double refChange = 0.0, noisyRmse = 0.0, noisySsim = 0.0;
    double shadingRmse = 0.0, shadingRms = 0.0;  ///< the input's `shading` against the reference's
    Rect crop;
};

/// Pointers to the variants of both lists, in order.
std::vector<Variant*> AllOf(std::vector<Variant>& a, std::vector<Variant>& b) {
    std::vector<Variant*> out;
    for (Variant& v : a) out.push_back(&v);
    for (Variant& v : b) out.push_back(&v);
    return out;
}

int Index(Method m, Demodulation d) {
    return int(m) * 2 + (d == Demodulation::On ? 1 : 0);
}

}  // namespace

int Temporal(const Setup& s) {
    const std::vector<std::string> scenes = SelectedScenes(s);
    // Full size: what renders in a few minutes on 2 cores (the references are most of it).
    // Quick: the test's size (its ASan run is the longest of the suite's at 96x54 and 32 spp).
    const int W = s.quick ? 64 : 320, H = s.quick ? 36 : 180;
    const int frames = s.quick ? 8 : 24;
    const int refSpp = s.quick ? 16 : 64;
    const int cropScale = s.quick ? 4 : 2;
    const std::string csv = (fs::path(s.outDir) / "temporal.csv").string();
    Table table({"scene", "method", "demodulation", "frame", "rmse", "ssim", "temporal_change",
                 "ms", "cpu_ms", "rmse_direct", "rmse_glossy", "rmse_indirect"});
    // One BRDF table for all 8 denoisers (it takes a few hundred ms to build; ctest -R
    // ScreenSpaceTables.BrdfTable builds one).
    const auto brdf = std::make_shared<const screen::BrdfPreintegration>();
    std::vector<SceneResult> results;
    std::string ablationRows;  // --ablation: markdown rows, per scene

    for (const std::string& name : scenes) {
        std::vector<std::string> warnings;
        const Scene scene =
            LoadScene((fs::path(s.scenesDir) / (name + ".json")).string(), &warnings);
        Say("[temporal] %s: %d frames at %.0f fps, %dx%d, reference %d spp", name.c_str(), frames,
            kFps, W, H, refSpp);
        std::vector<Variant> variants;
        for (Method m : kMethods)
            for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
                Variant& v = variants.emplace_back();
                v.method = m, v.demod = d;
                v.denoiser =
                    std::make_unique<screen::ScreenSpaceDenoiser>(screen::DenoiserSettings{}, brdf);
            }
        // Ablation: Reliable with one setting changed at a time, demodulation on; the first
        // three are issue 5's defaults (every history clamped at 3 sigma, indirect in cones) and
        // its two halves, so that issue 21's change is measured against them in the same run.
        std::vector<Variant> ablation;
        if (s.ablation) {
            struct Change {
                const char* label;
                void (*apply)(screen::DenoiserSettings*);
            };
            const Change changes[] = {
                {"reliable, issue 5 defaults (glossy and indirect clamped, cones)",
                 [](screen::DenoiserSettings* d) {
                     d->reliableGlossyClampK = d->reliableIndirectClampK = 3.0f;
                     d->indirectCones = true;
                 }},
                {"reliable, glossy clamped (3 sigma)",
                 [](screen::DenoiserSettings* d) { d->reliableGlossyClampK = 3.0f; }},
                {"reliable, indirect in cones, clamped (3 sigma)",
                 [](screen::DenoiserSettings* d) {
                     d->reliableIndirectClampK = 3.0f, d->indirectCones = true;
                 }},
                {"reliable, indirect colour clamped (3 sigma)",
                 [](screen::DenoiserSettings* d) { d->reliableIndirectClampK = 3.0f; }},
                {"reliable, alpha 0.1", [](screen::DenoiserSettings* d) { d->alpha = 0.1f; }},
                {"reliable, glossy jitter 4 (issue 21's default)",
                 [](screen::DenoiserSettings* d) { d->maxGlossyJitter = 4.0f; }},
                {"reliable, glossy jitter 16",
                 [](screen::DenoiserSettings* d) { d->maxGlossyJitter = 16.0f; }},
                // k = 1000: no clamping in practice (history within 1000 sigma of the 3x3 mean).
                {"reliable, no clamping (visibility too)",
                 [](screen::DenoiserSettings* d) { d->reliableClampK = 1000.0f; }},
                {"reliable, visibility in SVGF order (clamped where the vectors disagree)",
                 [](screen::DenoiserSettings* d) {
                     d->reliableVisibilityOrder = screen::VisibilityOrder::Svgf;
                 }},
                {"reliable, visibility in Zeng's order", [](screen::DenoiserSettings* d) {
                     d->reliableVisibilityOrder = screen::VisibilityOrder::Zeng;
                 }}};
            for (const Change& c : changes) {
                Variant& v = ablation.emplace_back();
                v.method = Method::Reliable, v.demod = Demodulation::On, v.label = c.label;
                screen::DenoiserSettings set;
                c.apply(&set);
                v.denoiser = std::make_unique<screen::ScreenSpaceDenoiser>(set, brdf);
            }
        }
        std::vector<float> refPrevY;
        // The reference, the 1-spp frame and the stage's input, as series without a denoiser.
        Variant reference, input;
        std::vector<double> shadingRmse, shadingRms;
        Image lastRef, lastNoisy, lastClamp, lastReliable;
        RenderOptions frameOptions = BaseOptions(scene, IntegratorKind::Path, W, H);
        frameOptions.spp = 1;
        AnimationFrames posed(scene, RenderSceneOptions{}, frameOptions, kFps, "temporal");
        for (int f = 0; f < frames; ++f) {
            posed.Pose(f);  // the scene at the frame's time, fresh noise per frame
            const RenderScene& rs = posed.PosedScene();
            const RenderOptions& o = posed.Options();
            const float t = o.frameTime;
            screen::FrameBuffers fb, refFb;
            RenderFrameBuffers(rs, o, posed.PreviousTime(), &fb);
            RenderOptions r = o;
            r.spp = refSpp;
            r.seed = o.seed ^ 0x5851F42D4C957F2Dull;  // independent of the input's noise
            RenderFrameBuffers(rs, r, posed.PreviousTime(), &refFb);
            const Image ref = ToImage(refFb.Compose(), W, H);
            // `shading` is the unshadowed direct light from many light samples (no rays): its
            // residual noise against the reference's.
            const Image refShading = PartImage(refFb.shading, W, H);
            shadingRmse.push_back(RMSE(PartImage(fb.shading, W, H), refShading));
            shadingRms.push_back(RMSE(Image(W, H, 3, 0.0f), refShading));
            const Image noisy = ToImage(fb.Compose(), W, H);
            const Image refPart[3] = {PartImage(Shadowed(refFb.shading, refFb.visibility), W, H),
                                      PartImage(refFb.glossy, W, H),
                                      PartImage(refFb.indirect, W, H)};

            // The reference's own frame-to-frame change: what the motion itself accounts for.
            const std::vector<float> refY = Luminance(ref);
            const double rc = f ? MeanAbsChange(refY, refPrevY) : NAN;
            refPrevY = refY;
            reference.rmse.push_back(0.0), reference.ssim.push_back(1.0);
            reference.change.push_back(rc);
            input.rmse.push_back(RMSE(noisy, ref)), input.ssim.push_back(SSIM(noisy, ref));

            for (Variant* vp : AllOf(variants, ablation)) {
                Variant& v = *vp;
                v.denoiser->Denoise(fb, v.method, v.demod, &v.image);
                const Image img = ToImage(v.image, W, H);
                const std::vector<float> y = Luminance(img);
                const double change = f ? MeanAbsChange(y, v.prevY) : NAN;
                v.prevY = y;
                v.rmse.push_back(RMSE(img, ref));
                v.ssim.push_back(SSIM(img, ref));
                v.change.push_back(change);
                v.ms.push_back(v.denoiser->Timings().total);
                v.cpuMs.push_back(v.denoiser->CpuTimings().total);
                const std::vector<glm::vec3> parts[3] = {
                    Shadowed(fb.shading, v.denoiser->Visibility()), v.denoiser->Glossy(),
                    v.denoiser->Indirect()};
                for (int c = 0; c < 3; ++c)
                    v.part[c].push_back(RMSE(PartImage(parts[c], W, H), refPart[c]));
                if (f == frames - 1 && v.demod == Demodulation::On) {
                    if (v.method == Method::BaselineClamp) lastClamp = img;
                    if (v.method == Method::Reliable) lastReliable = img;
                }
            }
            if (f == frames - 1) lastRef = ref, lastNoisy = noisy;
            const Variant& rel = variants[Index(Method::Reliable, Demodulation::On)];
            const Variant& bc = variants[Index(Method::BaselineClamp, Demodulation::On)];
            Say("  frame %2d (t = %.3f): RMSE noisy %.4f, baseline+clamp %.4f, reliable %.4f "
                "(demod on)",
                f, t, input.rmse.back(), bc.rmse.back(), rel.rmse.back());
        }
        // Rows grouped by series (not by frame), so gnuplot's lines through them are unbroken.
        AddRows(&table, name, "reference", "-", reference);
        AddRows(&table, name, "noisy", "-", input);
        for (const Variant& v : variants)
            AddRows(&table, name, screen::MethodName(v.method), DemodName(v.demod), v);
        for (const Variant& v : ablation) {
            AddRows(&table, name, v.label, DemodName(v.demod), v);
            ablationRows +=
                Format("| %s | %s | %.4f | %.4f | %.4f | %.4f |\n", name.c_str(), v.label.c_str(),
                       Mean(v.rmse), Mean(v.part[0]), Mean(v.part[1]), Mean(v.part[2]));
        }
        for (Method m : {Method::Baseline, Method::BaselineClamp, Method::Reliable}) {
            const Variant& v = variants[Index(m, Demodulation::On)];
            if (s.ablation)
                ablationRows += Format("| %s | %s (default) | %.4f | %.4f | %.4f | %.4f |\n",
                                       name.c_str(), screen::MethodName(m), Mean(v.rmse),
                                       Mean(v.part[0]), Mean(v.part[1]), Mean(v.part[2]));
        }

        SceneResult sr;
        sr.name = name;
        for (const Variant& v : variants) {
            const int i = Index(v.method, v.demod);
            sr.rmse[i] = Mean(v.rmse);
            sr.firstRmse[i] = v.rmse.front();
            for (int c = 0; c < 3; ++c)
                sr.part[i][c] = Mean(v.part[c]), sr.firstPart[i][c] = v.part[c].front();
            sr.ssim[i] = Mean(v.ssim);
            sr.change[i] = Mean(v.change);
            sr.ms[i] = Mean(v.ms);
            sr.cpuMs[i] = Mean(v.cpuMs);
        }
        sr.refChange = Mean(reference.change);
        sr.noisyRmse = Mean(input.rmse);
        sr.noisySsim = Mean(input.ssim);
        sr.shadingRmse = Mean(shadingRmse), sr.shadingRms = Mean(shadingRms);
        // Crop of the last frame where baseline + clamping and reliable disagree most.
        sr.crop = MostDifferent(lastClamp, lastReliable, W / 2, H / 2);
        WriteImage(
            (fs::path(s.outDir) / ("temporal_crop_" + name + ".png")).string(),
            SideBySide({&lastNoisy, &lastRef, &lastClamp, &lastReliable}, sr.crop, cropScale));
        WriteImage((fs::path(s.outDir) / ("temporal_reference_" + name + ".png")).string(),
                   lastRef);
        results.push_back(sr);
    }
    table.Write(csv);

    // Plots: RMSE and temporal change over frames, one line per method (and demodulation).
    for (const SceneResult& r : results) {
        for (const bool change : {false, true}) {
            Plot p;
            p.png = (fs::path(s.outDir) /
                     Format("temporal_%s_%s.png", change ? "change" : "rmse", r.name.c_str()))
                        .string();
            p.title = Escaped(r.name) +
                      (change ? ": mean |luminance change| between frames (demodulation on)"
                              : ": RMSE against the per-frame reference");
            p.xLabel = "frame";
            p.yLabel = change ? "mean |dY|" : "RMSE";
            if (change)
                p.series.push_back(
                    {"reference", csv, 4, 7,
                     Format("strcol(1) eq '%s' && strcol(2) eq 'reference'", r.name.c_str())});
            // The change plot shows demodulation on only: the reference plus 8 lines would
            // repeat the palette's colours.
            for (Method m : kMethods)
                for (Demodulation d : {Demodulation::Off, Demodulation::On})
                    if (!change || d == Demodulation::On)
                        p.series.push_back(
                            {std::string(screen::MethodName(m)) +
                                 (d == Demodulation::On ? " (demod)" : ""),
                             csv, 4, change ? 7 : 5,
                             Format("strcol(1) eq '%s' && strcol(2) eq '%s' && strcol(3) eq '%s'",
                                    r.name.c_str(), screen::MethodName(m), DemodName(d))});
            Draw(p);
        }
    }

    // The summary.
    std::string md = "# Temporal reuse in the screen-space stage\n\n";
    md += Format(
        "%d frames of each animated scene at %.0f fps from its start time, %dx%d, 1 sample per "
        "pixel (`RenderFrameBuffers`), denoised by each method with its own "
        "`ScreenSpaceDenoiser` over the whole sequence (default `DenoiserSettings`). Reference: "
        "the same frame at %d spp through the same pixel-centre camera rays, composed, so errors "
        "are shading noise and temporal artefacts only. Means are over all frames, the first "
        "included (there every method is spatial only). %s\n\n"
        "**Unshadowed direct light.** The stage takes `shading` as noise-free (Zeng et al. "
        "evaluate it analytically) and passes it through unfiltered; `RenderFrameBuffers` "
        "gives it in closed form where the lights and materials have one (diffuse surfaces "
        "under quad lights, an environment and distant lights; then `visibility` is the ratio "
        "of 8 light samples' shadowed to unshadowed light) and estimates it from 32 light "
        "samples without shadow rays per pixel elsewhere (its shadow ray goes to one of them, "
        "resampled by contribution); the stage gets the frame as rendered. The input's "
        "`shading` error against the reference's is in the last table.\n\n",
        frames, kFps, W, H, refSpp,
        s.quick ? "**Quick mode: test-size images and few frames; not for conclusions.**" : "");
    md +=
        "**Temporal change** is the mean absolute change of linear luminance (Rec. 709) between "
        "consecutive frames, over frames 1..N-1. Moving objects, light and camera change the "
        "reference too; a method's **excess change** is its value minus the reference's (a "
        "difference, same units): positive means flicker or lag on top of the real motion, "
        "negative means the method smooths away real change (e.g. by keeping stale history). The "
        "reference's change includes its own residual noise (independent per frame), so the "
        "excess is biased low for every method alike: compare methods with each other, not with "
        "0.\n\n";
    md +=
        "| scene | method | RMSE (demod off) | RMSE (demod on) | SSIM (off) | SSIM (on) | excess "
        "change (off) | excess change (on) |\n|---|---|---|---|---|---|---|---|\n";
    for (const SceneResult& r : results) {
        md += Format("| %s | 1-spp input | %.4f | | %.4f | | | |\n", r.name.c_str(), r.noisyRmse,
                     r.noisySsim);
        for (Method m : kMethods) {
            const int off = Index(m, Demodulation::Off), on = Index(m, Demodulation::On);
            md +=
                Format("| %s | %s | %.4f | %.4f | %.4f | %.4f | %+.5f | %+.5f |\n", r.name.c_str(),
                       screen::MethodName(m), r.rmse[off], r.rmse[on], r.ssim[off], r.ssim[on],
                       r.change[off] - r.refChange, r.change[on] - r.refChange);
        }
        md += Format("| %s | reference change | | | | | %.5f (absolute) | |\n", r.name.c_str(),
                     r.refChange);
    }

    // Per component: where a method's error comes from, on the first frame (spatial filters
    // only) and over the sequence.
    md +=
        "\n**Per component.** RMSE of each denoised component against the reference's (direct = "
        "shading * visibility), over all pixels; frame 0 alone (no history: the spatial filters) "
        "and the mean over the sequence.\n\n| scene | method | demod | direct (frame 0) | glossy "
        "(frame 0) | indirect (frame 0) | direct (mean) | glossy (mean) | indirect (mean) |\n"
        "|---|---|---|---|---|---|---|---|---|\n";
    for (const SceneResult& r : results)
        for (Method m : kMethods)
            for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
                const int i = Index(m, d);
                md += Format("| %s | %s | %s | %.4f | %.4f | %.4f | %.4f | %.4f | %.4f |\n",
                             r.name.c_str(), screen::MethodName(m), DemodName(d), r.firstPart[i][0],
                             r.firstPart[i][1], r.firstPart[i][2], r.part[i][0], r.part[i][1],
                             r.part[i][2]);
            }

    md +=
        "\n**Unshadowed direct light of the input** (`shading`, 1 spp: closed form, 0 error, "
        "or 32 light samples without shadow rays) against the reference's, mean over frames: "
        "RMSE, and relative to the reference's RMS.\n\n| scene | shading RMSE | relative "
        "|\n|---|---|---|\n";
    for (const SceneResult& r : results)
        md += Format("| %s | %.4f | %.2f%% |\n", r.name.c_str(), r.shadingRmse,
                     100.0 * r.shadingRmse / r.shadingRms);
    md += "\n";
    // Goal 1: reliable below baseline + clamping on every ghosting scene (each demodulation).
    md +=
        "\n## Goals of issue 5\n\n"
        "1. *\"On each ghosting scene (anim_shadow, anim_light, anim_glossy, anim_disocclusion) "
        "reliable motion vectors give lower mean RMSE than baseline + clamping\"* (Paper: Zeng et "
        "al. 2021, Fig. 1, pink room: RMSE 0.0957 with reliable motion vectors vs 0.1585 for "
        "SVGF).\n\n";
    bool goal1 = true;
    int ghostingRun = 0;
    for (const SceneResult& r : results) {
        if (std::find(kGhosting.begin(), kGhosting.end(), r.name) == kGhosting.end()) continue;
        ++ghostingRun;
        for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
            const double rel = r.rmse[Index(Method::Reliable, d)];
            const double bc = r.rmse[Index(Method::BaselineClamp, d)];
            const bool ok = rel < bc;
            goal1 = goal1 && ok;
            // Frame 0 has no history, so a difference there is the filters', not the vectors'.
            md += Format(
                "   - %s, demodulation %s: reliable %.4f vs baseline+clamp %.4f (%.2fx) — %s%s; "
                "frame 0 alone (no history): %.4f vs %.4f\n",
                r.name.c_str(), DemodName(d), rel, bc, bc / rel, ok ? "MET" : "NOT MET",
                ok && bc / rel < 1.0 + kNoise ? " (margin below the 2% noise)" : "",
                r.firstRmse[Index(Method::Reliable, d)],
                r.firstRmse[Index(Method::BaselineClamp, d)]);
        }
    }
    md += ghostingRun == 0
              ? "\n   **Goal 1: not evaluated** (no ghosting scene selected).\n\n"
              : Format("\n   **Goal 1: %s**%s\n\n", goal1 ? "MET" : "NOT MET",
                       ghostingRun < int(kGhosting.size()) ? " (on the selected scenes only)" : "");

    // Goal 2: demodulation lowers RMSE on anim_glossy, and elsewhere raises it by at most the
    // noise, for every method.
    md += Format(
        "2. *\"Demodulation lowers RMSE on anim_glossy and never raises it elsewhere by more than "
        "noise\"* (Zhuang et al. 2021). Taken as: on anim_glossy, mean RMSE with demodulation "
        "below without for every method; on every other scene and method, at most %.0f%% above "
        "(the noise of one 1-spp sequence's mean RMSE).\n\n",
        kNoise * 100.0);
    bool goal2 = true, glossyRun = false;
    for (const SceneResult& r : results) {
        const bool glossy = r.name == "anim_glossy";
        glossyRun = glossyRun || glossy;
        std::string line = "   - " + r.name + ":";
        bool ok = true;
        for (Method m : kMethods) {
            const double on = r.rmse[Index(m, Demodulation::On)];
            const double off = r.rmse[Index(m, Demodulation::Off)];
            const bool mOk = glossy ? on < off : on <= off * (1.0 + kNoise);
            ok = ok && mOk;
            line += Format(" %s %+.1f%%%s;", screen::MethodName(m), (on / off - 1.0) * 100.0,
                           mOk ? "" : " (!)");
        }
        goal2 = goal2 && ok;
        line.back() = ' ';
        md += line + "— " + (ok ? "MET" : "NOT MET") + "\n";
    }
    md += Format("\n   **Goal 2: %s**%s\n\n", goal2 ? "MET" : "NOT MET",
                 glossyRun ? "" : " (anim_glossy not selected: only the 'elsewhere' half checked)");
    md += "   (Percentages: RMSE with demodulation relative to without; (!) marks a failure.)\n\n";

    // Stage time at this resolution.
    md += Format(
        "## Stage time per frame at %dx%d\n\nMean over all scenes and frames, wall clock and "
        "process CPU time (2 threads, machine shared, so wall time is noisy). For 1080p see "
        "`build/bin/screen_space_benchmark`.\n\n| method | demodulation | wall ms | CPU ms |\n"
        "|---|---|---|---|\n",
        W, H);
    for (Method m : kMethods)
        for (Demodulation d : {Demodulation::Off, Demodulation::On}) {
            std::vector<double> ms, cpu;
            for (const SceneResult& r : results)
                ms.push_back(r.ms[Index(m, d)]), cpu.push_back(r.cpuMs[Index(m, d)]);
            md += Format("| %s | %s | %.2f | %.2f |\n", screen::MethodName(m), DemodName(d),
                         Mean(ms), Mean(cpu));
        }

    md += "\n## Plots and crops\n\n";
    md += Format(
        "Crops of the last frame (frame %d), magnified %dx, from left to right: **1-spp input | "
        "reference | baseline+clamp | reliable** (both with demodulation). The crop is the "
        "half-width, half-height window where baseline+clamp and reliable differ most.\n\n",
        frames - 1, cropScale);
    for (const SceneResult& r : results) {
        md += Format(
            "### %s\n\n![RMSE](temporal_rmse_%s.png)\n![change](temporal_change_%s.png)"
            "\n\nCrop at x %d..%d, y %d..%d of the %dx%d frame "
            "([full reference](temporal_reference_%s.png)):\n\n"
            "![crop](temporal_crop_%s.png)\n\n",
            r.name.c_str(), r.name.c_str(), r.name.c_str(), r.crop.x, r.crop.x + r.crop.w - 1,
            r.crop.y, r.crop.y + r.crop.h - 1, W, H, r.name.c_str(), r.name.c_str());
    }
    WriteText((fs::path(s.outDir) / "temporal.md").string(), md);
    if (s.ablation) {
        WriteText(
            (fs::path(s.outDir) / "temporal_ablation.md").string(),
            Format("# Reliable's settings, one at a time\n\n%d frames, %dx%d, 1 spp, reference %d "
                   "spp, demodulation on (as temporal.md). Mean RMSE over the frames, of the image "
                   "and of each component (direct = shading * visibility).\n\n"
                   "| scene | variant | RMSE | direct | glossy | indirect |\n"
                   "|---|---|---|---|---|---|\n",
                   frames, W, H, refSpp) +
                ablationRows);
        Say("wrote temporal_ablation.md");
    }
    Say("wrote %s, plots, crops and temporal.md in %s", csv.c_str(), s.outDir.c_str());
    return 0;
}

}  // namespace texcache::experiments
