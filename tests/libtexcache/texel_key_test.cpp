// SPDX-License-Identifier: Apache-2.0
// Texel addressing (texel_key.h): keys pack and unpack at their limits, eq. 1's mip level from a
// hit's ray differentials and eq. 2's quantization of (u, v) to a texel.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "texcache/texel_key.h"

namespace texcache {
namespace {

TEST(TexelKey, PackUnpackRoundTripsAtTheLimits) {
    for (TexelKey k : {TexelKey{0, 0, 0, 0}, TexelKey{TexelKey::kMaxFaces - 1, 15, 16383, 16383},
                       TexelKey{12345, 7, 100, 9000}}) {
        const TexelKey back = TexelKey::Unpack(k.Pack());
        EXPECT_EQ(back.face, k.face);
        EXPECT_EQ(back.mip, k.mip);
        EXPECT_EQ(back.iu, k.iu);
        EXPECT_EQ(back.iv, k.iv);
        EXPECT_NE(k.Pack(), TexelKey::kEmpty);
    }
}

// ComputeMip's exponent from the float's bits is std::ilogb's for every positive finite float
// kind: subnormal, normal, each power of two and its neighbours, the largest.
TEST(Addressing, FloatExponentMatchesIlogb) {
    for (float x = std::numeric_limits<float>::denorm_min(); std::isfinite(x);
         x = std::max(x * 1.37f, std::nextafter(x, INFINITY)))  // subnormals round x * 1.37 to x
        for (float y : {x, std::nextafter(x, 0.0f), std::nextafter(x, INFINITY)})
            if (y > 0.0f && std::isfinite(y)) {
                ASSERT_EQ(FloatExponent(y), std::ilogb(y)) << y;
            }
    for (int p = -149; p <= 127; ++p) {
        const float x = std::ldexp(1.0f, p);
        ASSERT_EQ(FloatExponent(x), p);
        if (p > -149) {
            ASSERT_EQ(FloatExponent(std::nextafter(x, 0.0f)), p - 1);
        }
    }
    EXPECT_EQ(FloatExponent(std::numeric_limits<float>::max()), 127);
}

TEST(Addressing, MipFromDifferentialsFollowsEquation1) {
    // 256-texel face; a pixel covering 1/64 of the face in x and 1/16 in y: min(4, 16) -> log2 4
    // = 2.
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 16, 0.0f), 2);
    // Grazing: huge footprint along y, small along x: eq. 1 takes the min (higher resolution).
    EXPECT_EQ(ComputeMip(8, 1.0f / 256, 0.0f, 0.0f, 50.0f, 0.0f), 0);
    // Tiny footprint: finest level; huge footprint: coarsest level (1x1).
    EXPECT_EQ(ComputeMip(8, 1e-9f, 0.0f, 0.0f, 1e-9f, 0.0f), 0);
    EXPECT_EQ(ComputeMip(8, 1e9f, 0.0f, 0.0f, 1e9f, 0.0f), 8);
    EXPECT_EQ(ComputeMip(8, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f), 0);
    EXPECT_EQ(ComputeMip(8, INFINITY, 0.0f, 0.0f, INFINITY, 0.0f), 8);
    EXPECT_EQ(ComputeMip(8, NAN, 0.0f, 0.0f, 1.0f, 0.0f), 0);
    // Floored (towards higher resolution): log2(3.9) = 1.96 -> 1.
    EXPECT_EQ(ComputeMip(8, 3.9f / 256, 0.0f, 0.0f, 3.9f / 256, 0.0f), 1);
    // LOD bias shifts, and a bias beyond the chain clamps to it.
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 64, 1.0f), 3);
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 64, 100.0f), 8);
    EXPECT_EQ(ComputeMip(8, 1.0f / 64, 0.0f, 0.0f, 1.0f / 64, -100.0f), 0);
    EXPECT_EQ(ComputeMip(0, 1.0f, 0.0f, 0.0f, 1.0f, 0.0f), 0);
}

TEST(Addressing, QuantizationFollowsEquation2AndIsRobust) {
    EXPECT_EQ(QuantizeCoord(0.0f, 16), 0);
    EXPECT_EQ(QuantizeCoord(-4e-10f, 16), 0);  // Embree's slightly negative u
    EXPECT_EQ(QuantizeCoord(1.0f, 16), 15);
    EXPECT_EQ(QuantizeCoord(1.00001f, 16), 15);
    EXPECT_EQ(QuantizeCoord(0.5f, 16), 8);
    EXPECT_EQ(QuantizeCoord(NAN, 16), 0);
    EXPECT_EQ(QuantizeCoord(1e30f, 16), 15);
    EXPECT_FLOAT_EQ(TexelCenter(8, 16), 8.5f / 16.0f);
}

}  // namespace
}  // namespace texcache
