// SPDX-License-Identifier: Apache-2.0
// `texcache preview`: the interactive preview window, its headless test mode and its frame-rate
// benchmark. The CLI registers the subcommand (apps/cli/cmd_preview.cpp).
#pragma once
#include <string>

#include "renderer/preview/progressive_renderer.h"
#include "renderer/scene/scene.h"

namespace texcache::preview {

struct PreviewArgs {
    std::string scenePath;            ///< the file given (a .json scene can take the camera back)
    int frames = 0;                   ///< > 0: headless test mode, this many frames then exit
    std::string screenshot;           ///< headless: PNG of the window after the last frame
    float orbitDegrees = 20.0f;       ///< headless / bench: camera orbit spread over the frames
    std::string filterName = "none";  ///< as given, for reports
    bool saveCamera = false;          ///< headless: write the final camera into the scene file
    bool play = false;                ///< headless: advance the scene time 1/fps per frame
    float fps = 24.0f;                ///< frames per second of --play and the timeline's steps
};

/// Opens the window (or runs the headless frames); returns the exit code. Throws InputError when
/// there is no display (exit 2 through main) or the window cannot be created.
int RunPreviewWindow(Scene scene, const PreviewSettings& settings, const PreviewArgs& args);

struct BenchArgs {
    int frames = 36;        ///< orbit frames timed per configuration (after one cold frame)
    int referenceSpp = 32;  ///< per-hit AO reference: spp x aoSamples rays per pixel
    int referenceAoSamples = 16;
    std::string out = "out/preview_bench";  ///< prefix of the images written
    /// With the stage: a still view instead of the orbit, its denoised relMSE frame by frame
    /// (texture space refreshed as a running mean, against per hit).
    bool still = false;
    /// With `still`: the stage told the view is still (its running mean); false keeps the
    /// moving view's blend, for comparison.
    bool stageRunningMean = true;
    /// With the stage: the light samples a pixel of the specular lobe on objects whose diffuse
    /// base the cache lights (TextureSpaceOptions::specularLightSamples); 0: the default.
    int specularSamples = 0;
    /// With the stage, moving: per hit again with 2, 4, 8 samples a pixel until its denoised
    /// relMSE reaches texture space's, for the cost ratio at equal error.
    bool equalError = false;
    /// With the stage: the frame buffers' store and grid both (then per hit), frame by frame in
    /// turn; false: only the settings' fbCache.
    bool bothCaches = true;
    /// With the stage: the texture-space run on Embree's subdivision geometry too (the
    /// settings' limit quads first), frame by frame in turn (`--geometry both`).
    bool bothGeometries = false;
};

/// Texture-space AO with a warm cache against per-hit AO at equal relMSE, while orbiting; prints
/// frames per second and relMSE of each. No window needed.
int RunPreviewBench(const Scene& scene, const PreviewSettings& settings, const PreviewArgs& args,
                    const BenchArgs& bench);

}  // namespace texcache::preview
