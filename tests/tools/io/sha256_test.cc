#include "tools/io/sha256.h"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

// FIPS 180-4's examples (NIST's "SHA256.pdf" and "SHA2_Additional.pdf"): one block, two blocks,
// the empty message, 896 bits and a million 'a's.
TEST(Sha256, MatchesTheFipsTestVectors) {
  EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256_hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(sha256_hex("abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmnoijklmnopjk"
                       "lmnopqklmnopqrlmnopqrsmnopqrstnopqrstu"),
            "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1");
  EXPECT_EQ(sha256_hex(std::string(1'000'000, 'a')),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

// The padding's edge cases: 55 bytes fit one block with the length, 56 need a second.
TEST(Sha256, PaddingAtTheBlockEdges) {
  EXPECT_EQ(sha256_hex(std::string(55, 'a')),
            "9f4390f8d30c2dd92ec9f095b65e2b9ae9b0a925a5258e241c9f1e910f734318");
  EXPECT_EQ(sha256_hex(std::string(56, 'a')),
            "b35439a4ac6f0948b6d6f9e3c6af0f5f590ce20f1bde7090ef7970686ec6738a");
  EXPECT_EQ(sha256_hex(std::string(64, 'a')),
            "ffe054fe7ae0cb6dc65c3af9b61d5209f439851db43d0ba5997337df154668eb");
}

// Any split of the same bytes over update() calls gives the one-shot digest.
TEST(Sha256, SplitsGiveTheSameDigest) {
  std::mt19937 random(3);
  std::string bytes(300, '\0');
  for (char& c : bytes) c = static_cast<char>(random());
  for (std::size_t n = 0; n <= bytes.size(); n += 7) {
    const std::string_view message(bytes.data(), n);
    const std::string whole = sha256_hex(message);
    for (std::size_t cut : {std::size_t{0}, std::size_t{1}, n / 3, n / 2, n}) {
      if (cut > n) continue;
      Sha256 h;
      h.update(message.substr(0, cut));
      h.update(message.substr(cut, n / 2 > cut ? n / 2 - cut : 0));
      h.update(message.substr(std::max(cut, n / 2)));
      EXPECT_EQ(to_hex(h.finish()), whole) << "n = " << n << ", cut = " << cut;
    }
  }
}

// An empty piece may come as a null pointer (an empty vector's data()), mid-block too.
TEST(Sha256, EmptyPiecesFromNullPointersChangeNothing) {
  Sha256 h;
  h.update("abc", 3);
  h.update(nullptr, 0);
  EXPECT_EQ(to_hex(h.finish()), sha256_hex("abc"));
}

// A file over two 1 MiB chunks, not a multiple of the block size, read in pieces.
TEST(Sha256, FileDigestEqualsTheBytesDigest) {
  const std::string path = testing::temp_path("sha256_file");
  std::string bytes((std::size_t{5} << 19) + 13, '\0');
  std::mt19937_64 random(11);
  for (char& c : bytes) c = static_cast<char>(random());
  std::ofstream(path, std::ios::binary) << bytes;
  EXPECT_EQ(sha256_file(path), sha256_hex(bytes));
  std::filesystem::remove(path);
}

TEST(Sha256, AMissingFileIsAnErrorNamingIt) {
  const std::string path = testing::temp_path("sha256_missing");
  try {
    sha256_file(path);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path + ": cannot open for hashing"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace fastslam::tools
