// SPDX-License-Identifier: Apache-2.0
#include "texcache/ptex/info.h"

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "texcache/error.h"

namespace texcache::ptex {

Info Summarize(const Texture& tex) {
    Info info;
    info.path = tex.Path();
    info.fileBytes = tex.FileBytes();
    info.header = tex.GetHeader();
    info.levels = tex.FileLevels();
    info.meta = tex.MetaData();
    info.decodedBytes = tex.Bytes();
    const int nchan = tex.NumChannels();
    info.faces.resize(size_t(tex.NumFaces()));
    for (int f = 0; f < tex.NumFaces(); ++f) {
        FaceSummary& s = info.faces[size_t(f)];
        s.info = tex.Face(f);
        s.numLevels = tex.NumLevels(f);
        s.constValue.resize(size_t(nchan));
        tex.ConstValue(f, s.constValue.data());
        s.mean.resize(size_t(nchan));
        tex.Mean(f, 0, s.mean.data());
    }
    return info;
}

namespace {

nlohmann::json Numbers(const std::vector<float>& v) {
    nlohmann::json a = nlohmann::json::array();
    for (const float x : v) a.push_back(std::isfinite(x) ? nlohmann::json(x) : nlohmann::json());
    return a;
}

nlohmann::json MetaValue(const MetaEntry& m) {
    if (m.type == MetaType::String) return m.text;
    nlohmann::json a = nlohmann::json::array();
    for (const double x : m.numbers)
        a.push_back(std::isfinite(x) ? nlohmann::json(x) : nlohmann::json());
    return a;
}

}  // namespace

std::string ToJson(const Info& info, int indent) {
    using nlohmann::json;
    const Header& h = info.header;
    json j;
    j["file"] = info.path;
    j["bytes"] = info.fileBytes;
    j["decoded_bytes"] = info.decodedBytes;
    j["header"] = {{"version", h.version},          {"minor_version", h.minorVersion},
                   {"mesh_type", Name(h.meshType)}, {"data_type", Name(h.dataType)},
                   {"channels", h.numChannels},     {"alpha_channel", h.alphaChannel},
                   {"levels", h.numLevels},         {"faces", h.numFaces}};
    j["border"] = {{"u", Name(h.uBorder)}, {"v", Name(h.vBorder)}};
    j["edge_filter"] = Name(h.edgeFilter);
    j["levels"] = json::array();
    for (const FileLevel& l : info.levels)
        j["levels"].push_back({{"faces", l.numFaces}, {"bytes", l.bytes}});
    j["meta"] = json::array();
    for (const MetaEntry& m : info.meta)
        j["meta"].push_back({{"key", m.key}, {"type", Name(m.type)}, {"value", MetaValue(m)}});
    j["faces"] = json::array();
    for (size_t f = 0; f < info.faces.size(); ++f) {
        const FaceSummary& s = info.faces[f];
        const FaceInfo& fi = s.info;
        j["faces"].push_back({{"id", f},
                              {"res", {fi.res.ulog2, fi.res.vlog2}},
                              {"size", {fi.res.U(), fi.res.V()}},
                              {"constant", fi.constant},
                              {"subface", fi.subface},
                              {"edited", fi.hasEdits},
                              {"levels", s.numLevels},
                              {"adjfaces", fi.adjFaces},
                              {"adjedges", fi.adjEdges},
                              {"mean", Numbers(s.mean)},
                              {"const", Numbers(s.constValue)}});
    }
    return j.dump(indent, ' ', false, json::error_handler_t::replace);
}

std::string ToText(const Info& info, bool perFace) {
    const Header& h = info.header;
    std::string out;
    char line[512];
    auto add = [&](const char* fmt, auto... args) {
        std::snprintf(line, sizeof line, fmt, args...);
        out += line;
    };
    add("file:          %s (%llu bytes)\n", info.path.c_str(),
        static_cast<unsigned long long>(info.fileBytes));
    add("format:        Ptex %d.%d\n", h.version, h.minorVersion);
    add("mesh type:     %s\n", Name(h.meshType));
    add("data type:     %s\n", Name(h.dataType));
    add("channels:      %d (alpha: %d)\n", h.numChannels, h.alphaChannel);
    add("faces:         %d\n", h.numFaces);
    add("border modes:  u %s, v %s\n", Name(h.uBorder), Name(h.vBorder));
    add("edge filter:   %s\n", Name(h.edgeFilter));
    add("levels:        %d\n", h.numLevels);
    for (size_t k = 0; k < info.levels.size(); ++k)
        add("  level %zu: %d faces, %llu bytes\n", k, info.levels[k].numFaces,
            static_cast<unsigned long long>(info.levels[k].bytes));
    add("meta data:     %zu entries\n", info.meta.size());
    for (const MetaEntry& m : info.meta) {
        std::string value;
        if (m.type == MetaType::String) {
            value = "\"" + Excerpt(m.text) + "\"";
        } else {
            for (size_t i = 0; i < m.numbers.size() && i < 8; ++i) {
                std::snprintf(line, sizeof line, "%s%g", i ? " " : "", m.numbers[i]);
                value += line;
            }
            if (m.numbers.size() > 8) value += " ... (" + std::to_string(m.numbers.size()) + ")";
        }
        add("  %s (%s): %s\n", Excerpt(m.key).c_str(), Name(m.type), value.c_str());
    }
    if (!perFace) return out;
    for (size_t f = 0; f < info.faces.size(); ++f) {
        const FaceSummary& s = info.faces[f];
        const FaceInfo& fi = s.info;
        add("face %zu: %dx%d%s%s%s, %d levels, adj faces %d %d %d %d, edges %d %d %d %d, mean", f,
            fi.res.U(), fi.res.V(), fi.constant ? " constant" : "", fi.subface ? " subface" : "",
            fi.hasEdits ? " edited" : "", s.numLevels, fi.adjFaces[0], fi.adjFaces[1],
            fi.adjFaces[2], fi.adjFaces[3], fi.adjEdges[0], fi.adjEdges[1], fi.adjEdges[2],
            fi.adjEdges[3]);
        for (const float x : s.mean) add(" %.4g", double(x));
        out += "\n";
    }
    return out;
}

FloatImage FaceImage(const Texture& tex, int face, int level) {
    if (face < 0 || face >= tex.NumFaces())
        throw InputError(tex.Path(), "face " + std::to_string(face) + ": the file has " +
                                         std::to_string(tex.NumFaces()) + " faces");
    if (level < 0 || level >= tex.NumLevels(face))
        throw InputError(tex.Path(), "face " + std::to_string(face) + " has levels 0 to " +
                                         std::to_string(tex.NumLevels(face) - 1) + ", not " +
                                         std::to_string(level));
    const Res res = tex.LevelRes(face, level);
    // An image is for looking at: 2^28 values (1 GB of floats) is more than any face needs.
    if (double(res.U()) * double(res.V()) * double(tex.NumChannels()) > double(1 << 28))
        throw InputError(tex.Path(), "face " + std::to_string(face) + " level " +
                                         std::to_string(level) + " (" + std::to_string(res.U()) +
                                         " x " + std::to_string(res.V()) +
                                         " texels) is too large for an image");
    FloatImage img;
    img.width = res.U();
    img.height = res.V();
    img.channels = tex.NumChannels();
    img.pixels.resize(size_t(img.width) * size_t(img.height) * size_t(img.channels));
    for (int t = 0; t < img.height; ++t)
        for (int s = 0; s < img.width; ++s)
            tex.Texel(
                face, level, s, t,
                &img.pixels[(size_t(t) * size_t(img.width) + size_t(s)) * size_t(img.channels)]);
    return img;
}

}  // namespace texcache::ptex
