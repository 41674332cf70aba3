#include "tools/studies/scaling_study.h"

#include <algorithm>
#include <array>
#include <memory>
#include <optional>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <thread>
#include <time.h>

#include <nlohmann/json.hpp>

#include "engine/filter.h"
#include "parallel/collective.h"
#include "tools/io/atomic_file.h"
#include "tools/sim/simulator.h"
#include "tools/sim/world.h"
#include "tools/studies/linear_baseline.h"

namespace fastslam::tools {
namespace {

// CPU seconds of the whole process (every thread): on a shared machine a one-thread run's CPU
// time is what the work cost, whatever share of a core it was given.
double process_cpu_seconds() {
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Step {
  engine::Control control;
  double dt = 0.0;
  bool has_scan = false;
  std::vector<engine::Observation> scan;
  TruePose truth;
};

// The first `scans` scans of the route (with the controls before them); observations carry
// the true ids (used only under known association).
std::vector<Step> simulate(const World& world, std::uint64_t scans, std::uint64_t seed) {
  Simulator sim(world, SimConfig{}, seed);
  SimStep s;
  std::vector<Step> out;
  std::uint64_t seen = 0;
  while (seen < scans && sim.next(s)) {
    Step step{{s.speed, s.steer}, s.dt, s.has_scan, {}, s.truth};
    for (const SimObservation& z : s.scan) {
      step.scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
    }
    seen += s.has_scan ? 1 : 0;
    out.push_back(std::move(step));
  }
  return out;
}

void check_limits(const ScalingOptions& options, std::uint64_t landmarks) {
  if (landmarks == 0) throw std::invalid_argument("scaling: landmarks must be at least 1");
  if (options.updates == 0) throw std::invalid_argument("scaling: updates must be at least 1");
  if (options.engine == ScalingEngine::kLinear && landmarks > options.linear_max_landmarks) {
    throw std::invalid_argument(
        "scaling: the linear baseline costs O(M N) time and memory per update; N = " +
        std::to_string(landmarks) + " is above its cap of " +
        std::to_string(options.linear_max_landmarks) + " landmarks (--linear-max-landmarks)");
  }
}

// The linear baseline over the same steps and prior (tools/studies/linear_baseline.h).
ScalingPoint run_linear_point(const engine::FilterConfig& config, const std::vector<Step>& steps,
                              const std::vector<engine::MapLandmark>& prior) {
  LinearFastSlam filter(config);
  filter.set_map(prior);
  ScalingPoint p;
  p.lower_bound_bytes = static_cast<std::int64_t>(prior.size() * sizeof(memory::Landmark));
  const double cpu0 = process_cpu_seconds();
  const auto t0 = std::chrono::steady_clock::now();
  for (const Step& step : steps) {
    filter.predict(step.control, step.dt);
    if (step.has_scan) filter.observe(step.scan);
  }
  const engine::Pose mean = filter.mean_pose();
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  p.cpu_seconds = process_cpu_seconds() - cpu0;
  const LinearStatistics& st = filter.statistics();
  p.updates = st.scans;
  p.observations = st.observations;
  p.live_bytes = filter.live_bytes();
  p.predict_seconds = st.predict_seconds;
  p.associate_seconds = st.associate_seconds;
  p.update_seconds = st.update_seconds;
  p.resample_seconds = st.resample_seconds;
  if (!steps.empty()) {
    p.pose_error = std::hypot(mean[0] - steps.back().truth.x, mean[1] - steps.back().truth.y);
  }
  return p;
}

}  // namespace

std::string_view to_string(ScalingEngine engine) {
  return engine == ScalingEngine::kLinear ? "linear" : "tree";
}

ScalingPoint run_scaling_point(const ScalingOptions& options, std::uint64_t landmarks) {
  check_limits(options, landmarks);
  engine::validate(options.filter);
  const World world = make_grid_world(landmarks, options.spacing, 45.0, options.filter.seed);
  const std::vector<Step> steps = simulate(world, options.updates, options.filter.seed);
  std::vector<engine::MapLandmark> prior;
  prior.reserve(world.landmarks.size());
  for (std::size_t i = 0; i < world.landmarks.size(); ++i) {
    prior.push_back({0, i, world.landmarks[i].x, world.landmarks[i].y, 0.1, 0.0, 0.1, 50.0, 0});
  }
  engine::FilterConfig config = options.filter;
  config.initial_pose[0] = world.start_x;
  config.initial_pose[1] = world.start_y;
  config.initial_pose[2] = world.start_theta;
  if (options.engine == ScalingEngine::kLinear) {
    ScalingPoint p = run_linear_point(config, steps, prior);
    p.landmarks = landmarks;
    p.particles = config.particles;
    p.threads = 1;
    p.seconds_per_update = p.updates == 0 ? 0.0 : p.seconds / static_cast<double>(p.updates);
    return p;
  }
  std::shared_ptr<parallel::TimedCollective> timed;
  if (options.group != nullptr) timed = std::make_shared<parallel::TimedCollective>(options.group);
  std::unique_ptr<engine::Filter> owned = timed != nullptr
                                              ? std::make_unique<engine::Filter>(config, timed)
                                              : std::make_unique<engine::Filter>(config);
  engine::Filter& filter = *owned;
  filter.set_map(prior);
  if (timed != nullptr) timed->reset();  // the updates only
  ScalingPoint p;
  p.landmarks = landmarks;
  p.particles = config.particles;
  p.threads =
      config.threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : config.threads;
  p.lower_bound_bytes = filter.statistics().live_bytes;
  const double cpu0 = process_cpu_seconds();
  const auto t0 = std::chrono::steady_clock::now();
  for (const Step& step : steps) {
    filter.predict(step.control, step.dt);
    if (step.has_scan) filter.observe(step.scan);
  }
  (void)filter.particles();  // runs any controls still queued (none when the route ends on a scan)
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  p.cpu_seconds = process_cpu_seconds() - cpu0;
  if (timed != nullptr) {  // the updates' collective time, before the estimate's gathers
    p.gather_seconds = timed->gather_seconds;
    p.transfer_seconds = timed->exchange_seconds;
  }
  // Not timed: the estimate copies the best particle's whole map, O(N) (at N = 10^7 it cost
  // more than the 500 updates together before it was moved out of the timed part).
  const engine::Estimate estimate = filter.estimate();
  if (!steps.empty()) {
    p.pose_error = std::hypot(estimate.mean_pose[0] - steps.back().truth.x,
                              estimate.mean_pose[1] - steps.back().truth.y);
  }
  const engine::FilterStatistics st = filter.statistics();
  p.updates = st.scans;
  p.observations = st.observations;
  p.seconds_per_update = p.updates == 0 ? 0.0 : p.seconds / static_cast<double>(p.updates);
  p.live_bytes = st.live_bytes;
  p.predict_seconds = st.predict_seconds;
  p.associate_seconds = st.associate_seconds;
  p.update_seconds = st.update_seconds;
  p.resample_seconds = st.resample_seconds;
  p.observe_wall_seconds = st.observe_wall_seconds;
  if (timed != nullptr) {
    p.ranks = options.group->size();
    p.exchange_seconds = st.exchange_seconds;
    p.resamples = st.resamples;
    using Sent = std::array<std::uint64_t, 4>;
    const Sent mine = {st.exchange_bytes, st.exchange_naive_bytes, st.exchange_copies,
                       static_cast<std::uint64_t>(st.live_bytes)};
    std::uint64_t live = 0;
    for (const Sent& s : parallel::all_gather_value(*options.group, mine)) {
      p.exchange_bytes += s[0];
      p.exchange_naive_bytes += s[1];
      p.exchange_copies += s[2];
      live += s[3];
    }
    p.live_bytes = static_cast<std::int64_t>(live);
  }
  return p;
}

TransportCost measure_transport(parallel::Collective& group) {
  TransportCost cost;
  const auto n = static_cast<std::size_t>(group.size());
  for (std::uint64_t bytes = 1; bytes <= (std::uint64_t{1} << 22); bytes *= 4) {
    std::vector<parallel::Bytes> to(n, parallel::Bytes(bytes, std::byte{1}));
    std::vector<double> times;
    for (int rep = 0; rep < 9; ++rep) {
      (void)group.all_gather({});  // start together
      const auto t0 = std::chrono::steady_clock::now();
      (void)group.exchange(to);
      times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::nth_element(times.begin(), times.begin() + 4, times.end());
    // Rank 0's median, agreed on by every rank (rank 0's value).
    const double median = parallel::all_gather_value(group, times[4]).front();
    cost.samples.emplace_back(bytes, median);
  }
  // The latency from the smallest message, the per-byte cost from the largest beyond it (a least
  // squares fit would let the large messages' noise swamp the latency).
  cost.latency_seconds = cost.samples.front().second;
  cost.seconds_per_byte = (cost.samples.back().second - cost.latency_seconds) /
                          static_cast<double>(cost.samples.back().first);
  return cost;
}

namespace {

// The fastest of `repeats` runs of one point, with every run's time kept.
ScalingPoint run_repeated(const ScalingOptions& options, std::uint64_t landmarks) {
  ScalingPoint best;
  std::vector<double> runs;
  for (std::uint64_t r = 0; r < options.repeats; ++r) {
    ScalingPoint p = run_scaling_point(options, landmarks);
    runs.push_back(p.seconds);
    if (r == 0 || p.seconds < best.seconds) best = std::move(p);
  }
  best.run_seconds = std::move(runs);
  return best;
}

double per_particle_observation(const ScalingPoint& p) {
  const double n = static_cast<double>(p.observations) * p.particles;
  return n == 0.0 ? 0.0 : p.seconds / n;
}

nlohmann::json to_json(const ScalingPoint& p) {
  return {{"landmarks", p.landmarks},
          {"particles", p.particles},
          {"threads", p.threads},
          {"updates", p.updates},
          {"observations", p.observations},
          {"seconds", p.seconds},
          {"seconds_per_update", p.seconds_per_update},
          {"cpu_seconds", p.cpu_seconds},
          {"cpu_seconds_per_update", p.cpu_seconds / static_cast<double>(p.updates)},
          {"seconds_per_particle_update", p.seconds_per_update / p.particles},
          {"seconds_per_particle_observation", per_particle_observation(p)},
          {"live_bytes", p.live_bytes},
          {"lower_bound_bytes", p.lower_bound_bytes},
          {"pose_error_m", p.pose_error},
          {"observe_wall_seconds", p.observe_wall_seconds},
          {"run_seconds", p.run_seconds},
          {"ranks", p.ranks},
          {"gather_seconds_per_update", p.gather_seconds / static_cast<double>(p.updates)},
          {"transfer_seconds_per_update", p.transfer_seconds / static_cast<double>(p.updates)},
          {"exchange_seconds_per_update", p.exchange_seconds / static_cast<double>(p.updates)},
          {"resamples", p.resamples},
          {"exchange_bytes_per_resampling",
           p.resamples == 0 ? 0.0
                            : static_cast<double>(p.exchange_bytes) / static_cast<double>(p.resamples)},
          {"exchange_naive_bytes_per_resampling",
           p.resamples == 0 ? 0.0
                            : static_cast<double>(p.exchange_naive_bytes) /
                                  static_cast<double>(p.resamples)},
          {"exchange_copies", p.exchange_copies},
          {"seconds_per_phase",
           {{"predict", p.predict_seconds},
            {"associate", p.associate_seconds},
            {"update", p.update_seconds},
            {"resample", p.resample_seconds}}}};
}

constexpr const char* kCsvHeader =
    "engine,algorithm,association,landmarks,particles,threads,updates,observations,seconds,"
    "seconds_per_update,seconds_per_particle_update,seconds_per_particle_observation,live_bytes,"
    "lower_bound_bytes,pose_error_m,predict_seconds,associate_seconds,update_seconds,"
    "resample_seconds,observe_wall_seconds,repeats,slowest_seconds,cpu_seconds";

std::string csv_line(const ScalingOptions& options, const ScalingPoint& p) {
  char buf[768];
  const double slowest = p.run_seconds.empty()
                             ? p.seconds
                             : *std::max_element(p.run_seconds.begin(), p.run_seconds.end());
  std::snprintf(buf, sizeof buf,
                "%s,%s,%s,%llu,%u,%u,%llu,%llu,%.9g,%.9g,%.9g,%.9g,%lld,%lld,%.6g,%.9g,%.9g,%.9g,"
                "%.9g,%.9g,%zu,%.9g,%.9g",
                std::string(to_string(options.engine)).c_str(),
                std::string(engine::to_string(options.filter.algorithm)).c_str(),
                std::string(engine::to_string(options.filter.association)).c_str(),
                static_cast<unsigned long long>(p.landmarks), p.particles, p.threads,
                static_cast<unsigned long long>(p.updates),
                static_cast<unsigned long long>(p.observations), p.seconds, p.seconds_per_update,
                p.seconds_per_update / p.particles, per_particle_observation(p),
                static_cast<long long>(p.live_bytes), static_cast<long long>(p.lower_bound_bytes),
                p.pose_error, p.predict_seconds, p.associate_seconds, p.update_seconds,
                p.resample_seconds, p.observe_wall_seconds,
                std::max<std::size_t>(1, p.run_seconds.size()), slowest, p.cpu_seconds);
  return buf;
}

}  // namespace

int run_scaling_command(const ScalingOptions& options, const std::string& json_path,
                        const std::string& csv_path) {
  if (options.landmarks.empty() || options.particles.empty() || options.threads.empty()) {
    throw std::invalid_argument(
        "scaling: the landmarks, particles and threads lists must not be "
        "empty");
  }
  if (options.repeats == 0) throw std::invalid_argument("scaling: repeats must be at least 1");
  if (options.engine == ScalingEngine::kLinear && options.threads.size() > 1) {
    throw std::invalid_argument(
        "scaling: the linear baseline runs on one thread; give one "
        "--threads value");
  }
  ScalingOptions run = options;
  for (const std::uint64_t n : options.landmarks) check_limits(options, n);
  for (const unsigned m : options.particles) {
    run.filter.particles = m;
    engine::validate(run.filter);
    if (options.engine == ScalingEngine::kLinear)
      (void)LinearFastSlam(run.filter);  // refuses early
  }
  const engine::FilterConfig& f = options.filter;
  // Over ranks every rank runs every point; rank 0 reports.
  const bool speaks = options.group == nullptr || options.group->rank() == 0;
  const auto say = [speaks](const char* format, auto... values) {
    if (speaks) std::printf(format, values...);
  };
  std::optional<TransportCost> transport;
  if (options.group != nullptr) {
    transport = measure_transport(*options.group);
    say("transport over %d ranks: %.2f us a message + %.3f ns a byte (exchange of 1 B .. 4 MiB)\n",
        options.group->size(), 1e6 * transport->latency_seconds, 1e9 * transport->seconds_per_byte);
  }
  say("scaling: %s engine, %s, %s association, %llu updates per point, best of %llu\n",
              std::string(to_string(options.engine)).c_str(),
              std::string(engine::to_string(f.algorithm)).c_str(),
              std::string(engine::to_string(f.association)).c_str(),
              static_cast<unsigned long long>(options.updates),
              static_cast<unsigned long long>(options.repeats));
  say("%10s %7s %3s %8s %12s %12s %12s %10s %10s %10s %8s %8s\n", "landmarks", "M", "T",
              "obs/upd", "us/update", "cpu us/upd", "ns/part-upd", "ns/part-obs", "live MiB",
              "1 map MiB", "live/map", "error m");
  std::ofstream csv;
  if (!csv_path.empty() && speaks) {
    csv.open(csv_path);
    if (!(csv << kCsvHeader << '\n')) throw std::runtime_error("cannot write " + csv_path);
  }
  nlohmann::json points = nlohmann::json::array();
  const auto wall0 = std::chrono::steady_clock::now();
  for (const std::uint64_t n : options.landmarks) {
    for (const unsigned m : options.particles) {
      for (const unsigned t : options.threads) {
        run.filter.particles = m;
        run.filter.threads = t;
        const ScalingPoint p = run_repeated(run, n);
        const double mib = 1.0 / (1 << 20);
        say("%10llu %7u %3u %8.1f %12.1f %12.1f %12.1f %10.1f %10.2f %10.2f %8.3f %8.2f\n",
            static_cast<unsigned long long>(n), p.particles, p.threads,
            static_cast<double>(p.observations) / static_cast<double>(p.updates),
            1e6 * p.seconds_per_update, 1e6 * p.cpu_seconds / static_cast<double>(p.updates),
            1e9 * p.seconds_per_update / p.particles, 1e9 * per_particle_observation(p),
            static_cast<double>(p.live_bytes) * mib, static_cast<double>(p.lower_bound_bytes) * mib,
            static_cast<double>(p.live_bytes) / static_cast<double>(p.lower_bound_bytes),
            p.pose_error);
        if (p.ranks > 1) {
          const double u = static_cast<double>(p.updates);
          const double r = p.resamples == 0 ? 1.0 : static_cast<double>(p.resamples);
          say("%10s %d ranks: per update %.1f us in reductions, %.1f us in the exchange (%.1f us "
              "transfer); per resampling %.1f KiB sent, %.1f KiB by whole copies\n",
              "", p.ranks, 1e6 * p.gather_seconds / u, 1e6 * p.exchange_seconds / u,
              1e6 * p.transfer_seconds / u, static_cast<double>(p.exchange_bytes) / r / 1024,
              static_cast<double>(p.exchange_naive_bytes) / r / 1024);
        }
        std::fflush(stdout);
        points.push_back(to_json(p));
        if (csv.is_open() && !(csv << csv_line(run, p) << '\n')) {
          throw std::runtime_error("cannot write " + csv_path);
        }
      }
    }
  }
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  say("study: %.1f s wall (setup included)\n", wall);
  if (!json_path.empty() && speaks) {
    nlohmann::json out = {
        {"config",
         {{"engine", to_string(options.engine)},
          {"algorithm", engine::to_string(f.algorithm)},
          {"association", engine::to_string(f.association)},
          {"landmarks", options.landmarks},
          {"particles", options.particles},
          {"threads", options.threads},
          {"grain", f.grain},
          {"split_seconds", f.split_seconds},
          {"resample", options.engine == ScalingEngine::kLinear ? std::string("every scan")
                       : f.resample.when == parallel::ResamplePolicy::When::kEveryStep
                           ? std::string("every scan")
                           : "ess < " + std::to_string(f.resample.ess_fraction) + " M"},
          {"seed", f.seed},
          {"updates", options.updates},
          {"repeats", options.repeats},
          {"spacing_m", options.spacing},
          {"study_wall_seconds", wall}}},
        {"points", points}};
    if (transport) {
      nlohmann::json samples = nlohmann::json::array();
      for (const auto& [bytes, seconds] : transport->samples) samples.push_back({bytes, seconds});
      out["transport"] = {{"ranks", options.group->size()},
                          {"latency_seconds", transport->latency_seconds},
                          {"seconds_per_byte", transport->seconds_per_byte},
                          {"samples_bytes_seconds", samples}};
    }
    write_file_atomically(json_path, out.dump(2) + '\n');
  }
  return 0;
}

}  // namespace fastslam::tools
