#include "tools/io/csv.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <ios>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "tools/io/decimal.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {
namespace {

bool is_blank(char c) { return c == ' ' || c == '\t'; }

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

// A field for a message: its first 80 bytes (control bytes as \xNN), then its length when
// longer, so a megabyte of garbage does not become a megabyte of message.
std::string quoted(std::string_view field) {
  constexpr std::size_t kMaxQuoted = 80;
  std::string out(1, '\'');
  for (const char c : field.substr(0, kMaxQuoted)) {
    const auto u = static_cast<unsigned char>(c);
    if (u >= 0x20 && u != 0x7f) {
      out.push_back(c);
    } else {
      constexpr char kHex[] = "0123456789abcdef";
      out.append("\\x").push_back(kHex[u >> 4]);
      out.push_back(kHex[u & 15]);
    }
  }
  if (field.size() > kMaxQuoted) out.append("...");
  out.push_back('\'');
  if (field.size() > kMaxQuoted) {
    out.append(" (").append(std::to_string(field.size())).append(" bytes)");
  }
  return out;
}

}  // namespace

CsvReader::CsvReader(std::string path, std::vector<std::string> columns)
    : path_(std::move(path)), columns_(std::move(columns)), in_(path_) {
  if (!in_) throw std::runtime_error(path_ + ": cannot open for reading");
  if (!read_line()) fail("empty file, expected a header line");
  split();
  bool same = fields_.size() == columns_.size();
  for (std::size_t i = 0; same && i < fields_.size(); ++i) same = fields_[i] == columns_[i];
  if (!same) {
    std::string expected;
    for (const std::string& c : columns_) expected += (expected.empty() ? "" : ",") + c;
    fail("header is " + quoted(trim(text_)) + ", expected '" + expected + "'");
  }
}

bool CsvReader::next(std::span<double> out) {
  std::string_view line;
  while (next_line(line)) {
    if (line.empty() || is_blank(line.front()) || line.front() == '\r') {
      if (trim(line).empty()) continue;
    }
    parse_row(line, out);
    return true;
  }
  return false;
}

bool CsvReader::next_line(std::string_view& line) {
  // The common case: the whole line lies in the block, and is read where it is.
  if (next_ != end_) {
    const char* const start = block_.get() + next_;
    const std::size_t n = end_ - next_;
    const void* const newline = std::memchr(start, '\n', std::min(n, kMaxLogLineBytes + 1));
    if (newline != nullptr) {
      const std::size_t length =
          static_cast<std::size_t>(static_cast<const char*>(newline) - start);
      ++line_;
      next_ += length + 1;
      line = std::string_view(start, length);
      return true;
    }
  }
  if (!read_line()) return false;
  line = text_;
  return true;
}

// One pass: each field is parsed where it stands, up to its comma. A wrong column count is
// reported before any field's own fault, so the first bad field is kept until the count is in.
void CsvReader::parse_row(std::string_view line, std::span<double> out) const {
  const char* p = line.data();
  const char* const end = p + line.size();
  const std::size_t columns = columns_.size();
  std::size_t count = 0, bad = columns;
  std::string_view bad_field;
  bool bad_finite = false;
  for (;;) {
    while (p != end && is_blank(*p)) ++p;
    const char* const begin = p;
    double value = 0.0;
    const auto [stop, ec] = parse_double(begin, end, value);
    const char* q = stop;
    while (q != end && (is_blank(*q) || *q == '\r')) ++q;
    if (ec != std::errc() || stop == begin || (q != end && *q != ',')) {
      // Not a number up to a comma: the field is what lies between the commas, trimmed.
      q = begin;
      while (q != end && *q != ',') ++q;
      if (count < columns && bad == columns) {
        bad = count, bad_field = trim(std::string_view(begin, static_cast<std::size_t>(q - begin)));
      }
    } else if (count < columns && bad == columns) {
      if (std::isfinite(value)) {
        out[count] = value;
      } else {
        bad = count, bad_field = std::string_view(begin, static_cast<std::size_t>(stop - begin));
        bad_finite = true;
      }
    }
    ++count;
    if (q == end) break;
    p = q + 1;
  }
  if (count != columns) {
    fail("expected " + std::to_string(columns) + " columns, found " + std::to_string(count));
  }
  if (bad != columns) {
    fail("column '" + columns_[bad] + "': " + (bad_finite ? "value " : "") + quoted(bad_field) +
         (bad_finite ? " is not finite" : " is not a number"));
  }
}

bool CsvReader::read_line() {
  ++line_;
  text_.clear();
  for (;;) {
    if (next_ == end_ && !fill()) {
      if (!text_.empty()) return true;  // a last line without its newline
      --line_;
      return false;
    }
    const char* const start = block_.get() + next_;
    const char* const newline = static_cast<const char*>(std::memchr(start, '\n', end_ - next_));
    const std::size_t n =
        newline != nullptr ? static_cast<std::size_t>(newline - start) : end_ - next_;
    if (text_.size() + n > kMaxLogLineBytes) {
      fail("line longer than " + std::to_string(kMaxLogLineBytes) +
           " bytes (the limit of a line, as for a log): not a CSV file of numbers");
    }
    text_.append(start, n);
    next_ += n;
    if (newline != nullptr) {
      ++next_;
      return true;
    }
  }
}

bool CsvReader::fill() {
  // Doubling from 4 KiB: a file of a few rows (a fuzzer's input, a test's) does not pay for
  // 64 KiB, a large one reaches 64 KiB blocks after four reads.
  constexpr std::size_t kFirstBlock = std::size_t{1} << 12, kMaxBlock = std::size_t{1} << 16;
  if (block_size_ < kMaxBlock) {
    block_size_ = block_size_ == 0 ? kFirstBlock : 2 * block_size_;
    block_.reset(new char[block_size_]);  // uninitialised: sgetn writes what is read
  }
  std::streamsize got = 0;
  // The file buffer throws for a read the system refuses (a directory).
  try {
    got = in_.rdbuf()->sgetn(block_.get(), static_cast<std::streamsize>(block_size_));
  } catch (const std::ios_base::failure& e) {
    fail("cannot read: " + e.code().message());
  }
  next_ = 0;
  end_ = got > 0 ? static_cast<std::size_t>(got) : 0;
  return end_ > 0;
}

void CsvReader::split() {
  fields_.clear();
  const std::string_view line = text_;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = line.find(',', start);
    fields_.push_back(trim(line.substr(start, comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
}

void CsvReader::fail(const std::string& what) const {
  throw std::runtime_error(path_ + ":" + std::to_string(line_) + ": " + what);
}

}  // namespace fastslam::tools
