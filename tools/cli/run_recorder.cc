#include "tools/cli/run_recorder.h"

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <functional>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include "tools/io/number_text.h"

namespace fastslam::tools {

// Formats and writes batches of poses on one background thread, so that the thread running the
// filter pays a copy per pose for the path files, not the number formatting and the writes.
// Batches run in the order given; a PoseFile waits for its own batches before it commits.
class RunRecorder::Writer {
 public:
  Writer() : thread_([this] { serve(); }) {}
  // Writes what is queued, then stops.
  ~Writer() {
    {
      const std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
  }

  void submit(std::function<void()> batch) {
    {
      const std::lock_guard lock(mutex_);
      queue_.push_back(std::move(batch));
    }
    wake_.notify_all();
  }

  // Waits until every batch submitted so far is written.
  void drain() {
    std::unique_lock lock(mutex_);
    const std::uint64_t target = submitted_ + queue_.size();
    done_.wait(lock, [&] { return written_ >= target; });
  }

 private:
  void serve() {
    std::unique_lock lock(mutex_);
    for (;;) {
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;  // stopping, and nothing left
      std::function<void()> batch = std::move(queue_.front());
      queue_.pop_front();
      ++submitted_;
      lock.unlock();
      batch();  // never throws: a PoseFile keeps its own error
      lock.lock();
      ++written_;
      done_.notify_all();
    }
  }

  std::mutex mutex_;
  std::condition_variable wake_, done_;
  std::deque<std::function<void()>> queue_;
  std::uint64_t submitted_ = 0;  // batches taken off the queue
  std::uint64_t written_ = 0;    // batches finished
  bool stopping_ = false;
  std::jthread thread_;  // last: it starts after, and is joined before, the members it uses
};

// One output file of poses: CSV "t,x,y,theta" (or "t,x,y" for fixes) or TUM, formatted and
// written to its temporary by the writer in batches, and put in place by close().
class RunRecorder::PoseFile {
 public:
  enum class Format { kCsv, kCsvPosition, kTum };

  PoseFile(const std::string& path, Format format, Writer& writer)
      : format_(format), file_(path), writer_(writer) {
    switch (format_) {
      case Format::kCsv:
        file_.write("t,x,y,theta\n");
        break;
      case Format::kCsvPosition:
        file_.write("t,x,y\n");
        break;
      case Format::kTum:
        file_.write(kTumHeader);
        break;
    }
    pending_.reserve(kBatch);
  }

  // Throws std::runtime_error naming the file once a write has failed (learnt a batch later
  // than the write).
  void add(const StampedPose& p) {
    if (failed_.load(std::memory_order_acquire)) throw std::runtime_error(error_);
    pending_.push_back(p);
    if (pending_.size() == kBatch) submit();
  }

  // Writes what is pending and puts the file in place. Throws as add() or AtomicFile::commit.
  void close() {
    submit();
    writer_.drain();
    if (failed_.load(std::memory_order_acquire)) throw std::runtime_error(error_);
    file_.commit();
  }

 private:
  static constexpr std::size_t kBatch = 2048;

  void submit() {
    if (pending_.empty()) return;
    writer_.submit([this, batch = std::move(pending_)] { write(batch); });
    pending_ = {};
    pending_.reserve(kBatch);
  }

  // On the writer's thread.
  void write(const std::vector<StampedPose>& batch) {
    if (failed_.load(std::memory_order_relaxed)) return;
    try {
      for (const StampedPose& p : batch) {
        if (format_ == Format::kTum) {
          line_.clear();
          append_tum(line_, p);
          file_.write(line_);
        } else {
          text_.clear();
          text_.fixed(p.time, 3).put(',').fixed(p.x, 6).put(',').fixed(p.y, 6);
          if (format_ == Format::kCsv) text_.put(',').fixed(p.theta, 6);
          file_.write(text_.put('\n').view());
        }
      }
    } catch (const std::exception& e) {
      error_ = e.what();
      failed_.store(true, std::memory_order_release);
    }
  }

  Format format_;
  AtomicFile file_;  // written on the writer's thread, committed after a drain
  Writer& writer_;
  std::vector<StampedPose> pending_;
  std::string line_;
  TextLine text_;
  std::string error_;  // set before failed_
  std::atomic<bool> failed_{false};
};

RunRecorder::RunRecorder(const LogHeader& header, const engine::SensorOffset& reported,
                         const std::string& out_dir, double rpe_delta)
    : reported_(reported),
      out_dir_(out_dir),
      dead_reckoning_(header.motion, header.start_pose, header.start_time),
      filter_truth_({.reference_heading = true, .rpe_delta = rpe_delta}, "pose error"),
      filter_gps_({.reference_heading = false, .rpe_delta = rpe_delta}, "GPS error"),
      dr_truth_({.reference_heading = true, .rpe_delta = rpe_delta}, "dead reckoning's pose error"),
      dr_gps_({.reference_heading = false, .rpe_delta = rpe_delta}, "dead reckoning's GPS error") {
  if (!out_dir_.empty()) {
    using F = PoseFile::Format;
    writer_ = std::make_unique<Writer>();
    trajectory_csv_ = std::make_unique<PoseFile>(out_dir_ + "/trajectory.csv", F::kCsv, *writer_);
    trajectory_tum_ = std::make_unique<PoseFile>(out_dir_ + "/trajectory.tum", F::kTum, *writer_);
  }
  // The start pose is scored (it is the estimate before the first control) but not written:
  // the files hold the poses after the controls.
  const StampedPose start = dead_reckoning_.pose();
  filter_truth_.estimate(start);
  filter_gps_.estimate(start);
  if (dead_reckoning_.available()) {
    dr_truth_.estimate(start);
    dr_gps_.estimate(start);
  }
}

RunRecorder::~RunRecorder() {
  writer_.reset();  // writes what is queued while the files are still there
}

void RunRecorder::Scored::estimate(const StampedPose& p) {
  if (error) return;
  try {
    evaluator.add_estimate(p);
  } catch (const std::exception& e) {
    error = e.what();
  }
}

void RunRecorder::Scored::reference(const StampedPose& p) {
  if (error) return;
  try {
    evaluator.add_reference(p);
  } catch (const std::exception& e) {
    error = e.what();
  }
}

RunRecorder::PoseFile& RunRecorder::file(std::unique_ptr<PoseFile>& slot, const char* name,
                                         bool position_only) {
  if (!slot) {
    slot = std::make_unique<PoseFile>(
        out_dir_ + "/" + name,
        position_only ? PoseFile::Format::kCsvPosition : PoseFile::Format::kCsv, *writer_);
  }
  return *slot;
}

void RunRecorder::control(const Event& e) {
  control_times_.push_back(e.time);
  dead_reckoning_.predict(e.control, e.dt, e.time);
  if (!dead_reckoning_.available()) return;
  dr_truth_.estimate(dead_reckoning_.pose());
  dr_gps_.estimate(dead_reckoning_.pose());
  if (!out_dir_.empty()) file(dr_csv_, "dead_reckoning.csv", false).add(dead_reckoning_.pose());
}

void RunRecorder::truth(const Event& e) {
  const StampedPose p{e.time, e.x, e.y, e.theta};
  filter_truth_.reference(p);
  if (dead_reckoning_.available()) dr_truth_.reference(p);
  last_truth_ = p;
  ++truth_poses_;
  if (!out_dir_.empty()) file(truth_csv_, "truth.csv", false).add(p);
}

void RunRecorder::gps(const Event& e) {
  const StampedPose p{e.time, e.x, e.y, 0.0};
  filter_gps_.reference(p);
  if (dead_reckoning_.available()) dr_gps_.reference(p);
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
    filter_truth_.estimate(p);
    filter_gps_.estimate(p);
    if (trajectory_csv_) {
      trajectory_csv_->add(p);
      trajectory_tum_->add(p);
    }
  }
}

RecordedRun RunRecorder::finish() {
  RecordedRun r;
  // Each file on its own: one that failed leaves the others whole. The files are closed
  // concurrently, so that their fsyncs share the file system's journal commits; the names and
  // errors are reported in a fixed order.
  struct Closing {
    std::unique_ptr<PoseFile>* file;
    const char* name;
    std::optional<std::string> error;
  };
  std::vector<Closing> closing;
  for (auto [f, name] : {std::pair{&trajectory_csv_, "trajectory.csv"},
                         std::pair{&trajectory_tum_, "trajectory.tum"},
                         std::pair{&truth_csv_, "truth.csv"}, std::pair{&gps_csv_, "gps.csv"},
                         std::pair{&dr_csv_, "dead_reckoning.csv"}}) {
    if (*f) closing.push_back({f, name, std::nullopt});
  }
  auto close = [](Closing& c) {
    try {
      (*c.file)->close();
    } catch (const std::exception& e) {
      c.error = e.what();
    }
    c.file->reset();
  };
  {
    std::vector<std::jthread> threads;
    for (std::size_t i = 1; i < closing.size(); ++i) {
      try {
        threads.emplace_back(close, std::ref(closing[i]));
      } catch (const std::system_error&) {  // no thread to be had: close it here
        close(closing[i]);
      }
    }
    if (!closing.empty()) close(closing[0]);
  }
  for (const Closing& c : closing) {
    if (c.error) {
      r.errors.push_back(*c.error);
    } else {
      r.files.emplace_back(c.name);
    }
  }
  auto score = [&](Scored& s, std::optional<TrajectoryMetrics>& into) {
    if (s.error) {
      r.warnings.push_back(std::string(s.name) + " not computed: " + *s.error);
      return;
    }
    try {
      into = s.evaluator.finish();
    } catch (const std::exception& e) {
      r.warnings.push_back(std::string(s.name) + " not computed: " + e.what());
    }
  };
  if (truth_poses_ > 0) score(filter_truth_, r.filter.truth);
  if (gps_fixes_ > 0) score(filter_gps_, r.filter.gps);
  if (dead_reckoning_.available()) {
    if (truth_poses_ > 0) score(dr_truth_, r.dead_reckoning.truth);
    if (gps_fixes_ > 0) score(dr_gps_, r.dead_reckoning.gps);
  }
  r.last_truth = last_truth_;
  r.truth_poses = truth_poses_;
  r.gps_fixes = gps_fixes_;
  return r;
}

}  // namespace fastslam::tools
