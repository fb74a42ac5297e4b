// SPDX-License-Identifier: Apache-2.0
#include "renderer/scene/obj_materials.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "texcache/error.h"

namespace texcache {

namespace fs = std::filesystem;

namespace {

/// The whitespace-separated tokens of a line.
std::vector<std::string_view> Tokens(std::string_view line) {
    std::vector<std::string_view> t;
    size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        const size_t b = i;
        while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        if (i > b) t.push_back(line.substr(b, i - b));
    }
    return t;
}

/// The rest of a line after its keyword, trimmed (names may hold spaces).
std::string_view Rest(std::string_view line, std::string_view keyword) {
    std::string_view r = line.substr(size_t(keyword.data() - line.data()) + keyword.size());
    while (!r.empty() && std::isspace(static_cast<unsigned char>(r.front()))) r.remove_prefix(1);
    while (!r.empty() && std::isspace(static_cast<unsigned char>(r.back()))) r.remove_suffix(1);
    return r;
}

class MtlParser {
public:
    MtlParser(const std::string& name, std::vector<std::string>* warnings)
        : name_(name), warnings_(warnings) {}

    std::vector<MtlMaterial> Parse(std::string_view text) {
        if (text.starts_with("\xEF\xBB\xBF")) text.remove_prefix(3);  // a UTF-8 byte order mark
        std::string_view rest = text;
        while (!rest.empty()) {
            ++line_;
            const size_t eol = std::min(rest.find('\n'), rest.size());
            // Comments run to the end of the line, after a statement too.
            const std::string_view line = rest.substr(0, std::min(eol, rest.find('#')));
            rest.remove_prefix(std::min(eol + 1, rest.size()));
            const std::vector<std::string_view> t = Tokens(line);
            if (!t.empty()) Statement(line, t);
        }
        for (const auto& [kw, at] : skipped_) {
            std::string w = "'" + Excerpt(kw) + "' is not used (" + std::to_string(at.second) +
                            (at.second == 1 ? " line)" : " lines)");
            if (warnings_) warnings_->push_back(name_ + ":" + std::to_string(at.first) + ": " + w);
        }
        return std::move(out_);
    }

private:
    [[noreturn]] void Fail(const std::string& what) const {
        throw InputError(name_ + ":" + std::to_string(line_), what);
    }

    float Number(std::string_view t, float lo, float hi) const {
        std::string_view d = t;
        if (d.size() > 1 && d[0] == '+') d.remove_prefix(1);
        float v = 0.0f;
        const auto r = std::from_chars(d.data(), d.data() + d.size(), v);
        if (r.ec != std::errc() || r.ptr != d.data() + d.size() || !std::isfinite(v))
            Fail("malformed number '" + Excerpt(t) + "'");
        if (v < lo || v > hi)
            Fail("value " + Excerpt(t) + " is out of range [" + std::to_string(lo) + ", " +
                 std::to_string(hi) + "]");
        return v;
    }

    /// `K? r [g b]`: one value is grey.
    glm::vec3 Color(const std::vector<std::string_view>& t) const {
        if (t.size() >= 2 && (t[1] == "spectral" || t[1] == "xyz"))
            Fail("'" + std::string(t[0]) + " " + std::string(t[1]) +
                 "' colours are not supported (give r g b)");
        if (t.size() != 2 && t.size() != 4)
            Fail("'" + std::string(t[0]) + "' needs r g b (or one grey value)");
        const float r = Number(t[1], 0.0f, 1e30f);
        if (t.size() == 2) return glm::vec3(r);
        return {r, Number(t[2], 0.0f, 1e30f), Number(t[3], 0.0f, 1e30f)};
    }

    MtlMaterial& Current(std::string_view kw) {
        if (out_.empty()) Fail("'" + Excerpt(kw) + "' before any 'newmtl'");
        return out_.back();
    }

    void Statement(std::string_view line, const std::vector<std::string_view>& t) {
        const std::string_view kw = t[0];
        if (kw == "newmtl") {
            const std::string_view n = Rest(line, kw);
            if (n.empty()) Fail("'newmtl' without a name");
            out_.push_back({});
            out_.back().name = std::string(n);
            out_.back().line = line_;
        } else if (kw == "Kd") {
            Current(kw).Kd = Color(t);
        } else if (kw == "Ks") {
            Current(kw).Ks = Color(t);
        } else if (kw == "Ke") {
            Current(kw).Ke = Color(t);
        } else if (kw == "Ns") {
            if (t.size() != 2) Fail("'Ns' needs one exponent");
            Current(kw).Ns = Number(t[1], 0.0f, 1e6f);
        } else if (kw == "d" || kw == "Tr") {
            // `d -halo 0.5`: the halo form's factor is still the dissolve.
            if (t.size() < 2 || (t.size() == 3 && t[1] != "-halo") || t.size() > 3)
                Fail("'" + std::string(kw) + "' needs one value in [0, 1]");
            const float v = Number(t.back(), 0.0f, 1.0f);
            Current(kw).d = kw == "d" ? v : 1.0f - v;
        } else if (kw == "map_Kd") {
            // Options (-s, -o, -clamp, ...) precede the file name, which comes last.
            if (t.size() < 2) Fail("'map_Kd' needs a file name");
            if (t.size() > 2 && warnings_)
                warnings_->push_back(name_ + ":" + std::to_string(line_) +
                                     ": map_Kd options are ignored (the texture is used as is)");
            MtlMaterial& m = Current(kw);
            m.mapKd = std::string(t.back());
            m.mapKdLine = line_;
        } else if (kw == "Ka" || kw == "illum" || kw == "Ni") {
            // Ambient colour, the illumination model, the index of refraction: a path tracer's
            // materials have no use for them, and every exporter writes them.
        } else {
            auto it = skipped_.find(std::string(kw));
            if (it == skipped_.end())
                it = skipped_.emplace(std::string(kw), std::pair{line_, 0}).first;
            ++it->second.second;
        }
    }

    std::string name_;
    std::vector<std::string>* warnings_;
    int line_ = 0;
    std::vector<MtlMaterial> out_;
    std::map<std::string, std::pair<int, int>> skipped_;  ///< first line, count
};

/// An MTL file's materials; a missing or unreadable file is a warning and none.
std::vector<MtlMaterial> ReadMtl(const std::string& path, const std::string& where,
                                 std::vector<std::string>* warnings) {
    std::error_code ec;
    std::ifstream f(path, std::ios::binary);
    if (!fs::is_regular_file(path, ec) || !f) {
        if (warnings)
            warnings->push_back(where + ": material library '" + path +
                                "' not found: its materials are the default");
        return {};
    }
    std::stringstream ss;
    ss << f.rdbuf();
    return ParseMtl(ss.str(), path, warnings);
}

}  // namespace

std::vector<MtlMaterial> ParseMtl(std::string_view text, const std::string& name,
                                  std::vector<std::string>* warnings) {
    return MtlParser(name, warnings).Parse(text);
}

Material ToMaterial(const MtlMaterial& mtl, const std::string& mtlPath,
                    std::vector<Texture>* textures, std::vector<std::string>* warnings) {
    Material m;
    m.name = mtl.name;
    m.albedo.value = glm::clamp(mtl.Kd, 0.0f, 1.0f);
    if (!mtl.mapKd.empty()) {
        Texture t;
        fs::path p(mtl.mapKd);
        if (p.is_relative()) p = fs::path(mtlPath).parent_path() / p;
        t.path = fs::absolute(p).lexically_normal().string();
        std::string ext = p.extension().string();
        for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
        t.kind = ext == ".ptx" ? Texture::Kind::Ptex : Texture::Kind::Image;
        t.where = mtlPath + ":" + std::to_string(mtl.mapKdLine) + ": map_Kd";
        std::error_code ec;
        if (!fs::is_regular_file(t.path, ec))
            throw InputError(t.where, "texture file '" + t.path + "' does not exist");
        textures->push_back(t);
        m.albedo.texture = int(textures->size()) - 1;
    }
    // A specular colour makes the GGX layer; its exponent the roughness (Blinn-Phong's exponent
    // n and Beckmann's alpha match as alpha = sqrt(2 / (n + 2)), and GGX's alpha is near
    // Beckmann's for the same highlight; roughness = sqrt(alpha)).
    if (std::max({mtl.Ks.x, mtl.Ks.y, mtl.Ks.z}) > 0.0f) {
        m.type = Material::Type::GGX;
        m.specular.value = glm::clamp(mtl.Ks, 0.0f, 1.0f);
        if (mtl.Ns >= 0.0f) m.roughness.value = std::pow(2.0f / (mtl.Ns + 2.0f), 0.25f);
    }
    m.emission.value = mtl.Ke;
    if (mtl.d < 1.0f && warnings)
        warnings->push_back(mtlPath + ":" + std::to_string(mtl.line) + ": material '" + mtl.name +
                            "': transparency (d/Tr) is not supported: rendered opaque");
    return m;
}

void AssignObjMaterials(const ObjFaceTags& tags, const std::string& objPath,
                        const std::map<std::string, int>& sceneMaterials,
                        const std::function<int()>& fallback, std::map<std::string, int>* loaded,
                        Scene* scene, Object* object, std::vector<std::string>* warnings) {
    // Each library once per scene: its materials keyed by "path\nname".
    std::vector<std::string> libraries;
    for (const ObjFaceTags::Named& lib : tags.libraries) {
        fs::path p(lib.name);
        if (p.is_relative()) p = fs::path(objPath).parent_path() / p;
        const std::string path = fs::absolute(p).lexically_normal().string();
        libraries.push_back(path);
        if (loaded->count(path + "\n")) continue;
        (*loaded)[path + "\n"] = -1;  // read (even if missing: warned once)
        for (const MtlMaterial& mtl :
             ReadMtl(path, objPath + ":" + std::to_string(lib.line), warnings)) {
            const std::string key = path + "\n" + mtl.name;
            if (loaded->count(key)) continue;  // the first definition of a name wins
            scene->materials.push_back(ToMaterial(mtl, path, &scene->textures, warnings));
            (*loaded)[key] = int(scene->materials.size()) - 1;
        }
    }
    std::vector<int> ids(tags.materials.size(), -1);
    for (size_t i = 0; i < tags.materials.size(); ++i) {
        const std::string& name = tags.materials[i].name;
        if (const auto it = sceneMaterials.find(name); it != sceneMaterials.end()) {
            ids[i] = it->second;
            continue;
        }
        for (const std::string& lib : libraries)
            if (const auto it = loaded->find(lib + "\n" + name); it != loaded->end()) {
                ids[i] = it->second;
                break;
            }
        if (ids[i] < 0) {
            ids[i] = fallback();
            if (warnings)
                warnings->push_back(objPath + ":" + std::to_string(tags.materials[i].line) +
                                    ": usemtl '" + Excerpt(name) +
                                    "': no material library of the OBJ (and no scene material) "
                                    "defines it: the default material");
        }
    }
    std::vector<int>& faces = object->faceMaterials;
    faces.resize(tags.faceMaterial.size());
    for (size_t f = 0; f < faces.size(); ++f)
        faces[f] = tags.faceMaterial[f] >= 0 ? ids[size_t(tags.faceMaterial[f])] : -1;
    if (std::find(faces.begin(), faces.end(), -1) != faces.end()) {
        const int d = fallback();
        std::replace(faces.begin(), faces.end(), -1, d);
    }
    object->material = faces.empty() ? fallback() : faces.front();
    if (std::all_of(faces.begin(), faces.end(), [&](int m) { return m == object->material; }))
        faces.clear();
}

}  // namespace texcache
