// The C API (bindings/c/fastslam.h) over engine::Filter. Every entry point is noexcept: it
// checks its pointers and counts, runs the engine inside `guarded`, which turns each exception
// into a status and keeps its what() as the message, on the handle and on the thread.
#include "bindings/c/fastslam.h"

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <memory>
#include <new>
#include <optional>
#include <span>
#include <sstream>
#include <stdexcept>
#include <streambuf>
#include <string>
#include <string_view>
#include <sys/stat.h>
#include <system_error>
#include <unistd.h>
#include <vector>

#include "bindings/config_json.h"
#include "engine/filter.h"

static_assert(std::string_view(FASTSLAM_VERSION) == FASTSLAM_PROJECT_VERSION,
              "bindings/c/fastslam.h's FASTSLAM_VERSION differs from the project's version");

namespace {

using fastslam::engine::Control;
using fastslam::engine::Estimate;
using fastslam::engine::Filter;
using fastslam::engine::Observation;

constexpr std::size_t kMaxBytes = PTRDIFF_MAX;

// A message that survives running out of memory: a static text stands in when the copy fails.
class ErrorText {
 public:
  void set(const char* text) noexcept {
    try {
      text_.assign(text);
      fallback_ = nullptr;
    } catch (...) {
      fallback_ = "out of memory (the error message could not be kept)";
    }
  }
  void clear() noexcept {
    text_.clear();
    fallback_ = nullptr;
  }
  const char* c_str() const noexcept { return fallback_ != nullptr ? fallback_ : text_.c_str(); }

 private:
  std::string text_;
  const char* fallback_ = nullptr;
};

// The latest failure on this thread, for calls without a handle (create, load) and for all.
thread_local ErrorText t_last_error;

}  // namespace

struct fastslam_filter {
  std::unique_ptr<Filter> filter;
  ErrorText error;                // of the latest call; "" after a success
  std::vector<Observation> scan;  // observe's copy of the caller's observations
  // What estimate() gave since the filter last changed: estimate, map and associations read it.
  std::optional<Estimate> snapshot;
  // The bytes of a save_buffer size query, for the save_buffer call right after it.
  std::optional<std::string> saved;

  const Estimate& estimate() {
    if (!snapshot) snapshot = filter->estimate();
    return *snapshot;
  }
};

namespace {

fastslam_status fail(fastslam_filter* f, fastslam_status status, const char* message) noexcept {
  if (f != nullptr) f->error.set(message);
  t_last_error.set(message);
  return status;
}

fastslam_status fail(fastslam_filter* f, fastslam_status status,
                     const std::string& message) noexcept {
  return fail(f, status, message.c_str());
}

// Runs `body` (which returns a status, having called `fail` for any but OK) and maps what it
// throws. A success clears the handle's message.
template <class Body>
fastslam_status guarded(fastslam_filter* f, Body&& body) noexcept {
  try {
    const fastslam_status status = body();
    if (status == FASTSLAM_OK && f != nullptr) f->error.clear();
    return status;
  } catch (const std::invalid_argument& e) {
    return fail(f, FASTSLAM_INVALID_ARGUMENT, e.what());
  } catch (const std::bad_alloc& e) {
    return fail(f, FASTSLAM_OUT_OF_MEMORY, e.what());
  } catch (const std::length_error& e) {  // a container asked for more than it can hold
    return fail(f, FASTSLAM_OUT_OF_MEMORY, e.what());
  } catch (const std::exception& e) {
    return fail(f, FASTSLAM_INTERNAL, e.what());
  } catch (...) {
    return fail(f, FASTSLAM_INTERNAL, "unknown exception");
  }
}

// The pointer checks, before anything can throw (their messages are literals).
#define FASTSLAM_REQUIRE_FILTER(f, function)                                        \
  do {                                                                              \
    if ((f) == nullptr) {                                                           \
      return fail(nullptr, FASTSLAM_INVALID_ARGUMENT, function ": filter is NULL"); \
    }                                                                               \
  } while (false)

#define FASTSLAM_REQUIRE_POINTER(f, p, function, name)                          \
  do {                                                                          \
    if ((p) == nullptr) {                                                       \
      return fail(f, FASTSLAM_INVALID_ARGUMENT, function ": " name " is NULL"); \
    }                                                                           \
  } while (false)

std::string too_large(const char* function, const char* what, std::size_t value,
                      std::size_t limit) {
  std::string message = std::string(function) + ": " + what + " = " + std::to_string(value) +
                        " is more than " + std::to_string(limit);
  if (value > static_cast<std::size_t>(PTRDIFF_MAX)) {
    message += " (" + std::to_string(static_cast<std::ptrdiff_t>(value)) +
               " as a signed number: a negative count?)";
  } else if (value > UINT32_MAX / 2 && value <= UINT32_MAX) {
    message += " (" + std::to_string(static_cast<std::int32_t>(static_cast<std::uint32_t>(value))) +
               " as a signed 32-bit number: a negative count?)";
  }
  return message;
}

// Copies `items` into the caller's buffer, converted by `convert`, after the size checks.
template <class T, class From, class Convert>
fastslam_status copy_out(fastslam_filter* f, const char* function, const std::vector<From>& items,
                         T* buf, std::size_t capacity, std::size_t* count, Convert convert) {
  if (buf != nullptr && capacity > FASTSLAM_MAX_COUNT) {
    return fail(f, FASTSLAM_INVALID_ARGUMENT,
                too_large(function, "capacity", capacity, FASTSLAM_MAX_COUNT));
  }
  *count = items.size();
  if (buf == nullptr) return FASTSLAM_OK;
  if (capacity < items.size()) {
    return fail(f, FASTSLAM_BUFFER_TOO_SMALL,
                std::string(function) + ": the buffer holds " + std::to_string(capacity) + ", " +
                    std::to_string(items.size()) + " are needed");
  }
  for (std::size_t i = 0; i < items.size(); ++i) buf[i] = convert(items[i]);
  return FASTSLAM_OK;
}

std::string system_message(int error) { return std::generic_category().message(error); }

// The bytes of `f`'s state: save_buffer's kept ones, or a fresh save.
std::string saved_bytes(fastslam_filter* f) {
  if (f->saved) return *f->saved;
  std::ostringstream out;
  f->filter->save(out);
  return std::move(out).str();
}

// An input stream over the caller's bytes, without copying them. Never written: there is no
// put area, and the default pbackfail refuses.
class MemoryBuffer : public std::streambuf {
 public:
  MemoryBuffer(const void* data, std::size_t size) {
    char* begin = static_cast<char*>(const_cast<void*>(data));
    setg(begin, begin, begin + size);
  }
  std::size_t remaining() const { return static_cast<std::size_t>(egptr() - gptr()); }
};

// Filter::load and the check that nothing follows the state. `trailing` counts the bytes left.
template <class Trailing>
fastslam_status load_from(std::istream& in, const char* function, fastslam_filter** out,
                          Trailing trailing) {
  auto handle = std::make_unique<fastslam_filter>();
  try {
    handle->filter = Filter::load(in);
    if (in.peek() != std::char_traits<char>::eof()) {
      return fail(nullptr, FASTSLAM_CORRUPT_STATE,
                  std::string(function) + ": " + std::to_string(trailing()) +
                      " bytes follow the end of the saved state");
    }
  } catch (const std::bad_alloc&) {
    throw;
  } catch (const std::exception& e) {
    // Filter::load throws std::runtime_error for a stream that is not a state; anything else
    // it throws on such input (a value a container or a check refuses) means the same.
    return fail(nullptr, in.bad() ? FASTSLAM_IO_ERROR : FASTSLAM_CORRUPT_STATE, e.what());
  }
  *out = handle.release();
  return FASTSLAM_OK;
}

fastslam_landmark to_c(const fastslam::engine::MapLandmark& m) {
  fastslam_landmark l;
  l.id = m.id;
  l.x = m.x;
  l.y = m.y;
  l.sxx = m.sxx;
  l.sxy = m.sxy;
  l.syy = m.syy;
  l.log_odds = m.log_odds;
  l.last_seen = m.last_seen;
  l.slot = m.slot;
  return l;
}

fastslam_association to_c(const fastslam::engine::ObservationAssociation& a) {
  fastslam_association c;
  c.observation = a.observation;
  c.outcome = static_cast<std::int32_t>(a.outcome);
  c.landmark_id = a.landmark_id;
  c.mahalanobis2 = a.mahalanobis2;
  return c;
}

static_assert(static_cast<int>(fastslam::engine::AssociationOutcome::kAssociated) ==
                  FASTSLAM_ASSOCIATED &&
              static_cast<int>(fastslam::engine::AssociationOutcome::kNew) == FASTSLAM_NEW &&
              static_cast<int>(fastslam::engine::AssociationOutcome::kDiscarded) ==
                  FASTSLAM_DISCARDED);

fastslam_status observe(fastslam_filter* f, const char* function,
                        const fastslam_observation* observations, std::size_t count,
                        const double* time) {
  return guarded(f, [&] {
    if (count > FASTSLAM_MAX_COUNT) {
      return fail(f, FASTSLAM_INVALID_ARGUMENT,
                  too_large(function, "count", count, FASTSLAM_MAX_COUNT));
    }
    if (observations == nullptr && count > 0) {
      return fail(
          f, FASTSLAM_INVALID_ARGUMENT,
          std::string(function) + ": observations is NULL and count = " + std::to_string(count));
    }
    f->scan.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
      f->scan[i] = Observation{observations[i].range, observations[i].bearing, observations[i].id};
    }
    if (time != nullptr) {
      f->filter->observe(f->scan, *time);
    } else {
      f->filter->observe(f->scan);
    }
    f->snapshot.reset();
    return FASTSLAM_OK;
  });
}

fastslam_status predict(fastslam_filter* f, double u0, double u1, double dt, const double* time) {
  return guarded(f, [&] {
    if (time != nullptr) {
      f->filter->predict(Control{u0, u1}, dt, *time);
    } else {
      f->filter->predict(Control{u0, u1}, dt);
    }
    f->snapshot.reset();
    return FASTSLAM_OK;
  });
}

}  // namespace

extern "C" {

const char* fastslam_version(void) { return FASTSLAM_VERSION; }

const char* fastslam_status_string(fastslam_status status) {
  switch (status) {
    case FASTSLAM_OK:
      return "FASTSLAM_OK";
    case FASTSLAM_INVALID_ARGUMENT:
      return "FASTSLAM_INVALID_ARGUMENT";
    case FASTSLAM_CORRUPT_STATE:
      return "FASTSLAM_CORRUPT_STATE";
    case FASTSLAM_IO_ERROR:
      return "FASTSLAM_IO_ERROR";
    case FASTSLAM_OUT_OF_MEMORY:
      return "FASTSLAM_OUT_OF_MEMORY";
    case FASTSLAM_BUFFER_TOO_SMALL:
      return "FASTSLAM_BUFFER_TOO_SMALL";
    case FASTSLAM_INTERNAL:
      return "FASTSLAM_INTERNAL";
  }
  return "unknown status";
}

const char* fastslam_last_error(const fastslam_filter* filter) {
  return filter != nullptr ? filter->error.c_str() : t_last_error.c_str();
}

fastslam_status fastslam_create(const char* json_config, fastslam_filter** out) {
  FASTSLAM_REQUIRE_POINTER(nullptr, out, "fastslam_create", "out");
  *out = nullptr;
  FASTSLAM_REQUIRE_POINTER(nullptr, json_config, "fastslam_create", "json_config");
  return guarded(nullptr, [&] {
    auto handle = std::make_unique<fastslam_filter>();
    handle->filter = std::make_unique<Filter>(fastslam::bindings::config_from_json(json_config));
    *out = handle.release();
    return FASTSLAM_OK;
  });
}

void fastslam_destroy(fastslam_filter* filter) { delete filter; }

fastslam_status fastslam_get_config(fastslam_filter* filter, char* buf, size_t capacity,
                                    size_t* size) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_get_config");
  filter->saved.reset();
  FASTSLAM_REQUIRE_POINTER(filter, size, "fastslam_get_config", "size");
  return guarded(filter, [&] {
    if (buf != nullptr && capacity > kMaxBytes) {
      return fail(filter, FASTSLAM_INVALID_ARGUMENT,
                  too_large("fastslam_get_config", "capacity", capacity, kMaxBytes));
    }
    const std::string text = fastslam::bindings::config_to_json(filter->filter->config());
    *size = text.size() + 1;
    if (buf == nullptr) return FASTSLAM_OK;
    if (capacity < text.size() + 1) {
      return fail(filter, FASTSLAM_BUFFER_TOO_SMALL,
                  "fastslam_get_config: the buffer holds " + std::to_string(capacity) + " bytes, " +
                      std::to_string(text.size() + 1) + " are needed");
    }
    std::memcpy(buf, text.c_str(), text.size() + 1);
    return FASTSLAM_OK;
  });
}

fastslam_status fastslam_predict(fastslam_filter* filter, double u0, double u1, double dt) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_predict");
  filter->saved.reset();
  return predict(filter, u0, u1, dt, nullptr);
}

fastslam_status fastslam_predict_timed(fastslam_filter* filter, double u0, double u1, double dt,
                                       double time) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_predict_timed");
  filter->saved.reset();
  return predict(filter, u0, u1, dt, &time);
}

fastslam_status fastslam_observe(fastslam_filter* filter, const fastslam_observation* observations,
                                 size_t count) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_observe");
  filter->saved.reset();
  return observe(filter, "fastslam_observe", observations, count, nullptr);
}

fastslam_status fastslam_observe_timed(fastslam_filter* filter,
                                       const fastslam_observation* observations, size_t count,
                                       double time) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_observe_timed");
  filter->saved.reset();
  return observe(filter, "fastslam_observe_timed", observations, count, &time);
}

fastslam_status fastslam_get_estimate(fastslam_filter* filter, fastslam_estimate* out) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_get_estimate");
  filter->saved.reset();
  FASTSLAM_REQUIRE_POINTER(filter, out, "fastslam_get_estimate", "out");
  return guarded(filter, [&] {
    const Estimate& e = filter->estimate();
    fastslam_estimate c;
    c.time = e.time;
    std::memcpy(c.mean_pose, e.mean_pose, sizeof(c.mean_pose));
    std::memcpy(c.pose_covariance, e.pose_covariance, sizeof(c.pose_covariance));
    std::memcpy(c.best_pose, e.best_pose, sizeof(c.best_pose));
    c.best_particle = e.best_particle;
    c.effective_sample_size = e.effective_sample_size;
    c.landmark_count = e.map.size();
    c.observation_count = e.associations.size();
    *out = c;
    return FASTSLAM_OK;
  });
}

fastslam_status fastslam_get_map(fastslam_filter* filter, fastslam_landmark* buf, size_t capacity,
                                 size_t* count) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_get_map");
  filter->saved.reset();
  FASTSLAM_REQUIRE_POINTER(filter, count, "fastslam_get_map", "count");
  return guarded(filter, [&] {
    return copy_out(filter, "fastslam_get_map", filter->estimate().map, buf, capacity, count,
                    [](const auto& m) { return to_c(m); });
  });
}

fastslam_status fastslam_get_associations(fastslam_filter* filter, fastslam_association* buf,
                                          size_t capacity, size_t* count) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_get_associations");
  filter->saved.reset();
  FASTSLAM_REQUIRE_POINTER(filter, count, "fastslam_get_associations", "count");
  return guarded(filter, [&] {
    return copy_out(filter, "fastslam_get_associations", filter->estimate().associations, buf,
                    capacity, count, [](const auto& a) { return to_c(a); });
  });
}

fastslam_status fastslam_get_statistics(fastslam_filter* filter, fastslam_statistics* out) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_get_statistics");
  filter->saved.reset();
  FASTSLAM_REQUIRE_POINTER(filter, out, "fastslam_get_statistics", "out");
  return guarded(filter, [&] {
    const fastslam::engine::FilterStatistics s = filter->filter->statistics();
    fastslam_statistics c;
    c.controls = s.controls;
    c.scans = s.scans;
    c.observations = s.observations;
    c.resamples = s.resamples;
    c.weight_resets = s.weight_resets;
    c.landmarks_created = s.landmarks_created;
    c.landmarks_removed = s.landmarks_removed;
    c.log_evidence = s.log_evidence;
    c.predict_seconds = s.predict_seconds;
    c.associate_seconds = s.associate_seconds;
    c.update_seconds = s.update_seconds;
    c.resample_seconds = s.resample_seconds;
    c.observe_wall_seconds = s.observe_wall_seconds;
    c.live_nodes = s.live_nodes;
    c.live_bytes = s.live_bytes;
    *out = c;
    return FASTSLAM_OK;
  });
}

namespace {

// Writes `bytes` to a temporary beside `path`, fsyncs it and renames it over `path`, so a
// failure or a kill mid-write leaves the previous file whole. Returns "" or the reason, naming
// the file. A symlink is written through. The same as tools/io/atomic_file.h, kept local:
// libfastslam links the engine and the bindings only, not the tools' libraries (and their
// export set). Costs: one fsync.
std::string replace_file(const std::string& path, std::string_view bytes) {
  std::error_code ec;
  std::string target = path;
  if (std::filesystem::is_symlink(path, ec)) {
    const std::filesystem::path resolved = std::filesystem::weakly_canonical(path, ec);
    if (!ec) target = resolved.string();
  }
  // Only a regular file is replaced: a directory, a device (/dev/null, which root could
  // otherwise rename a file over), a FIFO or a socket is refused.
  struct stat st {};
  const bool exists = ::stat(target.c_str(), &st) == 0;
  if (exists && S_ISDIR(st.st_mode)) return "'" + path + "' is a directory";
  if (exists && !S_ISREG(st.st_mode)) {
    return "'" + path +
           "' is not a regular file (a device, a FIFO or a socket); refusing to "
           "replace it";
  }
  const std::size_t slash = target.rfind('/');
  const std::string temp =
      (slash == std::string::npos ? std::string() : target.substr(0, slash + 1)) + "." +
      target.substr(slash == std::string::npos ? 0 : slash + 1) + ".tmp-" +
      std::to_string(::getpid());
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) return "cannot open '" + path + "' for writing: " + system_message(errno);
  if (exists) (void)::fchmod(fd, st.st_mode & 07777);  // a replaced file keeps its permissions
  const auto give_up = [&](const char* what) {
    const std::string reason = system_message(errno);
    ::close(fd);
    ::unlink(temp.c_str());
    return std::string(what) + " '" + path + "' failed: " + reason;
  };
  for (std::size_t done = 0; done < bytes.size();) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return give_up("writing");
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0) return give_up("writing");
  if (::close(fd) != 0) {
    const std::string reason = system_message(errno);
    ::unlink(temp.c_str());
    return "writing '" + path + "' failed: " + reason;
  }
  if (::rename(temp.c_str(), target.c_str()) != 0) {
    const std::string reason = system_message(errno);
    ::unlink(temp.c_str());
    return "replacing '" + path + "' failed: " + reason;
  }
  return "";
}

}  // namespace

fastslam_status fastslam_save_file(fastslam_filter* filter, const char* path) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_save_file");
  filter->saved.reset();
  FASTSLAM_REQUIRE_POINTER(filter, path, "fastslam_save_file", "path");
  return guarded(filter, [&] {
    std::ostringstream state;
    filter->filter->save(state);
    const std::string error = replace_file(path, state.view());
    if (!error.empty()) {
      return fail(filter, FASTSLAM_IO_ERROR, "fastslam_save_file: " + error);
    }
    return FASTSLAM_OK;
  });
}

fastslam_status fastslam_load_file(const char* path, fastslam_filter** out) {
  FASTSLAM_REQUIRE_POINTER(nullptr, out, "fastslam_load_file", "out");
  *out = nullptr;
  FASTSLAM_REQUIRE_POINTER(nullptr, path, "fastslam_load_file", "path");
  return guarded(nullptr, [&] {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) {
      return fail(nullptr, FASTSLAM_IO_ERROR,
                  std::string("fastslam_load_file: '") + path + "' is a directory");
    }
    errno = 0;
    std::ifstream in(path, std::ios::binary);
    if (!in) {
      return fail(nullptr, FASTSLAM_IO_ERROR,
                  std::string("fastslam_load_file: cannot open '") + path +
                      "' for reading: " + system_message(errno));
    }
    return load_from(in, "fastslam_load_file", out, [&in]() -> std::uint64_t {
      const std::streamoff here = in.tellg();
      in.seekg(0, std::ios::end);
      return static_cast<std::uint64_t>(in.tellg() - here);
    });
  });
}

fastslam_status fastslam_save_buffer(fastslam_filter* filter, void* buf, size_t capacity,
                                     size_t* size) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_save_buffer");
  FASTSLAM_REQUIRE_POINTER(filter, size, "fastslam_save_buffer", "size");
  return guarded(filter, [&] {
    if (buf != nullptr && capacity > kMaxBytes) {
      filter->saved.reset();
      return fail(filter, FASTSLAM_INVALID_ARGUMENT,
                  too_large("fastslam_save_buffer", "capacity", capacity, kMaxBytes));
    }
    if (!filter->saved) filter->saved = saved_bytes(filter);
    const std::string& bytes = *filter->saved;
    *size = bytes.size();
    if (buf == nullptr) return FASTSLAM_OK;
    if (capacity < bytes.size()) {
      return fail(filter, FASTSLAM_BUFFER_TOO_SMALL,
                  "fastslam_save_buffer: the buffer holds " + std::to_string(capacity) +
                      " bytes, the state takes " + std::to_string(bytes.size()));
    }
    std::memcpy(buf, bytes.data(), bytes.size());
    filter->saved.reset();
    return FASTSLAM_OK;
  });
}

fastslam_status fastslam_save_alloc(fastslam_filter* filter, void** data, size_t* size) {
  FASTSLAM_REQUIRE_FILTER(filter, "fastslam_save_alloc");
  FASTSLAM_REQUIRE_POINTER(filter, data, "fastslam_save_alloc", "data");
  FASTSLAM_REQUIRE_POINTER(filter, size, "fastslam_save_alloc", "size");
  *data = nullptr;
  *size = 0;
  return guarded(filter, [&] {
    const std::string bytes = saved_bytes(filter);
    filter->saved.reset();
    void* memory = std::malloc(bytes.empty() ? 1 : bytes.size());
    if (memory == nullptr) {
      return fail(
          filter, FASTSLAM_OUT_OF_MEMORY,
          "fastslam_save_alloc: cannot allocate " + std::to_string(bytes.size()) + " bytes");
    }
    std::memcpy(memory, bytes.data(), bytes.size());
    *data = memory;
    *size = bytes.size();
    return FASTSLAM_OK;
  });
}

void fastslam_free(void* data) { std::free(data); }

fastslam_status fastslam_load_buffer(const void* data, size_t size, fastslam_filter** out) {
  FASTSLAM_REQUIRE_POINTER(nullptr, out, "fastslam_load_buffer", "out");
  *out = nullptr;
  FASTSLAM_REQUIRE_POINTER(nullptr, data, "fastslam_load_buffer", "data");
  return guarded(nullptr, [&] {
    if (size > kMaxBytes) {
      return fail(nullptr, FASTSLAM_INVALID_ARGUMENT,
                  too_large("fastslam_load_buffer", "size", size, kMaxBytes));
    }
    MemoryBuffer buffer(data, size);
    std::istream in(&buffer);
    return load_from(in, "fastslam_load_buffer", out,
                     [&buffer]() -> std::uint64_t { return buffer.remaining(); });
  });
}

}  // extern "C"
