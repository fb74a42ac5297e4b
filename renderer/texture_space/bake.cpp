// SPDX-License-Identifier: Apache-2.0
#include "renderer/texture_space/bake.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>

#include <tbb/parallel_for.h>

#include "renderer/texture_space/cached_shading.h"
#include "texcache/error.h"
#include "texcache/ptex/mesh_faces.h"

namespace texcache {

using namespace internal;

std::vector<ptex::FaceTexels> BakedTexture::Faces() const {
    std::vector<ptex::FaceTexels> out(faces.size());
    for (size_t f = 0; f < faces.size(); ++f) out[f] = {faces[f], texels[f]};
    return out;
}

void CheckBakeOptions(const BakeOptions& bake) {
    if (bake.resolution < 1 || bake.resolution > 4096 ||
        !std::has_single_bit(unsigned(bake.resolution)))
        throw InputError("--resolution",
                         "texels along a face must be a power of two in [1, 4096], got " +
                             std::to_string(bake.resolution));
    if (bake.samples < 1 || bake.samples > (1 << 20))
        throw InputError("--samples",
                         "must be in [1, 1048576], got " + std::to_string(bake.samples));
    const IntegratorKind k = bake.integrator;
    if (k != IntegratorKind::AO && k != IntegratorKind::Direct && k != IntegratorKind::Path)
        throw InputError("--integrator",
                         std::string("bakes ao, direct or path, not ") + IntegratorName(k));
}

std::vector<BakedTexture> Bake(const RenderScene& rs, RenderOptions opt, const BakeOptions& bake) {
    CheckBakeOptions(bake);
    const bool ao = bake.integrator == IntegratorKind::AO;
    opt.integrator = bake.integrator;
    opt.aoSamples = bake.samples;
    opt.texture.enabled = true;
    opt.texture.indirectSamples = bake.samples;
    opt.texture.cacheDirect = true;
    if (bake.integrator == IntegratorKind::Direct) opt.maxDepth = 1;
    // Samples are shaded directly, never looked up: the cache's tables stay small.
    opt.texture.cache.sampleCacheBytes = opt.texture.cache.texelCacheBytes = size_t(64) << 10;
    opt.progress = false;
    Context c(rs, opt);
    TextureSpaceCache cache(rs, opt.texture);
    cache.PrepareGrid();
    c.tsc = &cache;

    const Scene& scene = rs.scene();
    std::vector<BakedTexture> out(scene.objects.size());
    for (size_t o = 0; o < scene.objects.size(); ++o) {
        BakedTexture& b = out[o];
        b.object = scene.objects[o].name;
        const int mesh = cache.MeshOf(int(o));
        const MeshGrids& grids = cache.Grids(mesh);
        // One mip offset for the object: texels keep the cache's density, equal on every face,
        // and the largest face gets `resolution` texels a side.
        int largest = 0;
        for (int f = 0; f < grids.NumFaces(); ++f) largest = std::max(largest, grids.Log2Res(f));
        const int mip = std::max(0, largest - std::countr_zero(unsigned(bake.resolution)));
        b.faces = ptex::MeshFaces(rs.Topology(int(o)), [&](int f) {
            const int8_t l = int8_t(std::countr_zero(unsigned(grids.Res(f, mip))));
            return ptex::Res{l, l};
        });
        b.options.dataType = ptex::DataType::Half;
        b.options.numChannels = ao && !bake.albedo ? 1 : 3;
        b.options.meta = {
            {"texcache:term",
             ptex::MetaType::String,
             ao ? "ambient occlusion" : (bake.albedo ? "diffuse radiance" : "diffuse light"),
             {}},
            {"texcache:samples", ptex::MetaType::Int32, "", {double(bake.samples)}}};
        b.texels.resize(b.faces.size());
        std::atomic<size_t> unreachable{0};
        tbb::parallel_for(0, grids.NumFaces(), [&](int f) {
            const int res = grids.Res(f, mip), channels = b.options.numChannels;
            std::vector<float>& texels = b.texels[size_t(f)];
            texels.resize(size_t(res) * size_t(res) * size_t(channels));
            RayCounts rays;
            size_t missed = 0;
            for (int t = 0; t < res; ++t)
                for (int s = 0; s < res; ++s) {
                    const TexelKey key{grids.FaceOffset() + uint32_t(f), uint8_t(mip), uint16_t(s),
                                       uint16_t(t)};
                    const SampleRequest r = cache.RequestOf(mesh, key);
                    const ShadedSample v =
                        ao ? ShadeAoSample(c, r, rays) : ShadeDiffuseSample(c, r, true, rays);
                    glm::vec3 value = v.value;
                    if (!std::isfinite(value.x + value.y + value.z)) {
                        value = glm::vec3(0.0f);
                        ++missed;
                    }
                    if (bake.albedo) value *= rs.AlbedoAt(int(o), {f, r.u, r.v}, 1.0f / float(res));
                    float* px = &texels[(size_t(t) * size_t(res) + size_t(s)) * size_t(channels)];
                    for (int k = 0; k < channels; ++k) px[k] = value[k];
                }
            unreachable += missed;
        });
        b.unreachable = unreachable;
    }
    return out;
}

}  // namespace texcache
