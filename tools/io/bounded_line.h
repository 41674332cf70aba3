// One line of text at most a given length, for the readers of untrusted files (the CSV reader,
// the log reader): input without newlines (a binary file, /dev/zero) stops at the limit instead
// of being read whole, and a read the system refuses (a directory, an I/O error) is an error the
// caller can name with its file and line rather than the stream buffer's bare message.
//
// Ownership: borrows the stream for the call. Thread safety: thread-compatible.
// Costs: O(line) per call, one character at a time from the stream's buffer.
#pragma once

#include <cstddef>
#include <istream>
#include <string>

namespace fastslam::tools {

enum class LineEnd { kNewline, kEndOfInput, kTooLong };

// Reads into `text` (cleared first; without the '\n') up to a newline, the end of the input
// (eofbit set) or `max_bytes` characters with more to come (kTooLong). kEndOfInput with `text`
// empty means there was no line. Throws std::runtime_error "cannot read: REASON" when the
// system refuses the read.
LineEnd read_bounded_line(std::istream& in, std::string& text, std::size_t max_bytes);

}  // namespace fastslam::tools
