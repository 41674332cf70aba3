#include "tools/io/log_format.h"

#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <ios>
#include <istream>
#include <memory>
#include <numbers>
#include <ostream>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <unordered_set>

#include "engine/enum_names.h"
#include "engine/motion_dispatch.h"
#include "tools/io/atomic_file.h"
#include "tools/io/bounded_line.h"
#include "tools/io/decimal.h"

namespace fastslam::tools {

using engine::MotionKind;

namespace {

constexpr std::string_view kMagic = "fastslam-log";

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }

// The first kMaxQuotedBytes of a token for a message, with control bytes (a NUL, an escape)
// written as \xNN: a NUL would otherwise end the message where it is printed as a C string.
std::string printable(std::string_view token) {
  std::string out;
  for (const char c : token.substr(0, kMaxQuotedBytes)) {
    const auto u = static_cast<unsigned char>(c);
    if (u >= 0x20 && u != 0x7f) {
      out.push_back(c);
    } else {
      constexpr char kHex[] = "0123456789abcdef";
      out.append("\\x").push_back(kHex[u >> 4]);
      out.push_back(kHex[u & 15]);
    }
  }
  return out;
}

// A token for a message: whole up to kMaxQuotedBytes, else its start and its length, so a
// megabyte of garbage does not become a megabyte of message.
std::string clipped(std::string_view token) {
  std::string out = printable(token);
  if (token.size() > kMaxQuotedBytes) {
    out.append("... (").append(std::to_string(token.size())).append(" bytes)");
  }
  return out;
}
std::string quoted(std::string_view token) {
  std::string out(1, '\'');
  out.append(printable(token)).push_back('\'');
  if (token.size() > kMaxQuotedBytes) {
    out.insert(out.size() - 1, "...");
    out.append(" (").append(std::to_string(token.size())).append(" bytes)");
  }
  return out;
}

// Splits on spaces and tabs; a trailing '\r' is ignored.
void tokenize(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
}

}  // namespace

class LogReader::Parser {
 public:
  Parser(std::istream& in, const std::string& name) : in_(in), name_(name) {}

  void header(LogHeader& h) {
    read_header(h);
    last_time_ = h.start_time;
  }

  // The next record: an event (true, kind set) into `e` and `scan`, or a truth landmark
  // appended to `landmarks` (and on to the next record); false at the end.
  bool next(Event& e, std::vector<engine::Observation>& scan,
            std::vector<TruthLandmark>& landmarks) {
    while (next_line()) {
      const std::string_view record = tokens_[0];
      if (end_line_ != 0) {
        fail(quoted(record) + " after the end marker (line " + std::to_string(end_line_) +
             "): the log ends there");
      }
      if (record == "end") {
        fields(2, "end RECORDS");
        const std::uint64_t said = integer(1, "record count");
        if (said != records_) {
          fail("the end marker counts " + std::to_string(said) + " records, but the log has " +
               std::to_string(records_) + " before it: records were lost or added");
        }
        end_line_ = line_;
        continue;
      }
      ++records_;
      if (record == "landmark") {
        fields(4, "landmark ID X Y");
        TruthLandmark l{integer(1, "landmark id"), number(2, "x"), number(3, "y")};
        if (!landmark_ids_.insert(l.id).second) {
          fail("landmark id " + std::to_string(l.id) + " is repeated");
        }
        landmarks.push_back(l);
        continue;
      }
      e = Event{};
      if (record == "control") {
        fields(5, "control T DT U0 U1");
        e.kind = EventKind::kControl;
        e.dt = number(2, "dt");
        if (e.dt < 0) fail("dt is negative (" + clipped(tokens_[2]) + ")");
        e.control = {number(3, "u0"), number(4, "u1")};
      } else if (record == "scan") {
        if (tokens_.size() < 3) fail("scan needs 'scan T N' and N (range bearing id) triples");
        const std::uint64_t n = integer(2, "observation count");
        if (n > kMaxScanObservations) {
          fail("scan of " + std::to_string(n) + " observations: more than the format's limit of " +
               std::to_string(kMaxScanObservations) + " (docs/log-format.md)");
        }
        if (n > (tokens_.size() - 3) / 3 || tokens_.size() != 3 + 3 * n) {
          fail("scan of " + std::to_string(n) + " observations needs " + std::to_string(3 + 3 * n) +
               " fields, found " + std::to_string(tokens_.size()));
        }
        e.kind = EventKind::kScan;
        e.count = static_cast<std::uint32_t>(n);
        scan.clear();
        for (std::uint64_t k = 0; k < n; ++k) {
          const std::size_t f = 3 + 3 * k;
          engine::Observation z;
          z.range = number(f, "range");
          if (!(z.range > 0)) fail("range must be > 0 (got " + clipped(tokens_[f]) + ")");
          z.bearing = number(f + 1, "bearing");
          z.id = tokens_[f + 2] == "-" ? -1 : static_cast<std::int64_t>(integer(f + 2, "id"));
          scan.push_back(z);
        }
      } else if (record == "pose") {
        fields(5, "pose T X Y THETA");
        e.kind = EventKind::kTruthPose;
        e.x = number(2, "x");
        e.y = number(3, "y");
        e.theta = number(4, "theta");
      } else if (record == "gps") {
        fields(4, "gps T X Y");
        e.kind = EventKind::kGps;
        e.x = number(2, "x");
        e.y = number(3, "y");
      } else {
        fail("unknown record " + quoted(record) + " (control, scan, pose, gps, landmark or end)");
      }
      e.time = number(1, "time");
      if (e.time < last_time_) {
        fail("time goes backwards: " + clipped(tokens_[1]) + " after " + format(last_time_));
      }
      last_time_ = e.time;
      return true;
    }
    if (in_.bad()) fail("read error");
    return false;
  }

  std::uint64_t line() const noexcept { return line_; }
  bool ended() const noexcept { return end_line_ != 0; }

 private:
  void read_header(LogHeader& h) {
    if (!next_line()) fail("empty file, expected 'fastslam-log 1'");
    if (tokens_[0] != kMagic) fail("not a fastslam log: expected 'fastslam-log 1' first");
    fields(2, "fastslam-log VERSION");
    if (integer(1, "version") != static_cast<std::uint64_t>(kLogFormatVersion)) {
      fail("unsupported version " + clipped(tokens_[1]) + " (this reader reads 1)");
    }
    bool motion = false, noise = false, sensor = false, start = false;
    auto once = [&](bool& seen) {
      if (seen) fail("header line " + quoted(tokens_[0]) + " is repeated");
      seen = true;
    };
    for (;;) {
      if (!next_line()) fail("end of file inside the header (no 'end_header')");
      const std::string_view key = tokens_[0];
      if (key == "end_header") {
        fields(1, "end_header");
        break;
      }
      if (key == "motion") {
        once(motion);
        if (tokens_.size() < 2) fail("motion needs a kind");
        read_motion(h.motion);
      } else if (key == "control_noise") {
        once(noise);
        fields(3, "control_noise SIGMA0 SIGMA1");
        h.motion.sigma_control[0] = non_negative(1, "sigma0");
        h.motion.sigma_control[1] = non_negative(2, "sigma1");
      } else if (key == "sensor") {
        once(sensor);
        fields(8,
               "sensor SIGMA_RANGE SIGMA_BEARING MAX_RANGE FIELD_OF_VIEW OFFSET_X OFFSET_Y "
               "OFFSET_YAW");
        h.sensor.sigma_range = positive(1, "sigma_range");
        h.sensor.sigma_bearing = positive(2, "sigma_bearing");
        h.sensor.max_range = positive(3, "max_range");
        h.sensor.field_of_view = positive(4, "field_of_view");
        if (h.sensor.field_of_view > 2 * std::numbers::pi + 1e-12) {
          fail("field_of_view must be at most 2 pi");
        }
        h.sensor.offset = {number(5, "offset_x"), number(6, "offset_y"), number(7, "offset_yaw")};
      } else if (key == "start") {
        once(start);
        fields(5, "start T X Y THETA");
        h.start_time = number(1, "time");
        for (int k = 0; k < 3; ++k) h.start_pose[k] = number(2 + k, "pose");
      } else {
        fail("unknown header line " + quoted(key) +
             " (motion, control_noise, sensor, start or end_header)");
      }
    }
    if (!motion) fail("header has no 'motion' line");
    if (!noise) fail("header has no 'control_noise' line");
    if (!sensor) fail("header has no 'sensor' line");
    if (!start) fail("header has no 'start' line");
  }

  // "motion KIND PARAMETERS...": the kind's parameters in engine::MotionTraits order, checked
  // by the model's constructor.
  void read_motion(engine::MotionConfig& m) {
    try {
      m.kind = engine::parse_enum<MotionKind>(tokens_[1]);
    } catch (const std::invalid_argument& e) {
      fail(e.what());
    }
    const std::span<const engine::MotionParameter> parameters = engine::motion_parameters(m.kind);
    std::string form = "motion " + std::string(engine::enum_name(m.kind));
    for (const engine::MotionParameter& p : parameters) {
      form += ' ';
      for (const char c : p.name) form += static_cast<char>(std::toupper(c));
    }
    fields(2 + parameters.size(), form.c_str());
    for (std::size_t i = 0; i < parameters.size(); ++i) {
      parameters[i].set(m, number(2 + i, std::string(parameters[i].name).c_str()));
    }
    try {
      engine::visit_motion(m, [](const auto& /*model*/) {});
    } catch (const std::invalid_argument& e) {
      fail(e.what());
    }
  }

  // Next line with content (blank lines and '#' comments skipped) into tokens_.
  bool next_line() {
    while (read_line()) {
      tokenize(text_, tokens_);
      if (!tokens_.empty() && tokens_[0].front() != '#') return true;
    }
    return false;
  }

  // One line into text_, without its '\n'; false at the end of the input with nothing read.
  // A line is at most kMaxLogLineBytes, so input without newlines (a binary file, /dev/zero)
  // fails there instead of being read whole. A read the system refuses (a directory, an I/O
  // error) fails naming the file and line, not with the stream buffer's bare message.
  bool read_line() {
    ++line_;
    LineEnd end = LineEnd::kEndOfInput;
    try {
      end = read_bounded_line(in_, text_, kMaxLogLineBytes);
    } catch (const std::runtime_error& e) {
      fail(e.what());
    }
    if (end == LineEnd::kTooLong) {
      fail("line longer than " + std::to_string(kMaxLogLineBytes) +
           " bytes (the format's limit, docs/log-format.md): not a fastslam log, or a scan "
           "of more than " +
           std::to_string(kMaxScanObservations) + " observations");
    }
    if (end == LineEnd::kEndOfInput && text_.empty()) {
      --line_;
      return false;
    }
    return true;
  }

  void fields(std::size_t n, const char* form) {
    if (tokens_.size() != n) {
      std::string what = quoted(tokens_[0]);
      what += " needs " + std::to_string(n) + " fields (";
      what += form;
      what += "), found " + std::to_string(tokens_.size());
      fail(what);
    }
  }

  double number(std::size_t i, const char* what) {
    const std::string_view f = tokens_[i];
    double value = 0.0;
    const auto [end, ec] = parse_double(f.data(), f.data() + f.size(), value);
    if (ec == std::errc::result_out_of_range && end == f.data() + f.size()) {
      fail(std::string(what) + ": " + quoted(f) + " is out of a double's range");
    }
    if (ec != std::errc() || end != f.data() + f.size()) {
      fail(std::string(what) + ": " + quoted(f) + " is not a number");
    }
    if (!std::isfinite(value)) fail(std::string(what) + ": " + quoted(f) + " is not finite");
    return value;
  }
  double positive(std::size_t i, const char* what) {
    const double v = number(i, what);
    if (!(v > 0)) fail(std::string(what) + " must be > 0 (got " + clipped(tokens_[i]) + ")");
    return v;
  }
  double non_negative(std::size_t i, const char* what) {
    const double v = number(i, what);
    if (v < 0) fail(std::string(what) + " must be >= 0 (got " + clipped(tokens_[i]) + ")");
    return v;
  }
  std::uint64_t integer(std::size_t i, const char* what) {
    const std::string_view f = tokens_[i];
    std::uint64_t value = 0;
    const auto [end, ec] = std::from_chars(f.data(), f.data() + f.size(), value);
    if (ec != std::errc() || end != f.data() + f.size() ||
        value > static_cast<std::uint64_t>(INT64_MAX)) {
      fail(std::string(what) + ": " + quoted(f) + " is not a non-negative integer");
    }
    return value;
  }

  static std::string format(double v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof(buf), v);
    return std::string(buf, r.ptr);
  }

  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(name_ + ":" + std::to_string(line_) + ": " + what);
  }

  std::istream& in_;
  std::string name_;
  std::string text_;
  std::vector<std::string_view> tokens_;
  std::uint64_t line_ = 0;
  double last_time_ = 0.0;
  std::unordered_set<std::uint64_t> landmark_ids_;
  std::uint64_t records_ = 0;   // after the header, landmarks included
  std::uint64_t end_line_ = 0;  // the end marker's line; 0 until it is read
};

namespace {

void require_finite(double v, const char* what) {
  if (!std::isfinite(v)) {
    throw std::invalid_argument(std::string("LogWriter: ") + what + " is not finite");
  }
}

}  // namespace

bool operator==(const LogHeader& a, const LogHeader& b) {
  const engine::MotionConfig& m = a.motion;
  const engine::MotionConfig& n = b.motion;
  const engine::SensorConfig& s = a.sensor;
  const engine::SensorConfig& t = b.sensor;
  // Only the parameters of the header's motion kind are part of a log.
  bool parameters = true;
  for (const engine::MotionParameter& p : engine::motion_parameters(m.kind)) {
    parameters = parameters && same_bits(p.get(m), p.get(n));
  }
  return m.kind == n.kind && parameters && same_bits(m.sigma_control[0], n.sigma_control[0]) &&
         same_bits(m.sigma_control[1], n.sigma_control[1]) &&
         same_bits(s.sigma_range, t.sigma_range) && same_bits(s.sigma_bearing, t.sigma_bearing) &&
         same_bits(s.max_range, t.max_range) && same_bits(s.field_of_view, t.field_of_view) &&
         same_bits(s.offset.x, t.offset.x) && same_bits(s.offset.y, t.offset.y) &&
         same_bits(s.offset.yaw, t.offset.yaw) && same_bits(a.start_time, b.start_time) &&
         same_bits(a.start_pose[0], b.start_pose[0]) &&
         same_bits(a.start_pose[1], b.start_pose[1]) && same_bits(a.start_pose[2], b.start_pose[2]);
}

bool operator==(const Event& a, const Event& b) {
  return a.kind == b.kind && same_bits(a.time, b.time) && same_bits(a.dt, b.dt) &&
         same_bits(a.control.u0, b.control.u0) && same_bits(a.control.u1, b.control.u1) &&
         same_bits(a.x, b.x) && same_bits(a.y, b.y) && same_bits(a.theta, b.theta) &&
         a.first == b.first && a.count == b.count;
}

bool operator==(const Log& a, const Log& b) {
  if (!(a.header == b.header) || a.events != b.events || a.landmarks != b.landmarks ||
      a.observations.size() != b.observations.size()) {
    return false;
  }
  for (std::size_t i = 0; i < a.observations.size(); ++i) {
    const engine::Observation& p = a.observations[i];
    const engine::Observation& q = b.observations[i];
    if (!same_bits(p.range, q.range) || !same_bits(p.bearing, q.bearing) || p.id != q.id) {
      return false;
    }
  }
  return true;
}

LogReader::LogReader(std::istream& in, const std::string& name)
    : parser_(std::make_unique<Parser>(in, name)) {
  parser_->header(header_);
}

LogReader::~LogReader() = default;

bool LogReader::next(Event& event, std::vector<engine::Observation>& scan) {
  if (!parser_->next(event, scan, landmarks_)) return false;
  line_ = parser_->line();
  return true;
}

bool LogReader::ended() const noexcept { return parser_->ended(); }

std::string unterminated_log_warning(const std::string& name) {
  return name +
         ": the log has no end marker ('end N'), so it may be truncated; regenerate it from its "
         "data with `fastslam convert`, which ends it with one (docs/log-format.md)";
}

Log read_log(std::istream& in, const std::string& name) {
  LogReader reader(in, name);
  Log log;
  log.header = reader.header();
  Event e;
  std::vector<engine::Observation> scan;
  while (reader.next(e, scan)) {
    if (e.kind == EventKind::kScan) {
      e.first = log.observations.size();
      log.observations.insert(log.observations.end(), scan.begin(), scan.end());
    }
    log.events.push_back(e);
    log.lines.push_back(reader.line());
  }
  log.landmarks = reader.landmarks();
  log.unterminated = !reader.ended();
  return log;
}

Log read_log(const std::string& path) {
  const std::unique_ptr<std::istream> in = open_log_file(path);
  return read_log(*in, path);
}

std::unique_ptr<std::istream> open_log_file(const std::string& path) {
  // A directory opens as a file on Linux and fails at the first read: refused here instead.
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) {
    throw std::runtime_error(path + ": is a directory, not a log file");
  }
  errno = 0;
  auto in = std::make_unique<std::ifstream>(path);
  if (!*in) {
    throw std::runtime_error(path + ": cannot open for reading" +
                             (errno != 0 ? std::string(": ") + std::strerror(errno) : ""));
  }
  return in;
}

// ---- writing ----

namespace {

void put(std::string& line, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);  // shortest exact form
  line += ' ';
  line.append(buf, static_cast<std::size_t>(r.ptr - buf));
}

void put(std::string& line, std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  line += ' ';
  line.append(buf, static_cast<std::size_t>(r.ptr - buf));
}

}  // namespace

LogWriter::LogWriter(std::ostream& out, const LogHeader& h) : out_(out), last_time_(h.start_time) {
  const engine::MotionConfig& m = h.motion;
  const engine::SensorConfig& s = h.sensor;
  if (!engine::enum_known(m.kind)) throw std::invalid_argument("LogWriter: unknown motion kind");
  const std::span<const engine::MotionParameter> parameters = engine::motion_parameters(m.kind);
  for (const engine::MotionParameter& p : parameters) require_finite(p.get(m), "a header value");
  for (double v : {m.sigma_control[0], m.sigma_control[1], s.sigma_range, s.sigma_bearing,
                   s.max_range, s.field_of_view, s.offset.x, s.offset.y, s.offset.yaw, h.start_time,
                   h.start_pose[0], h.start_pose[1], h.start_pose[2]}) {
    require_finite(v, "a header value");
  }
  std::string& l = line_;
  l = "fastslam-log 1\n# docs/log-format.md\nmotion ";
  l += engine::enum_name(m.kind);
  for (const engine::MotionParameter& p : parameters) put(l, p.get(m));
  l += "\ncontrol_noise";
  put(l, m.sigma_control[0]);
  put(l, m.sigma_control[1]);
  l += "\n# sensor SIGMA_RANGE SIGMA_BEARING MAX_RANGE FIELD_OF_VIEW OFFSET_X OFFSET_Y OFFSET_YAW"
       "\nsensor";
  for (double v : {s.sigma_range, s.sigma_bearing, s.max_range, s.field_of_view, s.offset.x,
                   s.offset.y, s.offset.yaw}) {
    put(l, v);
  }
  l += "\n# start T X Y THETA\nstart";
  put(l, h.start_time);
  for (double v : h.start_pose) put(l, v);
  l += "\nend_header\n";
  out_ << l;
}

void LogWriter::open_record() {
  if (finished_) throw std::logic_error("LogWriter: a record after finish()");
  ++records_;
}

void LogWriter::finish() {
  if (finished_) throw std::logic_error("LogWriter: finish() twice");
  finished_ = true;
  line_ = "end";
  put(line_, records_);
  line_ += '\n';
  out_ << line_;
}

void LogWriter::stamp(double time) {
  require_finite(time, "time");
  if (time < last_time_) throw std::invalid_argument("LogWriter: time goes backwards");
  open_record();
  last_time_ = time;
}

void LogWriter::landmark(const TruthLandmark& m) {
  require_finite(m.x, "landmark x");
  require_finite(m.y, "landmark y");
  open_record();
  line_ = "landmark";
  put(line_, m.id);
  put(line_, m.x);
  put(line_, m.y);
  line_ += '\n';
  out_ << line_;
}

void LogWriter::control(double time, double dt, const engine::Control& u) {
  require_finite(dt, "dt");
  require_finite(u.u0, "control");
  require_finite(u.u1, "control");
  if (dt < 0) throw std::invalid_argument("LogWriter: dt is negative");
  stamp(time);
  line_ = "control";
  for (double v : {time, dt, u.u0, u.u1}) put(line_, v);
  line_ += '\n';
  out_ << line_;
}

void LogWriter::scan(double time, std::span<const engine::Observation> zs) {
  for (const engine::Observation& z : zs) {
    require_finite(z.range, "range");
    require_finite(z.bearing, "bearing");
    if (!(z.range > 0)) throw std::invalid_argument("LogWriter: range must be > 0");
    if (z.id < -1) throw std::invalid_argument("LogWriter: id must be >= 0 or -1 (none)");
  }
  stamp(time);
  line_ = "scan";
  put(line_, time);
  put(line_, static_cast<std::uint64_t>(zs.size()));
  for (const engine::Observation& z : zs) {
    put(line_, z.range);
    put(line_, z.bearing);
    if (z.id < 0) {
      line_ += " -";
    } else {
      put(line_, static_cast<std::uint64_t>(z.id));
    }
  }
  line_ += '\n';
  out_ << line_;
}

void LogWriter::truth_pose(double time, double x, double y, double theta) {
  for (double v : {x, y, theta}) require_finite(v, "pose");
  stamp(time);
  line_ = "pose";
  for (double v : {time, x, y, theta}) put(line_, v);
  line_ += '\n';
  out_ << line_;
}

void LogWriter::gps(double time, double x, double y) {
  require_finite(x, "gps x");
  require_finite(y, "gps y");
  stamp(time);
  line_ = "gps";
  for (double v : {time, x, y}) put(line_, v);
  line_ += '\n';
  out_ << line_;
}

void LogWriter::event(const Log& log, const Event& e) {
  switch (e.kind) {
    case EventKind::kControl:
      control(e.time, e.dt, e.control);
      return;
    case EventKind::kScan: {
      if (e.first > log.observations.size() || e.count > log.observations.size() - e.first) {
        throw std::invalid_argument("LogWriter: a scan's observations are out of bounds");
      }
      scan(e.time,
           std::span<const engine::Observation>(log.observations).subspan(e.first, e.count));
      return;
    }
    case EventKind::kTruthPose:
      truth_pose(e.time, e.x, e.y, e.theta);
      return;
    case EventKind::kGps:
      gps(e.time, e.x, e.y);
      return;
  }
  throw std::invalid_argument("LogWriter: unknown event kind");
}

void write_log(std::ostream& out, const Log& log) {
  LogWriter writer(out, log.header);
  for (const TruthLandmark& m : log.landmarks) writer.landmark(m);
  for (const Event& e : log.events) writer.event(log, e);
  writer.finish();
}

void write_log(const std::string& path, const Log& log) {
  // Format into memory first so a log that would not read back leaves no file behind.
  std::ostringstream text;
  write_log(text, log);
  write_file_atomically(path, text.view());
}

}  // namespace fastslam::tools
