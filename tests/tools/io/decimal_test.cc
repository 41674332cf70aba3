#include "tools/io/decimal.h"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

// parse_double must be std::from_chars: the same end, error and bits (signed zeros and NaN
// payloads included), on the whole text and on every prefix of it.
void expect_same(const std::string& text) {
  for (std::size_t n = 0; n <= text.size(); ++n) {
    const char* first = text.data();
    double mine = 12345.0, theirs = 12345.0;  // an untouched value must stay untouched
    const std::from_chars_result a = parse_double(first, first + n, mine);
    const std::from_chars_result b = std::from_chars(first, first + n, theirs);
    ASSERT_EQ(a.ptr, b.ptr) << "'" << text.substr(0, n) << "'";
    ASSERT_EQ(a.ec, b.ec) << "'" << text.substr(0, n) << "'";
    ASSERT_EQ(std::bit_cast<std::uint64_t>(mine), std::bit_cast<std::uint64_t>(theirs))
        << "'" << text.substr(0, n) << "'";
  }
}

TEST(ParseDouble, EdgeCasesAreThoseOfFromChars) {
  for (const char* text : {"",
                           "-",
                           "+1",
                           ".5",
                           "-.5",
                           "5.",
                           "-5.",
                           "0",
                           "-0",
                           "0.0",
                           "-0.000000",
                           "00012.50",
                           "9007199254740992",
                           "9007199254740993",
                           "-9007199254740993",
                           "900719925474099.3",
                           "0.9007199254740993",
                           "18446744073709551616",
                           "99999999999999999999999",
                           "1e5",
                           "1E5",
                           "1.5e-3",
                           "1.5x",
                           "1..5",
                           "1.5.5",
                           "--1",
                           "- 1",
                           " 1",
                           "1 ",
                           "inf",
                           "-inf",
                           "nan",
                           "-nan",
                           "infinity",
                           "0x1p3",
                           "1.0000000000000000000001",
                           "0.0000000000000000000001",
                           "0.00000000000000000000001",
                           "1e400",
                           "1e-400",
                           "4.9406564584124654e-324",
                           "2.2250738585072014e-308",
                           "1.7976931348623157e308",
                           "0.1",
                           "0.2",
                           "0.3",
                           "123.456789",
                           "-26.701542",
                           "0.000584179692",
                           "1.5,2",
                           "-3 ,",
                           "0.25\t",
                           "7\r",
                           "8\n",
                           "1.5;",
                           "2.5e",
                           "2.5e+",
                           "2.5E-1,",
                           "12a",
                           "0.5.",
                           "1,e5"}) {
    expect_same(text);
  }
}

// Plain decimals of every length the fast path takes and just beyond: 1-20 integer digits
// (leading zeros too), 0-25 fraction digits, either sign.
TEST(ParseDouble, RandomPlainDecimalsAreThoseOfFromChars) {
  std::mt19937_64 random(11);
  std::uniform_int_distribution<int> integer_digits(1, 20), fraction_digits(0, 25), digit(0, 9);
  std::uniform_int_distribution<int> coin(0, 3);
  for (int i = 0; i < 200000; ++i) {
    std::string text = coin(random) == 0 ? "-" : "";
    const int a = integer_digits(random), b = fraction_digits(random);
    for (int k = 0; k < a; ++k) text.push_back(static_cast<char>('0' + digit(random)));
    if (b > 0) {
      text.push_back('.');
      for (int k = 0; k < b; ++k) text.push_back(static_cast<char>('0' + digit(random)));
    }
    expect_same(text);
  }
}

// The forms the project writes: printf's fixed decimals and shortest round trips of doubles
// over many magnitudes.
TEST(ParseDouble, WrittenNumbersAreThoseOfFromChars) {
  std::mt19937_64 random(12);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-30, 30), decimals(0, 17);
  char buf[64];
  for (int i = 0; i < 100000; ++i) {
    const double v = mantissa(random) * std::pow(10.0, exponent(random));
    std::snprintf(buf, sizeof(buf), "%.*f", decimals(random), v);
    expect_same(buf);
    const auto r = std::to_chars(buf, buf + sizeof(buf), v);
    expect_same(std::string(buf, r.ptr));
  }
}

}  // namespace
}  // namespace fastslam::tools
