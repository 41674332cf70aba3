#include "tools/cli/run_output.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <spawn.h>
#include <stdexcept>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include <nlohmann/json.hpp>

namespace fastslam::tools {
namespace {

void write_map_csv(std::ofstream& file, std::span<const engine::MapLandmark> map) {
  file << "id,x,y,sxx,sxy,syy\n";
  char line[200];
  for (const engine::MapLandmark& l : map) {
    std::snprintf(line, sizeof(line), "%llu,%.6f,%.6f,%.9g,%.9g,%.9g\n",
                  static_cast<unsigned long long>(l.id), l.x, l.y, l.sxx, l.sxy, l.syy);
    file << line;
  }
}

void write_true_landmarks_csv(std::ofstream& file, std::span<const TruthLandmark> landmarks) {
  file << "id,x,y\n";
  char line[120];
  for (const TruthLandmark& l : landmarks) {
    std::snprintf(line, sizeof(line), "%llu,%.6f,%.6f\n", static_cast<unsigned long long>(l.id),
                  l.x, l.y);
    file << line;
  }
}

}  // namespace

TraceWriter::TraceWriter(const std::string& path, std::uint64_t every)
    : path_(path), every_(every == 0 ? 1 : every), file_(path) {
  if (!file_) throw std::runtime_error("--trace " + path + ": cannot open for writing");
  file_ << "t,scan,pose_error_m,landmark_rmse_m,landmarks,observed_landmarks,n_eff,"
           "distinct_particles,particle_spread_m,truth_spreads,nearest_weight\n";
}

void TraceWriter::row(double t, std::optional<double> pose_error, std::optional<double> map_error,
                      std::size_t landmarks, std::size_t observed,
                      const std::optional<ParticleDiagnostics>& particles) {
  char line[400];
  int n = std::snprintf(line, sizeof(line), "%.3f,%llu,", t,
                        static_cast<unsigned long long>(scans_ - 1));
  n += pose_error ? std::snprintf(line + n, sizeof(line) - n, "%.6f,", *pose_error)
                  : std::snprintf(line + n, sizeof(line) - n, ",");
  n += map_error ? std::snprintf(line + n, sizeof(line) - n, "%.6f,", *map_error)
                 : std::snprintf(line + n, sizeof(line) - n, ",");
  n += std::snprintf(line + n, sizeof(line) - n, "%zu,%zu,", landmarks, observed);
  if (particles) {
    const ParticleDiagnostics& d = *particles;
    n += std::snprintf(line + n, sizeof(line) - n, "%.3f,%zu,%.6f,", d.effective_sample_size,
                       d.distinct, d.spread);
    n += d.truth_spreads ? std::snprintf(line + n, sizeof(line) - n, "%.3f,", *d.truth_spreads)
                         : std::snprintf(line + n, sizeof(line) - n, ",");
    n +=
        d.nearest_weight ? std::snprintf(line + n, sizeof(line) - n, "%.6f", *d.nearest_weight) : 0;
  } else {
    n += std::snprintf(line + n, sizeof(line) - n, ",,,,");
  }
  std::snprintf(line + n, sizeof(line) - n, "\n");
  file_ << line;
}

void TraceWriter::close() {
  file_.close();
  if (!file_) throw std::runtime_error("--trace " + path_ + ": write failed");
}

void write_run_files(const std::string& dir, const RunFiles& files, std::FILE* out) {
  std::filesystem::create_directories(dir);
  auto open = [&](const std::string& name) {
    std::ofstream file(dir + "/" + name);
    if (!file) throw std::runtime_error("cannot write " + dir + "/" + name);
    return file;
  };
  open("metrics.json") << files.metrics->dump(2) << '\n';
  {
    std::ofstream file = open("landmarks.csv");
    write_map_csv(file, files.map);
  }
  std::string written = "metrics.json";
  for (const std::string& name : files.streamed) written += "," + name;
  written += ",landmarks.csv";
  if (!files.true_landmarks.empty()) {
    std::ofstream file = open("true_landmarks.csv");
    write_true_landmarks_csv(file, files.true_landmarks);
    written += ",true_landmarks.csv";
  }
  if (!files.quiet) std::fprintf(out, "  wrote %s/{%s}\n", dir.c_str(), written.c_str());
}

void draw_map(const std::string& script, const std::string& dir, std::FILE* out) {
  std::fflush(stdout);
  std::fflush(stderr);
  const std::string python = "/usr/bin/python3";
  std::vector<std::string> args = {python, script, dir};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  int status = 0;
  // The script's own output goes where the run's text goes.
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (out != stdout) posix_spawn_file_actions_adddup2(&actions, fileno(out), STDOUT_FILENO);
  const int spawned = posix_spawn(&pid, python.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) {
    std::fprintf(stderr, "warning: map.png not drawn: cannot start %s: %s\n", python.c_str(),
                 std::strerror(spawned));
    return;
  }
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::fprintf(stderr, "warning: map.png not drawn: '%s %s %s' failed (status %d)\n",
                 python.c_str(), script.c_str(), dir.c_str(), status);
  }
}

}  // namespace fastslam::tools
