// SPDX-License-Identifier: Apache-2.0
// Baking: the converged texture-space shading of each object of a scene (ambient occlusion, or
// the diffuse light it receives) on a Ptex grid per face, for `texcache bake` to write as one
// Ptex file per object. Each texel is one cache sample at the texel's centre, shaded as the
// texture-space cache shades its samples (cached_shading.h) with as many rays as asked: the
// value the cache's progressive passes converge to, without a filter's footprint.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "renderer/render_options.h"
#include "renderer/scene/render_scene.h"
#include "texcache/ptex/writer.h"

namespace texcache {

struct BakeOptions {
    /// AO: ambient occlusion (opt.aoDistance); Direct or Path: the diffuse light a white
    /// surface receives, (1/pi) integral of L cos (direct and indirect; Direct: direct only).
    IntegratorKind integrator = IntegratorKind::AO;
    int samples = 256;    ///< AO rays or light paths per texel
    int resolution = 64;  ///< texels along the side of each object's largest face (power of 2)
    bool albedo = false;  ///< multiply by the material's albedo at the texel (baked radiance)
};

/// One object's baked texture: what ptex::EncodeTexture takes.
struct BakedTexture {
    std::string object;  ///< the object's name
    ptex::WriteOptions options;
    std::vector<ptex::FaceInfo> faces;
    std::vector<std::vector<float>> texels;  ///< per face, row-major from v = 0
    size_t unreachable = 0;  ///< texels whose surface point could not be shaded (written as 0)
    std::vector<ptex::FaceTexels> Faces() const;
};

/// Throws InputError naming the option for a resolution that is not a power of two in
/// [1, 4096], a sample count out of [1, 2^20] or an integrator other than ao, direct and path.
void CheckBakeOptions(const BakeOptions& bake);

/// Bakes every object of `rs` (front side: the side of its limit normals, or the outside of a
/// closed cage). `render` gives the scene's render settings (max depth, AO distance, seed, light
/// sampling); the integrator, sample counts and the texture-space settings are the bake's.
/// Throws as CheckBakeOptions.
std::vector<BakedTexture> Bake(const RenderScene& rs, RenderOptions render,
                               const BakeOptions& bake);

}  // namespace texcache
