#include "tools/cli/run_recorder.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/file_size_limit.h"

namespace fastslam::tools {
namespace {

namespace fs = std::filesystem;

class RunRecorderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("run_recorder_test-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Feeds `n` controls and truth poses, and the estimates in batches of 7 (as a filter hands
  // them over between scans); poses wind along a curve with values of every sign.
  static void feed(RunRecorder& recorder, int n) {
    std::vector<engine::TrajectoryPoint> batch;
    for (int k = 0; k < n; ++k) {
      Event control;
      control.kind = EventKind::kControl;
      control.time = 0.025 * (k + 1);
      control.dt = 0.025;
      control.control = {3.0, 0.01 * std::sin(0.01 * k)};
      recorder.control(control);
      Event truth;
      truth.kind = EventKind::kTruthPose;
      truth.time = control.time;
      truth.x = 40.0 * std::cos(0.003 * k) - 20.0;
      truth.y = -15.0 * std::sin(0.007 * k);
      truth.theta = std::remainder(0.003 * k, 2 * M_PI);
      recorder.truth(truth);
      batch.push_back(
          {static_cast<std::uint64_t>(k), truth.x + 0.1, truth.y - 0.2, truth.theta + 1e-3});
      if (batch.size() == 7 || k + 1 == n) {
        recorder.estimates(batch);
        batch.clear();
      }
    }
  }

  static std::vector<std::string> lines(const fs::path& file) {
    std::ifstream in(file);
    std::vector<std::string> out;
    for (std::string line; std::getline(in, line);) out.push_back(line);
    return out;
  }

  static std::string printf_pose(double t, double x, double y, double theta) {
    char buf[160];
    std::snprintf(buf, sizeof(buf), "%.3f,%.6f,%.6f,%.6f", t, x, y, theta);
    return buf;
  }

  fs::path dir_;
};

// Thousands of poses a file (several write buffers): every line is printf's, in order, and
// every file is in place after finish().
TEST_F(RunRecorderTest, WritesEveryPoseInOrderAsPrintfWould) {
  constexpr int kPoses = 9001;
  RecordedRun run;
  {
    RunRecorder recorder(LogHeader{}, engine::SensorOffset{}, dir_.string(), 10.0);
    feed(recorder, kPoses);
    run = recorder.finish();
  }
  EXPECT_TRUE(run.errors.empty());
  EXPECT_EQ(run.files, (std::vector<std::string>{"trajectory.csv", "trajectory.tum", "truth.csv",
                                                 "dead_reckoning.csv"}));
  const std::vector<std::string> trajectory = lines(dir_ / "trajectory.csv");
  const std::vector<std::string> truth = lines(dir_ / "truth.csv");
  ASSERT_EQ(trajectory.size(), kPoses + 1u);
  ASSERT_EQ(truth.size(), kPoses + 1u);
  EXPECT_EQ(trajectory[0], "t,x,y,theta");
  EXPECT_EQ(lines(dir_ / "trajectory.tum").size(), kPoses + 1u);
  EXPECT_EQ(lines(dir_ / "dead_reckoning.csv").size(), kPoses + 1u);
  for (int k = 0; k < kPoses; ++k) {
    const double t = 0.025 * (k + 1);
    const double x = 40.0 * std::cos(0.003 * k) - 20.0, y = -15.0 * std::sin(0.007 * k);
    const double theta = std::remainder(0.003 * k, 2 * M_PI);
    ASSERT_EQ(truth[k + 1], printf_pose(t, x, y, theta)) << "pose " << k;
    ASSERT_EQ(trajectory[k + 1], printf_pose(t, x + 0.1, y - 0.2, theta + 1e-3)) << "pose " << k;
  }
  for (const auto& entry : fs::directory_iterator(dir_)) {
    EXPECT_NE(entry.path().filename().string()[0], '.') << "a temporary is left";
  }
}

// The rows the writer keeps for the picture are the files' own: the picture drawn from them
// is byte for byte the one drawn by reading the files back, past the paths' thinning bound and
// with GPS fixes; without `picture` none are kept.
TEST_F(RunRecorderTest, ThePictureOfTheKeptRowsIsThePictureOfTheFiles) {
  const int poses = static_cast<int>(2 * kMaxPathPoints + 17);
  RecordedRun run;
  {
    RunRecorder recorder(LogHeader{}, engine::SensorOffset{}, dir_.string(), 10.0, true);
    for (int k = 0; k < 300; ++k) {
      Event fix;
      fix.kind = EventKind::kGps;
      fix.time = 0.001 * k;
      fix.x = 30.0 * std::cos(0.02 * k) - 1.0 / 3;
      fix.y = 10.0 * std::sin(0.05 * k);
      recorder.gps(fix);
    }
    feed(recorder, poses);
    run = recorder.finish();
  }
  ASSERT_TRUE(run.errors.empty());
  ASSERT_NE(run.picture, nullptr);
  EXPECT_EQ(run.picture->estimate.rows().offered(), static_cast<std::uint64_t>(poses));
  EXPECT_EQ(run.picture->gps.rows().offered(), 300u);
  const auto picture = [&](const PicturePaths* paths) {
    write_map_svg(dir_.string(), paths);
    std::ifstream in(dir_ / "map.svg");
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  };
  const std::string kept = picture(run.picture.get());
  EXPECT_EQ(kept, picture(nullptr));
  EXPECT_NE(kept.find("id=\"gps\""), std::string::npos);

  fs::create_directories(dir_ / "plain");
  RunRecorder plain(LogHeader{}, engine::SensorOffset{}, (dir_ / "plain").string(), 10.0);
  feed(plain, 10);
  EXPECT_EQ(plain.finish().picture, nullptr);
}

using fastslam::testing::FileSizeLimit;

// The TUM file outgrows a size limit the CSV files stay under: the run learns of it while it
// goes (as of a full disk), and finish(), called after such a failure as after any, reports it
// once, naming it, leaves nothing of it behind and writes the other files whole.
TEST_F(RunRecorderTest, AFileThatFailsIsReportedAndTheOthersStand) {
  constexpr int kPoses = 9001;
  RecordedRun run;
  std::string during;
  {
    const FileSizeLimit limit(500000);
    ASSERT_TRUE(limit.ok());
    RunRecorder recorder(LogHeader{}, engine::SensorOffset{}, dir_.string(), 10.0);
    try {
      feed(recorder, kPoses);
    } catch (const std::runtime_error& e) {
      during = e.what();
    }
    run = recorder.finish();
  }
  EXPECT_NE(during.find("trajectory.tum: write failed: File too large"), std::string::npos)
      << during;
  ASSERT_EQ(run.errors.size(), 1u);
  EXPECT_NE(run.errors[0].find("trajectory.tum: write failed: File too large"), std::string::npos)
      << run.errors[0];
  EXPECT_EQ(run.files,
            (std::vector<std::string>{"trajectory.csv", "truth.csv", "dead_reckoning.csv"}));
  EXPECT_FALSE(fs::exists(dir_ / "trajectory.tum"));
  // Whole up to where the run stopped: the poses handed over until then, in order.
  const std::vector<std::string> trajectory = lines(dir_ / "trajectory.csv");
  EXPECT_GT(trajectory.size(), 1000u);
  for (std::size_t k = 1; k < trajectory.size(); ++k) {
    const double x = 40.0 * std::cos(0.003 * (k - 1)) - 20.0, y = -15.0 * std::sin(0.007 * (k - 1));
    ASSERT_EQ(trajectory[k], printf_pose(0.025 * k, x + 0.1, y - 0.2,
                                         std::remainder(0.003 * (k - 1), 2 * M_PI) + 1e-3))
        << "pose " << k - 1;
  }
  EXPECT_GE(lines(dir_ / "truth.csv").size(), trajectory.size());
  EXPECT_GE(lines(dir_ / "dead_reckoning.csv").size(), trajectory.size());
  for (const auto& entry : fs::directory_iterator(dir_)) {
    EXPECT_NE(entry.path().filename().string()[0], '.') << "a temporary is left";
  }
  ASSERT_TRUE(run.filter.truth.has_value());  // the scores do not depend on the files
}

// A recorder dropped without finish() (a run that threw) leaves no file and no temporary
// behind.
TEST_F(RunRecorderTest, DroppedWithoutFinishLeavesNothing) {
  {
    RunRecorder recorder(LogHeader{}, engine::SensorOffset{}, dir_.string(), 10.0);
    feed(recorder, 7001);
  }
  EXPECT_TRUE(fs::is_empty(dir_));
}

// Without an output directory nothing is written and the scores still come.
TEST_F(RunRecorderTest, WithoutAnOutputDirectoryScoresOnly) {
  RunRecorder recorder(LogHeader{}, engine::SensorOffset{}, "", 10.0);
  feed(recorder, 500);
  const RecordedRun run = recorder.finish();
  EXPECT_TRUE(run.files.empty());
  ASSERT_TRUE(run.filter.truth.has_value());
  EXPECT_TRUE(fs::is_empty(dir_));
}

}  // namespace
}  // namespace fastslam::tools
