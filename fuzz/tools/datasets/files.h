// The data set readers read directories, so their fuzzers turn one input into files: the input
// is cut at NUL bytes into the reader's files, in the order given (missing ones are empty), and
// written to a directory of this process's own, made on first use and removed at exit. The
// directory is on tmpfs (/dev/shm) when there is one: on a disk file system each rewrite of a
// truncated file starts a write-back (ext4's auto_da_alloc), which made the fuzzers I/O-bound.
// FASTSLAM_FUZZ_TMPDIR, then TMPDIR, then /tmp otherwise.
// Thread safety: none (one fuzzer thread). Costs: O(input) per call, a file write each.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <string_view>

namespace fastslam::fuzz {

inline const std::filesystem::path& scratch_dir() {
  static const std::filesystem::path dir = [] {
    std::string base = "/tmp";
    std::error_code absent;
    if (const char* chosen = std::getenv("FASTSLAM_FUZZ_TMPDIR")) {
      base = chosen;
    } else if (std::filesystem::is_directory("/dev/shm", absent)) {
      base = "/dev/shm";
    } else if (const char* tmp = std::getenv("TMPDIR")) {
      base = tmp;
    }
    std::string pattern = base + "/fastslam-fuzz-XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) std::abort();
    static const std::filesystem::path made = pattern;
    std::atexit([] {
      std::error_code ignored;
      std::filesystem::remove_all(made, ignored);
    });
    return made;
  }();
  return dir;
}

// Writes the NUL-separated parts of [data, data + size) as `names`, in order; returns the
// directory.
inline const std::filesystem::path& write_files(const std::uint8_t* data, std::size_t size,
                                                std::initializer_list<const char*> names) {
  const std::filesystem::path& dir = scratch_dir();
  std::string_view rest(reinterpret_cast<const char*>(data), size);
  for (const char* name : names) {
    const std::size_t cut = rest.find('\0');
    const std::string_view part = rest.substr(0, cut);
    rest = cut == std::string_view::npos ? std::string_view() : rest.substr(cut + 1);
    std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
    out.write(part.data(), static_cast<std::streamsize>(part.size()));
    if (!out) std::abort();
  }
  return dir;
}

}  // namespace fastslam::fuzz
