#include "motionpipe/motion/foot_lock.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <stdexcept>

#include "motionpipe/motion/plausibility.h"
#include "motionpipe/motion/pose_solver.h"

namespace motionpipe {
namespace {

constexpr int kLeftHip = 1, kLeftKnee = 4, kLeftAnkle = 7, kRightAnkle = 8;

// A body standing with its pelvis at `pelvis_x(frame)` (default still), 30 frames at 30 fps, whose
// left ankle is put where `left_ankle(frame)` says (the right ankle stays under the pelvis), its
// left foot pointing along `left_toe_dir` (default level, forward), solved by the pose solver's IK.
Motion Standing(
    const std::function<Vec3(int)>& left_ankle,
    const std::function<double(int)>& pelvis_x = [](int) { return 0.0; },
    const Vec3& left_toe_dir = {1, 0, 0}) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  constexpr int kFrames = 30;
  Motion motion = Motion::Rest(kFrames, 30.0, skeleton.RestPelvisHeight());
  for (int frame = 0; frame < kFrames; ++frame) {
    PoseTargets t;
    t.pelvis = {pelvis_x(frame), 0.0, 0.78};
    t.facing = 0.0;  // facing +x; the body's left is +y
    for (int side = 0; side < 2; ++side) {
      FootTarget& foot = t.feet[static_cast<size_t>(side)];
      foot.ankle = side == 0 ? left_ankle(frame) : Vec3{pelvis_x(frame) + 0.02, -0.1, 0.03};
      foot.toe_dir = side == 0 ? left_toe_dir : Vec3{1, 0, 0};
      foot.knee_pole = {1, 0, 0};
    }
    for (auto& hand : t.hands)
      hand.wrist = {pelvis_x(frame), 0.0, 0.55}, hand.elbow_pole = {-1, 0, 0};
    t.hands[0].wrist.y = 0.25, t.hands[1].wrist.y = -0.25;
    const SolvedPose pose = SolvePose(skeleton, t);
    for (int joint = 0; joint < kNumJoints; ++joint)
      motion.SetLocalRotation(frame, joint, pose.local[static_cast<size_t>(joint)]);
    motion.SetTranslation(frame, pose.translation);
  }
  return motion;
}

Vec3 JointAt(const std::vector<float>& joints, int frame, int joint) {
  const float* p =
      &joints[(static_cast<size_t>(frame) * kNumJoints + static_cast<size_t>(joint)) * 3];
  return {p[0], p[1], p[2]};
}

TEST(FootLock, HoldsASlidingContactFootAtOnePlaceAndLeavesTheRestOfTheBody) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  // The left foot slides forward on the floor at 0.3 m/s (a skate, slower than max_speed 1 m/s).
  const Motion sliding = Standing([](int frame) { return Vec3{0.01 * frame - 0.1, 0.1, 0.03}; });
  ASSERT_GT(EvaluateMotionPlausibility(skeleton, sliding).foot_skate_ratio, 0.4);
  FootLockReport report;
  const Motion locked = LockFeet(skeleton, sliding, {}, &report);
  ASSERT_EQ(locked.num_frames(), sliding.num_frames());
  EXPECT_EQ(locked.trans, sliding.trans);
  EXPECT_EQ(report.unreached, 0);
  EXPECT_GE(report.runs, 2);  // at least the left ankle's run and the right ankle's
  // Held at one place, the run's mean (every frame is one run of contact), at its own height.
  const std::vector<float> before = ComputeJoints(skeleton, sliding);
  const std::vector<float> joints = ComputeJoints(skeleton, locked);
  Vec3 place{0, 0, 0};
  for (int frame = 0; frame < sliding.num_frames(); ++frame) {
    ASSERT_LT(JointAt(before, frame, kLeftAnkle).z, 0.05) << frame;
    place = place +
            (1.0 / static_cast<double>(sliding.num_frames())) * JointAt(before, frame, kLeftAnkle);
  }
  for (int frame = 0; frame < locked.num_frames(); ++frame) {
    const Vec3 at = JointAt(joints, frame, kLeftAnkle);
    EXPECT_NEAR(at.x, place.x, 1e-6) << frame;
    EXPECT_NEAR(at.y, place.y, 1e-6) << frame;
    EXPECT_NEAR(at.z, JointAt(before, frame, kLeftAnkle).z, 1e-6) << frame;
  }
  EXPECT_EQ(EvaluateMotionPlausibility(skeleton, locked).foot_skate_ratio, 0.0);
  // Only the legs below the pelvis change: every other joint's rotation is the motion's own.
  for (int frame = 0; frame < locked.num_frames(); ++frame) {
    for (int joint : {0, 3, 6, 9, 12, 15, 16, 17, 18, 19, 20, 21}) {
      EXPECT_LT(MaxAbsDiff(locked.LocalRotation(frame, joint), sliding.LocalRotation(frame, joint)),
                1e-6)
          << frame << " " << joint;
    }
    // The right foot already stood still: held where it stood, its leg is unchanged.
    EXPECT_LT(Norm(JointAt(joints, frame, kRightAnkle) - JointAt(before, frame, kRightAnkle)),
              1e-6);
  }
}

// A foot pivoting on its toe (the heel lifted above the contact height, the toe on the floor)
// that slides: only the toe is in contact, and it is the toe that must stand still. The leg
// carries the ankle so that the toe reaches its place; the foot keeps its pitch.
TEST(FootLock, AToeHeldWithoutItsAnkleStandsAtItsPlace) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  constexpr int kLeftToe = 10;
  const Vec3 pitched = (1.0 / std::hypot(1.0, 0.8)) * Vec3{1, 0, -0.8};
  const Motion sliding = Standing(
      [](int frame) {
        return Vec3{0.01 * frame - 0.1, 0.1, 0.1};
      },
      [](int) { return 0.0; }, pitched);
  const std::vector<float> before = ComputeJoints(skeleton, sliding);
  Vec3 place{0, 0, 0};
  for (int frame = 0; frame < sliding.num_frames(); ++frame) {
    ASSERT_GT(JointAt(before, frame, kLeftAnkle).z, 0.05) << frame;  // the heel is up
    ASSERT_LT(JointAt(before, frame, kLeftToe).z, 0.05) << frame;    // the toe is down
    place = place +
            (1.0 / static_cast<double>(sliding.num_frames())) * JointAt(before, frame, kLeftToe);
  }
  FootLockReport report;
  const Motion locked = LockFeet(skeleton, sliding, {}, &report);
  EXPECT_EQ(report.unreached, 0);
  const std::vector<float> joints = ComputeJoints(skeleton, locked);
  for (int frame = 0; frame < locked.num_frames(); ++frame) {
    const Vec3 toe = JointAt(joints, frame, kLeftToe);
    EXPECT_NEAR(toe.x, place.x, 1e-4) << frame;
    EXPECT_NEAR(toe.y, place.y, 1e-4) << frame;
    EXPECT_NEAR(toe.z, JointAt(before, frame, kLeftToe).z, 1e-3) << frame;
    // The foot's direction (ankle to toe) is the motion's own.
    const Vec3 foot = toe - JointAt(joints, frame, kLeftAnkle);
    const Vec3 own = JointAt(before, frame, kLeftToe) - JointAt(before, frame, kLeftAnkle);
    EXPECT_GT(Dot(foot, own) / (Norm(foot) * Norm(own)), 0.9999) << frame;
  }
  EXPECT_EQ(EvaluateMotionPlausibility(skeleton, locked).foot_skate_ratio, 0.0);
}

TEST(FootLock, TheKneeStillBendsOnlyAboutItsHinge) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  const Motion sliding = Standing([](int frame) { return Vec3{0.01 * frame - 0.1, 0.1, 0.03}; });
  const Motion locked = LockFeet(skeleton, sliding);
  for (int frame = 0; frame < locked.num_frames(); ++frame) {
    const Vec3 axis = MatrixToAxisAngle(locked.LocalRotation(frame, kLeftKnee));
    EXPECT_GT(axis.x, 0.0) << frame;  // flexion, not hyperextension
    EXPECT_NEAR(axis.y, 0.0, 1e-6) << frame;
    EXPECT_NEAR(axis.z, 0.0, 1e-6) << frame;
  }
}

TEST(FootLock, ASwingingFootIsLeftAloneAwayFromItsContacts) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  // Planted at x = -0.1 for frames 0-9, swung 0.4 m through the air in frames 10-19 (lifted by
  // 0.15 m), planted again at x = 0.3 from frame 20.
  const Motion stepping = Standing([](int frame) {
    if (frame < 10) return Vec3{-0.1, 0.1, 0.03};
    if (frame >= 20) return Vec3{0.3, 0.1, 0.03};
    const double s = (frame - 9) / 11.0;
    return Vec3{-0.1 + 0.4 * s, 0.1, 0.03 + 0.15 * std::sin(kPi * s)};
  });
  FootLockOptions options;
  options.blend_seconds = 0.1;  // 3 frames at 30 fps
  const Motion locked = LockFeet(skeleton, stepping, options);
  // The swing's middle, more than the blend's 3 frames from either run of contact, is untouched.
  for (int frame = 13; frame <= 16; ++frame) {
    for (int joint : {kLeftHip, kLeftKnee, kLeftAnkle})
      EXPECT_EQ(locked.LocalRotation(frame, joint).m, stepping.LocalRotation(frame, joint).m)
          << frame << " " << joint;
  }
  // The planted runs stay where they were (they did not slide).
  const std::vector<float> before = ComputeJoints(skeleton, stepping);
  const std::vector<float> after = ComputeJoints(skeleton, locked);
  for (int frame : {0, 5, 25, 29})
    EXPECT_LT(Norm(JointAt(after, frame, kLeftAnkle) - JointAt(before, frame, kLeftAnkle)), 1e-4);
}

// Issue 15: contacts given by a model (the MDT's contact head) replace the height and speed test:
// a foot dragged faster than max_speed, which the test takes for a swing, is held where they say
// it stands, and nothing is held where they say no foot stands.
TEST(FootLock, GivenContactsReplaceTheHeightAndSpeedTest) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  // The left ankle is dragged over the floor at 1.5 m/s for frames 0-9, then stands.
  const Motion dragged = Standing([](int frame) {
    return Vec3{-0.2 + 0.05 * std::min(frame, 9), 0.1, 0.03};
  });
  const std::vector<float> before = ComputeJoints(skeleton, dragged);
  // The test leaves the drag alone (too fast for a contact).
  const Motion tested = LockFeet(skeleton, dragged);
  const std::vector<float> tested_joints = ComputeJoints(skeleton, tested);
  for (int frame = 0; frame < 6; ++frame)
    EXPECT_LT(Norm(JointAt(tested_joints, frame, kLeftAnkle) - JointAt(before, frame, kLeftAnkle)),
              1e-6)
        << frame;
  // Given: the left ankle stands in frames 0-9, nothing else anywhere.
  std::vector<uint8_t> contacts(static_cast<size_t>(dragged.num_frames()) * 4, 0);
  for (int frame = 0; frame < 10; ++frame) contacts[static_cast<size_t>(frame) * 4] = 1;
  FootLockReport report;
  const Motion locked = LockFeet(skeleton, dragged, {}, &report, &contacts);
  EXPECT_EQ(report.runs, 1);
  EXPECT_EQ(report.held, 10);
  const std::vector<float> joints = ComputeJoints(skeleton, locked);
  Vec3 place{0, 0, 0};
  for (int frame = 0; frame < 10; ++frame) place = place + 0.1 * JointAt(before, frame, kLeftAnkle);
  for (int frame = 0; frame < 10; ++frame) {
    EXPECT_NEAR(JointAt(joints, frame, kLeftAnkle).x, place.x, 1e-6) << frame;
    EXPECT_NEAR(JointAt(joints, frame, kLeftAnkle).y, place.y, 1e-6) << frame;
  }
  // The right foot, which the test would hold, is left as it is.
  for (int frame = 0; frame < locked.num_frames(); ++frame)
    EXPECT_EQ(locked.LocalRotation(frame, kRightAnkle).m,
              dragged.LocalRotation(frame, kRightAnkle).m);
  // No contacts given: nothing moves.
  const std::vector<uint8_t> none(contacts.size(), 0);
  EXPECT_EQ(LockFeet(skeleton, dragged, {}, nullptr, &none).poses, dragged.poses);
  const std::vector<uint8_t> short_list(4, 1);
  EXPECT_THROW(LockFeet(skeleton, dragged, {}, nullptr, &short_list), std::invalid_argument);
}

// Issue 15: the calls combined with the test (options.given). The left ankle is dragged over the
// floor at 1.5 m/s in frames 0-9, stands on it in 10-19 and stands still in the air (20 cm) in
// 20-29; a model calls it standing in 0-9 and in 20-29, not in 10-19.
TEST(FootLock, GivenContactsNearTheFloorOrWithTheTest) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  const Motion motion = Standing([](int frame) {
    return Vec3{-0.2 + 0.05 * std::min(frame, 9), 0.1, frame < 20 ? 0.03 : 0.2};
  });
  std::vector<uint8_t> contacts(static_cast<size_t>(motion.num_frames()) * 4, 0);
  for (int frame = 0; frame < motion.num_frames(); ++frame)
    contacts[static_cast<size_t>(frame) * 4] = frame < 10 || frame >= 20;
  const std::vector<float> before = ComputeJoints(skeleton, motion);
  const auto lock = [&](GivenContacts given, FootLockReport* report) {
    FootLockOptions options;
    options.given = given;
    return ComputeJoints(skeleton, LockFeet(skeleton, motion, options, report, &contacts));
  };
  const auto place = [&](int begin, int end) {
    Vec3 sum{0, 0, 0};
    for (int frame = begin; frame < end; ++frame) sum = sum + JointAt(before, frame, kLeftAnkle);
    return (1.0 / (end - begin)) * sum;
  };
  const auto held_at = [&](const std::vector<float>& joints, int begin, int end, const Vec3& at) {
    for (int frame = begin; frame < end; ++frame) {
      EXPECT_NEAR(JointAt(joints, frame, kLeftAnkle).x, at.x, 1e-6) << frame;
      EXPECT_NEAR(JointAt(joints, frame, kLeftAnkle).y, at.y, 1e-6) << frame;
    }
  };
  const auto untouched = [&](const std::vector<float>& joints, int begin, int end) {
    for (int frame = begin; frame < end; ++frame)
      EXPECT_LT(Norm(JointAt(joints, frame, kLeftAnkle) - JointAt(before, frame, kLeftAnkle)), 1e-6)
          << frame;
  };
  // Alone: both called runs held, the one in the air too.
  FootLockReport alone;
  const std::vector<float> a = lock(GivenContacts::kAlone, &alone);
  EXPECT_EQ(alone.runs, 2);
  EXPECT_EQ(alone.held, 20);
  held_at(a, 0, 10, place(0, 10));
  held_at(a, 20, 30, place(20, 30));
  // Near the floor: the dragged run held, the one in the air left as it is.
  FootLockReport near;
  const std::vector<float> n = lock(GivenContacts::kNearFloor, &near);
  EXPECT_EQ(near.runs, 1);
  EXPECT_EQ(near.held, 10);
  held_at(n, 0, 10, place(0, 10));
  untouched(n, 20, 30);
  // Or the test: the dragged run and the standing one join into one run of 20 frames (with the
  // right foot and the toes the test holds), the air left as it is.
  const std::vector<float> o = lock(GivenContacts::kNearFloorOrTest, nullptr);
  held_at(o, 0, 20, place(0, 20));
  untouched(o, 23, 30);  // past the run's 0.1-s fade
}

TEST(FootLock, AnAnkleOutOfReachIsCountedNotStretched) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  // The left foot drags along the floor under a pelvis that walks 0.87 m at 0.9 m/s: from the
  // run's ends its mean place is out of the leg's reach.
  const auto pelvis_x = [](int frame) { return 0.03 * frame - 0.45; };
  const Motion dragging = Standing(
      [&](int frame) {
        return Vec3{pelvis_x(frame), 0.1, 0.03};
      },
      pelvis_x);
  FootLockReport report;
  FootLockOptions options;
  options.max_speed = 2;
  options.lower_pelvis = 0;  // the pelvis is the motion's own
  const Motion locked = LockFeet(skeleton, dragging, options, &report);
  EXPECT_GT(report.unreached, 0);
  EXPECT_GT(report.max_reach_error, 0.01);
  // Short of its place, the ankle stays on the floor at its own height: it does not float.
  const std::vector<float> before = ComputeJoints(skeleton, dragging);
  const std::vector<float> after = ComputeJoints(skeleton, locked);
  for (int frame = 0; frame < locked.num_frames(); ++frame)
    EXPECT_NEAR(JointAt(after, frame, kLeftAnkle).z, JointAt(before, frame, kLeftAnkle).z, 1e-6)
        << frame;
  // Bone lengths are the skeleton's by construction (rotations only).
  EXPECT_LT(EvaluateMotionPlausibility(skeleton, locked).bone_length_error, 1e-5);
}

// A foot dragged under a pelvis that walks 0.75 m at 0.78 m/s, a little too far for the leg to
// reach the run's place from its ends: with lower_pelvis the pelvis comes down, smoothly and no
// further than allowed, until the ankle reaches; the pelvis's path across the floor and the upper
// body's pose are the motion's.
TEST(FootLock, ThePelvisComesDownForAFootOutOfReach) {
  const Skeleton& skeleton = Skeleton::Smpl22();
  const auto pelvis_x = [](int frame) { return 0.026 * frame - 0.3; };
  const Motion dragging = Standing(
      [&](int frame) {
        return Vec3{pelvis_x(frame), 0.1, 0.03};
      },
      pelvis_x);
  FootLockOptions options;
  options.max_speed = 2;
  options.lower_pelvis = 0;
  FootLockReport kept;
  LockFeet(skeleton, dragging, options, &kept);
  ASSERT_GT(kept.unreached, 0);  // out of reach with the pelvis where it was
  options.lower_pelvis = 0.1;
  FootLockReport report;
  const Motion locked = LockFeet(skeleton, dragging, options, &report);
  EXPECT_EQ(report.unreached, 0);
  EXPECT_GT(report.max_lowered, 0.0);
  EXPECT_LE(report.max_lowered, 0.1);
  EXPECT_EQ(EvaluateMotionPlausibility(skeleton, locked).foot_skate_ratio, 0.0);
  const std::vector<float> before = ComputeJoints(skeleton, dragging);
  const std::vector<float> after = ComputeJoints(skeleton, locked);
  double previous_step = 0;
  for (int frame = 0; frame < locked.num_frames(); ++frame) {
    const Vec3 was = dragging.Translation(frame), now = locked.Translation(frame);
    EXPECT_EQ(now.x, was.x);
    EXPECT_EQ(now.y, was.y);
    const double down = was.z - now.z;
    EXPECT_GE(down, 0.0) << frame;
    EXPECT_LE(down, 0.1 + 1e-9) << frame;
    // The head comes down with the pelvis, by as much.
    EXPECT_NEAR(Norm(JointAt(after, frame, 15) - (JointAt(before, frame, 15) - Vec3{0, 0, down})),
                0.0, 1e-5)
        << frame;
    // The ankle stays at its own height.
    EXPECT_NEAR(JointAt(after, frame, kLeftAnkle).z, JointAt(before, frame, kLeftAnkle).z, 1e-5)
        << frame;
    // Smoothly: the lowering's frame-to-frame change itself changes by under 5 mm a frame.
    if (frame > 0) {
      const double step =
          down - (dragging.Translation(frame - 1).z - locked.Translation(frame - 1).z);
      if (frame > 1) {
        EXPECT_LT(std::abs(step - previous_step), 0.005) << frame;
      }
      previous_step = step;
    }
  }
}

TEST(FootLock, OptionsFromAMapNameTheBadKey) {
  auto options = FootLockOptionsFromJson(
      nlohmann::json{{"max_speed", 2.0}, {"blend_seconds", 0.2}, {"motions", "edit"}},
      "stage.params", {"motions"});
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_EQ(options->max_speed, 2.0);
  EXPECT_EQ(options->blend_seconds, 0.2);
  EXPECT_EQ(options->contact_height, FootLockOptions{}.contact_height);
  const auto negative = FootLockOptionsFromJson(nlohmann::json{{"max_speed", -1}}, "stage.params");
  ASSERT_FALSE(negative.ok());
  EXPECT_EQ(negative.status().message(), "stage.params.max_speed: must be > 0 m/s");
  const auto deep = FootLockOptionsFromJson(nlohmann::json{{"lower_pelvis", 0.8}}, "stage.params");
  ASSERT_FALSE(deep.ok());
  EXPECT_EQ(deep.status().message(), "stage.params.lower_pelvis: must be in [0, 0.5] m");
  const auto text = FootLockOptionsFromJson(nlohmann::json{{"min_frames", "two"}}, "x");
  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().message().rfind("x: ", 0), 0u) << text.status().message();
  EXPECT_FALSE(FootLockOptionsFromJson(nlohmann::json::array(), "x").ok());
  // A misspelt option is an error, not the default.
  const auto misspelt = FootLockOptionsFromJson(nlohmann::json{{"max_sped", 2.0}}, "x");
  ASSERT_FALSE(misspelt.ok());
  EXPECT_EQ(misspelt.status().message().rfind("x.max_sped: unknown", 0), 0u)
      << misspelt.status().message();
  // The map the stage's summary records reads back as the same options.
  FootLockOptions changed;
  changed.contact_height = 0.07;
  changed.max_speed = 2.5;
  changed.min_frames = 3;
  changed.blend_seconds = 0.2;
  changed.lower_pelvis = 0.05;
  const auto back = FootLockOptionsFromJson(FootLockOptionsToJson(changed), "x");
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(FootLockOptionsToJson(*back), FootLockOptionsToJson(changed));
  EXPECT_EQ(back->min_frames, 3);
  EXPECT_EQ(back->contact_height, 0.07);
}

}  // namespace
}  // namespace motionpipe
