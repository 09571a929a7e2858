#include "motionpipe/sinc/composition.h"

#include <algorithm>
#include <cstring>

namespace motionpipe::sinc {

const char* CropModeName(CropMode mode) { return mode == CropMode::kFirst ? "first" : "centre"; }

Result<CropMode> ParseCropMode(const std::string& name) {
  if (name == "first") return CropMode::kFirst;
  if (name == "centre" || name == "center") return CropMode::kCentre;
  return InvalidArgument("crop: '" + name + "' (known: first, centre)");
}

CompositionPlan PlanComposition(int64_t first_frames, PartSet first_parts, int64_t second_frames,
                                PartSet second_parts, CropMode crop) {
  CompositionPlan plan;
  // Step 2: B is the one with fewer parts.
  plan.swapped = PartCount(second_parts) > PartCount(first_parts);
  const int64_t a_frames = plan.swapped ? second_frames : first_frames;
  const int64_t b_frames = plan.swapped ? first_frames : second_frames;
  plan.a_parts = plan.swapped ? second_parts : first_parts;
  plan.b_parts = plan.swapped ? first_parts : second_parts;
  // Step 1: the shorter length; the longer motion is cropped.
  plan.frames = std::min(a_frames, b_frames);
  if (crop == CropMode::kCentre) {
    plan.a_start = (a_frames - plan.frames) / 2;
    plan.b_start = (b_frames - plan.frames) / 2;
  }
  // Step 3: legs, global orientation and translation travel together.
  plan.from_b = plan.b_parts;
  plan.root_from_b = (plan.b_parts & kLegsAndGlobal) != 0;
  if (plan.root_from_b) plan.from_b |= kLegsAndGlobal;
  const auto& part_joints = Skeleton::Smpl22().part_joints();
  for (int part = 0; part < kNumBodyParts; ++part) {
    if (!(plan.from_b & (1u << part))) continue;
    for (const int joint : part_joints[static_cast<size_t>(part)])
      plan.joint_from_b[static_cast<size_t>(joint)] = true;
  }
  return plan;
}

Motion ApplyComposition(const CompositionPlan& plan, const Motion& first, const Motion& second) {
  const Motion& a = plan.swapped ? second : first;
  const Motion& b = plan.swapped ? first : second;
  Motion out;
  out.fps = a.fps;
  const int64_t frames = plan.frames;
  out.poses.resize(static_cast<size_t>(frames * kNumJoints * 3));
  out.trans.resize(static_cast<size_t>(frames * 3));
  // Runs of joints from the same source are copied together (joints are contiguous per frame).
  for (int64_t f = 0; f < frames; ++f) {
    const float* pa = a.poses.data() + (plan.a_start + f) * kNumJoints * 3;
    const float* pb = b.poses.data() + (plan.b_start + f) * kNumJoints * 3;
    float* dst = out.poses.data() + f * kNumJoints * 3;
    int j = 0;
    while (j < kNumJoints) {
      const bool from_b = plan.joint_from_b[static_cast<size_t>(j)];
      int end = j + 1;
      while (end < kNumJoints && plan.joint_from_b[static_cast<size_t>(end)] == from_b) ++end;
      std::memcpy(dst + 3 * j, (from_b ? pb : pa) + 3 * j,
                  sizeof(float) * 3 * static_cast<size_t>(end - j));
      j = end;
    }
  }
  const Motion& root = plan.root_from_b ? b : a;
  const int64_t root_start = plan.root_from_b ? plan.b_start : plan.a_start;
  std::memcpy(out.trans.data(), root.trans.data() + root_start * 3,
              sizeof(float) * 3 * static_cast<size_t>(frames));
  return out;
}

Motion Compose(const Motion& first, PartSet first_parts, const Motion& second, PartSet second_parts,
               CropMode crop, CompositionPlan* plan_out) {
  const CompositionPlan plan =
      PlanComposition(first.num_frames(), first_parts, second.num_frames(), second_parts, crop);
  if (plan_out) *plan_out = plan;
  return ApplyComposition(plan, first, second);
}

}  // namespace motionpipe::sinc
