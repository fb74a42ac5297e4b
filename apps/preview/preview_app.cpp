// SPDX-License-Identifier: Apache-2.0
// The preview window: GLFW + OpenGL 3 + Dear ImGui. The UI thread draws the last published frame
// and the panel and turns input into camera / settings posts; all rendering is on the
// ProgressiveRenderer's worker, so the window never waits for a frame.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#define GLFW_INCLUDE_NONE
#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include "preview.h"
#include "renderer/image/image.h"
#include "renderer/preview/orbit_camera.h"
#include "scene_camera_file.h"
#include "texcache/error.h"

namespace texcache::preview {

namespace {

constexpr float kPanelWidth = 380.0f;
constexpr int kPlotLength = 180;

std::string g_glfwError;
void GlfwError(int code, const char* what) {
    g_glfwError = what ? what : ("GLFW error " + std::to_string(code));
}

/// "a, b, c" -> {"a", "b", "c"}: the renderer's name lists, so new integrators / filters show up
/// in the panel without touching it.
std::vector<std::string> SplitNames(const std::string& list) {
    std::vector<std::string> out;
    std::stringstream ss(list);
    std::string item;
    while (std::getline(ss, item, ',')) {
        const size_t a = item.find_first_not_of(" \t"), b = item.find_last_not_of(" \t");
        if (a != std::string::npos) out.push_back(item.substr(a, b - a + 1));
    }
    return out;
}

/// Combo over a list of names; returns true when the selection changed.
bool NameCombo(const char* label, const std::vector<std::string>& names, int* index) {
    bool changed = false;
    const char* preview = *index >= 0 && *index < int(names.size()) ? names[*index].c_str() : "?";
    if (ImGui::BeginCombo(label, preview)) {
        for (int i = 0; i < int(names.size()); ++i) {
            if (ImGui::Selectable(names[i].c_str(), i == *index)) {
                changed = *index != i;
                *index = i;
            }
        }
        ImGui::EndCombo();
    }
    return changed;
}

int IndexOf(const std::vector<std::string>& names, const std::string& n) {
    for (int i = 0; i < int(names.size()); ++i)
        if (names[i] == n) return i;
    return 0;
}

/// A linear colour as ImGui draws it (the image is shown sRGB-encoded, so legends match it).
ImU32 DisplayColour(glm::vec3 c) {
    return IM_COL32(LinearToSrgb8(c.x), LinearToSrgb8(c.y), LinearToSrgb8(c.z), 255);
}

/// A colour bar of `ramp(t)`, t in [0, 1] left to right, with `labels[i]` under position
/// `at[i]`.
template <typename Ramp>
void LegendBar(Ramp&& ramp, const std::vector<float>& at, const std::vector<std::string>& labels) {
    const float w = ImGui::GetContentRegionAvail().x, h = 14.0f;
    const ImVec2 p = ImGui::GetCursorScreenPos();
    ImDrawList* dl = ImGui::GetWindowDrawList();
    constexpr int kSteps = 32;
    for (int i = 0; i < kSteps; ++i) {
        const float x0 = p.x + w * float(i) / kSteps, x1 = p.x + w * float(i + 1) / kSteps;
        const ImU32 a = DisplayColour(ramp(float(i) / kSteps));
        const ImU32 b = DisplayColour(ramp(float(i + 1) / kSteps));
        dl->AddRectFilledMultiColor(ImVec2(x0, p.y), ImVec2(x1, p.y + h), a, b, b, a);
    }
    const float textY = p.y + h + 2.0f;
    for (size_t i = 0; i < at.size() && i < labels.size(); ++i) {
        const float tw = ImGui::CalcTextSize(labels[i].c_str()).x;
        const float x = std::clamp(p.x + at[i] * w - 0.5f * tw, p.x, p.x + w - tw);
        dl->AddText(ImVec2(x, textY), ImGui::GetColorU32(ImGuiCol_Text), labels[i].c_str());
    }
    ImGui::Dummy(ImVec2(w, h + 4.0f + ImGui::GetTextLineHeight()));
}

/// A small swatch of a colour followed by a caption on the same line.
void LegendSwatch(glm::vec3 colour, const char* caption) {
    const float s = ImGui::GetTextLineHeight();
    const ImVec2 p = ImGui::GetCursorScreenPos();
    ImGui::GetWindowDrawList()->AddRectFilled(p, ImVec2(p.x + s, p.y + s), DisplayColour(colour));
    ImGui::Dummy(ImVec2(s, s));
    ImGui::SameLine();
    ImGui::TextUnformatted(caption);
}

/// The legend of the heat-map views (nothing for the others).
void DrawViewLegend(ViewMode view, const FrameStats& st) {
    if (view == ViewMode::HitMiss) {
        LegendBar([](float t) { return HitMissColour(t); }, {0.0f, 0.5f, 1.0f},
                  {"all missed", "half hit", "all hit"});
        LegendSwatch(NoLookupColour(), "no cache lookup");
        ImGui::TextWrapped(
            "fraction of each pixel's texel lookups that hit, in the frame after the last "
            "change: %.1f %% of %llu lookups hit",
            100.0 * st.texelHitRate, (unsigned long long)st.lookups);
    } else if (view == ViewMode::Overshading) {
        // Integer counts (0 and powers of two) where they fall on the log scale; a label that
        // would touch the one before it is left out, the top one always stays.
        const uint32_t top = std::max(st.overshadeTop, 1u);
        const float width = ImGui::GetContentRegionAvail().x;
        std::vector<float> at;
        std::vector<std::string> labels;
        float lastRight = -1e30f;
        for (uint32_t n = 0; n <= top; n = n ? 2 * n : 1) {
            const std::string text = std::to_string(n);
            const float t = OvershadeScale(float(n), top);
            const float half = 0.5f * ImGui::CalcTextSize(text.c_str()).x + 4.0f;
            if (t * width - half < lastRight) {
                if (n != top) continue;
                at.pop_back(), labels.pop_back();
            }
            at.push_back(t), labels.push_back(text);
            lastRight = t * width + half;
            if (n >= (1u << 31)) break;
        }
        LegendBar([](float t) { return HeatColour(t); }, at, labels);
        LegendSwatch(NoLookupColour(), "no cache lookup");
        ImGui::TextWrapped(
            "samples shaded per pixel by its lookups in the frame after the last change (log "
            "scale): %llu in all",
            (unsigned long long)st.samplesShaded);
    }
}

/// The screen-space stage's controls: method (off or one of the stage's), demodulation, and the
/// motion view's vectors with their legend.
void DrawDenoiseControls(PreviewSettings& s) {
    static const std::vector<std::string> kMethods = [] {
        std::vector<std::string> m = {"off"};
        for (const std::string& k : SplitNames(screen::MethodKeys())) m.push_back(k);
        return m;
    }();
    int method = s.denoise ? IndexOf(kMethods, screen::MethodKey(s.denoiseMethod)) : 0;
    if (NameCombo("denoise", kMethods, &method)) {
        s.denoise = method > 0;
        if (s.denoise) s.denoiseMethod = screen::ParseMethodKey(kMethods[method], "denoise");
    }
    if (ImGui::IsItemHovered())
        ImGui::SetTooltip(
            "screen-space stage on each frame: the path tracer's split at 1 spp (diffuse "
            "indirect from the cache when it is on), denoised with history kept while the "
            "camera or the animation moves");
    if (s.denoise || s.view == ViewMode::Motion) {
        ImGui::Checkbox("demodulate (BRDF / albedo)", &s.demodulate);
        if (s.textureSpace) {
            ImGui::Checkbox("cached visibility where no history", &s.cachedVisibility);
            if (ImGui::IsItemHovered())
                ImGui::SetTooltip(
                    "the direct light's visibility cached in texture space too; the stage takes "
                    "it at disocclusions (results/disocclusion.md: +54%% render CPU)");
        }
        ImGui::TextDisabled("the stage renders the path tracer's split");
    }
    if (s.view == ViewMode::Motion) {
        static const std::vector<std::string> kKinds = SplitNames(MotionKindKeys());
        int kind = IndexOf(kKinds, MotionKindKey(s.motionKind));
        if (NameCombo("motion vectors", kKinds, &kind))
            s.motionKind = ParseMotionKind(kKinds[kind], "motion vectors");
        LegendBar(
            [](float t) {
                return MotionColour(glm::vec2(std::cos(6.2831853f * t), std::sin(6.2831853f * t)),
                                    1.0f);
            },
            {0.0f, 0.25f, 0.5f, 0.75f}, {"right", "down", "left", "up"});
        LegendSwatch(glm::vec3(1.0f), "no motion (saturation: length, full at 8 px)");
        LegendSwatch(glm::vec3(0.0f), "no history (disoccluded, off screen, first frame)");
        if (!s.denoise) ImGui::TextDisabled("the stage runs reliable for this view");
    }
}

/// The stage's passes of the last frame, wall-clock milliseconds.
void DrawStageTimings(const FrameStats& st) {
    const screen::StageTimings& t = st.stage;
    const double frameMs = st.seconds * 1e3;
    ImGui::Text("render %.1f ms + stage %.1f ms (%.0f %%), history %d", st.renderSeconds * 1e3,
                t.total, frameMs > 0.0 ? 100.0 * t.total / frameMs : 0.0, st.stageHistory);
    ImGui::TextDisabled("prepare %.1f  motion %.1f + %.1f  temporal %.1f", t.prepare,
                        t.traditionalMotion, t.reliableMotion, t.temporal);
    ImGui::TextDisabled("a-trous %.1f  clean-up %.1f  compose %.1f (ms)", t.spatial, t.cleanup,
                        t.compose);
}

/// The window's contents as a linear image (sRGB decoded, so WriteImage's PNG encoding gives the
/// read-back bytes again), rows flipped to top-first.
Image ReadWindow(int width, int height) {
    std::vector<uint8_t> px(size_t(width) * height * 4);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadBuffer(GL_BACK);
    glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, px.data());
    float lut[256];
    for (int i = 0; i < 256; ++i) {
        const float c = float(i) / 255.0f;
        lut[i] = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
    Image img(width, height, 3);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const uint8_t* s = &px[(size_t(height - 1 - y) * width + x) * 4];
            float* d = img.At(x, y);
            d[0] = lut[s[0]], d[1] = lut[s[1]], d[2] = lut[s[2]];
        }
    return img;
}

/// Everything the UI thread keeps between frames.
struct Ui {
    GLFWwindow* window = nullptr;
    Scene sceneCopy;  // for bounds, names and saving (the worker owns its own)
    std::string scenePath;
    bool sceneIsJson = false;
    OrbitCamera camera, home;
    PreviewSettings settings;
    std::vector<std::string> integrators, filters;
    GLuint texture = 0;
    int texWidth = 0, texHeight = 0;
    uint64_t seenFrame = 0;
    float frameMs[kPlotLength] = {};
    int plotNext = 0;
    int selected = -1;
    char savePath[512] = "out/preview.exr";
    std::string status;
    float tessellationEdit = 2.0f;
    ImVec2 imageMin{0, 0}, imageMax{0, 0};
    double lastTime = 0.0;
    bool dragged = false;
    // Timeline (animated scenes only).
    SceneAnimation anim;
    float timeMin = 0.0f, timeMax = 0.0f;  // the slider's range: the keyframes and the start time
    bool playing = false, loop = true, followCamera = true;
    float speed = 1.0f, fps = 24.0f;
    float posedTime = 0.0f;  // the time the camera was last made to follow
};

void UploadFrame(Ui& ui, ProgressiveRenderer& r) {
    r.WithDisplay(&ui.seenFrame, [&](const uint8_t* rgba, int w, int h) {
        glBindTexture(GL_TEXTURE_2D, ui.texture);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        if (w != ui.texWidth || h != ui.texHeight) {
            glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, w, h, 0, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
            ui.texWidth = w, ui.texHeight = h;
        } else {
            glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
        }
    });
}

void RecordFrameTime(Ui& ui, const FrameStats& s, uint64_t* lastNumber) {
    if (s.frameNumber == *lastNumber || s.seconds <= 0.0) return;
    *lastNumber = s.frameNumber;
    ui.frameMs[ui.plotNext] = float(s.seconds * 1e3);
    ui.plotNext = (ui.plotNext + 1) % kPlotLength;
}

/// Draws the image in the area left of the panel, keeping its aspect ratio.
void DrawImage(Ui& ui) {
    int fw, fh;
    glfwGetWindowSize(ui.window, &fw, &fh);
    const float areaW = std::max(1.0f, float(fw) - kPanelWidth), areaH = float(fh);
    if (ui.texWidth == 0) return;
    const float s = std::min(areaW / float(ui.texWidth), areaH / float(ui.texHeight));
    const float w = s * float(ui.texWidth), h = s * float(ui.texHeight);
    ui.imageMin = ImVec2(0.5f * (areaW - w), 0.5f * (areaH - h));
    ui.imageMax = ImVec2(ui.imageMin.x + w, ui.imageMin.y + h);
    ImGui::GetBackgroundDrawList()->AddImage((ImTextureID)(intptr_t)ui.texture, ui.imageMin,
                                             ui.imageMax);
}

void FrameSelected(Ui& ui) {
    const float t = ui.settings.time;
    ui.camera.Frame(ui.selected >= 0 ? ObjectBounds(ui.sceneCopy, ui.selected, t)
                                     : SceneBounds(ui.sceneCopy, t));
}

/// Mouse and keyboard -> camera (only when ImGui does not want them).
void HandleInput(Ui& ui, ProgressiveRenderer& r, double dt) {
    const ImGuiIO& io = ImGui::GetIO();
    const float radius = SceneBounds(ui.sceneCopy, ui.settings.time).Radius();
    if (!io.WantCaptureMouse) {
        const float imageH = std::max(1.0f, ui.imageMax.y - ui.imageMin.y);
        const ImVec2 d = io.MouseDelta;
        const bool shift = io.KeyShift;
        if (io.MouseClicked[0]) ui.dragged = false;
        if (io.MouseDown[0] && (d.x != 0.0f || d.y != 0.0f)) {
            ui.dragged = true;
            if (shift)
                ui.camera.Pan(-d.x / imageH, d.y / imageH);
            else
                ui.camera.Orbit(-0.3f * d.x, 0.3f * d.y);
        }
        if (io.MouseDown[1] && (d.x != 0.0f || d.y != 0.0f))
            ui.camera.Pan(-d.x / imageH, d.y / imageH);
        if (io.MouseDown[2] && d.y != 0.0f) ui.camera.Dolly(std::exp(0.01f * d.y));
        if (io.MouseWheel != 0.0f) ui.camera.Dolly(std::exp(-0.1f * io.MouseWheel));
        // A click without a drag picks the object under the cursor.
        if (io.MouseReleased[0] && !ui.dragged) {
            const ImVec2 m = io.MousePos;
            if (m.x >= ui.imageMin.x && m.x < ui.imageMax.x && m.y >= ui.imageMin.y &&
                m.y < ui.imageMax.y) {
                const float s = float(ui.texWidth) / (ui.imageMax.x - ui.imageMin.x);
                r.RequestPick(int((m.x - ui.imageMin.x) * s), int((m.y - ui.imageMin.y) * s));
            }
        }
    }
    if (!io.WantCaptureKeyboard) {
        auto key = [&](int k) { return glfwGetKey(ui.window, k) == GLFW_PRESS; };
        const float speed = float(dt) * radius * (io.KeyShift ? 2.0f : 0.5f);
        const float f = float(key(GLFW_KEY_W) - key(GLFW_KEY_S));
        const float rt = float(key(GLFW_KEY_D) - key(GLFW_KEY_A));
        const float up = float(key(GLFW_KEY_E) - key(GLFW_KEY_Q));
        if (f != 0.0f || rt != 0.0f || up != 0.0f) ui.camera.Fly(speed * f, speed * rt, speed * up);
        if (ImGui::IsKeyPressed(GLFW_KEY_R, false)) ui.camera = ui.home;
        if (ImGui::IsKeyPressed(GLFW_KEY_F, false)) FrameSelected(ui);
        if (ui.anim.animated && ImGui::IsKeyPressed(GLFW_KEY_SPACE, false))
            ui.playing = !ui.playing;
    }
}

/// Playback: advances the scene time by the wall-clock step (times the speed), looping or
/// stopping at the end; an animated camera is followed when asked. Frames the worker cannot
/// keep up with are skipped (it renders the newest time posted).
void AdvanceTime(Ui& ui, double dt) {
    if (!ui.anim.animated) return;
    float& t = ui.settings.time;
    if (ui.playing) {
        t += float(dt) * ui.speed;
        const float span = ui.timeMax - ui.timeMin;
        if (t > ui.timeMax) {
            if (ui.loop && span > 0.0f) {
                t = ui.timeMin + std::fmod(t - ui.timeMin, span);
            } else {
                t = ui.timeMax;
                ui.playing = false;
            }
        }
    }
    if (ui.anim.cameraAnimated && ui.followCamera && t != ui.posedTime)
        ui.camera.FromScene(ui.sceneCopy, t);
    ui.posedTime = t;
}

/// Steps the time by whole frames at the timeline's frame rate (paused).
void StepFrames(Ui& ui, int frames) {
    ui.playing = false;
    const float frame = std::round(ui.settings.time * ui.fps) + float(frames);
    ui.settings.time = std::clamp(frame / ui.fps, ui.timeMin, ui.timeMax);
}

void SaveImage(Ui& ui, const ProgressiveRenderer& r) {
    try {
        const std::filesystem::path exr(ui.savePath);
        if (exr.has_parent_path()) std::filesystem::create_directories(exr.parent_path());
        std::filesystem::path png = exr;
        png.replace_extension(".png");
        const Image img = r.CopyImage();
        if (img.width == 0) throw InputError(ui.savePath, "no frame rendered yet");
        WriteImage(exr.string(), img);
        if (exr.extension() == ".exr") WriteImage(png.string(), img, {}, ui.settings.exposure);
        ui.status = "wrote " + exr.string() + (exr.extension() == ".exr" ? " + .png" : "");
    } catch (const std::exception& e) {
        ui.status = std::string("save failed: ") + e.what();
    }
}

/// The orbit camera written into the scene file, in the file's units (the preview works in
/// render units: renderer/scene/scene_units.h).
void SaveSceneCamera(const Ui& ui) {
    const Scene& s = ui.sceneCopy;
    const auto file = [&](glm::vec3 p) {
        return glm::vec3(glm::dvec3(p) / s.unitScale + s.unitOrigin);
    };
    SaveCameraToSceneFile(ui.scenePath, file(ui.camera.Position()), file(ui.camera.Target()),
                          glm::vec3(0.0f, 1.0f, 0.0f), ui.camera.FovY());
}

void SaveCamera(Ui& ui) {
    try {
        SaveSceneCamera(ui);
        ui.status = "camera saved to " + ui.scenePath;
    } catch (const std::exception& e) {
        ui.status = std::string("camera not saved: ") + e.what();
    }
}

void DrawPanel(Ui& ui, ProgressiveRenderer& r) {
    int fw, fh;
    glfwGetWindowSize(ui.window, &fw, &fh);
    ImGui::SetNextWindowPos(ImVec2(float(fw) - kPanelWidth, 0.0f));
    ImGui::SetNextWindowSize(ImVec2(kPanelWidth, float(fh)));
    ImGui::Begin("texcache preview", nullptr,
                 ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse);
    PreviewSettings& s = ui.settings;
    const FrameStats st = r.Stats();

    // ---- live statistics
    if (!r.Ready()) ImGui::TextUnformatted("building the scene ...");
    ImGui::Text("frame %.1f ms (%.1f fps), %d accumulated", st.seconds * 1e3,
                st.seconds > 0 ? 1.0 / st.seconds : 0.0, st.accumulated);
    ImGui::Text("%.2f Mrays/s", st.raysPerSecond * 1e-6);
    if (st.textureSpace) {
        ImGui::Text("cache hit rate %.1f %% of %llu lookups", 100.0 * st.texelHitRate,
                    (unsigned long long)st.lookups);
        ImGui::Text("samples shaded %llu / frame", (unsigned long long)st.samplesShaded);
    } else {
        ImGui::TextDisabled("texture-space cache not in use");
    }
    ImGui::Text("cache memory %.1f MiB", double(st.cacheBytes) / (1 << 20));
    if (r.Ready()) {
        ImGui::Text("scene %zu Ptex faces", st.ptexFaces);
        ImGui::TextWrapped("%s", RenderScene::Describe(st.tessellation).c_str());
    }
    if (st.staged) DrawStageTimings(st);
    float maxMs = 1.0f;
    for (float v : ui.frameMs) maxMs = std::max(maxMs, v);
    ImGui::PlotLines("##ft", ui.frameMs, kPlotLength, ui.plotNext, "frame time (ms)", 0.0f,
                     1.1f * maxMs, ImVec2(kPanelWidth - 20.0f, 60.0f));
    const std::string err = r.Error();
    if (!err.empty()) ImGui::TextColored(ImVec4(1, 0.4f, 0.4f, 1), "%s", err.c_str());

    // ---- rendering
    if (ImGui::CollapsingHeader("Rendering", ImGuiTreeNodeFlags_DefaultOpen)) {
        int integrator = IndexOf(ui.integrators, "ao");
        for (int i = 0; i < int(ui.integrators.size()); ++i)
            if (ParseIntegrator(ui.integrators[i], "") == s.integrator) integrator = i;
        if (NameCombo("integrator", ui.integrators, &integrator))
            s.integrator = ParseIntegrator(ui.integrators[integrator], "integrator");
        int view = int(s.view);
        const char* views[kNumViewModes];
        for (int i = 0; i < kNumViewModes; ++i) views[i] = ViewModeName(ViewMode(i));
        ImGui::Combo("view", &view, views, kNumViewModes);
        s.view = ViewMode(view);
        DrawViewLegend(s.view, st);
        DrawDenoiseControls(s);
        ImGui::SliderInt("spp / frame", &s.sppPerFrame, 1, 64);
        ImGui::SliderInt("AO rays / sample", &s.aoSamples, 1, 256, "%d",
                         ImGuiSliderFlags_Logarithmic);
        ImGui::SliderInt("max depth", &s.maxDepth, 1, 16);
        ImGui::SliderFloat("tessellation", &ui.tessellationEdit, 1.0f, 16.0f, "%.1f");
        // The Embree rebuild is slow: apply when the slider is let go.
        if (ImGui::IsItemDeactivatedAfterEdit()) s.tessellationRate = ui.tessellationEdit;
        ImGui::Checkbox("limit quads", &s.limitQuads);
        if (ImGui::IsItemHovered())
            ImGui::SetTooltip(
                "On: every mesh as quads on its limit surface, tessellated up front.\n"
                "Off: Embree's subdivision surfaces. The same surface.");
        ImGui::SliderFloat("exposure", &s.exposure, -6.0f, 6.0f, "%.1f stops");
        ImGui::SliderInt("max frames", &s.maxFrames, 1, 4096, "%d", ImGuiSliderFlags_Logarithmic);
    }
    // ---- timeline (animated scenes only)
    if (ui.anim.animated && ImGui::CollapsingHeader("Timeline", ImGuiTreeNodeFlags_DefaultOpen)) {
        if (ImGui::Button(ui.playing ? "pause" : "play", ImVec2(60.0f, 0.0f))) {
            // Play from the start again once a non-looping playback has reached the end.
            if (!ui.playing && !ui.loop && s.time >= ui.timeMax) s.time = ui.timeMin;
            ui.playing = !ui.playing;
        }
        ImGui::SameLine();
        if (ImGui::Button("|<")) {
            ui.playing = false;
            s.time = ui.timeMin;
        }
        ImGui::SameLine();
        if (ImGui::Button("<")) StepFrames(ui, -1);
        ImGui::SameLine();
        if (ImGui::Button(">")) StepFrames(ui, 1);
        ImGui::SameLine();
        ImGui::Text("frame %d (space: play)", int(std::lround(s.time * ui.fps)));
        ImGui::SliderFloat("time", &s.time, ui.timeMin, ui.timeMax, "%.3f s");
        if (ImGui::IsItemActive()) ui.playing = false;  // scrubbing
        ImGui::Checkbox("loop", &ui.loop);
        ImGui::SameLine();
        ImGui::SetNextItemWidth(120.0f);
        ImGui::SliderFloat("speed", &ui.speed, 0.05f, 4.0f, "%.2fx", ImGuiSliderFlags_Logarithmic);
        ImGui::SliderFloat("fps (steps)", &ui.fps, 1.0f, 120.0f, "%.0f");
        if (ui.anim.cameraAnimated) ImGui::Checkbox("follow the scene camera", &ui.followCamera);
        if (ui.anim.posesAnimated)
            ImGui::TextDisabled("each new time re-shades the cache (cache frame %u)",
                                st.cacheFrame);
        else
            ImGui::TextDisabled("only the camera moves: the cache is kept");
    }
    // ---- texture-space cache
    if (ImGui::CollapsingHeader("Texture-space cache", ImGuiTreeNodeFlags_DefaultOpen)) {
        ImGui::Checkbox("cache AO / diffuse indirect", &s.textureSpace);
        int filter = 0;
        for (int i = 0; i < int(ui.filters.size()); ++i)
            if (ParseTextureFilter(ui.filters[i], "") == s.filter) filter = i;
        if (NameCombo("default filter", ui.filters, &filter))
            s.filter = ParseTextureFilter(ui.filters[filter], "filter");
        ImGui::SliderInt("radius", &s.radius, 0, 32);
        {
            static const std::vector<std::string> kModes = SplitNames(FootprintModeNames());
            int mode = 0;
            for (int i = 0; i < int(kModes.size()); ++i)
                if (ParseFootprintMode(kModes[i], "") == s.footprint) mode = i;
            if (NameCombo("footprint", kModes, &mode))
                s.footprint = ParseFootprintMode(kModes[mode], "footprint");
            if (ImGui::IsItemHovered())
                ImGui::SetTooltip(
                    "visible: footprints shade only texels this frame's camera rays "
                    "reach (a prepass marks them); all: every texel of the window; "
                    "auto: visible for AO, all for direct and path");
        }
        ImGui::SliderFloat("LOD bias", &s.lodBias, -4.0f, 8.0f, "%.2f");
        ImGui::SliderFloat("sample cache MiB", &s.sampleCacheMb, 1.0f, 1024.0f, "%.0f",
                           ImGuiSliderFlags_Logarithmic);
        ImGui::SliderFloat("texel cache MiB", &s.texelCacheMb, 1.0f, 1024.0f, "%.0f",
                           ImGuiSliderFlags_Logarithmic);
        ImGui::Checkbox("re-shade while still", &s.refineCacheWhenStill);
        ImGui::Checkbox("stereo (left | right eye)", &s.stereo);
        if (ImGui::TreeNode("per material")) {
            std::vector<std::string> choices = {"(default)"};
            choices.insert(choices.end(), ui.filters.begin(), ui.filters.end());
            for (size_t m = 0; m < ui.sceneCopy.materials.size(); ++m) {
                ImGui::PushID(int(m));
                ImGui::TextUnformatted(ui.sceneCopy.materials[m].name.c_str());
                int c = s.materialFilter[m].empty() ? 0 : IndexOf(choices, s.materialFilter[m]);
                if (NameCombo("filter", choices, &c))
                    s.materialFilter[m] = c == 0 ? "" : choices[c];
                ImGui::SliderInt("radius (-1 default)", &s.materialRadius[m], -1, 32);
                // Editing the colour forgets the cache of the objects that use the material.
                ImGui::ColorEdit3("albedo", &s.materialAlbedo[m].x, ImGuiColorEditFlags_Float);
                ImGui::PopID();
            }
            ImGui::TreePop();
        }
    }
    // ---- camera
    if (ImGui::CollapsingHeader("Camera", ImGuiTreeNodeFlags_DefaultOpen)) {
        ImGui::TextWrapped(
            "drag: orbit; shift+drag / right drag: pan; wheel / middle drag: dolly; WASD QE: fly; "
            "click: select");
        std::vector<std::string> objects = {"(whole scene)"};
        for (const Object& o : ui.sceneCopy.objects) objects.push_back(o.name);
        int sel = ui.selected + 1;
        if (NameCombo("selected", objects, &sel)) ui.selected = sel - 1;
        if (ImGui::Button("reset (R)")) ui.camera = ui.home;
        ImGui::SameLine();
        if (ImGui::Button("frame selected (F)")) FrameSelected(ui);
        const glm::vec3 p = ui.camera.Position(), t = ui.camera.Target();
        ImGui::Text("eye (%.2f %.2f %.2f)", p.x, p.y, p.z);
        ImGui::Text("at  (%.2f %.2f %.2f)", t.x, t.y, t.z);
    }
    // ---- saving
    if (ImGui::CollapsingHeader("Save", ImGuiTreeNodeFlags_DefaultOpen)) {
        ImGui::InputText("image", ui.savePath, sizeof ui.savePath);
        if (ImGui::Button("save image (EXR + PNG)")) SaveImage(ui, r);
        if (ui.sceneIsJson) {
            if (ImGui::Button("save camera to scene file")) SaveCamera(ui);
        } else {
            ImGui::TextDisabled("camera saving needs a .json scene");
        }
        if (!ui.status.empty()) ImGui::TextWrapped("%s", ui.status.c_str());
    }
    ImGui::End();
}

}  // namespace

int RunPreviewWindow(Scene scene, const PreviewSettings& settings, const PreviewArgs& args) {
    const bool headless = args.frames > 0;
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((!display || !*display) && (!wayland || !*wayland))
        throw InputError("preview",
                         "no display: neither DISPLAY nor WAYLAND_DISPLAY is set (run it in a "
                         "desktop session, or headless under Xvfb: xvfb-run -a texcache preview "
                         "SCENE --frames N --screenshot out.png)");
    if (headless && !args.screenshot.empty()) CheckImageOutputPath(args.screenshot);

    glfwSetErrorCallback(GlfwError);
    if (!glfwInit())
        throw InputError("preview", "cannot open the display '" +
                                        std::string(display ? display : "") + "': " + g_glfwError);
    struct Terminate {
        ~Terminate() { glfwTerminate(); }
    } terminate;
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    const int winW = settings.width * (settings.stereo ? 2 : 1) + int(kPanelWidth);
    const int winH = std::max(settings.height, 640);
    GLFWwindow* window = glfwCreateWindow(winW, winH, "texcache preview", nullptr, nullptr);
    if (!window) throw InputError("preview", "cannot create an OpenGL 3.3 window: " + g_glfwError);
    glfwMakeContextCurrent(window);
    glfwSwapInterval(headless ? 0 : 1);

    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini dropped in the working directory
    ImGui::StyleColorsDark();
    ImGui_ImplGlfw_InitForOpenGL(window, true);
    ImGui_ImplOpenGL3_Init("#version 330 core");

    Ui ui;
    ui.window = window;
    ui.sceneCopy = scene;
    ui.scenePath = args.scenePath;
    ui.sceneIsJson = std::filesystem::path(args.scenePath).extension() == ".json";
    ui.settings = settings;
    ui.settings.materialFilter.resize(scene.materials.size());
    ui.settings.materialRadius.resize(scene.materials.size(), -1);
    for (size_t m = 0; m < scene.materials.size(); ++m) {
        ui.settings.materialFilter[m] = scene.materials[m].cacheFilter;
        ui.settings.materialRadius[m] = scene.materials[m].cacheRadius;
    }
    ui.settings.materialAlbedo.clear();
    for (const Material& m : scene.materials) ui.settings.materialAlbedo.push_back(m.albedo.value);
    ui.tessellationEdit = settings.tessellationRate;
    ui.integrators = SplitNames(IntegratorNames());
    ui.filters = SplitNames(TextureFilterNames());
    ui.home.FromScene(scene, scene.settings.time);
    ui.camera = ui.home;
    ui.anim = AnimationOf(scene);
    ui.timeMin = std::min(ui.anim.start, settings.time);
    ui.timeMax = std::max(ui.anim.end, settings.time);
    ui.fps = args.fps;
    ui.posedTime = settings.time;
    if (headless) ui.settings.maxFrames = 1;  // one frame per scripted camera step
    glGenTextures(1, &ui.texture);
    glBindTexture(GL_TEXTURE_2D, ui.texture);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);

    int exitCode = 0;
    {
        ProgressiveRenderer renderer(std::move(scene), ui.settings, ui.camera);
        renderer.SetOnFrame(&glfwPostEmptyEvent);
        uint64_t lastPlotted = 0;

        // One UI frame: upload the newest image, draw image + panel; returns false to quit.
        auto uiFrame = [&](bool readBack, Image* shot) {
            ImGui_ImplOpenGL3_NewFrame();
            ImGui_ImplGlfw_NewFrame();
            ImGui::NewFrame();
            UploadFrame(ui, renderer);
            RecordFrameTime(ui, renderer.Stats(), &lastPlotted);
            DrawImage(ui);
            DrawPanel(ui, renderer);
            ImGui::Render();
            int fbw, fbh;
            glfwGetFramebufferSize(window, &fbw, &fbh);
            glViewport(0, 0, fbw, fbh);
            glClearColor(0.08f, 0.08f, 0.09f, 1.0f);
            glClear(GL_COLOR_BUFFER_BIT);
            ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
            if (readBack) *shot = ReadWindow(fbw, fbh);
            glfwSwapBuffers(window);
        };

        if (headless) {
            // Scripted orbit: frame 0 at the scene camera, the last one `orbitDegrees` around;
            // with --play, frame i at the start time + i / fps (an animated camera followed).
            const int n = args.frames;
            const float startTime = ui.settings.time;
            std::printf("integrator %s, texture space %s, screen-space stage %s\n",
                        IntegratorName(ui.settings.integrator),
                        ui.settings.textureSpace ? "on" : "off",
                        ui.settings.denoise ? screen::MethodKey(ui.settings.denoiseMethod) : "off");
            FrameStats last;
            for (int i = 0; i < n && exitCode == 0; ++i) {
                if (args.play) ui.settings.time = startTime + float(i) / args.fps;
                OrbitCamera cam = ui.home;
                if (args.play && ui.anim.cameraAnimated)
                    cam.FromScene(ui.sceneCopy, ui.settings.time);
                cam.Orbit(n > 1 ? args.orbitDegrees * float(i) / float(n - 1) : 0.0f, 0.0f);
                ui.camera = cam;
                const uint64_t v = renderer.Post(ui.settings, cam);
                if (!renderer.WaitForFrame(v)) {
                    std::fprintf(stderr, "texcache: error: %s\n", renderer.Error().c_str());
                    exitCode = 2;
                    break;
                }
                glfwPollEvents();
                Image shot;
                uiFrame(i == n - 1 && !args.screenshot.empty(), &shot);
                last = renderer.Stats();
                std::printf(
                    "frame %d: t = %.3f s, %.1f ms, %.2f Mrays/s, cache hit rate %.2f %%, %llu "
                    "samples shaded",
                    i, last.time, last.seconds * 1e3, last.raysPerSecond * 1e-6,
                    100.0 * last.texelHitRate, (unsigned long long)last.samplesShaded);
                if (last.staged)
                    std::printf(
                        ", render %.1f ms + stage %.1f ms (%.0f %% of the frame), %d frames "
                        "of history",
                        last.renderSeconds * 1e3, last.stage.total,
                        100.0 * last.stage.total / std::max(last.seconds * 1e3, 1e-9),
                        last.stageHistory);
                std::printf("\n");
                if (shot.width > 0) {
                    WriteImage(args.screenshot, shot);
                    std::printf("wrote %s (%dx%d)\n", args.screenshot.c_str(), shot.width,
                                shot.height);
                }
            }
            if (exitCode == 0 && args.saveCamera) {
                SaveSceneCamera(ui);
                std::printf("saved the camera to %s\n", ui.scenePath.c_str());
            }
            if (exitCode == 0) {
                if (last.textureSpace)
                    std::printf("cache hit rate after the move: %.2f %%\n",
                                100.0 * last.texelHitRate);
                else
                    std::printf("cache hit rate after the move: n/a (texture-space cache off)\n");
                if (ui.settings.view == ViewMode::Overshading)
                    std::printf("overshading scale: 0 to %u samples shaded per pixel\n",
                                last.overshadeTop);
            }
        } else {
            ui.lastTime = glfwGetTime();
            while (!glfwWindowShouldClose(window)) {
                // Wakes on input, on a published frame (glfwPostEmptyEvent) or at 60 Hz for
                // held keys.
                glfwWaitEventsTimeout(1.0 / 60.0);
                const double now = glfwGetTime();
                const double dt = std::min(now - ui.lastTime, 0.1);
                ui.lastTime = now;
                int picked;
                if (renderer.PickResult(&picked)) ui.selected = picked;
                uiFrame(false, nullptr);
                HandleInput(ui, renderer, dt);
                AdvanceTime(ui, dt);
                renderer.Post(ui.settings, ui.camera);
                if (ImGui::IsKeyPressed(GLFW_KEY_ESCAPE, false) &&
                    !ImGui::GetIO().WantCaptureKeyboard)
                    glfwSetWindowShouldClose(window, GLFW_TRUE);
            }
        }
        renderer.SetOnFrame(nullptr);
    }  // the worker stops here, before the GL context and GLFW go away

    glDeleteTextures(1, &ui.texture);
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(window);
    return exitCode;
}

}  // namespace texcache::preview
