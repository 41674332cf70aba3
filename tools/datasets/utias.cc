#include "tools/datasets/utias.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "engine/angles.h"
#include "tools/io/decimal.h"

namespace fastslam::tools {
namespace {

// Landmark_Groundtruth.dat lists these two subjects at each other's position (README: their
// detections fit Vicon only at the other's position).
constexpr std::uint64_t kSwappedA = 11;
constexpr std::uint64_t kSwappedB = 17;

// A whitespace-separated table ('#' starts a comment, blank lines skipped), row by row; every
// refusal names the file and the line.
class TableReader {
 public:
  TableReader(const std::string& dir, const std::string& name, std::vector<const char*> columns)
      : path_(dir + "/" + name), columns_(std::move(columns)), in_(path_) {
    if (!in_) {
      throw std::runtime_error(path_ +
                               ": cannot open for reading (--data must be the UTIAS MRCLAM "
                               "dataset1 directory, e.g. ../shared/data/utias_mrclam/dataset1)");
    }
  }

  bool next(std::span<double> out) {
    while (std::getline(in_, text_)) {
      ++line_;
      std::string_view rest(text_);
      rest = rest.substr(0, rest.find('#'));
      std::size_t n = 0;
      for (;;) {
        const std::size_t begin = rest.find_first_not_of(" \t\r");
        if (begin == std::string_view::npos) break;
        rest.remove_prefix(begin);
        const std::string_view field = rest.substr(0, rest.find_first_of(" \t\r"));
        rest.remove_prefix(field.size());
        if (n < columns_.size()) parse(field, n, out[n]);
        ++n;
      }
      if (n == 0) continue;
      if (n != columns_.size()) {
        fail("expected " + std::to_string(columns_.size()) + " columns, found " +
             std::to_string(n));
      }
      ++rows_;
      return true;
    }
    if (in_.bad()) fail("read error");
    return false;
  }

  // A column that must hold an integer >= `min`.
  std::int64_t integer(double v, std::size_t column, std::int64_t min) const {
    if (!(v >= static_cast<double>(min)) || v != std::floor(v) || v > 9.0e15) {
      fail(std::string("column '") + columns_[column] +
           "' must be an integer >= " + std::to_string(min) + " (got " + std::to_string(v) + ")");
    }
    return static_cast<std::int64_t>(v);
  }

  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(path_ + ":" + std::to_string(line_) + ": " + what);
  }
  std::size_t rows() const { return rows_; }  // data rows read so far

 private:
  void parse(std::string_view field, std::size_t column, double& value) const {
    const auto [end, ec] = parse_double(field.data(), field.data() + field.size(), value);
    if (ec != std::errc() || end != field.data() + field.size()) {
      fail(std::string("column '") + columns_[column] + "': '" + std::string(field) +
           "' is not a number");
    }
    if (!std::isfinite(value)) {
      fail(std::string("column '") + columns_[column] + "': '" + std::string(field) +
           "' is not finite");
    }
  }

  std::string path_;
  std::vector<const char*> columns_;
  std::ifstream in_;
  std::string text_;
  std::size_t line_ = 0;
  std::size_t rows_ = 0;
};

// Row k of a 50 Hz file is at 0.02 k, printed with 5 significant digits (so to 0.1 s from
// 1000 s on: README). REQUIRES: k is the row's 0-based index.
void check_row_time(const TableReader& reader, double printed, std::size_t k) {
  const double exact = static_cast<double>(k) / 50.0;  // correctly rounded 0.02 k
  const double unit = k == 0 ? 0.0 : std::pow(10.0, std::floor(std::log10(exact)) - 4);
  if (!(std::abs(printed - exact) <= 0.5 * unit + 1e-9)) {
    reader.fail("time " + std::to_string(printed) + " is not row " + std::to_string(k) +
                "'s time 0.02 x " + std::to_string(k) + " = " + std::to_string(exact) +
                " (rows are a 50 Hz grid from 0, times printed to 5 significant digits)");
  }
}

std::string file_of(int robot, const char* what) {
  return "Robot" + std::to_string(robot) + "_" + what + ".dat";
}

// Near +-pi the resampled Vicon heading has runs of a few rows averaged across the wrap (off by
// up to pi for 20-80 ms). A row is such a glitch when it is farther from the last good heading
// than kUtiasMaxHeadingStep per row since; a run of glitches is replaced by the straight turn
// between the good rows around it. A run longer than kUtiasMaxGlitchRows is taken as real (the
// heading starts over from it). Returns the rows replaced.
std::size_t repair_headings(std::vector<std::array<double, 3>>& poses) {
  std::size_t repaired = 0;
  std::size_t good = 0;  // the last good row
  std::vector<std::size_t> run;
  for (std::size_t k = 1; k < poses.size(); ++k) {
    const double step = engine::wrap_angle(poses[k][2] - poses[good][2]);
    if (std::abs(step) > kUtiasMaxHeadingStep * static_cast<double>(run.size() + 1)) {
      run.push_back(k);
      if (run.size() > kUtiasMaxGlitchRows) {
        good = k;
        run.clear();
      }
      continue;
    }
    for (std::size_t j = 0; j < run.size(); ++j) {
      const double f = static_cast<double>(j + 1) / static_cast<double>(run.size() + 1);
      poses[run[j]][2] = engine::wrap_angle(poses[good][2] + f * step);
    }
    repaired += run.size();
    run.clear();
    good = k;
  }
  return repaired;
}

}  // namespace

double utias_odometry_lead(const UtiasOptions& options) {
  return options.odometry_lead ? *options.odometry_lead
                               : kUtiasOdometryLead[static_cast<std::size_t>(options.robot - 1)];
}

Utias read_utias(const std::string& dir, const UtiasOptions& options) {
  if (options.robot < 1 || options.robot > kUtiasRobots) {
    throw std::invalid_argument("UTIAS MRCLAM: robot must be 1.." + std::to_string(kUtiasRobots) +
                                " (got " + std::to_string(options.robot) + ")");
  }
  if (options.truth_every < 1) {
    throw std::invalid_argument("UtiasOptions: truth_every must be >= 1");
  }
  const double lead = utias_odometry_lead(options);
  if (!(lead >= 0.0 && lead <= kUtiasMaxOdometryLead)) {
    throw std::invalid_argument("UTIAS MRCLAM: the odometry lead must be 0.." +
                                std::to_string(kUtiasMaxOdometryLead) + " s (got " +
                                std::to_string(lead) + ")");
  }
  Utias out;
  out.robot = options.robot;
  Log& log = out.log;
  std::vector<Event>& events = log.events;
  std::array<double, 5> row{};

  // Barcode -> subject.
  std::unordered_map<std::int64_t, std::int64_t> subject_of;
  {
    TableReader reader(dir, "Barcodes.dat", {"subject", "barcode"});
    while (reader.next(row)) {
      const std::int64_t subject = reader.integer(row[0], 0, 1);
      const std::int64_t barcode = reader.integer(row[1], 1, 0);
      const auto [at, fresh] = subject_of.emplace(barcode, subject);
      if (!fresh) {
        reader.fail("barcode " + std::to_string(barcode) + " is listed twice (subjects " +
                    std::to_string(at->second) + " and " + std::to_string(subject) + ")");
      }
    }
    if (subject_of.empty()) reader.fail("no barcodes");
  }

  {
    TableReader reader(dir, "Landmark_Groundtruth.dat", {"subject", "x", "y", "x_std", "y_std"});
    std::unordered_set<std::int64_t> seen;
    while (reader.next(row)) {
      const std::int64_t subject = reader.integer(row[0], 0, kUtiasRobots + 1);
      if (!seen.insert(subject).second) {
        reader.fail("landmark " + std::to_string(subject) + " is listed twice");
      }
      log.landmarks.push_back({static_cast<std::uint64_t>(subject), row[1], row[2]});
    }
    if (log.landmarks.empty()) reader.fail("no landmarks");
    auto find = [&](std::uint64_t id) {
      return std::find_if(log.landmarks.begin(), log.landmarks.end(),
                          [id](const TruthLandmark& l) { return l.id == id; });
    };
    const auto a = find(kSwappedA), b = find(kSwappedB);
    if (a != log.landmarks.end() && b != log.landmarks.end()) {
      std::swap(a->x, b->x);
      std::swap(a->y, b->y);
    }
  }

  // Controls: sample k held over [0.02 k, 0.02 (k + 1)), stamped at the end, both `lead` later:
  // the motion the odometry measures happens that much after its row's time.
  {
    TableReader reader(dir, file_of(options.robot, "Odometry"), {"time", "v", "omega"});
    while (reader.next(row)) {
      const std::size_t k = reader.rows() - 1;
      check_row_time(reader, row[0], k);
      Event e;
      e.kind = EventKind::kControl;
      e.time = static_cast<double>(k + 1) / 50.0 + lead;
      e.dt = kUtiasPeriod;
      e.control = {row[1], row[2]};
      events.push_back(e);
    }
    if (reader.rows() == 0) reader.fail("no odometry rows");
    out.odometry_samples = reader.rows();
  }

  {
    TableReader reader(dir, file_of(options.robot, "Groundtruth"), {"time", "x", "y", "heading"});
    std::vector<std::array<double, 3>> poses;
    while (reader.next(row)) {
      check_row_time(reader, row[0], reader.rows() - 1);
      poses.push_back({row[1], row[2], engine::wrap_angle(row[3])});
    }
    out.truth_headings_repaired = repair_headings(poses);
    for (std::size_t k = 0; k < poses.size(); ++k) {
      if (k == 0) std::copy(poses[0].begin(), poses[0].end(), log.header.start_pose);
      if (k % static_cast<std::size_t>(options.truth_every) != 0) continue;
      Event e;
      e.kind = EventKind::kTruthPose;
      e.time = static_cast<double>(k) / 50.0;
      e.x = poses[k][0];
      e.y = poses[k][1];
      e.theta = poses[k][2];
      events.push_back(e);
      ++out.truth_poses;
    }
    if (reader.rows() == 0) reader.fail("no ground-truth rows: the start pose is the first one");
    out.truth_rows = reader.rows();
  }

  // Scans: the detections of one printed time; a scan holding none (only robots, or dropped
  // unlabelled ones) is not emitted. A landmark seen twice at one time starts a new scan at
  // the same time (known association refuses a repeated id within a scan).
  {
    TableReader reader(dir, file_of(options.robot, "Measurement"),
                       {"time", "barcode", "range", "bearing"});
    Event e;
    e.kind = EventKind::kScan;
    e.time = -1.0;
    std::unordered_set<std::int64_t> in_scan;
    auto close_scan = [&] {
      if (e.count > 0) {
        events.push_back(e);
        ++out.scans;
      }
      e.first = log.observations.size();
      e.count = 0;
      in_scan.clear();
    };
    while (reader.next(row)) {
      if (row[0] < 0) reader.fail("time must be >= 0 (got " + std::to_string(row[0]) + ")");
      if (row[0] < e.time) {
        reader.fail("time goes backwards (" + std::to_string(row[0]) + " after " +
                    std::to_string(e.time) + ")");
      }
      const std::int64_t barcode = reader.integer(row[1], 1, 0);
      if (!(row[2] > 0)) reader.fail("range must be > 0 (got " + std::to_string(row[2]) + ")");
      if (std::abs(row[3]) > std::numbers::pi) {
        reader.fail("bearing must be within [-pi, pi] (got " + std::to_string(row[3]) + ")");
      }
      if (row[0] != e.time) {
        close_scan();
        e.time = row[0];
      }
      ++out.measurements;
      out.rounded_measurements += row[0] >= kUtiasExactBefore;
      const auto found = subject_of.find(barcode);
      std::int64_t id = -1;
      if (found == subject_of.end()) {
        ++out.unlabelled_detections;
        if (!options.unlabelled) continue;
      } else if (found->second <= kUtiasRobots) {
        ++out.robot_detections_dropped;
        continue;
      } else {
        id = found->second;
        ++out.landmark_detections;
        if (!in_scan.insert(id).second) {
          ++out.repeated_in_scan;
          close_scan();
          in_scan.insert(id);
        }
      }
      log.observations.push_back({row[2], row[3], id});
      ++e.count;
    }
    close_scan();
  }

  // One time order; on equal times control, scan, truth (EventKind's order): a scan at t sees
  // the pose after the control ending at t. Scans keep their observation ranges.
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    return a.time < b.time || (a.time == b.time && a.kind < b.kind);
  });

  LogHeader& h = log.header;
  h.motion.kind = engine::MotionKind::kUnicycle;
  h.motion.sigma_control[0] = kUtiasSigmaV;
  h.motion.sigma_control[1] = kUtiasSigmaOmega;
  h.sensor.sigma_range = kUtiasSigmaRange * kUtiasSensorWidth;
  h.sensor.sigma_bearing = kUtiasSigmaBearing * kUtiasSensorWidth;
  h.sensor.max_range = kUtiasMaxRange;
  h.sensor.field_of_view = kUtiasFieldOfView;
  h.start_time = 0.0;
  return out;
}

}  // namespace fastslam::tools
