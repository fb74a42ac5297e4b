// SPDX-License-Identifier: Apache-2.0
// OBJ control cages with OpenSubdiv tags (`t crease`, `t corner`, `t hole`,
// `t interpolateboundary`).
#pragma once
#include <string>
#include <string_view>
#include <vector>

#include "texcache/cage.h"

namespace texcache {

/// Loads an OBJ cage; throws InputError("file:line", problem) on bad input. Tags naming missing
/// edges, vertices or faces, and unknown tags, add a warning ("file:line: ...") and are skipped.
ControlCage LoadObj(const std::string& path, std::vector<std::string>* warnings);
/// Parses OBJ text (for tests); `name` is used in messages.
ControlCage ParseObj(std::string_view text, const std::string& name,
                     std::vector<std::string>* warnings);

}  // namespace texcache
