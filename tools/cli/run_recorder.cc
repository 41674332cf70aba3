#include "tools/cli/run_recorder.h"

#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <functional>
#include <future>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <utility>

#include "tools/io/decimal.h"
#include "tools/io/number_text.h"

namespace fastslam::tools {

// A task's outcome: the message of the exception it threw, or nothing. The exception itself
// stays on the thread that threw it; the waiting thread raises its own std::runtime_error of
// the message, so no exception object is shared between the threads.
namespace {

using TaskError = std::optional<std::string>;

TaskError attempt(const std::function<void()>& task) {
  try {
    task();
    return std::nullopt;
  } catch (const std::exception& e) {
    return std::string(e.what());
  }
}

}  // namespace

// The thread that writes the files: the tasks run one at a time in the order given, so each
// file's batches stay in order. Destroyed after the files (each waits for its last task).
class RunRecorder::Writer {
 public:
  Writer() : thread_([this] { loop(); }) {}
  ~Writer() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    ready_.notify_one();
    thread_.join();
  }
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  std::future<TaskError> run(std::function<void()> task) {
    std::packaged_task<TaskError()> job([task = std::move(task)] { return attempt(task); });
    std::future<TaskError> done = job.get_future();
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      queue_.push_back(std::move(job));
    }
    ready_.notify_one();
    return done;
  }

 private:
  void loop() {
    for (;;) {
      std::packaged_task<TaskError()> job;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        ready_.wait(lock, [&] { return stop_ || !queue_.empty(); });
        if (queue_.empty()) return;  // stopped, and every task has run
        job = std::move(queue_.front());
        queue_.pop_front();
      }
      job();
    }
  }

  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::packaged_task<TaskError()>> queue_;
  bool stop_ = false;
  std::thread thread_;  // last: started once the rest is built
};

// One output file of poses: CSV "t,x,y,theta" (or "t,x,y" for fixes) or TUM, put in place by
// its closing steps. The poses are queued; every kBatch of them a background task formats and
// writes them to the temporary while the run goes on (one task at a time per file, so the lines
// keep their order and the formatting buffers have one user), and the closing steps write the rest
// and commit. Without a writer (no thread to be had) each task runs in the caller.
class RunRecorder::PoseFile {
 public:
  enum class Format { kCsv, kCsvPosition, kTum };

  // `picture`: the path this file's rows are also given to (CSV formats), or null.
  PoseFile(const std::string& path, Format format, Writer* writer, PicturePath* picture = nullptr)
      : format_(format), file_(path), writer_(writer), picture_(picture) {
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
  // A task still writing uses this file: wait for it (its error, if any, is dropped with it).
  ~PoseFile() {
    if (job_.valid()) job_.wait();
  }
  PoseFile(const PoseFile&) = delete;
  PoseFile& operator=(const PoseFile&) = delete;

  // Throws std::runtime_error naming the file once a write has failed (reported when the next
  // batch is handed over, or by the closing steps).
  void add(const StampedPose& p) {
    pending_.push_back(p);
    if (pending_.size() >= kBatch) hand_over(Stage::kBatch);
  }

  // Closing, in three steps so that several files are written to the disk together: the rest
  // of the text and the start of its writeback; the commit (the fsync and the rename, the
  // directory's sync left to the caller); waiting for both. Each throws the first error of the
  // file's earlier tasks, finish_close the commit's.
  void start_close() { hand_over(Stage::kWriteback); }
  void start_commit() { hand_over(Stage::kCommit); }
  void finish_close() { wait(); }
  const std::string& target() const { return file_.target(); }

 private:
  static constexpr std::size_t kBatch = 1024;  // a full disk ends the run within two batches
  enum class Stage { kBatch, kWriteback, kCommit };

  void wait() {
    if (!job_.valid()) return;
    if (const TaskError error = job_.get()) throw std::runtime_error(*error);
  }

  void hand_over(Stage stage) {
    wait();
    std::function<void()> task;
    if (stage == Stage::kCommit) {
      task = [this] { file_.commit(DirectorySync::kDeferred); };
    } else {
      task = [this, batch = std::move(pending_), stage] {
        write(batch);
        if (stage == Stage::kWriteback) file_.start_writeback();
      };
      pending_ = {};
      if (stage == Stage::kBatch) pending_.reserve(kBatch);
    }
    if (writer_ != nullptr) {
      job_ = writer_->run(std::move(task));
    } else {
      // No thread: the task runs here, its error kept for the next step as the writer's is.
      std::promise<TaskError> done;
      done.set_value(attempt(task));
      job_ = done.get_future();
    }
  }

  void write(const std::vector<StampedPose>& batch) {
    chunk_.clear();
    for (const StampedPose& p : batch) {
      if (format_ == Format::kTum) {
        append_tum(chunk_, p);
      } else {
        text_.clear();
        text_.fixed(p.time, 3).put(',');
        const std::size_t x_begin = text_.view().size();
        text_.fixed(p.x, 6);
        const std::size_t x_end = text_.view().size();
        text_.put(',').fixed(p.y, 6);
        if (picture_ != nullptr) {
          // The values a reader of this text gets, so the picture is the one the file draws.
          const std::string_view t = text_.view();
          double x = 0, y = 0;
          parse_double(t.data() + x_begin, t.data() + x_end, x);
          parse_double(t.data() + x_end + 1, t.data() + t.size(), y);
          picture_->add(x, y);
        }
        if (format_ == Format::kCsv) text_.put(',').fixed(p.theta, 6);
        chunk_.append(text_.put('\n').view());
      }
    }
    file_.write(chunk_);
  }

  Format format_;
  AtomicFile file_;
  Writer* writer_;
  PicturePath* picture_;  // written by the task only
  std::vector<StampedPose> pending_;
  // Used by the task only.
  std::string chunk_;
  TextLine text_;
  std::future<TaskError> job_;  // last: waited for before the rest goes
};

RunRecorder::RunRecorder(const LogHeader& header, const engine::SensorOffset& reported,
                         const std::string& out_dir, double rpe_delta, bool picture)
    : reported_(reported),
      out_dir_(out_dir),
      dead_reckoning_(header.motion, header.start_pose, header.start_time),
      filter_truth_({.reference_heading = true, .rpe_delta = rpe_delta}, "pose error"),
      filter_gps_({.reference_heading = false, .rpe_delta = rpe_delta}, "GPS error"),
      dr_truth_({.reference_heading = true, .rpe_delta = rpe_delta}, "dead reckoning's pose error"),
      dr_gps_({.reference_heading = false, .rpe_delta = rpe_delta}, "dead reckoning's GPS error") {
  if (!out_dir_.empty()) {
    using F = PoseFile::Format;
    if (picture) picture_ = std::make_shared<PicturePaths>();
    try {
      writer_ = std::make_unique<Writer>();
    } catch (const std::system_error&) {
      // No thread to be had: the files are written by the run's own thread.
    }
    trajectory_csv_ =
        std::make_unique<PoseFile>(out_dir_ + "/trajectory.csv", F::kCsv, writer_.get(),
                                   picture_ ? &picture_->estimate : nullptr);
    trajectory_tum_ =
        std::make_unique<PoseFile>(out_dir_ + "/trajectory.tum", F::kTum, writer_.get());
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

RunRecorder::~RunRecorder() = default;

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
                                         bool position_only, PicturePath PicturePaths::*path) {
  if (!slot) {
    slot = std::make_unique<PoseFile>(
        out_dir_ + "/" + name,
        position_only ? PoseFile::Format::kCsvPosition : PoseFile::Format::kCsv, writer_.get(),
        picture_ ? &(*picture_.*path) : nullptr);
  }
  return *slot;
}

void RunRecorder::control(const Event& e) {
  control_times_.push_back(e.time);
  dead_reckoning_.predict(e.control, e.dt, e.time);
  if (!dead_reckoning_.available()) return;
  dr_truth_.estimate(dead_reckoning_.pose());
  dr_gps_.estimate(dead_reckoning_.pose());
  if (!out_dir_.empty())
    file(dr_csv_, "dead_reckoning.csv", false, &PicturePaths::dead_reckoning)
        .add(dead_reckoning_.pose());
}

void RunRecorder::truth(const Event& e) {
  const StampedPose p{e.time, e.x, e.y, e.theta};
  filter_truth_.reference(p);
  if (dead_reckoning_.available()) dr_truth_.reference(p);
  last_truth_ = p;
  ++truth_poses_;
  if (!out_dir_.empty()) file(truth_csv_, "truth.csv", false, &PicturePaths::truth).add(p);
}

void RunRecorder::gps(const Event& e) {
  const StampedPose p{e.time, e.x, e.y, 0.0};
  filter_gps_.reference(p);
  if (dead_reckoning_.available()) dr_gps_.reference(p);
  ++gps_fixes_;
  if (!out_dir_.empty()) file(gps_csv_, "gps.csv", true, &PicturePaths::gps).add(p);
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
  // Each file on its own: one that failed leaves the others whole. The writer writes the
  // files' last text and starts their writeback, then commits them, while this thread scores;
  // their directories are synced once at the end.
  struct Closing {
    std::unique_ptr<PoseFile>* file;
    const char* name;
    std::optional<std::string> error;
  };
  std::vector<Closing> closing;
  for (const auto& [file, name] :
       {std::pair{&trajectory_csv_, "trajectory.csv"},
        std::pair{&trajectory_tum_, "trajectory.tum"}, std::pair{&truth_csv_, "truth.csv"},
        std::pair{&gps_csv_, "gps.csv"}, std::pair{&dr_csv_, "dead_reckoning.csv"}}) {
    if (*file) closing.push_back({file, name, std::nullopt});
  }
  const auto step = [](Closing& c, void (PoseFile::*call)()) {
    if (c.error) return;
    try {
      ((**c.file).*call)();
    } catch (const std::exception& e) {
      c.error = e.what();
    }
  };
  for (Closing& c : closing) step(c, &PoseFile::start_close);
  for (Closing& c : closing) step(c, &PoseFile::start_commit);
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
  std::vector<std::string> committed;
  for (Closing& c : closing) {
    step(c, &PoseFile::finish_close);
    if (c.error) {
      r.errors.push_back(*c.error);
    } else {
      r.files.emplace_back(c.name);
      committed.push_back((**c.file).target());
    }
    c.file->reset();
  }
  sync_directories(committed);
  r.picture = picture_;  // every task that wrote to it has finished
  r.last_truth = last_truth_;
  r.truth_poses = truth_poses_;
  r.gps_fixes = gps_fixes_;
  return r;
}

}  // namespace fastslam::tools
