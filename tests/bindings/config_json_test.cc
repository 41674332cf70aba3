#include "bindings/config_json.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "engine/filter_config.h"

namespace fastslam::bindings {
namespace {

using engine::FilterConfig;

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

// The oracle: every field of FilterConfig, written out by hand, doubles compared bit for bit.
void expect_same(const FilterConfig& a, const FilterConfig& b) {
#define FASTSLAM_SAME(field) EXPECT_EQ(a.field, b.field) << #field
#define FASTSLAM_SAME_BITS(field) EXPECT_EQ(bits(a.field), bits(b.field)) << #field
  FASTSLAM_SAME(algorithm);
  FASTSLAM_SAME(particles);
  FASTSLAM_SAME(association);
  FASTSLAM_SAME(motion.kind);
  FASTSLAM_SAME_BITS(motion.wheelbase);
  FASTSLAM_SAME_BITS(motion.geometry.a);
  FASTSLAM_SAME_BITS(motion.geometry.b);
  FASTSLAM_SAME_BITS(motion.geometry.l);
  FASTSLAM_SAME_BITS(motion.geometry.h);
  FASTSLAM_SAME_BITS(motion.sigma_control[0]);
  FASTSLAM_SAME_BITS(motion.sigma_control[1]);
  FASTSLAM_SAME_BITS(sensor.sigma_range);
  FASTSLAM_SAME_BITS(sensor.sigma_bearing);
  FASTSLAM_SAME_BITS(sensor.offset.x);
  FASTSLAM_SAME_BITS(sensor.offset.y);
  FASTSLAM_SAME_BITS(sensor.offset.yaw);
  FASTSLAM_SAME_BITS(sensor.max_range);
  FASTSLAM_SAME_BITS(sensor.field_of_view);
  FASTSLAM_SAME_BITS(log_new_landmark);
  FASTSLAM_SAME_BITS(gating.gate);
  FASTSLAM_SAME_BITS(gating.search_scale);
  FASTSLAM_SAME(existence.negative_information);
  FASTSLAM_SAME_BITS(existence.initial);
  FASTSLAM_SAME_BITS(existence.seen);
  FASTSLAM_SAME_BITS(existence.missed);
  FASTSLAM_SAME_BITS(existence.remove_below);
  FASTSLAM_SAME_BITS(existence.confirm_at);
  FASTSLAM_SAME_BITS(existence.range_margin);
  FASTSLAM_SAME(resample.when);
  FASTSLAM_SAME_BITS(resample.ess_fraction);
  FASTSLAM_SAME(resample.scheme);
  FASTSLAM_SAME(seed);
  FASTSLAM_SAME(threads);
  FASTSLAM_SAME(grain);
  FASTSLAM_SAME_BITS(split_seconds);
  FASTSLAM_SAME(record_trajectory);
  FASTSLAM_SAME(motion_draw);
  FASTSLAM_SAME_BITS(ekf.gate_accept);
  FASTSLAM_SAME_BITS(ekf.gate_new);
  FASTSLAM_SAME(ekf.joint_compatibility);
  for (int i = 0; i < 5; ++i) FASTSLAM_SAME_BITS(initial_pose[i]);
  FASTSLAM_SAME_BITS(detection.probability);
  FASTSLAM_SAME_BITS(detection.clutter_density);
  FASTSLAM_SAME_BITS(loop_closure.reach);
  FASTSLAM_SAME(loop_closure.min_age);
  FASTSLAM_SAME_BITS(loop_closure.separation);
  FASTSLAM_SAME_BITS(loop_closure.max_turn);
  FASTSLAM_SAME_BITS(loop_closure.merge_gate);
#undef FASTSLAM_SAME
#undef FASTSLAM_SAME_BITS
}

// Every field away from its default, with doubles that print awkwardly.
FilterConfig unusual_config() {
  FilterConfig c;
  c.algorithm = engine::Algorithm::kFastSlam2;
  c.particles = 4'000'000'000U;
  c.association = engine::Association::kDataAssociationSampling;
  c.motion.kind = engine::MotionKind::kAckermann;
  c.motion.wheelbase = 0.1 + 0.2;
  c.motion.geometry = {3.78, 0.5, 2.83, 0.76};
  c.motion.sigma_control[0] = 1.0 / 3;
  c.motion.sigma_control[1] = 5e-324;  // the smallest subnormal
  c.sensor.sigma_range = 0.30000000000000004;
  c.sensor.sigma_bearing = std::numbers::pi / 180;
  c.sensor.offset = {-0.0, 1e-300, -std::numbers::pi};
  c.sensor.max_range = 1.7976931348623157e308;
  c.sensor.field_of_view = 2 * std::numbers::pi;
  c.log_new_landmark = -123456789.123456789;
  c.gating.gate = 9.21;
  c.gating.search_scale = 2.5;
  c.existence.negative_information = false;
  c.existence.initial = -2.2250738585072014e-308;
  c.existence.seen = 0.7;
  c.existence.missed = 1e22;
  c.existence.remove_below = -1.5;
  c.existence.confirm_at = 3.25;
  c.existence.range_margin = 0.0;
  c.resample.when = parallel::ResamplePolicy::When::kEveryStep;
  c.resample.ess_fraction = 0.1;
  c.resample.scheme = parallel::ResampleScheme::kMultinomial;
  c.seed = 18446744073709551615ULL;
  c.threads = 7;
  c.grain = 3;
  c.split_seconds = std::numeric_limits<double>::infinity();
  c.record_trajectory = true;
  c.ekf.gate_accept = 1.0000000000000002;
  c.ekf.gate_new = 4503599627370497.0;
  c.ekf.joint_compatibility = true;
  for (int i = 0; i < 5; ++i) c.initial_pose[i] = std::nextafter(i + 0.5, 10.0);
  c.detection.probability = 0.1 + 0.7;
  c.detection.clutter_density = 1e-5 / 3;
  c.loop_closure.reach = 0.1 * 3;
  c.loop_closure.min_age = 18446744073709551615ULL;
  c.loop_closure.separation = 0.7 * 3;
  c.loop_closure.max_turn = std::nextafter(0.1, 1.0);
  c.loop_closure.merge_gate = 0.3 * 7;
  return c;
}

TEST(ConfigJson, EmptyObjectIsTheDefault) {
  expect_same(config_from_json("{}"), FilterConfig{});
  expect_same(config_from_json(" \n{ }\t"), FilterConfig{});
}

TEST(ConfigJson, DefaultRoundTrips) {
  const std::string text = config_to_json(FilterConfig{});
  expect_same(config_from_json(text), FilterConfig{});
  EXPECT_EQ(config_to_json(config_from_json(text)), text);
}

TEST(ConfigJson, UnusualConfigRoundTripsBitForBit) {
  const FilterConfig c = unusual_config();
  const std::string text = config_to_json(c);
  expect_same(config_from_json(text), c);
  EXPECT_EQ(config_to_json(config_from_json(text)), text);
  EXPECT_NE(text.find("\"split_seconds\": \"never\""), std::string::npos) << text;
  EXPECT_NE(text.find("\"seed\": 18446744073709551615"), std::string::npos) << text;
  EXPECT_NE(text.find("\"x\": -0.0"), std::string::npos) << text;
}

TEST(ConfigJson, ComposedMotionDrawRoundTrips) {
  FilterConfig c;
  c.motion_draw = engine::MotionDraw::kComposed;
  const std::string text = config_to_json(c);
  EXPECT_NE(text.find("\"motion_draw\": \"composed\""), std::string::npos) << text;
  expect_same(config_from_json(text), c);
}

TEST(ConfigJson, RandomDoublesRoundTripBitForBit) {
  std::mt19937_64 random(20);
  FilterConfig c;
  for (int i = 0; i < 20000; ++i) {
    double v;
    do {
      v = std::bit_cast<double>(random());
    } while (!std::isfinite(v));
    c.log_new_landmark = v;
    c.sensor.offset.yaw = std::ldexp(static_cast<double>(random() >> 11), -53);  // in [0, 1)
    const FilterConfig back = config_from_json(config_to_json(c));
    ASSERT_EQ(bits(back.log_new_landmark), bits(v)) << config_to_json(c);
    ASSERT_EQ(bits(back.sensor.offset.yaw), bits(c.sensor.offset.yaw));
  }
}

// The keys written, as paths: every field, nothing else.
void collect_paths(const nlohmann::json& j, const std::string& prefix, std::set<std::string>& out) {
  for (const auto& item : j.items()) {
    if (item.value().is_object()) {
      collect_paths(item.value(), prefix + item.key() + ".", out);
    } else {
      out.insert(prefix + item.key());
    }
  }
}

TEST(ConfigJson, WritesEveryKey) {
  std::set<std::string> paths;
  collect_paths(nlohmann::json::parse(config_to_json(FilterConfig{})), "", paths);
  const std::set<std::string> expected = {"algorithm",
                                          "particles",
                                          "association",
                                          "motion.kind",
                                          "motion.wheelbase",
                                          "motion.geometry.a",
                                          "motion.geometry.b",
                                          "motion.geometry.l",
                                          "motion.geometry.h",
                                          "motion.sigma_control",
                                          "sensor.sigma_range",
                                          "sensor.sigma_bearing",
                                          "sensor.offset.x",
                                          "sensor.offset.y",
                                          "sensor.offset.yaw",
                                          "sensor.max_range",
                                          "sensor.field_of_view",
                                          "log_new_landmark",
                                          "gating.gate",
                                          "gating.search_scale",
                                          "existence.negative_information",
                                          "existence.initial",
                                          "existence.seen",
                                          "existence.missed",
                                          "existence.remove_below",
                                          "existence.confirm_at",
                                          "existence.range_margin",
                                          "resample.when",
                                          "resample.ess_fraction",
                                          "resample.scheme",
                                          "seed",
                                          "threads",
                                          "grain",
                                          "split_seconds",
                                          "record_trajectory",
                                          "motion_draw",
                                          "ekf.gate_accept",
                                          "ekf.gate_new",
                                          "ekf.joint_compatibility",
                                          "initial_pose",
                                          "detection.probability",
                                          "detection.clutter_density",
                                          "loop_closure.reach",
                                          "loop_closure.min_age",
                                          "loop_closure.separation",
                                          "loop_closure.max_turn",
                                          "loop_closure.merge_gate",
                                          "error_correlation"};
  EXPECT_EQ(paths, expected);
}

TEST(ConfigJson, ReadsTheDocumentedExample) {
  const FilterConfig c = config_from_json(R"({
    "algorithm": "fastslam2", "particles": 100, "association": "ml",
    "motion": {"kind": "bailey-car", "wheelbase": 4, "sigma_control": [0.3, 0.05]},
    "sensor": {"sigma_range": 0.1, "sigma_bearing": 0.0175, "max_range": 30,
               "field_of_view": 3.14, "offset": {"x": 0.5, "y": 0, "yaw": 0}},
    "existence": {"negative_information": false},
    "gating": {"gate": 9.21},
    "resample": {"when": "neff", "ess_fraction": 0.75, "scheme": "systematic"},
    "seed": 1, "threads": 0, "grain": 128, "record_trajectory": false,
    "initial_pose": [1, 2, 0.5], "log_new_landmark": -6, "split_seconds": 1e-4
  })");
  EXPECT_EQ(c.algorithm, engine::Algorithm::kFastSlam2);
  EXPECT_EQ(c.association, engine::Association::kMaximumLikelihood);
  EXPECT_EQ(c.motion.sigma_control[1], 0.05);
  EXPECT_EQ(c.sensor.offset.x, 0.5);
  EXPECT_FALSE(c.existence.negative_information);
  EXPECT_EQ(c.gating.gate, 9.21);
  EXPECT_EQ(c.gating.search_scale, FilterConfig{}.gating.search_scale);
  EXPECT_EQ(c.initial_pose[0], 1);
  EXPECT_EQ(c.initial_pose[2], 0.5);
  EXPECT_EQ(c.initial_pose[3], 0);
  EXPECT_EQ(c.split_seconds, 1e-4);
}

TEST(ConfigJson, AcceptsAliasesIntegralFloatsAndNever) {
  EXPECT_EQ(config_from_json(R"({"motion": {"kind": "victoria-park"}})").motion.kind,
            engine::MotionKind::kAckermann);
  EXPECT_EQ(config_from_json(R"({"particles": 100.0})").particles, 100U);
  EXPECT_EQ(config_from_json(R"({"seed": 1e3})").seed, 1000U);
  EXPECT_EQ(config_from_json(R"({"seed": 18446744073709551615})").seed, 18446744073709551615ULL);
  EXPECT_EQ(config_from_json(R"({"split_seconds": "never"})").split_seconds,
            std::numeric_limits<double>::infinity());
  EXPECT_EQ(config_from_json(R"({"initial_pose": [1, 2, 3, 4, 5]})").initial_pose[4], 5);
}

struct BadCase {
  const char* json;
  const char* message;  // a part of the message
};

class ConfigJsonError : public ::testing::TestWithParam<BadCase> {};

TEST_P(ConfigJsonError, NamesTheKey) {
  try {
    config_from_json(GetParam().json);
    FAIL() << "accepted: " << GetParam().json;
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_TRUE(what.starts_with("config: ")) << what;
    EXPECT_NE(what.find(GetParam().message), std::string::npos)
        << "message: " << what << "\nexpected to contain: " << GetParam().message;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Cases, ConfigJsonError,
    ::testing::Values(
        // Not JSON, or not an object.
        BadCase{"", "config: invalid JSON: parse error at line 1, column 1"},
        BadCase{"{\n  \"particles\": 5,\n}", "parse error at line 3, column 1"},
        BadCase{"{} x", "invalid JSON: parse error at line 1, column 4"},
        BadCase{"{/* a comment */}", "invalid JSON"}, BadCase{"{\"a\xff\": 1}", "invalid JSON"},
        BadCase{
            R"({"log_new_landmark": 1e999})",
            R"(config: "log_new_landmark" must be a finite number (number overflow parsing '1e999'))"},
        BadCase{R"({"motion": {"sigma_control": [0.3, -1e400]}})",
                R"("motion.sigma_control" must be a finite number)"},
        BadCase{"1e999", "config: invalid JSON: number overflow parsing '1e999'"},
        BadCase{"[]", "config: the configuration must be a JSON object (got an array"},
        BadCase{"null", "must be a JSON object (got null)"},
        // Unknown and repeated keys.
        BadCase{R"({"particels": 5})", R"(unknown key "particels" (did you mean "particles"?))"},
        BadCase{R"({"motion": {"wheelbse": 4}})",
                R"(unknown key "motion.wheelbse" (did you mean "motion.wheelbase"?))"},
        BadCase{R"({"sensor": {"offset": {"z": 1}}})",
                R"(unknown key "sensor.offset.z" (known keys of "sensor.offset": x, y, yaw))"},
        BadCase{R"({"zzzzzzzz": 1})",
                R"(unknown key "zzzzzzzz" (known keys: algorithm, particles, association, motion)"},
        BadCase{R"({"seed": 1, "seed": 2})", R"(config: repeated key "seed")"},
        BadCase{R"({"motion": {"kind": "unicycle", "kind": "none"}})",
                R"(repeated key "motion.kind")"},
        // Wrong types, lengths and ranges.
        BadCase{R"({"particles": "100"})",
                R"("particles" must be an integer in [0, 4294967295] (got "100"))"},
        BadCase{R"({"particles": -5})",
                R"("particles" must be an integer in [0, 4294967295] (got -5))"},
        BadCase{R"({"particles": 4294967296})", R"("particles" must be an integer)"},
        BadCase{R"({"particles": 1.5})",
                R"("particles" must be an integer in [0, 4294967295] (got 1.5))"},
        BadCase{R"({"seed": 18446744073709551616})",
                R"("seed" must be an integer in [0, 18446744073709551615])"},
        BadCase{R"({"threads": true})", R"("threads" must be an integer)"},
        BadCase{R"({"sensor": {"max_range": "30"}})",
                R"("sensor.max_range" must be a number (got "30"))"},
        BadCase{R"({"record_trajectory": 1})",
                R"("record_trajectory" must be true or false (got 1))"},
        BadCase{R"({"algorithm": 1})",
                R"("algorithm" must be a string: fastslam1, fastslam2 or ekf (got 1))"},
        BadCase{R"({"motion": {"kind": "bailey_car"}})",
                R"("motion.kind": unknown motion kind 'bailey_car' (bailey-car, unicycle)"},
        BadCase{R"({"resample": {"scheme": "residual"}})",
                R"("resample.scheme": unknown resampling scheme 'residual')"},
        BadCase{R"({"motion": {"sigma_control": [0.3, 0.05, 1]}})",
                R"(config: "motion.sigma_control" must be an array of 2 numbers (got 3 elements))"},
        BadCase{R"({"motion": {"sigma_control": [0.3, null]}})",
                R"("motion.sigma_control[1]" must be a number (got null))"},
        BadCase{R"({"motion": {"sigma_control": 0.3}})",
                R"("motion.sigma_control" must be an array of 2 numbers (got 0.3))"},
        BadCase{R"({"initial_pose": [1, 2]})",
                R"("initial_pose" must be an array of 3 to 5 numbers (got 2 elements))"},
        BadCase{R"({"motion": [1, 2]})",
                R"("motion" must be an object (got an array of 2 elements))"},
        BadCase{R"({"split_seconds": "sometimes"})",
                R"("split_seconds" must be a number of seconds or "never" (got "sometimes"))"},
        // Combinations engine::validate refuses.
        BadCase{R"({"particles": 0})", "config: particles must be at least 1"},
        BadCase{R"({"sensor": {"sigma_range": 0}})",
                "config: sensor.sigma_range must be finite and > 0"},
        BadCase{R"({"sensor": {"field_of_view": 7}})", "sensor.field_of_view must be in (0, 2 pi]"},
        BadCase{R"({"motion": {"wheelbase": -1}})",
                R"(config: "motion.wheelbase": BaileyCarModel)"},
        BadCase{R"({"motion": {"kind": "ackermann", "geometry": {"l": 0}}})",
                R"(config: "motion.geometry": AckermannModel)"},
        BadCase{R"({"motion": {"sigma_control": [-1, 0]}})",
                "motion.sigma_control[0] must be finite and >= 0"},
        BadCase{R"({"resample": {"ess_fraction": 1.5}})",
                R"("resample.ess_fraction" must be in [0, 1] (got 1.5))"},
        BadCase{R"({"algorithm": "ekf", "association": "das"})",
                "association 'das' is not meaningful"},
        BadCase{R"({"algorithm": "ekf", "ekf": {"gate_accept": 0}})", "ekf.gate_accept"},
        BadCase{R"({"threads": 100000})", "config: threads must be at most"},
        BadCase{R"({"grain": 0})", "config: grain must be at least 1"},
        BadCase{R"({"split_seconds": -1})", "config: split_seconds must be >= 0"},
        BadCase{R"({"existence": {"range_margin": -1}})", "existence.range_margin"},
        BadCase{R"({"gating": {"search_scale": 0.5}})", "gating.search_scale"},
        BadCase{R"({"motion_draw": "once"})", R"("motion_draw": unknown motion draw 'once')"},
        BadCase{R"({"algorithm": "ekf", "motion_draw": "composed"})",
                "config: motion_draw 'composed' is FastSLAM's"}));

TEST(ConfigJson, WritingRefusesWhatJsonCannotHold) {
  FilterConfig c;
  c.ekf.gate_accept = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(
      {
        try {
          config_to_json(c);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find("\"ekf.gate_accept\" is not finite"),
                    std::string::npos)
              << e.what();
          throw;
        }
      },
      std::invalid_argument);
  c = FilterConfig{};
  c.initial_pose[4] = -std::numeric_limits<double>::infinity();
  EXPECT_THROW(config_to_json(c), std::invalid_argument);
  c = FilterConfig{};
  c.split_seconds = -std::numeric_limits<double>::infinity();
  EXPECT_THROW(config_to_json(c), std::invalid_argument);
  c = FilterConfig{};
  c.algorithm = static_cast<engine::Algorithm>(9);
  EXPECT_THROW(config_to_json(c), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::bindings
