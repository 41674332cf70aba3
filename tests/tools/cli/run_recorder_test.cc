#include "tools/cli/run_recorder.h"

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

using testing::temp_path;

std::string contents(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// A drive of `controls` controls with truth after each, a GPS fix every 40 and an estimate
// batch every 8 (as a scan would hand them), the estimate a little off the truth.
RecordedRun record(const std::string& out, bool background, std::uint64_t controls) {
  LogHeader header;
  RunRecorder recorder(header, {0.3, -0.1, 0.0}, out, 10.0, background);
  std::vector<engine::TrajectoryPoint> batch;
  double x = 0.0, y = 0.0, theta = 0.0;
  for (std::uint64_t k = 0; k < controls; ++k) {
    Event c;
    c.kind = EventKind::kControl;
    c.dt = 0.025;
    c.time = 0.025 * static_cast<double>(k + 1);
    c.control = {3.0, 0.2 * std::sin(0.001 * static_cast<double>(k))};
    recorder.control(c);
    theta += 0.025 * 3.0 * std::sin(c.control.u1) / 4.0;
    x += 0.075 * std::cos(theta);
    y += 0.075 * std::sin(theta);
    Event t;
    t.kind = EventKind::kTruthPose;
    t.time = c.time;
    t.x = x;
    t.y = y;
    t.theta = theta;
    recorder.truth(t);
    if (k % 40 == 39) {
      Event g = t;
      g.kind = EventKind::kGps;
      g.x += 0.5;
      recorder.gps(g);
    }
    const double wobble = 0.3 * std::sin(0.01 * static_cast<double>(k));
    batch.push_back({k, x + wobble, y - wobble, theta + 0.01 * wobble});
    if (batch.size() == 8) {
      recorder.estimates(batch);
      batch.clear();
    }
  }
  recorder.estimates(batch);
  return recorder.finish();
}

void expect_same(const std::optional<TrajectoryMetrics>& a,
                 const std::optional<TrajectoryMetrics>& b) {
  ASSERT_EQ(a.has_value(), b.has_value());
  if (!a) return;
  EXPECT_EQ(a->raw.rmse, b->raw.rmse);
  EXPECT_EQ(a->raw.used, b->raw.used);
  EXPECT_EQ(a->raw_max, b->raw_max);
  EXPECT_EQ(a->aligned.rmse, b->aligned.rmse);
  EXPECT_EQ(a->aligned.rotation, b->aligned.rotation);
  EXPECT_EQ(a->rpe.pairs, b->rpe.pairs);
  EXPECT_EQ(a->rpe.translation_rmse, b->rpe.translation_rmse);
}

// The recorder's own thread writes and scores the same bytes as the calling thread: many
// hand-overs (kBatchEvents), the queue full at times, the last batch handed over by finish.
TEST(RunRecorder, InTheBackgroundWritesAndScoresTheSameBytes) {
  const std::uint64_t controls = 20 * RunRecorder::kBatchEvents + 3;
  const std::string here = temp_path("recorder_here");
  const std::string there = temp_path("recorder_background");
  std::filesystem::create_directories(here);
  std::filesystem::create_directories(there);
  const RecordedRun a = record(here, false, controls);
  const RecordedRun b = record(there, true, controls);
  EXPECT_EQ(a.files, b.files);
  EXPECT_TRUE(a.errors.empty());
  EXPECT_TRUE(b.errors.empty());
  ASSERT_EQ(a.files.size(), 5u);  // trajectory .csv and .tum, truth, GPS, dead reckoning
  for (const std::string& name : a.files) {
    const std::string bytes = contents(here + "/" + name);
    EXPECT_GT(bytes.size(), 1000u) << name;
    EXPECT_EQ(bytes, contents(there + "/" + name)) << name;
  }
  EXPECT_EQ(a.truth_poses, controls);
  EXPECT_EQ(a.truth_poses, b.truth_poses);
  EXPECT_EQ(a.gps_fixes, b.gps_fixes);
  expect_same(a.filter.truth, b.filter.truth);
  expect_same(a.filter.gps, b.filter.gps);
  expect_same(a.dead_reckoning.truth, b.dead_reckoning.truth);
  expect_same(a.dead_reckoning.gps, b.dead_reckoning.gps);
  std::filesystem::remove_all(here);
  std::filesystem::remove_all(there);
}

// Without an output directory, and with nothing recorded, the background changes nothing.
TEST(RunRecorder, InTheBackgroundWithoutFilesOrEvents) {
  const RecordedRun scored_here = record("", false, 500);
  const RecordedRun scored_there = record("", true, 500);
  EXPECT_TRUE(scored_there.files.empty());
  expect_same(scored_here.filter.truth, scored_there.filter.truth);
  LogHeader header;
  RunRecorder idle(header, {}, "", 10.0, true);
  const RecordedRun none = idle.finish();
  EXPECT_EQ(none.truth_poses, 0u);
  EXPECT_TRUE(none.errors.empty());
}

// A recorder destroyed without finish() (a run that threw) stops its thread: no hang, no
// files put in place.
TEST(RunRecorder, InTheBackgroundDestroyedWithoutFinish) {
  const std::string out = temp_path("recorder_abandoned");
  std::filesystem::create_directories(out);
  {
    LogHeader header;
    RunRecorder recorder(header, {}, out, 10.0, true);
    Event c;
    c.kind = EventKind::kControl;
    c.dt = 0.1;
    for (int k = 0; k < 5000; ++k) {
      c.time = 0.1 * (k + 1);
      c.control = {1.0, 0.0};
      recorder.control(c);
    }
  }
  EXPECT_FALSE(std::filesystem::exists(out + "/trajectory.csv"));
  EXPECT_FALSE(std::filesystem::exists(out + "/dead_reckoning.csv"));
  std::filesystem::remove_all(out);
}

}  // namespace
}  // namespace fastslam::tools
