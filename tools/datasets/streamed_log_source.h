// `--source log`: a native log (docs/log-format.md) read record by record, from a file or from
// standard input ("-"), so memory stays bounded however long the log and a producer can feed a
// live robot's data through a pipe. A file is read twice: a first pass checks every record
// before anything runs (a malformed line fails the run at once, naming it) and learns what a
// source says up front (the labels, the number of controls, every truth landmark); the second
// streams. A pipe cannot be read twice: the source reads ahead to the first scan with
// detections and takes the labels from it (all carry ids: known association under `auto`);
// truth landmarks must precede the first event; and a malformed record ends the stream where it
// is, with the error "<stdin>:<line>: <reason>" from `next`, after the events before it. A log
// without its end marker runs with a warning (Source::warnings): a file's from the first pass,
// a pipe's once `next` reached its end.
//
// Ownership: owns the file it opens; borrows standard input. Thread safety: thread-compatible.
// Costs: O(record) per event; a file's first pass reads it whole once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <istream>
#include <memory>
#include <string>
#include <vector>

#include "tools/datasets/source.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {

class StreamedLogSource final : public Source {
 public:
  // How many events a pipe is read ahead, at most, looking for a scan with detections.
  static constexpr std::size_t kLookahead = 1 << 16;

  // `path` "-" reads standard input. Throws std::runtime_error for a file that cannot be
  // opened, and as LogReader for the header (and, for a file, for any record).
  explicit StreamedLogSource(const std::string& path);
  ~StreamedLogSource() override;

  bool next(Event& event, std::vector<engine::Observation>& scan) override;
  // "FILE:LINE" (or "<stdin>:LINE") of the last event `next` gave.
  std::string where(std::uint64_t index) const override;

 private:
  struct Ahead {
    Event event;
    std::vector<engine::Observation> scan;
    std::uint64_t line = 0;
  };
  std::string name_;
  std::unique_ptr<std::istream> file_;  // null for standard input
  std::unique_ptr<LogReader> reader_;
  std::deque<Ahead> ahead_;          // a pipe's events read ahead
  std::size_t landmarks_known_ = 0;  // truth landmarks in info_
  std::uint64_t index_ = 0;          // events given so far
  std::uint64_t line_ = 0;           // the line of the last one
};

}  // namespace fastslam::tools
