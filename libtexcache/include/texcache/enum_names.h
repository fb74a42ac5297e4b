// SPDX-License-Identifier: Apache-2.0
// Names of enum values, for command lines, scene files and messages: one table per enum, so a
// name is spelled once and parsing, listing and printing cannot disagree.
//
//   constexpr EnumName<Colour> kColours[] = {{"red", Colour::Red}, {"green", Colour::Green}};
//   Colour c = ParseEnum(kColours, "green", "--colour", "colour");
//   // unknown: InputError "--colour: unknown colour 'blue' (valid: red, green)"
#pragma once
#include <cstddef>
#include <string>
#include <string_view>

#include "texcache/error.h"

namespace texcache {

template <typename E>
struct EnumName {
    const char* name;
    E value;
};

/// The names of a table, comma separated ("red, green"), for help texts and messages.
template <typename E, size_t N>
std::string EnumNames(const EnumName<E> (&table)[N]) {
    std::string s;
    for (const EnumName<E>& e : table) s += std::string(s.empty() ? "" : ", ") + e.name;
    return s;
}

/// The value named `name`; throws InputError naming `where` and every valid name otherwise.
/// `what` says what kind of name it is ("integrator", "filter").
template <typename E, size_t N>
E ParseEnum(const EnumName<E> (&table)[N], std::string_view name, const std::string& where,
            const char* what) {
    for (const EnumName<E>& e : table)
        if (name == e.name) return e.value;
    throw InputError(where, std::string("unknown ") + what + " '" + std::string(name) +
                                "' (valid: " + EnumNames(table) + ")");
}

/// The name of `value`, or "?" when the table lacks it.
template <typename E, size_t N>
const char* EnumToName(const EnumName<E> (&table)[N], E value) {
    for (const EnumName<E>& e : table)
        if (e.value == value) return e.name;
    return "?";
}

}  // namespace texcache
