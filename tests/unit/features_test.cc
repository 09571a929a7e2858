#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "motionpipe/features/motionfix207.h"
#include "motionpipe/features/normalization.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/motion/compare.h"
#include "test_util.h"

namespace motionpipe {
namespace {

// The same motion turned by `angle` about the vertical axis and shifted on the ground.
Motion TurnAndShift(const Motion& motion, double angle, double dx, double dy) {
  Motion out = motion;
  const Mat3 turn = RotZ(angle);
  for (int64_t frame = 0; frame < motion.num_frames(); ++frame) {
    out.SetLocalRotation(frame, 0, turn * motion.LocalRotation(frame, 0));
    out.SetTranslation(frame, turn * motion.Translation(frame) + Vec3{dx, dy, 0});
  }
  return out;
}

double MaxFeatureDiff(const FeatureMatrix& a, const FeatureMatrix& b) {
  double worst = 0;
  for (size_t k = 0; k < a.data.size(); ++k)
    worst = std::max(worst, static_cast<double>(std::abs(a.data[k] - b.data[k])));
  return worst;
}

TEST(MotionFix207, LayoutMatchesTheReferenceGroups) {
  const auto& groups = MotionFixFeatureGroups();
  EXPECT_EQ(groups.front().begin, 0);
  EXPECT_EQ(groups.back().end, kMotionFixFeatureDim);
  for (size_t k = 1; k < groups.size(); ++k) EXPECT_EQ(groups[k].begin, groups[k - 1].end);
}

TEST(MotionFix207, EncodeDecodeRoundTripTo1e5) {
  const Skeleton& s = Skeleton::Smpl22();
  for (uint32_t seed : {1u, 2u, 3u}) {
    const Motion motion = testing::SmoothMotion(300, seed);
    const FeatureMatrix f = EncodeMotionFix207(s, motion);
    ASSERT_EQ(f.rows, 300);
    ASSERT_EQ(f.cols, 207);
    const MotionDifference d =
        CompareMotions(s, motion, DecodeMotionFix207(f, AnchorOf(motion), 30));
    EXPECT_LT(d.max_rotation, 1e-5) << seed;
    EXPECT_LT(d.max_translation, 1e-5) << seed;
    EXPECT_LT(d.max_joint, 1e-5) << seed;
  }
}

TEST(MotionFix207, FirstFrameConventionsAndPelvisRelativeJoints) {
  const Skeleton& s = Skeleton::Smpl22();
  const Motion motion = testing::SmoothMotion(5, 4);
  const FeatureMatrix f = EncodeMotionFix207(s, motion);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(f.at(0, c), 0.0f);  // no velocity at frame 0
  const float identity6d[] = {1, 0, 0, 0, 1, 0};
  for (int c = 0; c < 6; ++c) EXPECT_EQ(f.at(0, 9 + c), identity6d[c]);
  for (int c = 141; c < 144; ++c) EXPECT_EQ(f.at(2, c), 0.0f);  // pelvis relative to itself
  // Heading removed: the orientation's own heading is zero.
  const Mat3 orient = ReadRot6d(f.row(3) + 3);
  EXPECT_NEAR(HeadingZYX(orient), 0.0, 1e-6);
}

TEST(MotionFix207, InvariantToHeadingAndGroundPosition) {
  const Skeleton& s = Skeleton::Smpl22();
  const Motion motion = testing::SmoothMotion(120, 5);
  const FeatureMatrix a = EncodeMotionFix207(s, motion);
  const FeatureMatrix b = EncodeMotionFix207(s, TurnAndShift(motion, 2.1, 3.0, -7.0));
  EXPECT_LT(MaxFeatureDiff(a, b), 2e-5);
}

TEST(MotionFix207, StandingPoseMatchesReferenceStatistics) {
  // The shipped MotionFix means describe upright bodies: orientation ~ Rx(90), heading delta ~
  // identity.
  auto stats = LoadStats(testing::DataDir() + "/stats/motionfix_feature_stats.json");
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  const Motion rest = Motion::Rest(3, 30, 0.9);
  const FeatureMatrix f = EncodeMotionFix207(Skeleton::Smpl22(), rest);
  for (int c = 3; c < 15; ++c)
    EXPECT_NEAR(f.at(1, c), stats->mean[static_cast<size_t>(c)], 0.06) << c;
}

TEST(Temos135, EncodeDecodeRoundTripTo1e5) {
  const Skeleton& s = Skeleton::Smpl22();
  for (uint32_t seed : {1u, 7u}) {
    const Motion motion = testing::SmoothMotion(300, seed);
    const FeatureMatrix f = EncodeTemos135(motion);
    ASSERT_EQ(f.cols, 135);
    const MotionDifference d = CompareMotions(s, motion, DecodeTemos135(f, AnchorOf(motion), 30));
    EXPECT_LT(d.max_rotation, 1e-5);
    EXPECT_LT(d.max_translation, 1e-5);
  }
}

TEST(Temos135, CanonicalisationIsInvariantToInitialHeading) {
  const Motion motion = testing::SmoothMotion(90, 8);
  const FeatureMatrix a = EncodeTemos135(motion);
  for (double angle : {0.5, -2.0, 3.0}) {
    const FeatureMatrix b = EncodeTemos135(TurnAndShift(motion, angle, -4.0, 1.5));
    EXPECT_LT(MaxFeatureDiff(a, b), 1e-5) << angle;
  }
  // Decoded without an anchor, the motion starts at the origin facing the canonical heading.
  const Motion canonical = DecodeTemos135(a, CanonicalTemosAnchor(), 30);
  EXPECT_NEAR(HeadingZYX(canonical.LocalRotation(0, 0)), kTemosCanonicalHeading, 1e-6);
  EXPECT_NEAR(canonical.Translation(0).x, 0.0, 1e-9);
}

// Issue 15: a model at its own rate (SINC's `fps`) trains on every k-th frame's features, made from
// the full-rate ones; they must be what encoding the resampled motion gives, velocities included.
TEST(Temos135, EveryKthFrameIsTheEncodingOfTheMotionResampledByIndex) {
  const Motion motion = testing::SmoothMotion(31, 5);
  const FeatureMatrix all = EncodeTemos135(motion);
  std::vector<float> thirds;
  for (const int64_t k : {1, 3, 4, 40}) {
    std::vector<float> out(all.data.size(), -7.f);
    const int64_t rows = EveryKthTemos135(all.data.data(), all.rows, k, out.data());
    const FeatureMatrix expected = EncodeTemos135(Resample(motion, 30.0 / static_cast<double>(k)));
    ASSERT_EQ(rows, expected.rows) << k;
    EXPECT_EQ(rows, (31 - 1) / k + 1) << k;
    double worst = 0;
    for (int64_t i = 0; i < rows * kTemosFeatureDim; ++i)
      worst = std::max(worst, std::abs(static_cast<double>(out[static_cast<size_t>(i)]) -
                                       expected.data[static_cast<size_t>(i)]));
    EXPECT_LT(worst, 1e-5) << k;
    if (k == 3) thirds.assign(out.begin(), out.begin() + rows * kTemosFeatureDim);
  }
  // The trajectory moves, so the velocities are not trivially 0.
  EXPECT_GT(std::abs(thirds[kTemosFeatureDim + 1]) + std::abs(thirds[kTemosFeatureDim + 2]), 1e-4);
  // In place: the same rows.
  std::vector<float> in_place = all.data;
  ASSERT_EQ(EveryKthTemos135(in_place.data(), all.rows, 3, in_place.data()), 11);
  in_place.resize(thirds.size());
  EXPECT_EQ(in_place, thirds);
  EXPECT_EQ(EveryKthTemos135(nullptr, 0, 3, nullptr), 0);
}

TEST(Temos135, CanonicalHeadingMatchesTheReferenceMean) {
  // The shipped SINC mean has the first pelvis facing -x: 6D orientation ~ [0, 0, -1, -1, 0, 0].
  auto stats = LoadStats(testing::DataDir() + "/stats/sinc_tmr_feature_stats.json",
                         "sinc_rfeats_babel-amass");
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  ASSERT_EQ(stats->mean.size(), 135u);
  const FeatureMatrix f = EncodeTemos135(testing::SmoothMotion(2, 3));
  const Mat3 canonical = ReadRot6d(f.row(0) + 3);
  EXPECT_NEAR(HeadingZYX(canonical), -kPi / 2, 1e-6);
  // Sign pattern of the reference: r02 and r10 strongly negative.
  EXPECT_LT(stats->mean[5], -0.5f);
  EXPECT_LT(stats->mean[6], -0.5f);
  const FeatureMatrix upright = EncodeTemos135(Motion::Rest(2, 30, 0.9));
  EXPECT_NEAR(upright.at(0, 5), -1.0, 1e-6);
  EXPECT_NEAR(upright.at(0, 6), -1.0, 1e-6);
}

TEST(Normalization, ComputeSaveLoadApply) {
  const Skeleton& s = Skeleton::Smpl22();
  FeatureMatrix a = EncodeMotionFix207(s, testing::SmoothMotion(50, 1));
  FeatureMatrix b = EncodeMotionFix207(s, testing::SmoothMotion(70, 2));
  auto stats = ComputeStats({&a, &b}, NormScale::kTwoSigma);
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->count, 120);
  // Column 20 by hand.
  double mean = 0;
  for (const FeatureMatrix* m : {&a, &b})
    for (int64_t r = 0; r < m->rows; ++r) mean += m->at(r, 20);
  mean /= 120;
  EXPECT_NEAR(stats->mean[20], mean, 1e-6);
  const std::string path = ::testing::TempDir() + "/stats.json";
  ASSERT_TRUE(SaveStats(path, *stats).ok());
  auto loaded = LoadStats(path);
  ASSERT_TRUE(loaded.ok());
  EXPECT_EQ(loaded->scale, NormScale::kTwoSigma);
  EXPECT_EQ(loaded->mean, stats->mean);
  FeatureMatrix copy = a;
  ASSERT_TRUE(Normalize(&copy, *loaded).ok());
  EXPECT_NEAR(copy.at(0, 20), (a.at(0, 20) - stats->mean[20]) / (2 * (stats->std[20] + 1e-5)),
              1e-4);
  ASSERT_TRUE(Denormalize(&copy, *loaded).ok());
  EXPECT_LT(MaxFeatureDiff(copy, a), 1e-5);
  FeatureMatrix wrong(3, 5);
  EXPECT_FALSE(Normalize(&wrong, *loaded).ok());
}

TEST(Normalization, ReferenceFilesLoadWithTheirConventions) {
  auto mf = LoadStats(testing::DataDir() + "/stats/motionfix_feature_stats.json");
  ASSERT_TRUE(mf.ok());
  EXPECT_EQ(mf->mean.size(), 207u);
  EXPECT_EQ(mf->scale, NormScale::kTwoSigma);
  auto needs_key = LoadStats(testing::DataDir() + "/stats/sinc_tmr_feature_stats.json");
  EXPECT_FALSE(needs_key.ok());
  auto wrong_key = LoadStats(testing::DataDir() + "/stats/sinc_tmr_feature_stats.json", "nope");
  ASSERT_FALSE(wrong_key.ok());
  EXPECT_NE(wrong_key.status().message().find("no entry 'nope_mean'"), std::string::npos);
  const std::string bad = ::testing::TempDir() + "/bad_stats.json";
  std::FILE* f = std::fopen(bad.c_str(), "w");
  std::fputs("{\"format\": \"motionpipe.stats/1\", \"mean\": [1, 2], \"std\": [1]}", f);
  std::fclose(f);
  auto mismatch = LoadStats(bad);
  ASSERT_FALSE(mismatch.ok());
  EXPECT_NE(mismatch.status().message().find("bad_stats.json"), std::string::npos);
}

}  // namespace
}  // namespace motionpipe
