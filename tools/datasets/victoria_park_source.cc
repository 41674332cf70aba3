// `--source victoria-park`: the data set read whole (tools/datasets/victoria_park.h) and served
// as a log, with the filter settings its reader recommends.
#include <cstdio>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <utility>

#include "tools/datasets/log_source.h"
#include "tools/datasets/source.h"
#include "tools/datasets/victoria_park.h"

namespace fastslam::tools {

FilterDefaults victoria_park_filter_defaults() {
  const VictoriaParkFilterDefaults vp;
  FilterDefaults d;
  d.existence_range_margin = vp.existence_range_margin;
  d.existence_missed = vp.existence_missed;
  d.fastslam2_sigma_range = vp.fastslam2_sigma_range;
  d.fastslam2_sigma_bearing = vp.fastslam2_sigma_bearing;
  d.fastslam2_error_correlation = vp.fastslam2_error_correlation;
  return d;
}

std::unique_ptr<Source> open_victoria_park_source(const SourceOptions& o) {
  if (o.data.empty()) {
    throw std::invalid_argument(
        "--source victoria-park needs --data DIR (../shared/data/victoria_park)");
  }
  VictoriaPark vp = read_victoria_park(o.data, o.victoria_park);
  char summary[256];
  std::snprintf(summary, sizeof(summary),
                "Victoria Park: %zu controls, %zu scans, %zu detections (%zu gated out), %zu GPS "
                "fixes, initial heading %.2f deg (GPS fit RMS %.2f m)",
                vp.odometry_samples, vp.scans, vp.detections, vp.gated_out, vp.gps_fixes,
                vp.initial_heading * 180 / std::numbers::pi, vp.heading_fit_rms_m);
  return std::make_unique<LogSource>(std::move(vp.log), o.data, summary);
}

}  // namespace fastslam::tools
