// Filter::load (engine/filter.h, engine/internal/state_io.h) on arbitrary bytes: a refusal is
// std::runtime_error; a loaded filter saves bytes that load again and save the same, and runs
// a control, a scan and an estimate, which must not crash on anything the loader let through
// (bad observations for the loaded config are std::invalid_argument).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>

#include "engine/filter.h"

namespace {

std::string saved(const fastslam::engine::Filter& filter) {
  std::ostringstream out;
  filter.save(out);
  return out.str();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace fastslam::engine;
  std::unique_ptr<Filter> filter;
  try {
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
    filter = Filter::load(in);
  } catch (const std::runtime_error&) {
    return 0;
  }
  const std::string bytes = saved(*filter);
  std::istringstream again(bytes);
  if (saved(*Filter::load(again)) != bytes) std::abort();  // load throws: a crash too
  try {
    filter->predict({0.5, 0.05}, 0.1);
    const Observation scan[] = {{4.0, 0.3, 0}, {6.0, -0.5, 1}};
    filter->observe(scan);
  } catch (const std::invalid_argument&) {
  } catch (const std::runtime_error& e) {
    // Valid but extreme numbers (a covariance of 1e300) may still overflow in the scan: the
    // engine refuses that cleanly as a numerical failure, which is not a crash. Anything else
    // is. (A state that broke an invariant this way is in fuzz/regressions/.)
    if (std::string(e.what()).find("numerical failure") == std::string::npos) throw;
    return 0;
  }
  (void)filter->estimate();
  return 0;
}
