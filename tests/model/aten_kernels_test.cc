// LibTorch's own kernels, as the plugin host asks for them (motionpipe/base/cpu_kernels.h). ctest
// runs each test in a process of its own, so nothing has dispatched a LibTorch operation before it.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "../../plugins/common/threads.h"
#include "motionpipe/base/cpu_kernels.h"

namespace motionpipe::nn {
namespace {

// Asked inside the process before the first operation (as the host asks before the first plugin
// loads, and the benchmarks at the top of main), the capability is what LibTorch then runs.
TEST(AtenKernels, AskedBeforeTheFirstOperationLibTorchRunsThem) {
  const char* caller = std::getenv("ATEN_CPU_CAPABILITY");
  if (caller && *caller) GTEST_SKIP() << "ATEN_CPU_CAPABILITY is set by the caller: " << caller;
  const std::string asked = PreferNativeAtenKernels();
  const torch::Tensor x = torch::randn({64, 64});
  const torch::Tensor y = torch::layer_norm(x, {64}).sum();
  EXPECT_TRUE(std::isfinite(y.item<float>()));
  const std::string in_use = AtenCapabilityInUse();
  ASSERT_FALSE(in_use.empty()) << at::show_config();
  if (DetectCpuVectorUnits().avx512) {
    EXPECT_EQ(asked, "avx512");
    EXPECT_EQ(in_use, "AVX512");
  } else {
    EXPECT_EQ(asked, "");
    EXPECT_NE(in_use, "AVX512");
  }
}

}  // namespace
}  // namespace motionpipe::nn
