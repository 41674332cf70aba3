// The Victoria Park reader (tools/datasets/victoria_park.h) on arbitrary files: the input is
// odometry.csv, laser_scan_times.csv, tree_observations.csv and gps.csv cut at NUL bytes. A
// refusal is std::runtime_error (a bad row) or std::invalid_argument (no heading to fit); an
// accepted data set is a log that writes and reads back equal.
#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "fuzz/tools/datasets/files.h"
#include "fuzz/tools/io/round_trip.h"
#include "tools/datasets/victoria_park.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace fastslam;
  const auto& dir = fuzz::write_files(
      data, size, {"odometry.csv", "laser_scan_times.csv", "tree_observations.csv", "gps.csv"});
  try {
    const tools::VictoriaPark vp = tools::read_victoria_park(dir.string());
    fuzz::check_round_trip(vp.log);
  } catch (const std::runtime_error&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
