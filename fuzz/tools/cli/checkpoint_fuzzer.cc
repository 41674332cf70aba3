// The checkpoint reader (tools/cli/checkpoint.h) past its hash: the input is a checkpoint's
// body, and its SHA-256 is appended here, so the fuzzer reaches the sections, the header's JSON
// and the filter's state rather than stopping at a mismatched hash. A refusal is
// std::runtime_error; an accepted checkpoint loads its filter (or refuses it), which then runs a
// control and a scan without crashing.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "engine/filter.h"
#include "tools/cli/checkpoint.h"
#include "tools/io/sha256.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace fastslam;
  std::string bytes(reinterpret_cast<const char*>(data), size);
  tools::Sha256 hash;
  hash.update(bytes);
  const tools::Sha256::Digest digest = hash.finish();
  bytes.append(reinterpret_cast<const char*>(digest.data()), digest.size());
  std::unique_ptr<engine::Filter> filter;
  try {
    const tools::Checkpoint c = tools::parse_checkpoint("fuzz.ckp", bytes);
    engine::FilterConfig execution;
    execution.threads = 1;
    filter = tools::load_filter("fuzz.ckp", c, execution);
  } catch (const std::runtime_error&) {
    return 0;
  }
  try {
    filter->predict({0.5, 0.05}, 0.1);
    const engine::Observation scan[] = {{4.0, 0.3, 0}, {6.0, -0.5, 1}};
    filter->observe(scan);
  } catch (const std::invalid_argument&) {
  } catch (const std::runtime_error& e) {
    if (std::string(e.what()).find("numerical failure") == std::string::npos) throw;
  }
  return 0;
}
