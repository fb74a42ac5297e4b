// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/scene/scene.h"

namespace texcache {

/// A texture ready for lookups: an image (linear RGB, bilinear, wrapping) or a checker.
class TextureImage {
public:
    /// Loads an image texture (8-bit formats are sRGB-decoded) or wraps a procedural one.
    explicit TextureImage(const Texture& desc);
    /// Linear RGB at uv (wrapping).
    glm::vec3 Eval(glm::vec2 uv) const;

private:
    Texture desc_;
    int width_ = 0, height_ = 0;
    std::vector<glm::vec3> texels_;
};

}  // namespace texcache
