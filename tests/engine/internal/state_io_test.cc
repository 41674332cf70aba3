// State I/O: a state read back saves the same bytes (the oracle is the first save), for known
// and unknown association with shared and distinct maps, holes and queued controls; the index is
// rebuilt from the map; corrupt and truncated streams fail with std::runtime_error.
#include "engine/internal/state_io.h"

#include <sstream>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "engine/internal/map_update.h"

namespace fastslam::engine::internal {
namespace {

std::string save(const FilterState& s, const std::vector<TrajectoryPoint>& trajectory) {
  std::ostringstream out;
  save_state(s, trajectory, out);
  return out.str();
}

void fill(FilterState& s) {
  s.counters.step = 12;
  s.counters.controls = 8;
  s.counters.scans = 4;
  s.pending.push_back({1.0, 0.1, 0.2, 10});
  s.pending.push_back({1.5, -0.1, 0.2, 11});
  s.landmark_variance_bound = 2.5;
  const bool known = s.config.association == Association::kKnown;
  for (std::size_t i = 0; i < s.store.size(); ++i) {
    s.store.x()[i] = 0.5 * static_cast<double>(i);
    s.store.log_weight()[i] = -static_cast<double>(i);
    if (!s.covariances.values().empty()) s.covariances.at<3>(i).setIdentity();
    if (i > 0 && i % 3 != 0) {
      s.store.map(i) = s.store.map(i - 1);  // shared roots are written once
      continue;
    }
    for (std::uint64_t k = 0; k < 6; ++k) {
      const memory::Landmark l{static_cast<double>(k + i), 1.0, 0.1, 0.0, 0.2, 1.0, k, 2};
      s.store.map(i).insert(l, largest_variance(l));
    }
    if (!known) s.store.map(i).erase(2);  // a hole
  }
  if (known) {
    for (std::int64_t k = 0; k < 6; ++k) s.known_slots[100 - k] = static_cast<memory::Slot>(k);
  }
}

std::string round_trip(const std::string& bytes, std::vector<TrajectoryPoint>* trajectory) {
  std::istringstream in(bytes);
  StateHeader header = read_header(in);
  FilterState s(header.config);
  *trajectory = header.trajectory;
  read_particles(in, std::move(header), s);
  return save(s, *trajectory);
}

TEST(StateIoTest, ReadStatesSaveTheSameBytes) {
  for (Association association : {Association::kKnown, Association::kMaximumLikelihood}) {
    FilterConfig c;
    c.particles = 10;
    c.association = association;
    // FastSLAM 2.0 with known ids keeps covariances, which must survive the round trip too.
    if (association == Association::kKnown) c.algorithm = Algorithm::kFastSlam2;
    FilterState s(c);
    fill(s);
    const std::vector<TrajectoryPoint> trajectory = {{3, 1.0, 2.0, 0.5}};
    const std::string bytes = save(s, trajectory);
    std::vector<TrajectoryPoint> read;
    EXPECT_EQ(round_trip(bytes, &read), bytes);
    ASSERT_EQ(read.size(), 1u);
    EXPECT_EQ(read[0].y, 2.0);
  }
}

TEST(StateIoTest, IndexIsRebuiltFromTheMap) {
  FilterConfig c;
  c.particles = 4;
  c.association = Association::kDataAssociationSampling;
  FilterState s(c);
  fill(s);
  std::istringstream in(save(s, {}));
  StateHeader header = read_header(in);
  FilterState loaded(header.config);
  read_particles(in, std::move(header), loaded);
  for (std::size_t i = 0; i < 4; ++i) {
    std::size_t entries = 0;
    loaded.store.map(i).index().within(0, 0, 1e9, [&](const memory::SpatialEntry& e) {
      ++entries;
      EXPECT_EQ(e.x, loaded.store.map(i).at(e.slot).x);
    });
    EXPECT_EQ(entries, loaded.store.map(i).size());
    EXPECT_EQ(loaded.store.map(i).size(), 5u);
  }
}

TEST(StateIoTest, CorruptStreamsFail) {
  FilterConfig c;
  c.particles = 5;
  FilterState s(c);
  fill(s);
  const std::string bytes = save(s, {});
  std::vector<TrajectoryPoint> unused;
  for (std::size_t cut :
       {std::size_t{0}, std::size_t{7}, std::size_t{40}, bytes.size() / 2, bytes.size() - 1}) {
    EXPECT_THROW(round_trip(bytes.substr(0, cut), &unused), std::runtime_error) << cut;
  }
  std::string bad_magic = bytes;
  bad_magic[0] = 'X';
  EXPECT_THROW(round_trip(bad_magic, &unused), std::runtime_error);
  std::string bad_version = bytes;
  bad_version[8] = 9;
  EXPECT_THROW(round_trip(bad_version, &unused), std::runtime_error);
}

// The random streams take steps below 2^56: a larger saved step is corrupt, not a key.
TEST(StateIoTest, StepBeyondTheStreamsFails) {
  FilterConfig c;
  c.particles = 5;
  FilterState s(c);
  fill(s);
  std::vector<TrajectoryPoint> unused;
  s.counters.step = (std::uint64_t{1} << 56) - 1;
  EXPECT_NO_THROW(round_trip(save(s, {}), &unused));
  s.counters.step = std::uint64_t{1} << 56;
  EXPECT_THROW(round_trip(save(s, {}), &unused), std::runtime_error);
}

}  // namespace
}  // namespace fastslam::engine::internal
