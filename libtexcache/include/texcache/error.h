// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <stdexcept>
#include <string>

namespace texcache {

/// An error in user input (a file, a command-line value, a scene key). The message always names
/// where the problem is ("scene.json: key 'camera.fov': expected a number") so the CLI can print it
/// verbatim and exit with code 2.
class InputError : public std::runtime_error {
public:
    /// `where` is "file:line" or "file: key 'a.b'" or "--option"; `what` describes the problem.
    InputError(const std::string& where, const std::string& what)
        : std::runtime_error(where.empty() ? what : where + ": " + what) {}
};

}  // namespace texcache
