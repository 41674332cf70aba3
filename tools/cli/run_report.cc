#include "tools/cli/run_report.h"

#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <sys/resource.h>

#include <nlohmann/json.hpp>
#include <oneapi/tbb/info.h>

#include "engine/enum_names.h"

namespace fastslam::tools {
namespace {

constexpr double kDegrees = 180 / std::numbers::pi;

std::int64_t peak_rss_bytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<std::int64_t>(usage.ru_maxrss) * 1024;
}

// The errors of one trajectory against one reference, under `prefix` ("pose", "gps").
void put_trajectory(nlohmann::json& m, const std::string& prefix, const TrajectoryMetrics& t) {
  m[prefix + "_rmse_m"] = t.raw.rmse;
  m[prefix + "_rmse_aligned_m"] = t.aligned.rmse;
  m[prefix + "_alignment"] = {
      {"rotation_deg", t.aligned.rotation * kDegrees}, {"x_m", t.aligned.x}, {"y_m", t.aligned.y}};
  m[prefix + "_rpe_translation_rmse_m"] = t.rpe.translation_rmse;
  if (t.rpe.rotation_rmse) m[prefix + "_rpe_rotation_rmse_deg"] = *t.rpe.rotation_rmse * kDegrees;
  m[prefix + "_rpe_pairs"] = t.rpe.pairs;
  m[prefix + "_references_used"] = t.raw.used;
  m[prefix + "_references_skipped"] = t.raw.skipped;
}

// The reference the run is judged by: truth, else GPS.
const TrajectoryMetrics* judged(const TrajectoryScores& s) {
  if (s.truth) return &*s.truth;
  if (s.gps) return &*s.gps;
  return nullptr;
}

// "12.49 m raw, 0.84 m aligned (1.27 deg), RPE 0.12 m / 0.53 deg per 10 m"
std::string describe(const TrajectoryMetrics& t, double rpe_delta) {
  char text[256];
  int n = std::snprintf(text, sizeof(text), "%.3f m raw, %.3f m aligned (%.2f deg), RPE %.3f m",
                        t.raw.rmse, t.aligned.rmse, t.aligned.rotation * kDegrees,
                        t.rpe.translation_rmse);
  if (t.rpe.rotation_rmse) {
    n += std::snprintf(text + n, sizeof(text) - n, " / %.2f deg", *t.rpe.rotation_rmse * kDegrees);
  }
  std::snprintf(text + n, sizeof(text) - n, " per %g m", rpe_delta);
  return text;
}

// GOSPA's localisation part (order 2) as the RMS distance of its assigned pairs.
double localisation_rms(const Gospa& g) {
  return g.assigned == 0 ? 0.0 : std::sqrt(g.localisation / double(g.assigned));
}

}  // namespace

bool worse_than_dead_reckoning(const RunResult& r) {
  const TrajectoryMetrics* filter = judged(r.trajectories.filter);
  const TrajectoryMetrics* baseline = judged(r.trajectories.dead_reckoning);
  return filter != nullptr && baseline != nullptr && filter->raw.rmse > baseline->raw.rmse;
}

nlohmann::json metrics_json(const RunSettings& s, const RunResult& r) {
  const engine::FilterStatistics& st = r.stats;
  const engine::FilterConfig& config = s.config;
  nlohmann::json m = {
      {"source", s.options.source},
      {"world", s.info.name},
      {"motion", engine::to_string(config.motion.kind)},
      {"algorithm", engine::to_string(config.algorithm)},
      {"particles", s.particles},
      {"association", s.association.mode},
      {"association_requested", s.options.association},
      {"seed", config.seed},
      {"threads", config.threads > 0 ? config.threads : unsigned(tbb::info::default_concurrency())},
      {"ended_by", r.ended_by},
      {"steps", st.controls},
      {"scans", st.scans},
      {"observations", st.observations},
      {"true_landmarks", s.info.landmarks.size()},
      {"landmarks", r.estimate.map.size()},
      {"wall_seconds", r.filter_seconds},
      {"source_open_seconds", r.open_seconds},
      {"source_seconds", r.open_seconds + r.source_seconds},
      {"seconds_per_phase",
       {{"predict", st.predict_seconds},
        {"associate", st.associate_seconds},
        {"update", st.update_seconds},
        {"resample", st.resample_seconds}}},
      {"scan_latency_ms",
       {{"scans", r.scan_latency.count()},
        {"p50", 1e3 * r.scan_latency.percentile(0.5)},
        {"p90", 1e3 * r.scan_latency.percentile(0.9)},
        {"p99", 1e3 * r.scan_latency.percentile(0.99)},
        {"max", 1e3 * r.scan_latency.max()},
        {"mean", 1e3 * r.scan_latency.mean()}}},
      {"innovations", r.innovations.metrics()},
      {"resamples", st.resamples},
      {"log_evidence", st.log_evidence},
      {"live_tree_nodes", st.live_nodes},
      {"live_tree_bytes", st.live_bytes},
      {"peak_rss_bytes", peak_rss_bytes()},
  };
  if (s.info.simulated) m["simulator_seconds"] = r.source_seconds;
  for (const auto& [key, value] : s.info.metrics) m[key] = value;
  if (s.association.discard_unlabelled) m["unlabelled_discarded"] = r.unlabelled_discarded;
  if (r.input_error) m["input_error"] = *r.input_error;
  m["status"] = run_status(r);
  m["warnings"] = r.warnings;
  if (const std::optional<std::string> wide = r.innovations.warning())
    m["warnings"].push_back(*wide);
  const RecordedRun& t = r.trajectories;
  m["rpe_delta_m"] = *s.options.rpe_delta;
  if (t.filter.truth) {
    put_trajectory(m, "pose", *t.filter.truth);
    m["final_position_error_m"] = std::hypot(r.estimate.mean_pose[0] - t.last_truth->x,
                                             r.estimate.mean_pose[1] - t.last_truth->y);
  }
  if (t.filter.gps) {
    put_trajectory(m, "gps", *t.filter.gps);
    m["final_gps_error_m"] = t.filter.gps->raw.last;
    m["gps_fixes_used"] = t.filter.gps->raw.used;
    m["gps_fixes_skipped"] = t.filter.gps->raw.skipped;
    m["gps_alignment_rotation_deg"] = t.filter.gps->aligned.rotation * kDegrees;
    m["initial_heading_deg"] = config.initial_pose[2] * kDegrees;
  }
  if (t.dead_reckoning.truth || t.dead_reckoning.gps) {
    nlohmann::json dr = nlohmann::json::object();
    if (t.dead_reckoning.truth) put_trajectory(dr, "pose", *t.dead_reckoning.truth);
    if (t.dead_reckoning.gps) put_trajectory(dr, "gps", *t.dead_reckoning.gps);
    m["dead_reckoning"] = dr;
    m["worse_than_dead_reckoning"] = worse_than_dead_reckoning(r);
  }
  if (r.map) {
    const MapScores& map = *r.map;
    m["landmark_rmse_m"] = map.rmse;
    m["observed_landmarks"] = map.observed;
    m["match_radius_m"] = *s.options.match_radius;
    m["matched_landmarks"] = map.paired.matched;
    m["spurious_landmarks"] = map.paired.spurious;
    m["missing_landmarks"] = map.paired.missing;
    m["landmark_precision"] = map.precision;
    m["landmark_recall"] = map.recall;
    m["gospa_m"] = map.gospa.distance;
    m["gospa_assigned"] = map.gospa.assigned;
    m["gospa_localisation_rms_m"] = localisation_rms(map.gospa);
    m["gospa_missed"] = map.gospa.missed;
    m["gospa_false"] = map.gospa.false_targets;
    m["gospa_cutoff_m"] = *s.options.match_radius;
    m["gospa_order"] = 2;
    m["ospa_m"] = map.gospa.ospa;
    if (map.gospa_aligned) {
      m["gospa_aligned_m"] = map.gospa_aligned->distance;
      m["gospa_aligned_localisation_rms_m"] = localisation_rms(*map.gospa_aligned);
      m["gospa_aligned_missed"] = map.gospa_aligned->missed;
      m["gospa_aligned_false"] = map.gospa_aligned->false_targets;
    }
    if (map.provenance) {
      // What started each reported landmark (tools/eval/landmark_provenance.h).
      m["landmark_origins"] = {{"false_alarms", map.provenance->from_false_alarms},
                               {"true_landmarks", map.provenance->from_true_landmarks},
                               {"second_copies", map.provenance->second_copies},
                               {"distinct_true_landmarks", map.provenance->true_landmarks_mapped},
                               {"unknown", map.provenance->unlabelled}};
    }
    // Components of the pair graph too large to solve exactly were paired greedily: the GOSPA
    // is then an upper bound (tools/eval/map_metrics.h).
    m["gospa_inexact_components"] = map.gospa.inexact_components;
  }
  if (config.association != engine::Association::kKnown) {
    m["landmarks_created"] = st.landmarks_created;
    m["landmarks_removed"] = st.landmarks_removed;
  }
  return m;
}

std::string run_status(const RunResult& r) {
  if (r.failure) return "failed: " + *r.failure;
  if (r.input_error) return "failed: " + *r.input_error;
  if (r.interrupted_by != 0) return "interrupted";
  return "complete";
}

void print_summary(const RunSettings& s, const RunResult& r, std::FILE* out) {
  const engine::FilterConfig& config = s.config;
  std::fprintf(out,
               "%s, M = %u, %s association, seed %llu: %llu steps, %llu scans, %zu landmarks%s\n",
               std::string(engine::to_string(config.algorithm)).c_str(), s.particles,
               s.association.mode.c_str(), static_cast<unsigned long long>(config.seed),
               static_cast<unsigned long long>(r.stats.controls),
               static_cast<unsigned long long>(r.stats.scans), r.estimate.map.size(),
               r.ended_by == "end of data" ? "" : (" (stopped by " + r.ended_by + ")").c_str());
  const RecordedRun& t = r.trajectories;
  const double delta = *s.options.rpe_delta;
  if (t.filter.truth) {
    std::fprintf(out, "  pose error: %s\n", describe(*t.filter.truth, delta).c_str());
    if (t.dead_reckoning.truth) {
      std::fprintf(out, "    dead reckoning: %s\n",
                   describe(*t.dead_reckoning.truth, delta).c_str());
    }
  }
  if (t.filter.gps) {
    std::fprintf(out, "  GPS error: %s; %zu fixes, %zu skipped, %.3f m at the end\n",
                 describe(*t.filter.gps, delta).c_str(), t.filter.gps->raw.used,
                 t.filter.gps->raw.skipped, t.filter.gps->raw.last);
    if (t.dead_reckoning.gps) {
      std::fprintf(out, "    dead reckoning: %s\n", describe(*t.dead_reckoning.gps, delta).c_str());
    }
  }
  if (r.map) {
    const MapScores& map = *r.map;
    std::fprintf(
        out,
        "  map: GOSPA %.3f m (cutoff %g m, order 2): %zu assigned at %.3f m RMS, %zu missed, "
        "%zu false; precision %.3f, recall %.3f within %g m; landmark RMSE %.3f m over %zu "
        "matched of %zu observed\n",
        map.gospa.distance, *s.options.match_radius, map.gospa.assigned,
        localisation_rms(map.gospa), map.gospa.missed, map.gospa.false_targets, map.precision,
        map.recall, *s.options.match_radius, map.rmse, map.paired.matched, map.observed);
    if (map.gospa_aligned) {
      std::fprintf(out,
                   "    with the path's alignment: GOSPA %.3f m: %zu assigned at %.3f m RMS, %zu "
                   "missed, %zu false\n",
                   map.gospa_aligned->distance, map.gospa_aligned->assigned,
                   localisation_rms(*map.gospa_aligned), map.gospa_aligned->missed,
                   map.gospa_aligned->false_targets);
    }
    if (map.provenance) {
      std::fprintf(out,
                   "    started by: %zu false alarms; %zu true landmarks, %zu of them second "
                   "copies\n",
                   map.provenance->from_false_alarms, map.provenance->from_true_landmarks,
                   map.provenance->second_copies);
    }
  }
  if (s.association.discard_unlabelled) {
    std::fprintf(out, "  mixed association: %llu unlabelled detections discarded\n",
                 static_cast<unsigned long long>(r.unlabelled_discarded));
  }
  std::fprintf(out, "  filter %.3f s, %s %.3f s (opening %.3f s), peak RSS %.1f MB\n",
               r.filter_seconds, s.info.simulated ? "simulator" : "reading",
               r.open_seconds + r.source_seconds, r.open_seconds,
               static_cast<double>(peak_rss_bytes()) / 1e6);
  if (r.scan_latency.count() > 0) {
    std::fprintf(out, "  per scan: p50 %.3f ms, p99 %.3f ms, max %.3f ms\n",
                 1e3 * r.scan_latency.percentile(0.5), 1e3 * r.scan_latency.percentile(0.99),
                 1e3 * r.scan_latency.max());
  }
  if (r.innovations.associated() > 0) {
    std::fprintf(out,
                 "  innovations: %llu associated, mean NIS %.2f (2 expected), %.1f%% beyond the "
                 "99%% bound (1%% expected)\n",
                 static_cast<unsigned long long>(r.innovations.associated()), r.innovations.mean(),
                 100.0 * r.innovations.beyond(2));
  }
  if (const std::optional<std::string> wide = r.innovations.warning()) {
    std::fprintf(stderr, "warning: %s\n", wide->c_str());
  }
  if (worse_than_dead_reckoning(r)) {
    std::fprintf(stderr,
                 "warning: the filter's position error is larger than dead reckoning's on the same "
                 "controls: it did worse than ignoring every observation\n");
  }
}

}  // namespace fastslam::tools
