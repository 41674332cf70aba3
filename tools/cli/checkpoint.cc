#include "tools/cli/checkpoint.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <istream>
#include <ostream>
#include <stdexcept>
#include <streambuf>
#include <string_view>

#include "tools/cli/build_info.h"
#include "tools/io/atomic_file.h"
#include "tools/io/sha256.h"

namespace fastslam::tools {
namespace {

constexpr char kMagic[8] = {'F', 'S', 'L', 'A', 'M', 'C', 'K', 'P'};
constexpr std::size_t kDigest = 32;
static_assert(sizeof(engine::TrajectoryPoint) == 32, "poses are saved as 32-byte records");

// Options that change no result: a run resumed with other values ends with the same files.
constexpr const char* kExecutionOptions[] = {
    "threads", "grain",       "split-seconds",   "out",         "trace",
    "stream",  "max-seconds", "max-memory",      "no-progress", "plot",
    "no-plot", "checkpoint",  "checkpoint-every"};

// Forwards every byte to `sink` and the hash.
class HashingBuffer : public std::streambuf {
 public:
  HashingBuffer(std::ostream& sink, Sha256& hash) : sink_(sink), hash_(hash) {}

 protected:
  int_type overflow(int_type c) override {
    if (traits_type::eq_int_type(c, traits_type::eof())) return traits_type::not_eof(c);
    const char byte = traits_type::to_char_type(c);
    return xsputn(&byte, 1) == 1 ? c : traits_type::eof();
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    hash_.update(s, static_cast<std::size_t>(n));
    sink_.write(s, n);
    return sink_ ? n : 0;
  }

 private:
  std::ostream& sink_;
  Sha256& hash_;
};

// Reads bytes in memory as a stream, for Filter::load.
class MemoryBuffer : public std::streambuf {
 public:
  MemoryBuffer(const char* begin, std::size_t size) {
    char* b = const_cast<char*>(begin);  // read only: no put area
    setg(b, b, b + size);
  }
};

template <class T>
void put(std::ostream& out, const T& value) {
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

void put_section(std::ostream& out, std::string_view bytes) {
  put<std::uint64_t>(out, bytes.size());
  if (!bytes.empty()) out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Reads sections from the file's bytes, every length checked against what is left.
class Reader {
 public:
  Reader(const std::string& path, std::string_view bytes) : path_(path), bytes_(bytes) {}
  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(path_ + ": not a usable checkpoint: " + what);
  }
  template <class T>
  T get(const char* what) {
    if (bytes_.size() - at_ < sizeof(T)) fail(std::string("truncated at the ") + what);
    T value;
    std::memcpy(&value, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }
  std::string_view section(const char* what, std::size_t record = 1) {
    const auto n = get<std::uint64_t>(what);
    if (n / record > (bytes_.size() - at_) / record || n % record != 0) {
      fail(std::string("the ") + what + " section's length " + std::to_string(n) +
           " exceeds the file");
    }
    const std::string_view out = bytes_.substr(at_, n);
    at_ += n;
    return out;
  }
  std::string_view rest() const { return bytes_.substr(at_); }

 private:
  const std::string& path_;
  std::string_view bytes_;
  std::size_t at_ = 0;
};

std::uint64_t get_count(const Reader& r, const nlohmann::json& header, const char* key) {
  const auto found = header.find(key);
  if (found == header.end() || !found->is_number_unsigned()) {
    r.fail(std::string("the header's \"") + key + "\" is missing or not a count");
  }
  return found->get<std::uint64_t>();
}

// "particles = 100" for a message.
std::string describe(const std::string& key, const nlohmann::json* value) {
  return value == nullptr ? key + " absent" : key + " = " + value->dump();
}

}  // namespace

nlohmann::json run_identity(const nlohmann::json& options, const nlohmann::json& inputs) {
  nlohmann::json kept = options;
  for (const char* key : kExecutionOptions) kept.erase(key);
  // Whether there is a trace decides what the checkpoint holds; its path does not.
  kept["trace"] = options.contains("trace") && !options["trace"].is_null();
  return {{"build", build_info_json()}, {"options", kept}, {"inputs", inputs}};
}

void write_checkpoint(const std::string& path, const Checkpoint& c,
                      std::span<const engine::TrajectoryPoint> poses,
                      const engine::Filter& filter) {
  AtomicFile file(path);
  Sha256 hash;
  HashingBuffer buffer(file.stream(), hash);
  std::ostream out(&buffer);
  out.write(kMagic, sizeof(kMagic));
  put<std::uint32_t>(out, kCheckpointVersion);
  nlohmann::json header = {{"identity", c.identity},
                           {"events", c.events},
                           {"controls", c.controls},
                           {"scans", c.scans},
                           {"run", c.run}};
  put_section(out, header.dump());
  put_section(out, c.trace);
  put_section(out, std::string_view(reinterpret_cast<const char*>(poses.data()),
                                    poses.size() * sizeof(engine::TrajectoryPoint)));
  filter.save(out);
  if (!out) file.flush();  // throws naming the file and the reason
  const Sha256::Digest digest = hash.finish();
  file.stream().write(reinterpret_cast<const char*>(digest.data()), digest.size());
  file.commit();
}

Checkpoint read_checkpoint(const std::string& path) {
  std::string bytes;
  {
    std::FILE* file = std::fopen(path.c_str(), "rb");
    if (file == nullptr) {
      throw std::runtime_error(path + ": cannot open the checkpoint: " + std::strerror(errno));
    }
    char chunk[1 << 16];
    std::size_t n = 0;
    while ((n = std::fread(chunk, 1, sizeof(chunk), file)) > 0) bytes.append(chunk, n);
    const bool failed = std::ferror(file) != 0;
    std::fclose(file);
    if (failed) throw std::runtime_error(path + ": cannot read the checkpoint");
  }
  return parse_checkpoint(path, bytes);
}

Checkpoint parse_checkpoint(const std::string& path, std::string_view bytes) {
  Reader r(path, bytes);
  if (bytes.size() < sizeof(kMagic) || std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) {
    r.fail("no checkpoint magic (not written by fastslam run --checkpoint)");
  }
  if (bytes.size() < sizeof(kMagic) + 4 + kDigest) r.fail("truncated");
  Sha256 hash;
  hash.update(bytes.substr(0, bytes.size() - kDigest));
  const Sha256::Digest digest = hash.finish();
  if (std::memcmp(digest.data(), bytes.data() + bytes.size() - kDigest, kDigest) != 0) {
    r.fail("its SHA-256 does not match (a torn or altered file)");
  }
  Reader body(path, bytes.substr(0, bytes.size() - kDigest));
  body.get<std::array<char, sizeof(kMagic)>>("magic");
  if (const auto version = body.get<std::uint32_t>("version"); version != kCheckpointVersion) {
    body.fail("format version " + std::to_string(version) + ", this build reads version " +
              std::to_string(kCheckpointVersion) + "; start the run again without --resume");
  }
  Checkpoint c;
  const std::string_view header_text = body.section("header");
  nlohmann::json header;
  try {
    header = nlohmann::json::parse(header_text);
  } catch (const nlohmann::json::exception& e) {
    body.fail(std::string("the header is not JSON: ") + e.what());
  }
  if (!header.is_object() || !header.contains("identity") || !header["identity"].is_object() ||
      !header.contains("run") || !header["run"].is_object()) {
    body.fail("the header lacks its identity or run objects");
  }
  c.identity = header["identity"];
  c.run = header["run"];
  c.events = get_count(body, header, "events");
  c.controls = get_count(body, header, "controls");
  c.scans = get_count(body, header, "scans");
  if (c.controls > c.events || c.scans > c.events - c.controls) {
    body.fail("more controls and scans than events");
  }
  c.trace = std::string(body.section("trace"));
  const std::string_view poses = body.section("poses", sizeof(engine::TrajectoryPoint));
  c.poses.resize(poses.size() / sizeof(engine::TrajectoryPoint));
  if (!poses.empty()) std::memcpy(c.poses.data(), poses.data(), poses.size());
  for (std::size_t k = 0; k < c.poses.size(); ++k) {
    if (c.poses[k].control != k) body.fail("pose " + std::to_string(k) + " out of order");
  }
  if (c.poses.size() > c.controls) body.fail("more poses than controls");
  c.filter_state = std::string(body.rest());
  return c;
}

void check_same_run(const std::string& path, const nlohmann::json& saved,
                    const nlohmann::json& now) {
  const std::string hint =
      "; resume with the arguments, inputs and build that made it, or "
      "start again without --resume";
  const auto refuse = [&](const std::string& what) {
    throw std::runtime_error("--resume " + path + ": " + what + hint);
  };
  const auto differs = [&](const char* part, const std::string& noun) {
    const nlohmann::json& a = saved.contains(part) ? saved[part] : nlohmann::json();
    const nlohmann::json& b = now[part];
    if (a == b) return;
    if (a.is_object() && b.is_object()) {
      for (const auto& [key, value] : b.items()) {
        const nlohmann::json* old = a.contains(key) ? &a[key] : nullptr;
        if (old == nullptr || *old != value) {
          refuse("the checkpoint was made with " + noun + " " + describe(key, old) +
                 ", this run has " + describe(key, &value));
        }
      }
      for (const auto& [key, value] : a.items()) {
        if (!b.contains(key))
          refuse("the checkpoint's " + noun + " has " + key + ", this run's not");
      }
    }
    refuse("the checkpoint was made with other " + noun + " (" + a.dump() + ", now " + b.dump() +
           ")");
  };
  differs("build", "build");
  differs("options", "option");
  differs("inputs", "inputs");
}

std::unique_ptr<engine::Filter> load_filter(const std::string& path, const Checkpoint& c,
                                            const engine::FilterConfig& execution) {
  MemoryBuffer buffer(c.filter_state.data(), c.filter_state.size());
  std::istream in(&buffer);
  std::unique_ptr<engine::Filter> filter;
  try {
    filter = engine::Filter::load(in, execution);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(path + ": not a usable checkpoint: " + e.what());
  }
  if (in.peek() != std::istream::traits_type::eof()) {
    throw std::runtime_error(path + ": not a usable checkpoint: bytes after the filter's state");
  }
  return filter;
}

}  // namespace fastslam::tools
