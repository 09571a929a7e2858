// The procedural corpus's action vocabulary: every action with its category, the body parts it
// uses (the ground truth the labelers are scored against), its parameter ranges, and paraphrased
// descriptions in the registers of BABEL labels ("wave right hand") and HumanML3D captions ("a
// person waves with their right hand").
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "motionpipe/base/random.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::corpus {

enum class ActionId : int {
  // locomotion (global + legs)
  kStand,
  kWalk,
  kJog,
  kRun,
  kWalkBackwards,
  kSideStep,
  kTurnInPlace,
  kWalkCircle,
  kJump,
  kHop,
  kMarchInPlace,
  // whole body
  kSitDown,
  kStandUp,
  kSquat,
  kKneel,
  kCrouch,
  kBow,
  kJumpingJacks,
  kSway,
  kTiptoe,
  // legs (while standing)
  kKick,
  kKneeLift,
  kStomp,
  kStretchLeg,
  // arms
  kWave,
  kRaiseArm,
  kPunch,
  kClap,
  kReachForward,
  kArmCircle,
  kThrow,
  kDrink,
  kHandsOnHips,
  kCrossArms,
  kPoint,
  kSalute,
  kScratchHead,
  kShrug,
  kStretchArms,
  // torso and head
  kBendForward,
  kLean,
  kTwist,
  kNod,
  kShakeHead,
  kLookAround,
  kLookUp,
  kCount
};
constexpr int kNumActions = static_cast<int>(ActionId::kCount);

// Which layer of the body an action drives. Base actions (locomotion, whole body, legs) follow one
// another; arm, torso and head actions overlay a base action.
enum class ActionKind { kLocomotion, kWholeBody, kLeg, kArm, kTorso, kHead };
bool IsBaseKind(ActionKind kind);

enum class Side : uint8_t { kNone = 0, kLeft, kRight, kBoth };
const char* SideName(Side side);

struct ActionDef {
  ActionId id;
  const char* name;  // canonical name, e.g. "walk_backwards"
  ActionKind kind;
  bool sided;        // takes a side (left/right)
  bool allows_both;  // side may be "both"
  PartSet parts;     // parts when not sided (sided: the side's arm or leg, see PartsOf)
  double min_seconds, max_seconds;
  int min_reps, max_reps;             // 0 = not a repeated action
  std::vector<std::string> labels;    // BABEL-style, with placeholders (see FillTemplate)
  std::vector<std::string> captions;  // HumanML3D-style
};

const std::vector<ActionDef>& Vocabulary();
const ActionDef& Def(ActionId id);
// The action with this canonical name, or kCount.
ActionId ActionByName(const std::string& name);

// Ground-truth parts of an action performed with `side`.
PartSet PartsOf(ActionId id, Side side);

struct TextParams {
  Side side = Side::kNone;
  double speed = 1;      // 1 = normal; < 0.8 slow, > 1.3 fast
  double amplitude = 1;  // 1 = normal
  int reps = 0;
  bool turn_left = true;  // turns, circles, side steps
};

// Replaces {side} {arm} {arms} {hand} {hands} {leg} {foot} {dir} {speed} {reps} {their} in a
// template and tidies spaces. Adverbs appear only when the parameter is clearly off normal.
std::string FillTemplate(const std::string& text, const TextParams& params);

// Whether an action's tempo / size is a parameter of its motion (what a speed or amplitude edit
// can change).
bool SpeedMatters(ActionId id);
bool AmplitudeMatters(ActionId id);

// The text with the manner an annotator may add when it is clearly off normal (HumanML3D's captions
// often say how: "quickly", "three times", "with big movements"): the tempo beyond the {speed}
// thresholds, the repetitions of counted actions, and the size (amplitude above 1.2 or below 0.8)
// of actions whose size is a parameter; a manner the text already states is not repeated. The
// corpus adds it to a share of its texts (CorpusOptions::manner_words).
std::string WithManner(const std::string& text, ActionId id, const TextParams& params);

// A random BABEL-style label / HumanML3D-style caption for an action.
std::string SampleLabel(ActionId id, const TextParams& params, Rng& rng);
std::string SampleCaption(ActionId id, const TextParams& params, Rng& rng);

}  // namespace motionpipe::corpus
