// SPDX-License-Identifier: Apache-2.0
// OBJ control cages with OpenSubdiv tags (`t crease`, `t corner`, `t hole`,
// `t interpolateboundary`); the accepted dialect and every policy are in scenes/README.md.
// Errors throw InputError("file:line", problem): malformed numbers, NaN/Inf, bad or zero indices,
// faces with < 3 or repeated vertices, a face with vt on some corners only, tag count mismatches,
// no faces. Warnings ("file:line: ...") skip: unknown tags and statements, tags naming missing
// edges/vertices/faces, uvs on some faces only (uvs dropped), dangling vn indices.
// Duplicate creases and corners keep their largest sharpness.
#pragma once
#include <string>
#include <string_view>
#include <vector>

#include "texcache/cage.h"

namespace texcache {

/// What an OBJ says of materials and groups (`mtllib`, `usemtl`, `g`, `o`), per face.
struct ObjFaceTags {
    struct Named {
        std::string name;
        int line = 0;  ///< where it first appears
    };
    std::vector<Named> libraries;   ///< `mtllib` files as written, in order
    std::vector<Named> materials;   ///< `usemtl` names, in order of first use
    std::vector<int> faceMaterial;  ///< per face: index into `materials`, -1 before any usemtl
    std::vector<Named> groups;      ///< `g` and `o` names, in order of first use
    std::vector<int> faceGroup;     ///< per face: index into `groups`, -1 before any g or o
};

/// Loads an OBJ cage; throws InputError naming file:line; `warnings` (may be null) gets skips;
/// `tags` (may be null) gets the file's materials and groups.
ControlCage LoadObj(const std::string& path, std::vector<std::string>* warnings,
                    ObjFaceTags* tags = nullptr);
/// Parses OBJ text as LoadObj does; `name` stands for the file in messages and sourcePath.
ControlCage ParseObj(std::string_view text, const std::string& name,
                     std::vector<std::string>* warnings, ObjFaceTags* tags = nullptr);

}  // namespace texcache
