#include "tools/cli/run_sweep.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <map>
#include <ostream>
#include <set>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "tools/cli/interrupt.h"
#include "tools/cli/run_output.h"
#include "tools/cli/run_provenance.h"
#include "tools/io/atomic_file.h"

namespace fastslam::tools {
namespace {

std::uint64_t parse_seed(std::string_view text, std::string_view part) {
  std::uint64_t value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size()) {
    throw std::invalid_argument("--seeds: '" + std::string(part) +
                                "' is not a seed or a range LO-HI (e.g. 1-10 or 1,3,7-9)");
  }
  return value;
}

// Every number of a metrics object, nested objects' as "outer.inner".
void flatten(const nlohmann::json& m, const std::string& prefix,
             std::map<std::string, nlohmann::json>& out) {
  for (const auto& [key, value] : m.items()) {
    if (value.is_object()) {
      flatten(value, prefix + key + ".", out);
    } else if (value.is_number() || value.is_boolean()) {
      out[prefix + key] = value;
    }
  }
}

// The errors a sweep's table shows, those the runs have.
constexpr const char* kHeadline[] = {"pose_rmse_m",
                                     "pose_rmse_aligned_m",
                                     "dead_reckoning.pose_rmse_m",
                                     "gps_rmse_m",
                                     "gps_rmse_aligned_m",
                                     "dead_reckoning.gps_rmse_m",
                                     "gospa_m",
                                     "gospa_aligned_m",
                                     "landmark_rmse_m",
                                     "landmarks",
                                     "landmark_origins.false_alarms",
                                     "landmark_origins.second_copies",
                                     "wall_seconds"};

}  // namespace

std::vector<std::uint64_t> parse_seeds(const std::string& text) {
  std::vector<std::uint64_t> seeds;
  std::set<std::uint64_t> seen;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    const std::string_view part(text.data() + start, comma - start);
    const std::size_t dash = part.find('-');
    const std::uint64_t lo = parse_seed(part.substr(0, dash), part);
    const std::uint64_t hi =
        dash == std::string_view::npos ? lo : parse_seed(part.substr(dash + 1), part);
    if (hi < lo || hi - lo >= 1'000'000) {
      throw std::invalid_argument("--seeds: '" + std::string(part) +
                                  "' must be LO-HI with LO <= HI (at most 10^6 seeds)");
    }
    for (std::uint64_t s = lo;; ++s) {
      if (!seen.insert(s).second) {
        throw std::invalid_argument("--seeds: seed " + std::to_string(s) + " is given twice");
      }
      seeds.push_back(s);
      if (s == hi) break;
    }
    start = comma + 1;
  }
  return seeds;
}

nlohmann::json summarise_seeds(const std::vector<nlohmann::json>& per_seed) {
  std::map<std::string, std::vector<double>> numbers;
  std::map<std::string, std::size_t> trues;
  for (const nlohmann::json& m : per_seed) {
    std::map<std::string, nlohmann::json> flat;
    flatten(m, "", flat);
    for (const auto& [key, value] : flat) {
      if (value.is_boolean()) {
        trues[key] += value.get<bool>();
      } else {
        numbers[key].push_back(value.get<double>());
      }
    }
  }
  nlohmann::json summary = nlohmann::json::object();
  for (auto& [key, values] : numbers) {
    std::sort(values.begin(), values.end());
    const std::size_t n = values.size();
    double mean = 0.0;
    for (double v : values) mean += v / static_cast<double>(n);
    double ss = 0.0;
    for (double v : values) ss += (v - mean) * (v - mean);
    const double median = n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
    summary[key] = {{"mean", mean},
                    {"median", median},
                    {"min", values.front()},
                    {"max", values.back()},
                    {"stdev", n > 1 ? std::sqrt(ss / static_cast<double>(n - 1)) : 0.0},
                    {"seeds", n}};
  }
  for (const auto& [key, count] : trues)
    summary[key] = {{"true", count}, {"seeds", per_seed.size()}};
  return summary;
}

nlohmann::json run_entry(const RunOptions& o, const std::function<void()>& accepted,
                         std::string& failure) {
  try {
    return run_once(o, accepted);
  } catch (const RunFailed& e) {
    failure = e.what();
    return e.metrics();
  }
}

void take_provenance(nlohmann::json& entry, nlohmann::json& provenance) {
  for (const char* key : {"schema_version", "build", "options", "inputs"}) {
    if (!entry.contains(key)) continue;
    if (!provenance.contains(key)) provenance[key] = entry[key];
    entry.erase(key);
  }
}

void write_rows_csv(const std::string& path, const std::vector<nlohmann::json>& rows,
                    const std::vector<std::string>& leading) {
  std::vector<std::map<std::string, nlohmann::json>> flat(rows.size());
  std::set<std::string> rest;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    flatten(rows[i], "", flat[i]);
    for (const auto& [key, value] : flat[i]) rest.insert(key);
  }
  // Strings too for the leading columns (a configuration's name, a source).
  for (std::size_t i = 0; i < rows.size(); ++i) {
    for (const std::string& c : leading) {
      if (rows[i].contains(c) && rows[i][c].is_string()) flat[i][c] = rows[i][c];
    }
  }
  std::vector<std::string> columns = leading;
  for (const std::string& c : rest) {
    if (std::find(leading.begin(), leading.end(), c) == leading.end()) columns.push_back(c);
  }
  AtomicFile file(path);
  std::ostream& csv = file.stream();
  bool first = true;
  for (const std::string& c : columns) csv << (first ? "" : ",") << c, first = false;
  csv << '\n';
  for (const auto& row : flat) {
    first = true;
    for (const std::string& c : columns) {
      csv << (first ? "" : ",");
      first = false;
      const auto found = row.find(c);
      if (found != row.end()) csv << found->second.dump();
    }
    csv << '\n';
  }
  file.commit();
}

void print_headline(const nlohmann::json& summary) {
  for (const char* key : kHeadline) {
    if (!summary.contains(key)) continue;
    const nlohmann::json& s = summary[key];
    std::printf("  %-30s %10.3f / %10.3f / %10.3f / %8.3f\n", key, s["mean"].get<double>(),
                s["median"].get<double>(), s["max"].get<double>(), s["stdev"].get<double>());
  }
}

int run_sweep(const RunOptions& options) {
  const std::vector<std::uint64_t>& seeds = options.seeds;
  if (seeds.empty()) throw std::invalid_argument("--seeds: no seed given");
  constexpr const char* kSweepFiles[] = {"sweep.json", "sweep.csv"};
  // As for a single run: the directory checked now, an earlier sweep's files removed only once
  // the first seed has opened the input and been accepted, so a refused sweep loses nothing.
  CreatedDir created(options.out.empty()
                         ? std::vector<std::string>()
                         : check_output_dir(options.out, run_inputs(options), kSweepFiles));
  bool accepted = false;
  const auto on_accepted = [&] {
    if (accepted) return;
    if (!options.out.empty()) clear_earlier_run(options.out, kSweepFiles);
    accepted = true;
    created.keep();
  };
  const InterruptHandlers handlers;
  // The provenance once for the sweep, not per seed: the inputs hashed once, the build and the
  // options (the first seed's, with the sweep's seeds and output directory) taken off each run.
  nlohmann::json provenance = {{"inputs", input_files_json(options)}};
  std::vector<nlohmann::json> per_seed;
  // The first seed that failed after it started, and why: the sweep stops there, its files
  // written with the seeds so far, and then reports it.
  std::string failure;
  for (const std::uint64_t seed : seeds) {
    RunOptions o = options;
    o.filter.seed = seed;
    o.hash_inputs = false;
    if (!options.out.empty()) o.out = options.out + "/seed-" + std::to_string(seed);
    std::printf("== seed %llu\n", static_cast<unsigned long long>(seed));
    std::fflush(stdout);
    nlohmann::json m;
    try {
      m = run_entry(o, on_accepted, failure);
      if (!failure.empty()) failure = "seed " + std::to_string(seed) + ": " + failure;
    } catch (const std::exception& e) {
      // Before the sweep started, a refusal: nothing to summarise.
      if (!accepted) throw;
      failure = "seed " + std::to_string(seed) + ": " + e.what();
      m = nlohmann::json{{"status", std::string("failed: ") + e.what()}};
    }
    per_seed.push_back(std::move(m));
    nlohmann::json& entry = per_seed.back();
    const bool interrupted = entry["status"] == "interrupted";
    entry["seed"] = seed;
    take_provenance(entry, provenance);
    // The seeds run so far are summarised; the rest are not started.
    if (interrupted || !failure.empty()) break;
  }
  const int signal = interrupt_signal();
  provenance["options"]["seed"] = nullptr;
  provenance["options"]["seeds"] = seeds;
  provenance["options"]["out"] = options.out;
  // A failed seed's numbers are those of a run cut short: listed, not summarised.
  std::vector<nlohmann::json> finished;
  for (const nlohmann::json& m : per_seed) {
    if (!m.value("status", "").starts_with("failed")) finished.push_back(m);
  }
  const nlohmann::json summary = summarise_seeds(finished);
  std::printf("== %zu seeds: mean / median / worst (max) / stdev\n", seeds.size());
  print_headline(summary);
  const int code = signal != 0 ? 128 + signal : 0;
  if (options.out.empty()) {
    if (!failure.empty()) throw std::runtime_error(failure);
    return code;
  }
  {
    nlohmann::json sweep = std::move(provenance);
    sweep["seeds"] = seeds;
    sweep["status"] = !failure.empty() ? "failed: " + failure
                      : signal != 0    ? "interrupted"
                                       : "complete";
    sweep["summary"] = summary;
    sweep["per_seed"] = per_seed;
    write_file_atomically(options.out + "/sweep.json", sweep.dump(2) + '\n');
  }
  write_rows_csv(options.out + "/sweep.csv", per_seed);
  std::printf("  wrote %s/{sweep.json,sweep.csv,seed-*/}\n", options.out.c_str());
  if (!failure.empty()) {
    throw std::runtime_error(failure + "; the seeds up to it are in " + options.out +
                             "/sweep.json");
  }
  return code;
}

}  // namespace fastslam::tools
