// Writes the fuzzers' seed corpora into <dir>/<target>/: valid small inputs made by the
// project's own writers (a short log with and without its end marker, JSON configurations, saved
// states of small filters). fuzz/make_corpus.sh runs it and adds a few rows of each data set for
// the dataset readers.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "bindings/config_json.h"
#include "engine/filter.h"
#include "tools/io/log_format.h"

namespace {

namespace fs = std::filesystem;
using namespace fastslam;

void write(const fs::path& dir, const std::string& name, const std::string& bytes) {
  fs::create_directories(dir);
  std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
  out << bytes;
}

std::string small_log() {
  tools::Log log;
  log.header.start_pose[2] = 0.25;
  tools::Event control;
  control.time = 0.1;
  control.dt = 0.1;
  control.control = {1.0, 0.05};
  log.events.push_back(control);
  tools::Event scan;
  scan.kind = tools::EventKind::kScan;
  scan.time = 0.1;
  scan.count = 2;
  log.events.push_back(scan);
  log.observations = {{4.5, 0.3, 1}, {7.25, -0.4, -1}};
  tools::Event truth;
  truth.kind = tools::EventKind::kTruthPose;
  truth.time = 0.2;
  truth.x = 0.1;
  truth.theta = 0.01;
  log.events.push_back(truth);
  tools::Event gps;
  gps.kind = tools::EventKind::kGps;
  gps.time = 0.2;
  gps.x = 0.12;
  gps.y = -0.02;
  log.events.push_back(gps);
  log.landmarks = {{1, 4.0, 1.5}, {2, -3.0, 2.0}};
  std::ostringstream out;
  tools::write_log(out, log);
  return out.str();
}

// A small filter after a few controls and scans; tiny so the fuzzer runs many inputs a second.
std::string small_state(engine::FilterConfig config, bool queued) {
  config.threads = 1;
  engine::Filter filter(config);
  const bool known = config.association == engine::Association::kKnown;
  for (int k = 0; k < 3; ++k) {
    filter.predict({1.0, 0.1}, 0.1);
    const engine::Observation scan[] = {{4.0 - 0.1 * k, 0.4, 3}, {6.0, -0.5 + 0.05 * k, 8}};
    filter.observe(std::span<const engine::Observation>(scan, known || k != 1 ? 2 : 1));
  }
  if (queued) filter.predict({1.0, -0.1}, 0.1);
  std::ostringstream out;
  filter.save(out);
  return out.str();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_seeds <corpus dir>\n");
    return 2;
  }
  const fs::path root = argv[1];
  const std::string log = small_log();
  write(root / "log_format_fuzzer", "small.log", log);
  // The same cut before its end marker, as a log written before the marker existed.
  write(root / "log_format_fuzzer", "small_unterminated.log", log.substr(0, log.rfind("end ")));

  engine::FilterConfig json_config;
  write(root / "config_json_fuzzer", "default.json", bindings::config_to_json(json_config));
  json_config.algorithm = engine::Algorithm::kFastSlam2;
  json_config.association = engine::Association::kMaximumLikelihood;
  json_config.particles = 7;
  write(root / "config_json_fuzzer", "fastslam2_unknown.json",
        bindings::config_to_json(json_config));

  for (const auto algorithm : {engine::Algorithm::kFastSlam1, engine::Algorithm::kFastSlam2}) {
    for (const auto association :
         {engine::Association::kKnown, engine::Association::kMaximumLikelihood}) {
      engine::FilterConfig c;
      c.particles = 3;
      c.algorithm = algorithm;
      c.association = association;
      c.record_trajectory = association == engine::Association::kKnown;
      const std::string name =
          std::string(algorithm == engine::Algorithm::kFastSlam1 ? "fs1" : "fs2") +
          (association == engine::Association::kKnown ? "_known" : "_unknown");
      write(root / "filter_load_fuzzer", name + ".state", small_state(c, false));
      write(root / "filter_load_fuzzer", name + "_queued.state", small_state(c, true));
    }
  }
  return 0;
}
