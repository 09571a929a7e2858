#include "motionpipe/motion/plausibility.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <vector>

namespace motionpipe {
namespace {

constexpr int kLeftToe = 10, kRightToe = 11;

// [frames, 22, 3] joint positions: every joint 1 m above the floor except the left toe, which is
// at `left_toe(t)` for t the frame's time in seconds; the right toe stands still on the floor.
std::vector<float> Joints(int64_t frames, double fps, const std::function<Vec3(double)>& left_toe) {
  std::vector<float> joints(static_cast<size_t>(frames) * kNumJoints * 3, 0.0f);
  for (int64_t f = 0; f < frames; ++f) {
    for (int j = 0; j < kNumJoints; ++j) {
      Vec3 p{0.0, 0.1 * j, 1.0};
      if (j == kLeftToe) p = left_toe(static_cast<double>(f) / fps);
      if (j == kRightToe) p = {0.0, -0.2, 0.02};
      float* out = &joints[(static_cast<size_t>(f) * kNumJoints + static_cast<size_t>(j)) * 3];
      out[0] = static_cast<float>(p.x), out[1] = static_cast<float>(p.y),
      out[2] = static_cast<float>(p.z);
    }
  }
  return joints;
}

PlausibilityReport Evaluate(const std::vector<float>& joints, double fps) {
  const int64_t frames = static_cast<int64_t>(joints.size()) / (kNumJoints * 3);
  return EvaluatePlausibility(Skeleton::Smpl22(), joints.data(), frames, fps, nullptr);
}

TEST(GmdSkatingRatio, ASlowSlideSkatesByOurMeasureAndNotByTheFields) {
  // 0.3 m/s on the floor: above our 0.15 m/s, below GMD's 0.5 m/s.
  const auto joints = Joints(31, 30.0, [](double t) { return Vec3{0.3 * t, 0.2, 0.02}; });
  const PlausibilityReport r = Evaluate(joints, 30.0);
  EXPECT_GT(r.foot_skate_ratio, 0.2);
  EXPECT_EQ(r.skating_ratio_gmd, 0.0);
}

TEST(GmdSkatingRatio, CountsPairsWhoseSpeedAndWindowMeanBothExceedTheThreshold) {
  // 1 s at 30 fps resamples to 21 frames at 20 fps (20 pairs). At 1 m/s every pair skates (the
  // end pairs' windows, padded with zeros, still average 0.6 m/s); at 0.7 m/s the two end pairs'
  // windows average 0.42 m/s and do not.
  const auto fast = Joints(31, 30.0, [](double t) { return Vec3{1.0 * t, 0.2, 0.02}; });
  EXPECT_DOUBLE_EQ(Evaluate(fast, 30.0).skating_ratio_gmd, 1.0);
  const auto medium = Joints(31, 30.0, [](double t) { return Vec3{0.7 * t, 0.2, 0.02}; });
  EXPECT_DOUBLE_EQ(Evaluate(medium, 30.0).skating_ratio_gmd, 18.0 / 20.0);
}

TEST(GmdSkatingRatio, AFootAboveFiveCentimetresDoesNotSkate) {
  const auto swing = Joints(31, 30.0, [](double t) { return Vec3{2.0 * t, 0.2, 0.06}; });
  EXPECT_EQ(Evaluate(swing, 30.0).skating_ratio_gmd, 0.0);
  EXPECT_EQ(Evaluate(swing, 30.0).foot_skate_ratio, 0.0);
}

TEST(GmdSkatingRatio, AOnePairSpikeSkatesOnlyWhenItsWindowMeanExceedsTheThreshold) {
  // At 20 fps the left toe jumps d metres between frames 10 and 11 and is still otherwise: the
  // pair's speed is 20 d, its window mean 4 d.
  const auto jump = [](double d) {
    return Joints(21, 20.0, [d](double t) { return Vec3{t > 0.52 ? d : 0.0, 0.2, 0.02}; });
  };
  EXPECT_EQ(Evaluate(jump(0.1), 20.0).skating_ratio_gmd, 0.0);  // 2 m/s, window 0.4 m/s
  EXPECT_DOUBLE_EQ(Evaluate(jump(0.15), 20.0).skating_ratio_gmd, 1.0 / 20.0);  // 3, 0.6 m/s
}

TEST(GmdSkatingRatio, DoesNotDependOnTheFrameRateOfTheSameMotion) {
  // Still, then sliding at 1 m/s from 0.5 s to 1.5 s, then still: at 20 fps 20 of 40 pairs skate;
  // sampled at 30 or 60 fps it is resampled to the same 20-fps frames.
  const auto toe = [](double t) { return Vec3{std::clamp(t, 0.5, 1.5) - 0.5, 0.2, 0.02}; };
  EXPECT_DOUBLE_EQ(Evaluate(Joints(41, 20.0, toe), 20.0).skating_ratio_gmd, 0.5);
  EXPECT_DOUBLE_EQ(Evaluate(Joints(61, 30.0, toe), 30.0).skating_ratio_gmd, 0.5);
  EXPECT_DOUBLE_EQ(Evaluate(Joints(121, 60.0, toe), 60.0).skating_ratio_gmd, 0.5);
}

}  // namespace
}  // namespace motionpipe
