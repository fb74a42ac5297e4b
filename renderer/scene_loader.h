// SPDX-License-Identifier: Apache-2.0
// Scene files (JSON, documented in scenes/README.md) and bare OBJ cages -> Scene.
#pragma once
#include <string>
#include <vector>

#include "renderer/scene.h"

namespace texcache {

/// Loads a scene file; throws InputError naming the file and the key path (or line:column for
/// JSON syntax errors). Paths in the file are relative to its directory.
Scene LoadScene(const std::string& path, std::vector<std::string>* warnings);
/// One OBJ cage framed by a default camera (3/4 view from above, whole bounding box in view) and
/// lit by the environment map `defaultEnvPath`, with a grey diffuse material.
Scene SceneFromObj(const std::string& objPath, const std::string& defaultEnvPath,
                   std::vector<std::string>* warnings);
/// Keyframe of a camera at `position` looking at `target` with `up` (throws when degenerate).
Keyframe CameraLookAt(glm::vec3 position, glm::vec3 target, glm::vec3 up, const std::string& where);

}  // namespace texcache
