// SPDX-License-Identifier: Apache-2.0
// `texcache render`, internal to the command-line program: its arguments as parsed, and the parts
// its files share. cmd_render.cpp declares the options and sends a parsed command to the
// kind of render it asks for; render_args.cpp turns the arguments into RenderOptions and checks
// them;
// render_image.cpp renders one image or an animation and reports on it; render_frame_buffers.cpp
// writes the screen-space stage's buffers or its denoised images; render_stereo.cpp renders both
// eyes.
#pragma once
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include "cli_util.h"
#include "renderer/render.h"
#include "renderer/render_options.h"
#include "renderer/render_policy.h"
#include "renderer/scene/render_scene.h"
#include "renderer/texture_space/texture_space.h"
#include "renderer/texture_space/visibility_pass.h"

namespace texcache::cli {

struct RenderArgs {
    std::string scene;
    std::string output = "out/render.exr";
    // Options not given keep the scene's settings (Given(); no value of the type means "unset",
    // so a NaN or -1 on the command line is checked like any other value).
    std::set<std::string> given;
    bool Given(const std::string& option) const { return given.count(option) > 0; }
    int spp = 0;
    float seconds = 0.0f;
    std::string resolution;
    int threads = 0;
    std::string seed;
    std::string integrator;
    int maxDepth = 0;
    int aoSamples = 0;
    float aoDistance = 0.0f;
    float tessellationRate = 0.0f;
    std::string geometry = "subdivision";  // or "quads" (RenderSceneOptions::tessellateAll)
    float time = 0.0f;
    std::vector<std::string> aovs;
    float exposure = 0.0f;
    bool quiet = false;
    bool noPng = false;
    // Texture-space shading (libtexcache).
    std::string shading = "hit";
    std::string filter = "normal";
    int filterRadius = -1;  // not given: the filter's own default (DefaultFilterRadius)
    std::string footprint = "auto";
    std::string tsSamples = "auto";
    int shadowSamples = 4;
    float temporalAlpha = 0.0f;
    int passSpp = TextureSpaceOptions{}.passSpp;
    // Animation: frames "A:B" (inclusive) or "N" (frames 0..N-1) at fps.
    std::string frames;
    float fps = 24.0f;
    // Over many ranks: frames rendered before each rank's chunk to fill the temporal history
    // (-1: enough for --temporal-alpha, WarmUpFrames).
    int warmupFrames = -1;
    double sampleCacheMb = 64.0, texelCacheMb = 64.0;
    double maxMemoryMb = 0.0;  // 0: MemoryBudgetMiB's default
    float lodBias = 0.0f;
    bool referenceCache = false;
    bool overshading = false;
    bool directMapped = false;
    int indirectSamples = 1;
    int hitSamples = 1;
    std::string cachedLight = "auto";
    std::string lightSampling = "mis";
    double psrCacheMb = double(RenderOptions{}.psrCacheBytes) / (1 << 20);
    float psrLodBias = RenderOptions{}.psrLodBias;
    std::string statsFile;
    // Screen-space frame buffers: one multi-layer EXR per frame in this directory.
    std::string frameBuffers;
    // Screen-space stage on the frame buffers, written as images.
    std::string denoise;
    // Demodulation is on unless --no-demodulate; --demodulate says so explicitly.
    bool demodulate = false, noDemodulate = false;
    bool cachedVisibility = false;
    int visibilityRadius = TextureSpaceOptions{}.visibilityRadius;
    // Stereo: both eyes through one texture-space cache (renderer/texture_space/stereo.h).
    bool stereo = false;
    float eyeSeparation = 0.0f, convergence = 0.0f;
    std::string stereoReuse = "neighbour";
    std::string visibilityFilter = "none";
};

/// The names of the cache size options, for errors about the caches' sizes.
inline constexpr const char* kCacheSizeOptions = "--sample-cache-mb/--texel-cache-mb";

// render_args.cpp: arguments -> options, and the checks across them.

/// The scene's render settings with the command line's values on top, each checked; lengths
/// (--ao-distance) are in the scene file's units and stored in render units (`unitScale`,
/// renderer/scene/scene_units.h).
void ApplySettings(const RenderArgs& a, RenderSettings* settings, double unitScale);
/// Throws InputError for an option that the integrator or the other options leave unused
/// (--max-depth without the path integrator, --psr-cache-mb without cpis, --fps without
/// --frames...): images and stereo pairs, not the frame buffers' split.
void CheckOptionsUsed(const RenderArgs& a, const RenderOptions& opt);
/// A warning when the camera shows none of the scene's objects in the frame (or in any frame of
/// --frames): CameraViewProblem.
void WarnIfNothingVisible(const RenderArgs& a, const Scene& scene);
/// A warning when the integrator `integrator` needs light and every light of the scene is black
/// (the loader already warns about a scene without lights), and one naming the environment map
/// and what its loading repaired (EnvironmentMap::Repairs). Reads the map, so that a bad one
/// fails before anything renders (EnvironmentMap::Shared keeps it for the render).
void WarnIfUnlit(const Scene& scene, IntegratorKind integrator);

/// The texture-space options of the command line; `lights`: the kinds of light the scene has,
/// which `--cached-light auto` decides by (CachedDirectLight).
TextureSpaceOptions ParseTextureOptions(const RenderArgs& a, LightKinds lights);
/// The cache sizes of a render of `opt` (`views` images): those given, else sized to the frame
/// (SizeTextureCaches), checked against this machine's memory.
void SizeCaches(const RenderArgs& a, RenderOptions* opt, int views);
/// The memory a render may take (MemoryBudgetMiB of --max-memory-mb, checked when given).
double MemoryBudget(const RenderArgs& a);
/// --light-sampling and its record cache: product sampling needs an environment light and an
/// integrator that samples lights (errors name the option and the problem).
void ParseLightSamplingOptions(const RenderArgs& a, const Scene& scene, RenderOptions* opt);
AovFlags ParseAovs(const std::vector<std::string>& names);
/// Frame range of --frames: "A:B" (inclusive) or "N" (0..N-1).
void ParseFrames(const std::string& s, int* first, int* last);
/// Output name of frame f: the run of '#' in the name replaced by the zero-padded number, or
/// "_NNNN" inserted before the extension.
std::string FramePath(const std::string& output, int f);
/// Options that only mean something together with others are errors when they would be ignored.
void CheckCombinations(const RenderArgs& a, const RenderSettings& s, const RenderOptions& opt,
                       const OutputPaths& out);
/// Checks the planned outputs against each other and against every file the scene reads, and
/// that each can be written, before anything renders (FileSet).
void CheckFiles(const Scene& scene, const std::vector<OutputPaths>& outs,
                const std::string& statsFile = "");
/// TBB's thread limit for --threads N (none for 0).
std::unique_ptr<tbb::global_control> ThreadLimit(int threads);
/// What a RenderScene of the scene at `time` builds for a render of `opt`.
RenderSceneOptions SceneOptionsFor(const RenderArgs& a, const RenderOptions& opt, float time);

// render_frame_buffers.cpp: the path tracer's decomposition, for the screen-space stage.

/// --frame-buffers DIR: each frame's buffers as DIR/frame_NNNN.exr (+ the composed image as a
/// PNG), frames first..last at `fps`.
int RunFrameBuffers(const RenderArgs& a, const Scene& scene, RenderOptions opt, int first, int last,
                    float fps);
/// --denoise: each frame's buffers rendered in memory and denoised by the screen-space stage.
int RunDenoised(const RenderArgs& a, const Scene& scene, RenderOptions opt, bool animated,
                int first, int last, float fps);

// render_stereo.cpp

/// The options --stereo cannot honour (yet) are errors, as are the rig's options without it.
void CheckStereoOptions(const RenderArgs& a);
/// --stereo: NAME_left.exr and NAME_right.exr (+ PNGs), both eyes through one cache.
int RunStereo(const RenderArgs& a, const Scene& scene, const RenderOptions& opt);

// render_image.cpp: one image, or an animation, and what a render reports besides its images.

/// One image to `out` (+ --stats), its figures printed; `loadSeconds`: reading the scene.
int RunImage(const RenderArgs& a, const Scene& scene, const RenderOptions& opt,
             VisibilityFilterKind visibility, OutputPaths& out, double loadSeconds);
/// Frames first..last at `fps` to `outs` (one per frame), the texture-space cache kept across
/// them (AnimationFrames).
int RunAnimation(const RenderArgs& a, const Scene& scene, const RenderOptions& opt,
                 VisibilityFilterKind visibility, std::vector<OutputPaths>& outs, int first,
                 int last, float fps);

/// Frames a rank renders (unwritten) before its chunk of an animation so that its temporal
/// history matches the sequence's: the history that is missing weighs alpha^W after W frames,
/// and W makes that at most 1% (13 frames at the paper's 0.7; none without temporal history).
int WarmUpFrames(float temporalAlpha);

/// This rank's part of frames first..last over the job's ranks: a contiguous chunk
/// [first, last] (empty when there are more ranks than frames), rendered from `from` (the
/// `warm` frames before the chunk rendered and not written). One rank: all of them.
struct FrameChunk {
    int from, first, last;
};
FrameChunk ChunkOfFrames(int first, int last, int warm);

/// --stats: the render's figures as JSON (`overshading` < 0: not measured).
std::string StatsJson(const RenderStats& s, const RenderScene& rs, const TextureSpaceCache* cache,
                      const RenderOptions& opt, double overshading);
/// The scene's size, and the meshes Embree could not take (embree_mesh.cpp's design note).
void PrintSceneStats(const RenderScene& rs);

}  // namespace texcache::cli
