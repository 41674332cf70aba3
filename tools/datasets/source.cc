#include "tools/datasets/source.h"

#include <stdexcept>
#include <string>

namespace fastslam::tools {

// The factories, each defined in its source's file (sim_source.cc, log_source.cc,
// victoria_park_source.cc, utias_source.cc). A new source: its factory here and its line in the
// table.
std::unique_ptr<Source> open_sim_source(const SourceOptions& options);
std::unique_ptr<Source> open_log_source(const SourceOptions& options);
std::unique_ptr<Source> open_victoria_park_source(const SourceOptions& options);
FilterDefaults victoria_park_filter_defaults();
std::unique_ptr<Source> open_utias_source(const SourceOptions& options);
FilterDefaults utias_filter_defaults();

std::string Source::where(std::uint64_t index) const {
  return info_.name + ", event " + std::to_string(index);
}

std::span<const SourceEntry> sources() {
  static const SourceEntry kSources[] = {
      {"sim", &open_sim_source, {}},
      {"log", &open_log_source, {}},
      {"victoria-park", &open_victoria_park_source, victoria_park_filter_defaults()},
      {"utias", &open_utias_source, utias_filter_defaults()},
  };
  return kSources;
}

const SourceEntry& find_source(std::string_view name) {
  for (const SourceEntry& entry : sources()) {
    if (entry.name == name) return entry;
  }
  std::string known;
  for (const SourceEntry& entry : sources()) {
    known += (known.empty() ? "" : ", ") + std::string(entry.name);
  }
  throw std::invalid_argument("--source '" + std::string(name) + "' is not supported (" + known +
                              ")");
}

std::vector<std::string> source_names() {
  std::vector<std::string> names;
  for (const SourceEntry& entry : sources()) names.emplace_back(entry.name);
  return names;
}

}  // namespace fastslam::tools
