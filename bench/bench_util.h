// What the benchmarks share: a stopwatch, running a command (the reference implementations, the
// motionpipe binary) for its output, exiting with its output when it fails, and writing arrays.
#pragma once

#include <dlfcn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "motionpipe/base/cpu_kernels.h"
#include "motionpipe/formats/npy.h"

namespace motionpipe::bench {

using Clock = std::chrono::steady_clock;

inline double Since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Examples per second of `step` (one training step of `batch` examples) over `steps` calls, after
// two calls that warm the allocator and the kernels up.
template <typename Step>
double ExamplesPerSecond(Step&& step, int64_t steps, int64_t batch) {
  for (int k = 0; k < 2; ++k) step();
  const auto started = Clock::now();
  for (int64_t k = 0; k < steps; ++k) step();
  return static_cast<double>(steps * batch) / Since(started);
}

// For a benchmark linked with LibTorch, whose OpenBLAS chose its kernels before main: when that
// choice is generic on a CPU with AVX2 or AVX-512 (motionpipe/base/cpu_kernels.h) and the user set
// no OPENBLAS_CORETYPE, runs this program again with the one the worker would ask for, so that the
// figures are those of the kernels the pipeline uses (the references it starts inherit it). Returns
// OpenBLAS's kernels, for the header of a table (nn::AtenCapabilityInUse says LibTorch's own).
inline std::string UseNativeBlasKernels(char** argv) {
  const std::string core = OpenBlasCoreName(RTLD_DEFAULT);
  const std::string in_use = core.empty() ? "none" : core;
  const char* set = std::getenv("OPENBLAS_CORETYPE");
  if (set && *set) return in_use;
  if (core.empty()) return in_use;  // no OpenBLAS behind LibTorch here
  const std::string ask = BlasKernelsToAsk(core, DetectCpuVectorUnits());
  if (ask.empty()) return in_use;
  std::fprintf(stderr,
               "OpenBLAS chose its generic %s kernels: running again with OPENBLAS_CORETYPE=%s\n",
               core.c_str(), ask.c_str());
  ::setenv("OPENBLAS_CORETYPE", ask.c_str(), 1);
  ::execv("/proc/self/exe", argv);
  return in_use;  // exec failed: keep going with the kernels at hand
}

// Starts `args` (args[0] a path) as a child process; its pid (the child exits 127 if exec fails).
inline pid_t Spawn(const std::vector<std::string>& args) {
  const pid_t pid = ::fork();
  if (pid != 0) return pid;
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  ::execv(args[0].c_str(), argv.data());
  std::_Exit(127);
}

inline std::string Run(const std::string& command) {
  std::string output;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return output;
  char buffer[4096];
  while (size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) output.append(buffer, n);
  const int status = ::pclose(pipe);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::fprintf(stderr, "command failed: %s\n%s\n", command.c_str(), output.c_str());
    std::exit(1);
  }
  return output;
}

// Writes an array for a reference implementation to read, exiting with the reason on failure.
inline void SaveNpy(const std::string& path, const NpyArray& array) {
  if (Status s = WriteNpy(path, array); !s.ok()) {
    std::fprintf(stderr, "%s\n", s.message().c_str());
    std::exit(1);
  }
}

}  // namespace motionpipe::bench
