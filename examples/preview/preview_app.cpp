// SPDX-License-Identifier: Apache-2.0
// The preview window: GLFW + OpenGL 3 + Dear ImGui. The UI thread draws the last published frame
// and the panel and turns input into camera / settings posts; all rendering is on the
// ProgressiveRenderer's worker, so the window never waits for a frame.
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

#include "orbit_camera.h"
#include "preview.h"
#include "renderer/image.h"
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
    const float t = ui.sceneCopy.settings.time;
    ui.camera.Frame(ui.selected >= 0 ? ObjectBounds(ui.sceneCopy, ui.selected, t)
                                     : SceneBounds(ui.sceneCopy, t));
}

/// Mouse and keyboard -> camera (only when ImGui does not want them).
void HandleInput(Ui& ui, ProgressiveRenderer& r, double dt) {
    const ImGuiIO& io = ImGui::GetIO();
    const float radius = SceneBounds(ui.sceneCopy, ui.sceneCopy.settings.time).Radius();
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
    }
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

void SaveCamera(Ui& ui) {
    try {
        SaveCameraToSceneFile(ui.scenePath, ui.camera.Position(), ui.camera.Target(),
                              glm::vec3(0.0f, 1.0f, 0.0f), ui.camera.FovY());
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
        const char* views[] = {ViewModeName(ViewMode::Beauty), ViewModeName(ViewMode::FaceId),
                               ViewModeName(ViewMode::TexelMip), ViewModeName(ViewMode::Texels)};
        ImGui::Combo("view", &view, views, 4);
        s.view = ViewMode(view);
        ImGui::SliderInt("spp / frame", &s.sppPerFrame, 1, 64);
        ImGui::SliderInt("AO rays / sample", &s.aoSamples, 1, 256, "%d",
                         ImGuiSliderFlags_Logarithmic);
        ImGui::SliderInt("max depth", &s.maxDepth, 1, 16);
        ImGui::SliderFloat("tessellation", &ui.tessellationEdit, 1.0f, 16.0f, "%.1f");
        // The Embree rebuild is slow: apply when the slider is let go.
        if (ImGui::IsItemDeactivatedAfterEdit()) s.tessellationRate = ui.tessellationEdit;
        ImGui::SliderFloat("exposure", &s.exposure, -6.0f, 6.0f, "%.1f stops");
        ImGui::SliderInt("max frames", &s.maxFrames, 1, 4096, "%d", ImGuiSliderFlags_Logarithmic);
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
        ImGui::SliderFloat("LOD bias", &s.lodBias, -4.0f, 8.0f, "%.2f");
        ImGui::SliderFloat("sample cache MiB", &s.sampleCacheMb, 1.0f, 1024.0f, "%.0f",
                           ImGuiSliderFlags_Logarithmic);
        ImGui::SliderFloat("texel cache MiB", &s.texelCacheMb, 1.0f, 1024.0f, "%.0f",
                           ImGuiSliderFlags_Logarithmic);
        ImGui::Checkbox("re-shade while still", &s.refineCacheWhenStill);
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
    const int winW = settings.width + int(kPanelWidth);
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
    ui.tessellationEdit = settings.tessellationRate;
    ui.integrators = SplitNames(IntegratorNames());
    ui.filters = SplitNames(TextureFilterNames());
    ui.home.FromScene(scene, scene.settings.time);
    ui.camera = ui.home;
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
            // Scripted orbit: frame 0 at the scene camera, the last one `orbitDegrees` around.
            const int n = args.frames;
            FrameStats last;
            for (int i = 0; i < n && exitCode == 0; ++i) {
                OrbitCamera cam = ui.home;
                cam.Orbit(n > 1 ? args.orbitDegrees * float(i) / float(n - 1) : 0.0f, 0.0f);
                ui.camera = cam;
                const uint64_t v = renderer.SetCamera(cam);
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
                    "frame %d: %.1f ms, %.2f Mrays/s, cache hit rate %.2f %%, %llu samples "
                    "shaded\n",
                    i, last.seconds * 1e3, last.raysPerSecond * 1e-6, 100.0 * last.texelHitRate,
                    (unsigned long long)last.samplesShaded);
                if (shot.width > 0) {
                    WriteImage(args.screenshot, shot);
                    std::printf("wrote %s (%dx%d)\n", args.screenshot.c_str(), shot.width,
                                shot.height);
                }
            }
            if (exitCode == 0 && args.saveCamera) {
                SaveCameraToSceneFile(ui.scenePath, ui.camera.Position(), ui.camera.Target(),
                                      glm::vec3(0.0f, 1.0f, 0.0f), ui.camera.FovY());
                std::printf("saved the camera to %s\n", ui.scenePath.c_str());
            }
            if (exitCode == 0) {
                if (last.textureSpace)
                    std::printf("cache hit rate after the move: %.2f %%\n",
                                100.0 * last.texelHitRate);
                else
                    std::printf("cache hit rate after the move: n/a (texture-space cache off)\n");
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
                renderer.SetSettings(ui.settings);
                renderer.SetCamera(ui.camera);
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
