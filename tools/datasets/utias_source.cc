// `--source utias`: one robot of UTIAS MRCLAM dataset 1 read whole (tools/datasets/utias.h) and
// served as a log, its counts in the run's metrics.
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <utility>

#include "tools/datasets/log_source.h"
#include "tools/datasets/source.h"
#include "tools/datasets/utias.h"

namespace fastslam::tools {

// The barcodes identify the landmarks, and a barcode in no row of Barcodes.dat is a misread:
// mixed association uses the ids and discards the rest.
FilterDefaults utias_filter_defaults() {
  FilterDefaults d;
  d.association = "mixed";
  return d;
}

std::unique_ptr<Source> open_utias_source(const SourceOptions& o) {
  if (o.data.empty()) {
    throw std::invalid_argument(
        "--source utias needs --data DIR (../shared/data/utias_mrclam/dataset1)");
  }
  UtiasOptions options = o.utias;
  options.unlabelled = o.clutter;  // known association sees landmark detections only
  Utias u = read_utias(o.data, options);
  char summary[320];
  std::snprintf(summary, sizeof(summary),
                "UTIAS MRCLAM robot %d: %zu controls, %zu scans, %zu measurements (%zu of "
                "landmarks, %zu of robots dropped, %zu unlabelled%s), %zu truth poses; landmarks "
                "11 and 17 swapped back",
                u.robot, u.odometry_samples, u.scans, u.measurements, u.landmark_detections,
                u.robot_detections_dropped, u.unlabelled_detections,
                options.unlabelled ? "" : " dropped", u.truth_poses);
  std::vector<std::pair<std::string, double>> metrics = {
      {"utias_robot", u.robot},
      {"landmark_detections", static_cast<double>(u.landmark_detections)},
      {"robot_detections_dropped", static_cast<double>(u.robot_detections_dropped)},
      {"unlabelled_detections", static_cast<double>(u.unlabelled_detections)},
      {"truth_headings_repaired", static_cast<double>(u.truth_headings_repaired)},
  };
  auto source = std::make_unique<LogSource>(std::move(u.log), o.data, summary, std::move(metrics));
  // The 15 landmarks stand 0.7-2.1 m from their nearest and a robot drives about 0.1 m/s.
  source->recommend_scoring(0.5, 1.0);
  return source;
}

}  // namespace fastslam::tools
