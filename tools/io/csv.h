// A strict reader for the numeric CSV files of the data sets (a header line, then rows of
// numbers). Every refusal names the file, the line and the reason: wrong column count, a field
// that is not a number, a non-finite value, a header that is not the expected one.
//
// Ownership: owns its file stream. Thread safety: thread-compatible.
// Costs: O(bytes read), read in blocks of 4 KiB growing to 64 KiB (a small file costs a small
// buffer), lines found with memchr and parsed where they lie in the block (a line across two
// blocks is copied once), each field parsed as it is cut (tools/io/decimal.h); no allocation
// per row. A line is held to kMaxLogLineBytes (tools/io/log_format.h): a longer one (a file with
// no newline) is refused, not read whole.
#pragma once

#include <cstddef>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <string_view>
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
  // The next line without its '\n': in place in the block when it lies there whole, else
  // gathered into text_ by read_line. The view lasts until the next call.
  bool next_line(std::string_view& line);
  // One line into text_, without its '\n'; false at the end with nothing read. Throws (fail)
  // for a line longer than kMaxLogLineBytes and for a read the system refuses.
  bool read_line();
  // The row's fields into `out`; throws (fail) for a wrong count or a field that is not a
  // finite number.
  void parse_row(std::string_view line, std::span<double> out) const;
  // Reads the next block; false at the end of the file.
  bool fill();
  // text_'s comma-separated fields, trimmed, into fields_ (the header's check).
  void split();

  std::string path_;
  std::vector<std::string> columns_;
  std::ifstream in_;
  std::unique_ptr<char[]> block_;         // read ahead of the lines, uninitialised
  std::size_t block_size_ = 0;            // its capacity
  std::size_t next_ = 0, end_ = 0;        // block_'s unread bytes
  std::string text_;                      // the current line
  std::vector<std::string_view> fields_;  // its fields
  std::size_t line_ = 0;
};

}  // namespace fastslam::tools
