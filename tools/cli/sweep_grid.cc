#include "tools/cli/sweep_grid.h"

#include <algorithm>
#include <fstream>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <stdexcept>

#include <CLI/CLI.hpp>

#include "tools/cli/checkpoint.h"
#include "tools/cli/command_line.h"
#include "tools/cli/run_provenance.h"
#include "tools/cli/run_sweep.h"

namespace fastslam::tools {
namespace {

// Steps assumed for a run without --max-steps when ordering runs by cost.
constexpr double kUnboundedSteps = 1e6;

// Keys that name one file for one run, or the sweep's own output.
const std::set<std::string> kOneRunKeys = {"out",        "trace",  "stream",
                                           "checkpoint", "resume", "config"};

// JSON with every key of every object given once: a repeated key would otherwise resolve
// silently to its last value.
nlohmann::json parse_strict(const std::string& text, const std::string& where) {
  std::vector<std::set<std::string>> open;
  const auto refuse_repeats = [&](int, nlohmann::json::parse_event_t event,
                                  nlohmann::json& parsed) {
    using Event = nlohmann::json::parse_event_t;
    if (event == Event::object_start) {
      open.emplace_back();
    } else if (event == Event::object_end) {
      open.pop_back();
    } else if (event == Event::key && !open.back().insert(parsed.get<std::string>()).second) {
      throw std::runtime_error(where + ": key '" + parsed.get<std::string>() +
                               "' is repeated: give each key once");
    }
    return true;
  };
  try {
    return nlohmann::json::parse(text, refuse_repeats);
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(where + ": not valid JSON: " + e.what());
  }
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw std::runtime_error(path + ": read failed");
  return text.str();
}

// A value as it appears in a configuration's name.
std::string value_text(const nlohmann::json& v) {
  return v.is_string() ? v.get<std::string>() : v.dump();
}

// Characters a directory name keeps; the others become '_'.
std::string sanitise(const std::string& text) {
  std::string out = text;
  for (char& c : out) {
    const bool keep = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                      c == '.' || c == '-' || c == '+';
    if (!keep) c = '_';
  }
  return out;
}

// A fresh `fastslam run` command with `args` parsed. Throws std::runtime_error with CLI11's
// message for a bad flag.
struct ParsedRun {
  CLI::App app{"fastslam run"};
  RunOptions options;
  RunWords words;
  explicit ParsedRun(const std::vector<std::string>& args) {
    add_run_options(app, options, words);
    std::vector<std::string> reversed(args.rbegin(), args.rend());
    try {
      app.parse(reversed);
    } catch (const CLI::ParseError& e) {
      throw std::runtime_error(std::string("fastslam sweep takes `fastslam run`'s options: ") +
                               e.what());
    }
  }
  bool given(const std::string& key) const {
    const CLI::Option* o = app.get_option_no_throw("--" + key);
    return o != nullptr && o->count() > 0;
  }
};

// Refuses a key no run may take in a sweep, or that `fastslam run` does not know.
void check_key(const CLI::App& probe, const std::string& where, const std::string& key) {
  const std::string head = where + ": key '" + key + "': ";
  if (key == "seed" || key == "seeds") {
    throw std::runtime_error(head +
                             "give the seeds as the file's top-level \"seeds\" (or --seeds)");
  }
  if (kOneRunKeys.contains(key)) {
    throw std::runtime_error(head +
                             "not in a sweep: it names one file for one run (each run writes "
                             "OUT/NAME/seed-S; the sweep's --out is OUT)");
  }
  if (probe.get_option_no_throw("--" + key) == nullptr) {
    throw std::runtime_error(head +
                             "unknown option of `fastslam run` (keys are its long flag names "
                             "without '--')");
  }
}

// An axis: a non-empty array of distinct numbers, strings or booleans.
void check_axis(const std::string& where, const std::string& key, const nlohmann::json& values) {
  const std::string head = where + ": key '" + key + "': ";
  if (!values.is_array()) throw std::runtime_error(head + "an axis must be an array of values");
  if (values.empty()) throw std::runtime_error(head + "empty axis: give at least one value");
  std::set<std::string> seen;
  for (const nlohmann::json& v : values) {
    if (!v.is_number() && !v.is_string() && !v.is_boolean()) {
      throw std::runtime_error(head + "values must be numbers, strings or booleans");
    }
    if (!seen.insert(value_text(v)).second) {
      throw std::runtime_error(head + "value " + v.dump() + " is given twice");
    }
  }
}

std::vector<std::uint64_t> seeds_of(const nlohmann::json& v, const std::string& where) {
  try {
    if (v.is_string()) return parse_seeds(v.get<std::string>());
    if (v.is_number_unsigned()) return {v.get<std::uint64_t>()};
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(where + ": key 'seeds': " + e.what());
  }
  throw std::runtime_error(where + ": key 'seeds': give a seed or a list such as \"1-10\"");
}

}  // namespace

SweepPlan plan_sweep(const SweepRequest& request) {
  SweepPlan plan;
  const std::string file = request.config.empty() ? "fastslam sweep" : request.config;
  nlohmann::json sweep = nlohmann::json::object();
  if (!request.config.empty()) {
    plan.config_text = read_text(request.config);
    sweep = parse_strict(plan.config_text, file);
    if (!sweep.is_object()) throw std::runtime_error(file + ": expected one JSON object");
  }
  for (const auto& item : sweep.items()) {
    if (item.key() != "base" && item.key() != "seeds" && item.key() != "grid" &&
        item.key() != "sources") {
      throw std::runtime_error(file + ": key '" + item.key() +
                               "': unknown (a sweep file has \"base\", \"seeds\", \"grid\" and "
                               "\"sources\"; run options go in \"base\")");
    }
  }
  const ParsedRun probe(request.run_args);
  for (const char* key : {"seed", "out", "trace", "stream", "checkpoint", "resume", "config"}) {
    if (probe.given(key)) {
      check_key(probe.app, "the command line", key);
    }
  }

  // The base, every source's options and the grid, each key checked where it stands.
  const nlohmann::json base = sweep.value("base", nlohmann::json::object());
  if (!base.is_object()) throw std::runtime_error(file + ": key 'base': expected an object");
  for (const auto& item : base.items()) check_key(probe.app, file + ": base", item.key());

  nlohmann::json grid = sweep.value("grid", nlohmann::json::object());
  if (!grid.is_object()) throw std::runtime_error(file + ": key 'grid': expected an object");
  for (const std::string& flag : request.grid) {
    const std::size_t eq = flag.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw std::runtime_error("--grid " + flag + ": give KEY=V1,V2,...");
    }
    nlohmann::json values = nlohmann::json::array();
    std::stringstream list(flag.substr(eq + 1));
    for (std::string v; std::getline(list, v, ',');) values.push_back(v);
    if (flag.back() == ',') values.push_back("");
    const std::string key = flag.substr(0, eq);
    if (values.empty()) throw std::runtime_error("--grid " + key + ": empty axis");
    grid[key] = values;  // replaces the file's axis
  }
  for (const auto& [key, values] : grid.items()) {
    check_key(probe.app, file + ": grid", key);
    check_axis(file + ": grid", key, values);
    if (base.contains(key)) {
      throw std::runtime_error(file + ": key '" + key +
                               "' is in both base and grid: give it in one");
    }
    if (probe.given(key)) {
      throw std::runtime_error("--" + key + " is given on the command line and as an axis of " +
                               file + "'s grid: give it in one");
    }
  }

  std::vector<nlohmann::json> sources;
  if (sweep.contains("sources")) {
    const nlohmann::json& list = sweep["sources"];
    if (!list.is_array()) throw std::runtime_error(file + ": key 'sources': expected an array");
    if (list.empty()) throw std::runtime_error(file + ": key 'sources': empty axis");
    std::set<std::string> names;
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string where = file + ": sources[" + std::to_string(i) + "]";
      const nlohmann::json& s = list[i];
      if (!s.is_object()) throw std::runtime_error(where + ": expected an object");
      if (!s.contains("name") || !s["name"].is_string() || s["name"].get<std::string>().empty() ||
          sanitise(s["name"].get<std::string>()) != s["name"].get<std::string>()) {
        throw std::runtime_error(where +
                                 ": key 'name': give each source a name of letters, digits, "
                                 "'.', '-' or '+'");
      }
      const std::string name = s["name"].get<std::string>();
      if (!names.insert(name).second) {
        throw std::runtime_error(where + ": key 'name': '" + name + "' is given twice");
      }
      for (const auto& item : s.items()) {
        if (item.key() == "name") continue;
        check_key(probe.app, where, item.key());
        if (base.contains(item.key()) || grid.contains(item.key())) {
          throw std::runtime_error(where + ": key '" + item.key() + "' is also in " +
                                   (base.contains(item.key()) ? "base" : "grid") +
                                   ": give it in one");
        }
      }
      sources.push_back(s);
    }
    plan.grid["source"] = nlohmann::json::array();
    for (const nlohmann::json& s : sources) plan.grid["source"].push_back(s["name"]);
  }
  for (const auto& [key, values] : grid.items()) plan.grid[key] = values;

  // Seeds: --seeds, else the file's, else the one seed of the run options.
  if (probe.given("seeds")) {
    plan.seeds = parse_seeds(probe.words.seeds);
  } else if (sweep.contains("seeds")) {
    plan.seeds = seeds_of(sweep["seeds"], file);
  } else {
    plan.seeds = {probe.options.filter.seed};
  }

  // The cartesian product: sources outermost, then the grid's keys in name order, the last
  // fastest.
  std::vector<std::string> keys;
  std::vector<std::size_t> sizes;
  for (const auto& [key, values] : grid.items())
    keys.push_back(key), sizes.push_back(values.size());
  const std::size_t n_sources = std::max<std::size_t>(1, sources.size());
  std::size_t product = 1;
  for (std::size_t s : sizes) product *= s;
  std::map<std::string, std::string> named;  // name -> the first configuration given it
  std::map<std::string, nlohmann::json> inputs_seen;
  std::map<std::string, nlohmann::json> all_inputs;  // path -> entry
  for (std::size_t s = 0; s < n_sources; ++s) {
    for (std::size_t k = 0; k < product; ++k) {
      SweepConfiguration c;
      c.axes = nlohmann::json::object();
      nlohmann::json merged = base;
      std::vector<std::string> parts;
      if (!sources.empty()) {
        c.axes["source"] = sources[s]["name"];
        parts.push_back(sources[s]["name"].get<std::string>());
        for (const auto& item : sources[s].items()) {
          if (item.key() != "name") merged[item.key()] = item.value();
        }
      }
      std::size_t rest = k;
      std::vector<std::size_t> at(keys.size());
      for (std::size_t a = keys.size(); a-- > 0;) {
        at[a] = rest % sizes[a];
        rest /= sizes[a];
      }
      for (std::size_t a = 0; a < keys.size(); ++a) {
        const nlohmann::json& v = grid[keys[a]][at[a]];
        c.axes[keys[a]] = v;
        merged[keys[a]] = v;
        parts.push_back(keys[a] + "-" + sanitise(value_text(v)));
      }
      for (const std::string& p : parts) c.name += (c.name.empty() ? "" : "_") + p;
      const auto [clash, fresh] = named.emplace(c.name, c.axes.dump());
      if (!fresh) {
        throw std::runtime_error(file + ": configurations " + clash->second + " and " +
                                 c.axes.dump() + " get the same directory name '" + c.name +
                                 "': give values that differ in letters or digits");
      }
      ParsedRun run(request.run_args);
      const std::string where = file + (c.name.empty() ? "" : " (configuration " + c.name + ")");
      try {
        apply_json_config(run.app, merged, where);
        finish_run_options(run.app, run.words, run.options);
      } catch (const std::invalid_argument& e) {
        throw std::runtime_error(where + ": " + e.what());
      }
      c.options = run.options;
      c.options.seeds.clear();
      c.options.config.clear();
      c.options.progress = false;
      c.options.quiet = true;
      c.options.hash_inputs = false;
      // Each set of inputs is hashed once for the whole sweep.
      std::string key;
      for (const std::string& path : run_inputs(c.options)) key += path + '\n';
      key += c.options.source;
      auto found = inputs_seen.find(key);
      if (found == inputs_seen.end()) {
        found = inputs_seen.emplace(key, input_files_json(c.options)).first;
      }
      c.inputs = found->second;
      for (const nlohmann::json& entry : c.inputs) all_inputs[entry["path"]] = entry;
      plan.configurations.push_back(std::move(c));
    }
  }
  plan.inputs = nlohmann::json::array();
  for (const auto& [path, entry] : all_inputs) plan.inputs.push_back(entry);

  for (std::size_t c = 0; c < plan.configurations.size(); ++c) {
    const SweepConfiguration& config = plan.configurations[c];
    const RunOptions& o = config.options;
    const bool ekf = o.filter.algorithm == engine::Algorithm::kEkf;
    const double cost = (ekf ? 1.0 : static_cast<double>(o.filter.particles)) *
                        (o.max_steps ? static_cast<double>(*o.max_steps) : kUnboundedSteps);
    for (const std::uint64_t seed : plan.seeds) {
      SweepRun r;
      r.configuration = c;
      r.seed = seed;
      r.dir = (config.name.empty() ? "" : config.name + "/") + "seed-" + std::to_string(seed);
      r.cost = cost;
      RunOptions seeded = o;
      seeded.filter.seed = seed;
      r.identity = run_identity(resolved_options_json(seeded, seeded.filter, seeded.association),
                                config.inputs);
      plan.runs.push_back(std::move(r));
    }
  }
  return plan;
}

std::vector<std::size_t> largest_first(const SweepPlan& plan) {
  std::vector<std::size_t> order(plan.runs.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return plan.runs[a].cost > plan.runs[b].cost;
  });
  return order;
}

RunOptions run_options(const SweepPlan& plan, std::size_t i, const std::string& out) {
  const SweepRun& r = plan.runs[i];
  const SweepConfiguration& c = plan.configurations[r.configuration];
  RunOptions o = c.options;
  o.filter.seed = r.seed;
  o.out = out + "/" + r.dir;
  o.sweep_run =
      nlohmann::json{{"configuration", c.name}, {"seed", r.seed}, {"identity", r.identity}}.dump();
  return o;
}

}  // namespace fastslam::tools
