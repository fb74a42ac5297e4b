// SPDX-License-Identifier: Apache-2.0
// Texel fetches and filtered lookups. The data type is resolved once per call (a template per
// type), so the per-texel conversion has no branch on it.
//
// Across edges: a bilinear tap outside the face is the texel centre's position, carried over the
// edge into the face across it (and over a second edge at corners), then point-sampled there at
// the level nearest in texel size. Carrying a point follows the file's adjacency: the position
// along the shared edge is mirrored (neighbours run the edge the other way), and between a quad
// and the two sub-faces of an n-gon each sub-face covers half the quad's edge, the first one met
// counter-clockwise round the quad being the one the quad names.
#include <algorithm>
#include <cmath>
#include <vector>

#include "texcache/topology.h"  // EdgeToUv, UvToEdge: the same edge frames as the cage's
#include "texture_impl.h"

namespace texcache::ptex {

using namespace internal;

namespace {

/// Where a point outside a face lands: the face, its (u,v) there, the quarter turns from that
/// face's frame to the starting one, and the texel size to sample at (log2 texels per unit).
struct Spot {
    int face;
    float u, v;
    int rot = 0;
    int resLog2;
    bool black = false;
};

int MaxLog2(const FaceInfo& f) {
    return std::max(f.res.ulog2, f.res.vlog2);
}

template <DataType T>
class Filter {
public:
    Filter(const Texture::Impl& im, float* out, int first, int count)
        : im_(im), out_(out), first_(first) {
        const Header& h = im.header;
        alpha_ = h.alphaChannel;
        // Channels past the file's stay 0.
        avail_ = std::clamp(h.numChannels - first, 0, count);
        tanvec_ = h.edgeFilter == EdgeFilterMode::TangentVector && first == 0 && avail_ >= 2;
    }

    /// Adds weight * pixel; `straight` pixels (level 0, constant values) are premultiplied
    /// first, so that all levels blend alike.
    void Add(const uint8_t* p, float w, bool straight, int rot) const {
        const float a = straight && alpha_ >= 0 ? ChannelToFloat(p, alpha_, T) : 1.0f;
        int c = 0;
        if (tanvec_ && rot != 0) {
            float x = ChannelToFloat(p, 0, T), y = ChannelToFloat(p, 1, T);
            x *= alpha_ == 0 ? 1.0f : a;
            y *= alpha_ == 1 ? 1.0f : a;
            for (int r = 0; r < (rot & 3); ++r) {  // a quarter turn counter-clockwise each
                const float t = x;
                x = -y, y = t;
            }
            out_[0] += w * x, out_[1] += w * y;
            c = 2;
        }
        for (; c < avail_; ++c) {
            const int ch = first_ + c;
            float v = ChannelToFloat(p, ch, T);
            if (ch != alpha_) v *= a;
            out_[c] += w * v;
        }
    }

    void Lookup(int face, float u, float v, float width) const {
        const FaceInfo& f = im_.faces[size_t(face)];
        const int nl = im_.NumLevels(face);
        u = Clamp01(u), v = Clamp01(v);
        // Level position: level k sits at k; the constant value (one texel) at the level where
        // the face would be one texel, after the last level there is.
        const int top = MaxLog2(f);
        const float last = float(nl - 1), constPos = std::max(float(top), float(nl));
        float pos = width > 0 ? std::log2(width) + float(top) : 0.0f;
        pos = std::isnan(pos) ? 0.0f : std::clamp(pos, 0.0f, constPos);
        if (pos <= last) {
            const int k = std::min(int(pos), nl - 1);
            const float frac = pos - float(k);
            Level(face, k, u, v, 1.0f - frac);
            if (frac > 0) Level(face, k + 1, u, v, frac);
        } else {
            const float frac = (pos - last) / (constPos - last);
            Level(face, nl - 1, u, v, 1.0f - frac);
            Add(im_.constData.data() + size_t(face) * size_t(im_.pixelSize), frac, true, 0);
        }
    }

private:
    static float Clamp01(float x) { return x >= 0.0f ? (x <= 1.0f ? x : 1.0f) : 0.0f; }

    void Level(int face, int k, float u, float v, float w) const {
        if (w == 0.0f) return;
        if (im_.header.meshType == MeshType::Triangle)
            Triangle(face, k, u, v, w);
        else
            Bilinear(face, k, u, v, w);
    }

    void Bilinear(int face, int k, float u, float v, float w) const {
        const LevelData& l = im_.Level(face, k);
        const int W = l.res.U(), H = l.res.V();
        const float x = u * float(W) - 0.5f, y = v * float(H) - 0.5f;
        const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
        const float fx = x - float(x0), fy = y - float(y0);
        const float wx[2] = {1.0f - fx, fx}, wy[2] = {1.0f - fy, fy};
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                const float tw = w * wx[i] * wy[j];
                if (tw == 0.0f) continue;
                const int s = x0 + i, t = y0 + j;
                if (s >= 0 && s < W && t >= 0 && t < H) {
                    Add(im_.Pixel(l, s, t), tw, l.straight, 0);
                    continue;
                }
                // The tap's texel centre, outside the face.
                const float cu = (float(s) + 0.5f) / float(W), cv = (float(t) + 0.5f) / float(H);
                const int resLog2 = std::max(l.res.ulog2, l.res.vlog2);
                const bool outU = s < 0 || s >= W, outV = t < 0 || t >= H;
                if (outU && outV) {  // a corner: the mean of going round either way
                    Sample(Walk(face, cu, cv, resLog2, true), 0.5f * tw);
                    Sample(Walk(face, cu, cv, resLog2, false), 0.5f * tw);
                } else {
                    Sample(Walk(face, cu, cv, resLog2, outU), tw);
                }
            }
    }

    /// The nearest triangular texel (format.h: the odd ones are stored mirrored).
    void Triangle(int face, int k, float u, float v, float w) const {
        const LevelData& l = im_.Level(face, k);
        const int n = l.res.U();
        if (u + v > 1.0f) {
            const float sum = u + v;
            u /= sum, v /= sum;
        }
        const float s = u * float(n), t = v * float(n);
        int i = std::min(int(s), n - 1), j = std::min(int(t), n - 1);
        if (i + j > n - 1) i = n - 1 - j;
        const bool odd = (s - float(i)) + (t - float(j)) > 1.0f && i + j <= n - 2;
        if (odd)
            Add(im_.Pixel(l, n - 1 - j, n - 1 - i), w, l.straight, 0);
        else
            Add(im_.Pixel(l, i, j), w, l.straight, 0);
    }

    /// Carries a point outside `face` over its edges (u's first when `uFirst`) until it lies in
    /// a face, a border (clamp, black or periodic) or two edges stop it.
    Spot Walk(int face, float u, float v, int resLog2, bool uFirst) const {
        Spot s{face, u, v, 0, resLog2};
        int crossings = 0;
        for (int step = 0; step < 4; ++step) {
            const bool outU = s.u < 0.0f || s.u > 1.0f, outV = s.v < 0.0f || s.v > 1.0f;
            if (!outU && !outV) break;
            const bool acrossU = outU && (uFirst || !outV);
            const int edge = acrossU ? (s.u < 0.0f ? 3 : 1) : (s.v < 0.0f ? 0 : 2);
            const FaceInfo& f = im_.faces[size_t(s.face)];
            if (f.adjFaces[edge] < 0 || crossings == 2) {
                const BorderMode m = f.adjFaces[edge] >= 0 ? BorderMode::Clamp
                                     : acrossU             ? im_.header.uBorder
                                                           : im_.header.vBorder;
                if (m == BorderMode::Black) {
                    s.black = true;
                    return s;
                }
                float& c = acrossU ? s.u : s.v;
                c = m == BorderMode::Periodic ? c - std::floor(c) : Clamp01(c);
                continue;
            }
            Cross(&s, edge);
            ++crossings;
        }
        s.u = Clamp01(s.u), s.v = Clamp01(s.v);
        return s;
    }

    /// Moves a spot over edge `edge` of its face into the face across it.
    void Cross(Spot* s, int edge) const {
        const FaceInfo& f = im_.faces[size_t(s->face)];
        int nf = f.adjFaces[edge], ne = f.adjEdges[edge];
        const FaceInfo& nb = im_.faces[size_t(nf)];
        float along, inward;
        UvToEdge(edge, s->u, s->v, &along, &inward);
        float nAlong = 1.0f - along, nInward = -inward;
        if (!f.subface && nb.subface) {
            // Quad to n-gon: the named sub-face covers the first half of our edge, the one
            // before it round the n-gon the second; their texels are twice as dense.
            nInward = -2.0f * inward;
            s->resLog2 -= 1;
            if (along < 0.5f) {
                nAlong = 1.0f - 2.0f * along;
            } else {
                const int second = nb.adjFaces[(ne + 3) & 3];
                const int e2 = second >= 0 ? EdgeTo(second, s->face) : -1;
                if (e2 >= 0) {
                    nf = second, ne = e2;
                    nAlong = 2.0f - 2.0f * along;
                } else {
                    nAlong = 0.0f;
                }
            }
        } else if (f.subface && !nb.subface) {
            // n-gon to quad: which half of the quad's edge depends on whether the quad names us.
            const bool first = nb.adjFaces[ne] == s->face;
            nAlong = first ? 0.5f * (1.0f - along) : 1.0f - 0.5f * along;
            nInward = -0.5f * inward;
            s->resLog2 += 1;
        }
        s->rot = (s->rot + edge - ne + 6) & 3;
        s->face = nf;
        EdgeToUv(ne, nAlong, nInward, &s->u, &s->v);
    }

    /// The edge of `face` across which lies `other`, or -1.
    int EdgeTo(int face, int other) const {
        const FaceInfo& f = im_.faces[size_t(face)];
        for (int e = 0; e < 4; ++e)
            if (f.adjFaces[e] == other) return e;
        return -1;
    }

    /// Point-samples a spot at the level whose texel size is nearest to its resLog2.
    void Sample(const Spot& s, float w) const {
        if (s.black) return;
        const int nl = im_.NumLevels(s.face);
        const int k = MaxLog2(im_.faces[size_t(s.face)]) - s.resLog2;
        if (k >= nl) {
            Add(im_.constData.data() + size_t(s.face) * size_t(im_.pixelSize), w, true, s.rot);
            return;
        }
        const LevelData& l = im_.Level(s.face, std::max(k, 0));
        const int i = std::min(int(s.u * float(l.res.U())), l.res.U() - 1);
        const int j = std::min(int(s.v * float(l.res.V())), l.res.V() - 1);
        Add(im_.Pixel(l, i, j), w, l.straight, s.rot);
    }

    const Texture::Impl& im_;
    float* out_;
    int first_, alpha_, avail_;
    bool tanvec_;
};

template <DataType T>
void TexelAs(const Texture::Impl& im, const uint8_t* p, float* out) {
    for (int c = 0; c < im.header.numChannels; ++c) out[c] = ChannelToFloat(p, c, T);
}

template <template <DataType> class F, typename... A>
void Dispatch(DataType t, A&&... a) {
    switch (t) {
        case DataType::UInt8:
            return F<DataType::UInt8>::Run(a...);
        case DataType::UInt16:
            return F<DataType::UInt16>::Run(a...);
        case DataType::Half:
            return F<DataType::Half>::Run(a...);
        default:
            return F<DataType::Float>::Run(a...);
    }
}

template <DataType T>
struct ConvertPixel {
    static void Run(const Texture::Impl& im, const uint8_t* p, float* out) {
        TexelAs<T>(im, p, out);
    }
};

template <DataType T>
struct FilterLookup {
    static void Run(const Texture::Impl& im, int face, float u, float v, float width, float* out,
                    int first, int count) {
        Filter<T>(im, out, first, count).Lookup(face, u, v, width);
    }
};

}  // namespace

void Texture::ConstValue(int face, float* out) const {
    const Impl& im = *impl_;
    if (face < 0 || face >= im.header.numFaces) {
        std::fill(out, out + im.header.numChannels, 0.0f);
        return;
    }
    Dispatch<ConvertPixel>(im.header.dataType, im,
                           im.constData.data() + size_t(face) * size_t(im.pixelSize), out);
}

void Texture::Texel(int face, int level, int s, int t, float* out) const {
    const Impl& im = *impl_;
    if (face < 0 || face >= im.header.numFaces) {
        std::fill(out, out + im.header.numChannels, 0.0f);
        return;
    }
    level = std::clamp(level, 0, im.NumLevels(face) - 1);
    const LevelData& l = im.Level(face, level);
    s = std::clamp(s, 0, l.res.U() - 1);
    t = std::clamp(t, 0, l.res.V() - 1);
    Dispatch<ConvertPixel>(im.header.dataType, im, im.Pixel(l, s, t), out);
}

void Texture::Mean(int face, int level, float* out) const {
    const Impl& im = *impl_;
    const int nchan = im.header.numChannels;
    std::fill(out, out + nchan, 0.0f);
    if (face < 0 || face >= im.header.numFaces) return;
    const LevelData& l = im.Level(face, std::clamp(level, 0, im.NumLevels(face) - 1));
    // Tile by tile: a constant tile counts once with its texel count, so a face of huge
    // constant tiles costs no more than its tiles.
    std::vector<double> sum(size_t(nchan), 0.0);
    std::vector<float> px(static_cast<size_t>(nchan));
    const int tw = l.tileRes.U(), th = l.tileRes.V();
    const int ntiles = (l.res.U() / tw) * (l.res.V() / th);
    for (int i = 0; i < ntiles; ++i) {
        const TileRef& tile = im.tiles[l.firstTile + uint32_t(i)];
        const size_t n = tile.constant ? 1 : size_t(tw) * size_t(th);
        const double weight = tile.constant ? double(tw) * double(th) : 1.0;
        for (size_t p = 0; p < n; ++p) {
            Dispatch<ConvertPixel>(im.header.dataType, im,
                                   im.texels.data() + tile.offset + p * size_t(im.pixelSize),
                                   px.data());
            for (int c = 0; c < nchan; ++c) sum[size_t(c)] += weight * double(px[size_t(c)]);
        }
    }
    const double total = double(l.res.U()) * double(l.res.V());
    for (int c = 0; c < nchan; ++c) out[c] = float(sum[size_t(c)] / total);
}

void Texture::Lookup(int face, float u, float v, float width, float* out, int firstChannel,
                     int numChannels) const {
    const Impl& im = *impl_;
    const int count =
        numChannels < 0 ? std::max(0, im.header.numChannels - firstChannel) : numChannels;
    std::fill(out, out + count, 0.0f);
    if (face < 0 || face >= im.header.numFaces || firstChannel < 0) return;
    Dispatch<FilterLookup>(im.header.dataType, im, face, u, v, width, out, firstChannel, count);
}

}  // namespace texcache::ptex
