// The UTIAS MRCLAM reader (tools/datasets/utias.h) on arbitrary files: the input is
// Barcodes.dat, Landmark_Groundtruth.dat and Robot1_{Odometry,Measurement,Groundtruth}.dat cut
// at NUL bytes. A refusal is std::runtime_error; an accepted data set is a log that writes and
// reads back equal.
#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "fuzz/tools/datasets/files.h"
#include "fuzz/tools/io/round_trip.h"
#include "tools/datasets/utias.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace fastslam;
  const auto& dir = fuzz::write_files(data, size,
                                      {"Barcodes.dat", "Landmark_Groundtruth.dat",
                                       "Robot1_Odometry.dat", "Robot1_Measurement.dat",
                                       "Robot1_Groundtruth.dat"});
  try {
    const tools::Utias utias = tools::read_utias(dir.string());
    fuzz::check_round_trip(utias.log);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
