// SHA-256 (FIPS 180-4) of bytes in memory and of files read in fixed-size chunks, so the
// provenance in metrics.json can name exactly which inputs a run read, whatever their size.
//
// Ownership: `Sha256` is a plain value holding its 64-byte block buffer; nothing is borrowed
// past a call. Thread safety: thread-compatible (one hasher per thread); the free functions are
// reentrant. Costs: O(bytes), no allocation in update(); sha256_file reads through one 1 MiB
// buffer, so memory does not grow with the file.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace fastslam::tools {

class Sha256 {
 public:
  using Digest = std::array<std::uint8_t, 32>;

  Sha256() noexcept;
  // Appends bytes; any split of the same bytes over calls gives the same digest.
  void update(const void* data, std::size_t size) noexcept;
  void update(std::string_view bytes) noexcept { update(bytes.data(), bytes.size()); }
  // The digest of everything appended. The hasher is spent afterwards (REQUIRES: no further
  // update or finish).
  Digest finish() noexcept;

 private:
  void block(const std::uint8_t* p) noexcept;

  std::array<std::uint32_t, 8> state_;
  std::array<std::uint8_t, 64> buffer_{};
  std::size_t buffered_ = 0;
  std::uint64_t length_ = 0;  // bytes appended
};

// Lower-case hexadecimal, 64 characters.
std::string to_hex(const Sha256::Digest& digest);
// The hex digest of `bytes`.
std::string sha256_hex(std::string_view bytes);
// The hex digest of the file at `path`, read in 1 MiB chunks. Throws std::runtime_error
// "<path>: ..." when it cannot be opened or read.
std::string sha256_file(const std::string& path);

}  // namespace fastslam::tools
