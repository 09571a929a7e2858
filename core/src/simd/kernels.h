// Declarations of the two builds of kernels.inc; simd.cc dispatches on the CPU.
#pragma once

#include <cstdint>

namespace motionpipe::simd {

// Per-frame layout of the similarity filter's branch vectors (see similarity.h).
inline constexpr int kRotDims = 126;
inline constexpr int kLocDims = 66;
inline constexpr int kLocOffset = 128;
inline constexpr int kFrameStride = 200;

#define MOTIONPIPE_SIMD_KERNELS                                                                  \
  void RawSimilarityKernel(const float* source, int64_t source_frames, const float* target,      \
                           int64_t target_frames, int window, double* raw_rot, double* raw_loc); \
  void AxisAngleToMatrices(const float* ax, const float* ay, const float* az, int64_t n,         \
                           float* out, int64_t plane_stride, int rows);                          \
  void ForwardKinematicsPlanes(const float* local, int64_t frames, const int* parents,           \
                               const float* offsets, float* global, float* positions);           \
  bool AllFinite(const float* values, int64_t n);                                                \
  void Transpose(const float* src, int64_t src_stride, int64_t rows, int64_t cols, float* dst,   \
                 int64_t dst_stride);

namespace avx2 {
MOTIONPIPE_SIMD_KERNELS
}
namespace generic {
MOTIONPIPE_SIMD_KERNELS
}
#undef MOTIONPIPE_SIMD_KERNELS

}  // namespace motionpipe::simd
