// Rotation and skeleton helpers in Torch that more than one model plugin needs: the 6D rotation
// representation (Zhou et al. 2019, "On the continuity of rotation representations") both ways,
// and the legs' joint chains as the skeleton states them.
#pragma once

#include <torch/torch.h>

#include <array>

#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::nn {

// Which two vectors of a rotation matrix a 6D representation keeps. The MotionFix features (core's
// Rot6dToMatrix, REFERENCE.md) keep its first two rows; the PyTorch reference's rotation_6d, which
// tools/leg_denoise.py and the leg_cleanup plugin were trained with, its first two columns.
enum class SixDAxes { kRows, kColumns };

// [..., 6] of rotation matrices [..., 3, 3].
torch::Tensor MatrixToSixD(const torch::Tensor& r, SixDAxes axes);
// Rotation matrices [..., 3, 3] of [..., 6], by Gram-Schmidt on the two vectors (the second made
// orthogonal to the first, the third their cross product).
torch::Tensor SixDToMatrix(const torch::Tensor& six, SixDAxes axes);

// The hip, knee, ankle and foot joint of the left leg, then of the right: the skeleton's kinematic
// chains from the root whose third and fourth joints after it are each side's two foot joints (in
// either order in the skeleton file). std::invalid_argument if the skeleton has no such chain.
std::array<std::array<int, 4>, 2> LegChains(const Skeleton& skeleton);

}  // namespace motionpipe::nn
