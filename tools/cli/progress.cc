#include "tools/cli/progress.h"

#include <algorithm>
#include <cmath>
#include <unistd.h>

namespace fastslam::tools {
namespace {

// 987, 12.3k, 4.56M, 7.89G.
std::string count(double v) {
  char buf[32];
  if (v < 1e3) {
    std::snprintf(buf, sizeof(buf), "%.0f", v);
  } else if (v < 1e6) {
    std::snprintf(buf, sizeof(buf), "%.3gk", v / 1e3);
  } else if (v < 1e9) {
    std::snprintf(buf, sizeof(buf), "%.3gM", v / 1e6);
  } else {
    std::snprintf(buf, sizeof(buf), "%.3gG", v / 1e9);
  }
  return buf;
}

std::string bytes(double v) {
  char buf[32];
  if (v < 1024.0 * 1024) {
    std::snprintf(buf, sizeof(buf), "%.1f kB", v / 1024);
  } else if (v < 1024.0 * 1024 * 1024) {
    std::snprintf(buf, sizeof(buf), "%.1f MB", v / (1024.0 * 1024));
  } else {
    std::snprintf(buf, sizeof(buf), "%.2f GB", v / (1024.0 * 1024 * 1024));
  }
  return buf;
}

// 0:07, 12:34, 1:02:03.
std::string clock(double seconds) {
  const long s = std::lround(std::max(0.0, seconds));
  char buf[32];
  if (s >= 3600) {
    std::snprintf(buf, sizeof(buf), "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
  } else {
    std::snprintf(buf, sizeof(buf), "%ld:%02ld", s / 60, s % 60);
  }
  return buf;
}

}  // namespace

std::string format_progress(const ProgressState& s, double elapsed, int bar_width) {
  std::string line;
  const double rate = elapsed > 0 ? s.done / elapsed : 0.0;
  if (s.total > 0) {
    const double fraction = std::min(1.0, double(s.done) / double(s.total));
    const int filled = static_cast<int>(fraction * bar_width);
    line += '[';
    line.append(filled, '#');
    line.append(bar_width - filled, '.');
    char pct[16];
    std::snprintf(pct, sizeof(pct), "] %5.1f%%  ", 100 * fraction);
    line += pct;
    line += count(s.done) + "/" + count(s.total) + " steps  ";
  } else {
    line += count(s.done) + " steps  ";
  }
  line += count(rate) + " steps/s  ";
  if (s.total > 0) {
    line += "ETA ";
    line += rate > 0 && s.done <= s.total ? clock((s.total - s.done) / rate) : "?";
    line += "  ";
  }
  line += "M " + std::to_string(s.particles) + "  " + count(double(s.landmarks)) + " landmarks  " +
          bytes(double(s.map_bytes));
  return line;
}

ProgressBar::ProgressBar(bool enabled, std::FILE* out)
    : out_(out),
      enabled_(enabled && out != nullptr && isatty(fileno(out)) != 0),
      start_(Clock::now()) {}

bool ProgressBar::due() {
  if (!enabled_) return false;
  const auto now = Clock::now();
  if (now - last_ < std::chrono::milliseconds(100)) return false;
  last_ = now;
  return true;
}

void ProgressBar::draw(const ProgressState& state) {
  if (!enabled_) return;
  const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
  // \r, the line, then clear to the end of the line (it may have shrunk).
  std::fprintf(out_, "\r%s\x1b[K", format_progress(state, elapsed).c_str());
  std::fflush(out_);
}

void ProgressBar::finish(const ProgressState& state) {
  if (!enabled_) return;
  draw(state);
  std::fprintf(out_, "\n");
  std::fflush(out_);
}

}  // namespace fastslam::tools
