#include "motionpipe/base/cpu_kernels.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <string>

namespace motionpipe {
namespace {

TEST(BlasKernels, AGenericChoiceOnAVectorCpuAsksForItsKernels) {
  const CpuVectorUnits avx512{true, true}, avx2{true, false}, sse{false, false};
  // OpenBLAS 0.3.21 on an Intel Xeon of family 6, model 207 (not in its tables) chose Prescott.
  EXPECT_EQ(BlasKernelsToAsk("Prescott", avx512), "SkylakeX");
  EXPECT_EQ(BlasKernelsToAsk("Prescott", avx2), "Haswell");
  EXPECT_EQ(BlasKernelsToAsk("Nehalem", avx2), "Haswell");
  EXPECT_EQ(BlasKernelsToAsk("Sandybridge", avx512), "SkylakeX");
  EXPECT_EQ(BlasKernelsToAsk("", avx512), "SkylakeX");
  // A CPU without AVX2 keeps whatever OpenBLAS chose.
  EXPECT_EQ(BlasKernelsToAsk("Prescott", sse), "");
}

TEST(BlasKernels, TheLibrarysOwnVectorChoiceStands) {
  const CpuVectorUnits avx512{true, true};
  // Zen 4 and 5 get Zen or SkylakeX/Cooperlake from OpenBLAS itself: nothing is changed there.
  for (const char* core :
       {"Haswell", "Zen", "SkylakeX", "Cooperlake", "SapphireRapids", "skylakex"})
    EXPECT_EQ(BlasKernelsToAsk(core, avx512), "") << core;
}

// On this machine, in this process (ctest runs each test alone, with no LibTorch loaded): after the
// probe, the OpenBLAS a plugin would load runs AVX2 or AVX-512 kernels wherever the CPU has them.
TEST(BlasKernels, AfterTheProbeOpenBlasLoadsWithVectorKernels) {
  if (const char* set = std::getenv("OPENBLAS_CORETYPE"); set && *set)
    GTEST_SKIP() << "OPENBLAS_CORETYPE is set by the caller: " << set;
  if (void* loaded = ::dlopen(kOpenBlasLibrary, RTLD_LAZY | RTLD_NOLOAD)) {
    ::dlclose(loaded);
    GTEST_SKIP() << "OpenBLAS is already loaded in this process";
  }
  const BlasKernelChoice choice = PreferNativeBlasKernels();
  if (!choice.note.empty()) GTEST_SKIP() << choice.note;
  void* blas = ::dlopen(kOpenBlasLibrary, RTLD_LAZY | RTLD_LOCAL);
  ASSERT_NE(blas, nullptr);
  const std::string core = OpenBlasCoreName(blas);
  ASSERT_FALSE(core.empty());
  ::dlclose(blas);
  EXPECT_EQ(BlasKernelsToAsk(core, DetectCpuVectorUnits()), "")
      << "OpenBLAS runs its " << core << " kernels (it chose " << choice.detected << ", asked '"
      << choice.asked << "')";
  if (!choice.asked.empty()) {
    EXPECT_STRCASEEQ(core.c_str(), choice.asked.c_str());
  }
  // Asked once per process: a second call reports the same choice.
  EXPECT_EQ(PreferNativeBlasKernels().asked, choice.asked);
}

// The CPUID reading against the kernel's own: the flags /proc/cpuinfo lists for the first CPU
// (which Linux shows only where the OS saves the registers they need).
TEST(CpuVectorUnits, AgreeWithTheFlagsLinuxReports) {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpuinfo, line) && line.rfind("flags", 0) != 0) {
  }
  if (line.rfind("flags", 0) != 0) GTEST_SKIP() << "no flags line in /proc/cpuinfo";
  std::set<std::string> flags;
  std::istringstream words(line.substr(line.find(':') + 1));
  for (std::string w; words >> w;) flags.insert(w);
  const auto has = [&](std::initializer_list<const char*> names) {
    for (const char* name : names)
      if (!flags.count(name)) return false;
    return true;
  };
  const CpuVectorUnits units = DetectCpuVectorUnits();
  EXPECT_EQ(units.avx2_fma, has({"avx2", "fma"}));
  EXPECT_EQ(units.avx512,
            has({"avx2", "fma", "avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"}));
  EXPECT_EQ(units.avx512_bf16, has({"avx512f", "avx512_bf16"}));
  EXPECT_EQ(units.amx_bf16, has({"amx_bf16"}));
}

}  // namespace
}  // namespace motionpipe
