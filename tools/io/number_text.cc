#include "tools/io/number_text.h"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>

namespace fastslam::tools {
namespace {

// "%.*f" of the largest finite double is 309 digits, a sign, a point and the decimals.
constexpr int kMaxPrecision = 40;
constexpr std::size_t kBuffer = 320 + kMaxPrecision;

int clamp(int precision) {
  return precision < 0 ? 0 : precision > kMaxPrecision ? kMaxPrecision : precision;
}

constexpr std::uint64_t kPowersOfTen[] = {1,      10,      100,      1000,      10000,
                                          100000, 1000000, 10000000, 100000000, 1000000000};
constexpr int kFastPrecision = 9;

// "00" to "99": two digits per division halves the chain of dependent divisions.
constexpr char kPairs[] =
    "00010203040506070809101112131415161718192021222324252627282930313233343536373839"
    "40414243444546474849505152535455565758596061626364656667686970717273747576777879"
    "8081828384858687888990919293949596979899";

// Writes the decimal digits of `v` backwards from `end` (lowest first at end[-1]); returns how
// many (at least one).
int digits_backwards(char* end, std::uint64_t v) {
  char* p = end;
  while (v >= 100) {
    const std::uint64_t pair = v % 100;
    v /= 100;
    *--p = kPairs[2 * pair + 1];
    *--p = kPairs[2 * pair];
  }
  if (v >= 10) {
    *--p = kPairs[2 * v + 1];
    *--p = kPairs[2 * v];
  } else {
    *--p = static_cast<char>('0' + v);
  }
  return static_cast<int>(end - p);
}

__extension__ typedef unsigned __int128 Uint128;  // GCC's and Clang's, outside ISO C++

constexpr double kScales[] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9};  // exact

// |v| 10^p rounded half to even, v = m 2^e with an integer m < 2^53 and e <= 0 (|v| < 2^53):
// v 10^p = m 10^p 2^e, where m 10^p < 2^83 fits 128 bits, and the shift by -e rounds on the
// exact remainder, as printf rounds the exact binary value.
Uint128 exact_scaled(std::uint64_t m, int e, int precision) {
  const Uint128 n = static_cast<Uint128>(m) * kPowersOfTen[precision];
  const int s = -e;
  if (s == 0) return n;
  if (s >= 128) return 0;  // below 2^83 / 2^128: rounds to zero
  const Uint128 q = n >> s;
  const Uint128 rem = n - (q << s);
  const Uint128 half = static_cast<Uint128>(1) << (s - 1);
  return q + ((rem > half || (rem == half && (q & 1) != 0)) ? 1 : 0);
}

// "%.*f" of a finite `v` with |v| < 2^53 and precision <= 9, exactly as printf. Returns the end
// of the text.
char* fixed_exact(char* out, double v, int precision) {
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(v);
  const bool negative = (bits >> 63) != 0;
  // Fast path: y = fl(|v| 10^p) lies within half an ulp (<= y 2^-53) of the exact product, so
  // when y is further than an ulp from the nearest tie, the exact product rounds to y's nearest
  // integer. Ties and near-ties take the exact path.
  const double y = std::fabs(v) * kScales[precision];
  const double nearest = std::nearbyint(y);
  Uint128 n;
  if (y < 0x1p52 && 0.5 - std::fabs(y - nearest) > y * 0x1p-51) {
    n = static_cast<std::uint64_t>(nearest);
  } else {
    const int biased = static_cast<int>((bits >> 52) & 0x7ff);
    const std::uint64_t fraction = bits & ((std::uint64_t{1} << 52) - 1);
    n = biased == 0 ? exact_scaled(fraction, -1074, precision)  // subnormal (or zero)
                    : exact_scaled(fraction | (std::uint64_t{1} << 52), biased - 1075, precision);
  }
  // n < 2^83 < 10^25: at most 25 digits; below 2^64 (|v| < 1.8e13 at 6 decimals) one word.
  char buf[48];
  char* const end = buf + sizeof(buf);
  int count;
  if ((n >> 64) == 0) {
    count = digits_backwards(end, static_cast<std::uint64_t>(n));
  } else {
    constexpr std::uint64_t k19 = 10000000000000000000ull;
    const int low = digits_backwards(end, static_cast<std::uint64_t>(n % k19));
    std::memset(end - 19, '0', static_cast<std::size_t>(19 - low));
    count = 19 + digits_backwards(end - 19, static_cast<std::uint64_t>(n / k19));
  }
  if (count <= precision) {  // at least one digit before the point
    std::memset(end - precision - 1, '0', static_cast<std::size_t>(precision + 1 - count));
    count = precision + 1;
  }
  if (negative) *out++ = '-';
  const int whole = count - precision;
  std::memcpy(out, end - count, static_cast<std::size_t>(whole));
  out += whole;
  if (precision > 0) {
    *out++ = '.';
    std::memcpy(out, end - precision, static_cast<std::size_t>(precision));
    out += precision;
  }
  return out;
}

}  // namespace

TextLine& TextLine::fixed(double v, int precision) {
  precision = clamp(precision);
  char buf[kBuffer];
  if (precision <= kFastPrecision && std::fabs(v) < 0x1p53) {  // false for NaN
    // (pointer, length): append's iterator-pair form goes through the general replace().
    line_.append(buf, static_cast<std::size_t>(fixed_exact(buf, v, precision) - buf));
    return *this;
  }
  const auto r = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::fixed, precision);
  line_.append(buf, static_cast<std::size_t>(r.ptr - buf));
  return *this;
}

TextLine& TextLine::general(double v, int precision) {
  char buf[kBuffer];
  const auto r =
      std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, clamp(precision));
  line_.append(buf, static_cast<std::size_t>(r.ptr - buf));
  return *this;
}

TextLine& TextLine::integer(std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  line_.append(buf, static_cast<std::size_t>(r.ptr - buf));
  return *this;
}

}  // namespace fastslam::tools
