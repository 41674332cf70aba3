#include "tools/cli/checkpoint.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
}

// A filter a few steps in, with unknown association.
std::unique_ptr<engine::Filter> small_filter() {
  engine::FilterConfig config;
  config.particles = 8;
  config.association = engine::Association::kMaximumLikelihood;
  config.record_trajectory = true;
  auto filter = std::make_unique<engine::Filter>(config);
  for (int k = 0; k < 5; ++k) {
    filter->predict({1.0, 0.1}, 0.1);
    const engine::Observation z[] = {{5.0 - k * 0.1, 0.2, -1}, {8.0, -0.5, -1}};
    filter->observe(z);
  }
  return filter;
}

Checkpoint sample(engine::Filter& filter) {
  Checkpoint c;
  c.identity =
      run_identity({{"particles", 8}, {"threads", 2}, {"trace", "t.csv"}}, nlohmann::json::array());
  c.events = 12;
  c.controls = 5;
  c.scans = 5;
  c.run = {{"filter_seconds", 0.5}};
  c.trace = "t,scan\n0.1,0\n";
  c.poses = filter.take_trajectory();
  return c;
}

class CheckpointTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        std::filesystem::temp_directory_path() / ("checkpoint_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    path_ = (dir_ / "run.ckp").string();
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::filesystem::path dir_;
  std::string path_;
};

TEST_F(CheckpointTest, RoundTripsEverySection) {
  const std::unique_ptr<engine::Filter> filter = small_filter();
  const Checkpoint saved = sample(*filter);
  ASSERT_EQ(saved.poses.size(), 5u);
  write_checkpoint(path_, saved, saved.poses, *filter);
  const Checkpoint read = read_checkpoint(path_);
  EXPECT_EQ(read.identity, saved.identity);
  EXPECT_EQ(read.events, 12u);
  EXPECT_EQ(read.controls, 5u);
  EXPECT_EQ(read.scans, 5u);
  EXPECT_EQ(read.run, saved.run);
  EXPECT_EQ(read.trace, saved.trace);
  ASSERT_EQ(read.poses.size(), saved.poses.size());
  for (std::size_t k = 0; k < read.poses.size(); ++k) {
    EXPECT_EQ(read.poses[k].control, k);
    EXPECT_EQ(read.poses[k].x, saved.poses[k].x);
  }
  std::ostringstream state;
  filter->save(state);
  EXPECT_EQ(read.filter_state, state.str());
  engine::FilterConfig execution = filter->config();
  execution.threads = 1;
  const std::unique_ptr<engine::Filter> loaded = load_filter(path_, read, execution);
  EXPECT_EQ(loaded->config().threads, 1u);
  EXPECT_EQ(loaded->statistics().scans, 5u);
  // The identity leaves out what changes no result, and keeps whether there is a trace.
  EXPECT_FALSE(read.identity["options"].contains("threads"));
  EXPECT_EQ(read.identity["options"]["trace"], true);
  EXPECT_TRUE(read.identity["build"].contains("commit"));
}

// A checkpoint before the first scan holds no poses: an empty section both ways
// (fuzz/regressions/checkpoint_fuzzer/no_poses.body once passed memcpy a null pointer).
TEST_F(CheckpointTest, ACheckpointWithoutPosesRoundTrips) {
  const std::unique_ptr<engine::Filter> filter = small_filter();
  Checkpoint c = sample(*filter);
  c.poses.clear();
  c.trace.clear();
  write_checkpoint(path_, c, c.poses, *filter);
  const Checkpoint read = read_checkpoint(path_);
  EXPECT_TRUE(read.poses.empty());
  EXPECT_TRUE(read.trace.empty());
  EXPECT_EQ(read.scans, 5u);
}

TEST_F(CheckpointTest, RefusesEveryTruncationAndAlteration) {
  const std::unique_ptr<engine::Filter> filter = small_filter();
  const Checkpoint c = sample(*filter);
  write_checkpoint(path_, c, c.poses, *filter);
  const std::string good = read_bytes(path_);
  const std::string spoiled = (dir_ / "spoiled.ckp").string();
  for (std::size_t n = 0; n < good.size(); n += (n < 512 ? 1 : 17)) {
    write_bytes(spoiled, good.substr(0, n));
    EXPECT_THROW(read_checkpoint(spoiled), std::runtime_error) << "truncated to " << n;
  }
  for (std::size_t at = 0; at < good.size(); at += 5) {
    std::string b = good;
    b[at] = static_cast<char>(b[at] ^ 0x20);
    write_bytes(spoiled, b);
    EXPECT_THROW(read_checkpoint(spoiled), std::runtime_error) << "byte " << at;
  }
  try {
    std::string b = good;
    b[good.size() / 2] ^= 1;
    write_bytes(spoiled, b);
    read_checkpoint(spoiled);
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(spoiled + ": not a usable checkpoint: its SHA-256"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(read_checkpoint((dir_ / "absent.ckp").string()), std::runtime_error);
}

TEST_F(CheckpointTest, SameRunNamesTheFirstDifference) {
  const nlohmann::json inputs = nlohmann::json::array();
  const nlohmann::json a = run_identity({{"particles", 8}, {"seed", 1}, {"threads", 2}}, inputs);
  // Execution options and output paths change no result.
  EXPECT_NO_THROW(check_same_run(
      path_, a,
      run_identity({{"particles", 8}, {"seed", 1}, {"threads", 1}, {"out", "x"}}, inputs)));
  try {
    check_same_run(path_, a, run_identity({{"particles", 9}, {"seed", 1}}, inputs));
    ADD_FAILURE() << "no refusal";
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("--resume " + path_), std::string::npos) << m;
    EXPECT_NE(m.find("made with option particles = 8, this run has particles = 9"),
              std::string::npos)
        << m;
  }
  nlohmann::json other_build = a;
  other_build["build"]["commit"] = "feed";
  EXPECT_THROW(check_same_run(path_, other_build, a), std::runtime_error);
  const nlohmann::json file = nlohmann::json::array({{{"option", "--data"}, {"sha256", "ab"}}});
  EXPECT_THROW(check_same_run(path_, a, run_identity({{"particles", 8}, {"seed", 1}}, file)),
               std::runtime_error);
}

}  // namespace
}  // namespace fastslam::tools
