#include "tools/datasets/utias.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "engine/angles.h"
#include "tests/shared_data.h"
#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

std::string dataset(const std::string& shared) { return shared + "/data/utias_mrclam/dataset1"; }

// The position of true landmark `id`.
const TruthLandmark& landmark(const Log& log, std::uint64_t id) {
  const auto at = std::find_if(log.landmarks.begin(), log.landmarks.end(),
                               [id](const TruthLandmark& l) { return l.id == id; });
  if (at == log.landmarks.end()) throw std::logic_error("no landmark " + std::to_string(id));
  return *at;
}

// Bearing residuals of every detection of landmark `id` against the latest truth pose at or
// before its scan (truth every 0.1 s: at most 0.1 s old).
std::vector<double> bearing_residuals(const Log& log, std::int64_t id) {
  const TruthLandmark& l = landmark(log, static_cast<std::uint64_t>(id));
  std::vector<double> out;
  const Event* truth = nullptr;
  for (const Event& e : log.events) {
    if (e.kind == EventKind::kTruthPose) truth = &e;
    if (e.kind != EventKind::kScan || truth == nullptr) continue;
    for (std::uint32_t i = 0; i < e.count; ++i) {
      const engine::Observation& z = log.observations[e.first + i];
      if (z.id != id) continue;
      const double expected = std::atan2(l.y - truth->y, l.x - truth->x) - truth->theta;
      out.push_back(engine::wrap_angle(z.bearing - expected));
    }
  }
  return out;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TEST(UtiasData, RobotOneCountsAndOneTimeOrder) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const Utias u = read_utias(dataset(shared));
  EXPECT_EQ(u.robot, 1);
  // 1500 s at 50 Hz; the measurement file's 5723 rows (README: 4,000-8,800 per robot).
  EXPECT_EQ(u.odometry_samples, 75000u);
  EXPECT_EQ(u.truth_rows, 75000u);
  EXPECT_EQ(u.truth_poses, 15000u);  // every 5th row: 10 Hz
  EXPECT_EQ(u.measurements, 5723u);
  EXPECT_EQ(u.landmark_detections + u.robot_detections_dropped + u.unlabelled_detections,
            u.measurements);
  EXPECT_EQ(u.robot_detections_dropped, 952u);
  EXPECT_EQ(u.unlabelled_detections, 0u);
  EXPECT_EQ(u.repeated_in_scan, 0u);
  EXPECT_EQ(u.log.observations.size(), u.landmark_detections);
  EXPECT_EQ(u.log.landmarks.size(), 15u);

  std::size_t controls = 0, scans = 0, truths = 0;
  for (std::size_t i = 0; i < u.log.events.size(); ++i) {
    const Event& e = u.log.events[i];
    if (i > 0) {
      const Event& p = u.log.events[i - 1];
      ASSERT_TRUE(p.time < e.time || (p.time == e.time && p.kind <= e.kind)) << "event " << i;
    }
    controls += e.kind == EventKind::kControl;
    truths += e.kind == EventKind::kTruthPose;
    if (e.kind == EventKind::kScan) {
      ++scans;
      ASSERT_GT(e.count, 0u);
    }
    if (e.kind == EventKind::kControl) {
      ASSERT_EQ(e.dt, kUtiasPeriod);
    }
  }
  EXPECT_EQ(controls, 75000u);
  EXPECT_EQ(scans, u.scans);
  EXPECT_EQ(truths, 15000u);
  // Header: unicycle, the calibrated noises (the sensor's widened), the first Vicon pose at
  // t = 0.
  const LogHeader& h = u.log.header;
  EXPECT_EQ(h.motion.kind, engine::MotionKind::kUnicycle);
  EXPECT_EQ(h.motion.sigma_control[0], kUtiasSigmaV);
  EXPECT_EQ(h.sensor.sigma_range, kUtiasSigmaRange * kUtiasSensorWidth);
  EXPECT_EQ(h.sensor.sigma_bearing, kUtiasSigmaBearing * kUtiasSensorWidth);
  EXPECT_EQ(h.sensor.field_of_view, kUtiasFieldOfView);
  EXPECT_EQ(h.start_time, 0.0);
  EXPECT_EQ(h.start_pose[0], 3.5732);
  EXPECT_EQ(h.start_pose[1], -3.3328);
  EXPECT_EQ(h.start_pose[2], 2.3408);
  for (const engine::Observation& z : u.log.observations) {
    ASSERT_GE(z.id, 6);
    ASSERT_LE(z.id, 20);
  }
}

// Past 1000 s the files print times rounded to 0.1 s; controls and truth poses take the row's
// exact time 0.02 k, scans keep the printed time.
TEST(UtiasData, RowIndexGivesTheTimePastOneThousandSeconds) {
  FASTSLAM_REQUIRE_SHARED(shared);
  UtiasOptions rows_own_times;
  rows_own_times.odometry_lead = 0.0;
  const Utias u = read_utias(dataset(shared), rows_own_times);
  std::vector<double> control_times, truth_times;
  for (const Event& e : u.log.events) {
    if (e.kind == EventKind::kControl) control_times.push_back(e.time);
    if (e.kind == EventKind::kTruthPose) truth_times.push_back(e.time);
  }
  // Rows 50000-50007 print as 1000, 1000, 1000, 1000.1 x 5: distinct stamps 0.02 apart.
  for (std::size_t k = 49990; k < 50010; ++k) {
    ASSERT_EQ(control_times[k], static_cast<double>(k + 1) / 50) << k;
    ASSERT_GT(control_times[k + 1], control_times[k]);
  }
  EXPECT_EQ(control_times.back(), 1500.0);
  EXPECT_EQ(truth_times[10000], 1000.0);  // rows 50000 and 50005: printed 1000 and 1000.1
  EXPECT_EQ(truth_times[10001], 1000.1);
  EXPECT_GT(u.rounded_measurements, 0u);
  for (const Event& e : u.log.events) {
    if (e.kind == EventKind::kScan && e.time >= 1000) {
      ASSERT_NEAR(e.time * 10, std::round(e.time * 10), 1e-6) << e.time;  // 0.1 s steps
    }
  }
}

// Landmark_Groundtruth.dat has 11 and 17 at each other's place (README: median bearing
// residuals near 90 deg); swapped back, their detections fit Vicon like the other landmarks'.
TEST(UtiasData, LandmarksElevenAndSeventeenAreSwappedBack) {
  FASTSLAM_REQUIRE_SHARED(shared);
  for (int robot : {1, 3}) {
    UtiasOptions options;
    options.robot = robot;
    options.truth_every = 1;
    const Utias u = read_utias(dataset(shared), options);
    EXPECT_NEAR(landmark(u.log, 11).x, 0.03596156, 1e-12);  // the file's row of 17
    EXPECT_NEAR(landmark(u.log, 17).y, 2.38294871, 1e-12);  // the file's row of 11
    for (std::int64_t id : {11, 17, 6, 16}) {
      const std::vector<double> e = bearing_residuals(u.log, id);
      ASSERT_GT(e.size(), 20u) << "robot " << robot << " landmark " << id;
      EXPECT_LT(std::abs(median(e)), 3 * kDeg) << "robot " << robot << " landmark " << id;
    }
  }
}

TEST(UtiasData, RobotOutsideOneToFiveIsRefused) {
  for (int robot : {0, 6, -1}) {
    UtiasOptions options;
    options.robot = robot;
    try {
      read_utias("/nonexistent", options);
      ADD_FAILURE() << "robot " << robot << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("robot must be 1..5 (got " + std::to_string(robot)),
                std::string::npos)
          << e.what();
    }
  }
}

// A tiny data set written to a temporary directory: three subjects (robot 1 with barcode 5,
// robot 2 with 14, landmarks 11 and 17), 6 rows at 50 Hz, a few detections.
class UtiasFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::temp_path("utias");
    std::filesystem::create_directories(dir_);
    files_ = {
        {"Barcodes.dat", "# Subject #    Barcode #\n  1 \t 5 \n  2 \t 14\n 11 18\n 17 61\n"},
        {"Landmark_Groundtruth.dat", "# Subject x y sx sy\n11 1 2 0 0\n17 3 4 0 0\n"},
        {"Robot1_Odometry.dat", "0 0.1 0\n0.02 0.1 0\n0.04 0.1 0.5\n0.06 0.1 0\n0.08 0 0\n"},
        {"Robot1_Groundtruth.dat", "0 1 2 3\n0.02 1 2 3\n0.04 1 2 3\n0.06 1 2 3\n"},
        {"Robot1_Measurement.dat",
         "0.02 18 2.5 0.1\n0.02 14 1.5 0\n0.04 43 3 0.2\n0.06 61 4 -0.2\n0.06 61 4.1 -0.2\n"
         "0.08 5 1 0\n"},
    };
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  void write(const std::map<std::string, std::string>& files) {
    for (const auto& [name, text] : files) std::ofstream(dir_ + "/" + name) << text;
  }
  // Writes the files with `name` replaced by `text`; returns the error message of reading.
  std::string error_with(const std::string& name, const std::string& text) {
    auto files = files_;
    files[name] = text;
    write(files);
    try {
      read_utias(dir_);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "(no error)";
  }

  std::string dir_;
  std::map<std::string, std::string> files_;
};

TEST_F(UtiasFiles, SortsDetectionsIntoLandmarksRobotsAndUnlabelled) {
  write(files_);
  const Utias u = read_utias(dir_);
  EXPECT_EQ(u.odometry_samples, 5u);
  EXPECT_EQ(u.truth_rows, 4u);
  EXPECT_EQ(u.truth_poses, 1u);  // rows 0 and 5, 10, ...
  EXPECT_EQ(u.measurements, 6u);
  EXPECT_EQ(u.landmark_detections, 3u);
  EXPECT_EQ(u.robot_detections_dropped, 2u);  // barcodes 14 and 5
  EXPECT_EQ(u.unlabelled_detections, 1u);     // barcode 43
  EXPECT_EQ(u.repeated_in_scan, 1u);          // 61 twice at 0.06
  // The scans: {11} at 0.02, {-1} at 0.04, {17} and {17} at 0.06; 0.08 held only a robot.
  std::vector<std::tuple<double, std::int64_t, double>> seen;
  for (const Event& e : u.log.events) {
    if (e.kind != EventKind::kScan) continue;
    ASSERT_EQ(e.count, 1u);
    const engine::Observation& z = u.log.observations[e.first];
    seen.emplace_back(e.time, z.id, z.range);
  }
  const std::vector<std::tuple<double, std::int64_t, double>> expected = {
      {0.02, 11, 2.5}, {0.04, -1, 3.0}, {0.06, 17, 4.0}, {0.06, 17, 4.1}};
  EXPECT_EQ(seen, expected);
  // Swapped back in the truth as well.
  EXPECT_EQ(landmark(u.log, 11).x, 3.0);
  EXPECT_EQ(landmark(u.log, 17).x, 1.0);
  // Controls stamped at the end of their 20 ms and robot 1's lead (0.14 s) later: the first
  // comes after the scans at 0.02-0.08 and the truth pose at 0.
  EXPECT_EQ(u.log.events[0].kind, EventKind::kTruthPose);
  EXPECT_EQ(u.log.events[1].kind, EventKind::kScan);
  const auto first_control =
      std::find_if(u.log.events.begin(), u.log.events.end(),
                   [](const Event& e) { return e.kind == EventKind::kControl; });
  ASSERT_NE(first_control, u.log.events.end());
  EXPECT_EQ(first_control->time, 0.02 + kUtiasOdometryLead[0]);
  EXPECT_EQ(u.log.header.start_pose[2], engine::wrap_angle(3.0));
  // Dropping the unlabelled: still counted, no scan at 0.04.
  UtiasOptions options;
  options.unlabelled = false;
  const Utias known = read_utias(dir_, options);
  EXPECT_EQ(known.unlabelled_detections, 1u);
  EXPECT_EQ(known.scans, 3u);
  for (const engine::Observation& z : known.log.observations) EXPECT_GE(z.id, 0);
}

// The odometry lead moves every control, and nothing else, that much later; the events stay in
// one time order (control before scan on equal times). Lead 0 keeps the rows' times.
TEST_F(UtiasFiles, OdometryLeadStampsControlsLater) {
  write(files_);
  auto controls = [](const Utias& u) {
    std::vector<double> times;
    for (const Event& e : u.log.events) {
      if (e.kind == EventKind::kControl) times.push_back(e.time);
    }
    return times;
  };
  UtiasOptions options;
  options.odometry_lead = 0.0;
  const Utias own = read_utias(dir_, options);
  EXPECT_EQ(controls(own), (std::vector<double>{0.02, 0.04, 0.06, 0.08, 0.1}));
  EXPECT_EQ(own.log.events[1].kind, EventKind::kControl);  // ends at 0.02, before that scan
  options.odometry_lead = 0.04;
  const Utias led = read_utias(dir_, options);
  const std::vector<double> shifted = controls(led);
  ASSERT_EQ(shifted.size(), 5u);
  for (std::size_t k = 0; k < 5; ++k) EXPECT_EQ(shifted[k], static_cast<double>(k + 1) / 50 + 0.04);
  EXPECT_EQ(led.log.observations.size(), own.log.observations.size());
  for (std::size_t k = 1; k < led.log.events.size(); ++k) {
    const Event& a = led.log.events[k - 1];
    const Event& b = led.log.events[k];
    ASSERT_TRUE(a.time < b.time || (a.time == b.time && a.kind <= b.kind)) << k;
  }
  // The scan at 0.06 comes after the control that ends there now (row 0's).
  const auto scan_at =
      std::find_if(led.log.events.begin(), led.log.events.end(),
                   [](const Event& e) { return e.kind == EventKind::kScan && e.time == 0.06; });
  ASSERT_NE(scan_at, led.log.events.end());
  EXPECT_EQ(std::prev(scan_at)->kind, EventKind::kControl);
  // Unset: the robot's calibrated lead; out of range or NaN: refused, naming the bound.
  EXPECT_EQ(utias_odometry_lead(UtiasOptions{}), kUtiasOdometryLead[0]);
  for (double bad : {-0.01, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    options.odometry_lead = bad;
    try {
      read_utias(dir_, options);
      ADD_FAILURE() << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("odometry lead must be 0.."), std::string::npos)
          << e.what();
    }
  }
}

TEST_F(UtiasFiles, RefusesEveryMalformedClassNamingFileLineAndReason) {
  const std::vector<std::tuple<std::string, std::string, std::string>> cases = {
      {"Robot1_Odometry.dat", "0 0.1 0\n0.02 0.1\n", "Robot1_Odometry.dat:2: expected 3 columns"},
      {"Robot1_Odometry.dat", "# c\n0 0.1 0\n0.02 x 0\n",
       "Robot1_Odometry.dat:3: column 'v': 'x' is not a number"},
      {"Robot1_Odometry.dat", "0 nan 0\n", "Robot1_Odometry.dat:1: column 'v': 'nan' is not"},
      {"Robot1_Odometry.dat", "0 0.1 0\n0.04 0.1 0\n",
       "Robot1_Odometry.dat:2: time 0.040000 is not row 1's time"},
      {"Robot1_Odometry.dat", "", "Robot1_Odometry.dat:0: no odometry rows"},
      {"Robot1_Groundtruth.dat", "0.02 1 2 3\n", "Robot1_Groundtruth.dat:1: time 0.020000 is not"},
      {"Robot1_Groundtruth.dat", "0 1 2 3 4\n", "Robot1_Groundtruth.dat:1: expected 4 columns"},
      {"Robot1_Measurement.dat", "0.02 18 2.5 0.1\n0.01 18 2.5 0.1\n",
       "Robot1_Measurement.dat:2: time goes backwards"},
      {"Robot1_Measurement.dat", "0.02 18.5 2.5 0.1\n",
       "Robot1_Measurement.dat:1: column 'barcode' must be an integer >= 0"},
      {"Robot1_Measurement.dat", "0.02 18 -2.5 0.1\n",
       "Robot1_Measurement.dat:1: range must be > 0"},
      {"Robot1_Measurement.dat", "0.02 18 2.5 4\n",
       "Robot1_Measurement.dat:1: bearing must be within [-pi, pi]"},
      {"Barcodes.dat", "1 5\n2 5\n", "Barcodes.dat:2: barcode 5 is listed twice"},
      {"Barcodes.dat", "0 5\n", "Barcodes.dat:1: column 'subject' must be an integer >= 1"},
      {"Landmark_Groundtruth.dat", "11 1 2 0 0\n11 3 4 0 0\n",
       "Landmark_Groundtruth.dat:2: landmark 11 is listed twice"},
      {"Landmark_Groundtruth.dat", "3 1 2 0 0\n",
       "Landmark_Groundtruth.dat:1: column 'subject' must be an integer >= 6"},
  };
  for (const auto& [file, text, expected] : cases) {
    const std::string e = error_with(file, text);
    EXPECT_NE(e.find(dir_ + "/" + expected), std::string::npos)
        << "got: " << e << "\nexpected: " << expected;
  }
  write(files_);
  std::filesystem::remove(dir_ + "/Robot1_Measurement.dat");
  try {
    read_utias(dir_);
    ADD_FAILURE() << "a missing file was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("Robot1_Measurement.dat: cannot open for reading "
                                         "(--data must be the UTIAS MRCLAM dataset1 directory"),
              std::string::npos)
        << e.what();
  }
}

// The real files edited: a malformed row deep in a large file is reported at its line.
TEST(UtiasData, MalformedRowOfTheRealDataNamesItsLine) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const std::string dir = testing::temp_path("utias_real");
  std::filesystem::create_directories(dir);
  for (const auto& entry : std::filesystem::directory_iterator(dataset(shared))) {
    std::filesystem::copy_file(entry.path(), dir + "/" + entry.path().filename().string());
  }
  std::ifstream in(dir + "/Robot2_Odometry.dat");
  std::stringstream text;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) text << (n == 60001 ? "1200 0.1" : line) << "\n";
  in.close();
  std::ofstream(dir + "/Robot2_Odometry.dat") << text.str();
  UtiasOptions options;
  options.robot = 2;
  try {
    read_utias(dir, options);
    ADD_FAILURE() << "a short row was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("Robot2_Odometry.dat:60001: expected 3 columns"),
              std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace fastslam::tools
