// Declarations of the two builds of kernels.inc; similarity.cc dispatches on the CPU.
#pragma once

#include <cstdint>

#include "motionpipe/similarity/similarity.h"

namespace motionpipe::similarity {

#define MOTIONPIPE_SIMILARITY_KERNELS                                                                            \
  void RawSimilarityKernel(const float* source, int64_t source_frames, const float* target, int64_t target_frames, \
                           int window, double* raw_rot, double* raw_loc);                                         \
  void AxisAngleToMatrices(const float* ax, const float* ay, const float* az, int64_t n, float* out,                \
                           int64_t plane_stride);                                                                 \
  void ForwardKinematicsPlanes(const float* local, int64_t frames, const int* parents, const float* offsets,        \
                               float* global, float* positions);                                                  \
  bool AllFinite(const float* values, int64_t n);                                                                  \
  void Transpose(const float* src, int64_t src_stride, int64_t rows, int64_t cols, float* dst, int64_t dst_stride);

namespace avx2 {
MOTIONPIPE_SIMILARITY_KERNELS
}
namespace generic {
MOTIONPIPE_SIMILARITY_KERNELS
}
#undef MOTIONPIPE_SIMILARITY_KERNELS

}  // namespace motionpipe::similarity
