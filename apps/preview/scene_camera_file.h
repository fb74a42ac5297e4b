// SPDX-License-Identifier: Apache-2.0
// Writing the preview's camera back into a scene file without disturbing the rest of it.
#pragma once
#include <string>

#include <glm/glm.hpp>

namespace texcache::preview {

/// Returns `text` (a scene file) with its top-level "camera" object replaced by one with this
/// position, look-at point, up vector and field of view. The camera's other keys (lens, shutter)
/// are kept, "keyframes" is dropped (the new camera is static); everything outside the camera
/// object, comments included, is kept byte for byte. A file without a camera gets one after its
/// opening brace. Throws InputError(`where`, ...) when the text is not a JSON object.
std::string ReplaceSceneCamera(const std::string& text, glm::vec3 position, glm::vec3 lookAt,
                               glm::vec3 up, float fovDegrees, const std::string& where);

/// Reads `path`, replaces its camera as above, checks that the result still loads as a scene,
/// writes it to a temporary file beside `path` and renames it over `path` (an interrupted or
/// failed save leaves the original intact). Throws InputError.
void SaveCameraToSceneFile(const std::string& path, glm::vec3 position, glm::vec3 lookAt,
                           glm::vec3 up, float fovDegrees);

}  // namespace texcache::preview
