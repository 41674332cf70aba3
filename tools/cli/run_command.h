// `fastslam run`: events from a source (tools/datasets/source.h: a simulated world, a native
// log, Victoria Park, ...) driven through the Filter or the EKF-SLAM baseline by one loop,
// scored against whatever truth the source holds (tools/eval/), with the metrics, trajectory
// and map written to an output directory (tools/cli/run_output.h); and `fastslam convert`,
// which writes any source as a native log.
//
// Ownership: plain options in; files out. Thread safety: one run per call; the filter runs its
// own threads. Costs: the source's plus the filter's; memory that of the map and the source,
// not of the run's length: the trajectory, the truth and the trace are streamed to their files
// and scored as they come (tools/cli/run_recorder.h).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "engine/filter_config.h"
#include "parallel/collective.h"
#include "tools/datasets/sim_source.h"
#include "tools/datasets/source.h"
#include "tools/datasets/utias.h"
#include "tools/datasets/victoria_park.h"
#include "tools/sim/simulator.h"

namespace fastslam::tools {

// Defaults of the no-odometry models (--motion none, none-curvature): the per-control steps
// of the random walks of v, omega and the curvature, about a car's acceleration and steering
// rate (docs/victoria-park.md has how they were chosen).
inline constexpr double kNoOdometrySigmaV = 0.15;      // m/s per step
inline constexpr double kNoOdometrySigmaOmega = 0.05;  // rad/s per step
inline constexpr double kNoOdometrySigmaKappa = 0.01;  // 1/m per step

// Filter models that replace the source's (a log header's, or the simulator's): noises, the
// sensor's range (m) and field of view (rad, centred ahead), and its detection model.
struct ModelOverrides {
  std::optional<double> sigma_range, sigma_bearing, sigma_control0, sigma_control1;
  std::optional<double> max_range, field_of_view;
  // The detection model (engine::DetectionConfig; unknown association only).
  std::optional<double> clutter_density, detection_probability;
};

// --association: the engine's modes, "mixed" (labelled detections by their ids, unlabelled
// ones discarded and counted) and "auto" (the source's recommendation, else known when every
// detection carries an id, ml otherwise).
inline constexpr const char* kAssociationModes[] = {"auto", "known", "ml", "das", "mixed"};

// The association a run uses: the engine's, and whether unlabelled detections are dropped.
struct AssociationChoice {
  engine::Association engine = engine::Association::kKnown;
  bool discard_unlabelled = false;
  std::string mode;  // "known", "ml", "das" or "mixed"
};
// Resolves `mode` for a source. Throws std::invalid_argument for an unknown mode.
AssociationChoice resolve_association(const std::string& mode, const SourceInfo& info,
                                      const FilterDefaults& defaults);

// --plot: the run's picture (RunOptions::plot).
inline constexpr const char* kPlotFormats[] = {"svg", "png", "none"};

struct RunOptions {
  std::string source = "sim";  // a name in the registry (tools/datasets/source.h)
  std::string data;            // a recorded source's file or directory
  // --source sim: the world and the simulator (tools/datasets/sim_source.h SimWorldOptions).
  std::string landmarks_csv;
  std::string waypoints_csv;
  std::string world = "grid";
  std::uint64_t landmarks = kDefaultGridLandmarks;  // grid
  std::optional<double> spacing;
  std::optional<double> scan_period;
  double loop_length = 2000.0;  // loop
  SimConfig sim;
  engine::FilterConfig filter;       // its association is set from `association` once resolved
  std::string association = "auto";  // one of kAssociationModes
  // Estimated and true landmarks are paired within this distance (tools/eval/map_evaluation.h)
  // for the unknown-association landmark RMSE, precision and recall; it is also GOSPA's cutoff.
  // Unset: the source's (SourceInfo::match_radius).
  std::optional<double> match_radius;
  // Metres of true path between the two poses of a relative-pose-error pair. Unset: the
  // source's (SourceInfo::rpe_delta).
  std::optional<double> rpe_delta;
  ModelOverrides model;
  // Budgets: the run stops after this many controls, or once this much wall time has passed
  // (checked between events), and reports what it has, saying why it ended.
  std::optional<std::uint64_t> max_steps;
  // --seeds: the run once per seed (tools/cli/run_sweep.h); empty: once, with filter.seed.
  std::vector<std::uint64_t> seeds;
  std::optional<double> max_seconds;
  // The run is refused before its filter is built when the filter's estimated memory
  // (tools/cli/memory_budget.h) exceeds this many bytes; 0: what the machine has available.
  std::uint64_t max_memory = 0;
  // "odometry": the source's motion model with its controls; "none": the controls are ignored
  // (only their dt is used) and the pose follows the Brownian velocity model of eq. 79-81
  // (engine::MotionKind::kBrownian), with `no_odometry_sigma` (the per-control increments of v,
  // m/s, and omega, rad/s; --sigma-u0/--sigma-u1 override them); "none-curvature": the same
  // with the curvature walked instead of omega (engine::MotionKind::kBrownianCurvature: a car
  // cannot turn while it stands), steps no_odometry_sigma[0] and `no_odometry_sigma_kappa`.
  std::string motion = "odometry";
  double no_odometry_sigma[2] = {kNoOdometrySigmaV, kNoOdometrySigmaOmega};
  double no_odometry_sigma_kappa = kNoOdometrySigmaKappa;  // 1/m per control
  // Replaces the source's start heading (rad) when set.
  std::optional<double> initial_heading;
  // --source victoria-park: the reader's options (gate, geometry, heading fit).
  VictoriaParkOptions victoria_park;
  // --source utias: the robot (--robot).
  UtiasOptions utias;
  std::string out;  // output directory; empty: metrics to stdout only
  // Errors over time: a CSV row every `trace_every` scans (after the scan's update) with
  // t, scan, pose_error_m (weighted-mean position against the latest truth pose, empty when the
  // source has none within kMaxInterpolationGap), landmark_rmse_m (the best particle's map
  // against the truth, by id under known association, else paired within match_radius; only
  // landmarks seen so far; empty without true landmarks), landmarks (in the best map) and
  // observed_landmarks (true landmarks seen so far). Empty: no trace, and no cost.
  // Costs per row: an estimate (O(M + N), the best map copied out) and its scoring.
  std::string trace;
  std::uint64_t trace_every = 1;
  // A JSON line per scan as it is processed (tools/cli/scan_stream.h), to a file or "-" for
  // standard output (the summary then goes to standard error). Empty: none.
  std::string stream;
  // Checkpoints (tools/cli/checkpoint.h): the whole run's state written atomically to this
  // file every `checkpoint_every` scans and when a signal or --max-seconds stops the run, and
  // removed once the run is complete. Empty: none. A FastSLAM filter and a source that can be
  // read again (not standard input) only.
  std::string checkpoint;
  std::uint64_t checkpoint_every = 1000;
  // A checkpoint to go on from, made with the same options (but those that change no result:
  // threads, grain, output paths, budgets), inputs and build; the run then ends with the files
  // the uninterrupted run would have written. Empty: start at the beginning.
  std::string resume;
  bool progress = true;  // a progress bar on stderr when it is a terminal
  // With `out`, the picture drawn once the files are written (one of kPlotFormats): "svg",
  // OUT/map.svg drawn natively (tools/cli/map_picture.h, milliseconds; the command line's
  // default); "png", OUT/map.png by `/usr/bin/python3 plot_script OUT` (matplotlib, about a
  // second; nothing when plot_script is empty); "none". A picture that fails is reported on
  // stderr and does not fail the run.
  std::string plot = "none";
  // The command line sets default_plot_script().
  std::string plot_script;
  // No summary on stdout (the Python module's run(), whose caller reads the metrics).
  bool quiet = false;
  // The --config file the options came from, recorded (and hashed) in metrics.json.
  std::string config;
  // metrics.json's "inputs": the SHA-256 of each input file (tools/cli/run_provenance.h). A
  // sweep hashes once for all its seeds and turns this off for each run.
  bool hash_inputs = true;
  // Set by `fastslam sweep` (tools/cli/sweep_command.h): a JSON object's text written to
  // metrics.json as "sweep_run" (the run's place in the sweep and its identity), by which a
  // rerun of the sweep knows the run is done. Empty: none.
  std::string sweep_run;
};

// The plot script `fastslam run` uses by default: $FASTSLAM_PLOT_SCRIPT when set, else this
// source tree's tools/scripts/plot_run.py.
std::string default_plot_script();

// The source's options: the world, the data, the seed; simulated false alarms unless the
// association is "known".
SourceOptions source_options(const RunOptions& options);

// The filter's configuration for a source with header `h` under `options`: the header's
// models and noises, the options' algorithm, particles, association, ... and model overrides;
// without odometry the Brownian model, and on an Ackermann car the rear axle tracked with the
// sensor at (a, b) from it plus the header's own sensor offset (`tracked_point_offset`).
engine::FilterConfig filter_config(const RunOptions& options, const LogHeader& h);
// Where the source's pose is relative to the point the filter tracks: zero, except without
// odometry on an Ackermann car ((a, b), the sensor from the rear axle).
engine::SensorOffset tracked_point_offset(const RunOptions& options, const LogHeader& h);

// The values --motion takes: "odometry" (the source's model), then the names of the models
// without odometry (engine::MotionKind's table).
std::vector<std::string> motion_choices();
// The no-odometry model --motion names. Throws std::invalid_argument listing motion_choices()
// for "odometry" or any other name.
engine::MotionKind no_odometry_kind(const std::string& motion);

// The files a run reads (--config, --data, the world CSVs), which --out must not be or hold.
std::vector<std::string> run_inputs(const RunOptions& options);

// `fastslam run` on any source; returns the process exit code: 0, or 128 + the signal when
// SIGINT or SIGTERM stopped it (tools/cli/interrupt.h; the results so far are written, with
// "status": "interrupted"). Throws std::exception with a clear message on bad options,
// unreadable files, or a failure after the start (the results so far written first, with
// "status": "failed: REASON").
int run_simulation(const RunOptions& options);
// What run_once throws for a failure after the run was accepted (a numerical failure, a file
// it could not write, a bad record in its input): the message, and the run's metrics.json
// object, with "status": "failed: REASON", as it was written.
class RunFailed : public std::runtime_error {
 public:
  RunFailed(const std::string& what, std::shared_ptr<const nlohmann::json> metrics)
      : std::runtime_error(what), metrics_(std::move(metrics)) {}
  const nlohmann::json& metrics() const noexcept { return *metrics_; }

 private:
  std::shared_ptr<const nlohmann::json> metrics_;  // shared: copying an exception must not throw
};

// The same, returning the run's metrics.json object. The output directory is checked before
// any work and cleared of an earlier run's files only once the source has opened and the
// settings are accepted (tools/cli/run_output.h); `accepted`, when given, is called then, so a
// caller can do the same for files of its own. A refusal before that throws std::exception; a
// failure after it throws RunFailed.
// `group` (a shared particle set over ranks, parallel/collective.h; every rank calls run_once
// with the same options): the filter's particles are spread over the ranks; rank 0 reports and
// writes the outputs, which are those of a run in one process (timings aside); the other ranks
// write nothing. Refused over ranks (std::invalid_argument, on every rank before any work):
// the EKF baseline, --checkpoint, --resume, --trace and standard input as --data.
nlohmann::json run_once(const RunOptions& options, const std::function<void()>& accepted = {},
                        parallel::Collective* group = nullptr);
// The filter configuration run_once(options) builds: the source opened for its header and its
// recommendations, the association resolved. For replaying a source through a Filter of one's
// own (the Python module). Costs: opening the source (a log is read whole).
engine::FilterConfig run_filter_config(const RunOptions& options);

// `fastslam convert`: writes any source's events, header and true landmarks (a simulated
// source passes its false alarms on) as a native log to the file `options.out`, which appears
// only when complete (tools/io/atomic_file.h: a symlink is written through; a directory or a
// device is refused). SIGINT or SIGTERM stop it, leaving `out` as it was, and it returns
// 128 + the signal.
int convert_to_log(const RunOptions& options);

}  // namespace fastslam::tools
