// The C API's contract, from C++: every bad input gets a status and the C++ exception's text
// (NULL pointers, NaN, negative counts, time going backwards, invalid JSON, corrupt saved
// states from a file and a buffer), buffers and size queries, a saved and restored filter
// continuing bit for bit, independent handles on independent threads. Run under ASan/UBSan by
// the asan preset: a crash or a leak fails it.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include "bindings/c/fastslam.h"
#include "bindings/config_json.h"
#include "engine/filter.h"

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

constexpr const char* kKnownConfig =
    R"({"particles": 16, "association": "known", "seed": 9, "threads": 2,
        "motion": {"kind": "unicycle", "sigma_control": [0.1, 0.05]}})";
constexpr const char* kMlConfig =
    R"({"algorithm": "fastslam2", "particles": 12, "association": "ml", "seed": 4, "threads": 2,
        "motion": {"kind": "unicycle", "sigma_control": [0.1, 0.05]}})";

struct Destroy {
  void operator()(fastslam_filter* f) const { fastslam_destroy(f); }
};
using Handle = std::unique_ptr<fastslam_filter, Destroy>;

Handle create(const char* json) {
  fastslam_filter* f = nullptr;
  const fastslam_status s = fastslam_create(json, &f);
  EXPECT_EQ(s, FASTSLAM_OK) << fastslam_last_error(nullptr);
  return Handle(f);
}

// A robot driving a circle among 24 landmarks on a ring, seen without noise; step k is one
// control of 0.1 s, and every 5th step a scan.
struct World {
  double x = 0, y = 0, theta = 0;

  static constexpr double kV = 1.0, kOmega = 0.2, kDt = 0.1;

  void move() {
    x += kV * kDt * std::cos(theta);
    y += kV * kDt * std::sin(theta);
    theta += kOmega * kDt;
  }

  std::vector<fastslam_observation> scan() const {
    std::vector<fastslam_observation> out;
    for (int i = 0; i < 24; ++i) {
      const double lx = 12 * std::cos(i * std::numbers::pi / 12) + 2;
      const double ly = 12 * std::sin(i * std::numbers::pi / 12) + 4;
      const double bearing =
          std::remainder(std::atan2(ly - y, lx - x) - theta, 2 * std::numbers::pi);
      if (std::abs(bearing) < 1.5) out.push_back({std::hypot(lx - x, ly - y), bearing, i});
    }
    return out;
  }
};

// Runs steps [from, to) of the world through the filter (timed calls).
void drive(fastslam_filter* f, World& world, int from, int to) {
  for (int k = from; k < to; ++k) {
    world.move();
    const double t = World::kDt * (k + 1);
    ASSERT_EQ(fastslam_predict_timed(f, World::kV, World::kOmega, World::kDt, t), FASTSLAM_OK)
        << fastslam_last_error(f);
    if (k % 5 == 4) {
      const std::vector<fastslam_observation> z = world.scan();
      ASSERT_EQ(fastslam_observe_timed(f, z.data(), z.size(), t), FASTSLAM_OK)
          << fastslam_last_error(f);
    }
  }
}

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

// Everything the filter reports, doubles as bits, for bit-for-bit comparisons.
std::vector<std::uint64_t> fingerprint(fastslam_filter* f) {
  std::vector<std::uint64_t> out;
  fastslam_estimate e;
  EXPECT_EQ(fastslam_get_estimate(f, &e), FASTSLAM_OK) << fastslam_last_error(f);
  out.push_back(bits(e.time));
  for (double v : e.mean_pose) out.push_back(bits(v));
  for (double v : e.pose_covariance) out.push_back(bits(v));
  for (double v : e.best_pose) out.push_back(bits(v));
  out.push_back(e.best_particle);
  out.push_back(bits(e.effective_sample_size));
  out.push_back(e.landmark_count);
  out.push_back(e.observation_count);
  std::size_t n = 0;
  EXPECT_EQ(fastslam_get_map(f, nullptr, 0, &n), FASTSLAM_OK);
  std::vector<fastslam_landmark> map(n);
  EXPECT_EQ(fastslam_get_map(f, map.data(), map.size(), &n), FASTSLAM_OK);
  for (const fastslam_landmark& l : map) {
    for (double v : {l.x, l.y, l.sxx, l.sxy, l.syy, l.log_odds}) out.push_back(bits(v));
    out.push_back(l.id);
    out.push_back(static_cast<std::uint64_t>(l.last_seen));
    out.push_back(l.slot);
  }
  EXPECT_EQ(fastslam_get_associations(f, nullptr, 0, &n), FASTSLAM_OK);
  std::vector<fastslam_association> associations(n);
  EXPECT_EQ(fastslam_get_associations(f, associations.data(), n, &n), FASTSLAM_OK);
  for (const fastslam_association& a : associations) {
    out.push_back(a.observation);
    out.push_back(static_cast<std::uint64_t>(a.outcome));
    out.push_back(a.landmark_id);
    out.push_back(bits(a.mahalanobis2));
  }
  return out;
}

std::vector<unsigned char> save(fastslam_filter* f) {
  std::size_t size = 0;
  EXPECT_EQ(fastslam_save_buffer(f, nullptr, 0, &size), FASTSLAM_OK) << fastslam_last_error(f);
  std::vector<unsigned char> bytes(size);
  EXPECT_EQ(fastslam_save_buffer(f, bytes.data(), bytes.size(), &size), FASTSLAM_OK)
      << fastslam_last_error(f);
  return bytes;
}

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("fastslam_c_api_test_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

void write_file(const std::string& path, const unsigned char* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
}

// The what() of the C++ exception `f` throws.
template <class F>
std::string exception_text(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no exception)";
}

TEST(CApi, VersionAndStatusNames) {
  EXPECT_STREQ(fastslam_version(), FASTSLAM_VERSION);
  EXPECT_STREQ(fastslam_status_string(FASTSLAM_OK), "FASTSLAM_OK");
  EXPECT_STREQ(fastslam_status_string(FASTSLAM_CORRUPT_STATE), "FASTSLAM_CORRUPT_STATE");
  EXPECT_STREQ(fastslam_status_string(static_cast<fastslam_status>(99)), "unknown status");
}

TEST(CApi, CreatesFromJsonAndReportsItsConfig) {
  Handle f = create("{}");
  std::size_t size = 0;
  ASSERT_EQ(fastslam_get_config(f.get(), nullptr, 0, &size), FASTSLAM_OK);
  std::string text(size, '\0');
  ASSERT_EQ(fastslam_get_config(f.get(), text.data(), text.size(), &size), FASTSLAM_OK);
  EXPECT_EQ(text.back(), '\0');
  text.pop_back();
  EXPECT_EQ(text, fastslam::bindings::config_to_json(fastslam::engine::FilterConfig{}));
  // Too small: nothing written, the size needed reported.
  std::string small(10, 'x');
  EXPECT_EQ(fastslam_get_config(f.get(), small.data(), small.size(), &size),
            FASTSLAM_BUFFER_TOO_SMALL);
  EXPECT_EQ(size, text.size() + 1);
  EXPECT_EQ(small, std::string(10, 'x'));
  EXPECT_NE(std::string(fastslam_last_error(f.get())).find("fastslam_get_config"),
            std::string::npos);
}

TEST(CApi, CreateRefusesBadConfigurationsWithTheParsersMessage) {
  fastslam_filter* f = reinterpret_cast<fastslam_filter*>(0x1);
  EXPECT_EQ(fastslam_create(nullptr, &f), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(f, nullptr);
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_create: json_config is NULL");
  EXPECT_EQ(fastslam_create("{}", nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_create: out is NULL");

  for (const char* json : {"", "{", "[1]", R"({"particels": 5})", R"({"particles": -1})",
                           R"({"motion": {"sigma_control": [0.3, 0.05, 1]}})",
                           R"({"sensor": {"sigma_range": 0}})", R"({"algorithm": "ekf"})"}) {
    f = reinterpret_cast<fastslam_filter*>(0x1);
    EXPECT_EQ(fastslam_create(json, &f), FASTSLAM_INVALID_ARGUMENT) << json;
    EXPECT_EQ(f, nullptr);
    const std::string expected = exception_text(
        [&] { fastslam::engine::Filter filter(fastslam::bindings::config_from_json(json)); });
    EXPECT_EQ(fastslam_last_error(nullptr), expected) << json;
  }
  EXPECT_NE(std::string(fastslam_last_error(nullptr)).find("EkfSlam"), std::string::npos);
}

TEST(CApi, NullHandleIsRefusedEverywhere) {
  fastslam_estimate e;
  fastslam_statistics s;
  std::size_t n = 0;
  void* data = nullptr;
  const fastslam_observation z{1.0, 0.0, 0};
  char text[8];
  EXPECT_EQ(fastslam_predict(nullptr, 1, 0, 0.1), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_predict: filter is NULL");
  EXPECT_EQ(fastslam_predict_timed(nullptr, 1, 0, 0.1, 1), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_observe(nullptr, &z, 1), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_observe_timed(nullptr, &z, 1, 1), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_observe_timed: filter is NULL");
  EXPECT_EQ(fastslam_get_estimate(nullptr, &e), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_map(nullptr, nullptr, 0, &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_associations(nullptr, nullptr, 0, &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_statistics(nullptr, &s), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_config(nullptr, text, sizeof text, &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_save_file(nullptr, "/tmp/x"), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_save_buffer(nullptr, nullptr, 0, &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_save_alloc(nullptr, &data, &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_save_alloc: filter is NULL");
  fastslam_destroy(nullptr);
  fastslam_free(nullptr);
}

TEST(CApi, NullOutputsAreRefused) {
  Handle h = create(kKnownConfig);
  fastslam_filter* f = h.get();
  fastslam_landmark l;
  EXPECT_EQ(fastslam_get_estimate(f, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(f), "fastslam_get_estimate: out is NULL");
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_get_estimate: out is NULL");
  EXPECT_EQ(fastslam_get_map(f, &l, 1, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_associations(f, nullptr, 0, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_statistics(f, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_get_config(f, nullptr, 0, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_save_file(f, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(f), "fastslam_save_file: path is NULL");
  EXPECT_EQ(fastslam_save_buffer(f, nullptr, 0, nullptr), FASTSLAM_INVALID_ARGUMENT);
  std::size_t n = 7;
  void* data = reinterpret_cast<void*>(0x1);
  EXPECT_EQ(fastslam_save_alloc(f, nullptr, &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_save_alloc(f, &data, nullptr), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(fastslam_observe(f, nullptr, 3), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_STREQ(fastslam_last_error(f), "fastslam_observe: observations is NULL and count = 3");
  // An empty scan may come without an array.
  EXPECT_EQ(fastslam_observe(f, nullptr, 0), FASTSLAM_OK) << fastslam_last_error(f);
  EXPECT_STREQ(fastslam_last_error(f), "");

  fastslam_filter* out = reinterpret_cast<fastslam_filter*>(0x1);
  const unsigned char byte = 0;
  EXPECT_EQ(fastslam_load_file(nullptr, &out), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(out, nullptr);
  EXPECT_EQ(fastslam_load_file("/nonexistent", nullptr), FASTSLAM_INVALID_ARGUMENT);
  out = reinterpret_cast<fastslam_filter*>(0x1);
  EXPECT_EQ(fastslam_load_buffer(nullptr, 5, &out), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(out, nullptr);
  EXPECT_STREQ(fastslam_last_error(nullptr), "fastslam_load_buffer: data is NULL");
  EXPECT_EQ(fastslam_load_buffer(&byte, 1, nullptr), FASTSLAM_INVALID_ARGUMENT);
}

// A bad call leaves the filter as it was: it continues exactly as its twin that never saw it.
TEST(CApi, BadInputLeavesTheFilterUnchangedWithTheEnginesMessage) {
  Handle a = create(kKnownConfig);
  Handle b = create(kKnownConfig);
  World wa, wb;
  drive(a.get(), wa, 0, 12);
  drive(b.get(), wb, 0, 12);
  fastslam::engine::Filter reference(fastslam::bindings::config_from_json(kKnownConfig));
  reference.predict({1, 0}, 0.1, World::kDt * 12);

  const auto expect_refused = [&](fastslam_status status, auto&& engine_call) {
    EXPECT_EQ(status, FASTSLAM_INVALID_ARGUMENT);
    EXPECT_EQ(fastslam_last_error(a.get()), exception_text(engine_call));
    EXPECT_EQ(fastslam_last_error(nullptr), exception_text(engine_call));
  };
  expect_refused(fastslam_predict(a.get(), kNaN, 0, 0.1), [&] {
    reference.predict({kNaN, 0}, 0.1);
  });
  expect_refused(fastslam_predict(a.get(), 1, kInf, 0.1), [&] {
    reference.predict({1, kInf}, 0.1);
  });
  expect_refused(fastslam_predict(a.get(), 1, 0, -0.1), [&] { reference.predict({1, 0}, -0.1); });
  expect_refused(fastslam_predict(a.get(), 1, 0, kNaN), [&] { reference.predict({1, 0}, kNaN); });
  // Time going backwards, or not a time.
  expect_refused(fastslam_predict_timed(a.get(), 1, 0, 0.1, 1.0), [&] {
    reference.predict({1, 0}, 0.1, 1.0);
  });
  expect_refused(fastslam_predict_timed(a.get(), 1, 0, 0.1, kNaN), [&] {
    reference.predict({1, 0}, 0.1, kNaN);
  });
  const fastslam_observation good{5.0, 0.1, 3};
  expect_refused(fastslam_observe_timed(a.get(), &good, 1, 0.5), [&] {
    reference.observe(std::vector<fastslam::engine::Observation>{{5.0, 0.1, 3}}, 0.5);
  });
  for (const fastslam_observation bad :
       {fastslam_observation{kNaN, 0.1, 3}, fastslam_observation{5.0, kInf, 3},
        fastslam_observation{-1.0, 0.1, 3}, fastslam_observation{0.0, 0.1, 3},
        fastslam_observation{5.0, 0.1, -1}}) {
    const fastslam_observation scan[2] = {good, bad};
    expect_refused(fastslam_observe(a.get(), scan, 2), [&] {
      reference.observe(std::vector<fastslam::engine::Observation>{
          {good.range, good.bearing, good.id}, {bad.range, bad.bearing, bad.id}});
    });
  }
  // A repeated id with known association.
  const fastslam_observation twice[2] = {good, good};
  EXPECT_EQ(fastslam_observe(a.get(), twice, 2), FASTSLAM_INVALID_ARGUMENT);

  drive(a.get(), wa, 12, 30);
  drive(b.get(), wb, 12, 30);
  EXPECT_EQ(fingerprint(a.get()), fingerprint(b.get()));
}

TEST(CApi, NegativeAndHugeCountsAreRefused) {
  Handle h = create(kKnownConfig);
  fastslam_filter* f = h.get();
  const fastslam_observation z{1.0, 0.0, 0};
  EXPECT_EQ(fastslam_observe(f, &z, static_cast<std::size_t>(-1)), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(std::string(fastslam_last_error(f)),
            "fastslam_observe: count = 18446744073709551615 is more than 2147483647 (-1 as a "
            "signed number: a negative count?)");
  EXPECT_EQ(fastslam_observe(f, &z, static_cast<std::uint32_t>(-5)), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_NE(std::string(fastslam_last_error(f)).find("-5 as a signed 32-bit number"),
            std::string::npos)
      << fastslam_last_error(f);
  EXPECT_EQ(fastslam_observe_timed(f, &z, FASTSLAM_MAX_COUNT + 1, 1), FASTSLAM_INVALID_ARGUMENT);

  fastslam_landmark l;
  fastslam_association a;
  std::size_t n = 99;
  EXPECT_EQ(fastslam_get_map(f, &l, static_cast<std::size_t>(-1), &n), FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(n, 99U);
  EXPECT_EQ(fastslam_get_associations(f, &a, static_cast<std::size_t>(-3), &n),
            FASTSLAM_INVALID_ARGUMENT);
  unsigned char byte;
  EXPECT_EQ(fastslam_save_buffer(f, &byte, static_cast<std::size_t>(-1), &n),
            FASTSLAM_INVALID_ARGUMENT);
  char c;
  EXPECT_EQ(fastslam_get_config(f, &c, static_cast<std::size_t>(-1), &n),
            FASTSLAM_INVALID_ARGUMENT);
  fastslam_filter* out = nullptr;
  EXPECT_EQ(fastslam_load_buffer(&byte, static_cast<std::size_t>(-1), &out),
            FASTSLAM_INVALID_ARGUMENT);
  EXPECT_EQ(out, nullptr);
  EXPECT_NE(std::string(fastslam_last_error(nullptr)).find("a negative count?"), std::string::npos);
  // A size query ignores the capacity.
  EXPECT_EQ(fastslam_get_map(f, nullptr, static_cast<std::size_t>(-1), &n), FASTSLAM_OK);
  EXPECT_EQ(n, 0U);
}

TEST(CApi, BuffersAndSizeQueries) {
  Handle h = create(kMlConfig);
  fastslam_filter* f = h.get();
  std::size_t n = 99;
  ASSERT_EQ(fastslam_get_associations(f, nullptr, 0, &n), FASTSLAM_OK);
  EXPECT_EQ(n, 0U);  // before the first scan
  World world;
  drive(f, world, 0, 20);

  fastslam_estimate e;
  ASSERT_EQ(fastslam_get_estimate(f, &e), FASTSLAM_OK);
  EXPECT_EQ(e.time, 2.0);
  EXPECT_GT(e.landmark_count, 5U);
  EXPECT_EQ(e.observation_count, world.scan().size());

  ASSERT_EQ(fastslam_get_map(f, nullptr, 0, &n), FASTSLAM_OK);
  EXPECT_EQ(n, e.landmark_count);
  std::vector<fastslam_landmark> map(n + 2);
  std::memset(map.data(), 0xAB, map.size() * sizeof(fastslam_landmark));
  std::size_t m = 0;
  EXPECT_EQ(fastslam_get_map(f, map.data(), n - 1, &m), FASTSLAM_BUFFER_TOO_SMALL);
  EXPECT_EQ(m, n);
  EXPECT_EQ(reinterpret_cast<const unsigned char*>(map.data())[0], 0xAB);  // nothing copied
  EXPECT_NE(std::string(fastslam_last_error(f)).find("fastslam_get_map: the buffer holds"),
            std::string::npos);
  EXPECT_EQ(fastslam_get_map(f, map.data(), map.size(), &m), FASTSLAM_OK);
  EXPECT_EQ(m, n);
  EXPECT_STREQ(fastslam_last_error(f), "");
  for (std::size_t i = 1; i < n; ++i) EXPECT_LT(map[i - 1].slot, map[i].slot);  // slot order

  ASSERT_EQ(fastslam_get_associations(f, nullptr, 0, &n), FASTSLAM_OK);
  ASSERT_EQ(n, e.observation_count);
  std::vector<fastslam_association> associations(n);
  EXPECT_EQ(fastslam_get_associations(f, associations.data(), 0, &m), FASTSLAM_BUFFER_TOO_SMALL);
  EXPECT_EQ(fastslam_get_associations(f, associations.data(), n, &m), FASTSLAM_OK);
  int associated = 0;
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(associations[i].observation, i);
    associated += associations[i].outcome == FASTSLAM_ASSOCIATED;
    if (associations[i].outcome == FASTSLAM_ASSOCIATED) {
      EXPECT_TRUE(std::isfinite(associations[i].mahalanobis2));
    }
  }
  EXPECT_GT(associated, 0);

  fastslam_statistics s;
  ASSERT_EQ(fastslam_get_statistics(f, &s), FASTSLAM_OK);
  EXPECT_EQ(s.controls, 20U);
  EXPECT_EQ(s.scans, 4U);

  // The state: too small, then the size the query gave.
  ASSERT_EQ(fastslam_save_buffer(f, nullptr, 0, &n), FASTSLAM_OK);
  std::vector<unsigned char> bytes(n);
  EXPECT_EQ(fastslam_save_buffer(f, bytes.data(), n - 1, &m), FASTSLAM_BUFFER_TOO_SMALL);
  EXPECT_EQ(m, n);
  EXPECT_EQ(fastslam_save_buffer(f, bytes.data(), n, &m), FASTSLAM_OK);
  void* data = nullptr;
  ASSERT_EQ(fastslam_save_alloc(f, &data, &m), FASTSLAM_OK);
  ASSERT_EQ(m, n);
  EXPECT_EQ(std::memcmp(data, bytes.data(), n), 0);
  fastslam_free(data);
}

TEST(CApi, SavedAndRestoredFiltersContinueBitForBit) {
  for (const char* config : {kKnownConfig, kMlConfig}) {
    Handle original = create(config);
    World world;
    drive(original.get(), world, 0, 23);  // ends between scans: controls are queued
    const std::vector<unsigned char> bytes = save(original.get());

    fastslam_filter* raw = nullptr;
    ASSERT_EQ(fastslam_load_buffer(bytes.data(), bytes.size(), &raw), FASTSLAM_OK)
        << fastslam_last_error(nullptr);
    Handle from_buffer(raw);
    const std::string path = temp_path("state");
    ASSERT_EQ(fastslam_save_file(original.get(), path.c_str()), FASTSLAM_OK)
        << fastslam_last_error(original.get());
    ASSERT_EQ(fastslam_load_file(path.c_str(), &raw), FASTSLAM_OK) << fastslam_last_error(nullptr);
    Handle from_file(raw);
    std::filesystem::remove(path);
    void* data = nullptr;
    std::size_t size = 0;
    ASSERT_EQ(fastslam_save_alloc(original.get(), &data, &size), FASTSLAM_OK);
    ASSERT_EQ(fastslam_load_buffer(data, size, &raw), FASTSLAM_OK);
    fastslam_free(data);
    Handle from_alloc(raw);

    // The restored filters save the same bytes, and continue as the original.
    EXPECT_EQ(save(from_buffer.get()), bytes);
    World w1 = world, w2 = world, w3 = world;
    drive(original.get(), world, 23, 60);
    drive(from_buffer.get(), w1, 23, 60);
    drive(from_file.get(), w2, 23, 60);
    drive(from_alloc.get(), w3, 23, 60);
    const std::vector<std::uint64_t> expected = fingerprint(original.get());
    EXPECT_EQ(fingerprint(from_buffer.get()), expected);
    EXPECT_EQ(fingerprint(from_file.get()), expected);
    EXPECT_EQ(fingerprint(from_alloc.get()), expected);
  }
}

// Loads `bytes` with each of the first `limit` bytes altered (one bit, the top bit, all bits):
// each load must succeed or be refused as corrupt, and a loaded filter must run.
void expect_altered_states_refused_or_running(const std::vector<unsigned char>& bytes,
                                              const World& world, std::size_t limit) {
  for (std::size_t i = 0; i < std::min(limit, bytes.size()); ++i) {
    for (unsigned char flip : {0x01, 0x80, 0xFF}) {
      std::vector<unsigned char> altered = bytes;
      altered[i] ^= flip;
      fastslam_filter* out = nullptr;
      const fastslam_status s = fastslam_load_buffer(altered.data(), altered.size(), &out);
      ASSERT_TRUE(s == FASTSLAM_OK || s == FASTSLAM_CORRUPT_STATE)
          << "byte " << i << ": " << fastslam_status_string(s) << ": "
          << fastslam_last_error(nullptr);
      if (s != FASTSLAM_OK) continue;
      World w = world;
      for (int k = 0; k < 3; ++k) {
        w.move();
        fastslam_predict(out, World::kV, World::kOmega, World::kDt);
        const std::vector<fastslam_observation> z = w.scan();
        fastslam_observe(out, z.data(), z.size());
      }
      fastslam_estimate e;
      fastslam_get_estimate(out, &e);
      fastslam_destroy(out);
    }
  }
}

TEST(CApi, CorruptStatesAreRefusedFromABufferAndAFile) {
  Handle h = create(kMlConfig);
  World world;
  drive(h.get(), world, 0, 23);
  const std::vector<unsigned char> bytes = save(h.get());
  fastslam_filter* out = nullptr;

  // Truncated anywhere: every prefix, dense near the start (the header), sparse after.
  for (std::size_t n = 0; n < bytes.size(); n += n < 600 ? 1 : 97) {
    out = reinterpret_cast<fastslam_filter*>(0x1);
    ASSERT_EQ(fastslam_load_buffer(bytes.data(), n, &out), FASTSLAM_CORRUPT_STATE) << n;
    ASSERT_EQ(out, nullptr);
  }
  // The engine's own message.
  ASSERT_EQ(fastslam_load_buffer(bytes.data(), 100, &out), FASTSLAM_CORRUPT_STATE);
  EXPECT_EQ(fastslam_last_error(nullptr), exception_text([&] {
              std::istringstream in(std::string(bytes.begin(), bytes.begin() + 100));
              fastslam::engine::Filter::load(in);
            }));
  // Bytes after the end.
  std::vector<unsigned char> longer = bytes;
  longer.push_back(0);
  longer.push_back(7);
  EXPECT_EQ(fastslam_load_buffer(longer.data(), longer.size(), &out), FASTSLAM_CORRUPT_STATE);
  EXPECT_STREQ(fastslam_last_error(nullptr),
               "fastslam_load_buffer: 2 bytes follow the end of the saved state");
  // Not a state at all.
  const std::string text = "{\"particles\": 10}";
  EXPECT_EQ(fastslam_load_buffer(text.data(), text.size(), &out), FASTSLAM_CORRUPT_STATE);
  // Altered bytes: refused or, where only a value changed, loaded; never anything else. Every
  // byte of a state whose maps are empty (queued controls, no scan yet), and the first 600
  // bytes (header, config, scan report) of the one with maps. Not the maps' slots: a slot
  // raised by up to 2^24 is accepted by the engine's bound on holes and costs seconds and a GB
  // to rebuild before the load is refused.
  Handle fresh = create(kMlConfig);
  World fresh_world;
  for (int k = 0; k < 3; ++k) {
    fresh_world.move();
    ASSERT_EQ(fastslam_predict(fresh.get(), World::kV, World::kOmega, World::kDt), FASTSLAM_OK);
  }
  expect_altered_states_refused_or_running(save(fresh.get()), fresh_world, bytes.size());
  expect_altered_states_refused_or_running(bytes, world, 600);

  // From files: truncated, altered, absent, a directory, an unwritable path.
  const std::string path = temp_path("corrupt");
  write_file(path, bytes.data(), bytes.size() / 2);
  out = reinterpret_cast<fastslam_filter*>(0x1);
  EXPECT_EQ(fastslam_load_file(path.c_str(), &out), FASTSLAM_CORRUPT_STATE);
  EXPECT_EQ(out, nullptr);
  write_file(path, longer.data(), longer.size());
  EXPECT_EQ(fastslam_load_file(path.c_str(), &out), FASTSLAM_CORRUPT_STATE);
  EXPECT_STREQ(fastslam_last_error(nullptr),
               "fastslam_load_file: 2 bytes follow the end of the saved state");
  write_file(path, nullptr, 0);
  EXPECT_EQ(fastslam_load_file(path.c_str(), &out), FASTSLAM_CORRUPT_STATE);
  std::filesystem::remove(path);
  EXPECT_EQ(fastslam_load_file(path.c_str(), &out), FASTSLAM_IO_ERROR);
  EXPECT_NE(std::string(fastslam_last_error(nullptr)).find("No such file or directory"),
            std::string::npos)
      << fastslam_last_error(nullptr);
  EXPECT_EQ(fastslam_load_file(std::filesystem::temp_directory_path().c_str(), &out),
            FASTSLAM_IO_ERROR);
  EXPECT_EQ(fastslam_save_file(h.get(), "/nonexistent-directory/state"), FASTSLAM_IO_ERROR);
  EXPECT_NE(std::string(fastslam_last_error(h.get())).find("cannot open"), std::string::npos);
}

std::string read_whole(const std::string& path) {
  std::string text(std::filesystem::file_size(path), '\0');
  std::ifstream(path, std::ios::binary)
      .read(text.data(), static_cast<std::streamsize>(text.size()));
  return text;
}

// A save that fails part way (a full disk: a 64 KiB tmpfs, root only) leaves the file it
// would have replaced whole, and no temporary beside it.
TEST(CApi, FailedSaveLeavesThePreviousFileWhole) {
  if (::geteuid() != 0) GTEST_SKIP() << "not root: cannot mount a tmpfs";
  const std::string dir = temp_path("full");
  std::filesystem::create_directories(dir);
  if (std::system(("mount -t tmpfs -o size=64k tmpfs " + dir + " 2>/dev/null").c_str()) != 0) {
    std::filesystem::remove(dir);
    GTEST_SKIP() << "cannot mount a tmpfs";
  }
  Handle h = create(kKnownConfig);
  const std::string path = dir + "/state";
  ASSERT_EQ(fastslam_save_file(h.get(), path.c_str()), FASTSLAM_OK) << fastslam_last_error(h.get());
  const std::string before = read_whole(path);
  {
    std::ofstream filler(dir + "/filler", std::ios::binary);
    const std::string block(4096, 'x');
    while (filler.write(block.data(), static_cast<std::streamsize>(block.size()))) {
    }
  }
  World world;
  drive(h.get(), world, 0, 60);
  // Larger than the old file by more than a page: written in place, it would not fit.
  ASSERT_GT(save(h.get()).size(), before.size() + 8192);
  EXPECT_EQ(fastslam_save_file(h.get(), path.c_str()), FASTSLAM_IO_ERROR);
  EXPECT_NE(std::string(fastslam_last_error(h.get())).find("No space left on device"),
            std::string::npos)
      << fastslam_last_error(h.get());
  EXPECT_EQ(read_whole(path), before);
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    names.push_back(e.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"filler", "state"}));
  EXPECT_EQ(std::system(("umount " + dir).c_str()), 0);
  std::filesystem::remove_all(dir);
}

// A save replaces a regular file keeping its permissions, and never a device or a directory.
TEST(CApi, SaveReplacesOnlyRegularFilesAndKeepsTheirMode) {
  Handle h = create(kKnownConfig);
  const std::string path = temp_path("mode_state");
  { std::ofstream(path) << "old"; }
  std::filesystem::permissions(path, std::filesystem::perms(0640));
  ASSERT_EQ(fastslam_save_file(h.get(), path.c_str()), FASTSLAM_OK) << fastslam_last_error(h.get());
  EXPECT_EQ(std::filesystem::status(path).permissions(), std::filesystem::perms(0640));
  const std::vector<unsigned char> bytes = save(h.get());
  EXPECT_EQ(read_whole(path), std::string(bytes.begin(), bytes.end()));
  std::filesystem::remove(path);
  EXPECT_EQ(fastslam_save_file(h.get(), "/dev/null"), FASTSLAM_IO_ERROR);
  EXPECT_NE(std::string(fastslam_last_error(h.get())).find("not a regular file"), std::string::npos)
      << fastslam_last_error(h.get());
  EXPECT_TRUE(std::filesystem::is_character_file("/dev/null"));
  const std::string dir = temp_path("mode_dir");
  std::filesystem::create_directories(dir);
  EXPECT_EQ(fastslam_save_file(h.get(), dir.c_str()), FASTSLAM_IO_ERROR);
  EXPECT_TRUE(std::filesystem::is_directory(dir));
  std::filesystem::remove_all(dir);
}

TEST(CApi, ErrorsBelongToTheirHandleAndThread) {
  Handle a = create(kKnownConfig);
  Handle b = create(kKnownConfig);
  EXPECT_EQ(fastslam_predict(a.get(), kNaN, 0, 1), FASTSLAM_INVALID_ARGUMENT);
  const std::string message = fastslam_last_error(a.get());
  EXPECT_FALSE(message.empty());
  EXPECT_STREQ(fastslam_last_error(b.get()), "");
  EXPECT_EQ(fastslam_predict(b.get(), 1, 0, 1), FASTSLAM_OK);
  EXPECT_EQ(fastslam_last_error(a.get()), message);
  EXPECT_EQ(fastslam_last_error(nullptr), message);  // the thread's latest failure stays
  std::string other_thread;
  std::thread([&] {
    other_thread = fastslam_last_error(nullptr);
    fastslam_filter* f = nullptr;
    EXPECT_EQ(fastslam_create("{", &f), FASTSLAM_INVALID_ARGUMENT);
  }).join();
  EXPECT_EQ(other_thread, "");
  EXPECT_EQ(fastslam_last_error(nullptr), message);
  EXPECT_EQ(fastslam_predict(a.get(), 1, 0, 1), FASTSLAM_OK);
  EXPECT_STREQ(fastslam_last_error(a.get()), "");
}

TEST(CApi, DistinctHandlesRunConcurrently) {
  std::vector<std::vector<std::uint64_t>> results(3);
  std::vector<std::thread> threads;
  for (auto& result : results) {
    threads.emplace_back([&result] {
      Handle f = create(kMlConfig);
      World world;
      drive(f.get(), world, 0, 40);
      result = fingerprint(f.get());
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(results[1], results[0]);
  EXPECT_EQ(results[2], results[0]);
}

TEST(CApi, MatchesTheCppFilter) {
  Handle h = create(kMlConfig);
  fastslam::engine::Filter reference(fastslam::bindings::config_from_json(kMlConfig));
  World w1, w2;
  drive(h.get(), w1, 0, 40);
  for (int k = 0; k < 40; ++k) {
    w2.move();
    const double t = World::kDt * (k + 1);
    reference.predict({World::kV, World::kOmega}, World::kDt, t);
    if (k % 5 == 4) {
      std::vector<fastslam::engine::Observation> z;
      for (const fastslam_observation& o : w2.scan()) z.push_back({o.range, o.bearing, o.id});
      reference.observe(z, t);
    }
  }
  const fastslam::engine::Estimate e = reference.estimate();
  fastslam_estimate c;
  ASSERT_EQ(fastslam_get_estimate(h.get(), &c), FASTSLAM_OK);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(bits(c.mean_pose[i]), bits(e.mean_pose[i]));
  for (int i = 0; i < 9; ++i) EXPECT_EQ(bits(c.pose_covariance[i]), bits(e.pose_covariance[i]));
  EXPECT_EQ(bits(c.effective_sample_size), bits(e.effective_sample_size));
  EXPECT_EQ(c.landmark_count, e.map.size());
}

}  // namespace
