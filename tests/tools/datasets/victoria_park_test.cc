#include "tools/datasets/victoria_park.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <unistd.h>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/shared_data.h"

namespace fastslam::tools {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

// A tiny data set in a temporary directory: 8 odometry samples (the car drives straight along
// +x at 2 m/s), 3 scans (the second empty), 3 GPS fixes along the heading 30 deg.
class VictoriaParkFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = (std::filesystem::temp_directory_path() /
            ("fastslam_vp_test_" + std::to_string(::getpid())))
               .string();
    std::filesystem::create_directories(dir_);
    files_ = {
        {"odometry.csv",
         "time_s,speed_mps,steering_rad\n"
         "1.000,2,0\n1.025,2,0\n1.050,2,0\n1.075,2,0\n1.100,2,0\n1.125,2,0\n1.150,2,0\n"
         "1.175,2,0\n"},
        {"laser_scan_times.csv", "scan_index,time_s,n_trees\n0,1.010,2\n1,1.060,0\n2,1.110,3\n"},
        {"tree_observations.csv",
         "time_s,scan_index,range_m,bearing_rad,diameter_m\n"
         "1.010,0,10.5,0.25,0.3\n1.010,0,20,-0.5,0.2\n"
         "1.110,2,3,0.1,0.2\n1.110,2,71,0.1,0.2\n1.110,2,30,1.55,0.2\n"},
        {"gps.csv", "time_s,x_m,y_m\n0.990,10,20\n1.090,10.15,20.05\n1.190,10.30,20.1\n"},
    };
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  void write(const std::vector<std::pair<std::string, std::string>>& files) {
    for (const auto& [name, text] : files) std::ofstream(dir_ + "/" + name) << text;
  }
  // Writes the files with `name` replaced by `text`; returns the error message of reading.
  std::string error_with(const std::string& name, const std::string& text) {
    auto files = files_;
    for (auto& [n, t] : files) {
      if (n == name) t = text;
    }
    write(files);
    VictoriaParkOptions options;
    options.initial_heading = 0.0;
    try {
      read_victoria_park(dir_, options);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "(no error)";
  }

  std::string dir_;
  std::vector<std::pair<std::string, std::string>> files_;
};

TEST_F(VictoriaParkFiles, ReadsEveryRecordInTimeOrder) {
  write(files_);
  VictoriaParkOptions options;
  options.heading_fit_seconds = 1.0;
  options.split_controls_at_scans = false;
  const VictoriaPark vp = read_victoria_park(dir_, options);
  EXPECT_EQ(vp.odometry_samples, 8u);
  EXPECT_EQ(vp.split_controls, 0u);
  EXPECT_EQ(vp.scans, 3u);
  EXPECT_EQ(vp.detections, 5u);
  EXPECT_EQ(vp.gated_out, 3u);  // 3 m and 71 m outside 5..70 m, 1.55 rad beyond 87.1 deg
  EXPECT_EQ(vp.gps_fixes, 3u);
  const Log& log = vp.log;
  ASSERT_EQ(log.events.size(), 8u + 3 + 3);
  for (std::size_t i = 1; i < log.events.size(); ++i) {
    EXPECT_LE(log.events[i - 1].time, log.events[i].time) << i;
  }
  // Controls: sample k held from t_k to t_{k+1}, stamped at t_{k+1}; the last for 25 ms.
  std::vector<const Event*> controls, scans;
  for (const Event& e : log.events) {
    if (e.kind == EventKind::kControl) controls.push_back(&e);
    if (e.kind == EventKind::kScan) scans.push_back(&e);
  }
  ASSERT_EQ(controls.size(), 8u);
  EXPECT_DOUBLE_EQ(controls[0]->time, 1.025);
  EXPECT_NEAR(controls[0]->dt, 0.025, 1e-12);
  EXPECT_DOUBLE_EQ(controls[7]->time, 1.2);
  EXPECT_EQ(controls[7]->dt, 0.025);
  EXPECT_EQ(controls[3]->control.u0, 2.0);
  ASSERT_EQ(scans.size(), 3u);
  EXPECT_EQ(scans[0]->count, 2u);
  EXPECT_EQ(scans[1]->count, 0u);  // an empty scan is still a scan (negative information)
  EXPECT_EQ(scans[2]->count, 0u);  // every detection gated out
  EXPECT_EQ(log.observations[scans[0]->first].range, 10.5);
  EXPECT_EQ(log.observations[scans[0]->first + 1].bearing, -0.5);
  EXPECT_EQ(log.observations[0].id, -1);
  // Header: the car, the gate as the sensor's reach, the first fix as the start.
  const LogHeader& h = log.header;
  EXPECT_EQ(h.motion.kind, engine::MotionKind::kAckermann);
  EXPECT_EQ(h.motion.geometry.a, 3.78);
  EXPECT_EQ(h.motion.geometry.h, 0.76);
  EXPECT_EQ(h.sensor.max_range, 70.0);
  EXPECT_NEAR(h.sensor.field_of_view, 2 * 87.1 * kDeg, 1e-12);
  EXPECT_EQ(h.start_time, 0.99);
  EXPECT_EQ(h.start_pose[0], 10.0);
  EXPECT_EQ(h.start_pose[1], 20.0);
  // Straight driving along the GPS track's direction, atan2(0.05, 0.15) = 18.43 deg: the fit
  // recovers it (the laser point moves straight when steering is 0).
  EXPECT_NEAR(vp.initial_heading, std::atan2(0.05, 0.15), 1e-9);
  EXPECT_NEAR(h.start_pose[2], vp.initial_heading, 0.0);
}

// Every scan falls inside an odometry interval (1.010 in [1.000, 1.025), ...): each such
// interval becomes two controls, one ending at the scan, and the scan comes right after it.
TEST_F(VictoriaParkFiles, SplitsTheControlHoldingAScanAtTheScanTime) {
  write(files_);
  VictoriaParkOptions options;
  options.initial_heading = 0.0;
  options.split_controls_at_scans = true;
  const VictoriaPark vp = read_victoria_park(dir_, options);
  EXPECT_EQ(vp.odometry_samples, 8u);
  EXPECT_EQ(vp.split_controls, 3u);
  const std::vector<Event>& events = vp.log.events;
  std::size_t controls = 0;
  double driven = 0.0;
  for (std::size_t i = 0; i < events.size(); ++i) {
    const Event& e = events[i];
    if (e.kind == EventKind::kControl) {
      ++controls;
      driven += e.control.u0 * e.dt;
      EXPECT_GT(e.dt, 0.0);
    }
    if (e.kind == EventKind::kScan) {
      ASSERT_GT(i, 0u);
      EXPECT_EQ(events[i - 1].kind, EventKind::kControl);
      EXPECT_EQ(events[i - 1].time, e.time);  // the pose is at the scan's own time
    }
  }
  EXPECT_EQ(controls, 8u + 3);
  EXPECT_NEAR(driven, 2.0 * 8 * 0.025, 1e-12);  // the same intervals, cut, not changed
  // The first sample [1.000, 1.025) cut at 1.010: the GPS fix at 0.990, the first part, the
  // scan, the rest.
  ASSERT_GE(events.size(), 4u);
  EXPECT_EQ(events[0].kind, EventKind::kGps);
  EXPECT_EQ(events[1].time, 1.010);
  EXPECT_NEAR(events[1].dt, 0.010, 1e-12);
  EXPECT_EQ(events[2].kind, EventKind::kScan);
  EXPECT_EQ(events[3].time, 1.025);
  EXPECT_NEAR(events[3].dt, 0.015, 1e-12);
}

TEST_F(VictoriaParkFiles, GateAndHeadingAreOptions) {
  write(files_);
  VictoriaParkOptions options;
  options.gate.min_range = 1.0;
  options.gate.max_range = 80.0;
  options.gate.max_bearing = 1.56;
  options.initial_heading = 0.5;
  const VictoriaPark vp = read_victoria_park(dir_, options);
  EXPECT_EQ(vp.gated_out, 0u);
  EXPECT_EQ(vp.log.observations.size(), 5u);
  EXPECT_EQ(vp.log.header.start_pose[2], 0.5);
  // Diameters are 0.3, 0.2, 0.2, 0.2, 0.2: a 0.25 m limit drops the first (0.25 keeps 0.2s).
  options.gate.max_diameter = 0.25;
  const VictoriaPark narrow = read_victoria_park(dir_, options);
  EXPECT_EQ(narrow.gated_out, 1u);
  EXPECT_EQ(narrow.log.observations.size(), 4u);
  EXPECT_EQ(narrow.log.observations.front().range, 20.0);
  options.gate.max_diameter = 0.0;
  EXPECT_THROW(read_victoria_park(dir_, options), std::invalid_argument);
  options.gate.max_diameter = 1.0;
  options.laser_yaw = -0.01;
  EXPECT_EQ(read_victoria_park(dir_, options).log.header.sensor.offset.yaw, -0.01);
  options.laser_yaw = 4.0;
  EXPECT_THROW(read_victoria_park(dir_, options), std::invalid_argument);
  options.laser_yaw = 0.0;
  options.gate.min_range = 90.0;
  EXPECT_THROW(read_victoria_park(dir_, options), std::invalid_argument);
  options = {};
  options.sigma_range = 0;
  EXPECT_THROW(read_victoria_park(dir_, options), std::invalid_argument);
}

TEST_F(VictoriaParkFiles, NoMovementMeansNoHeadingFit) {
  auto files = files_;
  files[0].second = "time_s,speed_mps,steering_rad\n1.000,0,0\n1.025,0,0\n";
  write(files);
  EXPECT_THROW(read_victoria_park(dir_), std::invalid_argument);
}

TEST_F(VictoriaParkFiles, RefusesEveryMalformedClassNamingFileLineAndReason) {
  const std::string odo = "time_s,speed_mps,steering_rad\n";
  const std::string scans = "scan_index,time_s,n_trees\n";
  const std::string trees = "time_s,scan_index,range_m,bearing_rad,diameter_m\n";
  const std::string gps = "time_s,x_m,y_m\n";
  const std::vector<std::tuple<std::string, std::string, std::string>> cases = {
      {"odometry.csv", "time,speed,steering\n1,2,3\n",
       "odometry.csv:1: header is 'time,speed,steering', expected"},
      {"odometry.csv", "", "odometry.csv:0: empty file"},
      {"odometry.csv", odo, "odometry.csv:1: no odometry rows"},
      {"odometry.csv", odo + "1,2\n", "odometry.csv:2: expected 3 columns, found 2"},
      {"odometry.csv", odo + "1,2,3,4\n", "odometry.csv:2: expected 3 columns, found 4"},
      {"odometry.csv", odo + "1,fast,0\n", "odometry.csv:2: column 'speed_mps': 'fast' is not"},
      {"odometry.csv", odo + "1,nan,0\n",
       "odometry.csv:2: column 'speed_mps': value 'nan' is not "
       "finite"},
      {"odometry.csv", odo + "1,1,-inf\n", "odometry.csv:2: column 'steering_rad': value '-inf'"},
      {"odometry.csv", odo + "1,1,0\n0.9,1,0\n", "odometry.csv:3: time goes backwards"},
      {"gps.csv", gps + "1,2,3\n0.5,2,3\n", "gps.csv:3: time goes backwards"},
      {"gps.csv", gps, "gps.csv:1: no GPS fixes"},
      {"gps.csv", gps + "1,2\n", "gps.csv:2: expected 3 columns"},
      {"laser_scan_times.csv", scans + "0,1,0\n2,1.1,0\n",
       "laser_scan_times.csv:3: scan_index 2 is not the next scan (1)"},
      {"laser_scan_times.csv", scans + "0,1,0\n1,0.9,0\n",
       "laser_scan_times.csv:3: time goes backwards"},
      {"laser_scan_times.csv", scans + "0,1,-1\n",
       "laser_scan_times.csv:2: n_trees must be a non-negative integer"},
      {"laser_scan_times.csv", scans + "0.5,1,0\n",
       "laser_scan_times.csv:2: scan_index must be a non-negative integer"},
      {"tree_observations.csv", trees + "1.010,0,-10.5,0.25,0.3\n",
       "tree_observations.csv:2: range_m must be > 0"},
      {"tree_observations.csv", trees + "1.010,0,10.5,0.25,-0.3\n",
       "tree_observations.csv:2: diameter_m must be >= 0"},
      {"tree_observations.csv", trees + "1.010,0,10.5,0.25\n",
       "tree_observations.csv:2: expected 5 columns, found 4"},
      {"tree_observations.csv", trees + "1.010,0,10.5,NaN,0.3\n",
       "tree_observations.csv:2: column 'bearing_rad': value 'NaN' is not finite"},
      {"tree_observations.csv", trees + "1.010,7,10.5,0.25,0.3\n",
       "tree_observations.csv:2: scan_index 7 is not in laser_scan_times.csv (3 scans)"},
      {"tree_observations.csv", trees + "1.500,0,10.5,0.25,0.3\n",
       "tree_observations.csv:2: time 1.500000 is not scan 0's time 1.010000"},
      {"tree_observations.csv",
       trees + "1.010,0,10,0.25,0.3\n1.010,0,11,0.25,0.3\n1.110,2,10,0,0.3\n1.010,0,10,0,0.3\n",
       "tree_observations.csv:5: scan_index goes backwards (0 after 2)"},
      // Scan 0 should have 2 detections and has 1: noticed when scan 2's rows begin.
      {"tree_observations.csv", trees + "1.010,0,10.5,0.25,0.3\n1.110,2,10,0,0.3\n",
       "tree_observations.csv:3: scan 0 has 1 detections, laser_scan_times.csv says 2"},
      // Scan 2 lacks its rows: noticed at the end of the file.
      {"tree_observations.csv", trees + "1.010,0,10.5,0.25,0.3\n1.010,0,20,-0.5,0.2\n",
       "tree_observations.csv:3: scan 2 has 0 detections, laser_scan_times.csv says 3"},
  };
  for (const auto& [file, text, expected] : cases) {
    const std::string e = error_with(file, text);
    EXPECT_NE(e.find(dir_ + "/" + expected), std::string::npos)
        << "got: " << e << "\nexpected: " << expected;
  }
  write(files_);
  std::filesystem::remove(dir_ + "/gps.csv");
  VictoriaParkOptions options;
  options.initial_heading = 0.0;
  try {
    read_victoria_park(dir_, options);
    ADD_FAILURE() << "a missing file was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("gps.csv: cannot open"), std::string::npos) << e.what();
  }
}

TEST(VictoriaParkData, CountsRangesAndHeadingOfTheSharedDataSet) {
  FASTSLAM_REQUIRE_SHARED(shared);
  VictoriaParkOptions options;
  options.split_controls_at_scans = true;
  const VictoriaPark vp = read_victoria_park(shared + "/data/victoria_park", options);
  // The counts of the README and the issue.
  EXPECT_EQ(vp.odometry_samples, 61945u);
  EXPECT_EQ(vp.scans, 7249u);
  EXPECT_EQ(vp.detections, 52974u);
  EXPECT_EQ(vp.gps_fixes, 4466u);
  std::size_t controls = 0, scans = 0, gps = 0, empty = 0;
  for (const Event& e : vp.log.events) {
    controls += e.kind == EventKind::kControl;
    scans += e.kind == EventKind::kScan;
    gps += e.kind == EventKind::kGps;
    empty += e.kind == EventKind::kScan && e.count == 0;
  }
  // A scan cuts the odometry interval it falls in, unless it falls on a sample's time (same
  // millisecond clock) or before the first sample: 6960 of the 7249.
  EXPECT_EQ(controls, 61945u + vp.split_controls);
  EXPECT_EQ(vp.split_controls, 6960u);
  EXPECT_EQ(scans, 7249u);
  EXPECT_EQ(gps, 4466u);
  EXPECT_GE(empty, 19u);  // 19 scans have no detection at all, more after gating
  // The gate 5..70 m drops 1153 + 234 detections (counted in the data) and no bearing.
  EXPECT_EQ(vp.gated_out, 1153u + 234u);
  EXPECT_EQ(vp.log.observations.size(), 52974u - vp.gated_out);
  for (const engine::Observation& z : vp.log.observations) {
    ASSERT_GE(z.range, 5.0);
    ASSERT_LE(z.range, 70.0);
    ASSERT_LE(std::abs(z.bearing), 87.1 * kDeg);
  }
  // Time spans (README): odometry 21.940-1570.540 s, laser 21.819-1570.208 s, GPS from 20.967 s.
  EXPECT_EQ(vp.log.header.start_time, 20.967);
  EXPECT_EQ(vp.log.header.start_pose[0], -67.649271);
  EXPECT_EQ(vp.log.header.start_pose[1], -41.714218);
  EXPECT_NEAR(vp.log.events.back().time, 1570.540 + 0.025, 1e-9);
  // Odometry is exactly 40 Hz: every control covers 25 ms, or part of it when cut at a scan.
  double covered = 0.0;
  for (const Event& e : vp.log.events) {
    if (e.kind == EventKind::kControl) {
      ASSERT_GT(e.dt, 0.0);
      ASSERT_LE(e.dt, 0.025 + 1e-9);
      covered += e.dt;
    }
  }
  EXPECT_NEAR(covered, 61945 * 0.025, 1e-6);
  // The default 20 s window gives 35.9 deg (public code uses 35.5 and 36; the README's own fit
  // of the first 60 s, 38.0 deg, takes in the dead reckoning's drift).
  EXPECT_NEAR(vp.initial_heading / kDeg, 35.9, 0.3);
  EXPECT_LT(vp.heading_fit_rms_m, 3.0);
  std::printf("fitted initial heading %.2f deg, RMS %.2f m\n", vp.initial_heading / kDeg,
              vp.heading_fit_rms_m);
}

}  // namespace
}  // namespace fastslam::tools
