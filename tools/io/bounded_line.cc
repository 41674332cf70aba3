#include "tools/io/bounded_line.h"

#include <stdexcept>

namespace fastslam::tools {

LineEnd read_bounded_line(std::istream& in, std::string& text, std::size_t max_bytes) {
  text.clear();
  std::streambuf* const buffer = in.rdbuf();
  if (buffer == nullptr) return LineEnd::kEndOfInput;
  for (;;) {
    int c = 0;
    // The stream buffer throws for a read the system refuses.
    try {
      c = buffer->sbumpc();
    } catch (const std::ios_base::failure& e) {
      throw std::runtime_error("cannot read: " + e.code().message());
    }
    if (c == std::char_traits<char>::eof()) {
      in.setstate(std::ios::eofbit);
      return LineEnd::kEndOfInput;
    }
    if (c == '\n') return LineEnd::kNewline;
    if (text.size() == max_bytes) return LineEnd::kTooLong;
    text.push_back(static_cast<char>(c));
  }
}

}  // namespace fastslam::tools
