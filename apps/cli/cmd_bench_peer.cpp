// SPDX-License-Identifier: Apache-2.0
// `texcache bench peer`: our per-hit path tracer against Embree's own (the `pathtracer` tutorial
// of Debian's embree-tools) on the same cage, camera, resolution, samples and path length.
//
// Both sides run as whole processes (load, BVH and lazy tessellation, render, image file), one
// after the other in ABAB order, so that a shared machine's load falls on both alike; the ratio
// of each pair's wall times is reported and their median taken. Equal time means little without
// equal noise: each side's image is compared with its own high-sample render (relMSE, eps
// 0.001), and the two high-sample renders with each other (they should show the same light).
//
// Path length: Embree's `--max-path-length L` traces L rays per path, each hit with one light
// sample (L = 2: direct light at the camera hit and at one bounce). Our `max_depth` L does the
// same and traces one more BSDF ray from the last hit, whose sky hit MIS-weights against that
// hit's light sample; neither image has light of more bounces.
//
// Light and pixels: Embree's pathtracer shades a diffuse Kd under `--ambientlight L` at 2 Kd L,
// where a Lambertian surface reflects Kd L (ours). Measured on the car at 128x128: median of the
// car's pixels 0.200 at Kd 0.1 and 0.498 at Kd 0.25, with L = 1; with Kd = albedo / 2 its 256-spp
// image matches ours at that albedo within relMSE 0.0021 (`pathtracer -i peer.xml ...` against
// `texcache render ours.json`, compared with `texcache compare`). So the peer's scene gets half
// our albedo. And it writes its 8-bit display framebuffer: pixels clamped to [0, 1] and
// quantized to 1/255. An albedo near 1 would clip the whole body at 1 on its side, and hide its
// noise there; hence the default albedo 0.5 (quantization adds a variance of (1/255)^2 / 12, about
// 1e-6: far below the noise compared).
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_util.h"
#include "commands.h"
#include "renderer/image/metrics.h"
#include "renderer/scene/embree_xml.h"
#include "renderer/scene/obj_loader.h"

extern char** environ;

namespace texcache::cli {

namespace {

namespace fs = std::filesystem;

struct PeerArgs {
    std::string cage = std::string(TEXCACHE_SCENES_DIR) + "/meshes/catmark_car.obj";
    std::vector<float> position{5.0f, -7.0f, 3.0f}, lookAt{0.0f, -1.5f, 0.3f}, up{0, 0, 1};
    float fov = 40.0f;
    std::string resolution = "512x512";
    int spp = 64;
    int referenceSpp = 1024;
    int pathLength = 2;
    float albedo = 0.5f;
    int repeats = 5;
    std::string pathtracer;  // empty: `pathtracer` on PATH
    std::string ours;        // empty: this program
    std::string out = "out/bench_peer";
};

/// The executable `name` on PATH, or "" when there is none.
std::string FindOnPath(const std::string& name) {
    const char* path = std::getenv("PATH");
    std::string dirs = path ? path : "/usr/bin:/bin";
    size_t start = 0;
    while (start <= dirs.size()) {
        const size_t end = std::min(dirs.find(':', start), dirs.size());
        const fs::path candidate = fs::path(dirs.substr(start, end - start)) / name;
        if (end > start && ::access(candidate.c_str(), X_OK) == 0) return candidate.string();
        start = end + 1;
    }
    return "";
}

struct RunResult {
    double wall = 0.0, cpu = 0.0;  // seconds; cpu = the child's user + system time
};

/// Runs `argv` with stdout and stderr going to `log`; throws when it cannot start or fails.
RunResult RunProcess(const std::vector<std::string>& argv, const std::string& log) {
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, 1, 2);
    const double t0 = NowSeconds();
    pid_t pid = 0;
    const int err = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (err != 0) throw InputError(argv[0], std::string("cannot run: ") + std::strerror(err));
    int status = 0;
    rusage usage{};
    while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
    }
    RunResult r;
    r.wall = NowSeconds() - t0;
    r.cpu = double(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
            1e-6 * double(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
        throw std::runtime_error(argv[0] + std::string(" failed (exit status ") +
                                 std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
                                 "); its output is in " + log);
    return r;
}

std::string Vec3Arg(const std::vector<float>& v, const char* option) {
    if (v.size() != 3) throw InputError(option, "expected 3 numbers");
    for (float x : v)
        if (!std::isfinite(x)) throw InputError(option, "expected finite numbers");
    return std::to_string(v[0]) + ' ' + std::to_string(v[1]) + ' ' + std::to_string(v[2]);
}

/// The render side of the benchmark: a scene file for `texcache render` with the peer's setup.
std::string OurScene(const PeerArgs& a, int width, int height) {
    using nlohmann::json;
    json scene;
    scene["camera"] = {
        {"position", a.position}, {"look_at", a.lookAt}, {"up", a.up}, {"fov", a.fov}};
    scene["materials"] = {
        {"white", {{"type", "diffuse"}, {"albedo", {a.albedo, a.albedo, a.albedo}}}}};
    scene["objects"] = json::array(
        {{{"name", "cage"}, {"mesh", fs::absolute(a.cage).string()}, {"material", "white"}}});
    scene["lights"] = json::array({{{"type", "environment"}, {"constant", {1.0, 1.0, 1.0}}}});
    scene["render"] = {
        {"resolution", {width, height}}, {"integrator", "path"}, {"max_depth", a.pathLength}};
    return scene.dump(2) + "\n";
}

double Median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// The four images in a 2x2 grid: ours (left) and Embree's (right), test row above the
/// high-sample row; written as a PNG.
void WriteSideBySide(const std::string& path, const Image& ours, const Image& peer,
                     const Image& oursRef, const Image& peerRef) {
    const Image grid = Montage({{&ours, &peer}, {&oursRef, &peerRef}}, 0);
    WriteImage(path, grid);
}

int RunPeerBench(const PeerArgs& a) {
    int width = 0, height = 0;
    ParseResolution(a.resolution, &width, &height);
    CheckRange("--spp", a.spp, 1, 1 << 16);
    CheckRange("--reference-spp", a.referenceSpp, 1, 1 << 20);
    // A reference no better than the timed image measures nothing (relMSE 0, a 0/0 ratio).
    if (a.referenceSpp <= a.spp)
        throw InputError("--reference-spp", "must be more than --spp (" + std::to_string(a.spp) +
                                                "), got " + std::to_string(a.referenceSpp));
    CheckRange("--max-path-length", a.pathLength, 1, 64);
    CheckRange("--repeats", a.repeats, 1, 100);
    CheckRange("--fov", a.fov, 1e-3f, 179.0f);
    CheckRange("--albedo", a.albedo, 0.0f, 1.0f);
    const std::string vp = Vec3Arg(a.position, "--position"), vi = Vec3Arg(a.lookAt, "--look-at"),
                      vu = Vec3Arg(a.up, "--up");

    std::vector<std::string> warnings;
    const ControlCage cage = LoadObj(a.cage, &warnings);
    for (const std::string& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
    const EmbreePeerCheck check = CheckEmbreePeer(cage);
    if (!check.cannot.empty()) {
        std::string what = "Embree's pathtracer cannot render this cage: ";
        for (size_t i = 0; i < check.cannot.size(); ++i) what += (i ? "; " : "") + check.cannot[i];
        throw InputError(a.cage, what);
    }
    const std::string pathtracer = a.pathtracer.empty() ? FindOnPath("pathtracer") : a.pathtracer;
    if (pathtracer.empty() || ::access(pathtracer.c_str(), X_OK) != 0)
        throw InputError(a.pathtracer.empty() ? "bench peer" : a.pathtracer,
                         "Embree's pathtracer is not installed (Debian: apt-get install "
                         "embree-tools)");
    for (const std::string& d : check.differs)
        std::printf("note: the images will differ: %s\n", d.c_str());

    std::error_code ec;
    fs::create_directories(a.out, ec);
    if (ec) throw InputError("--out", "cannot create directory '" + a.out + "': " + ec.message());
    const fs::path dir = fs::absolute(a.out);
    const std::string xml = (dir / "peer.xml").string(), json = (dir / "ours.json").string();
    {
        AtomicFiles files;  // both scene files, renamed together once written
        // Half the albedo: the peer's diffuse response is twice ours (see the top).
        WriteText(xml, EmbreeXmlScene(cage, glm::vec3(0.5f * a.albedo)), files);
        WriteText(json, OurScene(a, width, height), files);
        files.Commit();
    }

    const std::string self = a.ours.empty() ? fs::read_symlink("/proc/self/exe").string()
                                            : fs::absolute(a.ours).string();
    if (::access(self.c_str(), X_OK) != 0) throw InputError(self, "not an executable");
    auto ours = [&](int spp, const std::string& image) {
        return std::vector<std::string>{self,
                                        "render",
                                        json,
                                        "-q",
                                        "--no-png",
                                        "--spp",
                                        std::to_string(spp),
                                        "-o",
                                        (dir / image).string()};
    };
    auto peer = [&](int spp, const std::string& image) {
        std::vector<std::string> cmd{pathtracer, "-i", xml, "--ambientlight", "1", "1", "1"};
        for (const std::string& s :
             {"--size " + std::to_string(width) + " " + std::to_string(height),
              "--spp " + std::to_string(spp), "--vp " + vp, "--vi " + vi, "--vu " + vu,
              "--fov " + std::to_string(a.fov),
              "--max-path-length " + std::to_string(a.pathLength)}) {
            size_t start = 0;  // split "--opt a b c" into words
            while (start < s.size()) {
                const size_t end = std::min(s.find(' ', start), s.size());
                cmd.push_back(s.substr(start, end - start));
                start = end + 1;
            }
        }
        cmd.insert(cmd.end(), {"-o", (dir / image).string()});
        return cmd;
    };
    const std::string oursLog = (dir / "ours.log").string(), peerLog = (dir / "peer.log").string();

    std::printf("cage %s (%d faces, %zu creases), %dx%d, %d spp, path length %d, %d pairs\n",
                a.cage.c_str(), cage.numFaces(), cage.creaseEdges.size(), width, height, a.spp,
                a.pathLength, a.repeats);
    std::printf("ours: %s\npeer: %s\n", self.c_str(), pathtracer.c_str());
    std::vector<double> ratios, oursWall, peerWall, oursCpu, peerCpu;
    for (int i = 0; i < a.repeats; ++i) {
        // ABAB: alternate which side runs first, so a trend in the load favours neither.
        RunResult o, p;
        if (i % 2 == 0) {
            o = RunProcess(ours(a.spp, "ours.exr"), oursLog);
            p = RunProcess(peer(a.spp, "peer.pfm"), peerLog);
        } else {
            p = RunProcess(peer(a.spp, "peer.pfm"), peerLog);
            o = RunProcess(ours(a.spp, "ours.exr"), oursLog);
        }
        oursWall.push_back(o.wall), peerWall.push_back(p.wall);
        oursCpu.push_back(o.cpu), peerCpu.push_back(p.cpu);
        ratios.push_back(o.wall / p.wall);
        std::printf("pair %d: ours %.3f s (cpu %.3f s), Embree %.3f s (cpu %.3f s), ratio %.3f\n",
                    i + 1, o.wall, o.cpu, p.wall, p.cpu, o.wall / p.wall);
        std::fflush(stdout);
    }

    // High-sample renders. Embree's tutorial has no seed: its sample i of a pixel is the same in
    // every run (measured: two runs are bit-identical, and a 1-spp image is 1.7x closer to the
    // 2-spp image than to the 16-spp one, as shared samples predict), so its reference contains
    // the timed image's samples. Ours does too (same seed, sample streams by index), so both
    // relMSEs are lowered alike, by (1 - n/N) / (1 + n/N) (0.88 at 64 of 1024 samples).
    std::printf("references: %d spp each ...\n", a.referenceSpp);
    std::fflush(stdout);
    const RunResult oursRefRun = RunProcess(ours(a.referenceSpp, "ours_ref.exr"), oursLog);
    const RunResult peerRefRun = RunProcess(peer(a.referenceSpp, "peer_ref.pfm"), peerLog);
    const Image oursImg = ReadImageRGB((dir / "ours.exr").string());
    const Image peerImg = ReadImageRGB((dir / "peer.pfm").string());
    const Image oursRef = ReadImageRGB((dir / "ours_ref.exr").string());
    const Image peerRef = ReadImageRGB((dir / "peer_ref.pfm").string());
    const double eOurs = RelMSE(oursImg, oursRef), ePeer = RelMSE(peerImg, peerRef);
    double meanOurs = 0.0, meanPeer = 0.0;
    for (float v : oursRef.data) meanOurs += v;
    for (float v : peerRef.data) meanPeer += v;
    meanOurs /= double(oursRef.data.size()), meanPeer /= double(peerRef.data.size());
    WriteSideBySide((dir / "side_by_side.png").string(), oursImg, peerImg, oursRef, peerRef);

    std::printf("reference renders: ours %.2f s, Embree %.2f s (%.3fx)\n", oursRefRun.wall,
                peerRefRun.wall, oursRefRun.wall / peerRefRun.wall);
    std::printf("wall time  (median of %d): ours %.3f s, Embree %.3f s\n", a.repeats,
                Median(oursWall), Median(peerWall));
    std::printf("cpu time   (median of %d): ours %.3f s, Embree %.3f s\n", a.repeats,
                Median(oursCpu), Median(peerCpu));
    std::printf("ours / Embree wall time: median %.3f x, range %.3f-%.3f (goal <= 1.0)\n",
                Median(ratios), *std::min_element(ratios.begin(), ratios.end()),
                *std::max_element(ratios.begin(), ratios.end()));
    std::printf(
        "relMSE at %d spp against its own %d spp: ours %.5f, Embree %.5f; ours / Embree "
        "%.3f (goal <= 1.0)\n",
        a.spp, a.referenceSpp, eOurs, ePeer, eOurs / ePeer);
    std::printf("references against each other: relMSE %.5f, mean value ours %.4f, Embree %.4f\n",
                RelMSE(oursRef, peerRef), meanOurs, meanPeer);
    std::printf(
        "wrote %s/{peer.xml,ours.json,side_by_side.png} (top: %d spp, bottom: %d spp; "
        "left ours, right Embree)\n",
        a.out.c_str(), a.spp, a.referenceSpp);
    return 0;
}

}  // namespace

void AddBenchPeerCommand(CLI::App& bench, int& exitCode) {
    auto args = std::make_shared<PeerArgs>();
    CLI::App* cmd = bench.add_subcommand(
        "peer", "Our path tracer against Embree's pathtracer tutorial on the same cage");
    cmd->add_option("cage", args->cage, "OBJ control cage")->capture_default_str();
    cmd->add_option("--position", args->position, "Camera position")->expected(3);
    cmd->add_option("--look-at", args->lookAt, "Point the camera looks at")->expected(3);
    cmd->add_option("--up", args->up, "Camera up vector")->expected(3);
    cmd->add_option("--fov", args->fov, "Vertical field of view (degrees)")->capture_default_str();
    cmd->add_option("--resolution", args->resolution, "Image size WxH")->capture_default_str();
    cmd->add_option("--spp", args->spp, "Samples per pixel of the timed renders")
        ->capture_default_str();
    cmd->add_option("--reference-spp", args->referenceSpp, "Samples of each side's reference")
        ->capture_default_str();
    cmd->add_option("--max-path-length", args->pathLength,
                    "Rays per path, Embree's meaning (ours: max_depth)")
        ->capture_default_str();
    cmd->add_option("--albedo", args->albedo,
                    "Diffuse albedo of the cage (the peer's scene gets half: see the source)")
        ->capture_default_str();
    cmd->add_option("--repeats", args->repeats, "Timed pairs (the median ratio is reported)")
        ->capture_default_str();
    cmd->add_option("--pathtracer", args->pathtracer,
                    "Embree's pathtracer executable (default: `pathtracer` on PATH)");
    cmd->add_option("--ours", args->ours,
                    "The texcache program of our side (default: this one; another build to "
                    "compare builds)");
    cmd->add_option("--out", args->out, "Directory of the scene files and images")
        ->capture_default_str();
    cmd->callback([args, &exitCode] { exitCode = RunPeerBench(*args); });
}

}  // namespace texcache::cli
