#include "motionpipe/motion/compare.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace motionpipe {

MotionDifference CompareMotions(const Skeleton& skeleton, const Motion& a, const Motion& b) {
  MotionDifference diff;
  if (a.num_frames() != b.num_frames()) {
    const double inf = std::numeric_limits<double>::infinity();
    return {inf, inf, inf, inf};
  }
  for (int64_t frame = 0; frame < a.num_frames(); ++frame) {
    for (int joint = 0; joint < kNumJoints; ++joint) {
      diff.max_rotation = std::max(diff.max_rotation, MaxAbsDiff(a.LocalRotation(frame, joint),
                                                                 b.LocalRotation(frame, joint)));
    }
    diff.max_translation =
        std::max(diff.max_translation, Norm(a.Translation(frame) - b.Translation(frame)));
  }
  const std::vector<float> ja = ComputeJoints(skeleton, a), jb = ComputeJoints(skeleton, b);
  double sum = 0;
  for (size_t k = 0; k < ja.size(); k += 3) {
    const double d = std::sqrt((ja[k] - jb[k]) * (ja[k] - jb[k]) +
                               (ja[k + 1] - jb[k + 1]) * (ja[k + 1] - jb[k + 1]) +
                               (ja[k + 2] - jb[k + 2]) * (ja[k + 2] - jb[k + 2]));
    diff.max_joint = std::max(diff.max_joint, d);
    sum += d;
  }
  if (!ja.empty()) diff.mean_joint = sum / static_cast<double>(ja.size() / 3);
  return diff;
}

}  // namespace motionpipe
