#include "tools/io/number_text.h"

#include <charconv>

namespace fastslam::tools {
namespace {

// "%.*f" of the largest finite double is 309 digits, a sign, a point and the decimals.
constexpr int kMaxPrecision = 40;
constexpr std::size_t kBuffer = 320 + kMaxPrecision;

int clamp(int precision) { return precision < 0 ? 0 : precision > kMaxPrecision ? kMaxPrecision : precision; }

}  // namespace

TextLine& TextLine::fixed(double v, int precision) {
  char buf[kBuffer];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::fixed, clamp(precision));
  line_.append(buf, r.ptr);
  return *this;
}

TextLine& TextLine::general(double v, int precision) {
  char buf[kBuffer];
  const auto r =
      std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, clamp(precision));
  line_.append(buf, r.ptr);
  return *this;
}

TextLine& TextLine::integer(std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  line_.append(buf, r.ptr);
  return *this;
}

}  // namespace fastslam::tools
