// Lines of numbers for the output files (trajectories, maps, traces): the bytes printf's "%.Nf"
// and "%.Ng" would write, made with std::to_chars, whose precision forms the standard defines as
// printf's. glibc's snprintf formats a double through multi-precision arithmetic (~230 ns for
// "%.6f" on this project's machine), to_chars with Ryu (~37 ns); a run writes four numbers per
// pose and a pose per control into each of its path files.
//
// Ownership: owns its buffer, reused across lines. Thread safety: thread-compatible.
// Costs: O(digits) per number, no allocation once the buffer has grown to a line.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace fastslam::tools {

class TextLine {
 public:
  // printf("%.*f", precision, v), for a precision of 0 to 40 (clamped to that).
  TextLine& fixed(double v, int precision);
  // printf("%.*g", precision, v), likewise.
  TextLine& general(double v, int precision);
  // printf("%llu", v).
  TextLine& integer(std::uint64_t v);
  TextLine& text(std::string_view s) {
    line_.append(s);
    return *this;
  }
  TextLine& put(char c) {
    line_.push_back(c);
    return *this;
  }

  std::string_view view() const { return line_; }
  void clear() { line_.clear(); }

 private:
  std::string line_;
};

}  // namespace fastslam::tools
