// The native log format (docs/log-format.md): a line-oriented text file with a header naming
// the motion model, the sensor and the initial pose, then time-stamped records (controls, scans
// with optional landmark ids, optional truth poses and GPS fixes) and untimed truth landmarks,
// closed by an end marker (`end N`, N the records above it) so that a log cut at a line boundary
// can be told from a whole one. Any data set converted to it can be run by `fastslam run
// --source log`.
//
// Reading is strict: every refusal (unknown record, wrong field count, a field that is not a
// number, NaN or infinity, a negative range or dt, time going backwards, a missing or repeated
// header line, a repeated landmark id, a line or a scan over the limits below, an end marker
// whose count is not the number of records, a record after the end marker) throws
// std::runtime_error "<file>:<line>: <reason>", quoting at most kMaxQuotedBytes of a bad
// token (control bytes such as NUL as \xNN), and returns nothing partial. A log without the
// end marker (written before it existed, or cut short) is read; the reader says so
// (Log::unterminated, LogReader::ended) and callers warn with unterminated_log_warning. Writing
// prints every double in its shortest exact form
// (std::to_chars), so write -> read gives back bit-identical doubles.
//
// Ownership: `Log` is a plain value; `LogWriter` borrows its stream, which must outlive it.
// Thread safety: thread-compatible. Costs: O(bytes) to read or write; a `Log` holds every
// event (about 80 bytes each) and every observation (24 bytes each).
#pragma once

#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine/filter.h"
#include "engine/filter_config.h"

namespace fastslam::tools {

inline constexpr int kLogFormatVersion = 1;
// Limits a reader holds any input to, so input that is not a log (no newline, /dev/zero) fails
// early instead of filling memory: bytes in one line (4 MiB), observations in one scan (a
// scan's line at about 60 bytes per observation fits), and bytes of a bad token quoted in a
// message.
inline constexpr std::size_t kMaxLogLineBytes = std::size_t{4} << 20;
inline constexpr std::uint64_t kMaxScanObservations = 65'536;
inline constexpr std::size_t kMaxQuotedBytes = 80;

struct LogHeader {
  // Kind, its parameters (wheelbase, geometry) and the control noise.
  engine::MotionConfig motion;
  // Noises, max range, field of view and the sensor's offset on the vehicle.
  engine::SensorConfig sensor;
  // The pose every particle starts from, and the time it holds at.
  double start_time = 0.0;
  double start_pose[3] = {0.0, 0.0, 0.0};
  // Bit-exact comparison of what a log holds: the motion parameters of `motion.kind` only.
  friend bool operator==(const LogHeader& a, const LogHeader& b);
};

enum class EventKind : std::uint8_t { kControl, kScan, kTruthPose, kGps };

// One timed record. Which fields mean something depends on `kind`.
struct Event {
  EventKind kind = EventKind::kControl;
  double time = 0.0;  // s; a control is stamped at the END of the interval it covers
  // kControl: the control held over (time - dt, time].
  double dt = 0.0;
  engine::Control control;
  // kTruthPose: the true pose at `time`; kGps: a position fix (theta unused, 0).
  double x = 0.0, y = 0.0, theta = 0.0;
  // kScan: its observations are Log::observations[first, first + count).
  std::uint64_t first = 0;
  std::uint32_t count = 0;
  friend bool operator==(const Event& a, const Event& b);
};

struct TruthLandmark {
  std::uint64_t id = 0;
  double x = 0.0, y = 0.0;
  friend bool operator==(const TruthLandmark&, const TruthLandmark&) = default;
};

struct Log {
  LogHeader header;
  std::vector<Event> events;                      // time order (non-decreasing)
  std::vector<engine::Observation> observations;  // of all scans; id -1 = no id
  std::vector<TruthLandmark> landmarks;           // ids unique
  // The line of each event in the file it was read from; empty for a log built in memory.
  // Not part of what the log holds (operator== ignores it).
  std::vector<std::uint64_t> lines;
  // Read from a file that ended without the end marker: it may have been cut short. False for a
  // log built in memory. Not part of what the log holds either.
  bool unterminated = false;
  friend bool operator==(const Log& a, const Log& b);
};

// Reads a log record by record, for inputs too long to hold or still being written (a pipe):
// the constructor reads the header, `next` one event at a time; truth landmarks are collected
// as they come. Refusals throw as read_log does ("<name>:<line>: <reason>"), from the
// constructor for the header and from `next` for the record they are in; the events before it
// were returned. After the end marker `next` reads on to the end of the stream, refusing any
// record there. Borrows the stream. Costs: O(record) per call; memory O(one record +
// landmarks).
class LogReader {
 public:
  LogReader(std::istream& in, const std::string& name);
  ~LogReader();
  LogReader(const LogReader&) = delete;
  LogReader& operator=(const LogReader&) = delete;

  const LogHeader& header() const noexcept { return header_; }
  // The next event, a scan's observations in `scan` (Event::first 0, count their number);
  // false at the end of the stream. Landmark records on the way go to landmarks().
  bool next(Event& event, std::vector<engine::Observation>& scan);
  // The line of the last event `next` returned.
  std::uint64_t line() const noexcept { return line_; }
  // Whether the end marker was read; once `next` returned false, whether the log was whole.
  bool ended() const noexcept;
  const std::vector<TruthLandmark>& landmarks() const noexcept { return landmarks_; }

 private:
  class Parser;
  std::unique_ptr<Parser> parser_;
  LogHeader header_;
  std::vector<TruthLandmark> landmarks_;
  std::uint64_t line_ = 0;
};

// The warning for a log `name` that ended without its end marker: it may be truncated, and
// `fastslam convert` writes it whole.
std::string unterminated_log_warning(const std::string& name);

// Reads a log file. Throws std::runtime_error naming the file, the line and the reason.
Log read_log(const std::string& path);
// The same from a stream; `name` stands for the file in messages.
Log read_log(std::istream& in, const std::string& name);
// `path` opened for a LogReader: throws std::runtime_error "PATH: REASON" for a directory or a
// file that cannot be opened (the system's reason). Allocates the stream.
std::unique_ptr<std::istream> open_log_file(const std::string& path);

// Writes `log`, closed by its end marker, to `path` (whole or not at all:
// tools/io/atomic_file.h; throws std::runtime_error when the file cannot be written) or to a
// stream. Throws
// std::invalid_argument (writing nothing to a path) when the log would not read back: events
// out of time order, a scan's observations out of bounds, a non-finite value.
void write_log(const std::string& path, const Log& log);
void write_log(std::ostream& out, const Log& log);

// Streams a log out record by record, for sources too long to hold (a simulation of millions
// of steps). The header is written by the constructor; records must come in time order, which
// is checked (std::invalid_argument), as are the values; `finish` writes the end marker.
class LogWriter {
 public:
  LogWriter(std::ostream& out, const LogHeader& header);
  // Each record method throws std::logic_error after `finish`.
  void landmark(const TruthLandmark& landmark);
  void control(double time, double dt, const engine::Control& control);
  void scan(double time, std::span<const engine::Observation> observations);
  void truth_pose(double time, double x, double y, double theta);
  void gps(double time, double x, double y);
  // Writes one event of `log` (a scan takes its observations from `log`).
  void event(const Log& log, const Event& event);
  // Writes the end marker, `end N` with N the records written: the log is complete. Call it
  // once every record is out, and only then (a writer left unfinished, as when its source
  // failed, leaves a log that reads with a warning). Throws std::logic_error the second time.
  void finish();

 private:
  void stamp(double time);
  void open_record();
  std::ostream& out_;
  double last_time_;
  std::string line_;
  std::uint64_t records_ = 0;
  bool finished_ = false;
};

}  // namespace fastslam::tools
