#include "kinematics.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

namespace motionpipe::nn {

namespace {

// The axis along which the kept vectors lie side by side in the matrix: rows stack along -2 (the
// matrix's first index), columns along -1.
int64_t StackAxis(SixDAxes axes) { return axes == SixDAxes::kRows ? -2 : -1; }

}  // namespace

torch::Tensor MatrixToSixD(const torch::Tensor& r, SixDAxes axes) {
  const int64_t axis = StackAxis(axes);
  return torch::cat({r.select(axis, 0), r.select(axis, 1)}, -1);
}

torch::Tensor SixDToMatrix(const torch::Tensor& six, SixDAxes axes) {
  const auto a = six.narrow(-1, 0, 3), b = six.narrow(-1, 3, 3);
  const auto e1 = a / a.norm(2, -1, true).clamp_min(1e-8);
  const auto orthogonal = b - (e1 * b).sum(-1, true) * e1;
  const auto e2 = orthogonal / orthogonal.norm(2, -1, true).clamp_min(1e-8);
  return torch::stack({e1, e2, torch::cross(e1, e2, -1)}, StackAxis(axes));
}

std::array<std::array<int, 4>, 2> LegChains(const Skeleton& skeleton) {
  std::array<std::array<int, 4>, 2> legs{};
  const std::array<const std::array<int, 2>*, 2> feet = {&skeleton.left_foot_joints(),
                                                         &skeleton.right_foot_joints()};
  for (size_t side = 0; side < 2; ++side) {
    const std::array<int, 2>& joints = *feet[side];
    bool found = false;
    for (const std::vector<int>& chain : skeleton.kinematic_chains()) {
      if (chain.empty() || chain.front() != 0) continue;
      const auto depth = [&](int joint) {
        return std::find(chain.begin(), chain.end(), joint) - chain.begin();
      };
      // root, hip, knee, then the side's two foot joints (ankle and toe, in either order)
      const auto a = depth(joints[0]), b = depth(joints[1]);
      if (std::min(a, b) != 3 || std::max(a, b) != 4) continue;
      std::copy(chain.begin() + 1, chain.begin() + 5, legs[side].begin());
      found = true;
      break;
    }
    if (!found)
      throw std::invalid_argument(
          "skeleton: no kinematic chain from the root through hip and knee to "
          "the foot joints " +
          std::to_string(joints[0]) + " and " + std::to_string(joints[1]));
  }
  return legs;
}

}  // namespace motionpipe::nn
