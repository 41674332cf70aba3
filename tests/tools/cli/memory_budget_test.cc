#include "tools/cli/memory_budget.h"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "engine/filter.h"
#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

constexpr std::uint64_t kKiB = 1024, kMiB = kKiB << 10, kGiB = kMiB << 10;

TEST(MemorySize, ParsesBytesAndBinaryUnits) {
  EXPECT_EQ(parse_memory_size("0"), 0u);
  EXPECT_EQ(parse_memory_size("123"), 123u);
  EXPECT_EQ(parse_memory_size("123B"), 123u);
  EXPECT_EQ(parse_memory_size("18446744073709551615"), UINT64_MAX);
  EXPECT_EQ(parse_memory_size("64K"), 64 * kKiB);
  EXPECT_EQ(parse_memory_size("64kib"), 64 * kKiB);
  EXPECT_EQ(parse_memory_size("512M"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("512MB"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("4G"), 4 * kGiB);
  EXPECT_EQ(parse_memory_size("4g"), 4 * kGiB);
  EXPECT_EQ(parse_memory_size("1.5G"), 3 * kGiB / 2);
  EXPECT_EQ(parse_memory_size("2T"), 2 * (kGiB << 10));
}

TEST(MemorySize, RefusesWhatIsNotASizeSayingWhy) {
  for (const char* bad : {"", "G", "-1", "4X", "4 G", "4iB", "1.5", "1e9", "0x10", "4GG", "1.2.3G",
                          "18446744073709551616", "16777216T"}) {
    try {
      parse_memory_size(bad);
      ADD_FAILURE() << "'" << bad << "' was accepted";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind(std::string("'") + bad + "' is not a size (", 0), 0u) << what;
      EXPECT_NE(what.find("give bytes, or a number with K, M, G or T (512M, 4G)"),
                std::string::npos)
          << what;
    }
  }
  // The option's check rewrites a size as bytes and leaves anything else as it was.
  std::string text = "2M";
  EXPECT_EQ(memory_size_check(text), "");
  EXPECT_EQ(text, "2097152");
  text = "lots";
  EXPECT_NE(memory_size_check(text), "");
  EXPECT_EQ(text, "lots");
}

TEST(MemorySize, FormatsInBinaryUnits) {
  EXPECT_EQ(format_bytes(0), "0 B");
  EXPECT_EQ(format_bytes(1023), "1023 B");
  EXPECT_EQ(format_bytes(1536), "1.5 KiB");
  EXPECT_EQ(format_bytes(static_cast<double>(kGiB)), "1.0 GiB");
  EXPECT_EQ(format_bytes(11.2 * static_cast<double>(kGiB)), "11.2 GiB");
  EXPECT_EQ(format_bytes(510.4 * static_cast<double>(kGiB)), "510 GiB");
}

SourceInfo source(std::size_t landmarks, std::uint64_t controls, std::uint64_t detections) {
  SourceInfo info;
  info.landmarks.resize(landmarks);
  info.scans = {.controls = controls, .detections = detections, .known = true};
  return info;
}

engine::FilterConfig filter(std::uint32_t particles, engine::Algorithm algorithm,
                            engine::Association association = engine::Association::kKnown) {
  engine::FilterConfig c;
  c.particles = particles;
  c.algorithm = algorithm;
  c.association = association;
  c.record_trajectory = true;
  return c;
}

// Each term as memory_budget.cc measured it: the particles' linear in M, the map's in N.
TEST(MemoryEstimate, SumsThePerParticleAndThePerMapTerms) {
  using engine::Algorithm;
  const SourceInfo info = source(1000, 40, 300);
  const MemoryEstimate one = estimate_filter_memory(filter(1000, Algorithm::kFastSlam1), info);
  const MemoryEstimate two = estimate_filter_memory(filter(2000, Algorithm::kFastSlam1), info);
  EXPECT_EQ(two.bytes - one.bytes, 1000 * one.per_particle);
  EXPECT_EQ(one.bytes, 1000 * one.per_particle + one.map_bytes);
  EXPECT_FALSE(one.lower_bound);
  EXPECT_EQ(one.landmarks, 1000u);
  // 290 own + 320 leaf + 40 controls x 5 + 300 detections x (16 + 130).
  EXPECT_EQ(one.per_particle, 290u + 320u + 40u * 5u + 300u * 146u);
  EXPECT_EQ(one.map_bytes, 1000u * 180u);

  // Each control queued before a scan adds a trajectory row; each detection records and copies.
  EXPECT_EQ(
      estimate_filter_memory(filter(1, Algorithm::kFastSlam1), source(1000, 41, 300)).per_particle -
          one.per_particle,
      5u);
  EXPECT_EQ(
      estimate_filter_memory(filter(1, Algorithm::kFastSlam1), source(1000, 40, 301)).per_particle -
          one.per_particle,
      146u);
  engine::FilterConfig untraced = filter(1, Algorithm::kFastSlam1);
  untraced.record_trajectory = false;
  EXPECT_EQ(one.per_particle - estimate_filter_memory(untraced, info).per_particle, 40u * 5u);

  // FastSLAM 2.0's covariance column and dearer copies, and its second column without odometry.
  const MemoryEstimate fs2 = estimate_filter_memory(filter(1, Algorithm::kFastSlam2), info);
  EXPECT_EQ(fs2.per_particle - one.per_particle, 200u + 300u * 135u);
  engine::FilterConfig brownian = filter(1, Algorithm::kFastSlam2);
  brownian.motion.kind = engine::MotionKind::kBrownian;
  EXPECT_EQ(estimate_filter_memory(brownian, info).per_particle - fs2.per_particle, 200u);

  // Unknown association: the spatial index's nodes, and dearer copies.
  const MemoryEstimate ml = estimate_filter_memory(
      filter(1, Algorithm::kFastSlam1, engine::Association::kMaximumLikelihood), info);
  EXPECT_EQ(ml.per_particle - one.per_particle, 480u + 300u * 55u);
  EXPECT_EQ(ml.map_bytes, 1000u * 225u);
}

TEST(MemoryEstimate, IsALowerBoundWhenTheSourceCannotSay) {
  const engine::FilterConfig c = filter(100, engine::Algorithm::kFastSlam1);
  EXPECT_TRUE(estimate_filter_memory(c, source(0, 8, 20)).lower_bound);  // no true map
  SourceInfo pipe = source(50, 8, 20);
  pipe.scans.known = false;  // a pipe's first scans
  EXPECT_TRUE(estimate_filter_memory(c, pipe).lower_bound);
  // Unknown scans still count one control each.
  EXPECT_EQ(estimate_filter_memory(c, SourceInfo{}).per_particle, 290u + 320u + 5u);
}

TEST(MemoryEstimate, TheEkfNeedsItsDenseCovariance) {
  const MemoryEstimate e =
      estimate_filter_memory(filter(1, engine::Algorithm::kEkf), source(100'000, 40, 300));
  const double n = 3 + 2 * 100'000.0;
  EXPECT_EQ(e.bytes, static_cast<std::uint64_t>(8 * n * n));
  EXPECT_EQ(e.per_particle, 0u);
}

// The run of the issue: 10^7 particles on the built-in stress world, refused with its figure.
TEST(MemoryRefusal, NamesTheFigureTheRoomAndTheWayOut) {
  const engine::FilterConfig c = filter(10'000'000, engine::Algorithm::kFastSlam1);
  const SourceInfo info = source(100'000, 40, 353);
  const MemoryEstimate e = estimate_filter_memory(c, info);
  const MemoryRoom option{kGiB, "allowed by --max-memory", true};
  const std::optional<std::string> refusal = memory_refusal(e, c, option);
  ASSERT_TRUE(refusal.has_value());
  EXPECT_EQ(*refusal,
            "--particles 10000000: the filter needs about " + format_bytes(e.bytes) + " (" +
                format_bytes(e.per_particle) +
                " per particle, for scans of 40 controls and 353 detections; 17.2 MiB for a map "
                "of 100000 landmarks), more than the 1.0 GiB allowed by --max-memory: use fewer "
                "particles or raise --max-memory");
  const MemoryRoom machine{8 * kGiB, "available (MemAvailable in /proc/meminfo)", false};
  EXPECT_NE(memory_refusal(e, c, machine)
                ->find("more than the 8.0 GiB available (MemAvailable in "
                       "/proc/meminfo): use fewer particles, or give "
                       "--max-memory SIZE to run anyway"),
            std::string::npos);
  // What fits is not refused, up to the byte.
  EXPECT_FALSE(memory_refusal(e, c, MemoryRoom{e.bytes, "allowed by --max-memory", true}));
  EXPECT_TRUE(memory_refusal(e, c, MemoryRoom{e.bytes - 1, "allowed by --max-memory", true}));

  // A source without a map: at least; a map that dominates: the map named.
  const MemoryEstimate unknown = estimate_filter_memory(c, source(0, 40, 353));
  EXPECT_NE(memory_refusal(unknown, c, option)->find("the filter needs at least "),
            std::string::npos);
  const engine::FilterConfig few = filter(1, engine::Algorithm::kFastSlam1);
  const MemoryEstimate big = estimate_filter_memory(few, source(200'000, 40, 353));
  const MemoryRoom small{16 * kMiB, "allowed by --max-memory", true};
  EXPECT_EQ(memory_refusal(big, few, small)
                ->rfind("a map of 200000 landmarks with --particles 1: the filter needs about", 0),
            0u);
  EXPECT_NE(memory_refusal(big, few, small)->find(": use a smaller map or raise --max-memory"),
            std::string::npos);
  const engine::FilterConfig ekf = filter(1, engine::Algorithm::kEkf);
  EXPECT_NE(memory_refusal(estimate_filter_memory(ekf, info), ekf, option)
                ->find("--algorithm ekf on a map of 100000 landmarks: the filter needs about "),
            std::string::npos);
}

TEST(MemoryRefusal, CheckThrowsOnlyWhenTheRunDoesNotFit) {
  const SourceInfo info = source(100, 40, 10);
  EXPECT_NO_THROW(check_memory_budget(filter(100, engine::Algorithm::kFastSlam1), info, kGiB));
  EXPECT_THROW(check_memory_budget(filter(10'000'000, engine::Algorithm::kFastSlam1), info, kGiB),
               std::invalid_argument);
}

// A file under a fake root.
void put(const std::string& root, const std::string& path, const std::string& text) {
  std::filesystem::create_directories(std::filesystem::path(root + path).parent_path());
  std::ofstream(root + path) << text;
}

TEST(MachineMemory, TheLeastOfMemAvailableAndEveryCgroupLimitAbove) {
  const std::string root = testing::temp_path("memory_root");
  std::filesystem::remove_all(root);
  EXPECT_FALSE(machine_memory_room(root).has_value());  // nothing to read: no check

  put(root, "/proc/meminfo", "MemTotal:  16000000 kB\nMemAvailable:    8000000 kB\n");
  std::optional<MemoryRoom> room = machine_memory_room(root);
  ASSERT_TRUE(room.has_value());
  EXPECT_EQ(room->bytes, std::uint64_t{8'000'000} * 1024);
  EXPECT_EQ(room->source, "available (MemAvailable in /proc/meminfo)");

  // cgroup v2: this process's group has no limit, its parent has 4 GiB of which 1 GiB is used
  // (and 0.5 GiB of that is page cache it can drop).
  put(root, "/proc/self/cgroup", "0::/jobs/run1\n");
  put(root, "/sys/fs/cgroup/jobs/run1/memory.max", "max\n");
  put(root, "/sys/fs/cgroup/jobs/memory.max", std::to_string(4 * kGiB) + "\n");
  put(root, "/sys/fs/cgroup/jobs/memory.current", std::to_string(kGiB) + "\n");
  put(root, "/sys/fs/cgroup/jobs/memory.stat",
      "anon 1\ninactive_file " + std::to_string(kGiB / 2) + "\nactive_file 3\n");
  room = machine_memory_room(root);
  ASSERT_TRUE(room.has_value());
  EXPECT_EQ(room->bytes, 4 * kGiB - kGiB / 2);
  EXPECT_EQ(room->source, "left under the cgroup's memory.max");

  // A tighter limit further down wins; one above MemAvailable does not.
  put(root, "/sys/fs/cgroup/jobs/run1/memory.max", std::to_string(kGiB) + "\n");
  EXPECT_EQ(machine_memory_room(root)->bytes, kGiB);
  put(root, "/sys/fs/cgroup/jobs/run1/memory.max", std::to_string(64 * kGiB) + "\n");
  put(root, "/sys/fs/cgroup/jobs/memory.max", "max\n");
  EXPECT_EQ(machine_memory_room(root)->source, "available (MemAvailable in /proc/meminfo)");

  // cgroup v1: "no limit" is a number near 2^63; a real one counts.
  put(root, "/proc/self/cgroup", "4:memory:/box\n0::/\n");
  put(root, "/sys/fs/cgroup/memory/box/memory.limit_in_bytes", "9223372036854771712\n");
  EXPECT_EQ(machine_memory_room(root)->source, "available (MemAvailable in /proc/meminfo)");
  put(root, "/sys/fs/cgroup/memory/box/memory.limit_in_bytes", std::to_string(2 * kGiB) + "\n");
  put(root, "/sys/fs/cgroup/memory/box/memory.usage_in_bytes", std::to_string(kGiB) + "\n");
  room = machine_memory_room(root);
  EXPECT_EQ(room->bytes, kGiB);
  EXPECT_EQ(room->source, "left under the cgroup's memory.limit_in_bytes");

  // --max-memory replaces the machine's figure.
  room = memory_room(512 * kMiB, root);
  EXPECT_EQ(room->bytes, 512 * kMiB);
  EXPECT_TRUE(room->option);
  EXPECT_FALSE(memory_room(0, root)->option);
  std::filesystem::remove_all(root);
}

// The machine this runs on has a figure, and a small run fits in it.
TEST(MachineMemory, ThisMachineHasRoomForASmallRun) {
  const std::optional<MemoryRoom> room = machine_memory_room();
  if (!room) GTEST_SKIP() << "no /proc/meminfo";
  EXPECT_GT(room->bytes, 0u);
  EXPECT_NO_THROW(
      check_memory_budget(filter(100, engine::Algorithm::kFastSlam1), source(1000, 8, 20), 0));
}

}  // namespace
}  // namespace fastslam::tools
