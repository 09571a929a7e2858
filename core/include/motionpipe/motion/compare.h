// Differences between two motions of equal length: what round-trip tests and the demo report.
#pragma once

#include <vector>

#include "motionpipe/motion/motion.h"

namespace motionpipe {

struct MotionDifference {
  double max_rotation = 0;     // largest |R_a - R_b| entry over frames and joints (local rotations)
  double max_translation = 0;  // metres
  double max_joint = 0;        // metres, largest joint position distance (forward kinematics)
  double mean_joint = 0;       // metres
};

// Both motions must have the same frame count (else every field is +inf).
MotionDifference CompareMotions(const Skeleton& skeleton, const Motion& a, const Motion& b);

}  // namespace motionpipe
