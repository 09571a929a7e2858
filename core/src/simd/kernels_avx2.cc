// The SIMD kernels compiled for AVX2 + FMA (selected at run time when the CPU has them).
#include <cstdint>

#include "kernels.h"

namespace motionpipe::simd::avx2 {
#include "kernels.inc"
}  // namespace motionpipe::simd::avx2
