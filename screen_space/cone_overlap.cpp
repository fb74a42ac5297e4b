// SPDX-License-Identifier: Apache-2.0
#include "screen_space/cone_overlap.h"

#include <algorithm>
#include <cmath>

namespace texcache::screen {

double ConeOverlap(double angle) {
    const double t = std::acos(double(kConeCosHalfAngle));
    const double ct = std::cos(t);
    const double a = std::abs(angle);
    if (a < 1e-9) return 2.0 * 3.14159265358979323846 * (1.0 - ct);
    if (a >= 2.0 * t) return 0.0;
    const double gamma = std::atan((ct - std::cos(a) * ct) / (std::sin(a) * ct));
    const double beta = std::acos(std::clamp(std::sin(gamma) / std::sin(t), -1.0, 1.0));
    const double phi = std::acos(std::clamp(std::tan(gamma) / std::tan(t), -1.0, 1.0));
    return std::max(0.0, 4.0 * (beta - phi * ct));
}

ConeOverlapTable::ConeOverlapTable() {
    for (int i = 0; i < kEntries; ++i) {
        const double sh = double(i) / double(kEntries - 1) * double(kMaxS);
        table_[size_t(i)] = float(ConeOverlap(2.0 * std::asin(sh)));
    }
    // Any normal gives the same relative angles; use +z.
    const auto axes = ConeAxes(glm::vec3(0.0f, 0.0f, 1.0f));
    for (int k = 0; k < kNumCones; ++k) {
        rowSum_[k] = 0.0f;
        for (int j = 0; j < kNumCones; ++j) {
            const double c =
                std::clamp(double(glm::dot(axes[size_t(k)], axes[size_t(j)])), -1.0, 1.0);
            same_[k][j] = float(ConeOverlap(k == j ? 0.0 : std::acos(c)));
            rowSum_[k] += same_[k][j];
        }
    }
}

}  // namespace texcache::screen
