#include "tools/cli/run_output.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <spawn.h>
#include <stdexcept>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/cli/map_picture.h"
#include "tools/io/number_text.h"

namespace fastslam::tools {
namespace {

void write_map_csv(AtomicFile& file, std::span<const engine::MapLandmark> map) {
  file.write("id,x,y,sxx,sxy,syy\n");
  TextLine line;
  for (const engine::MapLandmark& l : map) {
    line.clear();
    line.integer(l.id).put(',').fixed(l.x, 6).put(',').fixed(l.y, 6).put(',');
    line.general(l.sxx, 9).put(',').general(l.sxy, 9).put(',').general(l.syy, 9).put('\n');
    file.write(line.view());
  }
}

void write_true_landmarks_csv(AtomicFile& file, std::span<const TruthLandmark> landmarks) {
  file.write("id,x,y\n");
  TextLine line;
  for (const TruthLandmark& l : landmarks) {
    line.clear();
    line.integer(l.id).put(',').fixed(l.x, 6).put(',').fixed(l.y, 6).put('\n');
    file.write(line.view());
  }
}

// `path`, whose error the caller wraps, as "--trace PATH: ...".
AtomicFile open_trace(const std::string& path) {
  try {
    return AtomicFile(path);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string("--trace ") + e.what());
  }
}

// The canonical form of `path` when it exists.
std::optional<std::filesystem::path> existing(const std::string& path) {
  std::error_code error;
  std::filesystem::path p = std::filesystem::canonical(path, error);
  if (error) return std::nullopt;
  return p;
}

bool inside(const std::filesystem::path& child, const std::filesystem::path& parent) {
  auto c = child.begin();
  for (auto p = parent.begin(); p != parent.end(); ++p, ++c) {
    if (c == child.end() || *c != *p) return false;
  }
  return true;
}

}  // namespace

TraceWriter::TraceWriter(const std::string& path, std::uint64_t every, bool keep_text)
    : every_(every == 0 ? 1 : every), file_(open_trace(path)), keep_(keep_text) {
  write(
      "t,scan,pose_error_m,landmark_rmse_m,landmarks,observed_landmarks,n_eff,"
      "distinct_particles,particle_spread_m,truth_spreads,nearest_weight,nis_mean,"
      "landmarks_started\n");
}

void TraceWriter::row(double t, std::optional<double> pose_error, std::optional<double> map_error,
                      std::size_t landmarks, std::size_t observed,
                      const std::optional<ParticleDiagnostics>& particles,
                      const InnovationStats& since_last) {
  TextLine line;
  line.fixed(t, 3).put(',').integer(scans_ - 1).put(',');
  if (pose_error) line.fixed(*pose_error, 6);
  line.put(',');
  if (map_error) line.fixed(*map_error, 6);
  line.put(',').integer(landmarks).put(',').integer(observed).put(',');
  if (particles) {
    const ParticleDiagnostics& d = *particles;
    line.fixed(d.effective_sample_size, 3).put(',').integer(d.distinct).put(',');
    line.fixed(d.spread, 6).put(',');
    if (d.truth_spreads) line.fixed(*d.truth_spreads, 3);
    line.put(',');
    if (d.nearest_weight) line.fixed(*d.nearest_weight, 6);
  } else {
    line.text(",,,,");
  }
  line.put(',');
  if (const double nis = since_last.mean(); !std::isnan(nis)) line.fixed(nis, 6);
  line.put(',').integer(since_last.started());
  write(line.put('\n').view());
}

void TraceWriter::write(std::string_view line) {
  file_.write(line);
  if (keep_) text_ += line;
}

TraceWriter::TraceWriter(const std::string& path, std::uint64_t every, bool keep_text,
                         const std::string& earlier, std::uint64_t scans)
    : every_(every == 0 ? 1 : every), file_(open_trace(path)), scans_(scans), keep_(keep_text) {
  write(earlier);
}

void TraceWriter::close() {
  try {
    file_.commit();
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string("--trace ") + e.what());
  }
}

std::vector<std::string> check_output_dir(const std::string& dir,
                                          std::span<const std::string> inputs,
                                          std::span<const char* const> names) {
  namespace fs = std::filesystem;
  const std::string what = "--out " + dir + ": ";
  struct stat st {};
  const bool exists = ::stat(dir.c_str(), &st) == 0;
  if (exists && !S_ISDIR(st.st_mode)) {
    throw std::runtime_error(what + "exists and is not a directory");
  }
  std::error_code error;
  const fs::path out = fs::weakly_canonical(dir, error);
  if (error) throw std::runtime_error(what + error.message());
  for (const std::string& input : inputs) {
    if (input.empty() || input == "-") continue;
    const std::optional<fs::path> in = existing(input);
    if (!in) continue;
    if (inside(out, *in)) {
      throw std::runtime_error(what + (out == *in ? "is the input " : "is inside the input ") +
                               input + ": give another directory");
    }
    for (const char* name : names) {
      if (*in == out / name) {
        throw std::runtime_error(what + "the run would replace its input " + input +
                                 ": give another directory");
      }
    }
  }
  // The levels about to be created, innermost first: those not there yet.
  std::vector<std::string> created;
  for (fs::path p = fs::absolute(dir, error); !error && !p.empty() && p != p.parent_path();
       p = p.parent_path()) {
    if (p.filename().empty()) continue;  // a trailing '/'
    if (fs::exists(p, error) || error) break;
    created.push_back(p.string());
  }
  fs::create_directories(dir, error);
  if (error) throw std::runtime_error(what + "cannot create it: " + error.message());
  CreatedDir undo(created);  // removed again if the probe fails

  // A probe, so an unwritable directory is refused now rather than after the run.
  const std::string probe = dir + "/.fastslam-probe-" + std::to_string(::getpid());
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) {
    throw std::runtime_error(what + "cannot write there: " + std::strerror(errno));
  }
  ::close(fd);
  ::unlink(probe.c_str());
  undo.keep();
  return created;
}

void clear_earlier_run(const std::string& dir, std::span<const char* const> names) {
  namespace fs = std::filesystem;
  const std::string what = "--out " + dir + ": ";
  std::error_code error;
  // An earlier run's files, so this one's never sit beside them; nothing else is touched.
  for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
    const std::string file = entry.path().filename().string();
    for (const char* name : names) {
      const std::string temp = std::string(".") + name + ".tmp-";
      if (file != name && !file.starts_with(temp)) continue;
      if (entry.is_directory(error)) {
        throw std::runtime_error(what + "holds a directory named " + file +
                                 ", where the run writes a file");
      }
      if (!fs::remove(entry.path(), error) && error) {
        throw std::runtime_error(what + "cannot remove the earlier run's " + file + ": " +
                                 error.message());
      }
    }
  }
}

void prepare_output_dir(const std::string& dir, std::span<const std::string> inputs,
                        std::span<const char* const> names) {
  check_output_dir(dir, inputs, names);
  clear_earlier_run(dir, names);
}

CreatedDir::~CreatedDir() {
  for (const std::string& dir : dirs_) {
    if (::rmdir(dir.c_str()) != 0) break;  // not empty: it and its parents stay
  }
}

void check_output_file(const std::string& option, const std::string& path,
                       std::span<const std::string> inputs, const std::string& dir,
                       std::span<const char* const> names) {
  namespace fs = std::filesystem;
  std::error_code error;
  const fs::path file = fs::weakly_canonical(resolve_output_path(path), error);
  if (error) return;  // AtomicFile reports it
  for (const std::string& input : inputs) {
    if (input.empty() || input == "-") continue;
    if (const std::optional<fs::path> in = existing(input); in && *in == file) {
      throw std::runtime_error(option + " " + path + ": is the input " + input +
                               ": give another file");
    }
  }
  if (dir.empty()) return;
  const fs::path out = fs::weakly_canonical(dir, error);
  for (const char* name : names) {
    if (!error && file == out / name) {
      throw std::runtime_error(option + " " + path + ": is the run's own " + name +
                               ": give another file");
    }
  }
}

std::vector<std::string> write_run_files(const std::string& dir, const RunFiles& files,
                                         std::FILE* out) {
  std::vector<std::string> errors;
  std::vector<std::string> written, targets;
  // The renames reach the disk with one sync of their directories, at the end.
  const auto attempt = [&](const char* name, auto&& write) {
    try {
      AtomicFile file(dir + "/" + name);
      write(file);
      file.commit(DirectorySync::kDeferred);
      written.emplace_back(name);
      targets.push_back(file.target());
    } catch (const std::exception& e) {
      errors.emplace_back(e.what());
    }
  };
  attempt("landmarks.csv", [&](AtomicFile& f) { write_map_csv(f, files.map); });
  if (!files.true_landmarks.empty()) {
    attempt("true_landmarks.csv",
            [&](AtomicFile& f) { write_true_landmarks_csv(f, files.true_landmarks); });
  }
  nlohmann::json& metrics = *files.metrics;
  if (!errors.empty() && metrics.value("status", "") == "complete") {
    metrics["status"] = "failed: " + errors.front();
  }
  attempt("metrics.json", [&](AtomicFile& f) { f.write(metrics.dump(2) + '\n'); });
  sync_directories(targets);
  // The list in the order a reader expects: metrics, the streamed files, the map, the truth.
  std::string list;
  const auto add = [&](const std::string& name) {
    if (std::find(written.begin(), written.end(), name) == written.end()) return;
    list += (list.empty() ? "" : ",") + name;
  };
  add("metrics.json");
  for (const std::string& name : files.streamed) list += (list.empty() ? "" : ",") + name;
  add("landmarks.csv");
  add("true_landmarks.csv");
  if (!files.quiet && !list.empty())
    std::fprintf(out, "  wrote %s/{%s}\n", dir.c_str(), list.c_str());
  return errors;
}

void draw_map_svg(const std::string& dir, std::FILE* out, const PicturePaths* paths) {
  try {
    write_map_svg(dir, paths);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "warning: map.svg not drawn: %s\n", e.what());
    return;
  }
  if (out != nullptr) std::fprintf(out, "  wrote %s/map.svg\n", dir.c_str());
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
