// SPDX-License-Identifier: Apache-2.0
#include "filters/texture_filters.h"

#include "texcache/error.h"

namespace texcache {

TextureFilterKind ParseTextureFilter(const std::string& name, const std::string& where) {
    if (name == "none") return TextureFilterKind::None;
    if (name == "normal") return TextureFilterKind::Normal;
    if (name == "gaussian") return TextureFilterKind::Gaussian;
    if (name == "regression") return TextureFilterKind::Regression;
    if (name == "softshadow") return TextureFilterKind::SoftShadow;
    throw InputError(where, "unknown filter '" + name + "' (valid: " + TextureFilterNames() + ")");
}

const char* TextureFilterNames() {
    return "none, normal, gaussian, regression, softshadow";
}

}  // namespace texcache
