// Feature normalisation statistics: compute, save, load (ours and the reference files in
// data/stats), apply. Standardisation is (x - mean) / (scale * (std + 1e-5)) with scale 1
// (TEMOS/SINC) or 2 (MotionFix, "2 sigma", REFERENCE.md section 2).
#pragma once

#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/features/feature_matrix.h"

namespace motionpipe {

constexpr double kStatsEpsilon = 1e-5;

enum class NormScale { kOneSigma = 1, kTwoSigma = 2 };

struct FeatureStats {
  std::vector<float> mean;
  std::vector<float> std;  // unbiased (n - 1), as torch.std
  NormScale scale = NormScale::kOneSigma;
  int64_t count = 0;  // frames the statistics were computed over (0 when loaded from a reference)
};

// Per-column mean and unbiased standard deviation over every row of every matrix. All matrices
// need the same column count; InvalidArgument otherwise or when there are no rows.
Result<FeatureStats> ComputeStats(const std::vector<const FeatureMatrix*>& matrices,
                                  NormScale scale);

// In place; FailedPrecondition when the dimensions differ.
Status Normalize(FeatureMatrix* features, const FeatureStats& stats);
Status Denormalize(FeatureMatrix* features, const FeatureStats& stats);

// Our JSON layout: {"format": "motionpipe.stats/1", "dim", "scale", "count", "mean", "std"}.
std::string StatsToJson(const FeatureStats& stats);
Status SaveStats(const std::string& path, const FeatureStats& stats);

// Loads our layout, or a reference file from data/stats:
//  - motionfix_feature_stats.json (groups concatenated in 207-d order, scale 2);
//  - sinc_tmr_feature_stats.json with `key` naming the entry pair, e.g. "sinc_rfeats_babel-amass"
//    (the file's "<key>_mean" and "<key>_std"), scale 1.
// DataLoss names the file and the field that is missing or malformed.
Result<FeatureStats> LoadStats(const std::string& path, const std::string& key = "");

}  // namespace motionpipe
