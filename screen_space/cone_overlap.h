// SPDX-License-Identifier: Apache-2.0
// Overlap solid angles of the 6 radiance cones (Zeng et al. 2021, Sec. 4.3 and 5, eqs. 9-10,
// after Mazonka 2012). Two cones of equal half angle t whose axes are `a` apart overlap in
//     Omega(a) = 4 (beta - phi cos t),  gamma = atan((cos t - cos a cos t) / (sin a cos t)),
//     beta = acos(sin gamma / sin t),   phi = acos(tan gamma / tan t),
// and not at all when a >= 2t. The paper writes t = pi/6, which does not give the cones the
// solid angle pi/3 it states; we use the half angle of the cone layout in frame_buffers.h,
// acos(5/6) (solid angle exactly pi/3).
//
// The weight of history / neighbour cone j for cone k is Omega(angle(axis_k, axis'_j)). Within
// one pixel the axes' relative angles do not depend on the normal, so that 6x6 table is fixed
// (SameFrame()); between two pixels with different normals it is looked up in a 1D table over
// the axes' angle (Overlap(cos angle)).
#pragma once
#include <algorithm>
#include <array>
#include <cmath>

#include "screen_space/frame_buffers.h"

namespace texcache::screen {

/// Mazonka's overlap solid angle of two cones of half angle acos(5/6) whose axes are `angle`
/// radians apart (exact formula, for tables and tests).
double ConeOverlap(double angle);

/// Overlap weights of the cone layout.
class ConeOverlapTable {
public:
    static constexpr int kEntries = 1024;
    /// The table runs over s = sin(angle / 2) in [0, kMaxS]: Omega is smooth (linear at 0) in s,
    /// not in cos(angle), and 0 beyond s = sin(half angle) = 0.553.
    static constexpr float kMaxS = 0.6f;

    ConeOverlapTable();
    /// Omega between two axes with cosine `c` (linear interpolation in the 1D table).
    float Overlap(float c) const {
        const float s = std::sqrt(std::max(0.0f, 0.5f * (1.0f - c)));  // sin(angle / 2)
        const float u = s * (float(kEntries - 1) / kMaxS);
        if (!(u < float(kEntries - 1))) return 0.0f;
        const int i = int(u);
        const float f = u - float(i);
        return table_[size_t(i)] + f * (table_[size_t(i) + 1] - table_[size_t(i)]);
    }
    /// Omega between cone k and cone j of the same frame (the 6x6 table).
    float SameFrame(int k, int j) const { return same_[k][j]; }
    /// Sum over j of SameFrame(k, j): the weight cone k collects from an identical hemisphere.
    float SameFrameRowSum(int k) const { return rowSum_[k]; }

private:
    std::array<float, kEntries> table_;
    float same_[kNumCones][kNumCones];
    float rowSum_[kNumCones];
};

}  // namespace texcache::screen
