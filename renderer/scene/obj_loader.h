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

/// Loads an OBJ cage; throws InputError naming file:line; `warnings` (may be null) gets skips.
ControlCage LoadObj(const std::string& path, std::vector<std::string>* warnings);
/// Parses OBJ text as LoadObj does; `name` stands for the file in messages and sourcePath.
ControlCage ParseObj(std::string_view text, const std::string& name,
                     std::vector<std::string>* warnings);

}  // namespace texcache
