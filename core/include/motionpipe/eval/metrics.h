// Evaluation metrics of the two papers (REFERENCE 3.4, 4.6), as plain functions on embeddings and
// joint positions, so that each can be checked on hand-computed cases:
//   retrieval   motion-to-motion (or text-to-motion) R@1/2/3 in percent and AvgR, ties averaged, in
//               seeded batches of 32 (remainder dropped; SimMotionEdit's protocol) or over all;
//   APE / AVE   TEMOS's average positional error and average variance error: root joint, global
//               trajectory (horizontal root), mean local (joints relative to the root), mean
//               global;
//   FID         Frechet distance between two embedding sets; diversity and multimodality.
// Inputs that do not fit (sizes that differ, empty motions) are InvalidArgument, as everywhere in
// core.
#pragma once

#include <cstdint>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe::eval {

// Row-major n x d embeddings.
struct Embeddings {
  int64_t n = 0, d = 0;
  std::vector<double> values;
  const double* row(int64_t i) const { return values.data() + i * d; }
};

// Cosine similarity matrix [a.n x b.n], row-major.
Result<std::vector<double>> CosineSimilarity(const Embeddings& a, const Embeddings& b);

// Rank (1-based) of the true match i for each query i of a square similarity matrix: 1 + the
// number of candidates scoring higher + half the number tying with it (ties averaged).
std::vector<double> TrueMatchRanks(const std::vector<double>& similarity, int64_t n);

struct RetrievalScores {
  double r1 = 0, r2 = 0, r3 = 0;  // percent of queries whose rank is <= k
  double avg_rank = 0;
  int64_t queries = 0;
  // Retrieval only: each query's rank by its index, NaN for a query left out (the remainder
  // dropped by batching); two retrievals of the same queries with the same batch and seed score
  // the same queries in the same batches, so their ranks pair up query by query.
  std::vector<double> rank_of_query;
};
RetrievalScores Summarize(const std::vector<double>& ranks);

// The difference of two R@1 (percent) over the same queries, a.r1 - b.r1, and its standard error
// as a mean of per-query differences [rank_a = 1] - [rank_b = 1] (paired: the queries scored in
// both). E.g. how far edits move towards their targets: generated-to-target against
// generated-to-source.
struct PairedDifference {
  double value = 0, standard_error = 0;
  int64_t queries = 0;
};
PairedDifference PairedR1Difference(const RetrievalScores& a, const RetrievalScores& b);

// Query i of `queries` should retrieve row i of `gallery`. batch <= 0: one batch of everything.
// Otherwise a seeded shuffle split into batches of `batch` (the remainder dropped), ranks within
// each batch, scores over all the batches' queries.
Result<RetrievalScores> Retrieval(const Embeddings& queries, const Embeddings& gallery,
                                  int64_t batch, uint64_t seed);

struct PositionErrors {
  double root = 0, trajectory = 0, mean_local = 0, mean_global = 0;
};
// The joints whose axis gives a frame's heading (SMPL-22: left hip 1, right hip 2); -1 = none.
struct HeadingJoints {
  int left = -1, right = -1;
};
inline constexpr HeadingJoints kSmpl22Hips{1, 2};
// Puts a motion's joints [frames, count, 3] in its first frame's body frame on the ground plane:
// the first root at x = y = 0 and, with hips given, the first hips' axis along +x. TEMOS compares
// motions so (its features drop the first frame's position and heading); generated motions start
// canonical and the ground truth starts anywhere in its world.
void Canonicalize(std::vector<float>* joints, int count, const HeadingJoints& heading);
// APE and AVE between generated and ground-truth joints [frames, joints, 3] (z up; joint 0 the
// root) (REFERENCE 4.6): root joint, ground-plane trajectory, mean global (all joints) and mean
// local (joints relative to the root, each frame's heading removed when `heading` names the hips).
// Both motions are cropped to the shorter length.
Result<PositionErrors> AveragePositionalError(const std::vector<float>& generated,
                                              const std::vector<float>& truth, int joints,
                                              const HeadingJoints& heading = {});
Result<PositionErrors> AverageVarianceError(const std::vector<float>& generated,
                                            const std::vector<float>& truth, int joints,
                                            const HeadingJoints& heading = {});

// Frechet distance between Gaussians fitted to two embedding sets (unbiased covariances).
Result<double> FrechetDistance(const Embeddings& a, const Embeddings& b);
// Mean Euclidean distance between `pairs` seeded random pairs of distinct rows.
double Diversity(const Embeddings& x, int64_t pairs, uint64_t seed);
// Mean distance between generations of the same condition: groups[g] lists rows of x.
double Multimodality(const Embeddings& x, const std::vector<std::vector<int64_t>>& groups);

// Eigen-decomposition of a symmetric matrix (cyclic Jacobi): eigenvalues, and eigenvectors as
// columns of a row-major n x n matrix.
void SymmetricEigen(std::vector<double> matrix, int64_t n, std::vector<double>* values,
                    std::vector<double>* vectors);

}  // namespace motionpipe::eval
