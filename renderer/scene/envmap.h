// SPDX-License-Identifier: Apache-2.0
// Lat-long environment light with importance sampling.
//
// Convention: world +Y is up. A direction d maps to phi = atan2(d.x, -d.z) + rotation and
// theta = acos(d.y); u = phi / 2pi wrapped to [0,1), v = theta / pi; image row 0 is the top
// (v = 0 looks along +Y). A rotation of r degrees turns the map by the right-handed rotation
// R_y(r): what was seen along d is seen along R_y(r) d.
#pragma once
#include <algorithm>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "renderer/integrators/distribution.h"

namespace texcache {

class EnvironmentMap {
public:
    /// Loads a lat-long image (width == 2 * height); throws InputError otherwise.
    static EnvironmentMap Load(const std::string& path, float intensity, float rotationDegrees);
    /// Load(), once while any caller holds the result, and the last map loaded stays loaded: a
    /// RenderScene is rebuilt for every frame of an animation, and reading a 4k map and building
    /// its distribution each time would be most of `texcache experiment temporal --quick`
    /// (clear_page + Distribution in `perf`). The key includes the file's size and modification
    /// time, so an edited file is read again.
    static std::shared_ptr<const EnvironmentMap> Shared(const std::string& path, float intensity,
                                                        float rotationDegrees);
    /// What Load() repaired in the file (NaN, infinite, negative or too bright texels, with their
    /// counts), for a warning naming the file; empty when nothing.
    const std::string& Repairs() const { return repairs_; }
    /// A uniform environment of the given radiance (white-furnace tests).
    static EnvironmentMap Constant(glm::vec3 radiance);

    /// Radiance arriving from direction `dir` (bilinear in the texels).
    glm::vec3 Eval(glm::vec3 dir) const;
    /// Samples a direction for a surface of shading normal `n` (unit); returns Eval(dir). A map:
    /// proportionally to max(0, luminance) * sin(theta), whatever n. A constant environment:
    /// cosine-weighted about n, since light that arrives alike from everywhere matters in
    /// proportion to the cosine alone (uniform sphere sampling wastes half its samples below the
    /// horizon: car under a white sky, path length 2, `texcache bench peer`).
    glm::vec3 Sample(glm::vec3 n, glm::vec2 u, glm::vec3* dir, float* pdfSolidAngle) const;
    /// Solid-angle density of Sample(n, ...) at `dir`.
    float Pdf(glm::vec3 n, glm::vec3 dir) const;
    /// Eval(dir), and Pdf(n, dir) in `pdf`: a ray that escapes needs both (MIS), and the
    /// direction's lat-long coordinates are found once.
    glm::vec3 EvalPdf(glm::vec3 n, glm::vec3 dir, float* pdf) const;
    /// Mean radiance over the sphere.
    glm::vec3 AverageRadiance() const;

    /// Eval() at lat-long coordinates (from DirToUv): for callers that have them already.
    glm::vec3 EvalUv(glm::vec2 uv) const;
    /// Pdf() of a map (not a constant environment) at lat-long coordinates.
    float PdfUv(glm::vec2 uv) const;
    /// Whether this is a constant environment (no map).
    bool IsConstant() const { return isConstant_; }
    /// Lat-long coordinates of a direction (see the convention at the top) and back.
    glm::vec2 DirToUv(glm::vec3 d) const;
    glm::vec3 UvToDir(glm::vec2 uv) const;

    /// Irradiance onto a surface of unit normal `n` (int L max(0, n.w) dw): pi * radiance for a
    /// constant environment; for a map, from its projection on the 9 real spherical harmonics of
    /// degree <= 2 (Ramamoorthi and Hanrahan 2001: a few % off for natural light, more next to a
    /// small bright source, whose ringing is clamped at 0). Projected on first use (thread-safe).
    glm::vec3 Irradiance(glm::vec3 n) const;

    /// A mip pyramid of the map's luminance, for distributions that need the light averaged over
    /// a solid angle and then refined (product sampling): level 0 is the map, each level a 2x2
    /// box average of the one before (an odd last row or column is left out), down to 2x1 texels
    /// or one row. A constant environment has one 2x1 level. Built on first use (thread-safe),
    /// never for renders that do not ask.
    struct LuminancePyramid {
        struct Level {
            int width, height;
            std::vector<float> texels;
        };
        std::vector<Level> levels;
        /// Every level halves the one below exactly (power-of-two maps): a texel's share of an
        /// ancestor is then its luminance over 4^k times the ancestor's.
        bool exact = true;
        /// Texel (x, y) of level `level` (in range).
        float Texel(int level, int x, int y) const {
            const Level& l = levels[size_t(level)];
            return l.texels[size_t(y) * size_t(l.width) + size_t(x)];
        }
        int NumLevels() const { return int(levels.size()); }
    };
    const LuminancePyramid& Pyramid() const;

private:
    glm::vec3 Texel(int x, int y) const { return glm::vec3(texels_[size_t(y) * width_ + x]); }

    int width_ = 0, height_ = 0;
    /// RGB radiance, and in w the sampling density over (u, v) of the texel (dist_.BinPdf): a
    /// direction's Eval and Pdf (an escaped ray's MIS weight) then read the same cache lines,
    /// where the density from dist_ read two more (its row's and the marginal's CDF), most of
    /// the time out of the caches.
    std::vector<glm::vec4> texels_;
    std::string repairs_;
    glm::vec3 constant_{0.0f};
    bool isConstant_ = true;
    float rotation_ = 0.0f;  // radians
    Distribution2D dist_;
    struct LazyPyramid {
        std::once_flag once;
        LuminancePyramid pyramid;
    };
    std::shared_ptr<LazyPyramid> pyramid_ = std::make_shared<LazyPyramid>();
    struct LazySh {
        std::once_flag once;
        glm::vec3 c[9];  // radiance's SH coefficients L_00, L_1-1, L_10, L_11, L_2-2 .. L_22
    };
    std::shared_ptr<LazySh> sh_ = std::make_shared<LazySh>();
};

}  // namespace texcache
