#include "simd.h"

#include <algorithm>

#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::simd {

bool HasAvx2() {
#if defined(__x86_64__) || defined(__i386__)
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
#else
  return false;
#endif
}

void RawSimilarity(const float* source, int64_t source_frames, const float* target,
                   int64_t target_frames, int window, double* raw_rot, double* raw_loc) {
  if (HasAvx2()) {
    avx2::RawSimilarityKernel(source, source_frames, target, target_frames, window, raw_rot,
                              raw_loc);
  } else {
    generic::RawSimilarityKernel(source, source_frames, target, target_frames, window, raw_rot,
                                 raw_loc);
  }
}

void AxisAngleToMatrices(const float* ax, const float* ay, const float* az, int64_t n, float* out,
                         int64_t plane_stride, int rows) {
  if (HasAvx2()) {
    avx2::AxisAngleToMatrices(ax, ay, az, n, out, plane_stride, rows);
  } else {
    generic::AxisAngleToMatrices(ax, ay, az, n, out, plane_stride, rows);
  }
}

void ForwardKinematics(const float* local, int64_t frames, const int* parents, const float* offsets,
                       float* global, float* positions) {
  if (HasAvx2()) {
    avx2::ForwardKinematicsPlanes(local, frames, parents, offsets, global, positions);
  } else {
    generic::ForwardKinematicsPlanes(local, frames, parents, offsets, global, positions);
  }
}

void Transpose(const float* src, int64_t src_stride, int64_t rows, int64_t cols, float* dst,
               int64_t dst_stride) {
  if (HasAvx2()) {
    avx2::Transpose(src, src_stride, rows, cols, dst, dst_stride);
  } else {
    generic::Transpose(src, src_stride, rows, cols, dst, dst_stride);
  }
}

const SkeletonArrays& TemplateSkeleton() {
  static const SkeletonArrays arrays = [] {
    SkeletonArrays a{};
    const Skeleton& skeleton = Skeleton::Smpl22();
    for (int j = 0; j < kNumJoints; ++j) {
      a.parents[j] = std::max(0, skeleton.parents()[static_cast<size_t>(j)]);
      const Vec3& o = skeleton.rest_offsets()[static_cast<size_t>(j)];
      a.offsets[3 * j] = static_cast<float>(o.x);
      a.offsets[3 * j + 1] = static_cast<float>(o.y);
      a.offsets[3 * j + 2] = static_cast<float>(o.z);
    }
    return a;
  }();
  return arrays;
}

void JointPlanes(const float* poses, const float* trans, int64_t frames,
                 std::vector<float>* scratch, float* out) {
  const int64_t n = frames * kNumJoints;
  scratch->resize(static_cast<size_t>(n * (3 + 9 + 9)));
  float* axis = scratch->data();
  float* local = axis + 3 * n;
  float* global = local + 9 * n;
  Transpose(poses, 3 * kNumJoints, frames, 3 * kNumJoints, axis, frames);
  for (int j = 0; j < kNumJoints; ++j) {
    const float* a = axis + 3 * j * frames;
    AxisAngleToMatrices(a, a + frames, a + 2 * frames, frames, local + j * frames, n, 3);
  }
  const SkeletonArrays& skeleton = TemplateSkeleton();
  ForwardKinematics(local, frames, skeleton.parents, skeleton.offsets, global, out);
  for (int j = 0; j < kNumJoints; ++j) {
    for (int a = 0; a < 3; ++a) {
      float* plane = out + (3 * j + a) * frames;
      for (int64_t f = 0; f < frames; ++f) plane[f] += trans[3 * f + a];
    }
  }
}

bool AllFinite(const float* values, int64_t n) {
  return HasAvx2() ? avx2::AllFinite(values, n) : generic::AllFinite(values, n);
}

}  // namespace motionpipe::simd
