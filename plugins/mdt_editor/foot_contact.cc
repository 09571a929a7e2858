#include "foot_contact.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "../common/kinematics.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::mdt {

namespace {

// Matrix products over the last two dimensions, written elementwise (see FootDisplacements).
torch::Tensor MatMat(const torch::Tensor& a, const torch::Tensor& b) {
  return (a.unsqueeze(-1) * b.unsqueeze(-3)).sum(-2);
}
torch::Tensor MatVec(const torch::Tensor& a, const torch::Tensor& v) {
  return (a * v.unsqueeze(-2)).sum(-1);
}

// The 6D representation's matrix (its first two rows, core's Rot6dToMatrix).
torch::Tensor Rot6dToMatrix(const torch::Tensor& six) {
  return nn::SixDToMatrix(six, nn::SixDAxes::kRows);
}

// The local rotation of joint j (1..21) from columns 15:141.
torch::Tensor LocalRotation(const torch::Tensor& features, int joint) {
  return Rot6dToMatrix(features.narrow(-1, 15 + 6 * (joint - 1), 6));
}

// Positions of the four foot joints relative to the pelvis in the heading-free frame, given the
// heading-free pelvis orientation `pelvis` [T, N, 3, 3]: [T, N, 4, 3].
torch::Tensor FootPositions(const torch::Tensor& features, const torch::Tensor& pelvis) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  const auto offset = [&](int joint) {
    const Vec3& o = skeleton.rest_offsets()[static_cast<size_t>(joint)];
    return torch::tensor({o.x, o.y, o.z}, torch::kFloat64).to(torch::kFloat32);
  };
  std::vector<torch::Tensor> feet;
  // hip, knee, ankle, foot of each leg (the parents chain).
  static const std::array<std::array<int, 4>, 2> legs = nn::LegChains(skeleton);
  for (const std::array<int, 4>& leg : legs) {
    auto global = pelvis;
    auto position = MatVec(global, offset(leg[0]));
    for (size_t k = 1; k < leg.size(); ++k) {
      global = MatMat(global, LocalRotation(features, leg[k - 1]));
      position = position + MatVec(global, offset(leg[k]));
      if (k >= 2) feet.push_back(position);
    }
  }
  return torch::stack({feet[0], feet[1], feet[2], feet[3]}, -2);
}

// The frame pairs (i - 1, i) whose frames are both real: [T - 1, N, 1] (padding [N, T]).
torch::Tensor RealPairs(const torch::Tensor& padding, int64_t frames) {
  return padding.narrow(1, 1, frames - 1)
      .logical_or(padding.narrow(1, 0, frames - 1))
      .logical_not()
      .t()
      .unsqueeze(-1);
}

}  // namespace

torch::Tensor FootDisplacements(const torch::Tensor& features) {
  const auto f = features.to(torch::kFloat32);
  const int64_t frames = f.size(0);
  const auto pelvis = Rot6dToMatrix(f.narrow(-1, 3, 6));   // G
  const auto q = FootPositions(f, pelvis);                 // [T, N, 4, 3]
  const auto heading = Rot6dToMatrix(f.narrow(-1, 9, 6));  // H
  const auto velocity = f.narrow(-1, 0, 3);                // v
  const auto later = [&](const torch::Tensor& x) { return x.narrow(0, 1, frames - 1); };
  const auto earlier = [&](const torch::Tensor& x) { return x.narrow(0, 0, frames - 1); };
  const auto step = MatVec(earlier(pelvis), later(velocity)).unsqueeze(-2);  // G_{i-1} v_i
  return step + MatVec(later(heading).unsqueeze(-3), later(q)) - earlier(q);
}

torch::Tensor FootContactLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                              const torch::Tensor& padding, double fps, double contact_speed) {
  if (prediction.size(0) < 2) return torch::zeros({}, torch::kFloat32);
  const int64_t frames = prediction.size(0);
  const auto speed = [&](const torch::Tensor& x) { return FootDisplacements(x) * fps; };
  const auto target_speed = speed(target).detach().norm(2, -1);  // [T - 1, N, 4]
  const auto real = RealPairs(padding, frames);
  const auto contact = target_speed.lt(contact_speed).logical_and(real).to(torch::kFloat32);
  const auto squared = speed(prediction).pow(2).sum(-1);
  return (squared * contact).sum() / contact.sum().clamp_min(1.0);
}

torch::Tensor FootVelocityLoss(const torch::Tensor& prediction, const torch::Tensor& target,
                               const torch::Tensor& padding, double fps) {
  if (prediction.size(0) < 2) return torch::zeros({}, torch::kFloat32);
  const auto real = RealPairs(padding, prediction.size(0)).to(torch::kFloat32);  // [T - 1, N, 1]
  const auto squared =
      ((FootDisplacements(prediction) - FootDisplacements(target).detach()) * fps).pow(2).sum(-1);
  return (squared * real).sum() / (real.sum() * 4).clamp_min(1.0);
}

torch::Tensor ContactLabels(const torch::Tensor& features, double fps, double still_speed) {
  const int64_t frames = features.size(0);
  if (frames < 2) return torch::zeros({frames, features.size(1), kContactJoints}, torch::kFloat32);
  const auto pair = (FootDisplacements(features).detach() * fps).norm(2, -1);  // [T - 1, N, 4]
  // Frame i's speed: the mean of its pairs (i - 1, i) and (i, i + 1), the one it has at an end.
  auto speed = torch::empty({frames, pair.size(1), kContactJoints}, torch::kFloat32);
  speed[0] = pair[0];
  speed[frames - 1] = pair[frames - 2];
  if (frames > 2)
    speed.narrow(0, 1, frames - 2)
        .copy_(0.5 * (pair.narrow(0, 0, frames - 2) + pair.narrow(0, 1, frames - 2)));
  return speed.lt(still_speed).to(torch::kFloat32);
}

torch::Tensor ContactLoss(const torch::Tensor& logits, const torch::Tensor& labels,
                          const torch::Tensor& padding) {
  const auto real = padding.logical_not().t().unsqueeze(-1).to(torch::kFloat32);  // [T, N, 1]
  const auto each = torch::binary_cross_entropy_with_logits(logits.to(torch::kFloat32), labels, {},
                                                            {}, at::Reduction::None);
  return (each * real).sum() / (real.sum() * kContactJoints).clamp_min(1.0);
}

std::vector<uint8_t> ContactsAtRate(const torch::Tensor& stands, double fps, double rate,
                                    int64_t frames) {
  const auto p = stands.to(torch::kFloat32).contiguous();
  const int64_t have = p.size(0);
  if (p.dim() != 2 || p.size(1) != kContactJoints || have < 1)
    throw std::invalid_argument("ContactsAtRate: stands must be [T >= 1, 4]");
  const auto a = p.accessor<float, 2>();
  std::vector<uint8_t> held(static_cast<size_t>(frames * kContactJoints));
  for (int64_t j = 0; j < frames; ++j) {
    const double at =
        std::clamp(fps > 0 ? static_cast<double>(j) * fps / rate : static_cast<double>(j), 0.0,
                   static_cast<double>(have - 1));
    const auto lo = static_cast<int64_t>(std::floor(at));
    const int64_t hi = std::min(lo + 1, have - 1);
    const double w = at - static_cast<double>(lo);
    for (int64_t q = 0; q < kContactJoints; ++q)
      held[static_cast<size_t>(j * kContactJoints + q)] =
          (1 - w) * a[lo][q] + w * a[hi][q] > 0.5 ? 1 : 0;
  }
  return held;
}

}  // namespace motionpipe::mdt
