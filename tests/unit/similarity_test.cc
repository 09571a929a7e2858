// SimMotionEdit's similarity curve, MotionSNR and classes (similarity.h), checked against naive
// implementations written here, hand-computed cases and the core library's own rotations and FK.
#include "motionpipe/similarity/similarity.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>

#include "motionpipe/base/file.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/math/rotation.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/similarity/filter.h"
#include "simd/kernels.h"

namespace motionpipe::similarity {
namespace {

std::vector<float> RandomFloats(size_t n, uint32_t seed, float scale = 1.f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-scale, scale);
  std::vector<float> v(n);
  for (float& x : v) x = u(rng);
  return v;
}

// Frames as BranchFeatures lays them out: random values in the used dims, zeros in the padding.
std::vector<float> RandomFrames(int64_t frames, uint32_t seed) {
  std::vector<float> v = RandomFloats(static_cast<size_t>(frames * kFrameStride), seed);
  for (int64_t f = 0; f < frames; ++f) {
    for (int d = 0; d < kFrameStride; ++d) {
      const bool used = d < kRotDims || (d >= kLocOffset && d < kLocOffset + kLocDims);
      if (!used) v[static_cast<size_t>(f * kFrameStride + d)] = 0.f;
    }
  }
  return v;
}

// Eq. (4) written the slow way.
void NaiveRaw(const std::vector<float>& x, int64_t tx, const std::vector<float>& m, int64_t tm,
              int window, std::vector<double>* rot, std::vector<double>* loc) {
  rot->assign(static_cast<size_t>(tx), 0);
  loc->assign(static_cast<size_t>(tx), 0);
  for (int64_t i = 0; i < tx; ++i) {
    const int64_t c = i * tm / tx;
    double best_r = 1e300, best_l = 1e300;
    for (int64_t j = std::max<int64_t>(c - window, 0); j < std::min<int64_t>(c + window, tm); ++j) {
      double dr = 0, dl = 0;
      for (int d = 0; d < kRotDims; ++d)
        dr += std::fabs(x[static_cast<size_t>(i * kFrameStride + d)] -
                        m[static_cast<size_t>(j * kFrameStride + d)]);
      for (int d = 0; d < kLocDims; ++d) {
        dl += std::fabs(x[static_cast<size_t>(i * kFrameStride + kLocOffset + d)] -
                        m[static_cast<size_t>(j * kFrameStride + kLocOffset + d)]);
      }
      best_r = std::min(best_r, dr / kRotDims);
      best_l = std::min(best_l, dl / kLocDims);
    }
    (*rot)[static_cast<size_t>(i)] = -best_r;
    (*loc)[static_cast<size_t>(i)] = -best_l;
  }
}

TEST(Similarity, RawSimilarityMatchesTheDefinition) {
  for (const auto& [tx, tm, window] : std::vector<std::tuple<int64_t, int64_t, int>>{
           {37, 52, 15}, {60, 23, 4}, {9, 9, 1}, {40, 41, 30}}) {
    const auto x = RandomFrames(tx, 1), m = RandomFrames(tm, 2);
    std::vector<double> want_rot, want_loc;
    NaiveRaw(x, tx, m, tm, window, &want_rot, &want_loc);
    std::vector<double> rot(static_cast<size_t>(tx)), loc(static_cast<size_t>(tx));
    RawSimilarity(x.data(), tx, m.data(), tm, window, rot.data(), loc.data());
    for (int64_t i = 0; i < tx; ++i) {
      EXPECT_NEAR(rot[static_cast<size_t>(i)], want_rot[static_cast<size_t>(i)], 1e-6)
          << tx << " " << i;
      EXPECT_NEAR(loc[static_cast<size_t>(i)], want_loc[static_cast<size_t>(i)], 1e-6)
          << tx << " " << i;
    }
    // Both builds of the kernel agree.
    std::vector<double> rot_g(rot.size()), loc_g(loc.size());
    simd::generic::RawSimilarityKernel(x.data(), tx, m.data(), tm, window, rot_g.data(),
                                       loc_g.data());
    for (size_t i = 0; i < rot.size(); ++i) {
      EXPECT_NEAR(rot[i], rot_g[i], 1e-7);
      EXPECT_NEAR(loc[i], loc_g[i], 1e-7);
    }
  }
}

TEST(Similarity, IdenticalFramesHaveZeroDistanceAndShiftsAreForgiven) {
  // A target that is the source delayed by 5 frames: within the window every source frame finds
  // itself, so the raw similarity is exactly 0 (the point of eq. 4's sliding window).
  const int64_t t = 80;
  const auto source = RandomFrames(t, 3);
  std::vector<float> target(source.size());
  for (int64_t f = 0; f < t; ++f) {
    const int64_t from = std::max<int64_t>(0, f - 5);
    std::copy_n(source.begin() + from * kFrameStride, kFrameStride,
                target.begin() + f * kFrameStride);
  }
  std::vector<double> rot(static_cast<size_t>(t)), loc(static_cast<size_t>(t));
  RawSimilarity(source.data(), t, target.data(), t, 15, rot.data(), loc.data());
  for (int64_t i = 0; i < t - 5; ++i) {
    EXPECT_EQ(rot[static_cast<size_t>(i)], 0.0) << i;
    EXPECT_EQ(loc[static_cast<size_t>(i)], 0.0) << i;
  }
}

TEST(Similarity, MovingAverageIsNumpySame) {
  // np.convolve(arange(5.), ones(4)/4, 'same') = [0.25, 0.75, 1.5, 2.5, 2.25]: out[i] averages
  // x[i-2 .. i+1] for an even length 4.
  const std::vector<double> x = {0, 1, 2, 3, 4};
  const std::vector<double> got = MovingAverage(x, 4);
  const std::vector<double> want = {0.25, 0.75, 1.5, 2.5, 2.25};
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) EXPECT_NEAR(got[i], want[i], 1e-15) << i;
  // m = 10 on an impulse at 15 of 30 covers outputs 11..20 (numpy's alignment for even lengths).
  std::vector<double> impulse(30, 0.0);
  impulse[15] = 1;
  const auto smooth = MovingAverage(impulse, 10);
  for (size_t i = 0; i < 30; ++i)
    EXPECT_NEAR(smooth[i], (i >= 11 && i <= 20) ? 0.1 : 0.0, 1e-15) << i;
  // m = 3 (odd) is centred.
  const auto odd = MovingAverage({3, 0, 0, 6}, 3);
  EXPECT_NEAR(odd[0], 1.0, 1e-15);
  EXPECT_NEAR(odd[1], 1.0, 1e-15);
  EXPECT_NEAR(odd[2], 2.0, 1e-15);
  EXPECT_NEAR(odd[3], 2.0, 1e-15);
  EXPECT_EQ(MovingAverage(x, 1), x);
}

TEST(Similarity, MotionSnrIsTheRatioOfExtremeMeans) {
  // Distances 1..10: kappa 2 -> (10 + 9) / (1 + 2).
  std::vector<double> s;
  for (int d = 10; d >= 1; --d) s.push_back(-d);
  EXPECT_NEAR(MotionSnr(s, 2), 19.0 / 3.0, 1e-12);
  EXPECT_NEAR(MotionSnr(s, 10), 1.0, 1e-12);
  EXPECT_NEAR(MotionSnr(s, 50), 1.0, 1e-12);  // kappa larger than the curve: all frames
  EXPECT_TRUE(std::isinf(MotionSnr({0, 0, -1, -2}, 2)));
  EXPECT_TRUE(std::isnan(MotionSnr({0, 0, 0}, 2)));
}

TEST(Similarity, NormalisationAndQuantisation) {
  std::vector<double> n;
  ASSERT_TRUE(MinMaxNormalize({-4, -2, 0}, &n));
  EXPECT_EQ(n, (std::vector<double>{0, 0.5, 1}));
  EXPECT_FALSE(MinMaxNormalize({-1, -1}, &n));
  // K equal bins of [0, 1]: [0, 1/3) -> 0, [1/3, 2/3) -> 1, [2/3, 1] -> 2.
  EXPECT_EQ(Quantize(0.0, 3), 0);
  EXPECT_EQ(Quantize(0.333, 3), 0);
  EXPECT_EQ(Quantize(1.0 / 3.0, 3), 1);
  EXPECT_EQ(Quantize(0.66, 3), 1);
  EXPECT_EQ(Quantize(2.0 / 3.0, 3), 2);
  EXPECT_EQ(Quantize(1.0, 3), 2);
  EXPECT_EQ(Quantize(1.0, 9), 8);
  EXPECT_EQ(Quantize(0.5, 5), 2);
}

TEST(Similarity, RotationKernelMatchesRodrigues) {
  std::vector<float> x, y, z;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1, 1);
  const std::vector<std::array<float, 3>> special = {
      {0, 0, 0}, {1e-8f, 0, 0}, {3.1f, 0, 0}, {0, 0, -3.14159f}, {4.f, 1.f, -2.f}, {0, 7.f, 0}};
  for (const auto& v : special) x.push_back(v[0]), y.push_back(v[1]), z.push_back(v[2]);
  for (int k = 0; k < 500; ++k) {
    const float scale = 3.0f * u(rng);
    x.push_back(scale * u(rng)), y.push_back(scale * u(rng)), z.push_back(scale * u(rng));
  }
  const auto n = static_cast<int64_t>(x.size());
  for (bool avx : {true, false}) {
    std::vector<float> planes(static_cast<size_t>(9 * n));
    if (avx && __builtin_cpu_supports("avx2")) {
      simd::avx2::AxisAngleToMatrices(x.data(), y.data(), z.data(), n, planes.data(), n, 3);
    } else {
      simd::generic::AxisAngleToMatrices(x.data(), y.data(), z.data(), n, planes.data(), n, 3);
    }
    for (int64_t r = 0; r < n; ++r) {
      const Mat3 want = AxisAngleToMatrix(
          {x[static_cast<size_t>(r)], y[static_cast<size_t>(r)], z[static_cast<size_t>(r)]});
      for (int k = 0; k < 9; ++k) {
        EXPECT_NEAR(planes[static_cast<size_t>(k * n + r)], want.m[k / 3][k % 3], 2e-6)
            << r << " " << k;
      }
    }
  }
}

TEST(Similarity, TransposeMatchesNaive) {
  for (const auto& [rows, cols] :
       std::vector<std::pair<int64_t, int64_t>>{{8, 8}, {21, 300}, {66, 13}, {5, 3}, {17, 9}}) {
    const auto src = RandomFloats(static_cast<size_t>(rows * (cols + 3)), 7);
    std::vector<float> got(static_cast<size_t>(cols * (rows + 5)), -1.f), generic_out = got;
    simd::avx2::Transpose(src.data(), cols + 3, rows, cols, got.data(), rows + 5);
    simd::generic::Transpose(src.data(), cols + 3, rows, cols, generic_out.data(), rows + 5);
    for (int64_t r = 0; r < rows; ++r) {
      for (int64_t c = 0; c < cols; ++c) {
        ASSERT_EQ(got[static_cast<size_t>(c * (rows + 5) + r)],
                  src[static_cast<size_t>(r * (cols + 3) + c)])
            << rows << "x" << cols;
      }
    }
    EXPECT_EQ(got, generic_out);
  }
}

// A motion with random but plausible rotations.
Motion RandomMotion(int64_t frames, uint32_t seed) {
  Motion m = Motion::Rest(frames, 30, 0.9);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.6f, 0.6f);
  for (int64_t f = 0; f < frames; ++f) {
    for (int j = 1; j < kNumJoints; ++j) {
      for (int a = 0; a < 3; ++a)
        m.poses[static_cast<size_t>((f * kNumJoints + j) * 3 + a)] = u(rng);
    }
    m.trans[static_cast<size_t>(f * 3)] = 0.01f * static_cast<float>(f);
  }
  return m;
}

MotionView ViewOf(const Motion& m, const std::vector<float>* joints) {
  MotionView v;
  v.frames = m.num_frames();
  v.joints = kNumJoints;
  v.poses = m.poses.data();
  v.trans = m.trans.data();
  if (joints) {
    v.position_joints = kNumJoints;
    v.positions = joints->data();
  }
  return v;
}

TEST(Similarity, BranchFeaturesAreSixDAndPelvisRelativeJoints) {
  const Motion m = RandomMotion(45, 11);
  const std::vector<float> joints = ComputeJoints(Skeleton::Smpl22(), m);
  std::vector<float> fk, stored;
  BranchFeatures(ViewOf(m, nullptr), false, &fk);
  BranchFeatures(ViewOf(m, &joints), true, &stored);
  ASSERT_EQ(fk.size(), static_cast<size_t>(45 * kFrameStride));
  for (int64_t f = 0; f < 45; ++f) {
    const float* row = fk.data() + f * kFrameStride;
    for (int j = 1; j < kNumJoints; ++j) {
      const Mat3 r = m.LocalRotation(f, j);
      for (int k = 0; k < 6; ++k) EXPECT_NEAR(row[k * 21 + j - 1], r.m[k / 3][k % 3], 2e-6);
    }
    for (int j = 0; j < kNumJoints; ++j) {
      for (int a = 0; a < 3; ++a) {
        const float want = joints[static_cast<size_t>((f * kNumJoints + j) * 3 + a)] -
                           m.trans[static_cast<size_t>(f * 3 + a)];
        EXPECT_NEAR(row[kLocOffset + 3 * j + a], want, 2e-6) << f << " " << j;
        EXPECT_NEAR(stored[static_cast<size_t>(f * kFrameStride + kLocOffset + 3 * j + a)], want,
                    1e-6);
      }
    }
    for (int d : {126, 127, 194, 199}) EXPECT_EQ(row[d], 0.f);
  }
}

TEST(Similarity, LocalEditGivesLowSimilarityWhereItHappens) {
  // The target raises the right arm in frames [40, 60) only.
  Motion source = RandomMotion(100, 21);
  for (int64_t f = 0; f < 100; ++f) {
    for (int j = 1; j < kNumJoints; ++j) {
      for (int a = 0; a < 3; ++a) {
        source.poses[static_cast<size_t>((f * kNumJoints + j) * 3 + a)] =
            0.3f * std::sin(0.05f * static_cast<float>(f) + static_cast<float>(j + a));
      }
    }
  }
  Motion target = source;
  for (int64_t f = 40; f < 60; ++f)
    target.SetLocalRotation(f, 17, AxisAngleToMatrix({0, 0, 1.5}) * source.LocalRotation(f, 17));
  Workspace ws;
  const SimilarityResult r =
      ComputeSimilarity(ViewOf(source, nullptr), ViewOf(target, nullptr), SimilarityOptions{}, &ws);
  ASSERT_TRUE(r.kept()) << r.detail;
  EXPECT_GT(r.snr, 10);
  for (int64_t i = 0; i < 100; ++i) {
    if (i >= 45 && i < 55) {
      EXPECT_EQ(r.classes[static_cast<size_t>(i)], 0) << i;  // inside the edit
    }
    if (i < 30 || i >= 70) {
      EXPECT_EQ(r.classes[static_cast<size_t>(i)], 2) << i;  // far from it
    }
  }
  // The combined curve is w1 S^Rr + w2 S^Rl after smoothing: with w_loc = 0 only rotations count.
  SimilarityOptions rot_only;
  rot_only.w_loc = 0;
  const SimilarityResult r2 =
      ComputeSimilarity(ViewOf(source, nullptr), ViewOf(target, nullptr), rot_only, &ws);
  const auto smooth = MovingAverage(r2.raw_rot, 10);
  for (size_t i = 0; i < smooth.size(); ++i) EXPECT_NEAR(r2.combined[i], smooth[i], 1e-12);
}

TEST(Similarity, BadInputIsDroppedWithAReason) {
  const Motion good = RandomMotion(50, 1);
  Workspace ws;
  const SimilarityOptions o;
  auto reason = [&](MotionView s, MotionView t) { return ComputeSimilarity(s, t, o, &ws); };
  MotionView s = ViewOf(good, nullptr), t = ViewOf(good, nullptr);
  // Identical motions: flat curve.
  EXPECT_EQ(reason(s, t).dropped, DropReason::kNoSignal);
  MotionView empty = s;
  empty.frames = 0;
  EXPECT_EQ(reason(empty, t).dropped, DropReason::kEmpty);
  MotionView one = s;
  one.frames = 1;
  EXPECT_EQ(reason(s, one).dropped, DropReason::kOneFrame);
  MotionView shorter = s;
  shorter.frames = 12;
  const auto short_result = reason(shorter, t);
  EXPECT_EQ(short_result.dropped, DropReason::kTooShort);
  EXPECT_NE(short_result.detail.find("12 frames"), std::string::npos);
  Motion nan = good;
  nan.poses[200] = std::numeric_limits<float>::quiet_NaN();
  const auto nan_result = reason(ViewOf(nan, nullptr), t);
  EXPECT_EQ(nan_result.dropped, DropReason::kNonFinite);
  EXPECT_NE(nan_result.detail.find("frame 3"), std::string::npos) << nan_result.detail;
  MotionView few_joints = s;
  few_joints.joints = 21;
  EXPECT_EQ(reason(few_joints, t).dropped, DropReason::kBadShape);
  SimilarityOptions stored;
  stored.locations = LocationSource::kStored;
  EXPECT_EQ(ComputeSimilarity(s, t, stored, &ws).dropped, DropReason::kBadShape);
  for (const auto& r : {reason(empty, t), reason(s, one)}) {
    EXPECT_TRUE(r.combined.empty());
    EXPECT_FALSE(r.detail.empty());
  }
}

TEST(Similarity, OptionsFromConfig) {
  auto paper = OptionsFromJson(nlohmann::json::object(), "cfg");
  ASSERT_TRUE(paper.ok());
  EXPECT_EQ(paper->kappa, 5);
  EXPECT_EQ(paper->window, 15);
  EXPECT_EQ(paper->smooth, 10);
  EXPECT_EQ(paper->classes, 3);
  auto reference = OptionsFromJson(
      {{"preset", "reference"}, {"classes", "regression"}, {"locations", "fk"}}, "cfg");
  ASSERT_TRUE(reference.ok());
  EXPECT_EQ(reference->kappa, 10);
  EXPECT_EQ(reference->classes, 0);
  EXPECT_EQ(reference->locations, LocationSource::kForwardKinematics);
  auto overridden = OptionsFromJson({{"preset", "reference"}, {"kappa", 7}}, "cfg");
  ASSERT_TRUE(overridden.ok());
  EXPECT_EQ(overridden->kappa, 7);
  for (const auto& bad :
       {nlohmann::json{{"kappa", 0}}, nlohmann::json{{"window", "wide"}},
        nlohmann::json{{"classes", 1}}, nlohmann::json{{"w_rot", 0}, {"w_loc", 0}},
        nlohmann::json{{"preset", "best"}}, nlohmann::json{{"kapa", 5}},
        nlohmann::json{{"locations", "gps"}}}) {
    auto r = OptionsFromJson(bad, "cfg.yaml");
    EXPECT_FALSE(r.ok()) << bad.dump();
    EXPECT_NE(r.status().message().find("cfg.yaml"), std::string::npos);
  }
  auto ignored = OptionsFromJson({{"triplets", "x"}}, "cfg", {"triplets"});
  EXPECT_TRUE(ignored.ok());
  EXPECT_EQ(OptionsToJson(*reference)["kappa"], 10);
}

TEST(Similarity, ShardPlansCoverEveryRowOnce) {
  const std::vector<TripletFile> files = {{"a", 500}, {"b", 500}, {"c", 120}, {"d", 500}};
  for (int shards : {1, 2, 3, 4, 7, 16}) {
    std::map<std::string, std::vector<int>> covered;
    int64_t total = 0;
    for (int index = 0; index < shards; ++index) {
      for (const ShardSlice& s : PlanShard(files, shards, index)) {
        auto& rows = covered[s.path];
        rows.resize(600, 0);
        for (int64_t r = s.row_begin; r < s.row_end; ++r) ++rows[static_cast<size_t>(r)];
        total += s.row_end - s.row_begin;
      }
    }
    EXPECT_EQ(total, 1620) << shards;
    for (const auto& f : files) {
      for (int64_t r = 0; r < f.count; ++r)
        EXPECT_EQ(covered[f.path][static_cast<size_t>(r)], 1) << shards << f.path << r;
    }
  }
  // With at least as many files as shards, files are never split.
  for (int index = 0; index < 2; ++index) {
    for (const ShardSlice& s : PlanShard(files, 2, index)) {
      EXPECT_EQ(s.row_begin, 0);
      EXPECT_EQ(s.row_end, std::find_if(files.begin(), files.end(), [&](const TripletFile& f) {
                             return f.path == s.path;
                           })->count);
    }
  }
}

TEST(Similarity, FilterShardOutputsAreIndependentOfThreads) {
  const std::string dir = ::testing::TempDir() + "/similarity_shard";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::vector<Triplet> triplets;
  for (int k = 0; k < 12; ++k) {
    Triplet t;
    t.id = "t" + std::to_string(k);
    t.text = "raise the arm";
    t.split = "train";
    t.source = RandomMotion(40 + 3 * k, static_cast<uint32_t>(k));
    t.target = t.source;
    for (int64_t f = 10; f < 20; ++f)
      t.target.SetLocalRotation(f, 16,
                                AxisAngleToMatrix({0, 1.2, 0}) * t.source.LocalRotation(f, 16));
    t.edit_start = 10;
    t.edit_end = 20;
    triplets.push_back(std::move(t));
  }
  ASSERT_TRUE(WriteTriplets(dir + "/triplets-00000.npz", triplets).ok());
  auto files = ResolveTripletFiles({dir});
  ASSERT_TRUE(files.ok()) << files.status().ToString();
  ASSERT_EQ(files->size(), 1u);
  EXPECT_EQ((*files)[0].count, 12);
  const auto slices = PlanShard(*files, 1, 0);
  auto one = FilterShard(slices, SimilarityOptions{}, 1, dir + "/one");
  auto two = FilterShard(slices, SimilarityOptions{}, 2, dir + "/two");
  ASSERT_TRUE(one.ok() && two.ok());
  EXPECT_EQ(one->triplets, 12);
  auto a = ReadFile(dir + "/one/similarity.npz"), b = ReadFile(dir + "/two/similarity.npz");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(*a, *b);
  auto table = ReadSimilarity(dir + "/one/similarity.npz");
  ASSERT_TRUE(table.ok()) << table.status().ToString();
  EXPECT_EQ(table->ids.size(), static_cast<size_t>(one->kept));
  EXPECT_EQ(table->classes.size(), table->similarity.size());
  auto summary = SummarizeFilter({dir + "/one"}, dir + "/summary");
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ((*summary)["triplets"], 12);
  EXPECT_GT((*summary)["edit_range"]["boundaries"][0]["recall"].get<double>(), 0.5);
  EXPECT_TRUE(std::filesystem::exists(dir + "/summary/summary.png"));
  // A damaged file is an error naming it.
  ASSERT_TRUE(WriteFileAtomic(dir + "/broken.npz", "not a zip").ok());
  auto broken = FilterShard({{dir + "/broken.npz", 0, 1}}, SimilarityOptions{}, 1, dir + "/broken");
  ASSERT_FALSE(broken.ok());
  EXPECT_NE(broken.status().message().find("broken.npz"), std::string::npos);
}

}  // namespace
}  // namespace motionpipe::similarity
