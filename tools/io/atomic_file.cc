#include "tools/io/atomic_file.h"

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <dirent.h>
#include <fcntl.h>
#include <stdexcept>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

namespace fastslam::tools {
namespace {

constexpr std::size_t kBufferBytes = std::size_t{1} << 16;

std::string reason(int error) { return std::strerror(error); }

std::string directory_of(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  return slash == 0 ? "/" : path.substr(0, slash);
}

void sync_directory_of(const std::string& path) {
  const int dir = ::open(directory_of(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    (void)::fsync(dir);
    ::close(dir);
  }
}

const char* kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode) || S_ISBLK(mode)) return "a device";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

}  // namespace

std::string resolve_output_path(const std::string& path) {
  std::string current = path;
  for (int hops = 0; hops < 40; ++hops) {
    struct stat st {};
    if (::lstat(current.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return current;
    std::string link(static_cast<std::size_t>(st.st_size > 0 ? st.st_size : 4096) + 1, '\0');
    const ssize_t n = ::readlink(current.c_str(), link.data(), link.size());
    if (n < 0) throw std::runtime_error(path + ": cannot read the link: " + reason(errno));
    link.resize(static_cast<std::size_t>(n));
    current = link.starts_with('/') ? link : directory_of(current) + "/" + link;
  }
  throw std::runtime_error(path + ": too many levels of symbolic links");
}

AtomicFile::AtomicFile(const std::string& path) : path_(path), target_(resolve_output_path(path)) {
  struct stat st {};
  const bool exists = ::stat(target_.c_str(), &st) == 0;
  if (exists && !S_ISREG(st.st_mode)) {
    throw std::runtime_error(path + ": is " + kind_of(st.st_mode) +
                             "; refusing to replace it (give a regular file's path)");
  }
  const std::size_t slash = target_.rfind('/');
  const std::string dir = slash == std::string::npos ? std::string() : target_.substr(0, slash + 1);
  const std::string name = slash == std::string::npos ? target_ : target_.substr(slash + 1);
  temp_ = dir + "." + name + ".tmp-" + std::to_string(::getpid());
  ::unlink(temp_.c_str());  // a killed earlier process with this pid
  fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
  if (fd_ < 0) {
    const int e = errno;
    throw std::runtime_error(path + ": cannot open for writing: " + reason(e));
  }
  // A replaced file keeps its permissions.
  if (exists) (void)::fchmod(fd_, st.st_mode & 07777);
  buffer_.reserve(kBufferBytes);
}

AtomicFile::~AtomicFile() { discard(); }

void remove_abandoned_temporaries(const std::string& path) {
  const std::string target = resolve_output_path(path);
  const std::size_t slash = target.rfind('/');
  const std::string dir = slash == std::string::npos ? std::string(".") : target.substr(0, slash);
  const std::string prefix =
      "." + (slash == std::string::npos ? target : target.substr(slash + 1)) + ".tmp-";
  DIR* listing = ::opendir(dir.empty() ? "/" : dir.c_str());
  if (listing == nullptr) return;
  while (const dirent* entry = ::readdir(listing)) {
    const std::string name = entry->d_name;
    if (!name.starts_with(prefix) || name.size() == prefix.size()) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
    const pid_t pid = static_cast<pid_t>(std::stol(digits));
    if (pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH) {
      ::unlink((dir + "/" + name).c_str());
    }
  }
  ::closedir(listing);
}

bool AtomicFile::push(std::string_view text) {
  if (error_ != 0) return false;
  if (fd_ < 0) {
    error_ = EBADF;
    return false;
  }
  while (!text.empty()) {
    const ssize_t n = ::write(fd_, text.data(), text.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      error_ = errno;
      return false;
    }
    if (n == 0) {
      error_ = EIO;
      return false;
    }
    text.remove_prefix(static_cast<std::size_t>(n));
  }
  return true;
}

bool AtomicFile::drain() {
  const bool ok = push(buffer_);
  buffer_.clear();
  return ok;
}

void AtomicFile::fail(const std::string& what) {
  const int e = error_ != 0 ? error_ : errno;
  discard();
  throw std::runtime_error(path_ + ": " + what + ": " + reason(e));
}

void AtomicFile::write(std::string_view text) {
  if (error_ != 0) fail("write failed");
  buffer_.append(text);
  if (buffer_.size() >= kBufferBytes && !drain()) fail("write failed");
}

void AtomicFile::flush() {
  if (!drain()) fail("write failed");
}

void AtomicFile::start_writeback() {
  if (!drain()) fail("write failed");
#if defined(__linux__)
  // Only a hint: a file system without it (EINVAL, ENOSYS) is written at the fsync.
  (void)::sync_file_range(fd_, 0, 0, SYNC_FILE_RANGE_WRITE);
#endif
}

void AtomicFile::commit(DirectorySync directory) {
  if (!drain()) fail("write failed");
  if (!stream_) {
    error_ = error_ != 0 ? error_ : EIO;
    fail("write failed");
  }
  if (::fsync(fd_) != 0 && errno != EINVAL) {
    error_ = errno;
    fail("write failed (fsync)");
  }
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    error_ = errno;
    fail("write failed (close)");
  }
  if (::rename(temp_.c_str(), target_.c_str()) != 0) {
    error_ = errno;
    fail("cannot rename " + temp_ + " onto " + target_);
  }
  temp_.clear();
  // The rename reaches the disk with its directory.
  if (directory == DirectorySync::kNow) sync_directory_of(target_);
}

void sync_directories(std::span<const std::string> targets) {
  std::vector<std::string> done;
  for (const std::string& target : targets) {
    std::string dir = directory_of(target);
    if (std::find(done.begin(), done.end(), dir) != done.end()) continue;
    sync_directory_of(target);
    done.push_back(std::move(dir));
  }
}

void AtomicFile::discard() {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  if (!temp_.empty()) {
    ::unlink(temp_.c_str());
    temp_.clear();
  }
  buffer_.clear();
}

AtomicFile::Buffer::int_type AtomicFile::Buffer::overflow(int_type c) {
  if (traits_type::eq_int_type(c, traits_type::eof())) return traits_type::not_eof(c);
  const char ch = traits_type::to_char_type(c);
  return xsputn(&ch, 1) == 1 ? c : traits_type::eof();
}

std::streamsize AtomicFile::Buffer::xsputn(const char* s, std::streamsize n) {
  AtomicFile& f = owner_;
  if (f.error_ != 0) return 0;
  f.buffer_.append(s, static_cast<std::size_t>(n));
  if (f.buffer_.size() >= kBufferBytes && !f.drain()) return 0;
  return n;
}

int AtomicFile::Buffer::sync() { return owner_.drain() ? 0 : -1; }

void write_file_atomically(const std::string& path, std::string_view text) {
  AtomicFile file(path);
  file.write(text);
  file.commit();
}

}  // namespace fastslam::tools
