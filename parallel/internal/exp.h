// exp(x) for x <= 0, from IEEE-754 +, *, and explicit fma only. Not API.
//
// Why not std::exp: the weights' exponentials are the hot loop of resampling and statistics
// (one per particle per step). glibc's exp is an opaque call (about 5 ns here) that does not
// vectorise, and its bits may differ between C library versions and CPU dispatch paths. This
// one vectorises (about 1 ns per value with AVX2), gives the same bits on every machine with
// IEEE-754 doubles and a correct std::fma, and, because every multiply-add is written as an
// explicit fma, the same bits in every caller whatever the compiler's -ffp-contract choices.
//
// Method: Cody-Waite reduction x = n ln2 + r, |r| <= ln2 / 2, then the Taylor polynomial of
// degree 13 for e^r by Horner (truncation error below 5e-18 relative), then scaling by 2^n
// built in the exponent bits. Accuracy: within 2 ulp of e^x for x in [-708, 0] (tested against
// long double). Inputs below -708 (and -inf) give exactly 0: relative weights under ~3e-308 are
// zero (never subnormal, so the scaling stays exact).
// Thread safety: a pure function. Costs: O(1), no allocation, no branches.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>

namespace fastslam::parallel::internal {

// REQUIRES: x <= 0, or x == -inf (NaN gives an unspecified value).
inline double exp_nonpositive(double x) noexcept {
  constexpr double kLog2e = 1.4426950408889634074;
  constexpr double kShift = 0x1.8p52;                    // adding it rounds to an integer
  constexpr double kLn2Hi = 6.93147180369123816490e-01;  // 0x3fe62e42fee00000
  constexpr double kLn2Lo = 1.90821492927058770002e-10;  // ln 2 - kLn2Hi
  constexpr double kMin = -708.0;
  const double xc = x < kMin ? kMin : x;
  const double t = std::fma(xc, kLog2e, kShift);
  const double n = t - kShift;  // round(x / ln 2), in [-1022, 0]
  double r = std::fma(-n, kLn2Hi, xc);
  r = std::fma(-n, kLn2Lo, r);
  double p = 1.0 / 6227020800.0;  // 1 / 13!
  p = std::fma(p, r, 1.0 / 479001600.0);
  p = std::fma(p, r, 1.0 / 39916800.0);
  p = std::fma(p, r, 1.0 / 3628800.0);
  p = std::fma(p, r, 1.0 / 362880.0);
  p = std::fma(p, r, 1.0 / 40320.0);
  p = std::fma(p, r, 1.0 / 5040.0);
  p = std::fma(p, r, 1.0 / 720.0);
  p = std::fma(p, r, 1.0 / 120.0);
  p = std::fma(p, r, 1.0 / 24.0);
  p = std::fma(p, r, 1.0 / 6.0);
  p = std::fma(p, r, 0.5);
  p = std::fma(p, r, 1.0);
  p = std::fma(p, r, 1.0);
  // 2^n from the integer in t's low mantissa bits.
  const std::int64_t ni = std::bit_cast<std::int64_t>(t) - std::bit_cast<std::int64_t>(kShift);
  const double scale = std::bit_cast<double>(static_cast<std::uint64_t>(ni + 1023) << 52);
  return x < kMin ? 0.0 : p * scale;
}

}  // namespace fastslam::parallel::internal
