// State I/O: a state read back saves the same bytes (the oracle is the first save), for known
// and unknown association with shared and distinct maps, holes and queued controls; the index is
// rebuilt from the map; corrupt and truncated streams fail with std::runtime_error.
#include "engine/internal/state_io.h"

#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "engine/filter.h"
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
      const std::uint64_t id = known ? 100 - k : k;  // known ids: the table's
      const memory::Landmark l{static_cast<double>(k + i), 1.0, 0.1, 0.0, 0.2, 1.0, id, 2};
      s.store.map(i).insert(l, largest_variance(l));
    }
    if (!known) s.store.map(i).erase(2);  // a hole
  }
  if (known) {
    for (std::int64_t k = 0; k < 6; ++k) s.known_slots[100 - k] = static_cast<memory::Slot>(k);
  }
}

// The state `bytes` holds, read back.
std::unique_ptr<FilterState> load_state(const std::string& bytes) {
  std::istringstream in(bytes);
  StateHeader header = read_header(in);
  auto state = std::make_unique<FilterState>(header.config);
  read_particles(in, std::move(header), *state);
  return state;
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
    c.record_trajectory = true;
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
  const std::unique_ptr<FilterState> read = load_state(save(s, {}));
  const FilterState& loaded = *read;
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
  s.counters.controls = s.counters.step - s.counters.scans;
  EXPECT_NO_THROW(round_trip(save(s, {}), &unused));
  s.counters.step = std::uint64_t{1} << 56;
  s.counters.controls = s.counters.step - s.counters.scans;
  EXPECT_THROW(round_trip(save(s, {}), &unused), std::runtime_error);
}

double kNaN() { return std::numeric_limits<double>::quiet_NaN(); }

// A state the engine cannot reach, saved as is: the load refuses it, naming the field.
void expect_refused(const FilterState& s, const std::vector<TrajectoryPoint>& trajectory,
                    const std::string& needle) {
  std::vector<TrajectoryPoint> unused;
  try {
    round_trip(save(s, trajectory), &unused);
    ADD_FAILURE() << "loaded; expected a refusal naming '" << needle << "'";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(StateIoTest, FieldsBreakingTheEnginesInvariantsAreRefusedByName) {
  for (Association association : {Association::kKnown, Association::kMaximumLikelihood}) {
    SCOPED_TRACE(association == Association::kKnown ? "known ids" : "unknown ids");
    FilterConfig c;
    c.particles = 4;
    c.association = association;
    const bool known = association == Association::kKnown;
    auto fresh = [&] {
      auto s = std::make_unique<FilterState>(c);
      fill(*s);
      return s;
    };
    std::vector<TrajectoryPoint> unused;
    ASSERT_NO_THROW(round_trip(save(*fresh(), {}), &unused));
    auto changed = [&](auto&& change, const std::string& needle,
                       const std::vector<TrajectoryPoint>& trajectory = {}) {
      SCOPED_TRACE(needle);
      std::unique_ptr<FilterState> s = fresh();
      change(*s);
      expect_refused(*s, trajectory, needle);
    };
    changed([](FilterState& s) { ++s.counters.scans; }, "do not add up");
    changed([](FilterState& s) { s.counters.resamples = s.counters.scans + 1; }, "resamples");
    changed([](FilterState& s) { std::swap(s.pending[0], s.pending[1]); }, "queued control 1");
    changed([](FilterState& s) { s.associations.push_back({0, AssociationOutcome::kNew, 1, 0}); },
            "scan report longer");
    changed([](FilterState&) {}, "trajectory recorded without record_trajectory",
            {{0, 1.0, 2.0, 3.0}});
    changed([](FilterState& s) { s.store.log_weight()[0] = s.store.log_weight()[1] =
                                     s.store.log_weight()[2] = s.store.log_weight()[3] =
                                         -std::numeric_limits<double>::infinity(); },
            "weight is zero");
    changed([](FilterState& s) { s.store.log_weight()[2] = 0.5; }, "particle 2");
    const auto edit = [](FilterState& s, memory::Slot slot, auto&& change) {
      // Not indexed with known ids; indexed otherwise (only the mean moves the entry).
      s.store.map(0).update(slot, change, largest_variance);
    };
    changed([&](FilterState& s) { edit(s, 0, [](memory::Landmark& l) { l.sxy = 0.2; }); },
            "landmark in slot 0 of particle 0: covariance not positive definite");
    changed([&](FilterState& s) { edit(s, 1, [](memory::Landmark& l) { l.syy = kNaN(); }); },
            "slot 1 of particle 0: covariance");
    changed([&](FilterState& s) { edit(s, 0, [](memory::Landmark& l) { l.log_odds = kNaN(); }); },
            "log-odds");
    changed([&](FilterState& s) { edit(s, 0, [](memory::Landmark& l) { l.last_seen = 13; }); },
            "last seen after the current step");
    if (known) {  // (the spatial index refuses such a mean before the save could)
      changed([&](FilterState& s) { edit(s, 0, [](memory::Landmark& l) { l.x = 1e200; }); },
              "slot 0 of particle 0: position");
      changed([&](FilterState& s) { edit(s, 3, [](memory::Landmark& l) { l.id = 5; }); },
              "slot 3 of particle 0: id differs from the known-id table's");
      // Two ids for one slot: the table's order and distinctness.
      changed([](FilterState& s) { s.known_slots[42] = 0; }, "known-id table");
    } else {
      changed([](FilterState& s) { s.known_slots[7] = 0; },
              "known-id table without known association");
    }
  }
  // FastSLAM 2.0's pose covariances must be finite; FastSLAM 1.0 keeps none and saves zeros,
  // so anything else in its block is corrupt.
  FilterConfig fs2;
  fs2.particles = 2;
  fs2.algorithm = Algorithm::kFastSlam2;
  FilterState s2(fs2);
  fill(s2);
  s2.covariances.at<3>(1)(2, 2) = kNaN();
  expect_refused(s2, {}, "pose covariance");
  // ... symmetric positive semi-definite (the proposal factors them), zero outside the block.
  FilterState indefinite(fs2);
  fill(indefinite);
  indefinite.covariances.at<3>(0)(0, 1) = indefinite.covariances.at<3>(0)(1, 0) = 2.0;
  expect_refused(indefinite, {}, "pose covariance of particle 0: not positive semi-definite");
  FilterState asymmetric(fs2);
  fill(asymmetric);
  asymmetric.covariances.at<3>(1)(0, 2) = 0.25;
  expect_refused(asymmetric, {}, "pose covariance of particle 1: not symmetric");
  FilterState outside(fs2);
  fill(outside);
  outside.covariances.values()[PoseCovariances::kSlot + 20] = 1.0;
  expect_refused(outside, {}, "pose covariance of particle 1: entry 20 outside the block");
  FilterState semidefinite(fs2);
  fill(semidefinite);
  semidefinite.covariances.at<3>(0).setZero();  // after a scan: zero, and accepted
  semidefinite.covariances.at<3>(1) << 1, 1, 0, 1, 1, 0, 0, 0, 1;  // singular, accepted
  std::vector<TrajectoryPoint> none;
  EXPECT_NO_THROW(round_trip(save(semidefinite, {}), &none));
  FilterConfig fs1;
  fs1.particles = 2;
  FilterState s1(fs1);
  fill(s1);
  std::string bytes = save(s1, {});
  // The block: its length (2 x 25) and 50 zeros, just before the six columns and the maps.
  const std::uint64_t length = 50;
  const std::size_t at = bytes.find(std::string(reinterpret_cast<const char*>(&length), 8) +
                                    std::string(50 * 8, '\0'));
  ASSERT_NE(at, std::string::npos);
  bytes[at + 8 + 7] = 0x3f;  // 0x3f00...: a small positive double
  std::vector<TrajectoryPoint> unused;
  try {
    round_trip(bytes, &unused);
    ADD_FAILURE() << "a FastSLAM 1.0 state with a pose covariance loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("pose covariance"), std::string::npos) << e.what();
  }
}

// Inputs the load fuzzer found (fuzz/regressions/filter_load_fuzzer/): each is refused by name.
TEST(StateIoTest, FuzzerFindingsAreRefusedByName) {
  const std::string dir = FASTSLAM_FUZZ_REGRESSIONS "/filter_load_fuzzer/";
  const std::pair<const char*, const char*> cases[] = {
      {"nan_after_scan.state", "pose covariance of particle 0: entry 9 outside the block"},
  };
  for (const auto& [file, needle] : cases) {
    SCOPED_TRACE(file);
    std::ifstream in(dir + file, std::ios::binary);
    ASSERT_TRUE(in) << dir + file;
    try {
      (void)Filter::load(in);
      ADD_FAILURE() << "loaded";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  }
}

// A slot far beyond the others costs one tree path (the old loader filled the holes below it
// with placeholders: 2^24 of them, 1.2 GB, for an 8 KB file), and the maps come back with the
// nodes they had: a far slot's path, shared roots and subtrees, no more. A leaf record moved to
// another slot is refused by name.
TEST(StateIoTest, MapsComeBackWithTheirNodesAndFarSlotsCostAPath) {
  FilterConfig c;
  c.particles = 4;
  c.association = Association::kMaximumLikelihood;
  FilterState s(c);
  fill(s);
  const memory::Slot kFar = 0xFFFF'FFF0u;
  const memory::Landmark far{3.0, 4.0, 0.1, 0.0, 0.2, 1.0, 77, 2};
  memory::LandmarkTree tree = s.store.map(0).tree();
  tree.insert_at(kFar, far);
  s.store.map(0) = memory::ParticleMap(std::move(tree), memory::Indexing::kSpatial,
                                       largest_variance);
  const std::string good = save(s, {});
  const std::unique_ptr<FilterState> read = load_state(good);
  const FilterState& loaded = *read;
  ASSERT_EQ(loaded.store.map(0).size(), 6u);
  EXPECT_EQ(*loaded.store.map(0).find(kFar), far);
  for (std::size_t i = 1; i < 4; ++i) {
    EXPECT_EQ(loaded.store.map(i).shares_root_with(loaded.store.map(i - 1)),
              s.store.map(i).shares_root_with(s.store.map(i - 1)));
  }
  const std::int64_t per_landmark = memory::LandmarkTree::kMaxHeight + 1 + 4;  // path + index
  EXPECT_LE(loaded.heap.stats().live_nodes, 2 * 6 * per_landmark);

  // The far landmark's leaf record: tag 0, base slot, occupancy 1, the landmark.
  std::string leaf(1, '\0');
  leaf.append(reinterpret_cast<const char*>(&kFar), 4);
  const std::uint32_t one = 1;
  leaf.append(reinterpret_cast<const char*>(&one), 4);
  leaf.append(reinterpret_cast<const char*>(&far), sizeof(far));
  const std::size_t at = good.find(leaf);
  ASSERT_NE(at, std::string::npos);
  std::string moved = good;
  const memory::Slot elsewhere = 0xFFFF'FF00u;
  std::memcpy(moved.data() + at + 1, &elsewhere, sizeof(elsewhere));
  std::vector<TrajectoryPoint> unused;
  try {
    round_trip(moved, &unused);
    ADD_FAILURE() << "a leaf moved to another slot loaded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("corrupt state (map graph"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("not its place under the node"), std::string::npos)
        << e.what();
  }
}

// Two large maps alternating over the particles (an order no filter makes: resampling keeps
// relatives next to each other) would cost a whole index per particle from a few bytes each;
// the loader refuses it by name instead. The same maps in ancestry order load.
TEST(StateIoTest, NeighboursThatShareNothingAreRefusedNotRebuiltAtLength) {
  FilterConfig c;
  c.particles = 400;
  c.association = Association::kMaximumLikelihood;
  FilterState s(c);
  for (int k = 0; k < 2; ++k) {
    for (std::uint64_t j = 0; j < 2000; ++j) {
      const memory::Landmark l{static_cast<double>(j) + 0.5 * k, 1.0 * k, 0.1, 0.0, 0.2, 1.0, j,
                               0};
      s.store.map(static_cast<std::size_t>(k)).insert(l, largest_variance(l));
    }
  }
  for (std::size_t i = 2; i < 400; ++i) s.store.map(i) = s.store.map(i % 2);
  std::vector<TrajectoryPoint> unused;
  try {
    round_trip(save(s, {}), &unused);
    ADD_FAILURE() << "alternating maps were rebuilt";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("differs from its neighbour's by far more"),
              std::string::npos)
        << e.what();
  }
  for (std::size_t i = 0; i < 400; ++i) s.store.map(i) = s.store.map(i < 200 ? 0 : 1);
  EXPECT_NO_THROW(round_trip(save(s, {}), &unused));
}

// Known ids keep no index: a loaded state holds exactly the nodes the saved one did, after
// maps that were copied and then changed apart (shared subtrees, not only shared roots).
TEST(StateIoTest, KnownIdMapsLoadIntoTheSameNodes) {
  FilterConfig c;
  c.particles = 6;
  c.association = Association::kKnown;
  FilterState s(c);
  fill(s);
  for (std::size_t i = 1; i < 6; ++i) {
    s.store.map(i) = s.store.map(0);
    s.store.map(i).edit_unindexed(static_cast<memory::Slot>(i % 6)).x += 0.25 * i;
  }
  const std::string bytes = save(s, {});
  const std::unique_ptr<FilterState> read = load_state(bytes);
  const FilterState& loaded = *read;
  EXPECT_EQ(loaded.heap.stats().live_nodes, s.heap.stats().live_nodes);
  EXPECT_EQ(loaded.heap.stats().live_bytes, s.heap.stats().live_bytes);
  EXPECT_EQ(save(loaded, {}), bytes);
}

}  // namespace
}  // namespace fastslam::engine::internal
