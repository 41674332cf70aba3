#include "tools/cli/scan_stream.h"

#include <charconv>
#include <cmath>
#include <stdexcept>

namespace fastslam::tools {
namespace {

// Shortest exact form, so a reader gets the bits back; null for what JSON cannot hold.
void put(std::string& out, double v) {
  if (!std::isfinite(v)) {
    out += "null";
    return;
  }
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  out.append(buf, static_cast<std::size_t>(r.ptr - buf));
}

void put(std::string& out, std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  out.append(buf, static_cast<std::size_t>(r.ptr - buf));
}

}  // namespace

ScanStream::ScanStream(const std::string& path) : path_(path) {
  if (path == "-") {
    file_ = stdout;
    return;
  }
  file_ = std::fopen(path.c_str(), "w");
  if (file_ == nullptr) throw std::runtime_error("--stream " + path + ": cannot open for writing");
  owned_ = true;
}

ScanStream::~ScanStream() {
  if (owned_) std::fclose(file_);
}

void ScanStream::write(double time, std::uint64_t scan, const engine::Estimate& e,
                       double latency_seconds) {
  std::string& l = line_;
  l = "{\"t\":";
  put(l, time);
  l += ",\"scan\":";
  put(l, scan);
  l += ",\"pose\":[";
  for (int k = 0; k < 3; ++k) {
    if (k > 0) l += ',';
    put(l, e.mean_pose[k]);
  }
  l += "],\"covariance\":[";
  for (int k = 0; k < 9; ++k) {
    if (k > 0) l += ',';
    put(l, e.pose_covariance[k]);
  }
  l += "],\"n_eff\":";
  put(l, e.effective_sample_size);
  l += ",\"landmarks\":";
  put(l, static_cast<std::uint64_t>(e.map_size));
  l += ",\"associations\":[";
  for (std::size_t j = 0; j < e.associations.size(); ++j) {
    const engine::ObservationAssociation& a = e.associations[j];
    if (j > 0) l += ',';
    l += "{\"observation\":";
    put(l, static_cast<std::uint64_t>(a.observation));
    l += ",\"outcome\":\"";
    l += engine::enum_name(a.outcome);
    l += "\",\"id\":";
    put(l, a.landmark_id);
    l += ",\"mahalanobis2\":";
    put(l, a.mahalanobis2);
    l += '}';
  }
  l += "],\"latency_ms\":";
  put(l, latency_seconds * 1e3);
  l += "}\n";
  if (std::fwrite(l.data(), 1, l.size(), file_) != l.size() || std::fflush(file_) != 0) {
    throw std::runtime_error("--stream " + path_ + ": write failed");
  }
}

}  // namespace fastslam::tools
