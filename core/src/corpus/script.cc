#include "motionpipe/corpus/script.h"

#include <algorithm>
#include <cmath>

namespace motionpipe::corpus {

namespace {

using A = ActionId;

struct Weighted {
  ActionId id;
  double weight;
};

// How often each base action starts a segment (standing posture).
const std::vector<Weighted>& BaseWeights() {
  static const std::vector<Weighted> weights = {
      {A::kStand, 1.0},       {A::kWalk, 1.8},          {A::kJog, 0.6},
      {A::kRun, 0.4},         {A::kWalkBackwards, 0.5}, {A::kSideStep, 0.5},
      {A::kTurnInPlace, 0.8}, {A::kWalkCircle, 0.4},    {A::kJump, 0.5},
      {A::kHop, 0.35},        {A::kMarchInPlace, 0.35}, {A::kSitDown, 0.6},
      {A::kSquat, 0.5},       {A::kKneel, 0.35},        {A::kCrouch, 0.35},
      {A::kBow, 0.4},         {A::kJumpingJacks, 0.35}, {A::kSway, 0.35},
      {A::kTiptoe, 0.3},      {A::kKick, 0.5},          {A::kKneeLift, 0.4},
      {A::kStomp, 0.35},      {A::kStretchLeg, 0.3}};
  return weights;
}

const std::vector<Weighted>& OverlayWeights() {
  static const std::vector<Weighted> weights = {
      {A::kWave, 1.2},         {A::kRaiseArm, 1.0},  {A::kPunch, 0.7},       {A::kClap, 0.7},
      {A::kReachForward, 0.6}, {A::kArmCircle, 0.5}, {A::kThrow, 0.5},       {A::kDrink, 0.5},
      {A::kHandsOnHips, 0.6},  {A::kCrossArms, 0.6}, {A::kPoint, 0.6},       {A::kSalute, 0.35},
      {A::kScratchHead, 0.4},  {A::kShrug, 0.4},     {A::kStretchArms, 0.4}, {A::kBendForward, 0.5},
      {A::kLean, 0.4},         {A::kTwist, 0.4},     {A::kNod, 0.4},         {A::kShakeHead, 0.4},
      {A::kLookAround, 0.6},   {A::kLookUp, 0.4}};
  return weights;
}

// Base actions under which a torso action is performed naturally.
bool TorsoOverlayAllowed(ActionId base) {
  switch (base) {
    case A::kStand:
    case A::kWalk:
    case A::kWalkCircle:
    case A::kSideStep:
    case A::kSitDown:
    case A::kKneel:
    case A::kTiptoe:
    case A::kMarchInPlace:
      return true;
    default:
      return false;
  }
}

// Seconds per repetition and the lead-in + lead-out time of repeated actions.
struct Tempo {
  double period;
  double lead;
};
Tempo TempoOf(ActionId id) {
  switch (id) {
    case A::kJump:
      return {1.25, 0.4};
    case A::kHop:
      return {0.55, 0.8};
    case A::kMarchInPlace:
      return {0.55, 0.4};
    case A::kSquat:
      return {2.2, 0.3};
    case A::kJumpingJacks:
      return {1.0, 0.4};
    case A::kKick:
      return {1.3, 0.8};
    case A::kKneeLift:
      return {1.3, 0.8};
    case A::kStomp:
      return {1.0, 0.8};
    case A::kWave:
      return {0.55, 0.9};
    case A::kPunch:
      return {0.6, 0.7};
    case A::kClap:
      return {0.45, 0.7};
    case A::kArmCircle:
      return {1.1, 0.7};
    case A::kNod:
      return {0.6, 0.4};
    case A::kShakeHead:
      return {0.6, 0.4};
    default:
      return {0, 0};
  }
}

double SampleSpeed(Rng& rng) {
  const double r = rng.Uniform();
  if (r < 0.15) return rng.Uniform(0.55, 0.75);
  if (r < 0.30) return rng.Uniform(1.3, 1.7);
  return rng.Uniform(0.8, 1.25);
}

ActionId PickWeighted(const std::vector<Weighted>& options, Rng& rng) {
  std::vector<double> weights;
  for (const Weighted& w : options) weights.push_back(w.weight);
  return options[rng.Weighted(weights)].id;
}

}  // namespace

int64_t ClipScript::num_frames() const {
  return std::max<int64_t>(1, static_cast<int64_t>(std::llround(duration * fps)));
}

size_t ClipScript::BaseAt(double t) const {
  for (size_t k = 0; k < base.size(); ++k) {
    if (t < base[k].end) return k;
  }
  return base.empty() ? 0 : base.size() - 1;
}

double NaturalDuration(const ActionInstance& instance, Rng& rng) {
  const ActionDef& def = Def(instance.id);
  const Tempo tempo = TempoOf(instance.id);
  if (tempo.period > 0 && instance.reps > 0)
    return tempo.lead + instance.reps * tempo.period / instance.speed;
  if (instance.id == A::kTurnInPlace)
    return 0.7 + std::abs(instance.angle) / (1.8 * instance.speed);
  return rng.Uniform(def.min_seconds, def.max_seconds) / std::sqrt(instance.speed);
}

void RetextInstance(ActionInstance* instance, Rng& rng) {
  instance->label = SampleLabel(instance->id, instance->text_params(), rng);
  instance->caption = SampleCaption(instance->id, instance->text_params(), rng);
}

ActionInstance SampleInstance(ActionId id, Rng& rng) {
  const ActionDef& def = Def(id);
  ActionInstance a;
  a.id = id;
  if (def.sided) {
    a.side = rng.Bernoulli(0.5) ? Side::kRight : Side::kLeft;
    if (def.allows_both && rng.Bernoulli(0.2)) a.side = Side::kBoth;
  }
  a.speed = SampleSpeed(rng);
  a.amplitude = rng.Uniform(0.6, 1.4);
  if (def.max_reps > 0) a.reps = rng.Int(def.min_reps, def.max_reps);
  a.turn_left = rng.Bernoulli(0.5);
  a.angle = (a.turn_left ? 1 : -1) * rng.Uniform(kPi / 3, kPi);
  a.start = 0;
  a.end = NaturalDuration(a, rng);
  RetextInstance(&a, rng);
  return a;
}

ActorStyle SampleStyle(Rng& rng) {
  ActorStyle s;
  s.speed_scale = rng.Uniform(0.92, 1.08);
  s.amplitude_scale = rng.Uniform(0.9, 1.1);
  s.posture_lean = rng.Normal(0, 0.035);
  s.arm_swing = rng.Uniform(0.7, 1.3);
  s.stance_width = rng.Uniform(0.09, 0.12);
  s.toe_out = rng.Uniform(0.03, 0.12);
  s.arm_hang_out = rng.Uniform(0.02, 0.07);
  s.sway = rng.Uniform(0.6, 1.4);
  s.noise_seed = rng.Next();
  return s;
}

ActorStyle JitterStyle(const ActorStyle& style, Rng& rng) {
  ActorStyle s = style;
  s.speed_scale *= 1 + rng.Normal(0, 0.01);
  s.amplitude_scale *= 1 + rng.Normal(0, 0.015);
  s.posture_lean += rng.Normal(0, 0.004);
  s.arm_swing *= 1 + rng.Normal(0, 0.03);
  s.stance_width += rng.Normal(0, 0.002);
  s.sway *= 1 + rng.Normal(0, 0.05);
  s.noise_seed = rng.Next();  // the idle noise is never the same twice
  return s;
}

ClipScript SampleScript(Rng& rng, const ScriptOptions& options, const std::string& id) {
  ClipScript script;
  script.id = id;
  script.fps = options.fps;
  script.style = SampleStyle(rng);
  script.start_x = rng.Uniform(-2, 2);
  script.start_y = rng.Uniform(-2, 2);
  script.start_facing = rng.Uniform(-kPi, kPi);
  script.start_seated = rng.Bernoulli(0.05);

  const int segments = static_cast<int>(rng.Weighted({0.4, 0.4, 0.2})) + 1;
  double t = 0;
  bool seated = script.start_seated;
  for (int k = 0; k < segments || t < options.min_seconds; ++k) {
    if (t >= options.max_seconds - 1.0) break;
    ActionId action;
    if (seated) {
      action = A::kStandUp;
    } else {
      do {
        action = PickWeighted(BaseWeights(), rng);
      } while (!script.base.empty() && action == A::kStand && script.base.back().id == A::kStand);
    }
    ActionInstance a = SampleInstance(action, rng);
    double length = a.end;
    length = std::min(length, options.max_seconds - t);
    if (length < 0.8) break;
    a.start = t;
    a.end = t + length;
    t = a.end;
    seated = action == A::kSitDown;
    script.base.push_back(a);
    if (seated && k + 1 >= segments && t >= options.min_seconds) break;
  }
  if (script.base.empty()) {
    ActionInstance a = SampleInstance(A::kStand, rng);
    a.end = options.min_seconds;
    script.base.push_back(a);
  }
  script.duration = script.base.back().end;

  // Overlays, performed jointly with their base action.
  for (size_t k = 0; k < script.base.size(); ++k) {
    ActionInstance& base = script.base[k];
    if (base.id == A::kStandUp || base.id == A::kJumpingJacks) continue;
    double window_start = base.start + 0.2;
    if (base.id == A::kSitDown) window_start = base.start + 0.6 * base.duration();  // once seated
    const double window_end = base.end - 0.2;
    if (window_end - window_start < 1.2) continue;
    const bool lone_stand = base.id == A::kStand;
    if (!rng.Bernoulli(lone_stand ? 0.75 : options.overlay_probability)) continue;
    PartSet used = PartsOf(base.id, base.side);
    const int count = rng.Bernoulli(options.second_overlay_probability) ? 2 : 1;
    double cursor = window_start;
    for (int n = 0; n < count; ++n) {
      std::vector<Weighted> candidates;
      for (const Weighted& w : OverlayWeights()) {
        const ActionDef& def = Def(w.id);
        if (def.kind == ActionKind::kTorso && !TorsoOverlayAllowed(base.id)) continue;
        candidates.push_back(w);
      }
      ActionInstance o;
      bool found = false;
      for (int attempt = 0; attempt < 20 && !found; ++attempt) {
        o = SampleInstance(PickWeighted(candidates, rng), rng);
        found = (PartsOf(o.id, o.side) & used) == 0;
      }
      if (!found) break;
      const double room = window_end - cursor;
      if (room < 1.0) break;
      const double length = std::min(o.end, room);
      // Two overlays may overlap in time (wave while looking around) or follow each other.
      const double start = count == 2 && n == 1 && rng.Bernoulli(0.5)
                               ? rng.Uniform(window_start, window_end - length)
                               : cursor + rng.Uniform(0, room - length);
      o.start = start;
      o.end = start + length;
      used |= PartsOf(o.id, o.side);
      cursor = std::min(window_end, o.end + 0.1);
      script.overlays.push_back(o);
    }
    if (lone_stand && !script.overlays.empty() && script.overlays.back().start >= base.start &&
        script.overlays.back().end <= base.end) {
      base.annotated = rng.Bernoulli(options.annotate_stand_probability);
    }
  }
  return script;
}

std::string VerbPhrase(const ActionInstance& a, Person person) {
  const std::string your = person == Person::kSecond ? "your" : "their";
  std::string side = a.side == Side::kLeft ? "left" : (a.side == Side::kBoth ? "both" : "right");
  const std::string dir = a.turn_left ? "left" : "right";
  const std::string arm = a.side == Side::kBoth ? "both arms" : "the " + side + " arm";
  const std::string hand = a.side == Side::kBoth ? "both hands" : "the " + side + " hand";
  switch (a.id) {
    case A::kStand:
      return "stand still";
    case A::kWalk:
      return "walk";
    case A::kJog:
      return "jog";
    case A::kRun:
      return "run";
    case A::kWalkBackwards:
      return "walk backwards";
    case A::kSideStep:
      return "step to the " + dir;
    case A::kTurnInPlace:
      return "turn " + dir;
    case A::kWalkCircle:
      return "walk in a circle";
    case A::kJump:
      return "jump";
    case A::kHop:
      return "hop on the " + side + " foot";
    case A::kMarchInPlace:
      return "march in place";
    case A::kSitDown:
      return "sit down";
    case A::kStandUp:
      return "stand up";
    case A::kSquat:
      return "squat";
    case A::kKneel:
      return "kneel";
    case A::kCrouch:
      return "crouch";
    case A::kBow:
      return "bow";
    case A::kJumpingJacks:
      return "do jumping jacks";
    case A::kSway:
      return "sway";
    case A::kTiptoe:
      return "stand on " + your + " toes";
    case A::kKick:
      return "kick with the " + side + " leg";
    case A::kKneeLift:
      return "lift the " + side + " knee";
    case A::kStomp:
      return "stomp with the " + side + " foot";
    case A::kStretchLeg:
      return "stretch the " + side + " leg";
    case A::kWave:
      return "wave with " + hand;
    case A::kRaiseArm:
      return "raise " + arm;
    case A::kPunch:
      return "punch with " + hand;
    case A::kClap:
      return "clap";
    case A::kReachForward:
      return "reach forward with " + hand;
    case A::kArmCircle:
      return "circle " + arm;
    case A::kThrow:
      return "throw with " + hand;
    case A::kDrink:
      return "drink";
    case A::kHandsOnHips:
      return "put " + your + " hands on " + your + " hips";
    case A::kCrossArms:
      return "cross " + your + " arms";
    case A::kPoint:
      return "point with " + hand;
    case A::kSalute:
      return "salute";
    case A::kScratchHead:
      return "scratch " + your + " head";
    case A::kShrug:
      return "shrug";
    case A::kStretchArms:
      return "stretch " + your + " arms up";
    case A::kBendForward:
      return "bend forward";
    case A::kLean:
      return "lean to the " + side;
    case A::kTwist:
      return "twist to the " + side;
    case A::kNod:
      return "nod";
    case A::kShakeHead:
      return "shake " + your + " head";
    case A::kLookAround:
      return "look around";
    case A::kLookUp:
      return "look up";
    default:
      return "move";
  }
}

PartSet PartsAt(const ClipScript& script, double t) {
  PartSet parts = 0;
  if (!script.base.empty()) {
    const ActionInstance& base = script.base[script.BaseAt(t)];
    parts |= PartsOf(base.id, base.side);
  }
  for (const ActionInstance& o : script.overlays) {
    if (t >= o.start && t < o.end) parts |= PartsOf(o.id, o.side);
  }
  return parts;
}

}  // namespace motionpipe::corpus
