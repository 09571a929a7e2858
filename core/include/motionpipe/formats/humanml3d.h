// HumanML3D joint files (new_joints/*.npy): float [T, 22, 3], y-up, metres, 20 fps. Used as an
// input to the metrics (positions only; no rotations can be recovered exactly from them).
#pragma once

#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe {

struct JointSequence {
  double fps = 20;
  int64_t frames = 0;
  std::vector<float> joints;  // [T, 22, 3], z-up (converted), metres
};

// Reads the file and converts y-up to our z-up world ((x, y, z) -> (x, -z, y)).
Result<JointSequence> ReadHumanML3DJoints(const std::string& path, double fps = 20);

}  // namespace motionpipe
