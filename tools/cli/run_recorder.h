// What a run records while it goes, in memory bounded by the gaps between scans rather than by
// the run's length: the estimated trajectory (the pose after every control, at the source's
// reported point), the truth poses and GPS fixes, and the dead-reckoning baseline of the same
// controls, each written to its file in the output directory as it arrives (to a temporary put
// in place at the end, tools/io/atomic_file.h) and fed to the
// streaming trajectory evaluation (tools/eval/trajectory_metrics.h) against the truth and
// against GPS.
//
// In the background (the constructor's `background`), the calls only queue their events and
// return; one thread of the recorder's own scores and writes them, in call order, so the files
// and scores are the same bytes, while the filter goes on with the next scan. A run with more
// than one thread uses it: at small M, formatting and scoring the poses costs about as much as
// the filter.
//
// Ownership: owns its files, evaluators and (in the background) its thread. Thread safety:
// thread-compatible (its own thread touches only what the calls hand it). Costs: O(1) per
// control, truth pose or fix plus a buffered file write; memory O(controls between two estimate
// batches), and in the background at most kQueuedBatches batches of kBatchEvents events queued.
#pragma once

#include <cstdint>
#include <deque>
#include <exception>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine/filter.h"
#include "tools/eval/dead_reckoning.h"
#include "tools/eval/trajectory_metrics.h"
#include "tools/io/atomic_file.h"
#include "tools/io/log_format.h"
#include "tools/io/tum.h"

namespace fastslam::tools {

// Errors of one trajectory (the filter's or dead reckoning's) against each reference.
struct TrajectoryScores {
  std::optional<TrajectoryMetrics> truth;  // when the source has truth poses
  std::optional<TrajectoryMetrics> gps;    // when it has GPS fixes
};

struct RecordedRun {
  TrajectoryScores filter;
  TrajectoryScores dead_reckoning;  // both empty when the model ignores the controls
  std::optional<StampedPose> last_truth;
  std::uint64_t truth_poses = 0, gps_fixes = 0;
  std::vector<std::string> files;   // written, in order
  std::vector<std::string> errors;  // one message per file that could not be written
  // Scores given up on (a reference out of time order, a pose not finite): the files and the
  // other scores stand.
  std::vector<std::string> warnings;
};

class RunRecorder {
 public:
  // `header`: the source's start pose and motion model (dead reckoning's); `reported`: where
  // the source's pose sits from the point the filter tracks; `out_dir`: empty for no files;
  // `rpe_delta`: metres of reference path per relative-error pair; `background`: score and
  // write on a thread of its own. Throws std::runtime_error naming a file it cannot create.
  RunRecorder(const LogHeader& header, const engine::SensorOffset& reported,
              const std::string& out_dir, double rpe_delta, bool background = false);
  ~RunRecorder();
  RunRecorder(const RunRecorder&) = delete;
  RunRecorder& operator=(const RunRecorder&) = delete;

  // Each throws std::runtime_error when a file cannot be written (in the background: at the
  // first call after the recorder's thread met the error; it then records nothing more).
  void control(const Event& event);
  void truth(const Event& event);
  void gps(const Event& event);
  // The filter's poses after the controls since the last batch (Filter::take_trajectory).
  void estimates(std::span<const engine::TrajectoryPoint> points);

  // Puts the files in place (one that fails is left out, its message in `errors`) and scores.
  // Call it also after a failed or interrupted run: the files then hold the poses so far. In
  // the background it first waits for the queued events; a write error not yet thrown by a
  // call is in `errors`.
  RecordedRun finish();

  static constexpr std::size_t kBatchEvents = 1024;
  static constexpr std::size_t kQueuedBatches = 4;

 private:
  class PoseFile;
  class Worker;

  void do_control(const Event& event);
  void do_truth(const Event& event);
  void do_gps(const Event& event);
  void do_estimates(std::span<const engine::TrajectoryPoint> points);
  // In the background: hands the events queued so far to the recorder's thread.
  void hand_over();

  PoseFile& file(std::unique_ptr<PoseFile>& slot, const char* name, bool position_only);

  engine::SensorOffset reported_;
  std::string out_dir_;
  DeadReckoning dead_reckoning_;
  // An evaluator that, once it refuses an input, is dropped with its message.
  struct Scored {
    Scored(const TrajectoryEvaluatorOptions& options, const char* what)
        : evaluator(options), name(what) {}
    void estimate(const StampedPose& p);
    void reference(const StampedPose& p);
    TrajectoryEvaluator evaluator;
    const char* name;
    std::optional<std::string> error;
  };

  Scored filter_truth_, filter_gps_, dr_truth_, dr_gps_;
  std::deque<double> control_times_;  // of controls not yet in an estimate batch
  std::uint64_t first_pending_control_ = 0;
  std::unique_ptr<PoseFile> trajectory_csv_, trajectory_tum_, truth_csv_, gps_csv_, dr_csv_;
  std::optional<StampedPose> last_truth_;
  std::uint64_t truth_poses_ = 0, gps_fixes_ = 0;
  std::unique_ptr<Worker> worker_;  // null unless in the background
};

}  // namespace fastslam::tools
