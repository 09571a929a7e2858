#include "motionpipe/base/cpu_kernels.h"

#include <dlfcn.h>
#include <gtest/gtest.h>

#include <cstdlib>
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

TEST(CpuVectorUnits, Avx512ImpliesAvx2AndBf16ProductsImplyAvx512) {
  const CpuVectorUnits units = DetectCpuVectorUnits();
  if (units.avx512) {
    EXPECT_TRUE(units.avx2_fma);
  }
  if (units.avx512_bf16) {
    EXPECT_TRUE(units.avx512);
  }
}

}  // namespace
}  // namespace motionpipe
