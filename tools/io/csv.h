// A strict reader for the numeric CSV files of the data sets (a header line, then rows of
// numbers). Every refusal names the file, the line and the reason: wrong column count, a field
// that is not a number, a non-finite value, a header that is not the expected one.
//
// Ownership: owns its file stream. Thread safety: thread-compatible.
// Costs: O(bytes read); one line buffer, reused, of at most kMaxLogLineBytes
// (tools/io/log_format.h): a longer line (a file with no newline) is refused, not read whole.
#pragma once

#include <cstddef>
#include <fstream>
#include <span>
#include <string>
#include <vector>

namespace fastslam::tools {

class CsvReader {
 public:
  // Opens `path` and checks that its header names exactly `columns`, in order. Throws
  // std::runtime_error when the file cannot be read or the header differs.
  CsvReader(std::string path, std::vector<std::string> columns);

  // Reads the next row into `out` (size = number of columns). Returns false at the end of the
  // file. Blank lines are skipped. Throws std::runtime_error on a malformed row.
  bool next(std::span<double> out);

  // Throws std::runtime_error "<path>:<line>: <what>" for the current line.
  [[noreturn]] void fail(const std::string& what) const;

 private:
  // One line into text_, without its '\n'; false at the end with nothing read. Throws (fail)
  // for a line longer than kMaxLogLineBytes.
  bool read_line();

  std::string path_;
  std::vector<std::string> columns_;
  std::ifstream in_;
  std::string text_;
  std::size_t line_ = 0;
};

}  // namespace fastslam::tools
