// SPDX-License-Identifier: Apache-2.0
// `texcache bake SCENE --out DIR`: each object's converged texture-space shading (ambient
// occlusion, or the diffuse light it receives) as a half-float Ptex file with mip levels and the
// cage's adjacency, DIR/<object>.ptx; every file is written only once all are complete.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>

#include "cli_util.h"
#include "commands.h"
#include "render_command.h"
#include "renderer/image/atomic_files.h"
#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/bake.h"
#include "texcache/error.h"
#include "texcache/ptex/writer.h"

namespace texcache::cli {

namespace {

namespace fs = std::filesystem;

struct BakeArgs {
    std::string scene, out, integrator = "ao";
    BakeOptions bake;
    int threads = 0;
};

/// A file name for an object: its name with anything but letters, digits, '.', '-' and '_'
/// replaced, made unique among the scene's objects.
std::string FileName(const std::string& object, std::map<std::string, int>* used) {
    std::string n;
    for (const char ch : object)
        n += std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '-' || ch == '_'
                 ? ch
                 : '_';
    if (n.empty() || n[0] == '.') n = "object" + n;
    const int k = (*used)[n]++;
    return k == 0 ? n : n + "_" + std::to_string(k);
}

int RunBake(BakeArgs a) {
    CheckRange("--threads", a.threads, 0, 4096);
    a.bake.integrator = ParseIntegrator(a.integrator, "--integrator");
    CheckBakeOptions(a.bake);  // before the scene loads: a bad option is the one message
    std::vector<std::string> warnings;
    const Scene scene = LoadSceneOrObj(a.scene, &warnings);
    for (const std::string& w : warnings)
        std::fprintf(stderr, "texcache: warning: %s\n", internal::OneLine(w).c_str());
    std::error_code ec;
    fs::create_directories(a.out, ec);
    if (ec || !fs::is_directory(a.out, ec))
        throw InputError("--out", "cannot create directory '" + a.out + "'");
    std::map<std::string, int> used;
    std::vector<std::string> paths;
    for (const Object& o : scene.objects)
        paths.push_back((fs::path(a.out) / (FileName(o.name, &used) + ".ptx")).string());
    FileSet files;
    files.SceneInputs(scene);
    for (const std::string& p : paths) files.Output(p, "--out");
    files.Check();

    const auto limit = ThreadLimit(a.threads);
    RenderOptions opt = RenderOptionsFrom(scene.settings);
    RenderSceneOptions ro;
    ro.frameTime = scene.settings.time;
    ro.threads = a.threads;
    ro.needLights = ro.needEnvironment = a.bake.integrator != IntegratorKind::AO;
    ro.needTextures = true;
    const RenderScene rs(scene, ro);
    const double t0 = NowSeconds();
    const std::vector<BakedTexture> baked = Bake(rs, opt, a.bake);
    const double seconds = NowSeconds() - t0;
    AtomicFiles group;
    for (size_t i = 0; i < baked.size(); ++i) {
        const std::vector<uint8_t> bytes = ptex::EncodeTexture(baked[i].options, baked[i].Faces());
        const std::string temp = group.Stage(paths[i]);
        std::ofstream f(temp, std::ios::binary);
        f.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
        if (!f.flush()) throw InputError(paths[i], "cannot write the baked texture");
    }
    group.Commit();
    for (size_t i = 0; i < baked.size(); ++i) {
        const BakedTexture& b = baked[i];
        std::printf("wrote %s (object '%s', %zu faces", paths[i].c_str(), b.object.c_str(),
                    b.faces.size());
        if (b.unreachable > 0) std::printf(", %zu texels unreachable, written as 0", b.unreachable);
        std::printf(")\n");
    }
    std::printf("baked in %.2f s\n", seconds);
    return 0;
}

}  // namespace

void AddBakeCommand(CLI::App& app, int& exitCode) {
    auto args = std::make_shared<BakeArgs>();
    CLI::App* cmd = app.add_subcommand(
        "bake",
        "Each object's converged texture-space shading, ambient occlusion or the diffuse light it "
        "receives, as a half-float Ptex file per object with mip levels and the cage's adjacency "
        "(DIR/<object>.ptx): one cache sample per texel centre, shaded as texture-space renders "
        "shade theirs, with --samples rays. A material with \"emission\": {\"ptex\": FILE} and "
        "no other light shows it as baked.");
    cmd->add_option("scene", args->scene, "Scene file (.json) or OBJ cage")->required();
    cmd->add_option("--out", args->out, "Output directory (created if missing)")->required();
    cmd->add_option("--integrator", args->integrator,
                    "ao: ambient occlusion (the scene's ao_distance); direct or path: the diffuse "
                    "light a white surface receives, (1/pi) integral of L cos (path: direct and "
                    "indirect)")
        ->capture_default_str();
    cmd->add_option("--samples", args->bake.samples, "AO rays or light paths per texel")
        ->capture_default_str();
    cmd->add_option("--resolution", args->bake.resolution,
                    "Texels along the side of each object's largest face, a power of two; the "
                    "other faces get the same texel size")
        ->capture_default_str();
    cmd->add_flag("--albedo", args->bake.albedo,
                  "Multiply by the material's albedo at each texel (the diffuse radiance a "
                  "surface sends, instead of the light it receives)");
    cmd->add_option("--threads", args->threads, "Threads (0: all)")->capture_default_str();
    cmd->callback([args, &exitCode] { exitCode = RunBake(*args); });
}

}  // namespace texcache::cli
