#include "tools/io/log_format.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <unistd.h>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "engine/motion_dispatch.h"
#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

// A log with every record kind and awkward doubles (not short in decimal, subnormal, -0, huge).
Log sample_log(engine::MotionKind kind) {
  Log log;
  LogHeader& h = log.header;
  h.motion.kind = kind;
  h.motion.wheelbase = 2.0 / 3.0;
  h.motion.geometry = {3.78, 0.5, 2.83, 0.76};
  h.motion.sigma_control[0] = 0.1 + 0.2;
  h.motion.sigma_control[1] = std::numbers::pi / 60;
  h.sensor.sigma_range = 0.1;
  h.sensor.sigma_bearing = std::numbers::pi / 180;
  h.sensor.max_range = 30.000000000000004;
  h.sensor.field_of_view = std::numbers::pi;
  h.sensor.offset = {0.25, -0.125, 1e-300};
  h.start_time = -0.0;
  h.start_pose[0] = -67.649271;
  h.start_pose[1] = 4.9e-324;  // the smallest subnormal
  h.start_pose[2] = 0.6632251157578453;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  double t = 0.0;
  for (int k = 0; k < 50; ++k) {
    t += 0.025;
    Event c;
    c.kind = EventKind::kControl;
    c.time = t;
    c.dt = 0.025;
    c.control = {u(rng), u(rng) / 1000};
    log.events.push_back(c);
    Event p;
    p.kind = EventKind::kTruthPose;
    p.time = t;
    p.x = u(rng);
    p.y = u(rng) * 1e20;
    p.theta = std::remainder(u(rng), 2 * std::numbers::pi);
    log.events.push_back(p);
    if (k % 5 == 0) {
      Event s;
      s.kind = EventKind::kScan;
      s.time = t;
      s.first = log.observations.size();
      s.count = static_cast<std::uint32_t>(k % 4);  // empty scans too
      for (std::uint32_t j = 0; j < s.count; ++j) {
        log.observations.push_back(
            {std::abs(u(rng)) + 1e-9, u(rng) / 50, j % 2 == 0 ? std::int64_t{-1} : k * 10 + j});
      }
      log.events.push_back(s);
    }
    if (k % 8 == 0) {
      Event g;
      g.kind = EventKind::kGps;
      g.time = t;
      g.x = u(rng);
      g.y = u(rng);
      log.events.push_back(g);
    }
  }
  log.landmarks = {{0, 1.5, -2.5}, {7, u(rng), u(rng)}, {std::uint64_t{1} << 40, 1e-17, 3e17}};
  return log;
}

TEST(LogFormat, RoundTripIsBitExactForEveryMotionKind) {
  for (const auto& entry : engine::EnumNames<engine::MotionKind>::kNames) {
    if (entry.alias) continue;
    const engine::MotionKind kind = entry.value;
    const Log log = sample_log(kind);
    std::stringstream text;
    write_log(text, log);
    const Log back = read_log(text, "memory");
    EXPECT_TRUE(back == log) << engine::to_string(kind);
    EXPECT_EQ(back.header.motion.kind, kind);
    if (kind == engine::MotionKind::kBrownianCurvature) {
      EXPECT_NE(text.str().find("\nmotion none-curvature\n"), std::string::npos) << text.str();
    }
    EXPECT_EQ(back.events.size(), log.events.size());
    EXPECT_EQ(std::bit_cast<std::uint64_t>(back.header.start_pose[1]),
              std::bit_cast<std::uint64_t>(4.9e-324));
    EXPECT_TRUE(std::signbit(back.header.start_time));  // -0 stays -0
    // Writing what was read gives the same text.
    std::stringstream again;
    write_log(again, back);
    EXPECT_EQ(again.str(), text.str());
  }
}

TEST(LogFormat, EqualityNoticesAOneUlpChange) {
  const Log log = sample_log(engine::MotionKind::kBaileyCar);
  Log other = log;
  other.observations[1].bearing = std::nextafter(other.observations[1].bearing, 10.0);
  EXPECT_FALSE(other == log);
  other = log;
  other.events[3].control.u1 = std::nextafter(other.events[3].control.u1, 10.0);
  EXPECT_FALSE(other == log);
}

TEST(LogFormat, FileRoundTripAndTheDocumentedShape) {
  const Log log = sample_log(engine::MotionKind::kAckermann);
  const std::string path = testing::temp_path("log_test") + ".log";
  write_log(path, log);
  EXPECT_TRUE(read_log(path) == log);
  std::ifstream in(path);
  std::string first, motion;
  std::getline(in, first);
  EXPECT_EQ(first, "fastslam-log 1");
  while (std::getline(in, motion) && motion.rfind("motion", 0) != 0) {
  }
  EXPECT_EQ(motion, "motion ackermann 3.78 0.5 2.83 0.76");
  std::filesystem::remove(path);
}

// Logs written before the Ackermann model had its generic name say `victoria-park`: they read as
// the same model and parameters, and are written back under the canonical name.
TEST(LogFormat, ReadsTheVictoriaParkAliasAsAckermann) {
  const Log log = sample_log(engine::MotionKind::kAckermann);
  std::stringstream text;
  write_log(text, log);
  std::string old = text.str();
  const std::string motion = "\nmotion ackermann ";
  const std::size_t at = old.find(motion);
  ASSERT_NE(at, std::string::npos);
  old.replace(at, motion.size(), "\nmotion victoria-park ");
  std::istringstream in(old);
  const Log back = read_log(in, "old.log");
  EXPECT_EQ(back.header.motion.kind, engine::MotionKind::kAckermann);
  EXPECT_EQ(back.header.motion.geometry.a, 3.78);
  EXPECT_EQ(back.header.motion.geometry.h, 0.76);
  EXPECT_TRUE(back == log);
  std::stringstream again;
  write_log(again, back);
  EXPECT_EQ(again.str(), text.str());
}

constexpr const char* kHeader =
    "fastslam-log 1\n"
    "motion bailey-car 4\n"
    "control_noise 0.3 0.05\n"
    "sensor 0.1 0.017 30 3.14 0 0 0\n"
    "start 0 0 0 0\n"
    "end_header\n";  // records start on line 7

std::string error_of(const std::string& text) {
  std::istringstream in(text);
  try {
    read_log(in, "x.log");
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(LogFormat, ReadsCommentsBlankLinesAndUnknownIds) {
  std::istringstream in(std::string(kHeader) +
                        "# a comment\n\ncontrol 0.5 0.5 3 0.1\r\nscan 0.5 2 10 0.5 - 20 -0.5 3\n"
                        "gps 0.6 1 2\nlandmark 3 5 6\n");
  const Log log = read_log(in, "x.log");
  ASSERT_EQ(log.events.size(), 3u);
  EXPECT_EQ(log.events[1].kind, EventKind::kScan);
  EXPECT_EQ(log.events[1].count, 2u);
  ASSERT_EQ(log.observations.size(), 2u);
  EXPECT_EQ(log.observations[0].id, -1);
  EXPECT_EQ(log.observations[1].id, 3);
  EXPECT_EQ(log.observations[1].bearing, -0.5);
  EXPECT_EQ(log.header.motion.wheelbase, 4.0);
  ASSERT_EQ(log.landmarks.size(), 1u);
  EXPECT_EQ(log.landmarks[0], (TruthLandmark{3, 5, 6}));
}

TEST(LogFormat, RefusesEveryMalformedClassNamingFileLineAndReason) {
  const std::string h = kHeader;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "x.log:0: empty file"},
      {"fastslam-log 2\n", "x.log:1: unsupported version 2"},
      {"hello 1\n", "x.log:1: not a fastslam log"},
      {"fastslam-log 1\nmotion bailey-car 4\n", "x.log:2: end of file inside the header"},
      {"fastslam-log 1\nmotion bicycle 4\n", "x.log:2: unknown motion kind 'bicycle'"},
      {"fastslam-log 1\nmotion bailey-car\n", "x.log:2: 'motion' needs 3 fields"},
      {"fastslam-log 1\nmotion bailey-car -4\n",
       "x.log:2: BaileyCarModel: wheelbase must be finite and > 0"},
      {"fastslam-log 1\nmotion ackermann 3.78 0.5 2.83\n",
       "x.log:2: 'motion' needs 6 fields (motion ackermann A B L H)"},
      {"fastslam-log 1\nmotion victoria-park 3.78 0.5 0 0.76\n",
       "x.log:2: AckermannModel: geometry must be finite with wheelbase l > 0"},
      {"fastslam-log 1\nmotion ackermann 3.78 0.5 2.83 -1\n",
       "x.log:2: AckermannModel: geometry must be finite"},
      {"fastslam-log 1\nmotion ackermann 3.78 x 2.83 0.76\n", "x.log:2: b: 'x' is not a number"},
      {"fastslam-log 1\nmotion none-curvature 0.1\n", "x.log:2: 'motion' needs 2 fields"},
      {"fastslam-log 1\nmotion none_curvature\n",
       "x.log:2: unknown motion kind 'none_curvature' (bailey-car, unicycle, ackermann, none or "
       "none-curvature)"},
      {"fastslam-log 1\nmotion none-curvature\ncontrol_noise 0.1 -0.01\n",
       "x.log:3: sigma1 must be >= 0"},
      {"fastslam-log 1\nmotion unicycle\nmotion unicycle\n",
       "x.log:3: header line 'motion' is "
       "repeated"},
      {"fastslam-log 1\ncolour blue\n", "x.log:2: unknown header line 'colour'"},
      {"fastslam-log 1\nmotion unicycle\ncontrol_noise 1 1\nsensor 1 1 1 1 0 0 0\nend_header\n",
       "x.log:5: header has no 'start' line"},
      {"fastslam-log 1\nsensor 1 0 1 1 0 0 0\n", "x.log:2: sigma_bearing must be > 0"},
      {"fastslam-log 1\nsensor 1 1 1 7 0 0 0\n", "x.log:2: field_of_view must be at most 2 pi"},
      {"fastslam-log 1\ncontrol 1 1 1 1\n", "x.log:2: unknown header line 'control'"},
      // Records.
      {h + "jump 1 2\n", "x.log:7: unknown record 'jump'"},
      {h + "control 1 0.1 3\n", "x.log:7: 'control' needs 5 fields"},
      {h + "control 1 0.1 3 4 5\n", "x.log:7: 'control' needs 5 fields"},
      {h + "control 1 0.1 three 0\n", "x.log:7: u0: 'three' is not a number"},
      {h + "control 1 0.1 3x 0\n", "x.log:7: u0: '3x' is not a number"},
      {h + "control 1 0.1 nan 0\n", "x.log:7: u0: 'nan' is not finite"},
      {h + "control 1 0.1 1e400 0\n", "x.log:7: u0: '1e400' is out of a double's range"},
      {h + "control 1 0.1 0x1p3 0\n", "x.log:7: u0: '0x1p3' is not a number"},
      // A NUL or a control byte is quoted as \xNN, so the message is not cut short there.
      {h + std::string("control 1 0.1 1\0 0\n", 20), "x.log:7: u0: '1\\x00' is not a number"},
      {h + "control 1 0.1 \x1b[2J 0\n", "x.log:7: u0: '\\x1b[2J' is not a number"},
      {h + "control 1 0.1 0 inf\n", "x.log:7: u1: 'inf' is not finite"},
      {h + "control 1 -0.1 0 0\n", "x.log:7: dt is negative"},
      {h + "control 2 0.1 0 0\ncontrol 1 0.1 0 0\n", "x.log:8: time goes backwards: 1 after 2"},
      {h + "control -1 0.1 0 0\n", "x.log:7: time goes backwards: -1 after 0"},
      {h + "gps 2 0 0\npose 1.5 0 0 0\n", "x.log:8: time goes backwards"},
      {h + "scan 1 2 5 0.1 -\n", "x.log:7: scan of 2 observations needs 9 fields, found 6"},
      {h + "scan 1 1 5 0.1 - 7\n", "x.log:7: scan of 1 observations needs 6 fields, found 7"},
      {h + "scan 1 -1\n", "x.log:7: observation count: '-1' is not a non-negative integer"},
      {h + "scan 1\n", "x.log:7: scan needs"},
      {h + "scan 1 1 -5 0.1 -\n", "x.log:7: range must be > 0 (got -5)"},
      {h + "scan 1 1 0 0.1 -\n", "x.log:7: range must be > 0 (got 0)"},
      {h + "scan 1 1 5 NaN -\n", "x.log:7: bearing: 'NaN' is not finite"},
      {h + "scan 1 1 5 0.1 -3\n", "x.log:7: id: '-3' is not a non-negative integer"},
      {h + "scan 1 1 5 0.1 2.5\n", "x.log:7: id: '2.5' is not a non-negative integer"},
      {h + "pose 1 0 0\n", "x.log:7: 'pose' needs 5 fields"},
      {h + "gps 1 0 0 0\n", "x.log:7: 'gps' needs 4 fields"},
      {h + "landmark 1 0 0\nlandmark 1 2 2\n", "x.log:8: landmark id 1 is repeated"},
      {h + "landmark 1 0\n", "x.log:7: 'landmark' needs 4 fields"},
      {h + "end_header\n", "x.log:7: unknown record 'end_header'"},
      {h + "end\n", "x.log:7: 'end' needs 2 fields (end RECORDS)"},
      {h + "end -1\n", "x.log:7: record count: '-1' is not a non-negative integer"},
      {h + "control 1 0.1 0 0\nend 0\n",
       "x.log:8: the end marker counts 0 records, but the log has 1 before it"},
      {h + "end 0\nend 0\n", "x.log:8: 'end' after the end marker (line 7)"},
      {"fastslam-log 1\nend 0\n", "x.log:2: unknown header line 'end'"},
  };
  for (const auto& [text, expected] : cases) {
    const std::string e = error_of(text);
    EXPECT_NE(e.find(expected), std::string::npos) << "got: " << e << "\nexpected: " << expected;
  }
}

// Input that is not a log is refused within one line's limit, not read whole: a stream of NUL
// bytes that never ends (--data /dev/zero) stops after about kMaxLogLineBytes.
TEST(LogFormat, InputWithoutNewlinesFailsAtTheLineLimit) {
  class Zeros : public std::streambuf {
   public:
    std::size_t served = 0;

   protected:
    int_type underflow() override {
      served += sizeof(chunk_);
      setg(chunk_, chunk_, chunk_ + sizeof(chunk_));
      return traits_type::to_int_type(chunk_[0]);
    }

   private:
    char chunk_[4096] = {};
  };
  Zeros zeros;
  std::istream in(&zeros);
  const std::string expected = "zeros:1: line longer than " + std::to_string(kMaxLogLineBytes) +
                               " bytes (the format's limit, docs/log-format.md)";
  try {
    read_log(in, "zeros");
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).rfind(expected, 0), 0U) << e.what();
  }
  EXPECT_LE(zeros.served, kMaxLogLineBytes + 8192);
}

TEST(LogFormat, LinesUpToTheLimitAreReadAndLongerOnesNamed) {
  const std::string h = kHeader;
  // A comment of exactly the limit is a line like any other.
  std::string text = h + "#" + std::string(kMaxLogLineBytes - 1, 'c') + "\ncontrol 1 0.1 0 0\n";
  std::istringstream fits(text);
  EXPECT_EQ(read_log(fits, "x.log").events.size(), 1U);
  text = h + "control 1 0.1 0 0\n#" + std::string(kMaxLogLineBytes, 'c') + "\n";
  EXPECT_NE(error_of(text).find("x.log:8: line longer than"), std::string::npos)
      << error_of(text).substr(0, 200);
}

TEST(LogFormat, ScansOverTheLimitAndLongTokensAreRefusedBriefly) {
  const std::string h = kHeader;
  const std::string over = std::to_string(kMaxScanObservations + 1);
  EXPECT_NE(error_of(h + "scan 1 " + over + " 5 0.1 -\n")
                .find("x.log:7: scan of " + over +
                      " observations: more than the format's "
                      "limit of " +
                      std::to_string(kMaxScanObservations)),
            std::string::npos);
  // A bad token of 200000 bytes is quoted by its first kMaxQuotedBytes and its length.
  const std::string junk(200'000, '7');
  for (const std::string& text : {h + "scan 1 1 5 " + junk + "x -\n", h + junk + "x 1 2\n"}) {
    const std::string e = error_of(text);
    EXPECT_LT(e.size(), 300U) << e.substr(0, 400);
    EXPECT_NE(e.find("'" + std::string(kMaxQuotedBytes, '7') + "...' (200001 bytes)"),
              std::string::npos)
        << e.substr(0, 400);
  }
}

// The reader gives read_log's events one at a time, landmarks as they come, the line of each
// event; a malformed record fails where it is, after the events before it were given.
TEST(LogReader, StreamsWhatReadLogReadsAndFailsAtTheBadRecord) {
  const Log log = sample_log(engine::MotionKind::kBaileyCar);
  std::ostringstream text;
  write_log(text, log);
  std::istringstream whole(text.str());
  const Log want = read_log(whole, "x.log");
  std::istringstream in(text.str());
  LogReader reader(in, "x.log");
  EXPECT_TRUE(reader.header() == log.header);
  Event e;
  std::vector<engine::Observation> scan;
  std::size_t k = 0;
  while (reader.next(e, scan)) {
    ASSERT_LT(k, want.events.size());
    const Event& w = want.events[k];
    EXPECT_EQ(e.kind, w.kind);
    EXPECT_EQ(std::bit_cast<std::uint64_t>(e.time), std::bit_cast<std::uint64_t>(w.time));
    EXPECT_EQ(reader.line(), want.lines[k]);
    if (e.kind == EventKind::kScan) {
      ASSERT_EQ(scan.size(), w.count);
      for (std::size_t j = 0; j < scan.size(); ++j) {
        const engine::Observation& z = want.observations[w.first + j];
        EXPECT_EQ(std::bit_cast<std::uint64_t>(scan[j].range),
                  std::bit_cast<std::uint64_t>(z.range));
        EXPECT_EQ(scan[j].id, z.id);
      }
    }
    ++k;
  }
  EXPECT_EQ(k, want.events.size());
  EXPECT_EQ(reader.landmarks(), log.landmarks);

  // A bad record after three events: those three come out, then the error names its line.
  std::string broken;
  std::istringstream lines(text.str());
  std::string line;
  std::uint64_t number = 0, events = 0, bad_line = 0;
  while (std::getline(lines, line)) {
    ++number;
    broken += line + "\n";
    if (line.rfind("control", 0) == 0 && ++events == 3) {
      broken += "control 99 0.1 nan 0\n";
      bad_line = number + 1;
      break;
    }
  }
  std::istringstream bad(broken);
  LogReader partial(bad, "<stdin>");
  std::size_t given = 0;
  try {
    while (partial.next(e, scan)) ++given;
    ADD_FAILURE() << "the bad record was accepted";
  } catch (const std::runtime_error& error) {
    EXPECT_EQ(std::string(error.what()).rfind("<stdin>:" + std::to_string(bad_line) + ": ", 0), 0u)
        << error.what();
  }
  EXPECT_GE(given, 3u);
}

// The writer closes a log with `end N`, N its records (landmarks included); the readers accept
// it, hold a log whole only with it, and refuse what would make it a lie.
TEST(LogFormat, TheEndMarkerCountsTheRecordsAndClosesTheLog) {
  const Log log = sample_log(engine::MotionKind::kBaileyCar);
  std::ostringstream written;
  write_log(written, log);
  const std::string text = written.str();
  const std::string end =
      "\nend " + std::to_string(log.events.size() + log.landmarks.size()) + "\n";
  ASSERT_GE(text.size(), end.size());
  EXPECT_EQ(text.substr(text.size() - end.size()), end);
  std::istringstream whole(text);
  const Log back = read_log(whole, "x.log");
  EXPECT_TRUE(back == log);
  EXPECT_FALSE(back.unterminated);
  std::istringstream streamed(text);
  LogReader reader(streamed, "x.log");
  Event e;
  std::vector<engine::Observation> scan;
  std::size_t events = 0;
  while (reader.next(e, scan)) ++events;
  EXPECT_EQ(events, log.events.size());
  EXPECT_TRUE(reader.ended());
  // Comments and blank lines may follow the marker.
  std::istringstream trailing(text + "# the end\n\n");
  EXPECT_FALSE(read_log(trailing, "x.log").unterminated);

  // Any record after it is refused, naming its line and the marker's.
  const std::uint64_t end_line =
      static_cast<std::uint64_t>(std::count(text.begin(), text.end(), '\n'));
  const std::string after = error_of(text + "control 1e9 0.1 0 0\n");
  EXPECT_NE(after.find("x.log:" + std::to_string(end_line + 1) +
                       ": 'control' after the end marker (line " + std::to_string(end_line) +
                       "): the log ends there"),
            std::string::npos)
      << after;
  EXPECT_NE(error_of(text + "landmark 99 0 0\n").find("'landmark' after the end marker"),
            std::string::npos);

  // A count that is not the records': both counts and the marker's line are named.
  std::string lost = text;
  const std::size_t first_control = lost.find("\ncontrol ");
  lost.erase(first_control, lost.find('\n', first_control + 1) - first_control);
  const std::string wrong = error_of(lost);
  EXPECT_NE(wrong.find("x.log:" + std::to_string(end_line - 1) + ": the end marker counts " +
                       std::to_string(log.events.size() + log.landmarks.size()) +
                       " records, but the log has " +
                       std::to_string(log.events.size() + log.landmarks.size() - 1) + " before it"),
            std::string::npos)
      << wrong;
}

// A log cut at a line boundary (or written before the marker existed) is read whole as it is,
// and says it may be truncated.
TEST(LogFormat, ALogWithoutTheEndMarkerReadsAndSaysSo) {
  const Log log = sample_log(engine::MotionKind::kBaileyCar);
  std::ostringstream written;
  write_log(written, log);
  std::string text = written.str();
  text.erase(text.rfind("end "));
  std::istringstream in(text);
  const Log back = read_log(in, "cut.log");
  EXPECT_TRUE(back.unterminated);
  EXPECT_TRUE(back == log);  // what it holds is the same
  std::istringstream streamed(text);
  LogReader reader(streamed, "cut.log");
  Event e;
  std::vector<engine::Observation> scan;
  while (reader.next(e, scan)) {
  }
  EXPECT_FALSE(reader.ended());
  const std::string warning = unterminated_log_warning("cut.log");
  EXPECT_EQ(
      warning.rfind("cut.log: the log has no end marker ('end N'), so it may be truncated", 0), 0u)
      << warning;
  EXPECT_NE(warning.find("fastslam convert"), std::string::npos);
  // A log built in memory has no file to be cut.
  EXPECT_FALSE(log.unterminated);
}

TEST(LogFormat, TheWriterWritesNothingAfterFinish) {
  std::ostringstream out;
  LogWriter writer(out, LogHeader{});
  writer.landmark({1, 2.0, 3.0});
  writer.control(0.5, 0.5, {1.0, 0.0});
  writer.finish();
  EXPECT_THROW(writer.control(1.0, 0.5, {1.0, 0.0}), std::logic_error);
  EXPECT_THROW(writer.landmark({2, 0.0, 0.0}), std::logic_error);
  EXPECT_THROW(writer.finish(), std::logic_error);
  const std::string text = out.str();
  EXPECT_EQ(text.substr(text.size() - 7), "\nend 2\n");
  std::istringstream in(text);
  EXPECT_FALSE(read_log(in, "x.log").unterminated);
}

TEST(LogFormat, NothingPartialAndAMissingFileIsNamed) {
  EXPECT_THROW(read_log("/nonexistent/dir/x.log"), std::runtime_error);
  try {
    read_log("/nonexistent/dir/x.log");
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "/nonexistent/dir/x.log: cannot open for reading: No such file or directory"),
              std::string::npos);
  }
  // A directory opens as a file on Linux; it is named as what it is, not as a read error.
  const std::string dir = testing::temp_path("log_format_dir");
  std::filesystem::create_directories(dir);
  try {
    read_log(dir);
    ADD_FAILURE() << "a directory read as a log";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), dir + ": is a directory, not a log file");
  }
  std::filesystem::remove_all(dir);
}

TEST(LogFormat, WriterRefusesWhatWouldNotReadBack) {
  Log log = sample_log(engine::MotionKind::kBaileyCar);
  std::ostringstream sink;
  {
    Log bad = log;
    std::swap(bad.events[0], bad.events[4]);  // out of time order
    EXPECT_THROW(write_log(sink, bad), std::invalid_argument);
  }
  {
    Log bad = log;
    bad.events[1].x = std::numeric_limits<double>::quiet_NaN();
    EXPECT_THROW(write_log(sink, bad), std::invalid_argument);
  }
  {
    Log bad = log;
    bad.observations.resize(1);
    EXPECT_THROW(write_log(sink, bad), std::invalid_argument);
  }
  {
    Log bad = log;
    bad.observations[0].range = -1;
    EXPECT_THROW(write_log(sink, bad), std::invalid_argument);
  }
  // To a path: nothing is left behind.
  Log bad = log;
  bad.header.sensor.max_range = std::numeric_limits<double>::infinity();
  const std::string path = testing::temp_path("log_bad") + ".log";
  EXPECT_THROW(write_log(path, bad), std::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(path));
}

}  // namespace
}  // namespace fastslam::tools
