#include "tools/cli/run_command.h"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <numbers>
#include <optional>
#include <span>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/angles.h"
#include "engine/ekf_slam.h"
#include "engine/enum_names.h"
#include "engine/filter.h"
#include "tools/cli/build_info.h"
#include "tools/cli/checkpoint.h"
#include "tools/cli/interrupt.h"
#include "tools/cli/memory_budget.h"
#include "tools/cli/mpi_ranks.h"
#include "tools/cli/progress.h"
#include "tools/cli/run_output.h"
#include "tools/cli/run_provenance.h"
#include "tools/cli/run_recorder.h"
#include "tools/cli/run_report.h"
#include "tools/cli/scan_stream.h"
#include "tools/eval/landmark_provenance.h"
#include "tools/eval/map_evaluation.h"
#include "tools/eval/map_metrics.h"
#include "tools/eval/particle_diagnostics.h"
#include "tools/eval/trajectory_errors.h"
#include "tools/io/atomic_file.h"
#include "tools/io/log_format.h"
#include "tools/io/tum.h"
#include "tools/sim/world.h"

namespace fastslam::tools {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// The true landmarks a run observed (by the ids its detections carry) and a kd-tree over them
// for scoring maps whose ids mean nothing.
class TruthTracker {
 public:
  explicit TruthTracker(std::span<const TruthLandmark> landmarks)
      : landmarks_(landmarks),
        observed_flags_(new bool[landmarks.size()]()),
        points_(truth_positions(landmarks)),
        index_(points_) {
    for (std::size_t i = 0; i < landmarks.size(); ++i) slot_[landmarks[i].id] = i;
  }
  // Unknown association: each scan's detections are labelled by true landmark, so that the map
  // can be traced back to them (landmark_provenance.h).
  void record_labels() { labels_.emplace(); }
  // Marks the scan's landmarks observed (and records their labels, the filter's step counter
  // at the scan being `step`); returns an id the truth lacks (when it has landmarks at all),
  // the first of the scan's.
  std::optional<std::int64_t> see(std::span<const engine::Observation> scan, std::uint64_t step) {
    std::optional<std::int64_t> unknown;
    scan_labels_.clear();
    for (const engine::Observation& z : scan) {
      std::int32_t label = ObservationLabels::kNoLandmark;
      const auto found = z.id < 0 ? slot_.end() : slot_.find(static_cast<std::uint64_t>(z.id));
      if (found != slot_.end()) {
        observed_flags_[found->second] = true;
        label = static_cast<std::int32_t>(found->second);
      } else if (z.id >= 0 && !unknown && !landmarks_.empty()) {
        unknown = z.id;
      }
      if (labels_) scan_labels_.push_back(label);
    }
    if (labels_) labels_->add(step, scan_labels_);
    return unknown;
  }
  // The map's landmarks traced to what started them; nothing unless labels were recorded.
  std::optional<Provenance> provenance(std::span<const engine::MapLandmark> map) const {
    if (!labels_) return std::nullopt;
    return landmark_provenance(map, *labels_);
  }
  std::span<const bool> observed() const { return {observed_flags_.get(), landmarks_.size()}; }
  std::size_t observed_count() const {
    return static_cast<std::size_t>(std::count(observed().begin(), observed().end(), true));
  }
  // The map paired with the truth within `match_radius` (tools/eval/map_evaluation.h).
  MapScore score(std::span<const engine::MapLandmark> map, double match_radius) const {
    return score_map(map, points_, index_, observed(), match_radius);
  }
  // Known association: each landmark against its own; else as score().
  double rmse(std::span<const engine::MapLandmark> map, bool known, double match_radius) const {
    return known ? landmark_rmse_by_id(map, landmarks_) : score(map, match_radius).rmse_m;
  }
  // Everything run_report.h reports of the map.
  // `alignment`: the rigid motion that best fits the path onto the truth, also applied to the
  // map for gospa_aligned.
  MapScores scores(std::span<const engine::MapLandmark> map, bool known, double match_radius,
                   const std::optional<AlignedAte>& alignment) const {
    MapScores s;
    s.provenance = provenance(map);
    s.paired = score(map, match_radius);
    s.rmse = known ? landmark_rmse_by_id(map, landmarks_) : s.paired.rmse_m;
    s.observed = observed_count();
    std::vector<Point> estimated = positions(map);
    const GospaOptions options{.cutoff = match_radius, .order = 2};
    s.gospa = gospa(estimated, points_, index_, observed(), options);
    if (alignment) {
      std::vector<Point> moved(estimated.size());
      const double c = std::cos(alignment->rotation), sn = std::sin(alignment->rotation);
      for (std::size_t i = 0; i < moved.size(); ++i) {
        const Point& p = estimated[i];
        moved[i] = {c * p.x - sn * p.y + alignment->x, sn * p.x + c * p.y + alignment->y};
      }
      s.gospa_aligned = gospa(moved, points_, index_, observed(), options);
    }
    const Detection d = precision_recall(estimated, points_, index_, observed(), match_radius);
    s.precision = d.precision;
    s.recall = d.recall;
    return s;
  }

 private:
  static std::vector<Point> truth_positions(std::span<const TruthLandmark> landmarks) {
    std::vector<Point> out(landmarks.size());
    for (std::size_t i = 0; i < landmarks.size(); ++i) out[i] = {landmarks[i].x, landmarks[i].y};
    return out;
  }

  std::span<const TruthLandmark> landmarks_;
  std::unordered_map<std::uint64_t, std::size_t> slot_;
  std::unique_ptr<bool[]> observed_flags_;
  std::vector<Point> points_;
  TruthIndex index_;
  std::optional<ObservationLabels> labels_;
  std::vector<std::int32_t> scan_labels_;
};

// Where a run stands in its source: events consumed, controls and scans among them, and the
// latest truth pose (for the trace).
struct Position {
  std::uint64_t events = 0, controls = 0, scans = 0;
  std::optional<StampedPose> last_truth;
};

// What a run with --checkpoint keeps to write one (tools/cli/checkpoint.h).
struct Checkpointing {
  std::string path;
  std::uint64_t every = 1;
  nlohmann::json identity;
  std::vector<engine::TrajectoryPoint> poses;  // every pose handed to the recorder so far
};

// What the loop reads from and reports to besides the filter.
struct RunLoop {
  const RunOptions& options;
  const AssociationChoice& association;
  Source& source;
  TruthTracker& truth;
  RunRecorder& recorder;
  TraceWriter* trace;  // null: no trace
  ScanStream* stream;  // null: no stream
  ProgressBar& progress;
  ProgressState& state;
  Position start;                       // where the loop begins: 0, or a checkpoint's position
  engine::FilterStatistics before;      // a resumed run's phase timings before its checkpoint
  Checkpointing* checkpoint = nullptr;  // null: no checkpoints
  // A particle set shared by ranks (null: one process): every rank runs this loop over the
  // same events, and they stop together (drive).
  parallel::Collective* group = nullptr;
  bool stream_estimates = false;  // the scans' estimates are taken (every rank) for --stream
};

// One rank's state at an event, for the ranks to stop together.
struct RankStatus {
  int signal = 0;
  int out_of_time = 0;
  int failed = 0;
  int input_over = 0;         // the run ends here: the source ended (or failed), or --max-steps
  std::uint64_t input = 0;    // InputDigest of the events read so far
};

// A running digest (FNV-1a) of the events a rank has read, so ranks that read different input
// (a file that differs between nodes, other options in an MPMD launch) find out at the next
// event instead of computing on it.
class InputDigest {
 public:
  void add(const Event& e, std::span<const engine::Observation> scan) {
    mix(static_cast<std::uint64_t>(e.kind));
    for (const double v : {e.time, e.dt, e.control.u0, e.control.u1, e.x, e.y, e.theta}) mix(v);
    if (e.kind != EventKind::kScan) return;
    mix(static_cast<std::uint64_t>(scan.size()));
    for (const engine::Observation& z : scan) {
      mix(z.range);
      mix(z.bearing);
      mix(static_cast<std::uint64_t>(z.id));
    }
  }
  std::uint64_t value() const noexcept { return h_; }

 private:
  void mix(double v) { mix(std::bit_cast<std::uint64_t>(v)); }
  void mix(std::uint64_t v) {
    for (int k = 0; k < 8; ++k, v >>= 8) h_ = (h_ ^ (v & 0xffu)) * 0x100000001b3ull;
  }
  std::uint64_t h_ = 0xcbf29ce484222325ull;
};

// `st` with the phase timings of the run before a resume added.
engine::FilterStatistics with_timings_before(engine::FilterStatistics st,
                                             const engine::FilterStatistics& before) {
  st.predict_seconds += before.predict_seconds;
  st.associate_seconds += before.associate_seconds;
  st.update_seconds += before.update_seconds;
  st.resample_seconds += before.resample_seconds;
  return st;
}

// The run's own state in a checkpoint, and back.
nlohmann::json run_state_json(const RunResult& r, const engine::FilterStatistics& st,
                              const TraceWriter* trace) {
  return {{"source_seconds", r.source_seconds},
          {"filter_seconds", r.filter_seconds},
          {"warnings", r.warnings},
          {"unknown_id_seen", r.unknown_id_seen},
          {"unlabelled_discarded", r.unlabelled_discarded},
          {"innovations", r.innovations.state()},
          {"innovations_at_trace_row", r.innovations_at_trace_row.state()},
          {"trace_scans", trace != nullptr ? trace->scans() : 0},
          {"seconds_per_phase",
           {st.predict_seconds, st.associate_seconds, st.update_seconds, st.resample_seconds}}};
}

// Restores what run_state_json saved into `r` and `before` (the phase timings); returns the
// trace's scan count. Throws std::runtime_error "PATH: ..." for a value of the wrong type.
std::uint64_t restore_run_state(const std::string& path, const nlohmann::json& j, RunResult& r,
                                engine::FilterStatistics& before) {
  try {
    r.source_seconds = j.at("source_seconds").get<double>();
    r.filter_seconds = j.at("filter_seconds").get<double>();
    r.warnings = j.at("warnings").get<std::vector<std::string>>();
    r.unknown_id_seen = j.at("unknown_id_seen").get<bool>();
    r.unlabelled_discarded = j.at("unlabelled_discarded").get<std::uint64_t>();
    r.innovations = InnovationStats::from_state(j.at("innovations"));
    r.innovations_at_trace_row = InnovationStats::from_state(j.at("innovations_at_trace_row"));
    const auto phases = j.at("seconds_per_phase").get<std::vector<double>>();
    if (phases.size() != 4) throw std::runtime_error("seconds_per_phase needs 4 values");
    before.predict_seconds = phases[0];
    before.associate_seconds = phases[1];
    before.update_seconds = phases[2];
    before.resample_seconds = phases[3];
    return j.at("trace_scans").get<std::uint64_t>();
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(path + ": not a usable checkpoint: its run state: " + e.what());
  }
}

// Writes the loop's checkpoint at `at` (the events consumed so far); a FastSLAM filter only
// (run_once refuses --checkpoint for the EKF baseline).
template <class F>
void write_loop_checkpoint(F& filter, const RunLoop& loop, const RunResult& r, const Position& at) {
  if constexpr (std::is_same_v<F, engine::Filter>) {
    Checkpointing& c = *loop.checkpoint;
    const engine::FilterStatistics st = with_timings_before(filter.statistics(), loop.before);
    Checkpoint saved;
    saved.identity = c.identity;
    saved.events = at.events;
    saved.controls = at.controls;
    saved.scans = at.scans;
    saved.run = run_state_json(r, st, loop.trace);
    if (loop.trace != nullptr) saved.trace = loop.trace->text();
    write_checkpoint(c.path, saved, c.poses, filter);
  }
}

template <class F>
void observe_state(F& filter, ProgressState& state) {
  const engine::FilterStatistics st = filter.statistics();
  state.done = st.controls;
  if constexpr (requires { filter.particles(); }) {
    state.landmarks = filter.particles().landmark_count(0);
  } else {
    state.landmarks = filter.estimate().map.size();
  }
  state.map_bytes = st.live_bytes;
}

// Adds `warning` to the run's unless it is there already.
void warn_once(RunResult& r, const std::string& warning) {
  if (std::find(r.warnings.begin(), r.warnings.end(), warning) == r.warnings.end()) {
    r.warnings.push_back(warning);
  }
}

template <class F>
void trace_row(F& filter, const RunLoop& loop, std::optional<StampedPose> truth, double time,
               RunResult& r) {
  const engine::Estimate now = filter.estimate();
  if (truth && time - truth->time > kMaxInterpolationGap) truth.reset();
  std::optional<double> pose_error;
  if (truth) pose_error = std::hypot(now.mean_pose[0] - truth->x, now.mean_pose[1] - truth->y);
  std::optional<ParticleDiagnostics> particles;
  if constexpr (requires { filter.particles(); }) {
    const memory::ParticleStore& store = filter.particles();
    particles = diagnose_particles(store.x(), store.y(), store.log_weight(), truth);
  }
  std::optional<double> map_error;
  if (!loop.source.info().landmarks.empty()) {
    // The truth failing to score the map (an id it lacks) leaves the value empty, not the run.
    try {
      map_error = loop.truth.rmse(now.map, loop.association.engine == engine::Association::kKnown,
                                  *loop.options.match_radius);
    } catch (const std::runtime_error& e) {
      warn_once(r, std::string("--trace landmark_rmse_m: ") + e.what());
    }
  }
  loop.trace->row(time, pose_error, map_error, now.map.size(), loop.truth.observed_count(),
                  particles, r.innovations.since(r.innovations_at_trace_row));
  r.innovations_at_trace_row = r.innovations;
}

// The scan as the filter takes it: under mixed association without its unlabelled detections
// (counted); under known association a detection without an id is refused
// (std::invalid_argument; drive() names the record) with the options that accept it.
void prepare_scan(const RunLoop& loop, std::vector<engine::Observation>& scan, RunResult& r) {
  if (loop.association.discard_unlabelled) {
    const auto unlabelled = std::remove_if(scan.begin(), scan.end(),
                                           [](const engine::Observation& z) { return z.id < 0; });
    r.unlabelled_discarded += static_cast<std::uint64_t>(scan.end() - unlabelled);
    scan.erase(unlabelled, scan.end());
    return;
  }
  if (loop.association.engine != engine::Association::kKnown) return;
  for (std::size_t j = 0; j < scan.size(); ++j) {
    if (scan[j].id >= 0) continue;
    throw std::invalid_argument("detection " + std::to_string(j) +
                                " has no landmark id ('-'), which known association needs. Run "
                                "with --association auto or ml to associate every detection, or "
                                "mixed to use the ids given and discard the rest");
  }
}

// "FILE:LINE (scan 200, t = 40.000 s)": the source's record (its file and line, or its event
// number), the scan's or control's ordinal in the run (from 1) and the time, for errors raised
// while the run processes that record.
std::string record_of(const RunLoop& loop, std::uint64_t index, const Event& event,
                      std::uint64_t controls, std::uint64_t scans) {
  const char* kind = event.kind == EventKind::kScan      ? "scan"
                     : event.kind == EventKind::kControl ? "control"
                                                         : "record";
  const std::uint64_t ordinal = event.kind == EventKind::kScan      ? scans + 1
                                : event.kind == EventKind::kControl ? controls + 1
                                                                    : index + 1;
  char what[96];
  std::snprintf(what, sizeof(what), " (%s %llu, t = %.3f s)", kind,
                static_cast<unsigned long long>(ordinal), event.time);
  return loop.source.where(index) + what;
}

// One loop over the events of any source, the same for the FastSLAM `Filter` and the `EkfSlam`
// baseline (same methods). Errors the filter raises for an event are rethrown naming the
// source's record and time.
template <class F>
void drive(F& filter, RunLoop& loop, RunResult& r) {
  Event event;
  std::vector<engine::Observation> scan;
  const Clock::time_point start = Clock::now();
  std::optional<StampedPose> last_truth = loop.start.last_truth;
  std::uint64_t controls = loop.start.controls, scans = loop.start.scans;
  // A stop the run can go on from: with --checkpoint, its state is saved here first.
  const auto stop = [&](std::uint64_t index, const char* why) {
    r.ended_by = why;
    if (loop.checkpoint == nullptr) return;
    try {
      write_loop_checkpoint(filter, loop, r, {index, controls, scans, last_truth});
      std::fprintf(stderr,
                   "fastslam: %s: checkpoint of scan %llu written to %s; go on with "
                   "--resume %s\n",
                   why, static_cast<unsigned long long>(scans), loop.checkpoint->path.c_str(),
                   loop.checkpoint->path.c_str());
    } catch (const std::exception& e) {
      r.failure = e.what();
    }
  };
  InputDigest input;
  bool steps_out = false;  // --max-steps reached: the run ends at this event
  bool input_over = false;  // over ranks: this rank's run ends here; the ranks agree below
  // A control's or scan's filter time runs from after its source call to the next event's first
  // clock read; everything else (the source's calls, and recording a truth pose or a GPS fix,
  // which read no clock: ~50 ns a read here, half a simulated run's events) is source time.
  std::optional<Clock::time_point> filter_from;
  Clock::time_point source_from = start;  // the open stretch of source time began here
  Clock::time_point last_read = start;
  double trace_seconds = 0.0;
  const auto close_filter_time = [&](Clock::time_point now) {
    if (!filter_from) return;
    r.filter_seconds += std::chrono::duration<double>(now - *filter_from).count() - trace_seconds;
    filter_from.reset();
  };
  for (std::uint64_t index = loop.start.events;; ++index) {
    // Also every 64th event, for --max-seconds in a long stretch of truth poses or fixes.
    if (filter_from || loop.stream_estimates || index % 64 == 0) {
      last_read = Clock::now();  // a streamed scan's latency counts from here
      if (filter_from) {
        source_from = last_read;
        close_filter_time(last_read);
      }
    }
    const Clock::time_point t0 = last_read;
    int signal = interrupt_signal();
    bool out_of_time =
        loop.options.max_seconds &&
        std::chrono::duration<double>(last_read - start).count() >= *loop.options.max_seconds;
    if (loop.group != nullptr) {
      // Ranks stop at the same event: a rank leaving alone would hang the others' collective
      // calls. The first signal in rank order, any rank out of time, any rank failed; and they
      // must have read the same events, to the same end.
      const RankStatus mine{signal, out_of_time ? 1 : 0, r.failure ? 1 : 0, input_over ? 1 : 0,
                            input.value()};
      const std::vector<RankStatus> all = parallel::all_gather_value(*loop.group, mine);
      signal = 0;
      out_of_time = false;
      for (std::size_t k = 0; k < all.size(); ++k) {
        if (all[k].failed != 0) {
          r.ended_by = "error";
          if (!r.failure) r.failure = "rank " + std::to_string(k) + " failed (its error is above)";
        }
        if (!r.failure && (all[k].input != all[0].input || all[k].input_over != all[0].input_over)) {
          r.ended_by = "error";
          r.failure = "the ranks read different input: by event " + std::to_string(index) +
                      " of the source, rank " + std::to_string(k) +
                      (all[k].input_over != all[0].input_over ? "'s run ended where rank 0's did not"
                                                              : "'s events differ from rank 0's") +
                      "; every rank must read the same source with the same options (a recorded "
                      "data set on a file system every node shares)";
        }
        if (signal == 0) signal = all[k].signal;
        out_of_time = out_of_time || all[k].out_of_time != 0;
      }
      if (r.failure || input_over) break;
    }
    if (signal != 0) {
      r.interrupted_by = signal;
      stop(index, interrupt_name(signal));
      break;
    }
    if (out_of_time) {
      stop(index, "--max-seconds");
      break;
    }
    try {
      if (!loop.source.next(event, scan)) {
        if (loop.group == nullptr) break;
        input_over = true;  // the ranks agree that every source ended here, at the next gather
        continue;
      }
    } catch (const std::runtime_error& e) {
      // A record the source cannot read (a pipe's malformed line): the run ends here and
      // reports what it has; run_once raises the error once the results are written.
      r.ended_by = "input error";
      r.input_error = e.what();
      if (loop.group == nullptr) break;
      input_over = true;
      continue;
    }
    if (loop.group != nullptr) input.add(event, scan);
    const bool filtered = event.kind == EventKind::kControl || event.kind == EventKind::kScan;
    if (filtered) {
      last_read = Clock::now();
      r.source_seconds += std::chrono::duration<double>(last_read - source_from).count();
    }
    const Clock::time_point t1 = last_read;
    trace_seconds = 0.0;
    // What the filter refuses (std::invalid_argument: the record, the filter unchanged) or fails
    // on (std::runtime_error: a numerical failure) is rethrown naming the record.
    const auto located = [&](auto&& call) {
      try {
        call();
      } catch (const std::exception& e) {
        if (dynamic_cast<const std::invalid_argument*>(&e) == nullptr &&
            dynamic_cast<const std::runtime_error*>(&e) == nullptr) {
          throw;
        }
        throw std::runtime_error(record_of(loop, index, event, controls, scans) + ": " + e.what());
      }
    };
    try {
      switch (event.kind) {
        case EventKind::kControl:
          if (loop.options.max_steps && controls == *loop.options.max_steps) {
            r.ended_by = "--max-steps";
            steps_out = true;
            break;
          }
          located([&] { filter.predict(event.control, event.dt, event.time); });
          ++controls;
          loop.recorder.control(event);
          break;
        case EventKind::kScan:
          located([&] {
            prepare_scan(loop, scan, r);
            const auto t_scan = Clock::now();
            filter.observe(scan, event.time);
            r.scan_latency.add(seconds_since(t_scan));
            r.innovations.add(filter.last_associations());
          });
          if (const std::optional<std::int64_t> id = loop.truth.see(scan, controls + scans);
              id && !r.unknown_id_seen) {
            // Said once, where it first happens: scoring by id will miss it.
            r.unknown_id_seen = true;
            r.warnings.push_back(record_of(loop, index, event, controls, scans) + ": landmark id " +
                                 std::to_string(*id) + " is not among the source's true landmarks");
          }
          {
            const std::vector<engine::TrajectoryPoint> poses = filter.take_trajectory();
            if (loop.checkpoint != nullptr) {
              loop.checkpoint->poses.insert(loop.checkpoint->poses.end(), poses.begin(),
                                            poses.end());
            }
            loop.recorder.estimates(poses);
          }
          if (loop.stream_estimates) {
            const engine::Estimate now = filter.estimate(engine::EstimateMap::kSizeOnly);
            if (loop.stream != nullptr) loop.stream->write(event.time, scans, now, seconds_since(t0));
          }
          ++scans;
          if (loop.trace != nullptr && loop.trace->due()) {
            const auto t_trace = Clock::now();
            trace_row(filter, loop, last_truth, event.time, r);
            trace_seconds = seconds_since(t_trace);
          }
          if (loop.progress.due()) {
            observe_state(filter, loop.state);
            loop.progress.draw(loop.state);
          }
          if (loop.checkpoint != nullptr && scans % loop.checkpoint->every == 0) {
            write_loop_checkpoint(filter, loop, r, {index + 1, controls, scans, last_truth});
          }
          break;
        case EventKind::kTruthPose:
          loop.recorder.truth(event);
          last_truth = StampedPose{event.time, event.x, event.y, event.theta};
          break;
        case EventKind::kGps:
          loop.recorder.gps(event);
          break;
      }
    } catch (const std::exception& e) {
      // The filter's refusal or failure, a file that cannot be written: the run ends here and
      // writes what it has; run_once raises the error after that.
      r.ended_by = "error";
      r.failure = e.what();
      if (loop.group == nullptr) break;
      // Over ranks: a bad record or a numerical failure happens on every rank alike, and a file
      // is written by rank 0 alone, outside the collective calls: the ranks stop together at
      // the next event. Anything else (memory, a message that does not parse) may have struck
      // this rank alone inside a collective call the others wait in: end them all.
      if (dynamic_cast<const std::runtime_error*>(&e) == nullptr) {
        std::fprintf(stderr, "fastslam: error: rank %d: %s; aborting every rank\n",
                     loop.group->rank(), e.what());
        loop.group->abort(1);
      }
      continue;
    }
    if (filtered) filter_from = t1;
    if (steps_out) {
      if (loop.group == nullptr) break;
      input_over = true;  // --max-steps: agreed at the next gather, as the input's end
    }
  }
  const auto t_end = Clock::now();
  if (!filter_from) r.source_seconds += std::chrono::duration<double>(t_end - source_from).count();
  close_filter_time(t_end);
  try {
    r.estimate = filter.estimate();
    loop.recorder.estimates(filter.take_trajectory());
  } catch (const std::exception& e) {
    if (!r.failure) r.failure = e.what();
  }
  r.filter_seconds += seconds_since(t_end);
  r.stats = with_timings_before(filter.statistics(), loop.before);
  if (loop.group != nullptr) {
    // The set's counts: each rank's particles' landmarks and its heap's nodes, summed.
    using Counts = std::array<std::int64_t, 4>;
    const Counts mine = {static_cast<std::int64_t>(r.stats.landmarks_created),
                         static_cast<std::int64_t>(r.stats.landmarks_removed),
                         r.stats.live_nodes, r.stats.live_bytes};
    Counts sum{};
    for (const Counts& c : parallel::all_gather_value(*loop.group, mine)) {
      for (std::size_t k = 0; k < sum.size(); ++k) sum[k] += c[k];
    }
    r.stats.landmarks_created = static_cast<std::uint64_t>(sum[0]);
    r.stats.landmarks_removed = static_cast<std::uint64_t>(sum[1]);
    r.stats.live_nodes = sum[2];
    r.stats.live_bytes = sum[3];
  }
  if (loop.trace != nullptr) {
    try {
      loop.trace->close();
    } catch (const std::exception& e) {
      if (!r.failure) r.failure = e.what();
    }
  }
  if (loop.progress.enabled()) {
    observe_state(filter, loop.state);
    loop.state.total = loop.state.done;  // the expected total was an estimate; the run is done
    loop.progress.finish(loop.state);
  }
}

// Rebuilds the recorder and the truth tracker as they stood at checkpoint `c`: the source's
// first c.events events again, the saved poses handed over after each scan as the run handed
// them (Filter::take_trajectory drains to the scan's last control). Returns the position.
// Throws std::runtime_error "PATH: ..." when the source does not match the checkpoint.
Position replay(const std::string& path, const Checkpoint& c, RunLoop& loop) {
  Event event;
  std::vector<engine::Observation> scan;
  Position at;
  std::size_t handed = 0;
  for (; at.events < c.events; ++at.events) {
    if (!loop.source.next(event, scan)) {
      throw std::runtime_error(path + ": the source ends after " + std::to_string(at.events) +
                               " events, before the checkpoint's " + std::to_string(c.events) +
                               "; resume with the input that made it");
    }
    switch (event.kind) {
      case EventKind::kControl:
        ++at.controls;
        loop.recorder.control(event);
        break;
      case EventKind::kScan: {
        loop.truth.see(scan, at.controls + at.scans);
        ++at.scans;
        std::size_t end = handed;
        while (end < c.poses.size() && c.poses[end].control < at.controls) ++end;
        loop.recorder.estimates(std::span(c.poses).subspan(handed, end - handed));
        handed = end;
        break;
      }
      case EventKind::kTruthPose:
        loop.recorder.truth(event);
        at.last_truth = StampedPose{event.time, event.x, event.y, event.theta};
        break;
      case EventKind::kGps:
        loop.recorder.gps(event);
        break;
    }
  }
  if (at.controls != c.controls || at.scans != c.scans || handed != c.poses.size()) {
    throw std::runtime_error(path + ": the source's first " + std::to_string(c.events) +
                             " events hold " + std::to_string(at.controls) + " controls and " +
                             std::to_string(at.scans) + " scans, the checkpoint's " +
                             std::to_string(c.controls) + " and " + std::to_string(c.scans) +
                             "; resume with the input that made it");
  }
  return at;
}

// The options with what the source decides filled in: the association, the match radius and
// the RPE distance.
RunOptions resolve_options(const RunOptions& options, const SourceInfo& info,
                           const AssociationChoice& association) {
  RunOptions resolved = options;
  resolved.filter.association = association.engine;
  resolved.match_radius = options.match_radius.value_or(info.match_radius);
  resolved.rpe_delta = options.rpe_delta.value_or(info.rpe_delta);
  return resolved;
}

// Writes one event of a source to a log.
void write_event(LogWriter& writer, const Event& e, std::span<const engine::Observation> scan) {
  switch (e.kind) {
    case EventKind::kControl:
      writer.control(e.time, e.dt, e.control);
      break;
    case EventKind::kScan:
      writer.scan(e.time, scan);
      break;
    case EventKind::kTruthPose:
      writer.truth_pose(e.time, e.x, e.y, e.theta);
      break;
    case EventKind::kGps:
      writer.gps(e.time, e.x, e.y);
      break;
  }
}

}  // namespace

SourceOptions source_options(const RunOptions& o) {
  SourceOptions s;
  s.data = o.data;
  s.seed = o.filter.seed;
  s.clutter = o.association != "known";
  s.sim.landmarks_csv = o.landmarks_csv;
  s.sim.waypoints_csv = o.waypoints_csv;
  s.sim.world = o.world;
  s.sim.landmarks = o.landmarks;
  s.sim.spacing = o.spacing;
  s.sim.scan_period = o.scan_period;
  s.sim.loop_length = o.loop_length;
  s.sim.config = o.sim;
  s.victoria_park = o.victoria_park;
  s.utias = o.utias;
  return s;
}

// Where the source's pose (the point its log and its GPS refer to) is relative to the point the
// filter tracks: zero, except without odometry on an Ackermann car (Victoria Park). There the
// log's state is the sensor's pose, (a, b) from the rear axle, and the sensor does not move
// along its heading when the car turns (its sideslip reaches ~40 deg in tight turns), which the
// Brownian model (eq. 81: x += v cos(theta) dt) assumes; the rear axle's centre does. So the
// filter tracks the axle, the sensor sits at (a, b) from it, and the trajectory is reported at
// the laser again.
std::vector<std::string> motion_choices() {
  std::vector<std::string> out = {"odometry"};
  for (const std::string& name : engine::enum_names<engine::MotionKind>()) {
    if (engine::without_odometry(engine::parse_enum<engine::MotionKind>(name))) out.push_back(name);
  }
  return out;
}

engine::MotionKind no_odometry_kind(const std::string& motion) {
  for (const engine::EnumName<engine::MotionKind>& n :
       engine::EnumNames<engine::MotionKind>::kNames) {
    if (n.name == motion && engine::without_odometry(n.value)) return n.value;
  }
  std::string choices;
  for (const std::string& c : motion_choices()) choices += (choices.empty() ? "" : ", ") + c;
  throw std::invalid_argument("--motion '" + motion + "' is not supported (" + choices + ")");
}

engine::SensorOffset tracked_point_offset(const RunOptions& o, const LogHeader& h) {
  if (o.motion == "odometry" || h.motion.kind != engine::MotionKind::kAckermann) return {};
  return {h.motion.geometry.a, h.motion.geometry.b, 0.0};
}

// The filter's configuration: the options' algorithm, particles, ...; the models of the
// source's header; the model overrides.
engine::FilterConfig filter_config(const RunOptions& o, const LogHeader& h) {
  engine::FilterConfig config = o.filter;
  config.record_trajectory = true;
  config.motion = h.motion;
  if (o.motion != "odometry") {
    const engine::MotionKind kind = no_odometry_kind(o.motion);
    config.motion.kind = kind;
    config.motion.sigma_control[0] = o.no_odometry_sigma[0];
    config.motion.sigma_control[1] = kind == engine::MotionKind::kBrownianCurvature
                                         ? o.no_odometry_sigma_kappa
                                         : o.no_odometry_sigma[1];
  }
  config.sensor = h.sensor;
  const ModelOverrides& m = o.model;
  if (m.sigma_range) config.sensor.sigma_range = *m.sigma_range;
  if (m.sigma_bearing) config.sensor.sigma_bearing = *m.sigma_bearing;
  if (m.max_range) config.sensor.max_range = *m.max_range;
  if (m.field_of_view) config.sensor.field_of_view = *m.field_of_view;
  if (o.source == "sim") {
    // The simulator's false alarms and misses, as its noises are the filter's by default.
    config.detection.clutter_density = clutter_density(o.sim);
    if (o.sim.detection_probability > 0) {
      config.detection.probability = o.sim.detection_probability;
    }
  }
  if (m.clutter_density) config.detection.clutter_density = *m.clutter_density;
  if (m.detection_probability) config.detection.probability = *m.detection_probability;
  if (m.sigma_control0) config.motion.sigma_control[0] = *m.sigma_control0;
  if (m.sigma_control1) config.motion.sigma_control[1] = *m.sigma_control1;
  for (int k = 0; k < 5; ++k) config.initial_pose[k] = k < 3 ? h.start_pose[k] : 0.0;
  if (o.initial_heading) config.initial_pose[2] = engine::wrap_angle(*o.initial_heading);
  const engine::SensorOffset axle = tracked_point_offset(o, h);
  if (axle.x != 0.0 || axle.y != 0.0) {
    // The filter tracks the rear axle; the source's pose sits at `axle` from it (same heading),
    // and the sensor at the header's offset from that.
    const engine::SensorOffset& header = h.sensor.offset;
    config.sensor.offset = {axle.x + header.x, axle.y + header.y, header.yaw};
    const double th = config.initial_pose[2];
    config.initial_pose[0] -= axle.x * std::cos(th) - axle.y * std::sin(th);
    config.initial_pose[1] -= axle.x * std::sin(th) + axle.y * std::cos(th);
  }
  return config;
}

std::string default_plot_script() {
  if (const char* env = std::getenv("FASTSLAM_PLOT_SCRIPT"); env != nullptr) return env;
  return FASTSLAM_PLOT_RUN_SCRIPT;
}

AssociationChoice resolve_association(const std::string& mode, const SourceInfo& info,
                                      const FilterDefaults& defaults) {
  std::string chosen = mode;
  if (mode == "auto") {
    chosen = defaults.association          ? std::string(*defaults.association)
             : info.labels == Labels::kAll ? "known"
                                           : "ml";
  }
  AssociationChoice c;
  c.mode = chosen;
  if (chosen == "mixed") {
    c.engine = engine::Association::kKnown;
    c.discard_unlabelled = true;
  } else {
    c.engine = engine::parse_enum<engine::Association>(chosen);  // throws naming the modes
  }
  return c;
}

std::vector<std::string> run_inputs(const RunOptions& o) {
  std::vector<std::string> inputs = {o.config, o.data};
  if (o.source == "sim") inputs.insert(inputs.end(), {o.landmarks_csv, o.waypoints_csv});
  return inputs;
}

int run_simulation(const RunOptions& options) {
  const Launch launch = launch_environment();
  if (launch.launched && launch.size > 1 && !have_mpi()) {
    throw std::runtime_error(
        "this fastslam was built without MPI but was started as one of " +
        std::to_string(launch.size) +
        " processes (mpirun): each would run the whole run into the same files. Rebuild with "
        "Open MPI (libopenmpi-dev) or run it without mpirun");
  }
  // Under mpirun the run's particles are spread over the ranks (run_once's group).
  const Ranks ranks(launch.launched && launch.size > 1);
  const std::shared_ptr<parallel::Collective> group =
      ranks.size() > 1 ? ranks.collective() : nullptr;
  const InterruptHandlers handlers;
  const nlohmann::json metrics = run_once(options, {}, group.get());
  return metrics["status"] == "interrupted" ? 128 + interrupt_signal() : 0;
}

namespace {

// Over ranks: what is refused, and what rank > 0 leaves to rank 0 (every output).
RunOptions for_rank(const RunOptions& o, const parallel::Collective& group) {
  auto refuse = [&](const std::string& what) {
    throw std::invalid_argument(what + " is not available when a run's particles are spread over " +
                                std::to_string(group.size()) +
                                " ranks (mpirun); run it in one process");
  };
  if (o.filter.algorithm == engine::Algorithm::kEkf) refuse("--algorithm ekf (one state, no particles)");
  if (!o.checkpoint.empty()) refuse("--checkpoint");
  if (!o.resume.empty()) refuse("--resume");
  if (!o.trace.empty()) refuse("--trace (its particle diagnostics are per process)");
  if (o.data == "-") refuse("--data - (only rank 0 has the standard input)");
  if (group.rank() == 0) return o;
  RunOptions quiet = o;
  quiet.out.clear();
  quiet.stream.clear();
  quiet.plot = "none";
  quiet.progress = false;
  quiet.quiet = true;
  return quiet;
}

}  // namespace

nlohmann::json run_once(const RunOptions& given, const std::function<void()>& accepted,
                        parallel::Collective* group) {
  if (group != nullptr && group->size() < 2) group = nullptr;
  const RunOptions& options = group != nullptr ? for_rank(given, *group) : given;
  const std::vector<std::string> input_paths = run_inputs(options);
  const bool checkpointing = !options.checkpoint.empty();
  const bool resuming = !options.resume.empty();
  if ((checkpointing || resuming) && options.filter.algorithm == engine::Algorithm::kEkf) {
    throw std::invalid_argument(
        "--checkpoint and --resume save a FastSLAM filter's state; the ekf baseline has none");
  }
  // A checkpoint is checked before anything is changed: a refused resume leaves the output
  // directory as it was. The inputs are hashed before the source reads them: what this run is
  // about to read.
  nlohmann::json inputs;
  if (options.hash_inputs || checkpointing || resuming) inputs = input_files_json(options);
  nlohmann::json identity;
  std::optional<Checkpoint> resumed;
  if (checkpointing || resuming) {
    identity =
        run_identity(resolved_options_json(options, options.filter, options.association), inputs);
  }
  if (resuming) {
    resumed = read_checkpoint(options.resume);
    check_same_run(options.resume, resumed->identity, identity);
  }
  // Before any work: a run that cannot write its results does not start.
  CreatedDir created(options.out.empty()
                         ? std::vector<std::string>()
                         : check_output_dir(options.out, input_paths, kRunFileNames));
  if (!options.trace.empty()) {
    check_output_file("--trace", options.trace, input_paths, options.out, kRunFileNames);
  }
  if (checkpointing) {
    check_output_file("--checkpoint", options.checkpoint, input_paths, options.out, kRunFileNames);
    if (options.checkpoint == options.trace) {
      throw std::runtime_error("--checkpoint " + options.checkpoint + " is the --trace file");
    }
    AtomicFile probe(options.checkpoint);  // refuses a directory or an unwritable place now
    remove_abandoned_temporaries(options.checkpoint);
  }
  if (!options.trace.empty()) remove_abandoned_temporaries(options.trace);
  RunResult r;
  const auto t_open = Clock::now();
  const SourceEntry& entry = find_source(options.source);
  const std::unique_ptr<Source> source = entry.open(source_options(options));
  r.open_seconds = seconds_since(t_open);
  const SourceInfo& info = source->info();
  const AssociationChoice association =
      resolve_association(options.association, info, entry.defaults);
  const RunOptions resolved = resolve_options(options, info, association);
  const engine::FilterConfig config = filter_config(resolved, info.header);
  engine::validate(config);
  const MemoryEstimate memory = check_memory_budget(config, info, options.max_memory);
  // The source opened and the settings accepted: only now does the run replace an earlier
  // one's files, so a run refused for its input or options leaves them as they were.
  if (!options.out.empty()) clear_earlier_run(options.out, kRunFileNames);
  if (accepted) accepted();
  created.keep();
  const bool ekf = config.algorithm == engine::Algorithm::kEkf;
  const std::uint32_t particles = ekf ? 1 : config.particles;
  ProgressBar progress(options.progress);
  ProgressState state;
  state.total = static_cast<std::uint64_t>(info.expected_controls);
  state.particles = particles;
  TruthTracker truth(info.landmarks);
  if (!ekf && config.association != engine::Association::kKnown && !info.landmarks.empty()) {
    truth.record_labels();
  }
  engine::FilterStatistics before;
  std::uint64_t trace_scans = 0;
  if (resumed) trace_scans = restore_run_state(options.resume, resumed->run, r, before);
  std::unique_ptr<TraceWriter> trace;
  if (!options.trace.empty()) {
    trace = resumed
                ? std::make_unique<TraceWriter>(options.trace, options.trace_every, checkpointing,
                                                resumed->trace, trace_scans)
                : std::make_unique<TraceWriter>(options.trace, options.trace_every, checkpointing);
  }
  RunRecorder recorder(info.header, tracked_point_offset(options, info.header), options.out,
                       *resolved.rpe_delta, options.plot == "svg");
  std::unique_ptr<ScanStream> stream;
  if (!options.stream.empty()) stream = std::make_unique<ScanStream>(options.stream);
  Checkpointing checkpoint{options.checkpoint, options.checkpoint_every, identity, {}};
  RunLoop loop{resolved,     association, *source, truth, recorder, trace.get(),
               stream.get(), progress,    state,   {},    before,   nullptr};
  if (checkpointing) loop.checkpoint = &checkpoint;
  loop.group = group;
  loop.stream_estimates = !given.stream.empty();
  if (ekf) {
    engine::EkfSlam filter(config);
    drive(filter, loop, r);
  } else if (resumed) {
    loop.start = replay(options.resume, *resumed, loop);
    const std::unique_ptr<engine::Filter> filter = load_filter(options.resume, *resumed, config);
    const engine::FilterConfig& saved = filter->config();
    if (saved.particles != config.particles || saved.algorithm != config.algorithm ||
        saved.association != config.association || saved.seed != config.seed) {
      throw std::runtime_error(options.resume +
                               ": the filter's state is not of this run's configuration");
    }
    checkpoint.poses = std::move(resumed->poses);
    if (!options.quiet) {
      std::fprintf(stderr, "fastslam: resumed from %s at scan %llu\n", options.resume.c_str(),
                   static_cast<unsigned long long>(loop.start.scans));
    }
    drive(*filter, loop, r);
  } else if (group != nullptr) {
    // The particles spread over the ranks; the filter gives every rank the one-process bits.
    engine::Filter filter(config, std::shared_ptr<parallel::Collective>(group, [](auto*) {}));
    drive(filter, loop, r);
  } else {
    engine::Filter filter(config);
    drive(filter, loop, r);
  }
  for (const std::string& w : source->warnings()) warn_once(r, w);
  r.trajectories = recorder.finish();
  // Every file that could not be written; the first is the run's failure.
  std::vector<std::string> errors = r.trajectories.errors;
  for (const std::string& w : r.trajectories.warnings) warn_once(r, w);
  if (!errors.empty() && !r.failure) r.failure = errors.front();
  if (!info.landmarks.empty()) {
    std::optional<AlignedAte> alignment;
    if (r.trajectories.filter.truth) alignment = r.trajectories.filter.truth->aligned;
    // A truth that cannot score the map (an estimated id it lacks) is a warning: the estimate
    // stands.
    try {
      r.map = truth.scores(r.estimate.map, association.engine == engine::Association::kKnown,
                           *resolved.match_radius, alignment);
    } catch (const std::runtime_error& e) {
      warn_once(r, std::string("landmark evaluation: ") + e.what());
    }
  }
  const RunSettings settings{resolved, info, config, association, particles};
  nlohmann::json metrics = metrics_json(settings, r);
  metrics["schema_version"] = kMetricsSchemaVersion;
  metrics["build"] = build_info_json();
  metrics["options"] = resolved_options_json(resolved, config, association.mode);
  metrics["memory_estimate_bytes"] = memory.bytes;
  if (group != nullptr) metrics["ranks"] = group->size();
  if (options.hash_inputs) metrics["inputs"] = inputs;
  if (!options.sweep_run.empty()) metrics["sweep_run"] = nlohmann::json::parse(options.sweep_run);
  // With the scans streamed to standard output, everything else goes to standard error.
  std::FILE* const text = options.stream == "-" ? stderr : stdout;
  if (!options.quiet) print_summary(settings, r, text);
  for (const std::string& w : r.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  if (!options.out.empty()) {
    const std::vector<std::string> more = write_run_files(options.out,
                                                          {.metrics = &metrics,
                                                           .streamed = r.trajectories.files,
                                                           .map = r.estimate.map,
                                                           .true_landmarks = info.landmarks,
                                                           .quiet = options.quiet},
                                                          text);
    if (!more.empty() && !r.failure) r.failure = more.front();
    errors.insert(errors.end(), more.begin(), more.end());
    if (errors.empty() && options.plot == "svg") {
      draw_map_svg(options.out, options.quiet ? nullptr : text, r.trajectories.picture.get());
    } else if (errors.empty() && options.plot == "png" && !options.plot_script.empty()) {
      draw_map(options.plot_script, options.out, text);
    }
  }
  for (const std::string& e : errors) {
    if (e != r.failure) std::fprintf(stderr, "fastslam: error: %s\n", e.c_str());
  }
  // A complete run leaves nothing to resume.
  if (checkpointing && errors.empty() && run_status(r) == "complete" &&
      r.ended_by != "--max-seconds") {
    std::error_code ignored;
    std::filesystem::remove(options.checkpoint, ignored);
  }
  if (r.failure) {
    throw RunFailed(*r.failure + (options.out.empty() ? std::string()
                                                      : "; what the run had is in " + options.out +
                                                            " (metrics.json: \"status\")"),
                    std::make_shared<const nlohmann::json>(std::move(metrics)));
  }
  if (r.input_error) {
    throw RunFailed(*r.input_error + (options.out.empty() ? std::string()
                                                          : "; the results up to the record "
                                                            "before it are in " +
                                                                options.out),
                    std::make_shared<const nlohmann::json>(std::move(metrics)));
  }
  return metrics;
}

engine::FilterConfig run_filter_config(const RunOptions& options) {
  const SourceEntry& entry = find_source(options.source);
  const std::unique_ptr<Source> source = entry.open(source_options(options));
  const SourceInfo& info = source->info();
  const AssociationChoice association =
      resolve_association(options.association, info, entry.defaults);
  return filter_config(resolve_options(options, info, association), info.header);
}

int convert_to_log(const RunOptions& options) {
  if (options.out.empty()) throw std::invalid_argument("convert needs --out FILE.log");
  std::error_code error;
  if (!options.data.empty() && options.data != "-" &&
      std::filesystem::equivalent(options.out, options.data, error)) {
    throw std::runtime_error("--out " + options.out + " is the input --data " + options.data +
                             ": give another file");
  }
  // Before any work: a directory, a device or an uncreatable path is refused here.
  AtomicFile file(options.out);
  const InterruptHandlers handlers;
  SourceOptions so = source_options(options);
  so.clutter = true;
  const std::unique_ptr<Source> source = find_source(options.source).open(so);
  const SourceInfo& info = source->info();
  if (!info.summary.empty()) std::printf("%s\n", info.summary.c_str());
  std::size_t events = 0;
  LogWriter writer(file.stream(), info.header);
  for (const TruthLandmark& l : info.landmarks) writer.landmark(l);
  Event e;
  std::vector<engine::Observation> scan;
  while (source->next(e, scan)) {
    if (const int signal = interrupt_signal(); signal != 0) {
      // A log cut short would read as a whole one: nothing is written.
      file.discard();
      std::fprintf(stderr, "fastslam: %s: stopped; %s left as it was\n", interrupt_name(signal),
                   options.out.c_str());
      return 128 + signal;
    }
    write_event(writer, e, scan);
    if (file.failed()) file.flush();  // throws naming the file and the reason
    ++events;
  }
  writer.finish();
  file.commit();
  std::printf("wrote %zu events to %s\n", events, options.out.c_str());
  for (const std::string& w : source->warnings()) std::fprintf(stderr, "warning: %s\n", w.c_str());
  return 0;
}

}  // namespace fastslam::tools
