#include "motionpipe/corpus/vocabulary.h"

#include <algorithm>

namespace motionpipe::corpus {

namespace {

// Repetition counts as words, [1, 6].
const char* const kTimesWords[] = {"",           "once",       "twice",    "three times",
                                   "four times", "five times", "six times"};

constexpr PartSet G = PartBit(BodyPart::kGlobal);
constexpr PartSet T = PartBit(BodyPart::kTorso);
constexpr PartSet LA = PartBit(BodyPart::kLeftArm);
constexpr PartSet RA = PartBit(BodyPart::kRightArm);
constexpr PartSet LL = PartBit(BodyPart::kLeftLeg);
constexpr PartSet RL = PartBit(BodyPart::kRightLeg);
constexpr PartSet kLegs = G | LL | RL;

// Locomotion (global + legs).
std::vector<ActionDef> LocomotionActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kStand,
       "stand",
       K::kLocomotion,
       false,
       false,
       kLegs,
       1.5,
       4,
       0,
       0,
       {"stand", "stand still", "standing", "stand in place", "idle", "stand upright"},
       {"a person stands still", "a person is standing in place", "someone stands and waits",
        "the person stands idle"}},
      {A::kWalk,
       "walk",
       K::kLocomotion,
       false,
       false,
       kLegs,
       2.5,
       6,
       0,
       0,
       {"walk", "walk forward", "walking", "walk forwards {speed}", "walk straight",
        "take steps forward"},
       {"a person walks forward {speed}", "a person is walking straight ahead",
        "someone walks forwards {speed}", "the person takes several steps forward"}},
      {A::kJog,
       "jog",
       K::kLocomotion,
       false,
       false,
       kLegs,
       2,
       5,
       0,
       0,
       {"jog", "jog forward", "jogging", "light jog", "jog in a straight line"},
       {"a person jogs forward", "a person is jogging {speed}", "someone jogs straight ahead"}},
      {A::kRun,
       "run",
       K::kLocomotion,
       false,
       false,
       kLegs,
       1.5,
       3.5,
       0,
       0,
       {"run", "run forward", "running", "sprint", "run fast"},
       {"a person runs forward", "a person is running {speed}", "someone sprints ahead"}},
      {A::kWalkBackwards,
       "walk_backwards",
       K::kLocomotion,
       false,
       false,
       kLegs,
       2,
       5,
       0,
       0,
       {"walk backwards", "walk backward", "step backwards", "backpedal",
        "walking backwards {speed}"},
       {"a person walks backwards {speed}", "a person steps backward several times",
        "someone walks backwards without turning around"}},
      {A::kSideStep,
       "side_step",
       K::kLocomotion,
       false,
       false,
       kLegs,
       1.5,
       4,
       0,
       0,
       {"side step {dir}", "sidestep to the {dir}", "step to the {dir}", "shuffle {dir}",
        "side steps"},
       {"a person side steps to the {dir}", "a person shuffles sideways to the {dir}",
        "someone takes steps to the {dir} side"}},
      {A::kTurnInPlace,
       "turn_in_place",
       K::kLocomotion,
       false,
       false,
       kLegs,
       1.2,
       3,
       0,
       0,
       {"turn {dir}", "turn around", "turn to the {dir}", "turn in place", "rotate {dir}",
        "turn {dir} in place"},
       {"a person turns to the {dir}", "a person turns around in place",
        "someone turns {dir} on the spot"}},
      {A::kWalkCircle,
       "walk_circle",
       K::kLocomotion,
       false,
       false,
       kLegs,
       4,
       8,
       0,
       0,
       {"walk in a circle", "walk in circle", "circle around", "walk around in a circle {dir}"},
       {"a person walks in a circle", "a person walks around in a {dir} circle",
        "someone walks in a small circle"}},
  };
}

// Locomotion: jumps, hops and marching in place.
std::vector<ActionDef> HopActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kJump,
       "jump",
       K::kLocomotion,
       false,
       false,
       kLegs,
       1,
       4,
       1,
       3,
       {"jump", "jump forward", "jump {reps}", "hop forward with both feet", "jump up", "jumping"},
       {"a person jumps forward {reps}", "a person jumps up {reps}",
        "someone jumps with both feet"}},
      {A::kHop,
       "hop",
       K::kLocomotion,
       true,
       false,
       kLegs,
       1,
       4,
       2,
       6,
       {"hop on {leg}", "hop on one leg", "hop on {foot}", "one leg hop", "hop {reps} on {foot}"},
       {"a person hops on {their_leg}", "a person hops forward on one foot",
        "someone hops on {their_foot} {reps}"}},
      {A::kMarchInPlace,
       "march_in_place",
       K::kLocomotion,
       false,
       false,
       kLegs,
       2,
       6,
       4,
       10,
       {"march in place", "march", "step in place", "marching", "jog in place"},
       {"a person marches in place", "a person steps on the spot lifting their knees",
        "someone marches without moving forward"}},
  };
}

// Whole body.
std::vector<ActionDef> WholeBodyActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kSitDown,
       "sit_down",
       K::kWholeBody,
       false,
       false,
       kLegs,
       2.5,
       5,
       0,
       0,
       {"sit down", "sit", "sit on chair", "take a seat", "sit down slowly", "sitting"},
       {"a person sits down", "a person sits down on a chair",
        "someone lowers themselves into a seat"}},
      {A::kStandUp,
       "stand_up",
       K::kWholeBody,
       false,
       false,
       kLegs,
       1.5,
       3,
       0,
       0,
       {"stand up", "get up", "stand up from chair", "rise", "stand up {speed}"},
       {"a person stands up", "a person gets up from a chair", "someone rises to their feet"}},
      {A::kSquat,
       "squat",
       K::kWholeBody,
       false,
       false,
       kLegs,
       2,
       6,
       1,
       3,
       {"squat", "squat down", "squats", "squat {reps}", "do a squat", "bend knees"},
       {"a person squats down and stands back up", "a person does squats {reps}",
        "someone bends their knees into a squat"}},
      {A::kKneel,
       "kneel",
       K::kWholeBody,
       true,
       false,
       kLegs,
       3,
       5.5,
       0,
       0,
       {"kneel", "kneel down", "kneel on {leg}", "go down on one knee",
        "kneel down with {side} knee"},
       {"a person kneels down on one knee", "a person kneels on {their_leg} and gets back up",
        "someone goes down on one knee"}},
      {A::kCrouch,
       "crouch",
       K::kWholeBody,
       false,
       false,
       kLegs | T,
       2,
       4.5,
       0,
       0,
       {"crouch", "crouch down", "duck", "crouching", "get low"},
       {"a person crouches down low", "a person ducks down and comes back up", "someone crouches"}},
      {A::kBow,
       "bow",
       K::kWholeBody,
       false,
       false,
       T,
       2,
       3.5,
       0,
       0,
       {"bow", "bow down", "take a bow", "full bow from waist", "bow slightly"},
       {"a person bows", "a person bows forward at the waist", "someone takes a bow"}},
      {A::kJumpingJacks,
       "jumping_jacks",
       K::kWholeBody,
       false,
       false,
       kLegs | T | LA | RA,
       2,
       6,
       2,
       6,
       {"jumping jacks", "do jumping jacks", "jumping jack", "star jumps"},
       {"a person does jumping jacks", "a person performs jumping jacks {reps}",
        "someone jumps while spreading arms and legs"}},
      {A::kSway,
       "sway",
       K::kWholeBody,
       false,
       false,
       G | T,
       3,
       6,
       0,
       0,
       {"sway", "sway side to side", "rock back and forth", "shift weight", "sway body"},
       {"a person sways from side to side", "a person shifts their weight left and right",
        "someone rocks their body gently"}},
      {A::kTiptoe,
       "tiptoe",
       K::kWholeBody,
       false,
       false,
       LL | RL,
       2,
       4,
       0,
       0,
       {"tiptoe", "stand on tiptoes", "stand on toes", "rise onto toes", "calf raise"},
       {"a person rises onto their tiptoes", "a person stands on their toes and comes back down",
        "someone lifts their heels off the ground"}},
  };
}

// Legs, while standing.
std::vector<ActionDef> LegActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kKick,
       "kick",
       K::kLeg,
       true,
       false,
       0,
       1,
       4,
       1,
       3,
       {"kick", "kick with {leg}", "{side} leg kick", "kick forward", "kick {reps}",
        "kick with {foot}"},
       {"a person kicks forward with {their_leg}", "a person kicks {reps} with {their_foot}",
        "someone does a front kick with {their_leg}"}},
      {A::kKneeLift,
       "knee_lift",
       K::kLeg,
       true,
       false,
       0,
       1.2,
       4,
       1,
       4,
       {"lift {side} knee", "knee lift", "raise {leg}", "lift {leg} up", "knee up",
        "raise {side} knee {reps}"},
       {"a person lifts {their_side} knee up {reps}",
        "a person raises {their_leg} bending the knee",
        "someone brings their {side} knee up to hip height"}},
      {A::kStomp,
       "stomp",
       K::kLeg,
       true,
       false,
       0,
       1,
       3.5,
       1,
       3,
       {"stomp", "stomp {foot}", "stamp foot", "stomp with {leg}", "stomp {reps}"},
       {"a person stomps {their_foot}", "a person stamps {their_foot} on the ground {reps}",
        "someone stomps with {their_leg}"}},
      {A::kStretchLeg,
       "stretch_leg",
       K::kLeg,
       true,
       false,
       0,
       2.5,
       4.5,
       0,
       0,
       {"stretch leg", "stretch {leg}", "side lunge", "lunge to the {side}",
        "stretch {leg} out to the side"},
       {"a person stretches {their_leg} out to the side",
        "a person does a side lunge to the {side}",
        "someone extends {their_leg} sideways and bends the other knee"}},
  };
}

// Arms: gestures and movements of the whole arm.
std::vector<ActionDef> ArmActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kWave,
       "wave",
       K::kArm,
       true,
       true,
       0,
       1.5,
       4.5,
       2,
       6,
       {"wave", "wave {hand}", "wave with {arm}", "waving", "wave hello", "{side} hand wave",
        "wave {hand} {speed}"},
       {"a person waves {their_hand}", "a person raises {their_hand} and waves {speed}",
        "someone waves hello with {their_hand}"}},
      {A::kRaiseArm,
       "raise_arm",
       K::kArm,
       true,
       true,
       0,
       1.5,
       3.5,
       0,
       0,
       {"raise {arm}", "raise {hand}", "lift {arm} up", "{side} arm up", "raise {arm} above head",
        "hand up"},
       {"a person raises {their_arm} above their head",
        "a person lifts {their_arm} up and lowers it", "someone puts {their_hand} up in the air"}},
      {A::kPunch,
       "punch",
       K::kArm,
       true,
       true,
       0,
       1,
       4,
       1,
       6,
       {"punch", "punch with {hand}", "{side} punch", "punch forward", "jab", "boxing punches",
        "punch {reps}"},
       {"a person punches forward with {their_hand}", "a person throws punches {reps}",
        "someone jabs the air with {their_arm}"}},
      {A::kClap,
       "clap",
       K::kArm,
       false,
       false,
       LA | RA,
       1.5,
       4,
       3,
       8,
       {"clap", "clap hands", "clapping", "applaud", "clap {speed}", "clap {reps}"},
       {"a person claps their hands {reps}", "a person claps in front of their chest",
        "someone applauds"}},
      {A::kReachForward,
       "reach_forward",
       K::kArm,
       true,
       true,
       0,
       1.5,
       3,
       0,
       0,
       {"reach forward", "reach out with {hand}", "extend {arm} forward",
        "stretch {arm} out in front", "reach for something"},
       {"a person reaches forward with {their_hand}", "a person extends {their_arm} straight ahead",
        "someone reaches out in front of them"}},
      {A::kArmCircle,
       "arm_circle",
       K::kArm,
       true,
       true,
       0,
       2,
       5,
       2,
       5,
       {"arm circles", "circle {arm}", "rotate {arm}", "swing {arm} in circles", "windmill {arm}"},
       {"a person swings {their_arm} in circles",
        "a person rotates {their_arm} in big circles {reps}",
        "someone makes circles with {their_arm}"}},
      {A::kThrow,
       "throw",
       K::kArm,
       true,
       false,
       0,
       1.2,
       2.2,
       0,
       0,
       {"throw", "throw with {hand}", "throw ball", "{side} arm throw", "throw something",
        "overhand throw"},
       {"a person throws something with {their_hand}",
        "a person winds up and throws with {their_arm}", "someone throws a ball overhand"}},
  };
}

// Arms: the hands at the body, the head or the hips.
std::vector<ActionDef> HandActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kDrink,
       "drink",
       K::kArm,
       true,
       false,
       0,
       2,
       4,
       0,
       0,
       {"drink", "drink from cup", "drink with {hand}", "take a sip", "drink from bottle",
        "bring cup to mouth"},
       {"a person drinks from a cup in {their_hand}",
        "a person brings {their_hand} to their mouth and drinks",
        "someone takes a sip of a drink"}},
      {A::kHandsOnHips,
       "hands_on_hips",
       K::kArm,
       false,
       false,
       LA | RA,
       2,
       4,
       0,
       0,
       {"hands on hips", "put hands on hips", "place hands on waist", "akimbo", "hold hips"},
       {"a person puts their hands on their hips", "a person stands with hands on hips",
        "someone places both hands on their waist"}},
      {A::kCrossArms,
       "cross_arms",
       K::kArm,
       false,
       false,
       LA | RA,
       2,
       4,
       0,
       0,
       {"cross arms", "fold arms", "arms crossed", "cross arms in front of chest"},
       {"a person crosses their arms", "a person folds their arms across their chest",
        "someone stands with arms crossed"}},
      {A::kPoint,
       "point",
       K::kArm,
       true,
       false,
       0,
       1.5,
       3,
       0,
       0,
       {"point", "point forward", "point with {hand}", "point at something", "{side} hand point"},
       {"a person points forward with {their_hand}",
        "a person points at something in front of them", "someone extends {their_arm} to point"}},
      {A::kSalute,
       "salute",
       K::kArm,
       true,
       false,
       0,
       1.5,
       3,
       0,
       0,
       {"salute", "military salute", "salute with {hand}", "hand to forehead"},
       {"a person salutes with {their_hand}",
        "a person raises {their_hand} to their forehead in a salute"}},
      {A::kScratchHead,
       "scratch_head",
       K::kArm,
       true,
       false,
       0,
       1.5,
       3,
       0,
       0,
       {"scratch head", "scratch head with {hand}", "touch head", "{side} hand on head",
        "rub head"},
       {"a person scratches their head with {their_hand}",
        "a person puts {their_hand} on their head", "someone rubs the top of their head"}},
      {A::kShrug,
       "shrug",
       K::kArm,
       false,
       false,
       LA | RA,
       1,
       2,
       0,
       0,
       {"shrug", "shrug shoulders", "shrugging", "shoulders up"},
       {"a person shrugs their shoulders", "a person shrugs with palms up",
        "someone lifts their shoulders"}},
      {A::kStretchArms,
       "stretch_arms",
       K::kArm,
       false,
       false,
       LA | RA,
       2,
       4,
       0,
       0,
       {"stretch arms", "stretch arms up", "reach up with both arms", "stretch",
        "arms overhead stretch"},
       {"a person stretches both arms above their head", "a person reaches up high with both arms",
        "someone stretches their arms overhead"}},
  };
}

// Torso and head.
std::vector<ActionDef> TorsoAndHeadActions() {
  using K = ActionKind;
  using A = ActionId;
  return {
      {A::kBendForward,
       "bend_forward",
       K::kTorso,
       false,
       false,
       T,
       2,
       4,
       0,
       0,
       {"bend forward", "bend over", "lean forward", "bend down", "bend at the waist",
        "bend over {speed}"},
       {"a person bends forward at the waist", "a person bends over and straightens up",
        "someone leans their upper body forward"}},
      {A::kLean,
       "lean",
       K::kTorso,
       true,
       false,
       T,
       1.5,
       3.5,
       0,
       0,
       {"lean {side}", "lean to the {side}", "tilt to the {side}", "side bend {side}",
        "lean sideways"},
       {"a person leans to the {side}", "a person bends their torso to the {side} side",
        "someone tilts their upper body to the {side}"}},
      {A::kTwist,
       "twist",
       K::kTorso,
       true,
       false,
       T,
       1.5,
       3.5,
       0,
       0,
       {"twist", "twist torso", "twist to the {side}", "rotate upper body {side}",
        "turn upper body"},
       {"a person twists their torso to the {side}",
        "a person rotates their upper body and turns back", "someone twists at the waist"}},
      {A::kNod,
       "nod",
       K::kHead,
       false,
       false,
       T,
       1,
       3,
       2,
       5,
       {"nod", "nod head", "nodding", "nod yes", "nod {reps}"},
       {"a person nods their head", "a person nods yes {reps}", "someone nods"}},
      {A::kShakeHead,
       "shake_head",
       K::kHead,
       false,
       false,
       T,
       1,
       3,
       2,
       5,
       {"shake head", "shake head no", "head shake", "shaking head"},
       {"a person shakes their head", "a person shakes their head no",
        "someone shakes their head side to side"}},
      {A::kLookAround,
       "look_around",
       K::kHead,
       false,
       false,
       T,
       2,
       5,
       0,
       0,
       {"look around", "look left and right", "scan area", "look to the {dir}",
        "look around {speed}"},
       {"a person looks around", "a person looks to the left and to the right",
        "someone scans the area"}},
      {A::kLookUp,
       "look_up",
       K::kHead,
       false,
       false,
       T,
       1.5,
       3,
       0,
       0,
       {"look up", "look up at the sky", "tilt head back", "look upward"},
       {"a person looks up", "a person tilts their head back and looks up",
        "someone looks up at the sky"}},
  };
}

// The vocabulary in ActionId order (Def indexes it by id).
std::vector<ActionDef> BuildVocabulary() {
  std::vector<ActionDef> v;
  for (auto family : {LocomotionActions, HopActions, WholeBodyActions, LegActions, ArmActions,
                      HandActions, TorsoAndHeadActions}) {
    for (ActionDef& def : family()) v.push_back(std::move(def));
  }
  return v;
}

}  // namespace

bool IsBaseKind(ActionKind kind) {
  return kind == ActionKind::kLocomotion || kind == ActionKind::kWholeBody ||
         kind == ActionKind::kLeg;
}

const char* SideName(Side side) {
  switch (side) {
    case Side::kLeft:
      return "left";
    case Side::kRight:
      return "right";
    case Side::kBoth:
      return "both";
    case Side::kNone:
      return "none";
  }
  return "none";
}

const std::vector<ActionDef>& Vocabulary() {
  static const std::vector<ActionDef> vocabulary = BuildVocabulary();
  return vocabulary;
}

const ActionDef& Def(ActionId id) { return Vocabulary()[static_cast<size_t>(id)]; }

ActionId ActionByName(const std::string& name) {
  for (const ActionDef& def : Vocabulary()) {
    if (name == def.name) return def.id;
  }
  return ActionId::kCount;
}

PartSet PartsOf(ActionId id, Side side) {
  const ActionDef& def = Def(id);
  if (!def.sided) return def.parts;
  PartSet parts = def.parts;
  const bool left = side == Side::kLeft || side == Side::kBoth;
  const bool right = side == Side::kRight || side == Side::kBoth;
  if (def.kind == ActionKind::kArm) {
    if (left) parts |= LA;
    if (right) parts |= RA;
  } else if (def.kind == ActionKind::kLeg || def.id == ActionId::kKneel) {
    if (left) parts |= LL;
    if (right) parts |= RL;
  }
  return parts;
}

namespace {
void ReplaceAll(std::string* text, const std::string& from, const std::string& to) {
  size_t at = 0;
  while ((at = text->find(from, at)) != std::string::npos) {
    text->replace(at, from.size(), to);
    at += to.size();
  }
}
}  // namespace

std::string FillTemplate(const std::string& text, const TextParams& p) {
  std::string out = text;
  const bool both = p.side == Side::kBoth;
  const std::string side = p.side == Side::kLeft ? "left" : "right";
  ReplaceAll(&out, "{their_hand}", both ? "both hands" : "their " + side + " hand");
  ReplaceAll(&out, "{their_arm}", both ? "both arms" : "their " + side + " arm");
  ReplaceAll(&out, "{their_leg}", "their " + side + " leg");
  ReplaceAll(&out, "{their_foot}", "their " + side + " foot");
  ReplaceAll(&out, "{their_side}", "their " + side);
  ReplaceAll(&out, "{hand}", both ? "both hands" : side + " hand");
  ReplaceAll(&out, "{arm}", both ? "both arms" : side + " arm");
  ReplaceAll(&out, "{leg}", side + " leg");
  ReplaceAll(&out, "{foot}", side + " foot");
  ReplaceAll(&out, "{side}", both ? "both" : side);
  ReplaceAll(&out, "{dir}", p.turn_left ? "left" : "right");
  ReplaceAll(&out, "{speed}", p.speed > 1.3 ? "quickly" : (p.speed < 0.75 ? "slowly" : ""));
  ReplaceAll(&out, "{reps}", p.reps >= 2 && p.reps <= 6 ? kTimesWords[p.reps] : "");
  // Tidy: collapse double spaces, trim.
  std::string tidy;
  for (char c : out) {
    if (c == ' ' && (tidy.empty() || tidy.back() == ' ')) continue;
    tidy.push_back(c);
  }
  while (!tidy.empty() && tidy.back() == ' ') tidy.pop_back();
  return tidy;
}

bool SpeedMatters(ActionId id) {
  return id != ActionId::kStand && id != ActionId::kHandsOnHips && id != ActionId::kCrossArms &&
         id != ActionId::kTiptoe;
}

bool AmplitudeMatters(ActionId id) {
  switch (id) {
    case ActionId::kWave:
    case ActionId::kRaiseArm:
    case ActionId::kPunch:
    case ActionId::kReachForward:
    case ActionId::kKick:
    case ActionId::kKneeLift:
    case ActionId::kStomp:
    case ActionId::kSquat:
    case ActionId::kCrouch:
    case ActionId::kBow:
    case ActionId::kBendForward:
    case ActionId::kLean:
    case ActionId::kTwist:
    case ActionId::kJump:
    case ActionId::kHop:
    case ActionId::kNod:
    case ActionId::kShakeHead:
    case ActionId::kLookAround:
    case ActionId::kLookUp:
    case ActionId::kSway:
    case ActionId::kStretchLeg:
    case ActionId::kShrug:
      return true;
    default:
      return false;
  }
}

std::string WithManner(const std::string& text, ActionId id, const TextParams& p) {
  // Whether a word of the text starts with one of the stems ("slow" finds "slowly", not "low").
  std::vector<std::string> words;
  for (size_t at = 0; at < text.size();) {
    const size_t end = std::min(text.find(' ', at), text.size());
    if (end > at) words.push_back(text.substr(at, end - at));
    at = end + 1;
  }
  const auto says = [&](std::initializer_list<const char*> stems) {
    for (const std::string& w : words) {
      for (const char* stem : stems) {
        if (w.rfind(stem, 0) == 0) return true;
      }
    }
    return false;
  };
  std::string out = text;
  if (SpeedMatters(id) && !says({"quick", "slow", "fast", "sprint"})) {
    if (p.speed > 1.3) out += " quickly";
    if (p.speed < 0.75) out += " slowly";
  }
  if (Def(id).max_reps > 0 && p.reps >= 1 && p.reps <= 6 && !says({"once", "twice", "times"}))
    out += std::string(" ") + kTimesWords[p.reps];
  if (AmplitudeMatters(id) && !says({"big", "small", "high", "low", "slight", "deep", "further"})) {
    if (p.amplitude > 1.2) out += " with big movements";
    if (p.amplitude < 0.8) out += " with small movements";
  }
  return out;
}

std::string SampleLabel(ActionId id, const TextParams& params, Rng& rng) {
  const auto& labels = Def(id).labels;
  return FillTemplate(rng.Pick(labels), params);
}

std::string SampleCaption(ActionId id, const TextParams& params, Rng& rng) {
  const auto& captions = Def(id).captions;
  return FillTemplate(rng.Pick(captions), params);
}

}  // namespace motionpipe::corpus
