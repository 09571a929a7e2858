#include "motionpipe/skeleton/skeleton.h"

#include <gtest/gtest.h>

#include "motionpipe/base/file.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/motion/plausibility.h"
#include "test_util.h"

namespace motionpipe {
namespace {

TEST(Skeleton, EmbeddedFactsMatchTheDataFile) {
  const Skeleton& s = Skeleton::Smpl22();
  ASSERT_EQ(s.joint_names().size(), 22u);
  EXPECT_EQ(s.parents(), (std::vector<int>{-1, 0, 0, 0, 1,  2,  3,  4,  5,  6,  7,
                                           8,  9, 9, 9, 12, 13, 14, 16, 17, 18, 19}));
  EXPECT_EQ(s.joint_names()[15], "head");
  EXPECT_EQ(s.JointIndex("left_wrist"), 20);
  EXPECT_EQ(s.part_of_joint(0), BodyPart::kGlobal);
  EXPECT_EQ(s.part_of_joint(20), BodyPart::kLeftArm);
  EXPECT_EQ(s.part_of_joint(11), BodyPart::kRightLeg);
  auto text = ReadFile(testing::DataDir() + "/skeleton/smpl22.json");
  ASSERT_TRUE(text.ok());
  auto loaded = Skeleton::FromJson(*text, "smpl22.json");
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  for (int j = 0; j < kNumJoints; ++j) {
    EXPECT_NEAR(Norm(loaded->rest_offsets()[static_cast<size_t>(j)]),
                loaded->bone_lengths()[static_cast<size_t>(j)], 1e-12);
  }
}

TEST(Skeleton, TPoseArmsPointSidewaysFileDirectionsHangDown) {
  const Skeleton& t = Skeleton::Smpl22();
  EXPECT_GT(t.rest_offsets()[18].x, 0.2);  // left elbow to the body's left (+x)
  EXPECT_LT(t.rest_offsets()[19].x, -0.2);
  auto text = ReadFile(testing::DataDir() + "/skeleton/smpl22.json");
  auto raw = Skeleton::FromJson(*text, "smpl22.json", RestPose::kFileDirections);
  ASSERT_TRUE(raw.ok());
  EXPECT_LT(raw->rest_offsets()[18].y, -0.2);  // hanging down
  EXPECT_GT(raw->rest_offsets()[15].z, 0.1);   // the file's head offset points forward
  EXPECT_GT(t.rest_offsets()[15].y, 0.1);      // SMPL's head sits above the neck
}

TEST(Skeleton, BadJsonNamesTheOriginAndField) {
  auto bad = Skeleton::FromJson("{\"joint_names\": []}", "my.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("my.json"), std::string::npos);
  auto broken = Skeleton::FromJson("{not json", "broken.json");
  ASSERT_FALSE(broken.ok());
  EXPECT_NE(broken.status().message().find("broken.json: malformed JSON"), std::string::npos);
}

TEST(ForwardKinematics, RestPoseStandsUprightInZUp) {
  const Skeleton& s = Skeleton::Smpl22();
  const Motion rest = Motion::Rest(1, 30, s.RestPelvisHeight());
  const std::vector<float> joints = ComputeJoints(s, rest);
  const auto z = [&](int j) { return joints[static_cast<size_t>(j * 3 + 2)]; };
  const auto x = [&](int j) { return joints[static_cast<size_t>(j * 3 + 0)]; };
  EXPECT_NEAR(z(7), 0.0, 1e-6);   // left ankle on the floor
  EXPECT_NEAR(z(10), 0.0, 1e-6);  // left foot on the floor
  EXPECT_GT(z(15), z(12));        // head above neck above pelvis
  EXPECT_GT(z(12), z(0));
  EXPECT_GT(x(1), 0);  // left hip on +x (the body's left at heading 0)
  EXPECT_GT(x(20), 0.5);
  EXPECT_LT(x(21), -0.5);
  // Pelvis to head along z equals the spine, neck and head lengths (all vertical in the rest pose).
  const auto& len = s.bone_lengths();
  EXPECT_NEAR(z(15) - z(0), len[3] + len[6] + len[9] + len[12] + len[15], 1e-6);
  // Feet point forward: SMPL forward (+z body) is -y in the z-up world at heading 0.
  EXPECT_LT(joints[10 * 3 + 1] - joints[7 * 3 + 1], -0.1);
}

TEST(ForwardKinematics, KneeBendMovesTheAnkleBackward) {
  const Skeleton& s = Skeleton::Smpl22();
  Motion motion = Motion::Rest(1, 30, 1.0);
  motion.SetLocalRotation(0, 4, RotX(kPi / 2));  // left knee: 90 degrees about the body's x axis
  const std::vector<float> joints = ComputeJoints(s, motion);
  const Vec3 knee{joints[4 * 3], joints[4 * 3 + 1], joints[4 * 3 + 2]};
  const Vec3 ankle{joints[7 * 3], joints[7 * 3 + 1], joints[7 * 3 + 2]};
  // The shin turns from hanging down to horizontal: same height as the knee, one shin length away.
  EXPECT_NEAR(ankle.z, knee.z, 1e-6);
  EXPECT_NEAR(Norm(ankle - knee), s.bone_lengths()[7], 1e-6);
  EXPECT_GT(ankle.y - knee.y, 0.4);  // behind the body (forward is -y)
}

TEST(ForwardKinematics, BoneLengthsStayFixedUnderAnyPose) {
  const Skeleton& s = Skeleton::Smpl22();
  const Motion motion = testing::SmoothMotion(40, 9);
  const std::vector<float> joints = ComputeJoints(s, motion);
  for (int64_t frame = 0; frame < motion.num_frames(); ++frame) {
    for (int j = 1; j < kNumJoints; ++j) {
      const int p = s.parents()[static_cast<size_t>(j)];
      const float* a = &joints[static_cast<size_t>((frame * kNumJoints + j) * 3)];
      const float* b = &joints[static_cast<size_t>((frame * kNumJoints + p) * 3)];
      const double len = std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                   (a[2] - b[2]) * (a[2] - b[2]));
      EXPECT_NEAR(len, s.bone_lengths()[static_cast<size_t>(j)], 1e-5);
    }
  }
}

TEST(Motion, ValidateRejectsNaNAndBadShapes) {
  Motion motion = testing::SmoothMotion(10, 1);
  EXPECT_TRUE(ValidateMotion(motion, "m").ok());
  motion.trans[7] = std::nanf("");
  const Status nan = ValidateMotion(motion, "clip.npz");
  EXPECT_FALSE(nan.ok());
  EXPECT_NE(nan.message().find("clip.npz: non-finite translation at frame 2"), std::string::npos);
  Motion empty;
  EXPECT_FALSE(ValidateMotion(empty, "e").ok());
  motion = testing::SmoothMotion(10, 1);
  motion.poses.pop_back();
  EXPECT_FALSE(ValidateMotion(motion, "m").ok());
}

TEST(Motion, ResampleByIndexFollowsNumpyArange) {
  const Motion motion = testing::SmoothMotion(994, 3, 120);
  const Motion down = Resample(motion, 30);
  EXPECT_EQ(down.num_frames(), 249);  // len(np.arange(0, 994, 4))
  EXPECT_EQ(down.fps, 30);
  for (int64_t frame : {0, 1, 100, 248}) {
    EXPECT_EQ(down.trans[static_cast<size_t>(frame * 3)],
              motion.trans[static_cast<size_t>(frame * 4 * 3)]);
  }
  const Motion odd = Resample(testing::SmoothMotion(100, 3, 100), 30);
  EXPECT_EQ(odd.num_frames(), 30);  // len(np.arange(0, 100, 10/3))
}

TEST(Motion, RatesThatAgreeToRoundingKeepEveryFrame) {
  // A BVH's "Frame Time: 0.03333333" is 30.0000003 fps: resampling to 30 must keep all 249 frames.
  Motion m = Motion::Rest(249, 1.0 / 0.03333333, 0.9);
  EXPECT_EQ(Resample(m, 30).num_frames(), 249);
  m.fps = 120.0000012;
  EXPECT_EQ(Resample(m, 30).num_frames(), 63);  // frames 0, 4, ..., 248
  // The rule itself, which the editor's network rate shares: symmetric, 10 ppm of the larger rate.
  EXPECT_TRUE(SameFrameRate(30, 1.0 / 0.03333333));
  EXPECT_TRUE(SameFrameRate(1.0 / 0.03333333, 30));
  EXPECT_TRUE(SameFrameRate(30, 30.0002));
  EXPECT_FALSE(SameFrameRate(30, 30.001));
  EXPECT_FALSE(SameFrameRate(10, 30));
}

// Issue 17: `import-bvh --fps 1e9` aborted with std::bad_alloc; `--fps 1e5` took 2.4 GB.
TEST(Motion, AnAbsurdResamplingRateIsAnErrorNamingTheFile) {
  const Motion motion = testing::SmoothMotion(100, 3, 120);
  EXPECT_TRUE(CheckResample(motion, 30, "a.bvh").ok());
  EXPECT_TRUE(CheckResample(motion, 0, "a.bvh").ok());  // 0 keeps the rate
  EXPECT_TRUE(CheckResample(motion, kMaxFrameRate, "a.bvh").ok());
  for (double fps : {1e9, 1e5, 1001.0, std::nan("")}) {
    const Status s = CheckResample(motion, fps, "a.bvh");
    ASSERT_FALSE(s.ok()) << fps;
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find("a.bvh: a frame rate of"), std::string::npos) << s.message();
  }
  // A legal rate that would still make more frames than a motion can sensibly have.
  Motion slow = testing::SmoothMotion(2000, 3, 0.5);
  const Status s = CheckResample(slow, 1000, "slow.npz");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("slow.npz: resampling 2000 frames"), std::string::npos) << s.message();
}

// A model at its own rate (the MDT's and SINC's `fps`) cuts its inputs the way its training data
// were cut: every k-th frame for a whole ratio, else interpolated; its outputs come back to exactly
// the frames asked for.
TEST(Motion, AModelsRateKeepsEveryKthFrameForWholeRatiosAndComesBackAtTheAskedLength) {
  EXPECT_EQ(WholeFrameStep(30, 10), 3);
  EXPECT_EQ(WholeFrameStep(120.0000012, 10), 12);
  EXPECT_EQ(WholeFrameStep(30, 0), 1);
  EXPECT_EQ(WholeFrameStep(30, 30), 1);
  EXPECT_EQ(WholeFrameStep(25, 10), 0);
  EXPECT_EQ(WholeFrameStep(30, 60), 0);
  const Motion motion = testing::SmoothMotion(31, 4, 30);
  const Motion tenth = ToModelRate(motion, 10);
  ASSERT_EQ(tenth.num_frames(), 11);
  EXPECT_EQ(tenth.fps, 10);
  EXPECT_EQ(tenth.poses[static_cast<size_t>(5 * kNumJoints * 3 + 7)],
            motion.poses[static_cast<size_t>(15 * kNumJoints * 3 + 7)]);  // a frame, not a blend
  const Motion twenty = ToModelRate(motion, 20);                          // 1.5 frames: slerped
  EXPECT_EQ(twenty.num_frames(), 21);
  EXPECT_LT(Norm(twenty.Translation(1) - 0.5 * (motion.Translation(1) + motion.Translation(2))),
            1e-6);
  EXPECT_EQ(ToModelRate(motion, 0).poses, motion.poses);
  EXPECT_EQ(FramesCovering(31, 30, 10), 11);
  EXPECT_EQ(FramesCovering(32, 30, 10), 12);  // frame 31 lies past network frame 10
  EXPECT_EQ(FramesCovering(32, 30, 0), 32);
  const Result<Motion> back = ResampleToFrames(ToModelRate(motion, 10), 30, 32);
  ASSERT_TRUE(back.ok());
  ASSERT_EQ(back->num_frames(), 32);
  EXPECT_EQ(back->fps, 30);
  EXPECT_LT(Norm(back->Translation(15) - motion.Translation(15)), 1e-6);  // a kept frame
  EXPECT_EQ(back->trans[31 * 3], back->trans[30 * 3]);                    // the last one repeated
  EXPECT_FALSE(ResampleToFrames(Motion{}, 30, 3).ok());
}

TEST(Motion, ResampleInterpolateIsSmoothAndExactAtSamples) {
  const Motion motion = testing::SmoothMotion(61, 5, 30);
  const Motion up = Resample(motion, 60, ResampleMethod::kInterpolate);
  EXPECT_EQ(up.num_frames(), 121);
  for (int joint = 0; joint < kNumJoints; ++joint) {
    EXPECT_LT(MaxAbsDiff(up.LocalRotation(20, joint), motion.LocalRotation(10, joint)), 1e-6);
  }
  const Vec3 mid = up.Translation(21);
  const Vec3 expect = 0.5 * (motion.Translation(10) + motion.Translation(11));
  EXPECT_LT(Norm(mid - expect), 1e-6);
}

TEST(Motion, ResampleCubicPassesThroughTheFramesAndFollowsASmoothMotionCloserThanLinear) {
  // A smooth 30-fps motion taken to a model's 10 fps by index and brought back: both upsamplings
  // give back every kept frame; between them the spline lies nearer the original than slerp does
  // (its error is third order in the frame step, linear interpolation's second), and its joints'
  // jerk is lower: slerp's velocity jumps at every kept frame.
  const Motion motion = testing::SmoothMotion(91, 7, 30);
  const Motion low = ToModelRate(motion, 10);
  const Result<Motion> linear = ResampleToFrames(low, 30, 91, ResampleMethod::kInterpolate);
  const Result<Motion> cubic = ResampleToFrames(low, 30, 91, ResampleMethod::kCubic);
  ASSERT_TRUE(linear.ok() && cubic.ok());
  ASSERT_EQ(cubic->num_frames(), 91);
  double linear_error = 0, cubic_error = 0;
  for (int64_t frame = 0; frame < 91; ++frame) {
    for (int joint = 0; joint < kNumJoints; ++joint) {
      const double off =
          MaxAbsDiff(cubic->LocalRotation(frame, joint), motion.LocalRotation(frame, joint));
      if (frame % 3 == 0) {
        EXPECT_LT(off, 1e-6) << "frame " << frame << " joint " << joint;
      }
      cubic_error += off;
      linear_error +=
          MaxAbsDiff(linear->LocalRotation(frame, joint), motion.LocalRotation(frame, joint));
    }
    if (frame % 3 == 0) {
      EXPECT_LT(Norm(cubic->Translation(frame) - motion.Translation(frame)), 1e-9);
    }
  }
  EXPECT_LT(cubic_error, 0.5 * linear_error);
  const Skeleton skeleton = Skeleton::Smpl22();
  const double jerk_linear = EvaluateMotionPlausibility(skeleton, *linear).jerk_mean;
  const double jerk_cubic = EvaluateMotionPlausibility(skeleton, *cubic).jerk_mean;
  const double jerk_original = EvaluateMotionPlausibility(skeleton, motion).jerk_mean;
  EXPECT_LT(jerk_cubic, jerk_linear);
  EXPECT_LT(std::abs(jerk_cubic - jerk_original), std::abs(jerk_linear - jerk_original));
}

TEST(Motion, ResampleCubicKeepsAStraightPathAndTakesTheShortArc) {
  // Translation along a line at constant speed is a line again between the second and the
  // second-to-last frame (the end segments see a repeated frame); a rotation whose quaternion
  // changes sign between frames (q and -q are one rotation) is not spun the long way round.
  Motion motion = Motion::Rest(6, 10, 0.9);
  for (int64_t frame = 0; frame < 6; ++frame) {
    motion.SetTranslation(frame, {0.3 * static_cast<double>(frame), 1.0, 0.9});
    // 2.6 to 3.85 rad: through pi, where the quaternion of the rotation changes sign
    motion.SetLocalRotation(frame, 1, RotZ(2.6 + 0.25 * static_cast<double>(frame)));
  }
  const Motion up = Resample(motion, 30, ResampleMethod::kCubic);
  ASSERT_EQ(up.num_frames(), 16);
  for (int64_t frame = 3; frame <= 12; ++frame) {
    EXPECT_NEAR(up.Translation(frame).x, 0.1 * static_cast<double>(frame), 1e-6) << frame;
    const double angle = 2.6 + 0.25 * static_cast<double>(frame) / 3;
    EXPECT_LT(MaxAbsDiff(up.LocalRotation(frame, 1), RotZ(angle)), 2e-3) << frame;
  }
  for (int64_t frame : {1, 2, 13, 14}) {  // the end segments: slower near the repeated frame
    const double angle = 2.6 + 0.25 * static_cast<double>(frame) / 3;
    EXPECT_LT(MaxAbsDiff(up.LocalRotation(frame, 1), RotZ(angle)), 0.03) << frame;
  }
  EXPECT_FALSE(ResampleToFrames(motion, 30, 16, ResampleMethod::kByIndex).ok());
}

TEST(Motion, ParseUpsamplingNamesTheOptionInItsError) {
  EXPECT_EQ(*ParseUpsampling("linear", "upsample"), ResampleMethod::kInterpolate);
  EXPECT_EQ(*ParseUpsampling("cubic", "upsample"), ResampleMethod::kCubic);
  const Result<ResampleMethod> bad = ParseUpsampling("spline", "edit option upsample");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "edit option upsample must be linear or cubic (got 'spline')");
}

}  // namespace
}  // namespace motionpipe
