// Replays files through a fuzz target without libFuzzer: the ordinary build (release, and the
// sanitizer presets) links each target with this main and runs it over the target's seed corpus
// and its regressions (fuzz/regressions/<target>/), so every input a fuzzer ever crashed on is
// checked on every test run, not only when the fuzz preset runs.
// usage: <target>_replay DIR_OR_FILE...; exits non-zero (or aborts, as the target does on a
// failed check) when an input fails, and prints how many inputs ran.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

int replay(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "%s: cannot be read\n", file.c_str());
    return 1;
  }
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                std::istreambuf_iterator<char>());
  return LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()),
                                bytes.size());
}

}  // namespace

int main(int argc, char** argv) {
  std::size_t inputs = 0;
  for (int i = 1; i < argc; ++i) {
    const std::filesystem::path path(argv[i]);
    std::vector<std::filesystem::path> files;
    if (std::filesystem::is_directory(path)) {
      for (const auto& entry : std::filesystem::directory_iterator(path)) {
        if (entry.is_regular_file() && entry.path().filename() != "README.md") {
          files.push_back(entry.path());
        }
      }
    } else {
      files.push_back(path);
    }
    for (const std::filesystem::path& file : files) {
      if (replay(file) != 0) {
        std::fprintf(stderr, "%s: the target returned non-zero\n", file.c_str());
        return 1;
      }
      ++inputs;
    }
  }
  if (inputs == 0) {
    std::fprintf(stderr, "no input found\n");
    return 1;
  }
  std::printf("%zu inputs replayed, no failure\n", inputs);
  return 0;
}
