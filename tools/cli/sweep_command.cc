#include "tools/cli/sweep_command.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/cli/build_info.h"
#include "tools/cli/interrupt.h"
#include "tools/cli/mpi_ranks.h"
#include "tools/cli/run_output.h"
#include "tools/cli/run_provenance.h"
#include "tools/cli/run_sweep.h"
#include "tools/io/atomic_file.h"
#include "tools/io/sha256.h"

namespace fastslam::tools {
namespace {

constexpr const char* kSweepFiles[] = {"sweep.json", "sweep.csv"};

// JSON text, with bytes that are not UTF-8 (a path in a warning) replaced rather than thrown on.
std::string dump(const nlohmann::json& j, int indent = -1) {
  return j.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}

// Message tags between rank 0 and the others.
enum Tag : int {
  kRequest = 1,  // a worker thread's result (JSON text; empty for its first request)
  kAssign = 2,   // rank 0's answer: a run index, or -1 for none left
  kDone = 3,     // a rank's threads have all finished
  kFinal = 4,    // rank 0's exit code for every rank
};

// One run, wherever it runs: {"run": i, "metrics": ..., "failure": "..."}.
nlohmann::json execute(const SweepPlan& plan, std::size_t i, const std::string& out,
                       unsigned threads) {
  RunOptions o = run_options(plan, i, out);
  // Threads change no result (tests/engine/*determinism*); they share the machine.
  if (o.filter.threads == 0) o.filter.threads = threads;
  std::string failure;
  nlohmann::json metrics;
  try {
    metrics = run_entry(o, {}, failure);
  } catch (const std::exception& e) {
    failure = e.what();
    metrics = {{"status", std::string("failed: ") + e.what()}};
  }
  return {{"run", i}, {"metrics", std::move(metrics)}, {"failure", failure}};
}

// Rank 0's ledger: which run goes next, the results as they come, when to stop.
class Dispenser {
 public:
  Dispenser(const SweepPlan& plan, std::vector<std::size_t> pending, std::size_t done_before)
      : plan_(plan),
        pending_(std::move(pending)),
        results_(plan.runs.size()),
        finished_(done_before) {}

  // The next run to start, or -1 once none is left or the sweep is stopping.
  long long next() {
    const std::lock_guard lock(mutex_);
    if (stop_ || interrupt_signal() != 0 || at_ >= pending_.size()) return -1;
    return static_cast<long long>(pending_[at_++]);
  }

  void record(const nlohmann::json& message, int rank) {
    const std::lock_guard lock(mutex_);
    const std::size_t i = message["run"].get<std::size_t>();
    const SweepRun& r = plan_.runs[i];
    const nlohmann::json& m = message["metrics"];
    const std::string failure = message["failure"].get<std::string>();
    const std::string status = m.value("status", "failed");
    results_[i] = m;
    ++finished_;
    const std::string& name = plan_.configurations[r.configuration].name;
    std::printf("[%zu/%zu] %s%sseed %llu: %s", finished_, plan_.runs.size(), name.c_str(),
                name.empty() ? "" : " ", static_cast<unsigned long long>(r.seed), status.c_str());
    if (m.contains("pose_rmse_m") && m["pose_rmse_m"].is_number()) {
      std::printf(", pose_rmse_m %.4f", m["pose_rmse_m"].get<double>());
    }
    if (m.contains("wall_seconds")) std::printf(", %.2f s", m["wall_seconds"].get<double>());
    if (rank >= 0) std::printf(", rank %d", rank);
    std::printf("\n");
    std::fflush(stdout);
    if (!failure.empty() && failure_.empty()) {
      failure_ =
          (name.empty() ? "" : name + " ") + "seed " + std::to_string(r.seed) + ": " + failure;
      stop_ = true;
    }
    if (status == "interrupted") stop_ = true;
  }

  void set_result(std::size_t i, nlohmann::json m) { results_[i] = std::move(m); }
  const std::vector<std::optional<nlohmann::json>>& results() const { return results_; }
  const std::string& failure() const { return failure_; }

 private:
  const SweepPlan& plan_;
  std::mutex mutex_;
  std::vector<std::size_t> pending_;
  std::size_t at_ = 0;
  std::vector<std::optional<nlohmann::json>> results_;
  std::size_t finished_;
  bool stop_ = false;
  std::string failure_;
};

// The metrics of a run an earlier sweep completed with the same identity, if any.
std::optional<nlohmann::json> done_before(const SweepPlan& plan, std::size_t i,
                                          const std::string& out) {
  const std::string path = out + "/" + plan.runs[i].dir + "/metrics.json";
  std::ifstream in(path);
  if (!in) return std::nullopt;
  try {
    nlohmann::json m = nlohmann::json::parse(in);
    if (m.value("status", "") != "complete" || !m.contains("sweep_run") ||
        m["sweep_run"].value("identity", nlohmann::json()) != plan.runs[i].identity) {
      return std::nullopt;
    }
    return m;
  } catch (const nlohmann::json::exception&) {
    return std::nullopt;  // a torn or foreign file: the run is done again
  }
}

// The sweep's exit code, sweep.json and sweep.csv from the results (rank 0).
int write_results(const SweepOptions& options, const SweepPlan& plan, const Dispenser& d,
                  std::size_t resumed, int ranks, unsigned jobs) {
  const std::string& out = options.request.out;
  std::vector<nlohmann::json> rows;
  std::vector<nlohmann::json> configurations(plan.configurations.size());
  std::vector<std::vector<nlohmann::json>> complete(plan.configurations.size());
  std::size_t n_complete = 0;
  bool interrupted = interrupt_signal() != 0;
  for (std::size_t i = 0; i < plan.runs.size(); ++i) {
    const SweepRun& r = plan.runs[i];
    const SweepConfiguration& c = plan.configurations[r.configuration];
    nlohmann::json entry =
        d.results()[i] ? *d.results()[i] : nlohmann::json{{"status", "not run"}, {"seed", r.seed}};
    nlohmann::json provenance;
    take_provenance(entry, provenance);
    entry.erase("sweep_run");
    nlohmann::json& config = configurations[r.configuration];
    if (!config.contains("options") && provenance.contains("options")) {
      config["options"] = provenance["options"];
      config["options"]["seed"] = nullptr;
      config["options"]["seeds"] = plan.seeds;
      config["options"]["out"] = out + (c.name.empty() ? "" : "/" + c.name);
    }
    const std::string status = entry.value("status", "");
    if (status == "interrupted") interrupted = true;
    if (status == "complete") {
      complete[r.configuration].push_back(entry);
      ++n_complete;
    }
    entry["configuration"] = c.name;
    entry["axes"] = c.axes;
    entry["dir"] = r.dir;
    rows.push_back(std::move(entry));
  }
  for (std::size_t c = 0; c < plan.configurations.size(); ++c) {
    nlohmann::json& config = configurations[c];
    config["name"] = plan.configurations[c].name;
    config["axes"] = plan.configurations[c].axes;
    config["runs"] = plan.seeds.size();
    config["complete"] = complete[c].size();
    config["summary"] = summarise_seeds(complete[c]);
  }
  const std::string& failure = d.failure();
  const int code = !failure.empty() ? 1
                   : interrupted    ? 128 + (interrupt_signal() != 0 ? interrupt_signal() : 2)
                                    : 0;
  nlohmann::json sweep = {
      {"schema_version", kMetricsSchemaVersion},
      {"build", build_info_json()},
      {"sweep",
       {{"config", options.request.config.empty() ? nlohmann::json(nullptr)
                                                  : nlohmann::json(options.request.config)},
        {"config_sha256", options.request.config.empty()
                              ? nlohmann::json(nullptr)
                              : nlohmann::json(sha256_hex(plan.config_text))},
        {"arguments", options.request.run_args},
        {"grid", plan.grid},
        {"seeds", plan.seeds},
        {"out", out},
        {"ranks", ranks},
        {"jobs", jobs}}},
      {"inputs", plan.inputs},
      {"status", !failure.empty() ? "failed: " + failure
                 : interrupted    ? std::string("interrupted")
                                  : std::string("complete")},
      {"runs_total", plan.runs.size()},
      {"runs_complete", n_complete},
      {"runs_resumed", resumed},
      {"configurations", configurations},
      {"runs", rows}};
  write_file_atomically(out + "/sweep.json", dump(sweep, 2) + '\n');
  std::vector<std::string> leading = {"configuration", "seed", "status"};
  for (const auto& [key, values] : plan.grid.items()) leading.push_back("axes." + key);
  write_rows_csv(out + "/sweep.csv", rows, leading);

  std::printf("== %zu configurations x %zu seeds: %zu runs complete (%zu from an earlier sweep)\n",
              plan.configurations.size(), plan.seeds.size(), n_complete, resumed);
  for (std::size_t c = 0; c < plan.configurations.size(); ++c) {
    const nlohmann::json& s = configurations[c]["summary"];
    if (s.empty()) continue;
    std::printf(
        "-- %s: %zu runs, mean / median / worst (max) / stdev\n",
        plan.configurations[c].name.empty() ? "(base)" : plan.configurations[c].name.c_str(),
        complete[c].size());
    print_headline(s);
  }
  std::printf("  wrote %s/{sweep.json,sweep.csv}\n", out.c_str());
  std::fflush(stdout);
  if (!failure.empty()) {
    std::fprintf(stderr, "fastslam: error: sweep: %s; the runs so far are in %s/sweep.json\n",
                 failure.c_str(), out.c_str());
  }
  return code;
}

// What every rank decides before any run: the plan, its digest; on rank 0 also the output
// directory checked and the runs an earlier sweep completed.
struct Setup {
  SweepPlan plan;
  std::string digest;  // SHA-256 of the file, the arguments and the inputs
  std::vector<std::size_t> pending;
  std::vector<std::pair<std::size_t, nlohmann::json>> done;
};

Setup set_up(const SweepOptions& options, bool rank0) {
  const SweepRequest& request = options.request;
  if (request.out.empty()) throw std::runtime_error("fastslam sweep needs --out DIR");
  Setup s;
  s.plan = plan_sweep(request);
  const nlohmann::json identity = {{"config", s.plan.config_text},
                                   {"arguments", request.run_args},
                                   {"grid", request.grid},
                                   {"out", request.out},
                                   {"inputs", s.plan.inputs}};
  s.digest = sha256_hex(dump(identity));
  if (!rank0) return s;
  std::vector<std::string> inputs = {request.config};
  for (const SweepConfiguration& c : s.plan.configurations) {
    for (const std::string& path : run_inputs(c.options)) inputs.push_back(path);
  }
  if (!options.dry_run) {  // a dry run only reads the output directory
    CreatedDir created(check_output_dir(request.out, inputs, kSweepFiles));
    created.keep();
  }
  for (const std::size_t i : largest_first(s.plan)) {
    if (std::optional<nlohmann::json> m = done_before(s.plan, i, request.out)) {
      s.done.emplace_back(i, std::move(*m));
    } else {
      s.pending.push_back(i);
    }
  }
  return s;
}

void print_plan(const Setup& s) {
  std::printf("%zu configurations x %zu seeds = %zu runs; %zu done by an earlier sweep\n",
              s.plan.configurations.size(), s.plan.seeds.size(), s.plan.runs.size(), s.done.size());
  for (const std::size_t i : s.pending) {
    const SweepRun& r = s.plan.runs[i];
    std::printf("  %-40s cost %.3g\n", r.dir.c_str(), r.cost);
  }
}

// The local worker threads: each hands `next` its last run's result (null at first) and gets
// the next run, until `next` says none is left.
template <class Next>
void run_workers(unsigned jobs, const SweepPlan& plan, const std::string& out, unsigned threads,
                 const Next& next) {
  std::vector<std::thread> workers;
  for (unsigned j = 0; j < jobs; ++j) {
    workers.emplace_back([&] {
      nlohmann::json result;
      for (long long i = next(nullptr); i >= 0; i = next(&result)) {
        result = execute(plan, static_cast<std::size_t>(i), out, threads);
      }
    });
  }
  for (std::thread& t : workers) t.join();
}

void pause_briefly(int& idle) {
  // From 0.1 ms up to 3.2 ms while nothing comes: answers stay prompt, an idle rank sleeps.
  std::this_thread::sleep_for(std::chrono::microseconds(100 << std::min(idle, 5)));
  idle = std::min(idle + 1, 6);
}

// A run index or an exit code as a message's bytes, and back.
template <class T>
std::string_view bytes_of(const T& v) {
  return {reinterpret_cast<const char*>(&v), sizeof(T)};
}
template <class T>
T value_of(const std::string& bytes) {
  T v{};
  if (bytes.size() != sizeof(T)) throw std::runtime_error("MPI: a message of the wrong size");
  std::memcpy(&v, bytes.data(), sizeof(T));
  return v;
}

// Rank 0 serves the other ranks' requests while its own workers run.
void serve(Ranks& ranks, Dispenser& d, const std::atomic<unsigned>& local_running) {
  int ranks_done = 0;
  int idle = 0;
  while (ranks_done < ranks.size() - 1 || local_running > 0) {
    std::optional<RankMessage> m = ranks.poll();
    if (!m) {
      pause_briefly(idle);
      continue;
    }
    idle = 0;
    if (m->tag == kDone) {
      ++ranks_done;
      continue;
    }
    if (!m->bytes.empty()) d.record(nlohmann::json::parse(m->bytes), m->source);
    const long long next = d.next();
    ranks.send(m->source, kAssign, bytes_of(next));
  }
}

// A rank other than 0: its workers ask rank 0 for runs and send back their results; then it
// waits for the sweep's exit code.
int work(Ranks& ranks, const Setup& s, const std::string& out, unsigned jobs, unsigned threads) {
  const auto next = [&ranks](const nlohmann::json* result) -> long long {
    const std::string text = result != nullptr ? dump(*result) : std::string();
    const std::lock_guard lock(ranks.exchange_mutex);
    ranks.send(0, kRequest, text);
    return value_of<long long>(ranks.receive(0, kAssign));
  };
  run_workers(ranks.serialized() ? jobs : 1, s.plan, out, threads, next);
  ranks.send(0, kDone, {});
  int idle = 0;
  for (;;) {
    if (std::optional<std::string> code = ranks.poll(0, kFinal)) return value_of<int>(*code);
    pause_briefly(idle);
  }
}

// Every rank: refuses the sweep on all ranks when any could not plan it or planned another.
// Returns false (after the messages) when refused.
bool agree(const Ranks& ranks, const std::string& error, const std::string& digest) {
  const std::vector<int> ok = ranks.all_flags(error.empty() ? 1 : 0);
  const bool all_ok = std::all_of(ok.begin(), ok.end(), [](int f) { return f != 0; });
  if (!all_ok) {
    // Each rank's own message, unless it is rank 0's: one copy of a shared mistake.
    const std::string first = ranks.broadcast(error);
    const std::string where = ranks.size() > 1 ? "rank " + std::to_string(ranks.rank()) + ": " : "";
    if (!error.empty() && (ranks.rank() == 0 || error != first)) {
      std::fprintf(stderr, "fastslam: error: %s%s\n", where.c_str(), error.c_str());
    }
    if (ranks.rank() == 0 && ranks.size() > 1) {
      std::string failed;
      for (std::size_t r = 0; r < ok.size(); ++r) {
        if (!ok[r]) failed += (failed.empty() ? "" : ", ") + std::to_string(r);
      }
      std::fprintf(stderr, "fastslam: error: sweep not started: rank(s) %s could not plan it\n",
                   failed.c_str());
    }
    return false;
  }
  const std::string zero = ranks.broadcast(digest);
  const std::vector<int> same = ranks.all_flags(zero == digest ? 1 : 0);
  const std::vector<std::string> digests = ranks.gather(digest, 64);
  if (std::all_of(same.begin(), same.end(), [](int f) { return f != 0; })) return true;
  if (ranks.rank() == 0) {
    for (std::size_t r = 1; r < same.size(); ++r) {
      if (same[r]) continue;
      std::fprintf(stderr,
                   "fastslam: error: ranks disagree on the sweep: rank %zu read another sweep "
                   "file, other arguments or other inputs than rank 0 (SHA-256 %s, rank 0 %s); "
                   "give every rank the same command and files\n",
                   r, digests[r].c_str(), digest.c_str());
    }
  }
  return false;
}

}  // namespace

int run_sweep_command(const SweepOptions& options) {
  const Launch launch = launch_environment();
  if (launch.size > 1 && !have_mpi()) {
    std::fprintf(stderr,
                 "fastslam: error: this fastslam was built without MPI but was started as one "
                 "of %d processes (mpirun): each would run the whole sweep. Rebuild with Open "
                 "MPI (libopenmpi-dev) or run it without mpirun (--jobs N uses local threads)\n",
                 launch.size);
    return 1;
  }
  Ranks ranks(launch.launched && have_mpi());
  const bool rank0 = ranks.rank() == 0;
  const InterruptHandlers handlers;
  Setup s;
  std::string error;
  try {
    s = set_up(options, rank0);
  } catch (const std::exception& e) {
    error = e.what();
  }
  if (!agree(ranks, error, s.digest)) return 1;

  // Runs at once here, and each run's threads when its options leave them to the sweep.
  const unsigned hardware = std::max(1U, std::thread::hardware_concurrency());
  const unsigned per_node = static_cast<unsigned>(ranks.mpi() ? launch.local_size : 1);
  unsigned run_threads = 0;
  for (const SweepConfiguration& c : s.plan.configurations) {
    run_threads = std::max(run_threads, c.options.filter.threads);
  }
  const unsigned jobs = options.jobs > 0
                            ? options.jobs
                            : std::max(1U, hardware / per_node / std::max(1U, run_threads));
  const unsigned threads = std::max(1U, hardware / per_node / jobs);

  int code = 0;
  if (rank0) {
    try {
      if (options.dry_run) {
        print_plan(s);
      } else {
        std::printf(
            "== sweep: %zu runs (%zu done before), %d rank%s x %u jobs, %u threads per run\n",
            s.plan.runs.size(), s.done.size(), ranks.size(), ranks.size() > 1 ? "s" : "", jobs,
            threads);
        std::fflush(stdout);
        Dispenser d(s.plan, s.pending, s.done.size());
        for (auto& [i, m] : s.done) d.set_result(i, std::move(m));
        const auto next = [&d](const nlohmann::json* result) {
          if (result != nullptr) d.record(*result, -1);
          return d.next();
        };
        if (ranks.size() == 1) {
          run_workers(jobs, s.plan, options.request.out, threads, next);
        } else {
          // The main thread serves the other ranks; the local workers run beside it.
          std::atomic<unsigned> running{1};
          std::thread local([&] {
            run_workers(jobs, s.plan, options.request.out, threads, next);
            running = 0;
          });
          try {
            serve(ranks, d, running);
          } catch (const std::exception& e) {
            // The other ranks wait on rank 0's answers: end them all rather than leave them.
            std::fprintf(stderr, "fastslam: error: rank 0: %s; aborting every rank\n", e.what());
            ranks.abort(1);
          }
          local.join();
        }
        code = write_results(options, s.plan, d, s.done.size(), ranks.size(), jobs);
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "fastslam: error: %s\n", e.what());
      code = 1;
    }
    for (int r = 1; r < ranks.size(); ++r) ranks.send(r, kFinal, bytes_of(code));
    return code;
  }
  if (options.dry_run) return value_of<int>(ranks.receive(0, kFinal));
  return work(ranks, s, options.request.out, jobs, threads);
}

}  // namespace fastslam::tools
