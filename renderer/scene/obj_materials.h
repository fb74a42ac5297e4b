// SPDX-License-Identifier: Apache-2.0
// OBJ materials: `mtllib` files (MTL) read into the scene's materials, and an OBJ's `usemtl`
// faces given them. The MTL dialect and how its statements map to the project's materials are in
// scenes/README.md ("OBJ materials").
#pragma once
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/scene/obj_loader.h"
#include "renderer/scene/scene.h"

namespace texcache {

/// One `newmtl` of an MTL file, as written.
struct MtlMaterial {
    std::string name;
    int line = 0;
    glm::vec3 Kd{0.8f}, Ks{0.0f}, Ke{0.0f};
    float Ns = -1.0f;   ///< -1: not given
    float d = 1.0f;     ///< dissolve (1 - Tr)
    std::string mapKd;  ///< as written, relative to the MTL file
    int mapKdLine = 0;
};

/// Parses MTL text; `name` stands for the file in messages. Throws InputError("file:line", ...)
/// for malformed values; unknown statements are skipped with one warning per keyword.
std::vector<MtlMaterial> ParseMtl(std::string_view text, const std::string& name,
                                  std::vector<std::string>* warnings);

/// The project's material for an MTL one (scenes/README.md has the mapping): its map_Kd is
/// relative to `mtlPath`'s directory; a texture it needs is appended to `textures`.
Material ToMaterial(const MtlMaterial& mtl, const std::string& mtlPath,
                    std::vector<Texture>* textures, std::vector<std::string>* warnings);

/// Gives `object`'s faces the materials its OBJ's `usemtl` names: the scene material of that
/// name when the scene file defines one (`sceneMaterials`: it overrides the MTL's), else the
/// material the OBJ's `mtllib` files define, read once per file (`loaded`: MTL path and name
/// -> material id); faces with no material, or one no library defines (a warning), get the
/// material `fallback()` returns. Sets object->material to its first face's, and leaves
/// faceMaterials empty when every face has the same.
void AssignObjMaterials(const ObjFaceTags& tags, const std::string& objPath,
                        const std::map<std::string, int>& sceneMaterials,
                        const std::function<int()>& fallback, std::map<std::string, int>* loaded,
                        Scene* scene, Object* object, std::vector<std::string>* warnings);

}  // namespace texcache
