// SPDX-License-Identifier: Apache-2.0
// Scene files (JSON, documented in scenes/README.md) and bare OBJ cages -> Scene. Errors throw
// InputError naming the file and the key path ("car.json: key 'camera.fov': ..."), or
// file:line:column for JSON syntax errors; OBJ errors keep the OBJ's own file:line.
#pragma once
#include <string>
#include <vector>

#include "renderer/scene/scene.h"

namespace texcache {

/// Loads a scene file (paths in it relative to its directory); `warnings` may be null.
Scene LoadScene(const std::string& path, std::vector<std::string>* warnings);
/// One OBJ, grey diffuse, framed from a 3/4 view above, lit by `defaultEnvPath` (white if absent).
Scene SceneFromObj(const std::string& objPath, const std::string& defaultEnvPath,
                   std::vector<std::string>* warnings);
/// A .json scene (LoadScene) or a bare .obj cage (SceneFromObj), by the file's extension;
/// throws InputError naming the path when it is missing or of another type.
Scene LoadSceneFile(const std::string& path, const std::string& defaultEnvPath,
                    std::vector<std::string>* warnings);
/// Camera pose at `position` looking down -Z at `target`, +Y towards `up`; throws if degenerate.
Keyframe CameraLookAt(glm::vec3 position, glm::vec3 target, glm::vec3 up, const std::string& where);

}  // namespace texcache
