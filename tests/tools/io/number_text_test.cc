#include "tools/io/number_text.h"

#include <cmath>
#include <cstdio>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

std::string printf_of(const char* format, int precision, double v) {
  char buf[512];
  std::snprintf(buf, sizeof(buf), format, precision, v);
  return buf;
}

// Values where a formatter goes wrong: signed zeros, ties at the last digit (exact in binary
// and not), the ends of the range, non-finite values.
std::vector<double> edge_values() {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> v = {0.0,     -0.0,    1e-9,    -1e-9,   5e-7,    -5e-7,   2.5e-7,
                           0.5,     1.5,     2.5,     -2.5,    0.125,   0.0625,  1e15 + 0.5,
                           1e21,    1e22,    123456789.0,      9.9999995e-4,     0.0005,
                           1e300,   -1e300,  std::numeric_limits<double>::max(),
                           std::numeric_limits<double>::min(),
                           std::numeric_limits<double>::denorm_min(),
                           inf,     -inf,    std::nan(""),      -std::nan("")};
  for (int k = -12; k <= 12; ++k) v.push_back(std::ldexp(1.0, k) * 3.0);
  return v;
}

TEST(TextLine, FixedAndGeneralAreTheBytesOfPrintf) {
  std::vector<double> values = edge_values();
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> wide(-1000.0, 1000.0);
  for (int i = 0; i < 20000; ++i) {
    values.push_back(wide(random));
    values.push_back(std::round(wide(random) * 1e6) / 1e6 + 5e-7);  // near a tie at 6 digits
    values.push_back(wide(random) * 1e-7);
    values.push_back(std::ldexp(wide(random), static_cast<int>(random() % 200) - 100));
  }
  TextLine line;
  for (const double v : values) {
    for (const int precision : {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 17}) {
      line.clear();
      line.fixed(v, precision);
      ASSERT_EQ(line.view(), printf_of("%.*f", precision, v)) << "precision " << precision;
      line.clear();
      line.general(v, precision);
      ASSERT_EQ(line.view(), printf_of("%.*g", precision, v)) << "precision " << precision;
    }
  }
}

TEST(TextLine, IntegersAndTextAppendInOrder) {
  TextLine line;
  line.integer(0).put(',').integer(std::numeric_limits<std::uint64_t>::max()).text(",x,");
  line.fixed(-1.25, 1).put('\n');
  EXPECT_EQ(line.view(), "0,18446744073709551615,x,-1.2\n");
  line.clear();
  EXPECT_TRUE(line.view().empty());
}

TEST(TextLine, PrecisionIsClampedToTheDocumentedRange) {
  TextLine line;
  line.fixed(std::numeric_limits<double>::max(), 99);
  EXPECT_EQ(line.view(), printf_of("%.*f", 40, std::numeric_limits<double>::max()));
  line.clear();
  line.fixed(2.5, -3);
  EXPECT_EQ(line.view(), "2");
}

}  // namespace
}  // namespace fastslam::tools
