// For end-to-end tests: `fastslam run ARGS` parsed as the command line parses it (the source's
// defaults included), run into a temporary directory, its metrics.json returned.
#pragma once

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/tools/temp_path.h"
#include "tools/cli/command_line.h"
#include "tools/cli/run_command.h"

namespace fastslam::tools::testing {

inline nlohmann::json parsed_run(const std::string& args, const std::string& name) {
  const std::string out = temp_path(name);
  CLI::App app;
  RunOptions o;
  RunWords w;
  add_run_options(app, o, w);
  app.parse(args + " --no-progress --no-plot --out " + out, false);
  finish_run_options(app, w, o);
  EXPECT_EQ(run_simulation(o), 0);
  std::ifstream in(out + "/metrics.json");
  nlohmann::json metrics = nlohmann::json::parse(in);
  std::filesystem::remove_all(out);
  return metrics;
}

}  // namespace fastslam::tools::testing
