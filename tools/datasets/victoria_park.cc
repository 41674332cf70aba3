#include "tools/datasets/victoria_park.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "engine/angles.h"
#include "tools/io/csv.h"

namespace fastslam::tools {
namespace {

// The odometry is exactly 40 Hz (README); the last sample is held for one period.
constexpr double kOdometryPeriod = 0.025;
// A detection's time must equal its scan's time in laser_scan_times.csv to this (both come
// from the same millisecond clock; the files print them with 3 decimals).
constexpr double kScanTimeTolerance = 5e-4;

std::uint64_t as_index(double v, const CsvReader& reader, const char* what) {
  if (v < 0 || v != std::floor(v) || v > 9.0e15) {
    reader.fail(std::string(what) + " must be a non-negative integer");
  }
  return static_cast<std::uint64_t>(v);
}

void check_options(const VictoriaParkOptions& o) {
  const VictoriaParkGate& g = o.gate;
  auto require = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("VictoriaParkOptions: ") + what);
  };
  require(std::isfinite(g.min_range) && std::isfinite(g.max_range) && g.min_range >= 0 &&
              g.min_range < g.max_range,
          "gate ranges must be finite with 0 <= min_range < max_range");
  require(std::isfinite(g.min_bearing) && std::isfinite(g.max_bearing) &&
              g.min_bearing < g.max_bearing && g.min_bearing >= -std::numbers::pi &&
              g.max_bearing <= std::numbers::pi,
          "gate bearings must be finite with -pi <= min_bearing < max_bearing <= pi");
  require(g.max_diameter > 0, "gate max_diameter must be > 0 (infinity for no limit)");
  require(std::isfinite(o.laser_yaw) && std::abs(o.laser_yaw) <= std::numbers::pi,
          "laser_yaw must be finite and within [-pi, pi]");
  for (double s : {o.sigma_speed, o.sigma_steer, o.sigma_range, o.sigma_bearing}) {
    require(std::isfinite(s) && s > 0, "noises must be finite and > 0");
  }
  require(std::isfinite(o.heading_fit_seconds) && o.heading_fit_seconds > 0,
          "heading_fit_seconds must be finite and > 0");
  require(!o.initial_heading || std::isfinite(*o.initial_heading),
          "initial_heading must be finite");
  // The model itself checks the geometry.
  engine::AckermannModel model(o.geometry);
}

struct Odometry {
  double time, speed, steer;
};
struct Fix {
  double time, x, y;
};

}  // namespace

VictoriaPark read_victoria_park(const std::string& dir, const VictoriaParkOptions& options) {
  check_options(options);
  VictoriaPark out;
  Log& log = out.log;
  std::vector<Event>& events = log.events;

  std::vector<Odometry> odometry;
  {
    CsvReader reader(dir + "/odometry.csv", {"time_s", "speed_mps", "steering_rad"});
    std::array<double, 3> row{};
    while (reader.next(row)) {
      if (!odometry.empty() && row[0] < odometry.back().time) {
        reader.fail("time goes backwards (" + std::to_string(row[0]) + " after " +
                    std::to_string(odometry.back().time) + ")");
      }
      odometry.push_back({row[0], row[1], row[2]});
    }
    if (odometry.empty()) reader.fail("no odometry rows");
  }

  // Every scan, with its detection count, from laser_scan_times.csv.
  std::vector<double> scan_time;
  std::vector<std::uint64_t> scan_trees;
  {
    CsvReader reader(dir + "/laser_scan_times.csv", {"scan_index", "time_s", "n_trees"});
    std::array<double, 3> row{};
    while (reader.next(row)) {
      const std::uint64_t index = as_index(row[0], reader, "scan_index");
      if (index != scan_time.size()) {
        reader.fail("scan_index " + std::to_string(index) + " is not the next scan (" +
                    std::to_string(scan_time.size()) + ")");
      }
      if (!scan_time.empty() && row[1] < scan_time.back()) {
        reader.fail("time goes backwards (" + std::to_string(row[1]) + " after " +
                    std::to_string(scan_time.back()) + ")");
      }
      scan_time.push_back(row[1]);
      scan_trees.push_back(as_index(row[2], reader, "n_trees"));
    }
    if (scan_time.empty()) reader.fail("no scans");
  }
  out.scans = scan_time.size();

  {
    const std::string path = dir + "/tree_observations.csv";
    CsvReader reader(path, {"time_s", "scan_index", "range_m", "bearing_rad", "diameter_m"});
    std::array<double, 5> row{};
    std::size_t scan = 0;       // the scan being filled
    std::uint64_t in_scan = 0;  // detections read for it
    Event e;
    e.kind = EventKind::kScan;
    auto close_scans_before = [&](std::size_t next) {
      // Emits scans [scan, next), checking each one's detection count.
      for (; scan < next; ++scan) {
        if (in_scan != scan_trees[scan]) {
          reader.fail("scan " + std::to_string(scan) + " has " + std::to_string(in_scan) +
                      " detections, laser_scan_times.csv says " + std::to_string(scan_trees[scan]));
        }
        e.time = scan_time[scan];
        events.push_back(e);
        e.first = log.observations.size();
        e.count = 0;
        in_scan = 0;
      }
    };
    while (reader.next(row)) {
      const std::uint64_t index = as_index(row[1], reader, "scan_index");
      if (index >= scan_time.size()) {
        reader.fail("scan_index " + std::to_string(index) + " is not in laser_scan_times.csv (" +
                    std::to_string(scan_time.size()) + " scans)");
      }
      if (index < scan) {
        reader.fail("scan_index goes backwards (" + std::to_string(index) + " after " +
                    std::to_string(scan) + ")");
      }
      close_scans_before(index);
      if (std::abs(row[0] - scan_time[index]) > kScanTimeTolerance) {
        reader.fail("time " + std::to_string(row[0]) + " is not scan " + std::to_string(index) +
                    "'s time " + std::to_string(scan_time[index]));
      }
      if (!(row[2] > 0)) reader.fail("range_m must be > 0 (got " + std::to_string(row[2]) + ")");
      if (row[4] < 0) reader.fail("diameter_m must be >= 0 (got " + std::to_string(row[4]) + ")");
      ++in_scan;
      ++out.detections;
      const VictoriaParkGate& g = options.gate;
      if (row[2] < g.min_range || row[2] > g.max_range || row[3] < g.min_bearing ||
          row[3] > g.max_bearing || row[4] > g.max_diameter) {
        ++out.gated_out;
        continue;
      }
      log.observations.push_back({row[2], row[3], -1});
      ++e.count;
    }
    close_scans_before(scan_time.size());
  }

  // The controls: sample k held over [t_k, t_{k+1}), stamped at the end; with
  // split_controls_at_scans, cut at every scan time inside that interval.
  {
    std::size_t next_scan = 0;
    for (std::size_t k = 0; k < odometry.size(); ++k) {
      const bool last = k + 1 == odometry.size();
      const double begin = odometry[k].time;
      const double end = last ? begin + kOdometryPeriod : odometry[k + 1].time;
      Event e;
      e.kind = EventKind::kControl;
      e.control = {odometry[k].speed, odometry[k].steer};
      double from = begin;
      if (options.split_controls_at_scans) {
        while (next_scan < scan_time.size() && scan_time[next_scan] <= begin) ++next_scan;
        for (; next_scan < scan_time.size() && scan_time[next_scan] < end; ++next_scan) {
          e.time = scan_time[next_scan];
          e.dt = e.time - from;
          events.push_back(e);
          from = e.time;
          ++out.split_controls;
        }
      }
      e.time = end;
      e.dt = from == begin && last ? kOdometryPeriod : end - from;  // exact when not cut
      events.push_back(e);
    }
  }
  out.odometry_samples = odometry.size();

  std::vector<Fix> gps;
  {
    CsvReader reader(dir + "/gps.csv", {"time_s", "x_m", "y_m"});
    std::array<double, 3> row{};
    while (reader.next(row)) {
      if (!gps.empty() && row[0] < gps.back().time) {
        reader.fail("time goes backwards (" + std::to_string(row[0]) + " after " +
                    std::to_string(gps.back().time) + ")");
      }
      gps.push_back({row[0], row[1], row[2]});
    }
    if (gps.empty()) reader.fail("no GPS fixes: the initial pose comes from the first one");
  }
  for (const Fix& f : gps) {
    Event e;
    e.kind = EventKind::kGps;
    e.time = f.time;
    e.x = f.x;
    e.y = f.y;
    events.push_back(e);
  }
  out.gps_fixes = gps.size();

  // One time order; on equal times control, scan, GPS (EventKind's order). Scans keep their
  // observation ranges, which do not depend on the event order.
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    return a.time < b.time || (a.time == b.time && a.kind < b.kind);
  });

  LogHeader& h = log.header;
  h.motion.kind = engine::MotionKind::kAckermann;
  h.motion.geometry = options.geometry;
  h.motion.sigma_control[0] = options.sigma_speed;
  h.motion.sigma_control[1] = options.sigma_steer;
  h.sensor.sigma_range = options.sigma_range;
  h.sensor.sigma_bearing = options.sigma_bearing;
  h.sensor.max_range = options.gate.max_range;
  // Negative information may only expect trees where the gate would keep them.
  h.sensor.field_of_view =
      2 * std::min(std::abs(options.gate.min_bearing), std::abs(options.gate.max_bearing));
  h.sensor.offset = {0.0, 0.0, options.laser_yaw};  // the state is the laser's pose
  // The pose holds from the first GPS fix, or from the first record if one comes earlier (the
  // first control's interval starts dt before its stamp).
  const Event& first = events.front();
  h.start_time = std::min(gps.front().time, first.time - first.dt);
  h.start_pose[0] = gps.front().x;
  h.start_pose[1] = gps.front().y;

  if (options.initial_heading) {
    h.start_pose[2] = engine::wrap_angle(*options.initial_heading);
  } else {
    // Dead reckoning from the first fix with heading 0; at each GPS fix in the window, the
    // dead-reckoned displacement p and the GPS displacement q. The heading theta minimises
    // sum |R(theta) p - q|^2: theta = atan2(sum p x q, sum p . q).
    const engine::AckermannModel model(options.geometry);
    engine::AckermannModel::State s(0.0, 0.0, 0.0);
    const double until = gps.front().time + options.heading_fit_seconds;
    double cross = 0.0, dot = 0.0;
    std::vector<std::array<double, 4>> pairs;
    for (const Event& e : events) {
      if (e.time > until) break;
      if (e.kind == EventKind::kControl) {
        s = model.predict(s, {e.control.u0, e.control.u1}, e.dt);
      } else if (e.kind == EventKind::kGps) {
        const double qx = e.x - gps.front().x, qy = e.y - gps.front().y;
        cross += s[0] * qy - s[1] * qx;
        dot += s[0] * qx + s[1] * qy;
        pairs.push_back({s[0], s[1], qx, qy});
      }
    }
    if (!(std::hypot(cross, dot) > 1e-6)) {
      throw std::invalid_argument(
          dir + ": cannot fit the initial heading: the car does not move within " +
          std::to_string(options.heading_fit_seconds) +
          " s of the first GPS fix, or there is no GPS there; give the heading");
    }
    const double theta = std::atan2(cross, dot);
    double se = 0.0;
    const double c = std::cos(theta), sn = std::sin(theta);
    for (const auto& [px, py, qx, qy] : pairs) {
      se += std::pow(c * px - sn * py - qx, 2) + std::pow(sn * px + c * py - qy, 2);
    }
    h.start_pose[2] = theta;
    out.heading_fit_rms_m = std::sqrt(se / pairs.size());
  }
  out.initial_heading = h.start_pose[2];
  return out;
}

}  // namespace fastslam::tools
