// Where `fastslam run` and `fastslam convert` get their events. A `Source` streams controls,
// scans, truth poses and GPS fixes in time order and says up front what it knows: the log
// header (models, noises, start pose), the true landmarks, the controls to expect. Sources are
// found by name in one registry (`sources()`, source.cc), so the command line lists and opens
// them without knowing which exist: a new data set is a file defining its factory plus its line
// in the registry.
//
// Ownership: a Source owns the data its events come from. Thread safety: thread-compatible.
// Costs: `next` is O(observations of the event); opening costs what reading the data costs.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "engine/filter.h"
#include "tools/datasets/sim_source.h"
#include "tools/datasets/utias.h"
#include "tools/datasets/victoria_park.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {

// What the factories may use; each source reads the fields that concern it.
struct SourceOptions {
  std::string data;        // a recorded source's file or directory
  std::uint64_t seed = 1;  // simulated sources
  bool clutter = true;     // simulated false alarms passed on (id -1)
  SimWorldOptions sim;
  VictoriaParkOptions victoria_park;
  UtiasOptions utias;
};

// Settings a data set recommends beyond its header's models; the command line applies each one
// set here unless the user gave that option.
struct FilterDefaults {
  // What --association auto means for this source ("known", "ml", "das" or "mixed"); unset:
  // known when every detection carries an id, ml otherwise.
  std::optional<std::string_view> association;
  std::optional<double> existence_range_margin;  // m
  std::optional<double> existence_missed;        // log-odds
  // FastSLAM 2.0 only: the sensor noises, replacing the header's, and with odometry the
  // measurement errors' correlation from scan to scan (engine::FilterConfig::error_correlation).
  std::optional<double> fastslam2_sigma_range;    // m
  std::optional<double> fastslam2_sigma_bearing;  // rad
  std::optional<double> fastslam2_error_correlation;
};

// Which detections carry a landmark id.
enum class Labels : std::uint8_t { kAll, kSome, kNone };

// The Labels of `detections` of which `labelled` carry an id.
constexpr Labels labels_of(std::size_t labelled, std::size_t detections) {
  return labelled == detections ? Labels::kAll : labelled == 0 ? Labels::kNone : Labels::kSome;
}

// The largest scan a source holds, as it can tell before it runs: what the filter's per-scan
// buffers grow to (tools/cli/memory_budget.h).
struct ScanShape {
  std::uint64_t controls = 0;    // the most controls before one scan (queued, then run with it)
  std::uint64_t detections = 0;  // the most detections in one scan
  // False: only what the source has seen so far (a pipe's first records), a lower bound.
  bool known = false;
};

// Walks a source's events to its ScanShape: `add` each event in order, then `shape`.
class ScanShapeCounter {
 public:
  void add(const Event& event) {
    if (event.kind == EventKind::kControl) ++run_;
    if (event.kind != EventKind::kScan) return;
    shape_.controls = std::max(shape_.controls, run_);
    shape_.detections = std::max<std::uint64_t>(shape_.detections, event.count);
    run_ = 0;
  }
  // The controls after the last scan count too: the filter runs them at the end.
  ScanShape shape(bool known) const {
    ScanShape s = shape_;
    s.controls = std::max(s.controls, run_);
    s.known = known;
    return s;
  }

 private:
  ScanShape shape_;
  std::uint64_t run_ = 0;
};

// What a source knows before its first event.
struct SourceInfo {
  Labels labels = Labels::kAll;
  LogHeader header;
  std::vector<TruthLandmark> landmarks;  // empty when the source has no true map
  double expected_controls = 0.0;        // for the progress bar; 0: unknown
  ScanShape scans;                       // the largest scan (for a simulator: expected)
  std::string name;                      // "world" in metrics.json
  bool simulated = false;                // its time is the simulator's, not reading's
  std::vector<std::pair<std::string, double>> metrics;  // added to metrics.json as they are
  std::string summary;                                  // a line `convert` prints; may be empty
  // Scoring, unless the options say otherwise: the radius pairing estimated and true
  // landmarks (about half their spacing) and the path length of a relative-pose-error pair
  // (about the scale of the run), metres.
  double match_radius = 5.0;
  double rpe_delta = 10.0;
};

class Source {
 public:
  virtual ~Source() = default;
  // The next event in time order, a scan's observations in `scan`; false at the end.
  virtual bool next(Event& event, std::vector<engine::Observation>& scan) = 0;
  const SourceInfo& info() const noexcept { return info_; }
  // Where event `index` (from 0, in the order `next` gave them) came from, for messages:
  // "NAME, event INDEX", or the file and line where the source knows them.
  virtual std::string where(std::uint64_t index) const;
  // What is wrong with the input without stopping the run (a log without its end marker), one
  // message each. A source may find one only at its end (a pipe), so a run reads them after its
  // last event; metrics.json and stderr report them.
  const std::vector<std::string>& warnings() const noexcept { return warnings_; }

 protected:
  SourceInfo info_;
  std::vector<std::string> warnings_;
};

struct SourceEntry {
  std::string_view name;  // --source NAME
  std::unique_ptr<Source> (*open)(const SourceOptions& options);
  FilterDefaults defaults;
};

// Every source, in the order the command line lists them.
std::span<const SourceEntry> sources();
// Throws std::invalid_argument naming the known sources when `name` is none of them.
const SourceEntry& find_source(std::string_view name);
std::vector<std::string> source_names();

}  // namespace fastslam::tools
