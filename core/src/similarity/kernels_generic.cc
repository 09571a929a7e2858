// The similarity kernels for any x86-64 (or other) CPU.
#include <cstdint>

#include "kernels.h"

namespace motionpipe::similarity::generic {
#include "kernels.inc"
}  // namespace motionpipe::similarity::generic
