// Every unit-test process gets its own temporary directory: ctest runs the tests of this binary as
// separate processes in parallel, and fixtures that write fixed names under ::testing::TempDir()
// (a corpus, npz files) would otherwise race. googletest reads TEST_TMPDIR on each TempDir() call.
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace {

std::string& Dir() {
  static std::string dir;
  return dir;
}

void RemoveDir() {
  std::error_code ec;
  std::filesystem::remove_all(Dir(), ec);
}

const bool kIsolated = [] {
  const char* base = std::getenv("TMPDIR");
  Dir() =
      std::string(base && *base ? base : "/tmp") + "/motionpipe-unit-" + std::to_string(::getpid());
  std::filesystem::create_directories(Dir());
  ::setenv("TEST_TMPDIR", Dir().c_str(), 1);
  std::atexit(RemoveDir);
  return true;
}();

}  // namespace
