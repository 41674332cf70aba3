// The native log reader (tools/io/log_format.h) on arbitrary bytes: a refusal is
// std::runtime_error; an accepted log writes and reads back equal; the streaming reader
// (LogReader) accepts the same logs, returns the same events and agrees on the end marker.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "fuzz/tools/io/round_trip.h"
#include "tools/io/log_format.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace fastslam;
  const std::string text(reinterpret_cast<const char*>(data), size);
  tools::Log log;
  bool read = false;
  try {
    std::istringstream in(text);
    log = tools::read_log(in, "fuzz");
    read = true;
  } catch (const std::runtime_error&) {
  }
  std::size_t streamed = 0;
  bool streamed_all = false;
  try {
    std::istringstream in(text);
    tools::LogReader reader(in, "fuzz");
    tools::Event event;
    std::vector<engine::Observation> scan;
    while (reader.next(event, scan)) {
      if (read && (streamed >= log.events.size() || event.kind != log.events[streamed].kind ||
                   event.time != log.events[streamed].time)) {
        std::abort();  // the two readers disagree on an event
      }
      ++streamed;
    }
    streamed_all = true;
    if (read && log.unterminated == reader.ended()) std::abort();  // disagree on the end
  } catch (const std::runtime_error&) {
  }
  if (read != streamed_all || (read && streamed != log.events.size())) std::abort();
  if (read) fastslam::fuzz::check_round_trip(log);
  return 0;
}
