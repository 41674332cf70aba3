#include "tools/datasets/streamed_log_source.h"

#include <iostream>
#include <stdexcept>
#include <utility>

namespace fastslam::tools {
namespace {

constexpr const char* kStdin = "<stdin>";

}  // namespace

StreamedLogSource::StreamedLogSource(const std::string& path) : name_(path == "-" ? kStdin : path) {
  info_.name = name_;
  Event e;
  std::vector<engine::Observation> scan;
  if (path != "-") {
    // The first pass: every record checked, and what the source knows up front.
    const std::unique_ptr<std::istream> first = open_log_file(path);
    LogReader check(*first, name_);
    std::size_t labelled = 0, observations = 0;
    ScanShapeCounter shape;
    while (check.next(e, scan)) {
      info_.expected_controls += e.kind == EventKind::kControl;
      shape.add(e);
      observations += scan.size() * (e.kind == EventKind::kScan);
      if (e.kind == EventKind::kScan) {
        for (const engine::Observation& z : scan) labelled += z.id >= 0;
      }
    }
    info_.labels = labels_of(labelled, observations);
    info_.scans = shape.shape(true);
    info_.landmarks = check.landmarks();
    if (!check.ended()) warnings_.push_back(unterminated_log_warning(name_));
    file_ = open_log_file(path);
    reader_ = std::make_unique<LogReader>(*file_, name_);
    info_.header = reader_->header();
    landmarks_known_ = info_.landmarks.size();
    return;
  }
  std::ios::sync_with_stdio(false);  // buffered reads of a pipe, not a syscall per character
  reader_ = std::make_unique<LogReader>(std::cin, name_);
  info_.header = reader_->header();
  info_.labels = Labels::kNone;  // until a scan with detections says otherwise
  ScanShapeCounter shape;
  bool whole = false;  // the stream ended within the look-ahead
  while (ahead_.size() < kLookahead) {
    if (!reader_->next(e, scan)) {
      whole = true;
      break;
    }
    ahead_.push_back({e, scan, reader_->line()});
    shape.add(e);
    if (e.kind == EventKind::kScan && !scan.empty()) {
      std::size_t labelled = 0;
      for (const engine::Observation& z : scan) labelled += z.id >= 0;
      info_.labels = labels_of(labelled, scan.size());
      break;
    }
  }
  info_.scans = shape.shape(whole);  // else the stream's first scans only
  info_.landmarks = reader_->landmarks();
  landmarks_known_ = info_.landmarks.size();
}

StreamedLogSource::~StreamedLogSource() = default;

bool StreamedLogSource::next(Event& event, std::vector<engine::Observation>& scan) {
  if (!ahead_.empty()) {
    Ahead& a = ahead_.front();
    event = a.event;
    scan.swap(a.scan);
    line_ = a.line;
    ahead_.pop_front();
    ++index_;
    return true;
  }
  if (!reader_->next(event, scan)) {
    // A pipe's end tells whether it was whole; a file's first pass has said so already.
    if (file_ == nullptr && !reader_->ended() && warnings_.empty()) {
      warnings_.push_back(unterminated_log_warning(name_));
    }
    return false;
  }
  line_ = reader_->line();
  ++index_;
  if (file_ == nullptr && reader_->landmarks().size() != landmarks_known_) {
    throw std::runtime_error(where(index_ - 1) +
                             ": a truth landmark record came after the first event (above this "
                             "line); from a pipe, 'landmark' records must come before the events");
  }
  return true;
}

std::string StreamedLogSource::where(std::uint64_t index) const {
  if (index_ > 0 && index == index_ - 1) return name_ + ":" + std::to_string(line_);
  return Source::where(index);
}

std::unique_ptr<Source> open_log_source(const SourceOptions& o) {
  if (o.data.empty()) {
    throw std::invalid_argument("--source log needs --data FILE.log (or - for standard input)");
  }
  return std::make_unique<StreamedLogSource>(o.data);
}

}  // namespace fastslam::tools
