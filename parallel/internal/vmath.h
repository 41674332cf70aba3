// Vectorisable log, sin, cos and atan2 for the batch kernels (random_kernels.cc,
// engine/motion_batch.h, engine/landmark_batch.cc); not API. Plain inline IEEE-754 arithmetic
// with every multiply-add an explicit `madd`, so loops over lanes vectorise and scalar and
// vector forms give the same bits; results never depend on the C library, only on whether
// `madd` fuses (where the target has a fast fma, unless FASTSLAM_VMATH_NO_FMA).
// Error bounds (asserted by tests/parallel/internal/vmath_test.cc):
//   log_positive(x)   positive normal x: 1 ulp.
//   sincos_turns(t)   cos and sin of 2 pi t 2^-53, integer t in [0, 2^53): 1.5 * 2^-53
//                     absolute where madd fuses, 2 * 2^-53 where it does not; exact quadrant.
//   sincos(x)         |x| <= kSinCosMaxArg = 2^20: 2^-52 absolute; beyond, finite but
//                     meaningless (callers test sincos_in_domain and fall back to libm).
//   sincos_small(x)   |x| <= kSinCosSmallArg: the bits of sincos(x), without range reduction.
//   arctan2(y, x)     finite y, x (signed zeros as std::atan2): 2 ulp.
// Why not libm, and the measured errors: docs/parallel.md.
// Thread safety: pure functions. Costs: O(1), no allocation; log divides once.
#pragma once

#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace fastslam::parallel::internal {

// a * b + c: one fma (one rounding) where the target has a fast one, else a multiply and an add.
// FASTSLAM_VMATH_NO_FMA keeps the two roundings on every target: a portable build defines it,
// with -ffp-contract=off, for the random-stream kernels it compiles once per instruction set
// (parallel/CMakeLists.txt), so that the AVX-512 copy, whose instruction set has fma, gives the
// bits of the baseline one, which has none.
#if defined(FP_FAST_FMA) && !defined(FASTSLAM_VMATH_NO_FMA)
inline constexpr bool kMaddFuses = true;
[[gnu::always_inline]] inline double madd(double a, double b, double c) noexcept {
  return std::fma(a, b, c);
}
#else
inline constexpr bool kMaddFuses = false;
[[gnu::always_inline]] inline double madd(double a, double b, double c) noexcept {
  return a * b + c;
}
#endif

// Natural log of a positive normal double; error within 1 ulp (tested).
// Reduction from musl's log (x = 2^k m, m in [sqrt(2)/2, sqrt(2))); polynomial from fdlibm's
// e_log.c (Sun Microsystems, 1993): log(m) = 2 atanh(s), s = f / (2 + f), f = m - 1.
[[gnu::always_inline]] inline double log_positive(double x) noexcept {
  constexpr double kLn2Hi = 6.93147180369123816490e-01;  // k * kLn2Hi is exact for |k| < 2^11
  constexpr double kLn2Lo = 1.90821492927058770002e-10;
  constexpr double kLg1 = 6.666666666666735130e-01;
  constexpr double kLg2 = 3.999999999940941908e-01;
  constexpr double kLg3 = 2.857142874366239149e-01;
  constexpr double kLg4 = 2.222219843214978396e-01;
  constexpr double kLg5 = 1.818357216161805012e-01;
  constexpr double kLg6 = 1.531383769920937332e-01;
  constexpr double kLg7 = 1.479819860511658591e-01;
  constexpr std::uint64_t kOff = 0x3FE6A09E667F3BCDu;  // bits of sqrt(2) / 2
  const auto bits = std::bit_cast<std::uint64_t>(x);
  const std::uint64_t tmp = bits - kOff;
  const double m = std::bit_cast<double>(bits - (tmp & 0xFFF0000000000000u));
  // k = the top 12 bits of tmp as a signed number, and dk = k exactly, with logical shifts and
  // integer adds only: AVX2 has neither a 64-bit arithmetic shift nor an int64 -> double
  // conversion, and without them GCC does not vectorise a loop that calls this. The sign
  // extension is (u ^ 2^11) - 2^11; adding k to the bits of 1.5 * 2^52 adds it to the integer
  // that double holds (|k| < 2^11), so the subtraction gives k exactly.
  constexpr std::uint64_t kMagicBits = 0x4338000000000000u;  // bits of 0x1.8p52
  const std::uint64_t u = tmp >> 52;
  const std::uint64_t k = (u ^ 0x800u) - 0x800u;  // two's complement of the signed 12-bit k
  const double dk = std::bit_cast<double>(kMagicBits + k) - 0x1.8p52;
  const double f = m - 1.0;  // exact (Sterbenz)
  const double s = f / (2.0 + f);
  const double z = s * s;
  const double w = z * z;
  const double odd = z * madd(w, madd(w, madd(w, kLg7, kLg5), kLg3), kLg1);
  const double r = madd(w, madd(w, madd(w, kLg6, kLg4), kLg2), odd);
  const double hf = 0.5 * f;                                  // f * f / 2 = hf * f
  const double inner = madd(s, madd(hf, f, r), dk * kLn2Lo);  // s (f^2/2 + R) + k ln2_lo
  const double tail = madd(hf, f, -inner);                    // f^2/2 - inner
  return madd(dk, kLn2Hi, f - tail);
}

namespace vmath_detail {

// Taylor coefficients on [-pi/4, pi/4], highest order first: kSinPoly[i] = (-1)^m / (2m + 1)!
// for m = 8 - i (a^17 down to a^3), kCosPoly[i] = (-1)^m / (2m)! for m = 8 - i (a^16 down to
// a^2). The first omitted terms are below 1e-19, far under an ulp.
constexpr double inverse_factorial(int n) {
  double f = 1.0;
  for (int i = 2; i <= n; ++i) f *= i;  // exact up to 18!
  return 1.0 / f;
}
constexpr std::array<double, 8> taylor(int first_odd_or_even) {
  std::array<double, 8> c{};
  for (int i = 0; i < 8; ++i) {
    const int m = 8 - i;
    c[i] = (m % 2 == 0 ? 1.0 : -1.0) * inverse_factorial(2 * m + first_odd_or_even);
  }
  return c;
}
inline constexpr std::array<double, 8> kSinPoly = taylor(1);
inline constexpr std::array<double, 8> kCosPoly = taylor(0);

// cos and sin of quadrant * pi/2 + a from sin a and cos a: a swap for odd quadrants and sign
// flips, done on the bits (masks, xor of the sign bit) rather than with conditional
// expressions, which GCC may turn into branches around the polynomial that only one side uses
// (then a loop no longer if-converts without AVX-512's masked operations).
[[gnu::always_inline]] inline void apply_quadrant(double sin_a, double cos_a,
                                                  std::uint64_t quadrant, double& cos_out,
                                                  double& sin_out) noexcept {
  const std::uint64_t swap = std::uint64_t{0} - (quadrant & 1u);  // all ones in odd quadrants
  const auto sin_bits = std::bit_cast<std::uint64_t>(sin_a);
  const auto cos_bits = std::bit_cast<std::uint64_t>(cos_a);
  const std::uint64_t c = (sin_bits & swap) | (cos_bits & ~swap);
  const std::uint64_t s = (cos_bits & swap) | (sin_bits & ~swap);
  cos_out = std::bit_cast<double>(c ^ (((quadrant + 1) & 2u) << 62));  // negative in 1, 2
  sin_out = std::bit_cast<double>(s ^ ((quadrant & 2u) << 62));        // negative in 2, 3
}

// cos and sin of quadrant * pi/2 + a for a in [-pi/4, pi/4] (slightly beyond is fine).
[[gnu::always_inline]] inline void sincos_quadrant(double a, std::uint64_t quadrant,
                                                   double& cos_out, double& sin_out) noexcept {
  const double z = a * a;
  double sin_poly = kSinPoly[0];
  double cos_poly = kCosPoly[0];
#pragma GCC unroll 8
  for (std::size_t i = 1; i < kSinPoly.size(); ++i) {
    sin_poly = madd(z, sin_poly, kSinPoly[i]);
    cos_poly = madd(z, cos_poly, kCosPoly[i]);
  }
  const double sin_a = madd(a * z, sin_poly, a);
  const double cos_a = madd(z, cos_poly, 1.0);
  apply_quadrant(sin_a, cos_a, quadrant, cos_out, sin_out);
}

}  // namespace vmath_detail

// cos(2 pi t) and sin(2 pi t) for t = turns * 2^-53, turns an integer in [0, 2^53); absolute
// error within 1.5 * 2^-53, or 2 * 2^-53 where madd does not fuse (tested). The quadrant comes
// from rounding 4t, which is exact, so there is no argument-reduction error.
[[gnu::always_inline]] inline void sincos_turns(double turns, double& cos_out,
                                                double& sin_out) noexcept {
  constexpr double kShift = 0x1.8p52;  // adding it rounds [0, 2^51) to an integer
  constexpr double kHalfPi = 1.57079632679489661923;
  const double shifted = madd(turns, 0x1p-51, kShift);  // kShift + round(4t), ties to even
  const auto quadrant = std::bit_cast<std::uint64_t>(shifted) & 3u;
  const double r = madd(turns, 0x1p-51, -(shifted - kShift));  // 4t - round(4t), exact
  vmath_detail::sincos_quadrant(r * kHalfPi, quadrant, cos_out, sin_out);
}

// The domain of `sincos`: |x| <= kSinCosMaxArg.
inline constexpr double kSinCosMaxArg = 0x1p20;

// True when sincos(x) is accurate (|x| <= kSinCosMaxArg; false for NaN and infinities).
[[gnu::always_inline]] inline bool sincos_in_domain(double x) noexcept {
  return std::fabs(x) <= kSinCosMaxArg;
}

namespace vmath_detail {

// fdlibm's minimax kernels (k_sin.c, k_cos.c; Sun Microsystems, 1993) on [-pi/4, pi/4]: sin a =
// a + a^3 (S1 + ... + S6 a^10), cos a = 1 - a^2/2 + a^4 (C1 + ... + C6 a^10), each within 2^-58
// of the function; two fewer terms than the Taylor series above, for the same accuracy.
inline constexpr std::array<double, 6> kSinMinimax = {
    1.58969099521155010221e-10,  -2.50507602534068634195e-08, 2.75573137070700676789e-06,
    -1.98412698298579493134e-04, 8.33333333332248946124e-03,  -1.66666666666666324348e-01};
inline constexpr std::array<double, 6> kCosMinimax = {
    -1.13596475577881948265e-11, 2.08757232129817482790e-09,  -2.75573143513906633035e-07,
    2.48015872894767294178e-05,  -1.38888888888741095749e-03, 4.16666666666666019037e-02};

[[gnu::always_inline]] inline void sincos_quadrant_minimax(double a, std::uint64_t quadrant,
                                                           double& cos_out,
                                                           double& sin_out) noexcept {
  const double z = a * a;
  double sin_poly = kSinMinimax[0];
  double cos_poly = kCosMinimax[0];
#pragma GCC unroll 8
  for (std::size_t i = 1; i < kSinMinimax.size(); ++i) {
    sin_poly = madd(z, sin_poly, kSinMinimax[i]);
    cos_poly = madd(z, cos_poly, kCosMinimax[i]);
  }
  const double sin_a = madd(a * z, sin_poly, a);
  const double cos_a = madd(z, madd(z, cos_poly, -0.5), 1.0);
  apply_quadrant(sin_a, cos_a, quadrant, cos_out, sin_out);
}

}  // namespace vmath_detail

// cos(x) and sin(x) for |x| <= kSinCosMaxArg (see the file comment for the bound; outside the
// domain the results are meaningless but finite for finite x).
// Reduction x = n pi/2 + r, n = round(x 2/pi) < 2^20, with pi/2 split into three 33-bit parts
// (fdlibm's pio2_1, pio2_2, pio2_3): n * part is exact, x - n * pio2_1 is exact (Sterbenz), the
// two later subtractions round once each; the neglected tail is below 2^20 * 8.5e-32.
[[gnu::always_inline]] inline void sincos(double x, double& cos_out, double& sin_out) noexcept {
  constexpr double kTwoOverPi = 6.36619772367581382433e-01;
  constexpr double kShift = 0x1.8p52;  // adding it rounds |v| < 2^51 to an integer
  constexpr double kPio2_1 = 1.57079632673412561417e+00;
  constexpr double kPio2_2 = 6.07710050630396597660e-11;
  constexpr double kPio2_3 = 2.02226624871116645580e-21;
  const double shifted = madd(x, kTwoOverPi, kShift);  // kShift + round(x 2/pi), ties to even
  const double n = shifted - kShift;
  const auto quadrant = std::bit_cast<std::uint64_t>(shifted) & 3u;  // n mod 4 (two's complement)
  double r = madd(-n, kPio2_1, x);
  r = madd(-n, kPio2_2, r);
  r = madd(-n, kPio2_3, r);
  vmath_detail::sincos_quadrant_minimax(r, quadrant, cos_out, sin_out);
}

// The domain of `sincos_small`: |x| <= kSinCosSmallArg (< pi/4, so round(x 2/pi) = 0).
inline constexpr double kSinCosSmallArg = 0.78125;

// cos(x) and sin(x) for |x| <= kSinCosSmallArg (callers test the bound): the bits of sincos(x),
// whose reduction is the identity there (n = 0, r = x, quadrant 0), without its cost. For
// small angles such as a steering angle.
[[gnu::always_inline]] inline void sincos_small(double x, double& cos_out,
                                                double& sin_out) noexcept {
  vmath_detail::sincos_quadrant_minimax(x, 0, cos_out, sin_out);
}

// c ? a : b on the bits: GCC 12 if-converts this where it may branch on a conditional
// expression (and then not vectorise the loop).
[[gnu::always_inline]] inline double select(bool c, double a, double b) noexcept {
  const std::uint64_t mask = std::uint64_t{0} - static_cast<std::uint64_t>(c);
  return std::bit_cast<double>((std::bit_cast<std::uint64_t>(a) & mask) |
                               (std::bit_cast<std::uint64_t>(b) & ~mask));
}

// arctan2(y, x) = atan2(y, x) in [-pi, pi] for finite y and x (bound in the file comment).
// Cephes' atan (S. Moshier): the ratio t = |y| / |x| reduced to |u| <= 0.66 by
// u = t (t <= 0.66), (t - 1) / (t + 1) (+ pi/4), or -1 / t (+ pi/2, t > tan(3 pi/8)), each form
// one division of |y| and |x| combined; atan u = u + u^3 P(u^2) / Q(u^2), a 4/5 rational of
// relative error 2.6e-18 on that interval. Then pi - atan for x < 0 and the sign of y. Every
// branch is a select, so loops over lanes vectorise.
[[gnu::always_inline]] inline double arctan2(double y, double x) noexcept {
  constexpr double kP0 = -8.750608600031904122785e-1;
  constexpr double kP1 = -1.615753718733365076637e1;
  constexpr double kP2 = -7.500855792314704667340e1;
  constexpr double kP3 = -1.228866684490136173410e2;
  constexpr double kP4 = -6.485021904942025371773e1;
  constexpr double kQ0 = 2.485846490142306297962e1;
  constexpr double kQ1 = 1.650270098316988542046e2;
  constexpr double kQ2 = 4.328810604912902668951e2;
  constexpr double kQ3 = 4.853903996359136964868e2;
  constexpr double kQ4 = 1.945506571482613964425e2;
  constexpr double kTan3PiOver8 = 2.41421356237309504880;
  constexpr double kHalfPi = 1.57079632679489661923;         // pi/2 rounded down
  constexpr double kQuarterPi = 7.85398163397448309616e-1;   // pi/4 rounded down
  constexpr double kHalfPiLo = 6.123233995736765886130e-17;  // pi/2 - kHalfPi
  constexpr double kPi = 3.14159265358979323846;             // pi rounded down
  constexpr double kPiLo = 1.2246467991473531772e-16;        // pi - kPi
  // |y| and |x| scaled by a power of two (exact) so that the breakpoint products below are not
  // subnormal and a + b does not overflow.
  const double ay = std::fabs(y);
  const double ax = std::fabs(x);
  const double scale = select((ay > 0x1p1000) | (ax > 0x1p1000), 0x1p-200,
                              select((ay < 0x1p-900) & (ax < 0x1p-900), 0x1p200, 1.0));
  const double a = ay * scale;
  const double b = ax * scale;
  // Whether t = a / b exceeds the breakpoints, decided without dividing.
  const bool big = a > kTan3PiOver8 * b;
  const bool mid = a > 0.66 * b;
  const double num = select(big, -b, select(mid, a - b, a));
  const double den_raw = select(big, a, select(mid, a + b, b));
  const double den = select(den_raw == 0.0, 1.0, den_raw);  // y = x = 0: u = 0
  const double base = select(big, kHalfPi, select(mid, kQuarterPi, 0.0));
  const double tail = select(big, kHalfPiLo, select(mid, 0.5 * kHalfPiLo, 0.0));
  const double u = num / den;
  const double z = u * u;
  const double p = madd(madd(madd(madd(kP0, z, kP1), z, kP2), z, kP3), z, kP4);
  const double q = madd(madd(madd(madd(z + kQ0, z, kQ1), z, kQ2), z, kQ3), z, kQ4);
  const double zp = z * p;
  const double atan_u = madd(u, zp / q, u);
  const double atan_t = base + (atan_u + tail);  // in [0, pi/2]
  const double flipped = (kPi - atan_t) + kPiLo;
  // Sign tests and the sign transfer on the bits: std::signbit and std::copysign stop GCC 12
  // from vectorising the loop.
  constexpr std::uint64_t kSign = std::uint64_t{1} << 63;
  const std::uint64_t x_negative = std::uint64_t{0} - (std::bit_cast<std::uint64_t>(x) >> 63);
  const std::uint64_t magnitude = (std::bit_cast<std::uint64_t>(flipped) & x_negative) |
                                  (std::bit_cast<std::uint64_t>(atan_t) & ~x_negative);
  return std::bit_cast<double>(magnitude | (std::bit_cast<std::uint64_t>(y) & kSign));
}

}  // namespace fastslam::parallel::internal
