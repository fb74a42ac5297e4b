// SPDX-License-Identifier: Apache-2.0
// The rewrite is textual on purpose: scene files may hold comments and a hand-chosen layout, which
// a parse + dump round trip would lose. A small scanner that knows JSON strings and comments finds
// the span of the top-level "camera" value; only that span changes.
#include "scene_camera_file.h"

#include <unistd.h>

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "renderer/scene/scene_loader.h"
#include "texcache/error.h"

namespace texcache::preview {

namespace {

namespace fs = std::filesystem;

/// Cursor over JSON text with comments (the scene loader accepts // and /* */).
struct Scanner {
    const std::string& s;
    size_t i = 0;
    std::string where;

    [[noreturn]] void Fail(const std::string& what) const {
        throw InputError(where, what + " at offset " + std::to_string(i));
    }
    void SkipSpace() {
        while (i < s.size()) {
            if (std::isspace(static_cast<unsigned char>(s[i]))) {
                ++i;
            } else if (s.compare(i, 2, "//") == 0) {
                while (i < s.size() && s[i] != '\n') ++i;
            } else if (s.compare(i, 2, "/*") == 0) {
                const size_t e = s.find("*/", i + 2);
                if (e == std::string::npos) Fail("unterminated comment");
                i = e + 2;
            } else {
                return;
            }
        }
    }
    std::string String() {
        if (s[i] != '"') Fail("expected a string");
        std::string out;
        for (++i; i < s.size() && s[i] != '"'; ++i) {
            if (s[i] == '\\') ++i;  // the escaped character cannot end the string
            if (i < s.size()) out += s[i];
        }
        if (i >= s.size()) Fail("unterminated string");
        ++i;
        return out;
    }
    /// Skips one value of any type.
    void Value() {
        SkipSpace();
        if (i >= s.size()) Fail("unexpected end of file");
        if (s[i] == '"') {
            String();
        } else if (s[i] == '{' || s[i] == '[') {
            const char close = s[i] == '{' ? '}' : ']';
            ++i;
            SkipSpace();
            if (i < s.size() && s[i] == close) {
                ++i;
                return;
            }
            for (;;) {
                SkipSpace();
                if (close == '}') {
                    String();
                    SkipSpace();
                    if (i >= s.size() || s[i] != ':') Fail("expected ':'");
                    ++i;
                }
                Value();
                SkipSpace();
                if (i < s.size() && s[i] == ',') {
                    ++i;
                } else if (i < s.size() && s[i] == close) {
                    ++i;
                    return;
                } else {
                    Fail(std::string("expected ',' or '") + close + "'");
                }
            }
        } else {
            // number, true, false, null
            while (i < s.size() && !std::isspace(static_cast<unsigned char>(s[i])) && s[i] != ',' &&
                   s[i] != '}' && s[i] != ']' && s.compare(i, 2, "//") != 0 &&
                   s.compare(i, 2, "/*") != 0)
                ++i;
        }
    }
};

std::string Vec(glm::vec3 v) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "[%.6g, %.6g, %.6g]", v.x, v.y, v.z);
    return buf;
}

}  // namespace

std::string ReplaceSceneCamera(const std::string& text, glm::vec3 position, glm::vec3 lookAt,
                               glm::vec3 up, float fovDegrees, const std::string& where) {
    Scanner sc{text, 0, where};
    sc.SkipSpace();
    if (sc.i >= text.size() || text[sc.i] != '{') sc.Fail("expected a JSON object");
    const size_t open = sc.i;
    ++sc.i;
    size_t valueBegin = std::string::npos, valueEnd = std::string::npos;
    sc.SkipSpace();
    if (text[sc.i] != '}') {
        for (;;) {
            sc.SkipSpace();
            const std::string key = sc.String();
            sc.SkipSpace();
            if (sc.i >= text.size() || text[sc.i] != ':') sc.Fail("expected ':'");
            ++sc.i;
            sc.SkipSpace();
            const size_t begin = sc.i;
            sc.Value();
            if (key == "camera") valueBegin = begin, valueEnd = sc.i;
            sc.SkipSpace();
            if (sc.i < text.size() && text[sc.i] == ',') {
                ++sc.i;
                continue;
            }
            if (sc.i < text.size() && text[sc.i] == '}') break;
            sc.Fail("expected ',' or '}'");
        }
    }

    // The camera's keys other than the pose stay, in their order; the pose keys come first.
    std::string extra;
    if (valueBegin != std::string::npos) {
        nlohmann::ordered_json old;
        try {
            old = nlohmann::ordered_json::parse(text.substr(valueBegin, valueEnd - valueBegin),
                                                nullptr, true, /*ignore_comments=*/true);
        } catch (const nlohmann::json::exception& e) {
            throw InputError(where, std::string("key 'camera': ") + e.what());
        }
        if (!old.is_object()) throw InputError(where, "key 'camera': expected an object");
        for (const auto& [k, v] : old.items()) {
            if (k == "position" || k == "look_at" || k == "up" || k == "fov" || k == "keyframes")
                continue;
            extra += ", \"" + k + "\": " + v.dump();
        }
    }
    char fov[32];
    std::snprintf(fov, sizeof fov, "%.6g", fovDegrees);
    const std::string camera = "{\"position\": " + Vec(position) + ", \"look_at\": " + Vec(lookAt) +
                               ", \"up\": " + Vec(up) + ", \"fov\": " + fov + extra + "}";
    if (valueBegin != std::string::npos)
        return text.substr(0, valueBegin) + camera + text.substr(valueEnd);
    // No camera yet: insert it as the first key.
    const bool empty = text.find_first_not_of(" \t\r\n", open + 1) == sc.i;
    return text.substr(0, open + 1) + "\n  \"camera\": " + camera + (empty ? "\n" : ",") +
           text.substr(open + 1);
}

void SaveCameraToSceneFile(const std::string& path, glm::vec3 position, glm::vec3 lookAt,
                           glm::vec3 up, float fovDegrees) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path, "cannot read scene file");
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string updated =
        ReplaceSceneCamera(ss.str(), position, lookAt, up, fovDegrees, path);

    // The temporary file sits beside the scene so relative mesh paths resolve when it is checked,
    // and so the rename stays within one file system (atomic).
    const std::string tmp = path + ".tmp-" + std::to_string(::getpid()) + ".json";
    std::error_code ec;
    {
        std::ofstream f(tmp, std::ios::binary);
        if (!f || !(f << updated) || !f.flush()) {
            fs::remove(tmp, ec);
            throw InputError(path, "cannot write scene file");
        }
    }
    try {
        std::vector<std::string> warnings;
        LoadScene(tmp, &warnings);
    } catch (...) {
        fs::remove(tmp, ec);
        throw;
    }
    // Keep the original's permissions (the temporary file got the umask's).
    fs::permissions(tmp, fs::status(path, ec).permissions(), ec);
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        throw InputError(path, "cannot replace scene file: " + ec.message());
    }
}

}  // namespace texcache::preview
