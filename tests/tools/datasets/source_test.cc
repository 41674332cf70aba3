#include "tools/datasets/source.h"

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/tools/temp_path.h"
#include "tools/datasets/log_source.h"
#include "tools/sim/simulator.h"
#include "tools/sim/world.h"

namespace fastslam::tools {
namespace {

using testing::temp_path;

TEST(SourceRegistry, ListsEverySourceOnceAndFindsThemByName) {
  const std::vector<std::string> names = source_names();
  EXPECT_EQ(names, (std::vector<std::string>{"sim", "log", "victoria-park", "utias"}));
  for (const std::string& name : names) {
    const SourceEntry& entry = find_source(name);
    EXPECT_EQ(entry.name, name);
    EXPECT_NE(entry.open, nullptr);
  }
  try {
    find_source("mrclam");
    FAIL() << "an unknown source was found";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()),
              "--source 'mrclam' is not supported (sim, log, victoria-park, utias)");
  }
}

TEST(SourceRegistry, OnlyVictoriaParkRecommendsFilterSettings) {
  const VictoriaParkFilterDefaults vp;
  const FilterDefaults& d = find_source("victoria-park").defaults;
  EXPECT_EQ(d.existence_range_margin, vp.existence_range_margin);
  EXPECT_EQ(d.existence_missed, vp.existence_missed);
  EXPECT_EQ(d.fastslam2_sigma_range, vp.fastslam2_sigma_range);
  EXPECT_EQ(d.fastslam2_sigma_bearing, vp.fastslam2_sigma_bearing);
  EXPECT_EQ(d.fastslam2_error_correlation, vp.fastslam2_error_correlation);
  for (const char* name : {"sim", "log"}) {
    const FilterDefaults& none = find_source(name).defaults;
    EXPECT_FALSE(none.existence_range_margin || none.existence_missed ||
                 none.fastslam2_sigma_range || none.fastslam2_sigma_bearing ||
                 none.fastslam2_error_correlation)
        << name;
  }
}

SourceOptions small_loop(bool clutter) {
  SourceOptions o;
  o.seed = 4;
  o.clutter = clutter;
  o.sim.world = "loop";
  o.sim.loop_length = 300.0;
  o.sim.config.loops = 1;
  o.sim.config.clutter_rate = 2.0;
  return o;
}

// Oracle: the simulator itself, step by step. The source gives per step the control, the truth
// after it and, when the step has one, its scan (false alarms only when asked, with id -1).
TEST(SimSource, GivesTheSimulatorsStepsAsEvents) {
  for (const bool clutter : {false, true}) {
    const SourceOptions o = small_loop(clutter);
    const std::unique_ptr<Source> source = find_source("sim").open(o);
    const SourceInfo& info = source->info();
    const World world = make_world(o.sim, o.seed);
    ASSERT_EQ(info.landmarks.size(), world.landmarks.size());
    for (std::size_t i = 0; i < world.landmarks.size(); ++i) {
      EXPECT_EQ(info.landmarks[i].id, i);
      EXPECT_EQ(info.landmarks[i].x, world.landmarks[i].x);
    }
    EXPECT_EQ(info.header.motion.kind, engine::MotionKind::kBaileyCar);
    EXPECT_EQ(info.header.sensor.sigma_range, o.sim.config.sigma_range);
    EXPECT_TRUE(info.simulated);
    EXPECT_EQ(info.name, "loop");

    Simulator sim(world, resolved_sim_config(o.sim), o.seed);
    SimStep step;
    Event e;
    std::vector<engine::Observation> scan;
    double t = 0.0;
    std::size_t steps = 0, clutter_seen = 0;
    while (sim.next(step)) {
      t += step.dt;
      ASSERT_TRUE(source->next(e, scan));
      ASSERT_EQ(e.kind, EventKind::kControl);
      EXPECT_EQ(e.time, t);
      EXPECT_EQ(e.dt, step.dt);
      EXPECT_EQ(e.control.u0, step.speed);
      EXPECT_EQ(e.control.u1, step.steer);
      ASSERT_TRUE(source->next(e, scan));
      ASSERT_EQ(e.kind, EventKind::kTruthPose);
      EXPECT_EQ(e.x, step.truth.x);
      EXPECT_EQ(e.theta, step.truth.theta);
      if (step.has_scan) {
        ASSERT_TRUE(source->next(e, scan));
        ASSERT_EQ(e.kind, EventKind::kScan);
        std::size_t k = 0;
        for (const SimObservation& z : step.scan) {
          if (z.landmark == kClutter) {
            ++clutter_seen;
            if (!clutter) continue;
          }
          ASSERT_LT(k, scan.size());
          EXPECT_EQ(scan[k].range, z.range);
          EXPECT_EQ(scan[k].id, z.landmark == kClutter ? -1 : std::int64_t{z.landmark});
          ++k;
        }
        EXPECT_EQ(k, scan.size());
        EXPECT_EQ(e.count, scan.size());
      }
      ++steps;
    }
    EXPECT_FALSE(source->next(e, scan));
    EXPECT_GT(steps, 100u);
    EXPECT_GT(clutter_seen, 0u);
    EXPECT_NEAR(info.expected_controls, static_cast<double>(steps), 0.1 * steps);
  }
}

TEST(LogSource, GivesTheLogsEventsAndScans) {
  Log log;
  log.landmarks = {{7, 1.0, 2.0}};
  log.observations = {{5.0, 0.1, 7}, {6.0, -0.2, -1}};
  Event control;
  control.kind = EventKind::kControl;
  control.time = 0.5;
  control.dt = 0.5;
  control.control = {1.0, 0.0};
  Event scan_event;
  scan_event.kind = EventKind::kScan;
  scan_event.time = 0.5;
  scan_event.first = 0;
  scan_event.count = 2;
  log.events = {control, scan_event, control};
  log.events[2].time = 1.0;
  LogSource source(log, "name", "summary");
  EXPECT_EQ(source.info().expected_controls, 2.0);
  EXPECT_EQ(source.info().landmarks, log.landmarks);
  EXPECT_EQ(source.info().name, "name");
  EXPECT_EQ(source.info().summary, "summary");
  EXPECT_FALSE(source.info().simulated);
  Event e;
  std::vector<engine::Observation> scan;
  for (const Event& expected : log.events) {
    ASSERT_TRUE(source.next(e, scan));
    EXPECT_EQ(e, expected);
  }
  EXPECT_FALSE(source.next(e, scan));
  ASSERT_EQ(scan.size(), 2u);
  EXPECT_EQ(scan[1].id, -1);
  EXPECT_EQ(scan[1].range, 6.0);
}

TEST(LogSource, OpensALogFileAndNeedsItsPath) {
  EXPECT_THROW(find_source("log").open(SourceOptions{}), std::invalid_argument);
  EXPECT_THROW(find_source("victoria-park").open(SourceOptions{}), std::invalid_argument);
  Log log;
  log.landmarks = {{3, -1.0, 4.0}};
  SourceOptions o;
  o.data = temp_path("log_source") + ".log";
  write_log(o.data, log);
  const std::unique_ptr<Source> source = find_source("log").open(o);
  EXPECT_EQ(source->info().landmarks, log.landmarks);
  EXPECT_EQ(source->info().name, o.data);
  Event e;
  std::vector<engine::Observation> scan;
  EXPECT_FALSE(source->next(e, scan));
  EXPECT_TRUE(source->warnings().empty());
  std::remove(o.data.c_str());
}

// A log without its end marker runs, with a warning naming the file: the in-memory source's
// from the log read, the streamed source's from its first pass over the file.
TEST(LogSource, WarnsOfALogWithoutItsEndMarker) {
  Log log;
  log.landmarks = {{3, -1.0, 4.0}};
  Event control;
  control.time = 0.5;
  control.dt = 0.5;
  log.events = {control};
  const std::string path = temp_path("log_source_cut") + ".log";
  std::ostringstream written;
  write_log(written, log);
  std::string text = written.str();
  ASSERT_EQ(text.substr(text.rfind("end ")), "end 2\n");
  text.erase(text.rfind("end "));
  std::ofstream(path) << text;

  Log read = read_log(path);
  ASSERT_TRUE(read.unterminated);
  const LogSource memory(std::move(read), path);
  ASSERT_EQ(memory.warnings().size(), 1u);
  EXPECT_EQ(memory.warnings()[0], unterminated_log_warning(path));
  EXPECT_TRUE(LogSource(log, "built").warnings().empty());  // built in memory: nothing to cut

  SourceOptions o;
  o.data = path;
  const std::unique_ptr<Source> streamed = find_source("log").open(o);
  ASSERT_EQ(streamed->warnings().size(), 1u);
  EXPECT_EQ(streamed->warnings()[0], unterminated_log_warning(path));
  Event e;
  std::vector<engine::Observation> scan;
  EXPECT_TRUE(streamed->next(e, scan));
  EXPECT_FALSE(streamed->next(e, scan));
  EXPECT_EQ(streamed->warnings().size(), 1u);  // said once

  // A record after the marker fails the opening, naming the line.
  std::ofstream(path) << text << "end 2\ncontrol 1 0.5 0 0\n";
  try {
    find_source("log").open(o);
    ADD_FAILURE() << "a record after the end marker was accepted";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("'control' after the end marker"), std::string::npos)
        << error.what();
  }
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fastslam::tools
