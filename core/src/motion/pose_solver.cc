#include "motionpipe/motion/pose_solver.h"

#include <algorithm>
#include <cmath>

namespace motionpipe {

namespace {

constexpr int kHip[2] = {1, 2};
constexpr int kKnee[2] = {4, 5};
constexpr int kAnkle[2] = {7, 8};
constexpr int kFoot[2] = {10, 11};
constexpr int kCollar[2] = {13, 14};
constexpr int kShoulder[2] = {16, 17};
constexpr int kElbow[2] = {18, 19};
constexpr int kWrist[2] = {20, 21};

Vec3 Unit(const Vec3& v, const Vec3& fallback) {
  const double n = Norm(v);
  return n > 1e-12 ? (1.0 / n) * v : fallback;
}

Mat3 FromColumns(const Vec3& x, const Vec3& y, const Vec3& z) {
  Mat3 m;
  m.m = {{{x.x, y.x, z.x}, {x.y, y.y, z.y}, {x.z, y.z, z.z}}};
  return m;
}

struct TwoBone {
  Vec3 middle;  // knee / elbow position
  Vec3 end;     // achieved ankle / wrist position
  Vec3 hinge;   // unit hinge axis n: the second bone is the first rotated about n by `bend`
  Vec3 upper;   // unit direction of the first bone
  double bend = 0;
  double reach_error = 0;
};

// Two-bone IK in the plane chosen by `pole`: the middle joint bulges towards the pole.
TwoBone SolveTwoBone(const Vec3& root, const Vec3& target, double l1, double l2, const Vec3& pole,
                     const Vec3& fallback_hinge) {
  TwoBone out;
  Vec3 axis = target - root;
  double d = Norm(axis);
  const Vec3 a = Unit(axis, Vec3{0, 0, -1});
  const double d_max = (l1 + l2) * 0.9999, d_min = std::abs(l1 - l2) + 1e-6;
  const double d_clamped = std::clamp(d, d_min, d_max);
  out.reach_error = std::max(0.0, d - d_max) + std::max(0.0, d_min - d);
  d = d_clamped;
  out.end = root + d * a;
  // Law of cosines: distance of the middle joint along the axis and from it.
  const double along = (l1 * l1 - l2 * l2 + d * d) / (2 * d);
  const double radius = std::sqrt(std::max(0.0, l1 * l1 - along * along));
  Vec3 perpendicular = pole - Dot(pole, a) * a;
  if (Norm(perpendicular) < 1e-9) perpendicular = Cross(fallback_hinge, a);
  perpendicular = Unit(perpendicular, Vec3{1, 0, 0});
  out.middle = root + along * a + radius * perpendicular;
  out.upper = Unit(out.middle - root, a);
  const Vec3 lower = Unit(out.end - out.middle, a);
  const double cos_bend = std::clamp(Dot(out.upper, lower), -1.0, 1.0);
  out.bend = std::acos(cos_bend);
  const Vec3 cross = Cross(out.upper, lower);
  if (Norm(cross) > 1e-9) {
    out.hinge = Unit(cross, fallback_hinge);
  } else {
    // Straight limb: bending would move the second bone away from the pole.
    out.hinge = Unit(Cross(out.upper, -1.0 * pole), fallback_hinge);
    if (Norm(Cross(out.upper, pole)) < 1e-9) out.hinge = fallback_hinge;
  }
  return out;
}

}  // namespace

Mat3 BodyAngles(const Vec3& angles) { return RotY(angles.y) * RotX(angles.x) * RotZ(angles.z); }

Mat3 PelvisOrientation(double facing, const Vec3& angles) {
  return RotZ(facing + kPi / 2) * YUpToZUp() * BodyAngles(angles);
}

Vec3 HipPosition(const Skeleton& skeleton, const Vec3& pelvis, const Mat3& pelvis_orientation,
                 int side) {
  return pelvis + pelvis_orientation * skeleton.rest_offsets()[static_cast<size_t>(kHip[side])];
}

UpperBodyFrame ComputeUpperBody(const Skeleton& skeleton, const PoseTargets& t) {
  const auto& offsets = skeleton.rest_offsets();
  Mat3 g = PelvisOrientation(t.facing, t.pelvis_angles);
  Vec3 p = t.pelvis;
  const int spine[3] = {3, 6, 9};
  for (int k = 0; k < 3; ++k) {
    p = p + g * offsets[static_cast<size_t>(spine[k])];
    g = g * BodyAngles(t.spine[static_cast<size_t>(k)]);
  }
  UpperBodyFrame frame;
  frame.chest = g;
  frame.chest_position = p;
  for (int side = 0; side < 2; ++side) {
    const double sign = side == 0 ? 1.0 : -1.0;
    const Vec3 collar = p + g * offsets[static_cast<size_t>(kCollar[side])];
    const Mat3 g_collar = g * RotZ(sign * t.hands[static_cast<size_t>(side)].collar_raise);
    frame.shoulders[static_cast<size_t>(side)] =
        collar + g_collar * offsets[static_cast<size_t>(kShoulder[side])];
  }
  return frame;
}

SolvedPose SolvePose(const Skeleton& skeleton, const PoseTargets& t) {
  SolvedPose out;
  const auto& offsets = skeleton.rest_offsets();
  const auto& lengths = skeleton.bone_lengths();
  std::array<Mat3, kNumJoints> global{};
  std::array<Vec3, kNumJoints> position{};
  auto& local = out.local;
  for (auto& m : local) m = Mat3::Identity();

  const Mat3 pelvis = PelvisOrientation(t.facing, t.pelvis_angles);
  local[0] = pelvis;
  global[0] = pelvis;
  position[0] = t.pelvis;
  out.translation = t.pelvis;
  const auto chain = [&](int joint, const Mat3& rotation) {
    const int parent = skeleton.parents()[static_cast<size_t>(joint)];
    local[static_cast<size_t>(joint)] = rotation;
    global[static_cast<size_t>(joint)] = global[static_cast<size_t>(parent)] * rotation;
    position[static_cast<size_t>(joint)] =
        position[static_cast<size_t>(parent)] +
        global[static_cast<size_t>(parent)] * offsets[static_cast<size_t>(joint)];
  };
  chain(3, BodyAngles(t.spine[0]));
  chain(6, BodyAngles(t.spine[1]));
  chain(9, BodyAngles(t.spine[2]));
  chain(12, BodyAngles(t.neck));
  chain(15, BodyAngles(t.head));

  // Legs: hip 3-DOF, knee a pure flexion about its x axis, ankle aligns the foot.
  for (int side = 0; side < 2; ++side) {
    const FootTarget& foot = t.feet[static_cast<size_t>(side)];
    const Vec3 hip = HipPosition(skeleton, t.pelvis, pelvis, side);
    position[static_cast<size_t>(kHip[side])] = hip;
    const Vec3 pelvis_x = pelvis * Vec3{1, 0, 0};
    const TwoBone leg =
        SolveTwoBone(hip, foot.ankle, lengths[static_cast<size_t>(kKnee[side])],
                     lengths[static_cast<size_t>(kAnkle[side])], foot.knee_pole, pelvis_x);
    out.leg_reach_error[static_cast<size_t>(side)] = leg.reach_error;
    // Columns: x -> hinge, y -> -thigh, z = x cross y = thigh x hinge (a proper rotation).
    const Mat3 g_hip = FromColumns(leg.hinge, -1.0 * leg.upper, Cross(leg.upper, leg.hinge));
    const Mat3 knee_local = RotX(leg.bend);
    const Mat3 g_knee = g_hip * knee_local;
    const Vec3 toe = Unit(foot.toe_dir, g_knee * Vec3{0, 0, 1});
    Vec3 lateral = leg.hinge - Dot(leg.hinge, toe) * toe;
    if (Norm(lateral) < 1e-6) lateral = Cross(g_knee * Vec3{0, 1, 0}, toe);
    const Mat3 g_ankle = RotationFromTwoDirections({0, 0, 1}, {1, 0, 0}, toe, lateral);
    local[static_cast<size_t>(kHip[side])] = Transpose(pelvis) * g_hip;
    local[static_cast<size_t>(kKnee[side])] = knee_local;
    local[static_cast<size_t>(kAnkle[side])] = Transpose(g_knee) * g_ankle;
    local[static_cast<size_t>(kFoot[side])] = Mat3::Identity();
  }

  // Arms: collar shrug, shoulder 3-DOF, elbow a pure flexion about its y axis.
  for (int side = 0; side < 2; ++side) {
    const HandTarget& hand = t.hands[static_cast<size_t>(side)];
    const double sign = side == 0 ? 1.0 : -1.0;  // left arm rests along +x, right along -x
    chain(kCollar[side], RotZ(sign * hand.collar_raise));
    const Mat3 g_collar = global[static_cast<size_t>(kCollar[side])];
    const Vec3 shoulder = position[static_cast<size_t>(kCollar[side])] +
                          g_collar * offsets[static_cast<size_t>(kShoulder[side])];
    const Vec3 chest_y = global[9] * Vec3{0, 1, 0};
    const TwoBone arm =
        SolveTwoBone(shoulder, hand.wrist, lengths[static_cast<size_t>(kElbow[side])],
                     lengths[static_cast<size_t>(kWrist[side])], hand.elbow_pole, -sign * chest_y);
    out.arm_reach_error[static_cast<size_t>(side)] = arm.reach_error;
    // Left: x -> upper, y -> -hinge; right: x -> -upper, y -> hinge; z = x cross y = hinge x upper.
    const Mat3 g_shoulder =
        side == 0 ? FromColumns(arm.upper, -1.0 * arm.hinge, Cross(arm.hinge, arm.upper))
                  : FromColumns(-1.0 * arm.upper, arm.hinge, Cross(arm.hinge, arm.upper));
    const Mat3 elbow_local = RotY(-sign * arm.bend);
    local[static_cast<size_t>(kShoulder[side])] = Transpose(g_collar) * g_shoulder;
    local[static_cast<size_t>(kElbow[side])] = elbow_local;
    local[static_cast<size_t>(kWrist[side])] = BodyAngles(hand.wrist_angles);
  }
  return out;
}

}  // namespace motionpipe
