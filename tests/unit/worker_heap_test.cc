// worker::UseMainHeapOnly: a thread started after it allocates from glibc's main heap, not from an
// arena of its own (whose heaps glibc unmaps and maps again between a model's training steps).
// Arenas are a process's state, so each case runs in a fresh copy of this binary.
#include <gtest/gtest.h>
#include <malloc.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "worker.h"

namespace motionpipe::worker {
namespace {

constexpr const char* kRole = "MOTIONPIPE_HEAP_TEST_ROLE";
// In the child: glibc's arenas once a new thread has allocated 4 MiB in small blocks and freed them
// (malloc_info lists each arena as a <heap nr=...>; arenas outlive their threads).
int ArenasAfterANewThreadAllocated() {
  std::thread thread([] {
    std::vector<void*> blocks;
    for (int i = 0; i < 1024; ++i) {
      blocks.push_back(std::malloc(4096));
      std::memset(blocks.back(), 1, 4096);
    }
    for (void* block : blocks) std::free(block);
  });
  thread.join();
  char* text = nullptr;
  size_t size = 0;
  FILE* out = open_memstream(&text, &size);
  if (out == nullptr || malloc_info(0, out) != 0) return -1;
  std::fclose(out);
  int arenas = 0;
  for (const char* at = text; (at = std::strstr(at, "<heap nr=")) != nullptr; ++at) ++arenas;
  std::free(text);
  return arenas;
}

// Runs this test alone in a fresh process with `role`; its exit status (0: its checks held).
int RunChild(const std::string& role) {
  std::array<char, 4096> exe{};
  if (readlink("/proc/self/exe", exe.data(), exe.size() - 1) <= 0) return -1;
  const ::testing::TestInfo* test = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::string filter =
      std::string("--gtest_filter=") + test->test_suite_name() + "." + test->name();
  const std::string role_variable = std::string(kRole) + "=" + role;
  std::vector<char*> environment;  // made before fork: the child only execs
  for (char** variable = environ; *variable != nullptr; ++variable)
    environment.push_back(*variable);
  environment.push_back(const_cast<char*>(role_variable.c_str()));
  environment.push_back(nullptr);
  char* argv[] = {exe.data(), const_cast<char*>(filter.c_str()), nullptr};
  const pid_t pid = fork();
  if (pid == 0) {
    execve(exe.data(), argv, environment.data());
    _exit(127);
  }
  int status = 0;
  if (pid < 0 || waitpid(pid, &status, 0) != pid) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(WorkerHeap, ThreadsStartedAfterUseMainHeapOnlyAllocateFromTheMainHeap) {
  const char* role = std::getenv(kRole);
  if (role == nullptr) {
    EXPECT_EQ(RunChild("one_heap"), 0) << "with UseMainHeapOnly, a new thread's blocks must be in "
                                          "the main heap (the child prints its arenas)";
    EXPECT_EQ(RunChild("default"), 0) << "without it, glibc must give the thread its own arena "
                                         "(else this test could not tell the two apart)";
    EXPECT_EQ(RunChild("environment"), 0) << "MALLOC_ARENA_MAX in the environment must win";
    return;
  }
  const std::string which = role;
  if (which == "one_heap") {
    ASSERT_TRUE(UseMainHeapOnly());
  }
  if (which == "environment") {
    ASSERT_EQ(setenv("MALLOC_ARENA_MAX", "8", 1), 0);
    ASSERT_FALSE(UseMainHeapOnly());
  }
  const int arenas = ArenasAfterANewThreadAllocated();
  std::printf("%s: %d arena(s)\n", role, arenas);
  EXPECT_EQ(arenas, which == "one_heap" ? 1 : 2);
}

}  // namespace
}  // namespace motionpipe::worker
