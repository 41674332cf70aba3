// The Filter over a particle set shared by ranks (Filter's group constructor): ranks run as
// threads of this process (parallel::LocalGroup), each with its own kernel threads, and every
// layout (ranks x threads) must give what one process gives, bit for bit: the estimate, the
// trajectory, the evidence and counters on every rank, and, concatenated in rank order, the
// particles themselves (columns and maps). parallel/collective.h, docs/distributed.md.
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "engine/filter.h"
#include "parallel/collective.h"
#include "tests/engine/filter_scenarios.h"

namespace fastslam::engine {
namespace {

using namespace testing;  // tests/engine/filter_scenarios.h

struct RankResult {
  Snapshot particles;
  Estimate estimate;
  std::vector<TrajectoryPoint> trajectory;
  FilterStatistics statistics;
};

// Each rank's run of `s`, ranks x threads.
std::vector<RankResult> run_shared(FilterConfig config, const Scenario& s, int ranks,
                                   unsigned threads,
                                   const std::function<void(Filter&)>& prepare = {},
                                   const std::function<Snapshot(Filter&)>& take = snapshot) {
  config.threads = threads;
  parallel::LocalGroup group(ranks);
  std::vector<RankResult> out(static_cast<std::size_t>(ranks));
  std::vector<std::exception_ptr> failed(static_cast<std::size_t>(ranks));
  std::vector<std::thread> workers;
  for (int r = 0; r < ranks; ++r) {
    workers.emplace_back([&, r] {
      try {
        Filter filter(config, group.member(r));
        if (prepare) prepare(filter);
        feed(filter, s.events, 0, s.events.size());
        RankResult& mine = out[static_cast<std::size_t>(r)];
        mine.trajectory = filter.take_trajectory();
        mine.estimate = filter.estimate();
        mine.particles = take(filter);
        mine.statistics = filter.statistics();
      } catch (const std::exception& e) {
        // Said at once: a rank failing alone leaves the others waiting in a collective call.
        std::fprintf(stderr, "rank %d: %s\n", r, e.what());
        failed[static_cast<std::size_t>(r)] = std::current_exception();
      }
    });
  }
  for (std::thread& t : workers) t.join();
  for (const std::exception_ptr& e : failed) {
    if (e) std::rethrow_exception(e);
  }
  return out;
}

// The ranks' particles in rank order: the set.
Snapshot concatenated(const std::vector<RankResult>& ranks) {
  Snapshot all;
  for (const RankResult& r : ranks) {
    for (int k = 0; k < 6; ++k) {
      all.columns[k].insert(all.columns[k].end(), r.particles.columns[k].begin(),
                            r.particles.columns[k].end());
    }
    all.maps.insert(all.maps.end(), r.particles.maps.begin(), r.particles.maps.end());
  }
  return all;
}

struct SharedCase {
  const char* name;
  Algorithm algorithm;
  Association association;
  parallel::ResampleScheme scheme;
  bool ess_policy;    // resample when N_eff < M / 2 instead of every scan
  bool no_odometry;   // kBrownian: FastSLAM 2.0's covariances travel with the particles
};

class SharedFilterTest : public ::testing::TestWithParam<SharedCase> {};

TEST_P(SharedFilterTest, EveryLayoutGivesTheOneProcessBits) {
  const SharedCase& p = GetParam();
  const bool unknown = p.association != Association::kKnown;
  const Scenario& s = unknown ? clutter_scenario() : loop_scenario();
  FilterConfig config = base_config(p.algorithm, kSanitized ? 600 : 1000);
  config.association = p.association;
  config.resample.scheme = p.scheme;
  if (p.ess_policy) config.resample.when = parallel::ResamplePolicy::When::kEssBelowFraction;
  if (p.no_odometry) {
    config.motion.kind = MotionKind::kBrownian;
    config.initial_pose[3] = 3.0;
  }
  config.record_trajectory = true;
  config.threads = 1;
  Filter one(config);
  feed(one, s.events, 0, s.events.size());
  const std::vector<TrajectoryPoint> trajectory = one.take_trajectory();
  const Estimate estimate = one.estimate();
  const Snapshot particles = snapshot(one);
  const FilterStatistics statistics = one.statistics();
  ASSERT_GT(statistics.resamples, 3u);

  struct Layout {
    int ranks;
    unsigned threads;
  };
  const std::vector<Layout> layouts =
      kSanitized ? std::vector<Layout>{{2, 1}, {2, 2}, {3, 1}}
                 : std::vector<Layout>{{1, 2}, {2, 1}, {2, 2}, {3, 1}, {4, 1}};
  for (const Layout& l : layouts) {
    SCOPED_TRACE(std::to_string(l.ranks) + " ranks x " + std::to_string(l.threads) + " threads");
    const std::vector<RankResult> ranks = run_shared(config, s, l.ranks, l.threads);
    EXPECT_TRUE(identical(concatenated(ranks), particles));
    std::uint64_t sent = 0;
    for (const RankResult& r : ranks) {
      EXPECT_TRUE(identical(r.estimate, estimate));
      EXPECT_TRUE(identical(r.trajectory, trajectory));
      ASSERT_EQ(r.estimate.associations.size(), estimate.associations.size());
      for (std::size_t j = 0; j < estimate.associations.size(); ++j) {
        EXPECT_EQ(r.estimate.associations[j].landmark_id, estimate.associations[j].landmark_id);
        EXPECT_EQ(r.estimate.associations[j].outcome, estimate.associations[j].outcome);
        EXPECT_TRUE(same_bits(r.estimate.associations[j].mahalanobis2,
                              estimate.associations[j].mahalanobis2));
      }
      EXPECT_EQ(r.estimate.map_size, estimate.map_size);
      EXPECT_TRUE(same_bits(r.statistics.log_evidence, statistics.log_evidence));
      EXPECT_EQ(r.statistics.resamples, statistics.resamples);
      EXPECT_EQ(r.statistics.scans, statistics.scans);
      sent += r.statistics.exchange_copies;
    }
    if (l.ranks > 1) {
      EXPECT_GT(sent, 0u) << "no particle ever moved between ranks: the exchange is untested";
    }
  }
}

const SharedCase kSharedCases[] = {
    {"fastslam1_known_systematic", Algorithm::kFastSlam1, Association::kKnown,
     parallel::ResampleScheme::kSystematic, false, false},
    {"fastslam1_known_stratified_ess", Algorithm::kFastSlam1, Association::kKnown,
     parallel::ResampleScheme::kStratified, true, false},
    {"fastslam2_known_systematic", Algorithm::kFastSlam2, Association::kKnown,
     parallel::ResampleScheme::kSystematic, false, false},
    {"fastslam1_ml", Algorithm::kFastSlam1, Association::kMaximumLikelihood,
     parallel::ResampleScheme::kSystematic, false, false},
    {"fastslam1_das", Algorithm::kFastSlam1, Association::kDataAssociationSampling,
     parallel::ResampleScheme::kSystematic, false, false},
    {"fastslam2_ml_no_odometry", Algorithm::kFastSlam2, Association::kMaximumLikelihood,
     parallel::ResampleScheme::kStratified, false, true},
};

INSTANTIATE_TEST_SUITE_P(Cases, SharedFilterTest, ::testing::ValuesIn(kSharedCases),
                         [](const ::testing::TestParamInfo<SharedCase>& p) {
                           return std::string(p.param.name);
                         });

// The exchange sends what a receiver lacks: a prior map every rank set never travels, and after
// that a message carries the paths changed since the maps last met. Without names each message
// would carry at least one whole map.
TEST(SharedFilterMapsTest, APriorMapNeverTravels) {
  const Scenario& s = loop_scenario();
  const FilterConfig config = base_config(Algorithm::kFastSlam1, 1000);
  std::vector<MapLandmark> prior;  // far from the loop: never seen, never changed
  const int n = kSanitized ? 20000 : 100000;
  for (int k = 0; k < n; ++k) {
    prior.push_back({0, 1'000'000u + static_cast<std::uint64_t>(k), 1e4 + (k % 300) * 3.0,
                     1e4 + (k / 300) * 3.0, 0.1, 0.0, 0.1, 0.0, 0});
  }
  const auto prepare = [&](Filter& f) { f.set_map(prior); };
  // Every column, each map's size and its landmarks beyond the prior's slots.
  const auto take = [&](Filter& f) {
    Snapshot all = snapshot_columns(f);
    const memory::ParticleStore& store = f.particles();
    all.maps.resize(store.size());
    for (std::size_t i = 0; i < store.size(); ++i) {
      const memory::LandmarkTree& map = store.map(i).tree();
      all.maps[i].emplace_back(static_cast<memory::Slot>(map.size()), memory::Landmark{});
      for (auto it = map.begin(); it != map.end(); ++it) {
        if ((*it).slot >= static_cast<memory::Slot>(n)) all.maps[i].emplace_back((*it).slot, (*it).landmark);
      }
    }
    return all;
  };
  Filter one(config);
  prepare(one);
  feed(one, s.events, 0, s.events.size());
  const Snapshot particles = take(one);
  const std::uint64_t resamples = one.statistics().resamples;
  ASSERT_GT(resamples, 3u);
  for (const int ranks : {2, 3}) {
    const std::vector<RankResult> shared = run_shared(config, s, ranks, 1, prepare, take);
    EXPECT_TRUE(identical(concatenated(shared), particles)) << ranks << " ranks";
    std::uint64_t bytes = 0, copies = 0;
    for (const RankResult& r : shared) {
      bytes += r.statistics.exchange_bytes;
      copies += r.statistics.exchange_copies;
    }
    EXPECT_GT(copies, 0u);
    const double map_bytes = static_cast<double>(n) * sizeof(memory::Landmark);
    EXPECT_LT(static_cast<double>(bytes) / static_cast<double>(resamples), map_bytes / 10)
        << ranks << " ranks: " << bytes << " bytes over " << resamples << " resamplings";
  }
}

TEST(SharedFilterErrorsTest, ASetTooSmallForItsRanksIsRefusedByName) {
  FilterConfig config = base_config(Algorithm::kFastSlam1, 300);
  parallel::LocalGroup group(3);
  try {
    Filter filter(config, group.member(0));
    ADD_FAILURE() << "300 particles dealt to 3 ranks were accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("use at least 513 particles or at most 2 rank(s)"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(Filter(config, nullptr), std::invalid_argument);
}

TEST(SharedFilterErrorsTest, MultinomialAndSavingAreRefusedOnEveryRank) {
  FilterConfig config = base_config(Algorithm::kFastSlam1, 600);
  config.resample.scheme = parallel::ResampleScheme::kMultinomial;
  const Scenario& s = loop_scenario();
  parallel::LocalGroup group(1);
  try {
    Filter filter(config, group.member(0));
    ADD_FAILURE() << "multinomial resampling over a group was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("multinomial"), std::string::npos) << e.what();
  }
  config.resample.scheme = parallel::ResampleScheme::kSystematic;
  Filter filter(config, group.member(0));
  feed(filter, s.events, 0, 50);
  std::ostringstream out;
  EXPECT_THROW(filter.save(out), std::logic_error);
}

}  // namespace
}  // namespace fastslam::engine
