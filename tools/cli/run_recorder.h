// What a run records while it goes, in memory bounded by the gaps between scans rather than by
// the run's length: the estimated trajectory (the pose after every control, at the source's
// reported point), the truth poses and GPS fixes, and the dead-reckoning baseline of the same
// controls, each written to its file in the output directory as it arrives (to a temporary put
// in place at the end, tools/io/atomic_file.h) and fed to the
// streaming trajectory evaluation (tools/eval/trajectory_metrics.h) against the truth and
// against GPS.
//
// The files' text is formatted and written by one background thread, a batch of poses at a time,
// so the run's thread only queues the poses. Asked to, that thread also keeps the position
// files' rows for the picture (tools/cli/map_picture.h), read from the text it writes, so that
// the picture need not read the files back.
//
// Ownership: owns its files, their writer thread and the evaluators. Thread safety:
// thread-compatible (the writer touches only what the files hand it). Costs: O(1) per control,
// truth pose or fix, the text and the write on the writer; memory O(controls between two
// estimate batches) plus two batches of poses per file.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine/filter.h"
#include "tools/cli/map_picture.h"
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
  // The position files as the picture takes them, when asked for (RunRecorder's `picture`).
  std::shared_ptr<const PicturePaths> picture;
  std::vector<std::string> errors;  // one message per file that could not be written
  // Scores given up on (a reference out of time order, a pose not finite): the files and the
  // other scores stand.
  std::vector<std::string> warnings;
};

class RunRecorder {
 public:
  // `header`: the source's start pose and motion model (dead reckoning's); `reported`: where
  // the source's pose sits from the point the filter tracks; `out_dir`: empty for no files;
  // `rpe_delta`: metres of reference path per relative-error pair; `picture`: keep the position
  // files' rows for map.svg as they are written (RecordedRun::picture). Throws
  // std::runtime_error naming a file it cannot create.
  RunRecorder(const LogHeader& header, const engine::SensorOffset& reported,
              const std::string& out_dir, double rpe_delta, bool picture = false);
  ~RunRecorder();

  void control(const Event& event);
  void truth(const Event& event);
  void gps(const Event& event);
  // The filter's poses after the controls since the last batch (Filter::take_trajectory).
  void estimates(std::span<const engine::TrajectoryPoint> points);

  // Puts the files in place (one that fails is left out, its message in `errors`) and scores.
  // Call it also after a failed or interrupted run: the files then hold the poses so far.
  RecordedRun finish();

 private:
  class Writer;
  class PoseFile;

  PoseFile& file(std::unique_ptr<PoseFile>& slot, const char* name, bool position_only,
                 PicturePath PicturePaths::*path);

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
  // Filled by the files' tasks, each path by its own file's; read once the files are closed.
  std::shared_ptr<PicturePaths> picture_;
  std::unique_ptr<Writer> writer_;  // before the files: it outlives their tasks
  std::unique_ptr<PoseFile> trajectory_csv_, trajectory_tum_, truth_csv_, gps_csv_, dr_csv_;
  std::optional<StampedPose> last_truth_;
  std::uint64_t truth_poses_ = 0, gps_fixes_ = 0;
};

}  // namespace fastslam::tools
