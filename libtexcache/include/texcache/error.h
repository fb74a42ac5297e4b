// SPDX-License-Identifier: Apache-2.0
#pragma once
#include <cstdio>
#include <stdexcept>
#include <string>
#include <string_view>

namespace texcache {

/// A user-supplied token (a number, a key, a name) as it should appear inside a message: whole
/// when short, else its first `keep` bytes, "..." and its length, so that an 8 MB OBJ line or a
/// 10 MB JSON key cannot flood the terminal. Control bytes are escaped by InputError itself.
inline std::string Excerpt(std::string_view token, size_t keep = 48) {
    if (token.size() <= keep + 16) return std::string(token);
    return std::string(token.substr(0, keep)) + "... (" + std::to_string(token.size()) + " bytes)";
}

namespace internal {

/// The message as one printable line: control bytes (NUL, newline, escape sequences, ...) become
/// "\n" or "\xHH", because what() is a C string (a NUL would cut it short) and the CLI promises
/// one line per error. Bytes >= 0x80 stay (UTF-8 file names). Messages longer than `limit`
/// bytes (only when a caller forgot Excerpt) keep their start and end.
inline std::string OneLine(const std::string& s, size_t limit = 2048) {
    std::string o;
    o.reserve(s.size() < limit ? s.size() : limit);
    for (const char ch : s) {
        const unsigned char c = static_cast<unsigned char>(ch);
        if (c >= 0x20 && c != 0x7f) {
            o += ch;
        } else if (c == '\n') {
            o += "\\n";
        } else if (c == '\t') {
            o += "\\t";
        } else {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\x%02x", c);
            o += buf;
        }
    }
    if (o.size() > limit)
        o = o.substr(0, limit / 2) + " ... (" + std::to_string(o.size() - limit) +
            " bytes cut) ... " + o.substr(o.size() - limit / 2);
    return o;
}

}  // namespace internal

/// An error in user input (a file, a command-line value, a scene key). The message always names
/// where the problem is ("scene.json: key 'camera.fov': expected a number") so the CLI can print it
/// verbatim and exit with code 2. It is always one printable line (internal::OneLine).
class InputError : public std::runtime_error {
public:
    /// `where` is "file:line" or "file: key 'a.b'" or "--option"; `what` describes the problem.
    InputError(const std::string& where, const std::string& what)
        : std::runtime_error(internal::OneLine(where.empty() ? what : where + ": " + what)) {}
};

}  // namespace texcache
