// The Filter over MPI ranks (parallel/mpi_collective.h), run by distributed_mpi_test.py under
// `mpirun -n R` with FASTSLAM_TEST_THREADS threads a rank: each rank also runs the one-process
// filter itself and checks that its share of the particles, and the estimate, trajectory and
// evidence it returns, are that filter's bits. A failure on any rank fails the test.
#include <mpi.h>

#include <cstdlib>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "engine/filter.h"
#include "parallel/collective.h"
#include "parallel/mpi_collective.h"
#include "tests/engine/filter_scenarios.h"

namespace fastslam::engine {
namespace {

using namespace testing;  // tests/engine/filter_scenarios.h

unsigned threads_per_rank() {
  const char* t = std::getenv("FASTSLAM_TEST_THREADS");
  return t != nullptr ? static_cast<unsigned>(std::atoi(t)) : 1u;
}

struct MpiCase {
  const char* name;
  Algorithm algorithm;
  Association association;
};

class MpiFilterTest : public ::testing::TestWithParam<MpiCase> {};

TEST_P(MpiFilterTest, EveryRankGetsTheOneProcessBits) {
  const std::shared_ptr<parallel::Collective> group = parallel::mpi_world();
  const bool unknown = GetParam().association != Association::kKnown;
  const Scenario& s = unknown ? clutter_scenario() : loop_scenario();
  FilterConfig config = base_config(GetParam().algorithm, 1100);
  config.association = GetParam().association;
  config.record_trajectory = true;
  config.threads = 1;
  Filter one(config);
  feed(one, s.events, 0, s.events.size());
  const std::vector<TrajectoryPoint> trajectory = one.take_trajectory();
  const Estimate estimate = one.estimate();
  const Snapshot all = snapshot(one);
  const double evidence = one.statistics().log_evidence;

  config.threads = threads_per_rank();
  Filter shared(config, group);
  feed(shared, s.events, 0, s.events.size());
  EXPECT_TRUE(identical(shared.take_trajectory(), trajectory));
  EXPECT_TRUE(identical(shared.estimate(), estimate));
  EXPECT_TRUE(same_bits(shared.statistics().log_evidence, evidence));
  // This rank's share of the set.
  const parallel::ParticleShare share =
      parallel::particle_share(config.particles, group->size(), group->rank());
  Snapshot mine;
  for (int k = 0; k < 6; ++k) {
    mine.columns[k].assign(all.columns[k].begin() + static_cast<std::ptrdiff_t>(share.first),
                           all.columns[k].begin() +
                               static_cast<std::ptrdiff_t>(share.first + share.count));
  }
  mine.maps.assign(all.maps.begin() + static_cast<std::ptrdiff_t>(share.first),
                   all.maps.begin() + static_cast<std::ptrdiff_t>(share.first + share.count));
  EXPECT_TRUE(identical(snapshot(shared), mine));
  // Every rank's verdict, so that no rank passes while another fails.
  const int failed = ::testing::Test::HasFailure() ? 1 : 0;
  for (const int f : parallel::all_gather_value(*group, failed)) EXPECT_EQ(f, 0) << "a rank failed";
}

INSTANTIATE_TEST_SUITE_P(
    Cases, MpiFilterTest,
    ::testing::Values(MpiCase{"fastslam1_known", Algorithm::kFastSlam1, Association::kKnown},
                      MpiCase{"fastslam2_known", Algorithm::kFastSlam2, Association::kKnown},
                      MpiCase{"fastslam1_ml", Algorithm::kFastSlam1,
                              Association::kMaximumLikelihood}),
    [](const ::testing::TestParamInfo<MpiCase>& p) { return std::string(p.param.name); });

}  // namespace
}  // namespace fastslam::engine

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  ::testing::InitGoogleTest(&argc, argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  if (rank != 0) {
    // One report: rank 0's (every rank's failures reach it through the verdict check).
    ::testing::TestEventListeners& listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  const int code = RUN_ALL_TESTS();
  MPI_Finalize();
  return code;
}
