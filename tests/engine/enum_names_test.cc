#include "engine/enum_names.h"

#include <algorithm>
#include <cstdint>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <gtest/gtest.h>

#include "engine/filter_config.h"
#include "engine/motion_dispatch.h"

namespace fastslam::engine {
namespace {

// Every value of E's underlying type: exactly `enumerators` are known, each writes a name that
// parses back to it, the names are distinct, and every other value writes "unknown".
template <class E>
void expect_round_trip(const std::vector<E>& enumerators) {
  static_assert(sizeof(E) == 1, "the sweep covers one-byte enums");
  const std::set<E> expected(enumerators.begin(), enumerators.end());
  std::set<std::string_view> names;
  int known = 0;
  for (int v = 0; v < 256; ++v) {
    const E value = static_cast<E>(v);
    SCOPED_TRACE(std::string(EnumNames<E>::kWhat) + " " + std::to_string(v));
    if (!expected.contains(value)) {
      EXPECT_FALSE(enum_known(value));
      EXPECT_EQ(enum_name(value), "unknown");
      continue;
    }
    ++known;
    ASSERT_TRUE(enum_known(value));
    const std::string_view name = enum_name(value);
    EXPECT_NE(name, "unknown");
    EXPECT_TRUE(names.insert(name).second) << "repeated name " << name;
    EXPECT_EQ(parse_enum<E>(name), value);
  }
  EXPECT_EQ(known, static_cast<int>(expected.size()));
  EXPECT_EQ(enum_names<E>().size(), expected.size());
  EXPECT_THROW(parse_enum<E>("unknown"), std::invalid_argument);
  EXPECT_THROW(parse_enum<E>(""), std::invalid_argument);
}

TEST(EnumNamesTest, AlgorithmRoundTrips) {
  expect_round_trip<Algorithm>({Algorithm::kFastSlam1, Algorithm::kFastSlam2, Algorithm::kEkf});
  EXPECT_EQ(to_string(Algorithm::kFastSlam2), "fastslam2");
}

TEST(EnumNamesTest, AssociationRoundTrips) {
  expect_round_trip<Association>({Association::kKnown, Association::kMaximumLikelihood,
                                  Association::kDataAssociationSampling});
  EXPECT_EQ(to_string(Association::kDataAssociationSampling), "das");
}

TEST(EnumNamesTest, MotionKindRoundTrips) {
  expect_round_trip<MotionKind>({MotionKind::kBaileyCar, MotionKind::kUnicycle,
                                 MotionKind::kAckermann, MotionKind::kBrownian,
                                 MotionKind::kBrownianCurvature});
  EXPECT_EQ(to_string(MotionKind::kAckermann), "ackermann");
  EXPECT_EQ(to_string(MotionKind::kBrownian), "none");
}

TEST(EnumNamesTest, ResamplingRoundTrips) {
  using parallel::ResamplePolicy;
  using parallel::ResampleScheme;
  expect_round_trip<ResamplePolicy::When>(
      {ResamplePolicy::When::kEveryStep, ResamplePolicy::When::kEssBelowFraction});
  expect_round_trip<ResampleScheme>(
      {ResampleScheme::kSystematic, ResampleScheme::kStratified, ResampleScheme::kMultinomial});
  EXPECT_EQ(enum_name(ResampleScheme::kStratified), "stratified");
  EXPECT_EQ(enum_name(ResamplePolicy::When::kEssBelowFraction), "neff");
}

// An alias parses to its enumerator and is never written or listed.
TEST(EnumNamesTest, AnAliasParsesButIsNeverWritten) {
  EXPECT_EQ(parse_enum<MotionKind>("victoria-park"), MotionKind::kAckermann);
  EXPECT_EQ(enum_name(MotionKind::kAckermann), "ackermann");
  const std::vector<std::string> names = enum_names<MotionKind>();
  EXPECT_EQ(std::count(names.begin(), names.end(), "victoria-park"), 0);
}

TEST(EnumNamesTest, AParseErrorNamesWhatAndListsTheValidNames) {
  try {
    parse_enum<Association>("nearest");
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "unknown association 'nearest' (known, ml or das)");
  }
  EXPECT_EQ(enum_name_list<MotionKind>(),
            "bailey-car, unicycle, ackermann, none or none-curvature");
  EXPECT_EQ(enum_name_list<parallel::ResamplePolicy::When>(), "every or neff");
}

}  // namespace
}  // namespace fastslam::engine
