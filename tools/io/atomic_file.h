// Files that appear whole or not at all: the text goes to a temporary `.NAME.tmp-PID` in the
// target's directory, every write and the close are checked, and commit() flushes, fsyncs and
// renames it over the target. A file that is not committed (an error, an exception) leaves
// nothing behind: the destructor removes the temporary. A symlink target is written through
// (the file it names is replaced, the link stays); a directory, a device, a FIFO or a socket is
// refused, never replaced.
//
// A run writing several files into one directory starts their writeback, commits each with
// the directory's sync deferred and syncs the directory once (sync_directories): the disk then
// writes the files together and the renames reach it in one directory sync.
//
// Ownership: owns its descriptor and the temporary. Thread safety: thread-compatible.
// Costs: writes are buffered (64 KiB) and reach the kernel when the buffer fills or on
// flush(); commit() costs an fsync of the file and, unless deferred, one of its directory.
#pragma once

#include <cstddef>
#include <ostream>
#include <span>
#include <streambuf>
#include <string>
#include <string_view>

namespace fastslam::tools {

// Whether commit() syncs the target's directory (the rename's durability) or leaves it to a
// later sync_directory() of that directory.
enum class DirectorySync { kNow, kDeferred };

class AtomicFile {
 public:
  // Creates the temporary beside `path` (after resolving symlinks). Throws std::runtime_error
  // "PATH: ..." when the target is not a regular file or cannot be created.
  explicit AtomicFile(const std::string& path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  // Appends `text`. Throws std::runtime_error "PATH: write failed: REASON" once a write to the
  // kernel has failed (a full disk), so a run learns of it when it happens.
  void write(std::string_view text);
  // A stream over the same buffer, for writers that take a std::ostream; a failed write sets
  // its badbit, and commit() reports it.
  std::ostream& stream() { return stream_; }
  // Hands the buffer to the kernel. Throws as write().
  void flush();
  // Flushes and asks the kernel to start writing the text to the disk without waiting for it,
  // so that the fsync of a later commit() overlaps with other files' (Linux; elsewhere only
  // flushes). Throws as write().
  void start_writeback();
  // Flushes, fsyncs, closes and renames onto the target, then (kNow) syncs the target's
  // directory. Throws std::runtime_error naming the target and the reason; the temporary is
  // removed then.
  void commit(DirectorySync directory = DirectorySync::kNow);
  // Removes the temporary; the target is left as it was. Idempotent.
  void discard();

  bool failed() const { return error_ != 0; }
  // The file the text will replace (a symlink resolved).
  const std::string& target() const { return target_; }
  // The path as given.
  const std::string& path() const { return path_; }

 private:
  class Buffer : public std::streambuf {
   public:
    explicit Buffer(AtomicFile& owner) : owner_(owner) {}

   protected:
    int_type overflow(int_type c) override;
    std::streamsize xsputn(const char* s, std::streamsize n) override;
    int sync() override;

   private:
    AtomicFile& owner_;
  };

  bool push(std::string_view text);  // writes to the descriptor; false on failure
  bool drain();                      // pushes the buffer
  [[noreturn]] void fail(const std::string& what);

  std::string path_, target_, temp_;
  int fd_ = -1;
  int error_ = 0;  // errno of the first failed write
  std::string buffer_;
  Buffer streambuf_{*this};
  std::ostream stream_{&streambuf_};
};

// Removes the temporaries of `path` (its target) that processes no longer running left (a run
// killed with SIGKILL cannot remove its own). Costs one listing of the target's directory.
void remove_abandoned_temporaries(const std::string& path);

// Syncs, once each, the directories that hold `targets` (AtomicFile::target() of files
// committed with DirectorySync::kDeferred), so that their renames reach the disk. Best effort,
// as commit()'s own: a directory that cannot be opened or synced is left as it is.
void sync_directories(std::span<const std::string> targets);

// Writes `text` to `path` as one AtomicFile.
void write_file_atomically(const std::string& path, std::string_view text);

// The file `path` names once symlinks are followed (the path itself when it is not a link;
// a dangling link gives the path it points to). Throws std::runtime_error for a link loop.
std::string resolve_output_path(const std::string& path);

}  // namespace fastslam::tools
