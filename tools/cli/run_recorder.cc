#include "tools/cli/run_recorder.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <utility>

namespace fastslam::tools {

// One output file of poses, buffered: CSV "t,x,y,theta" (or "t,x,y" for fixes) or TUM.
class RunRecorder::PoseFile {
 public:
  enum class Format { kCsv, kCsvPosition, kTum };

  PoseFile(std::string path, Format format) : path_(std::move(path)), format_(format) {
    file_.open(path_);
    if (!file_) throw std::runtime_error("cannot write " + path_);
    switch (format_) {
      case Format::kCsv:
        text_ = "t,x,y,theta\n";
        break;
      case Format::kCsvPosition:
        text_ = "t,x,y\n";
        break;
      case Format::kTum:
        text_ = kTumHeader;
        break;
    }
  }

  void add(const StampedPose& p) {
    if (format_ == Format::kTum) {
      append_tum(text_, p);
    } else {
      char line[160];
      const int n = format_ == Format::kCsv
                        ? std::snprintf(line, sizeof(line), "%.3f,%.6f,%.6f,%.6f\n", p.time, p.x,
                                        p.y, p.theta)
                        : std::snprintf(line, sizeof(line), "%.3f,%.6f,%.6f\n", p.time, p.x, p.y);
      text_.append(line, static_cast<std::size_t>(n));
    }
    if (text_.size() > (std::size_t{1} << 16)) flush();
  }

  void close() {
    flush();
    file_.close();
    if (!file_) throw std::runtime_error("write failed: " + path_);
  }

 private:
  void flush() {
    file_ << text_;
    text_.clear();
  }

  std::string path_;
  Format format_;
  std::ofstream file_;
  std::string text_;
};

RunRecorder::RunRecorder(const LogHeader& header, const engine::SensorOffset& reported,
                         const std::string& out_dir, double rpe_delta)
    : reported_(reported),
      out_dir_(out_dir),
      dead_reckoning_(header.motion, header.start_pose, header.start_time),
      filter_truth_({.reference_heading = true, .rpe_delta = rpe_delta}),
      filter_gps_({.reference_heading = false, .rpe_delta = rpe_delta}),
      dr_truth_({.reference_heading = true, .rpe_delta = rpe_delta}),
      dr_gps_({.reference_heading = false, .rpe_delta = rpe_delta}) {
  if (!out_dir_.empty()) {
    std::filesystem::create_directories(out_dir_);
    using F = PoseFile::Format;
    trajectory_csv_ = std::make_unique<PoseFile>(out_dir_ + "/trajectory.csv", F::kCsv);
    trajectory_tum_ = std::make_unique<PoseFile>(out_dir_ + "/trajectory.tum", F::kTum);
  }
  // The start pose is scored (it is the estimate before the first control) but not written:
  // the files hold the poses after the controls.
  const StampedPose start = dead_reckoning_.pose();
  filter_truth_.add_estimate(start);
  filter_gps_.add_estimate(start);
  if (dead_reckoning_.available()) {
    dr_truth_.add_estimate(start);
    dr_gps_.add_estimate(start);
  }
}

RunRecorder::~RunRecorder() = default;

RunRecorder::PoseFile& RunRecorder::file(std::unique_ptr<PoseFile>& slot, const char* name,
                                         bool position_only) {
  if (!slot) {
    slot = std::make_unique<PoseFile>(out_dir_ + "/" + name, position_only
                                                                 ? PoseFile::Format::kCsvPosition
                                                                 : PoseFile::Format::kCsv);
  }
  return *slot;
}

void RunRecorder::control(const Event& e) {
  control_times_.push_back(e.time);
  dead_reckoning_.predict(e.control, e.dt, e.time);
  if (!dead_reckoning_.available()) return;
  dr_truth_.add_estimate(dead_reckoning_.pose());
  dr_gps_.add_estimate(dead_reckoning_.pose());
  if (!out_dir_.empty()) file(dr_csv_, "dead_reckoning.csv", false).add(dead_reckoning_.pose());
}

void RunRecorder::truth(const Event& e) {
  const StampedPose p{e.time, e.x, e.y, e.theta};
  filter_truth_.add_reference(p);
  if (dead_reckoning_.available()) dr_truth_.add_reference(p);
  last_truth_ = p;
  ++truth_poses_;
  if (!out_dir_.empty()) file(truth_csv_, "truth.csv", false).add(p);
}

void RunRecorder::gps(const Event& e) {
  const StampedPose p{e.time, e.x, e.y, 0.0};
  filter_gps_.add_reference(p);
  if (dead_reckoning_.available()) dr_gps_.add_reference(p);
  ++gps_fixes_;
  if (!out_dir_.empty()) file(gps_csv_, "gps.csv", true).add(p);
}

void RunRecorder::estimates(std::span<const engine::TrajectoryPoint> points) {
  for (const engine::TrajectoryPoint& point : points) {
    if (point.control != first_pending_control_ || control_times_.empty()) {
      throw std::logic_error("RunRecorder: trajectory point of control " +
                             std::to_string(point.control) + " out of order");
    }
    const double c = std::cos(point.theta), s = std::sin(point.theta);
    const StampedPose p{control_times_.front(), point.x + reported_.x * c - reported_.y * s,
                        point.y + reported_.x * s + reported_.y * c, point.theta};
    control_times_.pop_front();
    ++first_pending_control_;
    filter_truth_.add_estimate(p);
    filter_gps_.add_estimate(p);
    if (trajectory_csv_) {
      trajectory_csv_->add(p);
      trajectory_tum_->add(p);
    }
  }
}

RecordedRun RunRecorder::finish() {
  RecordedRun r;
  auto close = [&](std::unique_ptr<PoseFile>& f, const char* name) {
    if (!f) return;
    f->close();
    r.files.emplace_back(name);
  };
  close(trajectory_csv_, "trajectory.csv");
  close(trajectory_tum_, "trajectory.tum");
  close(truth_csv_, "truth.csv");
  close(gps_csv_, "gps.csv");
  close(dr_csv_, "dead_reckoning.csv");
  if (truth_poses_ > 0) r.filter.truth = filter_truth_.finish();
  if (gps_fixes_ > 0) r.filter.gps = filter_gps_.finish();
  if (dead_reckoning_.available()) {
    if (truth_poses_ > 0) r.dead_reckoning.truth = dr_truth_.finish();
    if (gps_fixes_ > 0) r.dead_reckoning.gps = dr_gps_.finish();
  }
  r.last_truth = last_truth_;
  r.truth_poses = truth_poses_;
  r.gps_fixes = gps_fixes_;
  return r;
}

}  // namespace fastslam::tools
