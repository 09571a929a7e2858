// The similarity kernels compiled for AVX2 + FMA (selected at run time when the CPU has them).
#include <cstdint>

#include "kernels.h"

namespace motionpipe::similarity::avx2 {
#include "kernels.inc"
}  // namespace motionpipe::similarity::avx2
