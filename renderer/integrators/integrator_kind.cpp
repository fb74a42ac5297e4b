// SPDX-License-Identifier: Apache-2.0
#include "renderer/integrators/integrator_kind.h"

#include "texcache/enum_names.h"

namespace texcache {

namespace {
constexpr EnumName<IntegratorKind> kIntegrators[] = {
    {"normal", IntegratorKind::Normal}, {"ptex", IntegratorKind::Ptex},
    {"uv", IntegratorKind::Uv},         {"eyelight", IntegratorKind::EyeLight},
    {"ao", IntegratorKind::AO},         {"direct", IntegratorKind::Direct},
    {"path", IntegratorKind::Path},
};
}  // namespace

IntegratorKind ParseIntegrator(const std::string& name, const std::string& where) {
    return ParseEnum(kIntegrators, name, where, "integrator");
}

std::string IntegratorNames() {
    return EnumNames(kIntegrators);
}

const char* IntegratorName(IntegratorKind kind) {
    return EnumToName(kIntegrators, kind);
}

bool IntegratorUsesLights(IntegratorKind kind) {
    return kind == IntegratorKind::Direct || kind == IntegratorKind::Path;
}

}  // namespace texcache
