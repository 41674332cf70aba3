#include "tools/io/atomic_file.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include "tests/file_size_limit.h"

namespace fastslam::tools {
namespace {

namespace fs = std::filesystem;

class AtomicFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("fastslam_atomic_file_test_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string read(const std::string& p) {
    std::ifstream in(p);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }
  static void put(const std::string& p, const std::string& text) { std::ofstream(p) << text; }
  // Every name in the directory, temporaries included.
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const fs::directory_entry& e : fs::directory_iterator(dir_)) {
      out.push_back(e.path().filename().string());
    }
    std::sort(out.begin(), out.end());
    return out;
  }
  std::string error_of(const std::string& p) {
    try {
      AtomicFile file(p);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  }

  fs::path dir_;
};

TEST_F(AtomicFileTest, AppearsOnlyAtCommit) {
  const std::string p = path("out.csv");
  AtomicFile file(p);
  file.write("a,b\n");
  file.stream() << 1 << ',' << 2 << '\n';
  file.flush();
  EXPECT_FALSE(fs::exists(p));
  // The temporary sits beside the target, named after it and this process.
  EXPECT_EQ(names(), std::vector<std::string>{".out.csv.tmp-" + std::to_string(::getpid())});
  file.commit();
  EXPECT_EQ(read(p), "a,b\n1,2\n");
  EXPECT_EQ(names(), std::vector<std::string>{"out.csv"});
}

// Several files into one directory: writeback started before the commits, each commit leaving
// the directory's sync to one sync_directories call; the text and the names are as with commit().
TEST_F(AtomicFileTest, CommitsWithTheDirectorySyncDeferredPutEveryFileInPlace) {
  fs::create_directories(dir_ / "sub");
  std::vector<std::string> targets;
  {
    AtomicFile a(path("a.csv")), b(path("b.csv")), c(path("sub/c.csv"));
    const std::string big(200000, 'x');
    a.write(big);
    a.write("\n");
    b.write("b\n");
    c.write("c\n");
    for (AtomicFile* f : {&a, &b, &c}) f->start_writeback();
    EXPECT_FALSE(fs::exists(path("a.csv")));
    b.write("more\n");  // text after the writeback started is kept
    for (AtomicFile* f : {&a, &b, &c}) {
      f->commit(DirectorySync::kDeferred);
      targets.push_back(f->target());
    }
  }
  targets.push_back(path("a.csv"));                // a directory named twice is synced once
  targets.push_back(path("no such directory/d"));  // one that cannot be opened is skipped
  sync_directories(targets);
  EXPECT_EQ(read(path("a.csv")), std::string(200000, 'x') + "\n");
  EXPECT_EQ(read(path("b.csv")), "b\nmore\n");
  EXPECT_EQ(read(path("sub/c.csv")), "c\n");
  EXPECT_EQ(names(), (std::vector<std::string>{"a.csv", "b.csv", "sub"}));
}

TEST_F(AtomicFileTest, UncommittedLeavesTheTargetAsItWas) {
  const std::string p = path("metrics.json");
  put(p, "old");
  {
    AtomicFile file(p);
    file.write(std::string(200000, 'x'));  // past the buffer: the temporary holds bytes
  }
  EXPECT_EQ(read(p), "old");
  EXPECT_EQ(names(), std::vector<std::string>{"metrics.json"});
  AtomicFile file(p);
  file.write("new");
  file.discard();
  file.discard();
  EXPECT_EQ(read(p), "old");
  EXPECT_EQ(names(), std::vector<std::string>{"metrics.json"});
}

TEST_F(AtomicFileTest, ReplacingKeepsThePermissions) {
  const std::string p = path("x.log");
  put(p, "old");
  ASSERT_EQ(::chmod(p.c_str(), 0640), 0);
  write_file_atomically(p, "new");
  struct stat st {};
  ASSERT_EQ(::stat(p.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0640u);
  EXPECT_EQ(read(p), "new");
}

TEST_F(AtomicFileTest, WritesThroughASymlink) {
  fs::create_directories(dir_ / "real");
  const std::string target = path("real/run.log");
  put(target, "old");
  // A relative link to a relative link: both followed from the link's own directory.
  fs::create_symlink("real/run.log", dir_ / "first");
  fs::create_symlink("first", dir_ / "link.log");
  AtomicFile file(path("link.log"));
  EXPECT_EQ(file.target(), path("real/run.log"));
  file.write("new");
  file.commit();
  EXPECT_TRUE(fs::is_symlink(dir_ / "link.log"));
  EXPECT_TRUE(fs::is_symlink(dir_ / "first"));
  EXPECT_EQ(read(target), "new");
  EXPECT_EQ(fs::directory_iterator(dir_ / "real")->path().filename(), "run.log");
}

TEST_F(AtomicFileTest, ADanglingSymlinkCreatesItsTarget) {
  fs::create_symlink("made.log", dir_ / "link.log");
  write_file_atomically(path("link.log"), "text");
  EXPECT_TRUE(fs::is_symlink(dir_ / "link.log"));
  EXPECT_EQ(read(path("made.log")), "text");
}

TEST_F(AtomicFileTest, RefusesDirectoriesDevicesAndLinksToThem) {
  fs::create_directories(dir_ / "d");
  EXPECT_NE(error_of(path("d")).find("is a directory; refusing to replace it"), std::string::npos);
  EXPECT_NE(error_of("/dev/null").find("/dev/null: is a device"), std::string::npos);
  fs::create_symlink("/dev/full", dir_ / "full");
  EXPECT_NE(error_of(path("full")).find("is a device"), std::string::npos);
  ASSERT_EQ(::mkfifo(path("fifo").c_str(), 0600), 0);
  EXPECT_NE(error_of(path("fifo")).find("is a FIFO"), std::string::npos);
  fs::create_symlink("loop2", dir_ / "loop1");
  fs::create_symlink("loop1", dir_ / "loop2");
  EXPECT_NE(error_of(path("loop1")).find("too many levels of symbolic links"), std::string::npos);
  // Nothing was created and nothing replaced.
  EXPECT_TRUE(fs::is_directory(dir_ / "d"));
  EXPECT_TRUE(fs::is_character_file("/dev/full"));
  EXPECT_EQ(names(), (std::vector<std::string>{"d", "fifo", "full", "loop1", "loop2"}));
}

TEST_F(AtomicFileTest, AMissingDirectoryIsReportedAtOpening) {
  const std::string message = error_of(path("no/such/dir/out.csv"));
  EXPECT_NE(message.find(path("no/such/dir/out.csv") + ": cannot open for writing"),
            std::string::npos);
  EXPECT_NE(message.find("No such file or directory"), std::string::npos);
}

using fastslam::testing::FileSizeLimit;

TEST_F(AtomicFileTest, AFailedWriteThrowsWhenItHappensAndLeavesNothing) {
  const std::string p = path("trajectory.csv");
  put(p, "old");
  std::string message;
  std::size_t written = 0;
  {
    const FileSizeLimit limit(100000);
    ASSERT_TRUE(limit.ok());
    AtomicFile file(p);
    const std::string row(1000, 'r');
    try {
      for (; written < 1000; ++written) file.write(row);
    } catch (const std::runtime_error& e) {
      message = e.what();
    }
    // Later calls keep failing rather than pretending.
    EXPECT_THROW(file.commit(), std::runtime_error);
  }
  EXPECT_NE(message.find(p + ": write failed: File too large"), std::string::npos) << message;
  // Reported within a buffer of the limit, not at the end.
  EXPECT_LT(written, 200u);
  EXPECT_EQ(read(p), "old");
  EXPECT_EQ(names(), std::vector<std::string>{"trajectory.csv"});
}

TEST_F(AtomicFileTest, AFailedStreamWriteFailsTheCommit) {
  const std::string p = path("landmarks.csv");
  std::string message;
  {
    const FileSizeLimit limit(100000);
    ASSERT_TRUE(limit.ok());
    AtomicFile file(p);
    for (int i = 0; i < 20000; ++i) file.stream() << "0123456789\n";
    EXPECT_TRUE(file.failed());
    try {
      file.commit();
    } catch (const std::runtime_error& e) {
      message = e.what();
    }
  }
  EXPECT_NE(message.find(p + ": write failed: File too large"), std::string::npos) << message;
  EXPECT_TRUE(names().empty());
}

TEST_F(AtomicFileTest, ResolvesOnlyLinks) {
  EXPECT_EQ(resolve_output_path(path("plain")), path("plain"));
  fs::create_symlink("/tmp/elsewhere", dir_ / "abs");
  EXPECT_EQ(resolve_output_path(path("abs")), "/tmp/elsewhere");
}

}  // namespace
}  // namespace fastslam::tools
