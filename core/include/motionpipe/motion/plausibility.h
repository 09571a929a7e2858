// Physical plausibility of a motion from its joint positions (and, when given, its local
// rotations): what the corpus checks on every clip, the synth stage uses to drop bad compositions,
// and the evaluation stage reports in place of a pretrained MotionCritic (none is available
// offline).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe {

struct PlausibilityOptions {
  double floor = 0;              // z of the floor (joint level) in metres
  double contact_height = 0.05;  // a foot joint below floor + this is in contact
  double skate_speed = 0.15;     // m/s: a contact foot moving faster than this is skating
  double float_height = 0.05;    // a frame whose lowest joint is above floor + this floats
};

struct PlausibilityReport {
  int64_t frames = 0;
  double foot_skate_mean = 0;  // m/s: mean horizontal speed of foot joints in contact (both frames)
  double foot_skate_ratio = 0;  // fraction of contact foot-frames faster than skate_speed
  // The field's skating ratio (GMD, Karunratanakul et al. 2023, as OmniControl and later text-to-
  // motion papers report it): the motion resampled to 20 fps, the fraction of frame pairs in which
  // either toe joint is below 5 cm in both frames and moves faster than 0.5 m/s both in that pair
  // and averaged over a centred window of 5 pairs. Far laxer than foot_skate_ratio (0.15 m/s).
  double skating_ratio_gmd = 0;
  double penetration_max = 0;    // m: deepest any joint goes below the floor (>= 0)
  double penetration_mean = 0;   // m: mean over frames of the deepest penetration
  double float_ratio = 0;        // fraction of frames with every joint above floor + float_height
  double jerk_mean = 0;          // m/s^3: mean magnitude of the third derivative of joint positions
  double max_joint_step = 0;     // m: largest displacement of any joint between two frames
  double bone_length_error = 0;  // m: largest deviation of a bone length from the skeleton's
  int64_t joint_limit_violations = 0;  // joint-frames outside anatomical ranges (needs rotations)
  std::string worst_joint_limit;       // "left_knee hyperextended at frame 12" (empty if none)
};

// `joints` is [frames, 22, 3]; `local` (optional, [frames * 22]) enables the joint-limit check.
PlausibilityReport EvaluatePlausibility(const Skeleton& skeleton, const float* joints,
                                        int64_t frames, double fps, const std::vector<Mat3>* local,
                                        const PlausibilityOptions& options = {});
PlausibilityReport EvaluateMotionPlausibility(const Skeleton& skeleton, const Motion& motion,
                                              const PlausibilityOptions& options = {});

// Anatomical range check of one joint's local rotation; returns an empty string when plausible,
// else what is wrong ("hyperextended", "rotated 170 deg (limit 165)").
std::string CheckJointLimit(const Skeleton& skeleton, int joint, const Mat3& local);

}  // namespace motionpipe
