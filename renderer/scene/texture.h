// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/scene/scene.h"
#include "texcache/ptex/texture.h"

namespace texcache {

/// Where a texture is looked up: the cage's uv (images, checkers), or a Ptex face, its (u,v) and
/// the filter width in the face's parameter units (Ptex files; 0: the finest level).
struct TextureQuery {
    glm::vec2 uv{0.0f};
    int face = 0;
    float u = 0.0f, v = 0.0f;
    float width = 0.0f;
};

/// A texture ready for lookups: an image (linear RGB, bilinear, wrapping), a checker, or a Ptex
/// file (filtered across face edges by its adjacency; ptex::Texture::Lookup).
class TextureImage {
public:
    /// Loads an image texture (8-bit formats are sRGB-decoded) or a Ptex file (its values as
    /// stored), or wraps a procedural one. Throws InputError naming the file.
    explicit TextureImage(const Texture& desc);
    /// Linear RGB at uv (wrapping); images and checkers only.
    glm::vec3 Eval(glm::vec2 uv) const;
    /// A colour: RGB at the query (a Ptex file's channels from the texture's `channel` on; one
    /// channel left there reads as grey).
    glm::vec3 Color(const TextureQuery& q) const;
    /// A scalar: a Ptex file's `channel`, else the colour's luminance.
    float Scalar(const TextureQuery& q) const;
    /// The Ptex file's faces, or -1 when the texture is not a Ptex file.
    int PtexFaces() const { return ptex_ ? ptex_->NumFaces() : -1; }

private:
    Texture desc_;
    int width_ = 0, height_ = 0;
    std::vector<glm::vec3> texels_;
    std::optional<ptex::Texture> ptex_;
};

}  // namespace texcache
