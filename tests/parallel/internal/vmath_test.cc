// Tests of parallel/internal/vmath.h: accuracy of log, sin, cos and atan2 against long-double
// libm over wide ranges (including large angles and arguments next to multiples of pi/2), and
// bit equality of the vectorised and the scalar forms (a loop the compiler vectorises against
// calls through a function it cannot inline).
#include "parallel/internal/vmath.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::parallel::internal {
namespace {

constexpr double kUlp1 = 0x1p-52;  // ulp(1)

#if defined(__SANITIZE_ADDRESS__) || !defined(NDEBUG)
constexpr std::size_t kDraws = std::size_t{1} << 16;
#else
constexpr std::size_t kDraws = std::size_t{1} << 18;
#endif

long double ref_sin(double x) { return std::sin(static_cast<long double>(x)); }
long double ref_cos(double x) { return std::cos(static_cast<long double>(x)); }

// Largest |sincos(x) - reference| over xs, in units of 2^-53.
struct SinCosError {
  double sin = 0.0;
  double cos = 0.0;
};
SinCosError sincos_error(const std::vector<double>& xs) {
  SinCosError e;
  for (double x : xs) {
    double c = 0.0;
    double s = 0.0;
    sincos(x, c, s);
    e.sin = std::max(e.sin, static_cast<double>(std::fabs(s - ref_sin(x))) / 0x1p-53);
    e.cos = std::max(e.cos, static_cast<double>(std::fabs(c - ref_cos(x))) / 0x1p-53);
  }
  return e;
}

std::vector<double> uniform_draws(double lo, double hi, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<double> xs(kDraws);
  for (double& x : xs) x = u(rng);
  return xs;
}

// Absolute error bound asserted for sin and cos, in units of 2^-53 (so 2^-52): the reduction
// (two roundings of r) and the kernel's final rounding. Measured on 4e6 draws: 1.17 for
// |x| <= 1000, 1.43 for |x| <= 2^20.
constexpr double kSinCosBound = 2.0;

TEST(VmathSinCos, AccurateOnSmallAndModerateAngles) {
  for (const double range : {0.8, 4.0, 50.0, 1000.0}) {
    const SinCosError e = sincos_error(uniform_draws(-range, range, 7));
    EXPECT_LE(e.sin, kSinCosBound) << "range " << range;
    EXPECT_LE(e.cos, kSinCosBound) << "range " << range;
  }
}

TEST(VmathSinCos, AccurateUpToTheDomainLimit) {
  const SinCosError e = sincos_error(uniform_draws(-kSinCosMaxArg, kSinCosMaxArg, 11));
  EXPECT_LE(e.sin, kSinCosBound);
  EXPECT_LE(e.cos, kSinCosBound);
  EXPECT_TRUE(sincos_in_domain(kSinCosMaxArg));
  EXPECT_TRUE(sincos_in_domain(-kSinCosMaxArg));
  EXPECT_FALSE(sincos_in_domain(std::nextafter(kSinCosMaxArg, 1e300)));
  EXPECT_FALSE(sincos_in_domain(std::numeric_limits<double>::quiet_NaN()));
  EXPECT_FALSE(sincos_in_domain(std::numeric_limits<double>::infinity()));
}

// Arguments next to multiples of pi/2, where the reduced argument is tiny and any reduction
// error would be relative error of the result: the doubles nearest k pi/2 and their neighbours.
TEST(VmathSinCos, AccurateNextToMultiplesOfHalfPi) {
  std::vector<double> xs;
  for (std::int64_t k = -2000; k <= 2000; ++k) {
    for (const std::int64_t scale : {std::int64_t{1}, std::int64_t{509}}) {
      const double x = static_cast<double>(static_cast<long double>(k * scale) *
                                           1.570796326794896619231321691639751442L);
      if (!sincos_in_domain(x)) continue;
      xs.push_back(x);
      xs.push_back(std::nextafter(x, 1e300));
      xs.push_back(std::nextafter(x, -1e300));
    }
  }
  const SinCosError e = sincos_error(xs);
  EXPECT_LE(e.sin, kSinCosBound);
  EXPECT_LE(e.cos, kSinCosBound);
}

// sincos_small is sincos without the reduction: the same bits over its whole domain, which the
// accuracy tests above cover (uniform draws, tiny and signed-zero arguments, the bounds).
TEST(VmathSinCos, SmallGivesTheBitsOfSincos) {
  std::vector<double> xs = uniform_draws(-kSinCosSmallArg, kSinCosSmallArg, 13);
  for (const double x : {0.0, -0.0, 1e-300, -1e-300, 1e-8, 0.5, kSinCosSmallArg,
                         -kSinCosSmallArg, std::nextafter(kSinCosSmallArg, 0.0)}) {
    xs.push_back(x);
  }
  std::size_t differing = 0;
  for (const double x : xs) {
    double c = 0.0, s = 0.0, c_small = 0.0, s_small = 0.0;
    sincos(x, c, s);
    sincos_small(x, c_small, s_small);
    if (std::memcmp(&c, &c_small, sizeof c) != 0 || std::memcmp(&s, &s_small, sizeof s) != 0) {
      ++differing;
    }
  }
  EXPECT_EQ(differing, 0u) << "of " << xs.size();
  EXPECT_LT(kSinCosSmallArg, std::numbers::pi / 4);
}

TEST(VmathSinCos, ExactValuesAndSigns) {
  double c = 0.0;
  double s = 0.0;
  sincos(0.0, c, s);
  EXPECT_EQ(c, 1.0);
  EXPECT_EQ(s, 0.0);
  sincos(1e-300, c, s);
  EXPECT_EQ(c, 1.0);
  EXPECT_EQ(s, 1e-300);
  for (const double x : {0.5, 2.0, 3.0, 100.0, 12345.678}) {
    double c_neg = 0.0;
    double s_neg = 0.0;
    sincos(x, c, s);
    sincos(-x, c_neg, s_neg);
    EXPECT_EQ(c, c_neg) << x;  // even and odd up to the reduction's ties, exact here
    EXPECT_EQ(s, -s_neg) << x;
  }
}

TEST(VmathTurns, AccurateOverEveryOctant) {
  std::mt19937_64 rng(3);
  double worst = 0.0;
  const long double two_pi = 6.283185307179586476925286766559005768L;
  for (std::size_t i = 0; i < kDraws; ++i) {
    const auto turns = static_cast<double>(rng() >> 11);
    double c = 0.0;
    double s = 0.0;
    sincos_turns(turns, c, s);
    const long double angle = two_pi * static_cast<long double>(turns) * 0x1p-53L;
    worst = std::max({worst, static_cast<double>(std::fabs(c - std::cos(angle))),
                      static_cast<double>(std::fabs(s - std::sin(angle)))});
  }
  // Two roundings per multiply-add (a target without fma, or a portable build) cost a little:
  // 1.56 measured over these draws.
  EXPECT_LE(worst / 0x1p-53, kMaddFuses ? 1.5 : 2.0);
  std::cout << "sincos_turns: worst " << worst / 0x1p-53 << " * 2^-53"
            << (kMaddFuses ? " (fused madd)\n" : " (unfused madd)\n");
}

TEST(VmathLog, WithinOneUlpOverManyBinades) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> exponent(-1000.0, 1000.0);
  double worst_ulps = 0.0;
  for (std::size_t i = 0; i < kDraws; ++i) {
    const double x = std::exp2(exponent(rng));
    const long double ref = std::log(static_cast<long double>(x));
    const double ulp =
        std::fabs(std::nextafter(static_cast<double>(ref), 1e300) - static_cast<double>(ref));
    worst_ulps = std::max(worst_ulps, static_cast<double>(std::fabs(log_positive(x) - ref)) / ulp);
  }
  EXPECT_LE(worst_ulps, 1.0);
  EXPECT_EQ(log_positive(1.0), 0.0);
}

// Error of arctan2(y, x) in ulps of the long-double reference (the ulp of the rounded result).
double atan2_ulps(double y, double x) {
  const long double ref = std::atan2(static_cast<long double>(y), static_cast<long double>(x));
  const double rounded = std::fabs(static_cast<double>(ref));
  const double ulp = std::nextafter(rounded, 1e300) - rounded;
  return static_cast<double>(std::fabs(arctan2(y, x) - ref)) / ulp;
}

// Every octant and both signs of each argument, ratios from 2^-60 to 2^60 (the three
// reduction intervals and the breakpoints between them), and points on the breakpoints.
TEST(VmathAtan2, WithinTwoUlpsOverTheFullRange) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> exponent(-30.0, 30.0);
  double worst = 0.0;
  for (std::size_t i = 0; i < kDraws; ++i) {
    const double y = unit(rng) * std::exp2(exponent(rng));
    const double x = unit(rng) * std::exp2(exponent(rng));
    worst = std::max(worst, atan2_ulps(y, x));
    worst = std::max(worst, atan2_ulps(unit(rng), unit(rng)));
  }
  for (const double ratio : {0.66, 2.41421356237309504880, 1.0, 0.4142135623730950488}) {
    for (const double sy : {1.0, -1.0}) {
      for (const double sx : {1.0, -1.0}) {
        for (const double t : {ratio, std::nextafter(ratio, 0.0), std::nextafter(ratio, 9.0)}) {
          worst = std::max(worst, atan2_ulps(sy * t, sx));
          worst = std::max(worst, atan2_ulps(sy * 3.7, sx * 3.7 / t));
        }
      }
    }
  }
  EXPECT_LE(worst, 2.0);
  std::cout << "arctan2: worst " << worst << " ulp\n";
}

// Axes, signed zeros and the quadrant boundaries as std::atan2 gives them (finite arguments).
TEST(VmathAtan2, AxesSignedZerosAndWrapAgreeWithStd) {
  const double values[] = {0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300, 3.5};
  for (const double y : values) {
    for (const double x : values) {
      const double want = std::atan2(y, x);
      const double got = arctan2(y, x);
      EXPECT_EQ(std::signbit(got), std::signbit(want)) << y << ", " << x;
      EXPECT_NEAR(got, want, 2.0 * kUlp1 * std::max(1.0, std::fabs(want))) << y << ", " << x;
    }
  }
  EXPECT_EQ(arctan2(0.0, -1.0), std::atan2(0.0, -1.0));  // +pi, never beyond
  EXPECT_EQ(arctan2(-0.0, -1.0), std::atan2(-0.0, -1.0));
  EXPECT_LE(arctan2(1e-300, -1.0), std::numbers::pi);
  EXPECT_GE(arctan2(-1e-300, -1.0), -std::numbers::pi);
}

// The scalar forms, through a function the compiler may not inline into a vectorised loop.
[[gnu::noinline]] void scalar_all(double x, double out[5]) {
  sincos(x, out[0], out[1]);
  out[2] = log_positive(std::fabs(x) + 1e-3);
  double c = 0.0;
  double s = 0.0;
  sincos_turns(std::fabs(std::floor(x * 1e9)), c, s);
  out[3] = c + s;
  out[4] = arctan2(x, x * 0.37 - 900.0);
}

TEST(Vmath, VectorisedLoopsGiveTheScalarBits) {
  const std::vector<double> xs = uniform_draws(-3000.0, 3000.0, 13);
  std::vector<double> c(xs.size()), s(xs.size()), lg(xs.size()), tr(xs.size()), at(xs.size());
  for (std::size_t i = 0; i < xs.size(); ++i) {  // vectorised at -O3
    sincos(xs[i], c[i], s[i]);
    lg[i] = log_positive(std::fabs(xs[i]) + 1e-3);
    double tc = 0.0;
    double ts = 0.0;
    sincos_turns(std::fabs(std::floor(xs[i] * 1e9)), tc, ts);
    tr[i] = tc + ts;
    at[i] = arctan2(xs[i], xs[i] * 0.37 - 900.0);
  }
  for (std::size_t i = 0; i < xs.size(); ++i) {
    double ref[5];
    scalar_all(xs[i], ref);
    const double got[5] = {c[i], s[i], lg[i], tr[i], at[i]};
    ASSERT_EQ(std::memcmp(got, ref, sizeof(got)), 0) << "x = " << xs[i];
  }
}

}  // namespace
}  // namespace fastslam::parallel::internal
