#include "tools/io/decimal.h"

#include <cstddef>
#include <cstdint>

namespace fastslam::tools {
namespace {

// 10^0 .. 10^22: the powers of ten a double holds exactly.
constexpr double kExactPowers[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                   1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                   1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
constexpr std::uint64_t kMaxExactInteger = std::uint64_t{1} << 53;

// Appends the digits from p on to `digits` (wrapping past 19 of them; the caller then does not
// use it) and returns where they stop.
const char* take_digits(const char* p, const char* last, std::uint64_t& digits) noexcept {
  for (; p != last && static_cast<unsigned char>(*p - '0') < 10; ++p) {
    digits = digits * 10 + static_cast<unsigned char>(*p - '0');
  }
  return p;
}

}  // namespace

std::from_chars_result parse_double(const char* first, const char* last, double& value) noexcept {
  const char* p = first;
  const bool negative = p != last && *p == '-';
  if (negative) ++p;
  // At most 19 digits accumulate without overflow; 2^53 is checked once at the end.
  std::uint64_t digits = 0;
  const char* const integer_begin = p;
  p = take_digits(p, last, digits);
  std::ptrdiff_t count = p - integer_begin;
  std::ptrdiff_t fraction = 0;
  if (count > 0 && p != last && *p == '.') {
    const char* const fraction_begin = ++p;
    p = take_digits(p, last, digits);
    fraction = p - fraction_begin;
    count += fraction;
    if (fraction == 0) count = 0;  // "5.": from_chars decides
  }
  // The plain form must end the text or stop at a character that cannot continue a number
  // (a field's separator or padding); a prefix of something longer ("1e5", "1.5x") is
  // from_chars's to read.
  const bool ends = p == last || *p == ',' || *p == ' ' || *p == '\t' || *p == '\r' || *p == '\n';
  if (ends && count > 0 && count <= 19 && fraction <= 22 && digits <= kMaxExactInteger) {
    const double magnitude = static_cast<double>(digits) / kExactPowers[fraction];
    value = negative ? -magnitude : magnitude;
    return {p, std::errc()};
  }
  return std::from_chars(first, last, value);
}

}  // namespace fastslam::tools
