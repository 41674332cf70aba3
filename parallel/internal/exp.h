// exp(x) for x <= 0, from IEEE-754 +, * and explicit fma only (not API): it vectorises and
// gives the same bits on every machine and C library, whatever -ffp-contract does. Cody-Waite
// reduction, a degree-13 Taylor polynomial, scaling in the exponent bits. Within 2 ulp of e^x
// on [-708, 0]; below -708 (and -inf) exactly 0. Why not std::exp: docs/parallel.md.
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
  // Below kMin the scale is +0, so the product is exactly 0. An integer select, not a select of
  // the product: GCC does not if-convert a conditional floating-point operation
  // (-ftrapping-math), and the loops calling this would not vectorise.
  const std::uint64_t bits = x < kMin ? 0 : static_cast<std::uint64_t>(ni + 1023) << 52;
  return p * std::bit_cast<double>(bits);
}

}  // namespace fastslam::parallel::internal
