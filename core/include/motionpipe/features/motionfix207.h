// The 207-d per-frame editing feature of MotionFix / TMED / SimMotionEdit (REFERENCE.md section 2):
//   0:3     pelvis translation velocity in the previous frame's pelvis frame, R_{i-1}^T (t_i -
//   t_{i-1}) 3:9     global orientation with its heading removed, 6D 9:15    heading change
//   Rz_{i-1}^T Rz_i, 6D (identity at frame 0) 15:141  the 21 local joint rotations (joints 1..21),
//   6D 141:207 the 22 joint positions relative to the pelvis, heading removed
// The feature is relative: decoding needs the first frame's heading and translation (MotionAnchor).
#pragma once

#include <array>
#include <string>

#include "motionpipe/features/anchor.h"
#include "motionpipe/features/feature_matrix.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

constexpr int kMotionFixFeatureDim = 207;

struct FeatureGroup {
  const char* name;  // the reference implementation's name for the slice
  int begin;
  int end;
};
// The five slices above, in order; names match data/stats/motionfix_feature_stats.json.
const std::array<FeatureGroup, 5>& MotionFixFeatureGroups();

// Encodes a motion. Joint positions come from forward kinematics on `skeleton`.
FeatureMatrix EncodeMotionFix207(const Skeleton& skeleton, const Motion& motion);
// Encodes with caller-supplied joint positions [T, 22, 3] (e.g. MotionFix's stored SMPL joints).
FeatureMatrix EncodeMotionFix207WithJoints(const Motion& motion, const float* joints);

// Exact inverse of the encoders (up to float rounding) given the anchor of the original motion.
// Columns 141:207 are derived data and are not read.
Motion DecodeMotionFix207(const FeatureMatrix& features, const MotionAnchor& anchor, double fps);

}  // namespace motionpipe
