// Replays a libFuzzer target's corpus files in ordinary builds: every seed and every regression
// input (tests/data/fuzz/<target>/) runs through LLVMFuzzerTestOneInput on each CI run, under the
// dev preset's ASan + UBSan too, without needing clang's libFuzzer.
// Usage: replay_<target> DIR_OR_FILE...   (exit 0 when every input ran to completion)
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace fs = std::filesystem;

namespace {
int run_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
  return 1;
}
}  // namespace

int main(int argc, char** argv) {
  int n = 0;
  for (int i = 1; i < argc; ++i) {
    const fs::path p(argv[i]);
    if (fs::is_directory(p)) {
      for (const auto& e : fs::directory_iterator(p)) {
        if (e.is_regular_file()) n += run_file(e.path());
      }
    } else if (fs::is_regular_file(p)) {
      n += run_file(p);
    } else {
      std::fprintf(stderr, "replay: no such file or directory: %s\n", argv[i]);
      return 2;
    }
  }
  if (n == 0) {
    std::fprintf(stderr, "replay: no inputs found\n");
    return 2;
  }
  std::printf("replay: %d inputs ran to completion\n", n);
  return 0;
}
