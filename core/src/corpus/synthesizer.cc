#include "motionpipe/corpus/synthesizer.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "motionpipe/motion/pose_solver.h"

namespace motionpipe::corpus {

namespace {

using A = ActionId;

constexpr double kFadeSeconds = 0.4;    // cross-fade between consecutive base actions
constexpr double kReachMargin = 0.985;  // planted legs never fully straighten
constexpr int kLeft = 0, kRight = 1;

// ---------------------------------------------------------------------------------------------
// Small curve helpers.

double Clamp01(double x) { return std::clamp(x, 0.0, 1.0); }
double Smooth(double x) {
  x = Clamp01(x);
  return x * x * (3 - 2 * x);
}
double Lerp(double a, double b, double w) { return a + (b - a) * w; }
Vec3 Lerp(const Vec3& a, const Vec3& b, double w) { return a + w * (b - a); }
// 0 -> 1 over `in` seconds at the start and 1 -> 0 over `out` seconds at the end of [0, length].
double Envelope(double tau, double length, double in, double out) {
  return Smooth(tau / in) * Smooth((length - tau) / out);
}
double AngleLerp(double a, double b, double w) {
  double d = std::remainder(b - a, 2 * kPi);
  return a + d * w;
}

// Piecewise smoothstep through (u, value) keys, u increasing; clamps outside.
template <typename T>
T Keys(const std::vector<std::pair<double, T>>& keys, double u) {
  if (u <= keys.front().first) return keys.front().second;
  for (size_t k = 1; k < keys.size(); ++k) {
    if (u <= keys[k].first) {
      const double w = Smooth((u - keys[k - 1].first) / (keys[k].first - keys[k - 1].first));
      return Lerp(keys[k - 1].second, keys[k].second, w);
    }
  }
  return keys.back().second;
}

// Smooth pseudo-random signal in about [-1, 1]: three incommensurate sines with seeded phases.
class SmoothNoise {
 public:
  SmoothNoise(uint64_t seed, double base_frequency) {
    Rng rng(seed);
    for (int k = 0; k < 3; ++k) {
      frequency_[k] = base_frequency * (1.0 + 0.73 * k) * rng.Uniform(0.8, 1.25);
      phase_[k] = rng.Uniform(0, 2 * kPi);
    }
  }
  double operator()(double t) const {
    return 0.5 * std::sin(2 * kPi * frequency_[0] * t + phase_[0]) +
           0.3 * std::sin(2 * kPi * frequency_[1] * t + phase_[1]) +
           0.2 * std::sin(2 * kPi * frequency_[2] * t + phase_[2]);
  }

 private:
  double frequency_[3]{};
  double phase_[3]{};
};

// Blends two shoulder-to-wrist offsets along an arc: direction by slerp, length linearly. A linear
// blend between a hanging and a raised arm would pass the hand through the shoulder.
Vec3 ArcBlend(const Vec3& a, const Vec3& b, double w) {
  const double la = Norm(a), lb = Norm(b);
  if (la < 1e-9 || lb < 1e-9) return Lerp(a, b, w);
  const Vec3 ua = (1.0 / la) * a, ub = (1.0 / lb) * b;
  const double angle = std::acos(std::clamp(Dot(ua, ub), -1.0, 1.0));
  Vec3 dir;
  if (angle < 1e-6) {
    dir = ua;
  } else if (kPi - angle < 1e-3) {
    dir = Lerp(ua, ub, w);  // opposite directions: any arc will do; keep it finite
    if (Norm(dir) < 1e-6) dir = Vec3{0, 0, 1};
    dir = (1.0 / Norm(dir)) * dir;
  } else {
    dir = (std::sin((1 - w) * angle) / std::sin(angle)) * ua +
          (std::sin(w * angle) / std::sin(angle)) * ub;
  }
  return Lerp(la, lb, w) * dir;
}

Vec3 Forward(double facing) { return {std::cos(facing), std::sin(facing), 0}; }
Vec3 LeftOf(double facing) { return {-std::sin(facing), std::cos(facing), 0}; }
double SideSign(int side) { return side == kLeft ? 1.0 : -1.0; }
int SideIndex(Side side) { return side == Side::kLeft ? kLeft : kRight; }

// ---------------------------------------------------------------------------------------------
// Base layer: what a base action asks of the body at local time tau.

enum class FootMode { kSupport, kGait, kScripted, kFlight };
enum class ScriptReference { kPlant, kPath };

struct FootRequest {
  FootMode mode = FootMode::kSupport;
  // kScripted: ankle offset (forward, left, up) from the reference, the foot's pitch (toes up +).
  ScriptReference reference = ScriptReference::kPlant;
  Vec3 offset;
  double pitch = 0;
  double knee_down = 0;  // 0..1: point the knee down (kneeling)
  // kFlight: absolute times of takeoff and landing and the tuck height at mid-flight.
  double takeoff = 0, landing = 0, tuck = 0;
};

enum class ArmStyle { kHang, kRun, kSeated, kForward, kBalance, kJacks, kJumpSwing };

struct BaseFrame {
  double speed_forward = 0, speed_left = 0, facing_rate = 0;
  double height = 0;  // nominal pelvis height
  Vec3 pelvis_angles, spine, head;
  double offset_forward = 0, offset_left = 0;  // pelvis shift from the path point, body frame
  ArmStyle arm_style = ArmStyle::kHang;
  double arm_param = 0;
  ArmStyle previous_arm_style = ArmStyle::kHang;  // during a cross-fade: the previous action's arms
  double previous_arm_param = 0;
  double arm_fade = 1;   // weight of this action's arms (1 = no fade)
  double arm_swing = 0;  // gait arm swing amount
  double stance_width = 0.1;
  double heel_raise = 0;  // radians: planted feet pivot on their toes
  FootRequest feet[2];
  bool gait = false;
  double cycle = 1, duty = 0.62, clearance = 0.06, lead = 1;
  bool heel_toe = true;
  double settle_threshold = 0.10;  // metres of foot error that trigger a corrective step
  double settle_lead = 0;          // seconds of path velocity added to a corrective step's target
};

BaseFrame Blend(const BaseFrame& a, const BaseFrame& b, double w) {
  BaseFrame out = b;
  out.height = Lerp(a.height, b.height, w);
  out.pelvis_angles = Lerp(a.pelvis_angles, b.pelvis_angles, w);
  out.spine = Lerp(a.spine, b.spine, w);
  out.head = Lerp(a.head, b.head, w);
  out.offset_forward = Lerp(a.offset_forward, b.offset_forward, w);
  out.offset_left = Lerp(a.offset_left, b.offset_left, w);
  out.arm_swing = Lerp(a.arm_swing, b.arm_swing, w);
  out.stance_width = Lerp(a.stance_width, b.stance_width, w);
  out.heel_raise = Lerp(a.heel_raise, b.heel_raise, w);
  out.previous_arm_style = a.arm_style;
  out.previous_arm_param = a.arm_param;
  out.arm_fade = w;
  return out;
}

struct Context {
  const ActorStyle* style;
  double standing_height;
  double seat_height;
  double seat_back;
  double foot_length;
};

// What an action's base layer reads at one instant: the instance, the actor and the derived
// scales every family uses.
struct BaseInput {
  const ActionInstance& a;
  const Context& ctx;
  const ActorStyle& style;
  double tau;       // seconds since the action started
  double D;         // its duration
  double v_scale;   // its speed times the actor's
  double amp;       // its amplitude times the actor's, clamped
  double H0;        // standing pelvis height
  double ramp;      // 0 -> 1 -> 0 over 0.6 s at either end
  int side, other;  // the side the action names and the opposite one
};

// ---- Locomotion: the path moves, the feet follow a gait or step to keep up.

void Walk(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double v = std::clamp((in.a.id == A::kWalk ? 1.15 : 0.95) * in.v_scale, 0.5, 1.9);
  f.speed_forward = v * in.ramp;
  f.gait = true;
  f.duty = 0.62;
  f.cycle = std::clamp(0.62 / (v * f.duty), 0.85, 1.3);
  f.clearance = 0.08;
  f.arm_swing = 1;
  f.height = in.H0 - 0.01;
  if (in.a.id == A::kWalkCircle) {
    const double radius = 0.9 + 0.8 * in.amp;
    f.facing_rate = (in.a.turn_left ? 1 : -1) * f.speed_forward / radius;
  } else {
    f.facing_rate = 0.05 * in.a.angle / kPi * in.ramp;  // a gently drifting heading
  }
}

void JogOrRun(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const bool jog = in.a.id == A::kJog;
  const double v =
      jog ? std::clamp(2.3 * in.v_scale, 1.5, 3.2) : std::clamp(3.3 * in.v_scale, 2.4, 4.3);
  f.speed_forward = v * in.ramp;
  f.gait = true;
  f.duty = jog ? 0.40 : 0.33;
  f.cycle = std::clamp(0.62 / (v * f.duty), jog ? 0.6 : 0.55, jog ? 0.85 : 0.75);
  f.clearance = jog ? 0.11 : 0.16;
  f.heel_toe = false;
  f.arm_style = ArmStyle::kRun;
  f.arm_swing = 1.3;
  f.spine = {jog ? 0.08 : 0.14, 0, 0};
  f.height = in.H0 - (jog ? 0.03 : 0.04);
}

void WalkBackwards(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double v = std::clamp(0.7 * in.v_scale, 0.4, 1.1);
  f.speed_forward = -v * in.ramp;
  f.gait = true;
  f.duty = 0.62;
  f.cycle = std::clamp(0.5 / (v * f.duty), 0.9, 1.4);
  f.clearance = 0.08;
  f.heel_toe = false;
  f.arm_swing = 0.4;
  f.spine = {0.05, 0, 0};
}

void SideStep(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double v = std::clamp(0.5 * in.v_scale, 0.3, 0.8);
  f.speed_left = (in.a.turn_left ? 1 : -1) * v * in.ramp;
  f.settle_threshold = 0.09;
  f.settle_lead = 0.35;
}

void TurnInPlace(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double u = Clamp01(in.tau / in.D);
  f.facing_rate = in.a.angle * 6 * u * (1 - u) / in.D;  // derivative of smoothstep
  f.settle_threshold = 0.08;
}

void MarchInPlace(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  f.gait = true;
  f.duty = 0.5;
  f.cycle = 1.1 / in.v_scale;
  f.clearance = 0.20 * in.amp;
  f.heel_toe = false;
  f.lead = 0;
  f.arm_swing = 1.2;
}

// ---- Jumps: both feet (or one) leave the floor on a schedule of repetitions.

void Jump(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double period = 1.25 / std::sqrt(in.v_scale);
  const double local = in.tau - 0.2;
  const int rep = static_cast<int>(std::floor(local / period));
  if (local < 0 || rep >= std::max(1, in.a.reps)) return;
  const double u = (local - rep * period) / period;
  const double rep_start = in.a.start + 0.2 + rep * period;
  const double crouch = 0.16 * in.amp, apex = 0.10 + 0.15 * in.amp;
  const bool forward = in.a.angle > 0;
  if (u < 0.3) {
    f.height = in.H0 - crouch * Smooth(u / 0.3);
    f.arm_style = ArmStyle::kJumpSwing;
    f.arm_param = u;
  } else if (u < 0.42) {
    f.height = Lerp(in.H0 - crouch, in.H0 + 0.03, Smooth((u - 0.3) / 0.12));
    f.arm_style = ArmStyle::kJumpSwing;
    f.arm_param = u;
  } else if (u < 0.72) {
    const double s = (u - 0.42) / 0.30;
    f.height = in.H0 + 0.03 + 4 * apex * s * (1 - s);
    const double flight = 0.30 * period;
    if (forward) f.speed_forward = 0.35 * in.amp / flight;
    for (FootRequest& foot : f.feet) {
      foot.mode = FootMode::kFlight;
      foot.takeoff = rep_start + 0.42 * period;
      foot.landing = rep_start + 0.72 * period;
      foot.tuck = 0.10 * in.amp;
    }
    f.arm_style = ArmStyle::kJumpSwing;
    f.arm_param = u;
  } else if (u < 0.86) {
    f.height = Lerp(in.H0 + 0.03, in.H0 - 0.13 * in.amp, Smooth((u - 0.72) / 0.14));
    f.arm_style = ArmStyle::kJumpSwing;
    f.arm_param = u;
  } else {
    f.height = Lerp(in.H0 - 0.13 * in.amp, in.H0, Smooth((u - 0.86) / 0.14));
  }
}

void Hop(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  // `side` hops; the other leg is held up behind.
  const double lift = Envelope(in.tau, in.D, 0.35, 0.35);
  f.feet[in.other].mode = FootMode::kScripted;
  f.feet[in.other].reference = ScriptReference::kPath;
  f.feet[in.other].offset = {-0.12 * Smooth((lift - 0.3) / 0.7), 0,
                             0.28 * lift};  // up first, then back
  f.feet[in.other].pitch = -0.3 * lift;
  f.offset_left = SideSign(in.side) * 0.08 * lift;
  f.arm_style = ArmStyle::kBalance;
  f.arm_param = lift;
  const double period = 0.55 / std::sqrt(in.v_scale);
  const double local = in.tau - 0.4;
  const int rep = static_cast<int>(std::floor(local / period));
  if (local < 0 || rep >= std::max(1, in.a.reps)) return;
  const double u = (local - rep * period) / period;
  const double rep_start = in.a.start + 0.4 + rep * period;
  if (u < 0.45) {
    f.height = in.H0 - 0.08 * std::sin(kPi * u / 0.45);
  } else if (u < 0.9) {
    const double s = (u - 0.45) / 0.45;
    f.height = in.H0 + 4 * (0.05 + 0.05 * in.amp) * s * (1 - s);
    f.speed_forward = 0.22 * in.amp / (0.45 * period);
    f.feet[in.side].mode = FootMode::kFlight;
    f.feet[in.side].takeoff = rep_start + 0.45 * period;
    f.feet[in.side].landing = rep_start + 0.9 * period;
    f.feet[in.side].tuck = 0.05;
  }
}

void JumpingJacks(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double period = 1.0 / std::sqrt(in.v_scale);
  const double local = in.tau - 0.2;
  const int rep = static_cast<int>(std::floor(local / period));
  if (local < 0 || rep >= std::max(1, in.a.reps)) return;
  const double u = (local - rep * period) / period;
  const bool out = u < 0.5;  // this half-cycle lands wide (arms up)
  const double h = out ? u / 0.5 : (u - 0.5) / 0.5;
  const double half_start = in.a.start + 0.2 + rep * period + (out ? 0 : 0.5 * period);
  const double width_from = out ? in.style.stance_width : 0.26;
  const double width_to = out ? 0.26 : in.style.stance_width;
  const double arm_from = out ? 0.0 : 1.0, arm_to = out ? 1.0 : 0.0;
  f.arm_style = ArmStyle::kJacks;
  if (h < 0.2) {
    f.height = in.H0 - 0.05 * std::sin(kPi * h / 0.2);
    f.stance_width = width_from;
    f.arm_param = arm_from;
  } else if (h < 0.75) {
    const double s = (h - 0.2) / 0.55;
    f.height = in.H0 + 0.02 + 4 * (0.08 + 0.04 * in.amp) * s * (1 - s);
    f.stance_width = s < 0.5 ? width_from : width_to;
    f.arm_param = Lerp(arm_from, arm_to, Smooth(s));
    for (FootRequest& foot : f.feet) {
      foot.mode = FootMode::kFlight;
      foot.takeoff = half_start + 0.2 * 0.5 * period;
      foot.landing = half_start + 0.75 * 0.5 * period;
      foot.tuck = 0.06;
    }
  } else {
    f.height = in.H0 - 0.06 * std::sin(kPi * (h - 0.75) / 0.25);
    f.stance_width = width_to;
    f.arm_param = arm_to;
  }
}

// ---- Posture: the pelvis lowers and the trunk bends; the feet stay planted or kneel.

void SitDown(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double descent = 1.4 / std::sqrt(in.v_scale);
  const double u = Clamp01((in.tau - 0.3) / descent);
  f.height = Lerp(in.H0, in.ctx.seat_height, Smooth(u));
  f.offset_forward = -in.ctx.seat_back * Smooth(u);
  f.spine = {Keys<double>({{0, 0.0}, {0.45, 0.45}, {1, 0.10}}, u), 0, 0};
  f.head = {-0.3 * f.spine.x, 0, 0};
  f.arm_style = ArmStyle::kSeated;
  f.arm_param = Smooth((u - 0.6) / 0.4);
}

void StandUp(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double rise = 1.4 / std::sqrt(in.v_scale);
  const double u = Clamp01(in.tau / rise);
  const double w = Smooth((u - 0.25) / 0.75);
  f.height = Lerp(in.ctx.seat_height, in.H0, w);
  f.offset_forward = -in.ctx.seat_back * (1 - w);
  f.spine = {Keys<double>({{0, 0.10}, {0.3, 0.55}, {1, 0.0}}, u), 0, 0};
  f.head = {-0.3 * f.spine.x, 0, 0};
  f.arm_style = ArmStyle::kSeated;
  f.arm_param = 1 - Smooth(u / 0.4);
}

void Squat(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double period = 2.2 / in.a.speed;
  const double local = in.tau - 0.15;
  const int rep = static_cast<int>(std::floor(local / period));
  double depth = 0;
  if (local >= 0 && rep < std::max(1, in.a.reps)) {
    const double u = (local - rep * period) / period;
    depth = Keys<double>({{0, 0.0}, {0.45, 1.0}, {0.55, 1.0}, {1, 0.0}}, u);
  }
  f.height = in.H0 - 0.36 * in.amp * depth;
  f.offset_forward = -0.10 * in.amp * depth;
  f.spine = {0.45 * in.amp * depth, 0, 0};
  f.head = {-0.25 * in.amp * depth, 0, 0};
  f.arm_style = ArmStyle::kForward;
  f.arm_param = depth;
}

void Kneel(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double down = 1.0 / std::sqrt(in.v_scale);
  const double hold_end = in.D - down;
  const double u =
      in.tau < hold_end ? Clamp01(in.tau / down) : 1 - Clamp01((in.tau - hold_end) / down);
  FootRequest& knee = f.feet[in.side];
  knee.mode = FootMode::kScripted;
  knee.reference = ScriptReference::kPlant;
  // Step back with the foot lifted, then rest on the toes: ankle height = foot length *
  // sin(pitch).
  const double toe_height = in.ctx.foot_length * std::sin(1.15);
  knee.offset = Keys<Vec3>({{0, {0, 0, 0}},
                            {0.3, {-0.06, 0, 0.10}},
                            {0.65, {-0.30, 0, 0.14}},
                            {1, {-0.40, 0, toe_height}}},
                           u);
  knee.pitch = -1.15 * Smooth((u - 0.2) / 0.8);
  knee.knee_down = Smooth(u);
  f.height = Lerp(in.H0, 0.47, Smooth(u));
  f.spine = {0.12 * std::sin(kPi * u), 0, 0};
  f.arm_style = ArmStyle::kBalance;
  f.arm_param = 0.3 * Smooth(u);
}

void Crouch(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double down = 0.8 / std::sqrt(in.v_scale);
  const double u = Envelope(in.tau, in.D, down, down);
  f.height = in.H0 - 0.30 * in.amp * u;
  f.offset_forward = -0.06 * in.amp * u;
  f.spine = {0.6 * in.amp * u, 0, 0};
  f.head = {-0.35 * u, 0, 0};
  f.arm_style = ArmStyle::kForward;
  f.arm_param = 0.6 * u;
}

void Bow(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double u =
      Keys<double>({{0, 0.0}, {0.35, 1.0}, {0.6, 1.0}, {1, 0.0}}, Clamp01(in.tau / in.D));
  f.spine = {0.55 * in.amp * u, 0, 0};
  f.pelvis_angles = {0.25 * in.amp * u, 0, 0};
  f.offset_forward = -0.06 * in.amp * u;
  f.head = {-0.1 * u, 0, 0};
}

// ---- Balance: weight shifts over planted feet.

void Sway(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double env = Envelope(in.tau, in.D, 0.5, 0.5);
  const double s = std::sin(2 * kPi * 0.33 * in.v_scale * in.tau);
  f.offset_left = 0.07 * in.amp * s * env;
  f.spine = {0, 0, 0.15 * in.amp * s * env};  // lean with the weight shift
  f.pelvis_angles = {0, 0, -0.05 * in.amp * s * env};
}

void Tiptoe(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double env =
      Envelope(in.tau, in.D, 0.5 / std::sqrt(in.v_scale), 0.5 / std::sqrt(in.v_scale));
  f.heel_raise = 0.55 * in.amp * env;
  f.height = in.H0 + 0.08 * in.amp * env;
  f.arm_style = ArmStyle::kBalance;
  f.arm_param = 0.3 * env;
}

// ---- One leg: the other carries the weight while this one is scripted.

void KickKneeLiftOrStomp(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double shift = Envelope(in.tau, in.D, 0.35, 0.35);
  f.offset_left = -SideSign(in.side) * 0.07 * shift;  // weight over the standing leg
  f.arm_style = ArmStyle::kBalance;
  f.arm_param = shift;
  const double period = (in.a.id == A::kStomp ? 1.0 : 1.3) / std::sqrt(in.v_scale);
  const double local = in.tau - 0.4;
  const int rep = static_cast<int>(std::floor(local / period));
  if (local < 0 || rep >= std::max(1, in.a.reps)) return;
  const double u = (local - rep * period) / period;
  FootRequest& foot = f.feet[in.side];
  foot.mode = FootMode::kScripted;
  foot.reference = ScriptReference::kPlant;
  const double reach = std::clamp(in.amp, 0.6, 1.2);
  if (in.a.id == A::kKick) {
    foot.offset = Keys<Vec3>({{0, {0, 0, 0}},
                              {0.1, {0.0, 0, 0.07}},
                              {0.25, {0.12, 0, 0.22}},
                              {0.45, {0.42 * reach, 0, 0.48 * reach}},
                              {0.6, {0.15, 0, 0.22}},
                              {0.85, {0.0, 0, 0.02}},
                              {1, {0, 0, 0}}},
                             u);
    foot.pitch = -0.45 * Keys<double>({{0, 0.0}, {0.45, 1.0}, {0.85, 0.0}}, u);
    f.spine = {-0.15 * Keys<double>({{0, 0.0}, {0.45, 1.0}, {0.8, 0.0}}, u), 0, 0};
  } else if (in.a.id == A::kKneeLift) {
    foot.offset = Keys<Vec3>({{0, {0, 0, 0}},
                              {0.12, {0.0, 0, 0.08}},
                              {0.35, {0.15, 0, 0.38 * reach}},
                              {0.6, {0.15, 0, 0.38 * reach}},
                              {0.9, {0.0, 0, 0.06}},
                              {1, {0, 0, 0}}},
                             u);
    foot.pitch = -0.3 * Keys<double>({{0, 0.0}, {0.35, 1.0}, {0.6, 1.0}, {1, 0.0}}, u);
  } else {
    foot.offset = Keys<Vec3>(
        {{0, {0, 0, 0}}, {0.55, {0.04, 0, 0.24 * reach}}, {0.65, {0.02, 0, 0.0}}, {1, {0, 0, 0}}},
        u);
  }
}

void StretchLeg(const BaseInput& in, BaseFrame* frame) {
  BaseFrame& f = *frame;
  const double out_time = 0.6 / std::sqrt(in.v_scale);
  const double hold = Envelope(in.tau, in.D, out_time, out_time);
  FootRequest& foot = f.feet[in.side];
  foot.mode = FootMode::kScripted;
  foot.reference = ScriptReference::kPlant;
  const double reach = 0.40 * std::clamp(in.amp, 0.7, 1.2);
  // The foot rises, travels sideways and is set down; the way back mirrors it.
  const double lift = std::sin(kPi * Clamp01(in.tau / out_time)) +
                      std::sin(kPi * Clamp01((in.tau - (in.D - out_time)) / out_time));
  const double travel =
      Smooth((in.tau - 0.15 * out_time) / (0.7 * out_time)) *
      (1 - Smooth((in.tau - (in.D - out_time) - 0.15 * out_time) / (0.7 * out_time)));
  foot.offset = {0, SideSign(in.side) * reach * travel, 0.09 * lift};
  f.offset_left = -SideSign(in.side) * 0.10 * hold;  // over the bending leg
  f.height = in.H0 - 0.14 * hold * std::clamp(in.amp, 0.7, 1.2);
  f.spine = {0.1 * hold, 0, -SideSign(in.side) * 0.05 * hold};
  f.arm_style = ArmStyle::kBalance;
  f.arm_param = 0.5 * hold;
}

using BaseFunction = void (*)(const BaseInput& in, BaseFrame* frame);

// The table of base actions: each action's function (none for kStand and the overlay-only ones,
// whose base layer is the standing default).
BaseFunction BaseFunctionOf(ActionId id) {
  switch (id) {
    case A::kWalk:
    case A::kWalkCircle:
      return Walk;
    case A::kJog:
    case A::kRun:
      return JogOrRun;
    case A::kWalkBackwards:
      return WalkBackwards;
    case A::kSideStep:
      return SideStep;
    case A::kTurnInPlace:
      return TurnInPlace;
    case A::kJump:
      return Jump;
    case A::kHop:
      return Hop;
    case A::kMarchInPlace:
      return MarchInPlace;
    case A::kSitDown:
      return SitDown;
    case A::kStandUp:
      return StandUp;
    case A::kSquat:
      return Squat;
    case A::kKneel:
      return Kneel;
    case A::kCrouch:
      return Crouch;
    case A::kBow:
      return Bow;
    case A::kJumpingJacks:
      return JumpingJacks;
    case A::kSway:
      return Sway;
    case A::kTiptoe:
      return Tiptoe;
    case A::kKick:
    case A::kKneeLift:
    case A::kStomp:
      return KickKneeLiftOrStomp;
    case A::kStretchLeg:
      return StretchLeg;
    default:
      return nullptr;
  }
}

BaseFrame EvaluateBase(const ActionInstance& a, double tau, const Context& ctx) {
  const ActorStyle& style = *ctx.style;
  const double D = a.duration();
  const double H0 = ctx.standing_height;
  const int side = SideIndex(a.side);
  const BaseInput in{a,
                     ctx,
                     style,
                     tau,
                     D,
                     a.speed * style.speed_scale,
                     std::clamp(a.amplitude * style.amplitude_scale, 0.5, 1.3),
                     H0,
                     Envelope(tau, D, 0.6, 0.6),
                     side,
                     1 - side};
  BaseFrame f;
  f.height = H0;
  f.stance_width = style.stance_width;
  if (const BaseFunction evaluate = BaseFunctionOf(a.id)) evaluate(in, &f);
  return f;
}

// ---------------------------------------------------------------------------------------------
// Overlays: arm goals in the chest frame (x = outward for that arm, y = up, z = forward, relative
// to the shoulder), torso and head angles, and how much they slow locomotion.

struct ArmGoal {
  double weight = 0;
  Vec3 offset;
  Vec3 pole{0.3, -0.5, -1};
  double collar = 0;
  Vec3 wrist;
};

struct OverlayFrame {
  ArmGoal arms[2];
  Vec3 spine, head;
  double slow = 0;
};

void AddArm(OverlayFrame* out, int side, double weight, const Vec3& offset, const Vec3& pole,
            double collar = 0, const Vec3& wrist = {}) {
  ArmGoal& g = out->arms[side];
  // Two overlays rarely share an arm; if they do, the later one wins where it is stronger.
  if (weight < g.weight) return;
  g = {weight, offset, pole, collar, wrist};
}

// What an overlay action reads at one instant (the base actions' BaseInput for the upper body).
struct OverlayInput {
  const ActionInstance& a;
  const ActorStyle& style;
  double tau;              // seconds since the action started
  double D;                // its duration
  double v;                // its speed times the actor's
  double amp;              // its amplitude times the actor's, clamped
  double env;              // 0 -> 1 -> 0 over 0.35 s at either end (> 0 here)
  std::vector<int> sides;  // the arms it moves
};

void Wave(const OverlayInput& in, OverlayFrame* out) {
  const double f = in.a.reps > 0 ? in.a.reps / std::max(0.5, in.D - 0.9) : 1.8 * in.v;
  const double swing =
      0.10 * in.amp * std::sin(2 * kPi * f * (in.tau - 0.45)) * Smooth((in.tau - 0.3) / 0.3);
  for (int s : in.sides) {
    AddArm(out, s, in.env, {0.12 + swing, 0.30, 0.08}, {1, -1, 0}, 0.06, {0, 0, 0.3 * swing});
    out->spine.z += (s == kRight ? -1 : 1) * 0.04 * in.env;
  }
}

void RaiseArm(const OverlayInput& in, OverlayFrame* out) {
  const double elevation = std::clamp(2.0 + 0.8 * (in.amp - 1), 1.5, 2.8);  // radians from hanging
  const double u = Envelope(in.tau, in.D, 0.5, 0.5);
  for (int s : in.sides) {
    const double e = elevation * u;
    AddArm(out, s, in.env,
           {0.15 * std::sin(e), -0.50 * std::cos(e),
            0.42 * std::sin(e) - 0.3 * std::sin(e) * std::sin(e) * 0.5},
           {0.3, 0, -1}, 0.15 * u * (e > 1.6 ? 1 : 0));
    if (in.a.side != Side::kBoth) out->spine.z += (s == kRight ? -1 : 1) * 0.05 * u;
  }
}

void Punch(const OverlayInput& in, OverlayFrame* out) {
  const int reps = std::max(1, in.a.reps);
  const double period = (in.D - 0.7) / reps;
  const Vec3 guard{-0.12, 0.05, 0.24};
  for (size_t k = 0; k < in.sides.size(); ++k) {
    const int s = in.sides[k];
    double extension = 0;
    const double local = in.tau - 0.35;
    if (local > 0) {
      // With both hands the punches alternate.
      const double offset = in.sides.size() == 2 ? 0.5 * k : 0.0;
      double u = std::fmod(local / period + offset, 1.0);
      const int rep = static_cast<int>(local / period + offset);
      if (rep < reps) extension = Keys<double>({{0, 0.0}, {0.3, 1.0}, {0.45, 1.0}, {1, 0.0}}, u);
    }
    const Vec3 strike{-0.16, 0.05, 0.50 * std::min(1.04, in.amp)};
    AddArm(out, s, in.env, Lerp(guard, strike, extension), {1, -1, -0.3});
    out->spine.y += (s == kRight ? 1 : -1) * 0.10 * extension;
  }
  out->slow = std::max(out->slow, 0.2 * in.env);
}

void Clap(const OverlayInput& in, OverlayFrame* out) {
  const int reps = std::max(1, in.a.reps);
  const double f = reps / std::max(0.5, in.D - 0.7);
  const double close = std::pow(0.5 - 0.5 * std::cos(2 * kPi * f * (in.tau - 0.35)), 2.0) *
                       Smooth((in.tau - 0.35) / 0.2);
  const Vec3 open{-0.10, -0.04, 0.30}, shut{-0.245, -0.05, 0.33};
  for (int s : {kLeft, kRight}) AddArm(out, s, in.env, Lerp(open, shut, close), {1, -1, -0.4});
}

void ReachForward(const OverlayInput& in, OverlayFrame* out) {
  const double u = Envelope(in.tau, in.D, 0.45, 0.45);
  for (int s : in.sides)
    AddArm(out, s, in.env,
           Lerp({0.04, -0.49, 0.05}, {-0.06, 0.02, 0.50 * std::min(1.04, in.amp)}, u),
           {1, -1, -0.2});
  out->spine.x += 0.10 * u * in.amp;
}

void ArmCircle(const OverlayInput& in, OverlayFrame* out) {
  const int reps = std::max(1, in.a.reps);
  const double theta = 2 * kPi * reps * Clamp01((in.tau - 0.35) / std::max(0.5, in.D - 0.7));
  for (int s : in.sides) {
    const double phase = in.a.side == Side::kBoth ? 0 : 0;
    AddArm(out, s, in.env, {0.08, -0.48 * std::cos(theta + phase), 0.48 * std::sin(theta + phase)},
           {1, 0, -1}, 0.12 * Smooth(-std::cos(theta)));
  }
}

void Throw(const OverlayInput& in, OverlayFrame* out) {
  const double u = Clamp01(in.tau / in.D);
  const Vec3 pose = Keys<Vec3>({{0, {0.04, -0.49, 0.03}},
                                {0.35, {0.06, 0.22, -0.26}},
                                {0.55, {-0.05, 0.20, 0.45}},
                                {0.70, {-0.25, -0.30, 0.25}},
                                {1, {0.04, -0.49, 0.03}}},
                               u);
  const double twist = Keys<double>({{0, 0.0}, {0.35, -0.35}, {0.6, 0.35}, {1, 0.0}}, u);
  for (int s : in.sides) {
    AddArm(out, s, in.env, pose, {1, -0.6, -0.5});
    out->spine.y += (s == kRight ? 1 : -1) * twist * in.amp;
  }
}

void Drink(const OverlayInput& in, OverlayFrame* out) {
  const double u = Envelope(in.tau, in.D, 0.6, 0.6);
  for (int s : in.sides)
    AddArm(out, s, in.env, Lerp({0.04, -0.49, 0.03}, {-0.24, 0.24, 0.15}, u), {1, -1, 0});
  out->head.x -= 0.25 * Smooth((u - 0.6) / 0.4);
  out->slow = std::max(out->slow, 0.25 * in.env);
}

void HandsOnHips(const OverlayInput& in, OverlayFrame* out) {
  for (int s : {kLeft, kRight}) AddArm(out, s, in.env, {-0.10, -0.30, -0.03}, {1, 0, -0.5});
}

void CrossArms(const OverlayInput& in, OverlayFrame* out) {
  AddArm(out, kLeft, in.env, {-0.41, -0.15, 0.22}, {1, -1, 0});
  AddArm(out, kRight, in.env, {-0.40, -0.11, 0.19}, {1, -1, 0});
}

void Point(const OverlayInput& in, OverlayFrame* out) {
  const double u = Envelope(in.tau, in.D, 0.4, 0.4);
  for (int s : in.sides)
    AddArm(out, s, in.env, Lerp({0.04, -0.49, 0.03}, {-0.02, 0.05, 0.50}, u), {1, -1, -0.2});
}

void Salute(const OverlayInput& in, OverlayFrame* out) {
  const double u = Envelope(in.tau, in.D, 0.35, 0.35);
  for (int s : in.sides)
    AddArm(out, s, in.env, Lerp({0.04, -0.49, 0.03}, {-0.21, 0.33, 0.12}, u), {1, 0, 0});
}

void ScratchHead(const OverlayInput& in, OverlayFrame* out) {
  const double u = Envelope(in.tau, in.D, 0.4, 0.4);
  const double rub = 0.03 * std::sin(2 * kPi * 3.0 * in.tau) * u;
  for (int s : in.sides)
    AddArm(out, s, in.env, Lerp({0.04, -0.49, 0.03}, {-0.24, 0.42, rub}, u), {1, 0.3, 0});
  out->head.x += 0.1 * u;
}

void Shrug(const OverlayInput& in, OverlayFrame* out) {
  const double u =
      Keys<double>({{0, 0.0}, {0.3, 1.0}, {0.6, 1.0}, {1, 0.0}}, Clamp01(in.tau / in.D));
  for (int s : {kLeft, kRight}) {
    AddArm(out, s, in.env, Lerp({0.04, -0.49, 0.03}, {0.10, -0.38, 0.18}, u), {0.3, 0, -1},
           0.28 * u * in.amp);
  }
}

void StretchArms(const OverlayInput& in, OverlayFrame* out) {
  const double u = Envelope(in.tau, in.D, 0.6, 0.6);
  for (int s : {kLeft, kRight})
    AddArm(out, s, in.env, Lerp({0.04, -0.49, 0.03}, {0.02, 0.52, 0.02}, u), {0.3, 0, -1}, 0.2 * u);
  out->spine.x -= 0.12 * u;
}

void BendForward(const OverlayInput& in, OverlayFrame* out) {
  out->spine.x += 1.0 * in.amp * in.env;
  out->head.x -= 0.3 * in.amp * in.env;
  out->slow = std::max(out->slow, 0.35 * in.env);
}

void Lean(const OverlayInput& in, OverlayFrame* out) {
  out->spine.z += (in.a.side == Side::kLeft ? -1 : 1) * 0.45 * in.amp * in.env;
  out->slow = std::max(out->slow, 0.1 * in.env);
}

void Twist(const OverlayInput& in, OverlayFrame* out) {
  const double u =
      Keys<double>({{0, 0.0}, {0.4, 1.0}, {0.6, 1.0}, {1, 0.0}}, Clamp01(in.tau / in.D));
  out->spine.y += (in.a.side == Side::kLeft ? 1 : -1) * 0.7 * in.amp * u;
  out->slow = std::max(out->slow, 0.1 * in.env);
}

void Nod(const OverlayInput& in, OverlayFrame* out) {
  const double f = std::max(1, in.a.reps) / std::max(0.5, in.D - 0.4);
  out->head.x += 0.30 * in.amp * std::sin(2 * kPi * f * (in.tau - 0.2)) * in.env;
}

void ShakeHead(const OverlayInput& in, OverlayFrame* out) {
  const double f = std::max(1, in.a.reps) / std::max(0.5, in.D - 0.4);
  out->head.y += 0.45 * in.amp * std::sin(2 * kPi * f * (in.tau - 0.2)) * in.env;
}

void LookAround(const OverlayInput& in, OverlayFrame* out) {
  const double yaw =
      0.9 * in.amp * std::sin(2 * kPi * 0.28 * in.v * in.tau + (in.a.turn_left ? 0 : kPi)) * in.env;
  out->head.y += yaw;
  out->head.x -= 0.08 * in.env;
  out->spine.y += 0.25 * yaw;
  out->slow = std::max(out->slow, 0.05 * in.env);
}

void LookUp(const OverlayInput& in, OverlayFrame* out) {
  out->head.x -= 0.55 * in.amp * in.env;
  out->spine.x -= 0.08 * in.env;
}

using OverlayFunction = void (*)(const OverlayInput& in, OverlayFrame* out);

// The table of overlay actions (arms, trunk and head over the base layer).
OverlayFunction OverlayFunctionOf(ActionId id) {
  switch (id) {
    case A::kWave:
      return Wave;
    case A::kRaiseArm:
      return RaiseArm;
    case A::kPunch:
      return Punch;
    case A::kClap:
      return Clap;
    case A::kReachForward:
      return ReachForward;
    case A::kArmCircle:
      return ArmCircle;
    case A::kThrow:
      return Throw;
    case A::kDrink:
      return Drink;
    case A::kHandsOnHips:
      return HandsOnHips;
    case A::kCrossArms:
      return CrossArms;
    case A::kPoint:
      return Point;
    case A::kSalute:
      return Salute;
    case A::kScratchHead:
      return ScratchHead;
    case A::kShrug:
      return Shrug;
    case A::kStretchArms:
      return StretchArms;
    case A::kBendForward:
      return BendForward;
    case A::kLean:
      return Lean;
    case A::kTwist:
      return Twist;
    case A::kNod:
      return Nod;
    case A::kShakeHead:
      return ShakeHead;
    case A::kLookAround:
      return LookAround;
    case A::kLookUp:
      return LookUp;
    default:
      return nullptr;
  }
}

void EvaluateOverlay(const ActionInstance& a, double tau, const ActorStyle& style,
                     OverlayFrame* out) {
  const double D = a.duration();
  const double env = Envelope(tau, D, 0.35, 0.35);
  if (env <= 0) return;
  OverlayInput in{a,
                  style,
                  tau,
                  D,
                  a.speed * style.speed_scale,
                  std::clamp(a.amplitude * style.amplitude_scale, 0.5, 1.3),
                  env,
                  {}};
  if (a.side == Side::kLeft || a.side == Side::kBoth) in.sides.push_back(kLeft);
  if (a.side == Side::kRight || a.side == Side::kBoth) in.sides.push_back(kRight);
  if (Def(a.id).kind == ActionKind::kArm) out->slow = std::max(out->slow, 0.12 * env);
  if (const OverlayFunction evaluate = OverlayFunctionOf(a.id)) evaluate(in, out);
}

// Default arm placement of a base action (chest frame, x = outward, relative to the shoulder).
struct ArmPlacement {
  Vec3 offset;
  Vec3 pole;
  bool gravity = true;  // hangs towards the world's down rather than the chest's
};

ArmPlacement DefaultArm(ArmStyle style, double param, double hang_out) {
  const Vec3 hang{hang_out, -0.495, 0.03};
  const Vec3 hang_pole{0.25, 0, -1};
  switch (style) {
    case ArmStyle::kHang:
      return {hang, hang_pole, true};
    case ArmStyle::kRun:
      return {{0.05, -0.25, 0.20}, {0.1, -0.3, -1}, false};
    case ArmStyle::kSeated:
      return {Lerp(hang, {-0.02, -0.42, 0.27}, param), hang_pole, true};
    case ArmStyle::kForward:
      return {Lerp(hang, {-0.06, -0.05, 0.46}, param), {0.6, -1, -0.3}, param < 0.5};
    case ArmStyle::kBalance:
      return {Lerp(hang, {0.18, -0.42, 0.06}, param), hang_pole, true};
    case ArmStyle::kJacks:
      return {Lerp(hang, {0.24, 0.43, 0.0}, param), {0.3, -1, -0.3}, false};
    case ArmStyle::kJumpSwing: {
      const Vec3 pose = Keys<Vec3>({{0, hang},
                                    {0.3, {0.05, -0.44, -0.20}},
                                    {0.45, {0.03, -0.12, 0.38}},
                                    {0.72, {0.03, -0.20, 0.34}},
                                    {0.86, {0.03, -0.35, 0.24}},
                                    {1, hang}},
                                   param);
      return {pose, hang_pole, false};
    }
  }
  return {hang, hang_pole, true};
}

// ---------------------------------------------------------------------------------------------
// Foot planner.

struct FootPose {
  Vec3 ankle;
  double yaw = 0;
  double pitch = 0;  // toes up +
  double knee_down = 0;
  bool bears_weight =
      true;  // planted, scripted or about to touch down: the pelvis must keep it in reach
  bool flight = false;  // ankle filled in once the pelvis height is known
  double flight_s = 0;
  Vec3 flight_from, flight_to;
  int64_t takeoff_frame = 0, landing_frame = 0;
  double tuck = 0;
};

struct FootState {
  bool swinging = false, scripted = false, flying = false;
  Vec3 plant;  // ankle position of the flat foot (z = 0)
  double yaw = 0;
  // swing
  Vec3 from, to;
  double from_yaw = 0, to_yaw = 0, from_pitch = 0, to_pitch = 0, t0 = 0, t1 = 0, clearance = 0;
  // scripted / flight
  Vec3 anchor;
  double anchor_yaw = 0;
  double last_phase = 0;
};

Vec3 ToeDirection(double yaw, double pitch) {
  return {std::cos(yaw) * std::cos(pitch), std::sin(yaw) * std::cos(pitch), std::sin(pitch)};
}

// The passes of Synthesize over one clip and the per-frame state they hand on: each pass fills its
// arrays from the earlier passes' (layers -> pelvis path -> footsteps -> pelvis placement ->
// poses).
class ClipSynthesizer {
 public:
  ClipSynthesizer(const ClipScript& script, const Skeleton& skeleton);
  Synthesis Run();

 private:
  // Pass 1: base and overlay layers per frame.
  void EvaluateLayers();
  // Pass 2: the pelvis path on the ground (locomotion slows while the upper body is busy).
  void PlanPelvisPath();
  // Pass 3: footsteps.
  void PlanFootsteps();
  // The gait oscillator at frame f; true when a gait starts there.
  bool AdvanceGait(int64_t f);
  void StepFoot(int64_t f, int s, bool fresh_gait);
  // Leaving scripted or flight modes: the foot lands where the mode left it.
  void LeaveScriptedOrFlight(int64_t f, int s);
  // A scripted or flying foot is placed by its mode (true); gait and support feet are not.
  bool PlaceByMode(int64_t f, int s);
  // Gait lift-off: this foot's phase crosses the end of its stance.
  void LiftOff(int64_t f, int s, bool fresh_gait);
  void SwingFoot(int64_t f, int s);
  void PlantedFoot(int64_t f, int s);
  // Corrective steps between actions and while side-stepping or turning.
  void CorrectiveStep(int64_t f);
  // Pass 4: pelvis placement, then the feet in flight.
  void PlacePelvis();
  // Pass 5: upper body and the pose solver.
  void SolvePoses(Synthesis* result) const;
  PoseTargets TrunkTargets(int64_t f) const;
  void PlaceHand(int64_t f, int s, const UpperBodyFrame& chest, PoseTargets* targets) const;
  void PlaceFoot(int64_t f, int s, PoseTargets* targets) const;
  // Ground truth: one segment per annotated action instance.
  void AddSegments(Synthesis* result) const;

  int64_t FrameAt(double t) const {
    return std::clamp<int64_t>(static_cast<int64_t>(std::llround(t * fps_)), 0, frames_ - 1);
  }
  // Where a foot wants to be at frame f: beside the path, facing its way.
  Vec3 Desired(int side, int64_t f) const {
    const auto fi = static_cast<size_t>(std::clamp<int64_t>(f, 0, frames_ - 1));
    return path_[fi] + (SideSign(side) * base_[fi].stance_width) * LeftOf(facing_[fi]);
  }
  double DesiredYaw(int side, int64_t f) const {
    return facing_[static_cast<size_t>(std::clamp<int64_t>(f, 0, frames_ - 1))] +
           SideSign(side) * style_.toe_out;
  }

  const ClipScript& script_;
  const Skeleton& skeleton_;
  const ActorStyle& style_;
  const int64_t frames_;
  const double fps_, dt_;
  const SmoothNoise head_noise_x_, head_noise_y_, spine_noise_;  // the trunk's idle motion
  double leg_[2], foot_length_[2];
  Context ctx_;
  // Pass 1.
  std::vector<BaseFrame> base_;
  std::vector<OverlayFrame> over_;
  std::vector<size_t> base_index_;
  // Pass 2: frames + 1 entries.
  std::vector<Vec3> path_, velocity_;
  std::vector<double> facing_;
  // Pass 3.
  std::vector<std::array<FootPose, 2>> feet_;
  FootState state_[2];
  double gait_phase_ = 0;
  bool gait_active_ = false;
  int gait_first_ = kLeft;  // the foot that lifts first when a gait starts
  double last_landing_ = -1;
  std::vector<double> gait_phase_at_, gait_amount_;
  // Pass 4.
  std::vector<Vec3> pelvis_, pelvis_angles_;
  std::vector<double> height_;
};

ClipSynthesizer::ClipSynthesizer(const ClipScript& script, const Skeleton& skeleton)
    : script_(script),
      skeleton_(skeleton),
      style_(script.style),
      frames_(script.num_frames()),
      fps_(script.fps),
      dt_(1.0 / script.fps),
      head_noise_x_(MixSeed(script.style.noise_seed, 3), 0.2),
      head_noise_y_(MixSeed(script.style.noise_seed, 4), 0.15),
      spine_noise_(MixSeed(script.style.noise_seed, 5), 0.12) {
  const auto& len = skeleton.bone_lengths();
  leg_[0] = len[4] + len[7];
  leg_[1] = len[5] + len[8];
  foot_length_[0] = len[10];
  foot_length_[1] = len[11];
  ctx_ = Context{&style_, 0.975 * std::min(leg_[0], leg_[1]), 0.0, 0.0, 0.5 * (len[10] + len[11])};
  ctx_.seat_height = 0.47;
  ctx_.seat_back = 0.33;
}

Synthesis ClipSynthesizer::Run() {
  EvaluateLayers();
  PlanPelvisPath();
  PlanFootsteps();
  PlacePelvis();
  Synthesis result;
  SolvePoses(&result);
  AddSegments(&result);
  return result;
}

void ClipSynthesizer::EvaluateLayers() {
  base_.resize(static_cast<size_t>(frames_));
  over_.resize(static_cast<size_t>(frames_));
  base_index_.resize(static_cast<size_t>(frames_));
  for (int64_t f = 0; f < frames_; ++f) {
    const double t = static_cast<double>(f) * dt_;
    const size_t k = script_.BaseAt(t);
    const ActionInstance& a = script_.base[k];
    BaseFrame frame = EvaluateBase(a, t - a.start, ctx_);
    const double since = t - a.start;
    if (k > 0 && since < kFadeSeconds) {
      const ActionInstance& prev = script_.base[k - 1];
      frame = Blend(EvaluateBase(prev, prev.duration(), ctx_), frame, Smooth(since / kFadeSeconds));
    } else if (k == 0 && script_.start_seated && a.id != A::kStandUp) {
      frame.height = ctx_.seat_height;
    }
    base_[static_cast<size_t>(f)] = frame;
    base_index_[static_cast<size_t>(f)] = k;
    for (const ActionInstance& o : script_.overlays) {
      if (t >= o.start && t < o.end)
        EvaluateOverlay(o, t - o.start, style_, &over_[static_cast<size_t>(f)]);
    }
  }
}

void ClipSynthesizer::PlanPelvisPath() {
  path_.resize(static_cast<size_t>(frames_ + 1));
  velocity_.resize(static_cast<size_t>(frames_ + 1));
  facing_.resize(static_cast<size_t>(frames_ + 1));
  path_[0] = {script_.start_x, script_.start_y, 0};
  facing_[0] = script_.start_facing;
  for (int64_t f = 0; f < frames_; ++f) {
    const BaseFrame& b = base_[static_cast<size_t>(f)];
    const double slow = std::clamp(1.0 - over_[static_cast<size_t>(f)].slow, 0.55, 1.0);
    const Vec3 v = slow * (b.speed_forward * Forward(facing_[static_cast<size_t>(f)]) +
                           b.speed_left * LeftOf(facing_[static_cast<size_t>(f)]));
    velocity_[static_cast<size_t>(f)] = v;
    path_[static_cast<size_t>(f + 1)] = path_[static_cast<size_t>(f)] + dt_ * v;
    facing_[static_cast<size_t>(f + 1)] = facing_[static_cast<size_t>(f)] + dt_ * b.facing_rate;
  }
  velocity_[static_cast<size_t>(frames_)] = velocity_[static_cast<size_t>(frames_ - 1)];
}

void ClipSynthesizer::PlanFootsteps() {
  feet_.resize(static_cast<size_t>(frames_));
  for (int s = 0; s < 2; ++s) {
    state_[s].plant = Desired(s, 0);
    state_[s].yaw = DesiredYaw(s, 0);
  }
  gait_phase_at_.resize(static_cast<size_t>(frames_));
  gait_amount_.resize(static_cast<size_t>(frames_));
  for (int64_t f = 0; f < frames_; ++f) {
    const bool fresh_gait = AdvanceGait(f);
    for (int s = 0; s < 2; ++s) StepFoot(f, s, fresh_gait);
    CorrectiveStep(f);
  }
}

bool ClipSynthesizer::AdvanceGait(int64_t f) {
  const BaseFrame& b = base_[static_cast<size_t>(f)];
  // The gait oscillator: left stance for phase in [0, duty), right shifted by half a cycle.
  bool fresh_gait = false;
  if (b.gait) {
    if (!gait_active_) {
      // Lift the foot that is further behind in the direction of travel first.
      const Vec3 dir = Norm(velocity_[static_cast<size_t>(f)]) > 1e-6
                           ? velocity_[static_cast<size_t>(f)]
                           : Forward(facing_[static_cast<size_t>(f)]);
      gait_first_ = Dot(state_[kLeft].plant - state_[kRight].plant, dir) <= 0 ? kLeft : kRight;
      gait_phase_ = gait_first_ == kLeft ? b.duty : b.duty - 0.5;
      if (gait_phase_ < 0) gait_phase_ += 1;
      fresh_gait = true;
    } else {
      gait_phase_ = std::fmod(gait_phase_ + dt_ / b.cycle, 1.0);
    }
  }
  gait_active_ = b.gait;
  gait_phase_at_[static_cast<size_t>(f)] = gait_phase_;
  gait_amount_[static_cast<size_t>(f)] =
      b.gait
          ? std::clamp(Norm(velocity_[static_cast<size_t>(f)]) / 1.1, b.lead == 0 ? 0.6 : 0.0, 1.0)
          : 0.0;
  return fresh_gait;
}

void ClipSynthesizer::StepFoot(int64_t f, int s, bool fresh_gait) {
  LeaveScriptedOrFlight(f, s);
  if (PlaceByMode(f, s)) return;
  LiftOff(f, s, fresh_gait);
  if (state_[s].swinging) {
    SwingFoot(f, s);
    return;
  }
  PlantedFoot(f, s);
}

void ClipSynthesizer::LeaveScriptedOrFlight(int64_t f, int s) {
  const double t = static_cast<double>(f) * dt_;
  FootState& st = state_[s];
  const FootRequest& req = base_[static_cast<size_t>(f)].feet[s];
  if (st.scripted && req.mode != FootMode::kScripted) {
    st.scripted = false;
    const FootPose& prev =
        feet_[static_cast<size_t>(std::max<int64_t>(0, f - 1))][static_cast<size_t>(s)];
    st.plant = {prev.ankle.x, prev.ankle.y, 0};
    st.yaw = prev.yaw;
    if (prev.ankle.z > 0.01) {  // still in the air: finish with a short step down
      st.swinging = true;
      st.from = prev.ankle;
      st.from_yaw = prev.yaw;
      st.from_pitch = prev.pitch;
      st.to = Desired(s, f + FrameAt(0.25));
      st.to_yaw = DesiredYaw(s, f + FrameAt(0.25));
      st.to_pitch = 0;
      st.t0 = t;
      st.t1 = t + 0.25;
      st.clearance = 0.02;
    }
  }
  if (st.flying && req.mode != FootMode::kFlight) {
    st.flying = false;
    st.plant = st.to;
    st.yaw = st.to_yaw;
    last_landing_ = t;
  }
}

bool ClipSynthesizer::PlaceByMode(int64_t f, int s) {
  const double t = static_cast<double>(f) * dt_;
  FootState& st = state_[s];
  const FootRequest& req = base_[static_cast<size_t>(f)].feet[s];
  FootPose& out = feet_[static_cast<size_t>(f)][static_cast<size_t>(s)];
  switch (req.mode) {
    case FootMode::kScripted: {
      if (!st.scripted) {
        st.scripted = true;
        st.swinging = false;
        st.anchor = st.plant;
        st.anchor_yaw = st.yaw;
      }
      Vec3 reference = st.anchor;
      double reference_yaw = st.anchor_yaw;
      if (req.reference == ScriptReference::kPath) {
        reference = Desired(s, f);
        reference_yaw = DesiredYaw(s, f);
      }
      out.ankle = reference + req.offset.x * Forward(reference_yaw) +
                  req.offset.y * LeftOf(reference_yaw) + Vec3{0, 0, req.offset.z};
      out.yaw = reference_yaw;
      out.pitch = req.pitch;
      out.knee_down = req.knee_down;
      return true;
    }
    case FootMode::kFlight: {
      if (!st.flying) {
        st.flying = true;
        st.swinging = false;
        st.from = st.plant;
        st.from_yaw = st.yaw;
        const int64_t land = FrameAt(req.landing);
        st.to = Desired(s, land);
        st.to_yaw = DesiredYaw(s, land);
      }
      out.flight = true;
      out.flight_s = Clamp01((t - req.takeoff) / std::max(1e-3, req.landing - req.takeoff));
      out.flight_from = st.from;
      out.flight_to = st.to;
      out.takeoff_frame = FrameAt(req.takeoff);
      out.landing_frame = FrameAt(req.landing);
      out.tuck = req.tuck;
      out.yaw = AngleLerp(st.from_yaw, st.to_yaw, Smooth(out.flight_s));
      return true;
    }
    case FootMode::kGait:
    case FootMode::kSupport:
      break;
  }
  return false;
}

void ClipSynthesizer::LiftOff(int64_t f, int s, bool fresh_gait) {
  const double t = static_cast<double>(f) * dt_;
  const BaseFrame& b = base_[static_cast<size_t>(f)];
  FootState& st = state_[s];
  if (b.gait && !st.swinging) {
    const double phase = std::fmod(gait_phase_ + (s == kRight ? 0.5 : 0.0), 1.0);
    // From standing only the chosen foot lifts. Afterwards a planted foot lifts anywhere in its
    // swing window once it has carried weight for a minimum stance (late after a corrective
    // step or a change of gait), so no foot is left behind a body that speeds up.
    const bool in_window = phase >= b.duty;
    const double min_stance = 0.6 * b.duty * b.cycle;
    // Safety net: a foot about to be left half a metre behind lifts now if the other is down.
    const bool left_behind = Norm(Desired(s, f + 3) - st.plant) > 0.5 && !state_[1 - s].swinging &&
                             !state_[1 - s].flying && t - st.t1 > 0.1;
    const bool lifts =
        fresh_gait ? s == gait_first_ : (in_window && t - st.t1 > min_stance) || left_behind;
    st.last_phase = phase;
    if (lifts) {
      const double swing = std::max(left_behind && !in_window ? 0.3 : 0.15, (1 - phase) * b.cycle);
      const int64_t land =
          f + std::max<int64_t>(1, static_cast<int64_t>(std::llround(swing * fps_)));
      // Land where the pelvis will be halfway through the coming stance (exact under
      // acceleration), timed by the gait in force at landing (the next action's when the gait
      // changes).
      const BaseFrame& at_landing = base_[static_cast<size_t>(std::min(land, frames_ - 1))];
      const double stance = at_landing.gait ? at_landing.duty * at_landing.cycle : b.duty * b.cycle;
      const int64_t stance_end = land + static_cast<int64_t>(std::llround(stance * fps_));
      const Vec3 lead = (0.5 * b.lead) * (Desired(s, stance_end) - Desired(s, land));
      st.swinging = true;
      st.t0 = t;
      st.t1 = t + swing;
      st.from_pitch = b.heel_toe ? -0.5 : -0.35;
      st.from_yaw = st.yaw;
      // Toe-off: the foot pivots about its fixed toe.
      const Vec3 toe = st.plant + foot_length_[s] * ToeDirection(st.yaw, 0);
      st.from = toe - foot_length_[s] * ToeDirection(st.yaw, st.from_pitch);
      st.to = Desired(s, land) + lead;
      st.to_yaw = DesiredYaw(s, land);
      st.to_pitch = b.heel_toe ? 0.25 : 0.0;
      st.clearance = b.clearance;
    }
  } else if (b.gait) {
    st.last_phase = std::fmod(gait_phase_ + (s == kRight ? 0.5 : 0.0), 1.0);
  }
}

void ClipSynthesizer::SwingFoot(int64_t f, int s) {
  const double t = static_cast<double>(f) * dt_;
  FootState& st = state_[s];
  FootPose& out = feet_[static_cast<size_t>(f)][static_cast<size_t>(s)];
  const double u = Clamp01((t - st.t0) / std::max(1e-6, st.t1 - st.t0));
  // Lift first, travel, then set down: the foot leaves the floor before it moves forward.
  const double w = Smooth((u - 0.12) / 0.8);
  Vec3 ankle = Lerp(st.from, st.to, w);
  ankle.z = Lerp(st.from.z, st.to.z, u) + st.clearance * std::pow(std::sin(kPi * u), 0.6);
  out.ankle = ankle;
  out.yaw = AngleLerp(st.from_yaw, st.to_yaw, w);
  // The toe comes up early in the swing and the heel leads the landing.
  out.pitch =
      Keys<double>({{0, st.from_pitch}, {0.3, 0.0}, {0.85, st.to_pitch}, {1, st.to_pitch}}, u);
  out.bears_weight = u < 0.08 || u > 0.92;
  if (u >= 1.0) {
    st.swinging = false;
    st.plant = st.to;
    st.yaw = st.to_yaw;
    last_landing_ = t;
  }
}

void ClipSynthesizer::PlantedFoot(int64_t f, int s) {
  const BaseFrame& b = base_[static_cast<size_t>(f)];
  const FootState& st = state_[s];
  FootPose& out = feet_[static_cast<size_t>(f)][static_cast<size_t>(s)];
  // Planted: heel strike and toe-off roll during gait stance, tiptoe otherwise.
  double pitch = -b.heel_raise;
  if (b.gait && b.heel_toe) {
    const double phase = std::fmod(gait_phase_ + (s == kRight ? 0.5 : 0.0), 1.0);
    const double u = phase / b.duty;
    if (u < 0.15) pitch = 0.25 * (1 - u / 0.15);
    if (u > 0.6) pitch = -0.5 * Smooth((u - 0.6) / 0.4);
  } else if (b.gait) {
    const double phase = std::fmod(gait_phase_ + (s == kRight ? 0.5 : 0.0), 1.0);
    const double u = phase / b.duty;
    if (u > 0.5) pitch = -0.35 * Smooth((u - 0.5) / 0.5);
  }
  if (pitch >= 0) {  // heel down: pivot about the ankle
    out.ankle = st.plant;
  } else {  // heel up: pivot about the toe
    const Vec3 toe = st.plant + foot_length_[s] * ToeDirection(st.yaw, 0);
    out.ankle = toe - foot_length_[s] * ToeDirection(st.yaw, pitch);
  }
  out.yaw = st.yaw;
  out.pitch = pitch;
}

void ClipSynthesizer::CorrectiveStep(int64_t f) {
  const double t = static_cast<double>(f) * dt_;
  const BaseFrame& b = base_[static_cast<size_t>(f)];
  // The foot furthest from where the body wants it steps, one foot at a time.
  const bool both_support =
      b.feet[0].mode == FootMode::kSupport && b.feet[1].mode == FootMode::kSupport && !b.gait;
  if (!both_support || state_[0].swinging || state_[1].swinging || state_[0].scripted ||
      state_[1].scripted || state_[0].flying || state_[1].flying || t - last_landing_ <= 0.08)
    return;
  const double step_time = 0.42;
  // Look ahead only within this action: the next one plans its own footsteps.
  const int64_t action_end = FrameAt(script_.base[base_index_[static_cast<size_t>(f)]].end) - 1;
  const int64_t land = std::min(f + FrameAt(step_time), std::max(f, action_end));
  double error[2];
  for (int s = 0; s < 2; ++s) {
    error[s] = Norm(Desired(s, land) - state_[s].plant) +
               0.3 * std::abs(std::remainder(DesiredYaw(s, land) - state_[s].yaw, 2 * kPi));
  }
  const Vec3 v = velocity_[static_cast<size_t>(f)];
  int pick = error[0] >= error[1] ? 0 : 1;
  if (std::abs(error[0] - error[1]) < 0.02 && Norm(v) > 1e-6) {
    pick = Dot(v, LeftOf(facing_[static_cast<size_t>(f)])) >= 0
               ? kLeft
               : kRight;  // lead with the foot on the side of travel
  }
  if (error[pick] > b.settle_threshold) {
    FootState& st = state_[pick];
    st.swinging = true;
    st.t0 = t;
    st.t1 = t + step_time;
    st.from = st.plant;
    st.from_yaw = st.yaw;
    st.from_pitch = 0;
    st.to = Desired(pick, land) +
            b.settle_lead * velocity_[static_cast<size_t>(std::min(land, frames_ - 1))];
    st.to_yaw = DesiredYaw(pick, land);
    st.to_pitch = 0;
    st.clearance = 0.09;
  }
}

void ClipSynthesizer::PlacePelvis() {
  // Horizontal: path + action offsets + idle and gait sway. Height: the action's nominal height,
  // lowered wherever a planted foot would otherwise be out of reach.
  const SmoothNoise sway_x(MixSeed(style_.noise_seed, 1), 0.22),
      sway_y(MixSeed(style_.noise_seed, 2), 0.17);
  pelvis_.resize(static_cast<size_t>(frames_));
  pelvis_angles_.resize(static_cast<size_t>(frames_));
  std::vector<double> envelope(static_cast<size_t>(frames_),
                               std::numeric_limits<double>::infinity());
  for (int64_t f = 0; f < frames_; ++f) {
    const auto fi = static_cast<size_t>(f);
    const double t = static_cast<double>(f) * dt_;
    const BaseFrame& b = base_[fi];
    const double gait = gait_amount_[fi];
    const double wave = std::sin(2 * kPi * (gait_phase_at_[fi] - 0.06));
    const double idle = (1 - gait) * style_.sway;
    const double lateral = b.offset_left + 0.022 * gait * wave + 0.012 * idle * sway_x(t);
    const double forward = b.offset_forward + 0.006 * idle * sway_y(t);
    pelvis_[fi] = path_[fi] + forward * Forward(facing_[fi]) + lateral * LeftOf(facing_[fi]);
    pelvis_angles_[fi] = b.pelvis_angles + Vec3{0, 0.07 * gait * wave, 0.035 * gait * wave};
    const Mat3 orientation = PelvisOrientation(facing_[fi], pelvis_angles_[fi]);
    for (int s = 0; s < 2; ++s) {
      const FootPose& foot = feet_[fi][static_cast<size_t>(s)];
      if (foot.flight || !foot.bears_weight) continue;
      const Vec3 hip_offset =
          orientation * skeleton_.rest_offsets()[static_cast<size_t>(s == kLeft ? 1 : 2)];
      const Vec3 hip_xy = pelvis_[fi] + hip_offset;
      const double d = std::hypot(hip_xy.x - foot.ankle.x, hip_xy.y - foot.ankle.y);
      const double reach = kReachMargin * leg_[s];
      const double hip_z = foot.ankle.z + std::sqrt(std::max(0.0, reach * reach - d * d));
      envelope[fi] = std::min(envelope[fi], hip_z - hip_offset.z);
    }
  }
  // Lower envelope smoothed by a parabolic erosion (|vertical acceleration| <= 2 * 3 m/s^2), so
  // the pelvis never has to drop abruptly to keep a foot in reach.
  height_.resize(static_cast<size_t>(frames_));
  const int window = static_cast<int>(fps_ * 0.5);
  for (int64_t f = 0; f < frames_; ++f) {
    double eroded = std::numeric_limits<double>::infinity();
    for (int k = -window; k <= window; ++k) {
      const int64_t g = f + k;
      if (g < 0 || g >= frames_) continue;
      const double tk = k * dt_;
      eroded = std::min(eroded, envelope[static_cast<size_t>(g)] + 3.0 * tk * tk);
    }
    height_[static_cast<size_t>(f)] = std::min(base_[static_cast<size_t>(f)].height, eroded);
    pelvis_[static_cast<size_t>(f)].z = height_[static_cast<size_t>(f)];
  }
  // Feet in flight move with the pelvis above the chord between takeoff and landing.
  for (int64_t f = 0; f < frames_; ++f) {
    for (int s = 0; s < 2; ++s) {
      FootPose& foot = feet_[static_cast<size_t>(f)][static_cast<size_t>(s)];
      if (!foot.flight) continue;
      const double u = foot.flight_s;
      const double chord = Lerp(height_[static_cast<size_t>(foot.takeoff_frame)],
                                height_[static_cast<size_t>(foot.landing_frame)], u);
      foot.ankle = Lerp(foot.flight_from, foot.flight_to, Smooth((u - 0.15) / 0.7)) +
                   Vec3{0, 0,
                        std::max(0.0, height_[static_cast<size_t>(f)] - chord) +
                            foot.tuck * std::sin(kPi * u)};
      foot.pitch = -0.3 * std::sin(kPi * u);
    }
  }
}

void ClipSynthesizer::SolvePoses(Synthesis* result) const {
  Motion& motion = result->motion;
  motion.fps = fps_;
  motion.poses.resize(static_cast<size_t>(frames_) * kNumJoints * 3);
  motion.trans.resize(static_cast<size_t>(frames_) * 3);
  for (int64_t f = 0; f < frames_; ++f) {
    PoseTargets targets = TrunkTargets(f);
    const UpperBodyFrame chest = ComputeUpperBody(skeleton_, targets);
    for (int s = 0; s < 2; ++s) {
      PlaceHand(f, s, chest, &targets);
      PlaceFoot(f, s, &targets);
    }
    const SolvedPose pose = SolvePose(skeleton_, targets);
    for (int j = 0; j < kNumJoints; ++j)
      motion.SetLocalRotation(f, j, pose.local[static_cast<size_t>(j)]);
    motion.SetTranslation(f, pose.translation);
    for (double e : pose.leg_reach_error)
      result->max_reach_error = std::max(result->max_reach_error, e);
  }
}

PoseTargets ClipSynthesizer::TrunkTargets(int64_t f) const {
  const auto fi = static_cast<size_t>(f);
  const double t = static_cast<double>(f) * dt_;
  const BaseFrame& b = base_[fi];
  const OverlayFrame& o = over_[fi];
  PoseTargets targets;
  targets.pelvis = pelvis_[fi];
  targets.facing = facing_[fi];
  targets.pelvis_angles = pelvis_angles_[fi];
  const double breathing = 0.012 * std::sin(2 * kPi * 0.25 * t);
  Vec3 spine = b.spine + o.spine +
               Vec3{style_.posture_lean + breathing + 0.015 * spine_noise_(t),
                    -1.1 * pelvis_angles_[fi].y, 0};
  // Raised arms are balanced by a small lean away (jointly performed, not pasted).
  for (int s = 0; s < 2; ++s) {
    const ArmGoal& g = o.arms[s];
    if (g.weight > 0 && g.offset.y > 0.1) spine.z += (s == kRight ? -1 : 1) * 0.04 * g.weight;
  }
  const Vec3 head = b.head + o.head +
                    Vec3{0.03 * head_noise_x_(t),
                         0.05 * head_noise_y_(t) - 0.3 * (spine.y + pelvis_angles_[fi].y), 0};
  targets.spine = {0.3 * spine, 0.3 * spine, 0.4 * spine};
  targets.neck = 0.4 * head;
  targets.head = 0.6 * head;
  for (int s = 0; s < 2; ++s) {
    targets.hands[static_cast<size_t>(s)].collar_raise = o.arms[s].weight * o.arms[s].collar;
  }
  return targets;
}

void ClipSynthesizer::PlaceHand(int64_t f, int s, const UpperBodyFrame& chest,
                                PoseTargets* targets) const {
  const auto fi = static_cast<size_t>(f);
  const BaseFrame& b = base_[fi];
  const OverlayFrame& o = over_[fi];
  const double gait = gait_amount_[fi];
  const double wave = std::sin(2 * kPi * (gait_phase_at_[fi] - 0.06));
  const Vec3 world_down{0, 0, -1};
  const double mirror = SideSign(s);
  const auto to_world = [&](const Vec3& v) { return chest.chest * Vec3{mirror * v.x, v.y, v.z}; };
  // Default arm of the base action with its gait swing (reduced when the other arm is busy).
  ArmPlacement placement = DefaultArm(b.arm_style, b.arm_param, style_.arm_hang_out);
  if (b.arm_fade < 1) {
    const ArmPlacement previous =
        DefaultArm(b.previous_arm_style, b.previous_arm_param, style_.arm_hang_out);
    placement.offset = ArcBlend(previous.offset, placement.offset, b.arm_fade);
    placement.pole = Lerp(previous.pole, placement.pole, b.arm_fade);
    placement.gravity = b.arm_fade < 0.5 ? previous.gravity : placement.gravity;
  }
  const double other_busy = o.arms[1 - s].weight;
  const double swing =
      b.arm_swing * style_.arm_swing * gait * (1 - 0.4 * other_busy) * (s == kLeft ? wave : -wave);
  placement.offset.z += (b.arm_style == ArmStyle::kRun ? 0.15 : 0.10) * swing;
  placement.offset.y += 0.02 * std::abs(swing);
  Vec3 wrist_offset = to_world(placement.offset);
  if (placement.gravity) {
    // A relaxed arm hangs towards the floor, not along a bent-over chest.
    const Quat tilt = MatrixToQuat(RotationBetween(chest.chest * Vec3{0, -1, 0}, world_down));
    wrist_offset = QuatToMatrix(Slerp(Quat{}, tilt, 0.8)) * wrist_offset;
  }
  Vec3 pole = to_world(placement.pole);
  const ArmGoal& goal = o.arms[s];
  if (goal.weight > 0) {
    wrist_offset = ArcBlend(wrist_offset, to_world(goal.offset), goal.weight);
    pole = Lerp(pole, to_world(goal.pole), goal.weight);
  }
  // Hands never come closer than 20 cm to their shoulder (the elbow would fold past its range).
  if (Norm(wrist_offset) < 0.2)
    wrist_offset = (0.2 / std::max(1e-9, Norm(wrist_offset))) * wrist_offset;
  HandTarget& hand = targets->hands[static_cast<size_t>(s)];
  hand.wrist = chest.shoulders[static_cast<size_t>(s)] + wrist_offset;
  hand.elbow_pole = pole;
  hand.wrist_angles = goal.weight * goal.wrist;
}

void ClipSynthesizer::PlaceFoot(int64_t f, int s, PoseTargets* targets) const {
  const auto fi = static_cast<size_t>(f);
  const FootPose& foot = feet_[fi][static_cast<size_t>(s)];
  FootTarget& target = targets->feet[static_cast<size_t>(s)];
  target.ankle = foot.ankle;
  if (!foot.bears_weight || foot.flight) {
    // A swinging foot bends its knee rather than stretching: keep its target within reach.
    const Vec3 hip = HipPosition(skeleton_, targets->pelvis,
                                 PelvisOrientation(targets->facing, targets->pelvis_angles), s);
    const Vec3 reach = target.ankle - hip;
    const double limit = kReachMargin * leg_[s];
    if (Norm(reach) > limit) target.ankle = hip + (limit / Norm(reach)) * reach;
  }
  target.toe_dir = ToeDirection(foot.yaw, foot.pitch);
  // Knees point over the toes (the hip, not the ankle, takes the twist of a turning body); a
  // kneeling knee points down.
  target.knee_pole = Lerp(0.3 * Forward(facing_[fi]) + 0.7 * Forward(foot.yaw), Vec3{0, 0, -1},
                          0.5 * foot.knee_down);
}

void ClipSynthesizer::AddSegments(Synthesis* result) const {
  const auto add_segment = [&](const ActionInstance& a) {
    if (!a.annotated) return;
    Segment seg;
    seg.start_frame =
        static_cast<int32_t>(std::clamp<int64_t>(std::llround(a.start * fps_), 0, frames_ - 1));
    seg.end_frame = static_cast<int32_t>(
        std::clamp<int64_t>(std::llround(a.end * fps_), seg.start_frame + 1, frames_));
    seg.text = a.label;
    seg.parts = PartsOf(a.id, a.side);
    result->segments.push_back(seg);
  };
  for (const ActionInstance& a : script_.base) add_segment(a);
  for (const ActionInstance& a : script_.overlays) add_segment(a);
}

}  // namespace

Synthesis Synthesize(const ClipScript& script, const Skeleton& skeleton) {
  return ClipSynthesizer(script, skeleton).Run();
}

}  // namespace motionpipe::corpus
