// SPDX-License-Identifier: Apache-2.0
// What a render computes per pixel. Its own header, below the scene, so that a scene file's
// render settings can name an integrator and every layer spells the names from one table.
#pragma once
#include <string>

namespace texcache {

/// Debug views (normal, ptex face, uv, eye light), ambient occlusion, direct lighting (one
/// bounce) and path tracing.
enum class IntegratorKind { Normal, Ptex, Uv, EyeLight, AO, Direct, Path };

/// Parses an integrator name; throws InputError naming `where` and listing the valid names.
IntegratorKind ParseIntegrator(const std::string& name, const std::string& where);
/// Valid integrator names, comma separated (for help texts).
std::string IntegratorNames();
/// The name ParseIntegrator takes for `kind`.
const char* IntegratorName(IntegratorKind kind);
/// Whether an integrator needs lights (environment, area, distant) to be built.
bool IntegratorUsesLights(IntegratorKind kind);

}  // namespace texcache
