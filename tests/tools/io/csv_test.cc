#include "tools/io/csv.h"

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tools/io/log_format.h"

namespace fastslam::tools {
namespace {

class CsvTest : public ::testing::Test {
 protected:
  std::string write(const std::string& text) {
    path_ = (std::filesystem::temp_directory_path() /
             ("fastslam_csv_test_" + std::to_string(::getpid()) + ".csv"))
                .string();
    std::ofstream(path_) << text;
    return path_;
  }
  void TearDown() override { std::filesystem::remove(path_); }

  // The message of the error reading `text` raises.
  std::string error_of(const std::string& text) {
    const std::string path = write(text);
    try {
      CsvReader reader(path, {"id", "x_m", "y_m"});
      std::array<double, 3> row{};
      while (reader.next(row)) {
      }
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  }
  std::string path_;
};

TEST_F(CsvTest, ReadsRowsAndSkipsBlankLines) {
  const std::string path = write("id,x_m,y_m\n1,2.5,-3\n\n2, 4e1 ,5\r\n");
  CsvReader reader(path, {"id", "x_m", "y_m"});
  std::array<double, 3> row{};
  ASSERT_TRUE(reader.next(row));
  EXPECT_EQ(row, (std::array<double, 3>{1, 2.5, -3}));
  ASSERT_TRUE(reader.next(row));
  EXPECT_EQ(row, (std::array<double, 3>{2, 40, 5}));
  EXPECT_FALSE(reader.next(row));
}

// The reader's blocks grow from 4 KiB to 64 KiB; rows cut by every block edge on the way (and
// by several 64 KiB ones) read whole, with their line numbers.
TEST_F(CsvTest, ReadsRowsAcrossGrowingBlocks) {
  std::string text = "id,x_m,y_m\n";
  constexpr int kRows = 20000;  // about 400 KiB
  for (int i = 0; i < kRows; ++i) {
    text += std::to_string(i) + ",0.125," + std::to_string(i * 3) + ".5\n";
  }
  text += "bad,1,2\n";
  const std::string path = write(text);
  CsvReader reader(path, {"id", "x_m", "y_m"});
  std::array<double, 3> row{};
  for (int i = 0; i < kRows; ++i) {
    ASSERT_TRUE(reader.next(row)) << i;
    ASSERT_EQ(row, (std::array<double, 3>{double(i), 0.125, i * 3 + 0.5})) << i;
  }
  try {
    reader.next(row);
    FAIL() << "the last row is not a number";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).substr(0, path.size() + 7), path + ":20002:");
  }
}

// A line is held to the log reader's limit, so a file with no newline is refused, not read
// whole into memory.
TEST_F(CsvTest, RefusesALineLongerThanTheLimit) {
  const std::string limit = std::to_string(kMaxLogLineBytes);
  {
    const std::string e = error_of("id,x_m,y_m\n1,2,3\n" + std::string(kMaxLogLineBytes + 1, '7'));
    EXPECT_NE(e.find(path_ + ":3: line longer than " + limit + " bytes"), std::string::npos) << e;
  }
  {
    const std::string e = error_of(std::string(kMaxLogLineBytes + 1, 'x'));
    EXPECT_NE(e.find(path_ + ":1: line longer than " + limit + " bytes"), std::string::npos) << e;
  }
  // A line of exactly the limit is read.
  const std::string e =
      error_of("id,x_m,y_m\n1,2," + std::string(kMaxLogLineBytes - 5, '0') + "3\n");
  EXPECT_EQ(e, "");
}

// A directory opens but cannot be read: named, not a bare stream error.
TEST_F(CsvTest, RefusesADirectory) {
  const std::string dir = std::filesystem::temp_directory_path().string();
  try {
    CsvReader reader(dir, {"id"});
    FAIL() << "read a directory";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(dir + ":"), std::string::npos) << e.what();
  }
}

// Fields in every form a writer might use, padded with blanks and a \r\n ending now and then:
// each reads as std::from_chars reads the field trimmed.
TEST_F(CsvTest, ReadsEveryNumberFormAsFromChars) {
  std::mt19937_64 random(5);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-12, 12), form(0, 3), pad(0, 2);
  const char* const pads[] = {"", " ", "\t "};
  std::string text = "id,x_m,y_m\n";
  std::vector<std::array<std::string, 3>> rows;
  for (int i = 0; i < 5000; ++i) {
    std::array<std::string, 3> fields;
    for (std::string& f : fields) {
      const double v = mantissa(random) * std::pow(10.0, exponent(random));
      char buf[64];
      switch (form(random)) {
        case 0:
          std::snprintf(buf, sizeof(buf), "%.6f", v);
          break;
        case 1:
          std::snprintf(buf, sizeof(buf), "%.17g", v);
          break;
        case 2:
          std::snprintf(buf, sizeof(buf), "%.3e", v);
          break;
        default:
          *std::to_chars(buf, buf + sizeof(buf), v).ptr = 0;
          break;
      }
      f = buf;
      text += pads[pad(random)] + f + pads[pad(random)] + (&f == &fields[2] ? "" : ",");
    }
    text += i % 7 == 0 ? "\r\n" : "\n";
    rows.push_back(fields);
  }
  const std::string path = write(text);
  CsvReader reader(path, {"id", "x_m", "y_m"});
  std::array<double, 3> row{};
  for (const std::array<std::string, 3>& fields : rows) {
    ASSERT_TRUE(reader.next(row));
    for (int k = 0; k < 3; ++k) {
      double expected = 0;
      std::from_chars(fields[k].data(), fields[k].data() + fields[k].size(), expected);
      ASSERT_EQ(row[k], expected) << fields[k];
    }
  }
  EXPECT_FALSE(reader.next(row));
}

TEST_F(CsvTest, RefusesMalformedInputNamingFileLineAndReason) {
  {
    const std::string e = error_of("id,x_m\n");
    EXPECT_NE(e.find(":1: header is 'id,x_m', expected 'id,x_m,y_m'"), std::string::npos) << e;
  }
  {
    const std::string e = error_of("id,x_m,y_m\n1,2,3\n1,2\n");
    EXPECT_NE(e.find(":3: expected 3 columns, found 2"), std::string::npos) << e;
  }
  {
    const std::string e = error_of("id,x_m,y_m\n1,abc,3\n");
    EXPECT_NE(e.find(":2: column 'x_m': 'abc' is not a number"), std::string::npos) << e;
  }
  {
    const std::string e = error_of("id,x_m,y_m\n1,2.5x,3\n");
    EXPECT_NE(e.find(":2: column 'x_m': '2.5x' is not a number"), std::string::npos) << e;
  }
  {
    const std::string e = error_of("id,x_m,y_m\n1,nan,3\n");
    EXPECT_NE(e.find(":2: column 'x_m': value 'nan' is not finite"), std::string::npos) << e;
  }
  {
    // A wrong count is reported before a field's own fault, on either side of it.
    EXPECT_NE(error_of("id,x_m,y_m\n1,abc\n").find(":2: expected 3 columns, found 2"),
              std::string::npos);
    EXPECT_NE(error_of("id,x_m,y_m\n1,abc,3,4\n").find(":2: expected 3 columns, found 4"),
              std::string::npos);
    EXPECT_NE(error_of("id,x_m,y_m\n1,2,3,\n").find(":2: expected 3 columns, found 4"),
              std::string::npos);
  }
  {
    // The first bad field is named, trimmed, when two are bad.
    const std::string e = error_of("id,x_m,y_m\n1, 2 5 ,x\n");
    EXPECT_NE(e.find(":2: column 'x_m': '2 5' is not a number"), std::string::npos) << e;
    EXPECT_NE(error_of("id,x_m,y_m\n-,1,2\n").find(":2: column 'id': '-' is not a number"),
              std::string::npos);
    EXPECT_NE(error_of("id,x_m,y_m\n1,2,1e999\n").find(":2: column 'y_m': '1e999' is not a number"),
              std::string::npos);
    EXPECT_NE(
        error_of("id,x_m,y_m\n1,-inf ,2\n").find(":2: column 'x_m': value '-inf' is not finite"),
        std::string::npos);
  }
  {
    const std::string e = error_of("id,x_m,y_m\n1,,3\n");
    EXPECT_NE(e.find(":2: column 'x_m': '' is not a number"), std::string::npos) << e;
  }
  {
    const std::string e = error_of("");
    EXPECT_NE(e.find(":0: empty file"), std::string::npos) << e;
  }
  {
    // A long bad field is quoted by its first 80 bytes and its length; a NUL as \x00.
    const std::string e = error_of("id,x_m,y_m\n1," + std::string(100'000, '7') + "x,3\n");
    EXPECT_NE(e.find(":2: column 'x_m': '" + std::string(80, '7') +
                     "...' (100001 bytes) is not a number"),
              std::string::npos)
        << e.substr(0, 300);
    EXPECT_LT(e.size(), 300U);
    const std::string nul = error_of(std::string("id,x_m,y_m\n1,2\0,3\n", 18));
    EXPECT_NE(nul.find(":2: column 'x_m': '2\\x00' is not a number"), std::string::npos) << nul;
  }
  EXPECT_THROW(CsvReader("/nonexistent/file.csv", {"a"}), std::runtime_error);
}

}  // namespace
}  // namespace fastslam::tools
