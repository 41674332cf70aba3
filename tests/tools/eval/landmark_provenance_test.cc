#include "tools/eval/landmark_provenance.h"

#include <cstdint>
#include <map>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

constexpr std::int32_t kNone = ObservationLabels::kNoLandmark;

engine::MapLandmark landmark(std::uint64_t step, std::uint64_t j) {
  engine::MapLandmark lm;
  lm.id = step * engine::kLandmarkIdsPerScan + j;
  return lm;
}

TEST(ObservationLabels, LooksUpTheStartingObservationOfAnId) {
  ObservationLabels labels;
  labels.add(3, std::vector<std::int32_t>{4, kNone, 7});
  labels.add(12, std::vector<std::int32_t>{});
  labels.add(13, std::vector<std::int32_t>{kNone});
  EXPECT_EQ(labels.scans(), 3u);
  EXPECT_EQ(labels.label(landmark(3, 0).id), 4);
  EXPECT_EQ(labels.label(landmark(3, 1).id), kNone);
  EXPECT_EQ(labels.label(landmark(3, 2).id), 7);
  EXPECT_EQ(labels.label(landmark(13, 0).id), kNone);
  // An index past its scan's observations, an empty scan, a step with no scan recorded.
  EXPECT_FALSE(labels.label(landmark(3, 3).id));
  EXPECT_FALSE(labels.label(landmark(12, 0).id));
  EXPECT_FALSE(labels.label(landmark(4, 0).id));
  EXPECT_FALSE(labels.label(landmark(14, 0).id));
  EXPECT_FALSE(labels.label(landmark(0, 0).id));
}

TEST(ObservationLabels, RefusesStepsOutOfOrderAndBadLabels) {
  ObservationLabels labels;
  labels.add(5, std::vector<std::int32_t>{1});
  EXPECT_THROW(labels.add(5, std::vector<std::int32_t>{1}), std::invalid_argument);
  EXPECT_THROW(labels.add(4, std::vector<std::int32_t>{1}), std::invalid_argument);
  EXPECT_THROW(labels.add(6, std::vector<std::int32_t>{0, -2}), std::invalid_argument);
  // A refused scan leaves the labels as they were.
  EXPECT_EQ(labels.scans(), 1u);
  EXPECT_FALSE(labels.label(landmark(6, 0).id));
  labels.add(6, std::vector<std::int32_t>{2});
  EXPECT_EQ(labels.label(landmark(6, 0).id), 2);
}

TEST(LandmarkProvenance, CountsFalseAlarmsTwinsAndTrueLandmarks) {
  ObservationLabels labels;
  labels.add(1, std::vector<std::int32_t>{0, 1, kNone});
  labels.add(4, std::vector<std::int32_t>{1, kNone, 2});
  labels.add(9, std::vector<std::int32_t>{1, 0});
  // Landmark 1 started three, landmark 0 two, landmark 2 one; two false alarms; one id of no
  // recorded scan (a prior map's).
  const std::vector<engine::MapLandmark> map = {landmark(1, 0), landmark(1, 1), landmark(1, 2),
                                                landmark(4, 0), landmark(4, 1), landmark(4, 2),
                                                landmark(9, 0), landmark(9, 1), landmark(2, 0)};
  const Provenance p = landmark_provenance(map, labels);
  EXPECT_EQ(p.from_false_alarms, 2u);
  EXPECT_EQ(p.from_true_landmarks, 6u);
  EXPECT_EQ(p.second_copies, 3u);
  EXPECT_EQ(p.true_landmarks_mapped, 3u);
  EXPECT_EQ(p.unlabelled, 1u);
  const Provenance empty = landmark_provenance({}, labels);
  EXPECT_EQ(empty.from_false_alarms + empty.from_true_landmarks + empty.unlabelled, 0u);
}

// Random scans and maps against a direct count over a std::map of every observation's label.
TEST(LandmarkProvenance, MatchesADirectCountOnRandomRuns) {
  std::mt19937_64 random(11);
  for (int run = 0; run < 50; ++run) {
    ObservationLabels labels;
    std::map<std::uint64_t, std::int32_t> oracle;  // id -> label
    std::uint64_t step = 0;
    for (int scan = 0; scan < 200; ++scan) {
      step += 1 + random() % 9;
      std::vector<std::int32_t> scan_labels(random() % 6);
      for (std::size_t j = 0; j < scan_labels.size(); ++j) {
        scan_labels[j] = random() % 4 == 0 ? kNone : static_cast<std::int32_t>(random() % 30);
        oracle[step * engine::kLandmarkIdsPerScan + j] = scan_labels[j];
      }
      labels.add(step, scan_labels);
    }
    std::vector<engine::MapLandmark> map;
    std::size_t falses = 0, trues = 0, unknown = 0;
    std::map<std::int32_t, std::size_t> started;
    for (int k = 0; k < 60; ++k) {
      const std::uint64_t id = (random() % (step + 2)) * engine::kLandmarkIdsPerScan + random() % 7;
      engine::MapLandmark lm;
      lm.id = id;
      map.push_back(lm);
      const auto found = oracle.find(id);
      if (found == oracle.end()) {
        ++unknown;
      } else if (found->second == kNone) {
        ++falses;
      } else {
        ++trues;
        ++started[found->second];
      }
    }
    std::size_t copies = 0;
    for (const auto& [l, n] : started) copies += n - 1;
    const Provenance p = landmark_provenance(map, labels);
    EXPECT_EQ(p.from_false_alarms, falses);
    EXPECT_EQ(p.from_true_landmarks, trues);
    EXPECT_EQ(p.unlabelled, unknown);
    EXPECT_EQ(p.second_copies, copies);
    EXPECT_EQ(p.true_landmarks_mapped, started.size());
  }
}

}  // namespace
}  // namespace fastslam::tools
