// SINC's body-part composition of two motions (paper sec. 3.1 "Body part composition",
// REFERENCE 4.2):
//
//   1. trim both motions to the shorter length (first frames, as the reference does in training,
//      or a centred crop);
//   2. order them so that B has fewer body parts than A (ties keep the given order);
//   3. if B uses a leg or the global orientation, B also supplies both legs, the global orientation
//      and the translation; otherwise A keeps them;
//   4. every part not selected from B comes from A;
//   5. B's parts override A's (synthetic pairs are compatible: disjoint part sets, nothing to
//   override;
//      the GPT-compositing baseline composes generated motions whose parts may overlap).
//
// Parts map to joints as in data/skeleton/smpl22.json: global = joint 0 (+ translation), torso =
// spine1..3, neck, head; arms = collar, shoulder, elbow, wrist; legs = hip, knee, ankle, foot.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::sinc {

inline constexpr PartSet kAllParts = 0x3F;
inline constexpr PartSet kLegsAndGlobal =
    PartBit(BodyPart::kGlobal) | PartBit(BodyPart::kLeftLeg) | PartBit(BodyPart::kRightLeg);

// Two actions can be performed at once when their part sets are non-empty and disjoint.
inline bool Compatible(PartSet a, PartSet b) { return a != 0 && b != 0 && (a & b) == 0; }

enum class CropMode {
  kFirst,   // keep the first frames of the longer motion (the reference code, in training)
  kCentre,  // keep the centred window of the longer motion
};
const char* CropModeName(CropMode mode);
Result<CropMode> ParseCropMode(const std::string& name);

// How a composition was made: enough to make it again (a recipe) and to describe it.
struct CompositionPlan {
  bool swapped = false;  // step 2 exchanged the inputs: "A" below is the second argument
  int64_t frames = 0;    // the shorter length
  int64_t a_start = 0;   // first frame taken from A (after the swap)
  int64_t b_start = 0;
  PartSet a_parts = 0;  // part sets after the swap
  PartSet b_parts = 0;
  PartSet from_b = 0;        // parts whose joints come from B (step 3 may add legs + global)
  bool root_from_b = false;  // global orientation and translation come from B
  // joint j's rotation comes from B
  std::array<bool, kNumJoints> joint_from_b{};
};

// Steps 1-3: which frames and joints come from where. `first_*` are the arguments' own lengths.
CompositionPlan PlanComposition(int64_t first_frames, PartSet first_parts, int64_t second_frames,
                                PartSet second_parts, CropMode crop);

// Steps 4-5: the composed motion (same fps as A). Inputs must be valid motions with >= 1 frame.
Motion ApplyComposition(const CompositionPlan& plan, const Motion& first, const Motion& second);

// Plan + apply.
Motion Compose(const Motion& first, PartSet first_parts, const Motion& second, PartSet second_parts,
               CropMode crop, CompositionPlan* plan_out = nullptr);

}  // namespace motionpipe::sinc
