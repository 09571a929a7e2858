// The evaluation metrics on hand-computed cases.
#include "motionpipe/eval/metrics.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>

#include "metric_history.h"

namespace motionpipe::eval {
namespace {

TEST(Retrieval, RanksCountHigherCandidatesAndAverageTies) {
  // Query 0: own 0.9, best -> rank 1. Query 1: own 0.5, one higher (0.8) -> 2. Query 2: own 0.3,
  // ties with one (0.3) and one higher (0.7) -> 1 + 1 + 0.5 = 2.5. Query 3: own lowest -> 4.
  const std::vector<double> s = {0.9, 0.1, 0.2, 0.3,  //
                                 0.8, 0.5, 0.1, 0.2,  //
                                 0.7, 0.3, 0.3, 0.1,  //
                                 0.5, 0.6, 0.7, 0.0};
  const auto ranks = TrueMatchRanks(s, 4);
  EXPECT_EQ(ranks, (std::vector<double>{1, 2, 2.5, 4}));
  const RetrievalScores r = Summarize(ranks);
  EXPECT_DOUBLE_EQ(r.r1, 25.0);
  EXPECT_DOUBLE_EQ(r.r2, 50.0);
  EXPECT_DOUBLE_EQ(r.r3, 75.0);
  EXPECT_DOUBLE_EQ(r.avg_rank, 2.375);
  // All equal: every query ties with n - 1 others -> rank (n + 1) / 2.
  EXPECT_EQ(TrueMatchRanks(std::vector<double>(9, 0.5), 3), (std::vector<double>{2, 2, 2}));
}

Embeddings Random(int64_t n, int64_t d, uint64_t seed, double shift = 0) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0, 1);
  Embeddings e{n, d, {}};
  for (int64_t i = 0; i < n * d; ++i) e.values.push_back(normal(rng) + shift);
  return e;
}

TEST(Retrieval, IdenticalEmbeddingsAreFoundFirstAndBatchesDropTheRemainder) {
  const Embeddings x = Random(70, 8, 1);
  const RetrievalScores all = *Retrieval(x, x, 0, 1);
  EXPECT_EQ(all.queries, 70);
  EXPECT_DOUBLE_EQ(all.r1, 100.0);
  EXPECT_DOUBLE_EQ(all.avg_rank, 1.0);
  const RetrievalScores batched = *Retrieval(x, x, 32, 7);
  EXPECT_EQ(batched.queries, 64);  // 2 batches of 32, 6 dropped
  EXPECT_DOUBLE_EQ(batched.r1, 100.0);
  // Unrelated embeddings: mean rank near (32 + 1) / 2 in batches of 32, the same under the same
  // seed.
  const Embeddings y = Random(640, 8, 2);
  const RetrievalScores chance = *Retrieval(Random(640, 8, 3), y, 32, 5);
  EXPECT_NEAR(chance.avg_rank, 16.5, 1.5);
  EXPECT_DOUBLE_EQ(Retrieval(Random(640, 8, 3), y, 32, 5).value().avg_rank, chance.avg_rank);
}

TEST(Retrieval, PairedR1DifferencePairsTheSameQueriesAndGivesItsStandardError) {
  // By hand: query 3 is left out of a; the pairs (1, 2), (1, 1), (2, 1) differ by +100, 0, -100.
  RetrievalScores a, b;
  const double left_out = std::numeric_limits<double>::quiet_NaN();
  a.rank_of_query = {1, 1, 2, left_out};
  b.rank_of_query = {2, 1, 1, 1};
  PairedDifference d = PairedR1Difference(a, b);
  EXPECT_EQ(d.queries, 3);
  EXPECT_DOUBLE_EQ(d.value, 0);
  EXPECT_NEAR(d.standard_error, 100 / std::sqrt(3.0), 1e-9);  // sd 100 over sqrt(3)
  // Two retrievals with the same batch and seed: the same 64 of 70 queries, ranked by query index.
  const Embeddings x = Random(70, 8, 1), y = Random(70, 8, 2);
  const RetrievalScores same = *Retrieval(x, x, 32, 7), other = *Retrieval(x, y, 32, 7);
  ASSERT_EQ(same.rank_of_query.size(), 70U);
  EXPECT_EQ(std::count_if(same.rank_of_query.begin(), same.rank_of_query.end(),
                          [](double r) { return std::isnan(r); }),
            6);
  d = PairedR1Difference(same, other);
  EXPECT_EQ(d.queries, 64);
  EXPECT_NEAR(d.value, same.r1 - other.r1, 1e-9);
  const double p = other.r1 / 100;  // the differences are 100 (1 - [b's rank is 1])
  EXPECT_NEAR(d.standard_error, 100 * std::sqrt(p * (1 - p) * 64 / 63 / 64), 1e-9);
}

TEST(PositionErrors, ApeAndAveOfHandMadeMotions) {
  // Two joints, three frames. Truth: root at the origin, joint 1 at (0, 0, 1). Generated: the whole
  // body shifted by (3, 4, 0) -> root and global errors 5, trajectory 5, local 0.
  std::vector<float> truth, shifted;
  for (int t = 0; t < 3; ++t) {
    truth.insert(truth.end(), {0, 0, 0, 0, 0, 1});
    shifted.insert(shifted.end(), {3, 4, 0, 3, 4, 1});
  }
  PositionErrors ape = *AveragePositionalError(shifted, truth, 2);
  EXPECT_NEAR(ape.root, 5, 1e-9);
  EXPECT_NEAR(ape.trajectory, 5, 1e-9);
  EXPECT_NEAR(ape.mean_global, 5, 1e-9);
  EXPECT_NEAR(ape.mean_local, 0, 1e-9);
  // A vertical-only offset does not count in the trajectory.
  std::vector<float> raised = truth;
  for (size_t k = 2; k < raised.size(); k += 3) raised[k] += 2;
  ape = *AveragePositionalError(raised, truth, 2);
  EXPECT_NEAR(ape.root, 2, 1e-9);
  EXPECT_NEAR(ape.trajectory, 0, 1e-9);
  // AVE: a constant offset has the same variance (0); a root moving 0, 1, 2 along x has variance 1
  // in x (unbiased), the still truth 0 -> root AVE 1; joint 1 moves with it: local 0, global 1.
  EXPECT_NEAR(AverageVarianceError(shifted, truth, 2).value().mean_global, 0, 1e-9);
  std::vector<float> moving = {0, 0, 0, 0, 0, 1, 1, 0, 0, 1, 0, 1, 2, 0, 0, 2, 0, 1};
  const PositionErrors ave = *AverageVarianceError(moving, truth, 2);
  EXPECT_NEAR(ave.root, 1, 1e-9);
  EXPECT_NEAR(ave.trajectory, 1, 1e-9);
  EXPECT_NEAR(ave.mean_global, 1, 1e-9);
  EXPECT_NEAR(ave.mean_local, 0, 1e-9);
  // Different lengths are cropped to the shorter.
  std::vector<float> longer = truth;
  longer.insert(longer.end(), {9, 9, 9, 9, 9, 9});
  EXPECT_NEAR(AveragePositionalError(longer, truth, 2).value().root, 0, 1e-9);
}

TEST(PositionErrors, LocalErrorsRemoveEachFramesHeading) {
  // Three joints: root, left hip (+x), right hip (-x), hips 0.1 m from the root. The generated body
  // is the truth turned 90 degrees about z (hips along y) and walked 2 m: root-relative joints
  // differ by the turn, heading-aligned ones do not.
  std::vector<float> truth = {0, 0, 1, 0.1f, 0, 1, -0.1f, 0, 1};
  std::vector<float> turned = {2, 0, 1, 2, 0.1f, 1, 2, -0.1f, 1};
  const PositionErrors plain = *AveragePositionalError(turned, truth, 3);
  EXPECT_NEAR(plain.mean_local, std::hypot(0.1, 0.1), 1e-6);  // each hip off by the 90-degree turn
  const PositionErrors aligned = *AveragePositionalError(turned, truth, 3, HeadingJoints{1, 2});
  EXPECT_NEAR(aligned.mean_local, 0, 1e-6);
  EXPECT_NEAR(aligned.root, 2, 1e-6);  // the global terms are unchanged
  EXPECT_NEAR(aligned.mean_global, (2 + std::hypot(2 - 0.1, 0.1) + std::hypot(2 + 0.1, 0.1)) / 3,
              1e-6);
}

TEST(PositionErrors, CanonicalMotionsCompareWhereverTheyStarted) {
  // The same two-frame walk of root + hips, once at the origin facing +x (hips along +x) and once
  // 5 m away, turned 90 degrees: canonical, they are identical.
  std::vector<float> here = {0, 0,    1, 0.1f, 0,    1, -0.1f, 0,    1,
                             0, 0.5f, 1, 0.1f, 0.5f, 1, -0.1f, 0.5f, 1};
  std::vector<float> there = {5,    5, 1, 5,    5.1f, 1, 5,    4.9f, 1,
                              4.5f, 5, 1, 4.5f, 5.1f, 1, 4.5f, 4.9f, 1};
  EXPECT_GT(AveragePositionalError(there, here, 3).value().root, 5);
  Canonicalize(&here, 3, HeadingJoints{1, 2});
  Canonicalize(&there, 3, HeadingJoints{1, 2});
  for (size_t k = 0; k < here.size(); ++k) EXPECT_NEAR(here[k], there[k], 1e-5) << k;
  EXPECT_NEAR(AveragePositionalError(there, here, 3).value().mean_global, 0, 1e-5);
}

TEST(Fid, IsZeroForIdenticalSetsAndTheClosedFormOtherwise) {
  const Embeddings x = Random(400, 6, 4);
  EXPECT_NEAR(*FrechetDistance(x, x), 0, 1e-6);
  // A shifted copy: only the mean term, |shift|^2 = 6 * 0.5^2.
  Embeddings shifted = x;
  for (auto& v : shifted.values) v += 0.5;
  EXPECT_NEAR(*FrechetDistance(x, shifted), 1.5, 1e-6);
  // A scaled copy (covariance times 4): Tr(C + 4C - 2 * 2C) = Tr(C), and the mean term |mu|^2 (1 -
  // 2)^2.
  Embeddings scaled = x;
  for (auto& v : scaled.values) v *= 2;
  double trace = 0, mean_sq = 0;
  for (int64_t k = 0; k < 6; ++k) {
    double m = 0, s = 0;
    for (int64_t i = 0; i < 400; ++i) m += x.row(i)[k];
    m /= 400;
    for (int64_t i = 0; i < 400; ++i) s += (x.row(i)[k] - m) * (x.row(i)[k] - m);
    trace += s / 399;
    mean_sq += m * m;
  }
  EXPECT_NEAR(*FrechetDistance(x, scaled), trace + mean_sq, 1e-6);
}

TEST(Fid, SymmetricEigenReconstructsTheMatrix) {
  const std::vector<double> m = {4, 1, 2, 1, 3, 0, 2, 0, 5};
  std::vector<double> values, vectors;
  SymmetricEigen(m, 3, &values, &vectors);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double s = 0;
      for (int k = 0; k < 3; ++k)
        s += vectors[static_cast<size_t>(i * 3 + k)] * values[static_cast<size_t>(k)] *
             vectors[static_cast<size_t>(j * 3 + k)];
      EXPECT_NEAR(s, m[static_cast<size_t>(i * 3 + j)], 1e-10);
    }
  }
  EXPECT_NEAR(values[0] + values[1] + values[2], 12, 1e-10);
}

// Issue 16: core returns Status; metrics that do not fit their inputs say so instead of throwing.
TEST(Metrics, InputsThatDoNotFitAreInvalidArgumentNotExceptions) {
  const Embeddings four{4, 2, std::vector<double>(8, 1.0)},
      three{3, 2, std::vector<double>(6, 1.0)}, wide{4, 3, std::vector<double>(12, 1.0)};
  const auto retrieval = Retrieval(four, three, 0, 1);
  ASSERT_FALSE(retrieval.ok());
  EXPECT_EQ(retrieval.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(retrieval.status().message().find("4 queries against 3"), std::string::npos);
  EXPECT_FALSE(Retrieval(four, wide, 0, 1).ok());  // different embedding sizes
  EXPECT_FALSE(FrechetDistance(four, wide).ok());
  const Embeddings one{1, 2, {1.0, 2.0}};
  EXPECT_FALSE(FrechetDistance(one, one).ok());
  EXPECT_FALSE(AveragePositionalError({}, std::vector<float>(6, 0.f), 2).ok());
  EXPECT_FALSE(AverageVarianceError(std::vector<float>(6, 0.f), {}, 2).ok());
}

TEST(Diversity, MeasuresDistancesBetweenRowsAndWithinGroups) {
  // Two points 5 apart: every pair of distinct rows is at distance 5.
  const Embeddings x{2, 2, {0, 0, 3, 4}};
  EXPECT_DOUBLE_EQ(Diversity(x, 10, 1), 5.0);
  const Embeddings y{4, 1, {0, 1, 10, 14}};
  EXPECT_DOUBLE_EQ(Multimodality(y, {{0, 1}, {2, 3}}), 2.5);
}

}  // namespace
}  // namespace motionpipe::eval

namespace motionpipe::report {
namespace {

TEST(MetricHistory, ARegressionIsAFallOfMoreThanTheMarginBelowTheBest) {
  const std::string path = ::testing::TempDir() + "/history.sqlite";
  std::filesystem::remove(path);
  const auto record = [](const std::string& method, const std::string& metric, double value,
                         bool higher, const std::string& ckpt) {
    MetricRecord r;
    r.method = method, r.metric = metric, r.value = value, r.higher_is_better = higher,
    r.checkpoint = ckpt;
    return r;
  };
  auto first = AppendAndCompare(
      path, {record("mdt", "R@1", 50, true, "a"), record("mdt", "AvgR", 3.0, false, "a")}, 2.0);
  ASSERT_TRUE(first.ok()) << first.status().message();
  EXPECT_TRUE(first->empty());  // nothing to compare with
  ASSERT_TRUE(AppendAndCompare(path, {record("mdt", "R@1", 60, true, "b")}, 2.0).ok());
  // 59 is within the margin of the best (60); 57 is not; AvgR 5.5 is worse than 3.0 by more than 2.
  EXPECT_TRUE(AppendAndCompare(path, {record("mdt", "R@1", 59, true, "c")}, 2.0)->empty());
  auto worse =
      AppendAndCompare(path,
                       {record("mdt", "R@1", 57, true, "d"), record("mdt", "AvgR", 5.5, false, "d"),
                        record("tmed", "R@1", 10, true, "d")},
                       2.0);
  ASSERT_TRUE(worse.ok());
  ASSERT_EQ(worse->size(), 2u);  // tmed has no history yet
  EXPECT_EQ((*worse)[0].metric, "R@1");
  EXPECT_DOUBLE_EQ((*worse)[0].best, 60);
  EXPECT_EQ((*worse)[0].best_checkpoint, "b");
  EXPECT_EQ((*worse)[1].metric, "AvgR");
  EXPECT_DOUBLE_EQ((*worse)[1].best, 3.0);
  EXPECT_NE((*worse)[0].Describe().find("regressed: 57 against its best 60"), std::string::npos)
      << (*worse)[0].Describe();
  EXPECT_FALSE(
      AppendAndCompare("/no/such/dir/history.sqlite", {record("m", "x", 1, true, "")}, 0).ok());
  EXPECT_EQ(HashText("abc"), HashText("abc"));
  EXPECT_NE(HashText("abc"), HashText("abd"));
}

}  // namespace
}  // namespace motionpipe::report
