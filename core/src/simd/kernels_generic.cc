// The SIMD kernels for any x86-64 (or other) CPU.
#include <cstdint>

#include "kernels.h"

namespace motionpipe::simd::generic {
#include "kernels.inc"
}  // namespace motionpipe::simd::generic
