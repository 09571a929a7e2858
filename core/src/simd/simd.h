// Vectorised building blocks shared by the similarity filter and the SINC featuriser, dispatched to
// the AVX2/FMA build of kernels.inc when the CPU has it, else to the baseline build.
#pragma once

#include <cstdint>
#include <vector>

#include "kernels.h"

namespace motionpipe::simd {

bool HasAvx2();

// Eq. (4) of SimMotionEdit for both branches (see similarity.h for the frame layout).
void RawSimilarity(const float* source, int64_t source_frames, const float* target,
                   int64_t target_frames, int window, double* raw_rot, double* raw_loc);
// Rodrigues on planes: out[k * plane_stride + r] = element k of rotation r, rows 2 (6D) or 3.
void AxisAngleToMatrices(const float* ax, const float* ay, const float* az, int64_t n, float* out,
                         int64_t plane_stride, int rows = 3);
// Forward kinematics along time on joint-major planes (kernels.inc).
void ForwardKinematics(const float* local, int64_t frames, const int* parents, const float* offsets,
                       float* global, float* positions);
// dst[c * dst_stride + r] = src[r * src_stride + c].
void Transpose(const float* src, int64_t src_stride, int64_t rows, int64_t cols, float* dst,
               int64_t dst_stride);
bool AllFinite(const float* values, int64_t n);

// The SMPL-22 template skeleton as the FK kernel wants it (parents with the root's as 0).
struct SkeletonArrays {
  int parents[22];
  float offsets[3 * 22];
};
const SkeletonArrays& TemplateSkeleton();

// World joint positions of a motion as planes: out[(3 j + a) * frames + f], computed with the
// kernels above. `scratch` is resized as needed.
void JointPlanes(const float* poses, const float* trans, int64_t frames,
                 std::vector<float>* scratch, float* out);

}  // namespace motionpipe::simd
