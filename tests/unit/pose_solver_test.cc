#include "motionpipe/motion/pose_solver.h"

#include <gtest/gtest.h>

#include "motionpipe/motion/plausibility.h"
#include "test_util.h"

namespace motionpipe {
namespace {

double Det(const Mat3& m) {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

PoseTargets Standing(const Skeleton& s) {
  PoseTargets t;
  t.pelvis = {0.3, -0.2, 0.78};
  t.facing = 0.7;
  const Vec3 forward{std::cos(t.facing), std::sin(t.facing), 0},
      left{-std::sin(t.facing), std::cos(t.facing), 0};
  for (int side = 0; side < 2; ++side) {
    const double sign = side == 0 ? 1 : -1;
    t.feet[static_cast<size_t>(side)] = {
        t.pelvis + (sign * 0.1) * left + Vec3{0, 0, -0.78} + 0.1 * forward, forward, forward};
    const UpperBodyFrame chest = ComputeUpperBody(s, t);
    t.hands[static_cast<size_t>(side)].wrist =
        chest.shoulders[static_cast<size_t>(side)] + Vec3{0, 0, -0.45} + 0.1 * forward;
    t.hands[static_cast<size_t>(side)].elbow_pole = -1.0 * forward;
  }
  return t;
}

TEST(PoseSolver, ReachesTargetsWithProperRotationsAndHinges) {
  const Skeleton& s = Skeleton::Smpl22();
  PoseTargets t = Standing(s);
  const SolvedPose pose = SolvePose(s, t);
  std::array<Mat3, kNumJoints> global;
  std::array<Vec3, kNumJoints> position;
  ForwardKinematicsFrame(s, pose.local.data(), pose.translation, global.data(), position.data());
  for (int j = 0; j < kNumJoints; ++j) {
    EXPECT_NEAR(Det(pose.local[static_cast<size_t>(j)]), 1.0, 1e-9) << j;
    EXPECT_LT(MaxAbsDiff(pose.local[static_cast<size_t>(j)] *
                             Transpose(pose.local[static_cast<size_t>(j)]),
                         Mat3::Identity()),
              1e-9);
  }
  for (int side = 0; side < 2; ++side) {
    EXPECT_LT(Norm(position[static_cast<size_t>(side == 0 ? 7 : 8)] -
                   t.feet[static_cast<size_t>(side)].ankle),
              1e-6);
    EXPECT_LT(Norm(position[static_cast<size_t>(side == 0 ? 20 : 21)] -
                   t.hands[static_cast<size_t>(side)].wrist),
              1e-6);
    EXPECT_EQ(pose.leg_reach_error[static_cast<size_t>(side)], 0.0);
    // The foot points where asked.
    const Vec3 toe = position[static_cast<size_t>(side == 0 ? 10 : 11)] -
                     position[static_cast<size_t>(side == 0 ? 7 : 8)];
    EXPECT_GT(Dot(toe, t.feet[static_cast<size_t>(side)].toe_dir) / Norm(toe), 0.999);
    // Knees are hinges about x, elbows about y (SMPL's axes), bending the right way.
    const Mat3& knee = pose.local[static_cast<size_t>(side == 0 ? 4 : 5)];
    EXPECT_LT(MaxAbsDiff(knee, RotX(std::atan2(knee[2][1], knee[1][1]))), 1e-9);
    EXPECT_TRUE(CheckJointLimit(s, side == 0 ? 4 : 5, knee).empty());
    const Mat3& elbow = pose.local[static_cast<size_t>(side == 0 ? 18 : 19)];
    EXPECT_LT(MaxAbsDiff(elbow, RotY(std::atan2(elbow[0][2], elbow[0][0]))), 1e-9);
    EXPECT_TRUE(CheckJointLimit(s, side == 0 ? 18 : 19, elbow).empty());
  }
  // The knees point forward of the hip-ankle line.
  const Vec3 forward{std::cos(t.facing), std::sin(t.facing), 0};
  EXPECT_GT(Dot(position[4] - 0.5 * (position[1] + position[7]), forward), 0.01);
}

TEST(PoseSolver, UnreachableTargetsReportTheShortfall) {
  const Skeleton& s = Skeleton::Smpl22();
  PoseTargets t = Standing(s);
  t.feet[0].ankle = t.feet[0].ankle + Vec3{0, 0, -0.3};  // below the floor, out of reach
  const SolvedPose pose = SolvePose(s, t);
  EXPECT_GT(pose.leg_reach_error[0], 0.2);
  EXPECT_EQ(pose.leg_reach_error[1], 0.0);
}

TEST(Plausibility, DetectsSkatingPenetrationFloatingLimitsAndBoneErrors) {
  const Skeleton& s = Skeleton::Smpl22();
  Motion still = Motion::Rest(30, 30, s.RestPelvisHeight());
  PlausibilityReport r = EvaluateMotionPlausibility(s, still);
  EXPECT_EQ(r.foot_skate_ratio, 0.0);
  EXPECT_NEAR(r.penetration_max, 0.0, 1e-6);
  EXPECT_EQ(r.joint_limit_violations, 0);
  EXPECT_LT(r.bone_length_error, 1e-6);
  // Sliding the whole standing body at 1 m/s: every contact frame skates.
  Motion sliding = still;
  for (int64_t f = 0; f < 30; ++f) sliding.SetTranslation(f, {f / 30.0, 0, s.RestPelvisHeight()});
  r = EvaluateMotionPlausibility(s, sliding);
  EXPECT_GT(r.foot_skate_ratio, 0.95);
  EXPECT_NEAR(r.foot_skate_mean, 1.0, 1e-3);
  // Sunk by 5 cm / lifted by 20 cm.
  Motion sunk = still;
  for (int64_t f = 0; f < 30; ++f) sunk.SetTranslation(f, {0, 0, s.RestPelvisHeight() - 0.05});
  EXPECT_NEAR(EvaluateMotionPlausibility(s, sunk).penetration_max, 0.05, 1e-5);
  Motion lifted = still;
  for (int64_t f = 0; f < 30; ++f) lifted.SetTranslation(f, {0, 0, s.RestPelvisHeight() + 0.2});
  EXPECT_EQ(EvaluateMotionPlausibility(s, lifted).float_ratio, 1.0);
  // A knee bent backwards.
  Motion hyper = still;
  hyper.SetLocalRotation(10, 4, RotX(-0.6));
  r = EvaluateMotionPlausibility(s, hyper);
  EXPECT_EQ(r.joint_limit_violations, 1);
  EXPECT_NE(r.worst_joint_limit.find("left_knee hyperextended"), std::string::npos);
  // Joint positions with a stretched bone (as a positions-only model might output).
  std::vector<float> joints = ComputeJoints(s, still);
  joints[7 * 3 + 2] -= 0.03f;  // left ankle 3 cm lower in frame 0
  r = EvaluatePlausibility(s, joints.data(), 30, 30, nullptr);
  EXPECT_NEAR(r.bone_length_error, 0.03, 1e-3);
  EXPECT_NEAR(r.max_joint_step, 0.03, 1e-3);
}

}  // namespace
}  // namespace motionpipe
