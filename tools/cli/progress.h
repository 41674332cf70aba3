// A one-line progress bar for long runs: steps done of the expected total, steps per second,
// the estimated time left, the particles, the landmarks in the map and the maps' memory (the
// filter's statistics). Drawn on stderr only when it is a terminal, at most ten times a second;
// `format_progress` is the pure formatting, for tests.
//
// Ownership: borrows the FILE it draws on. Thread safety: thread-compatible (one run's loop).
// Costs: `due` is one clock read; a draw formats ~100 characters.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace fastslam::tools {

struct ProgressState {
  std::uint64_t done = 0;   // steps (controls) done
  std::uint64_t total = 0;  // expected steps; 0 when unknown (no bar, no ETA)
  std::uint32_t particles = 0;
  std::uint64_t landmarks = 0;  // in the map shown (e.g. the first particle's)
  std::int64_t map_bytes = 0;   // live bytes of all maps
};

// "[#####.....]  45.2%  12.3k/27.0k steps  4.10k steps/s  ETA 0:03  M 100  1.23k landmarks
// 12.3 MB" for `elapsed_seconds` since the start.
std::string format_progress(const ProgressState& state, double elapsed_seconds, int bar_width = 24);

class ProgressBar {
 public:
  // Draws only when `enabled` and `out` is a terminal.
  explicit ProgressBar(bool enabled, std::FILE* out = stderr);
  bool enabled() const noexcept { return enabled_; }
  // True at most ten times a second (and false when disabled): gather the state only then.
  bool due();
  void draw(const ProgressState& state);
  // The final state, then a newline.
  void finish(const ProgressState& state);

 private:
  using Clock = std::chrono::steady_clock;
  std::FILE* out_;
  bool enabled_;
  Clock::time_point start_;
  Clock::time_point last_{};
};

}  // namespace fastslam::tools
