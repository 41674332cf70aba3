// The JSON configuration (bindings/config_json.h) on arbitrary text: a refusal is
// std::invalid_argument starting "config: "; an accepted config writes JSON that parses to the
// same config, which writes the same JSON.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <string_view>

#include "bindings/config_json.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace fastslam;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  engine::FilterConfig config;
  try {
    config = bindings::config_from_json(text);
  } catch (const std::invalid_argument& e) {
    if (std::string_view(e.what()).substr(0, 8) != "config: ") {
      std::fprintf(stderr, "refusal without the 'config: ' prefix: %s\n", e.what());
      std::abort();
    }
    return 0;
  }
  std::string json;
  try {
    json = bindings::config_to_json(config);
  } catch (const std::invalid_argument&) {
    return 0;  // a value JSON cannot hold (documented); nothing to read back
  }
  const std::string again = bindings::config_to_json(bindings::config_from_json(json));
  if (again != json) {
    std::fprintf(stderr, "config JSON does not read back:\n%s\n---\n%s\n", json.c_str(),
                 again.c_str());
    std::abort();
  }
  return 0;
}
