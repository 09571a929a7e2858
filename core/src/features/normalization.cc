#include "motionpipe/features/normalization.h"

#include <cmath>
#include <nlohmann/json.hpp>

#include "motionpipe/base/file.h"
#include "motionpipe/features/motionfix207.h"

namespace motionpipe {

Result<FeatureStats> ComputeStats(const std::vector<const FeatureMatrix*>& matrices,
                                  NormScale scale) {
  if (matrices.empty()) return InvalidArgument("ComputeStats: no feature matrices");
  const int64_t cols = matrices.front()->cols;
  std::vector<double> sum(static_cast<size_t>(cols), 0.0);
  int64_t count = 0;
  for (const FeatureMatrix* m : matrices) {
    if (m->cols != cols) {
      return InvalidArgument("ComputeStats: feature dimension " + std::to_string(m->cols) +
                             " differs from " + std::to_string(cols));
    }
    for (int64_t r = 0; r < m->rows; ++r) {
      const float* row = m->row(r);
      for (int64_t c = 0; c < cols; ++c) sum[static_cast<size_t>(c)] += row[c];
    }
    count += m->rows;
  }
  if (count < 2) return InvalidArgument("ComputeStats: need at least two frames");
  // Two passes in double: the mean first, then squared deviations (numerically stable enough for
  // feature magnitudes and millions of frames).
  std::vector<double> mean(static_cast<size_t>(cols));
  for (int64_t c = 0; c < cols; ++c)
    mean[static_cast<size_t>(c)] = sum[static_cast<size_t>(c)] / static_cast<double>(count);
  std::vector<double> sq(static_cast<size_t>(cols), 0.0);
  for (const FeatureMatrix* m : matrices) {
    for (int64_t r = 0; r < m->rows; ++r) {
      const float* row = m->row(r);
      for (int64_t c = 0; c < cols; ++c) {
        const double d = row[c] - mean[static_cast<size_t>(c)];
        sq[static_cast<size_t>(c)] += d * d;
      }
    }
  }
  FeatureStats stats;
  stats.scale = scale;
  stats.count = count;
  for (int64_t c = 0; c < cols; ++c) {
    stats.mean.push_back(static_cast<float>(mean[static_cast<size_t>(c)]));
    stats.std.push_back(
        static_cast<float>(std::sqrt(sq[static_cast<size_t>(c)] / static_cast<double>(count - 1))));
  }
  return stats;
}

namespace {
Status CheckDims(const FeatureMatrix& features, const FeatureStats& stats) {
  if (static_cast<size_t>(features.cols) != stats.mean.size() ||
      stats.mean.size() != stats.std.size()) {
    return FailedPrecondition("features have " + std::to_string(features.cols) +
                              " columns, statistics " + std::to_string(stats.mean.size()));
  }
  return Status::Ok();
}
}  // namespace

Status Normalize(FeatureMatrix* features, const FeatureStats& stats) {
  MP_RETURN_IF_ERROR(CheckDims(*features, stats));
  const double scale = static_cast<double>(static_cast<int>(stats.scale));
  std::vector<float> inv(stats.std.size());
  for (size_t c = 0; c < inv.size(); ++c)
    inv[c] = static_cast<float>(1.0 / (scale * (stats.std[c] + kStatsEpsilon)));
  for (int64_t r = 0; r < features->rows; ++r) {
    float* row = features->row(r);
    for (size_t c = 0; c < inv.size(); ++c) row[c] = (row[c] - stats.mean[c]) * inv[c];
  }
  return Status::Ok();
}

Status Denormalize(FeatureMatrix* features, const FeatureStats& stats) {
  MP_RETURN_IF_ERROR(CheckDims(*features, stats));
  const double scale = static_cast<double>(static_cast<int>(stats.scale));
  std::vector<float> mul(stats.std.size());
  for (size_t c = 0; c < mul.size(); ++c)
    mul[c] = static_cast<float>(scale * (stats.std[c] + kStatsEpsilon));
  for (int64_t r = 0; r < features->rows; ++r) {
    float* row = features->row(r);
    for (size_t c = 0; c < mul.size(); ++c) row[c] = row[c] * mul[c] + stats.mean[c];
  }
  return Status::Ok();
}

std::string StatsToJson(const FeatureStats& stats) {
  nlohmann::json doc;
  doc["format"] = "motionpipe.stats/1";
  doc["dim"] = stats.mean.size();
  doc["scale"] = static_cast<int>(stats.scale);
  doc["epsilon"] = kStatsEpsilon;
  doc["count"] = stats.count;
  doc["mean"] = stats.mean;
  doc["std"] = stats.std;
  return doc.dump(1) + "\n";
}

Status SaveStats(const std::string& path, const FeatureStats& stats) {
  return WriteFileAtomic(path, StatsToJson(stats));
}

namespace {
Result<std::vector<float>> FloatList(const nlohmann::json& node, const std::string& origin,
                                     const std::string& field) {
  if (!node.is_array())
    return DataLoss(origin + ": field '" + field + "' is not a list of numbers");
  std::vector<float> out;
  for (const auto& value : node) {
    if (!value.is_number()) return DataLoss(origin + ": field '" + field + "' holds a non-number");
    out.push_back(value.get<float>());
  }
  return out;
}
}  // namespace

Result<FeatureStats> LoadStats(const std::string& path, const std::string& key) {
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& error) {
    return DataLoss(path + ": malformed JSON: " + error.what());
  }
  if (!doc.is_object()) return DataLoss(path + ": expected a JSON object");
  FeatureStats stats;
  if (doc.contains("format")) {
    if (doc["format"] != "motionpipe.stats/1")
      return DataLoss(path + ": unknown stats format " + doc["format"].dump());
    MP_ASSIGN_OR_RETURN(stats.mean, FloatList(doc["mean"], path, "mean"));
    MP_ASSIGN_OR_RETURN(stats.std, FloatList(doc["std"], path, "std"));
    const int scale = doc.value("scale", 1);
    if (scale != 1 && scale != 2) return DataLoss(path + ": scale must be 1 or 2");
    stats.scale = static_cast<NormScale>(scale);
    stats.count = doc.value("count", int64_t{0});
  } else if (doc.contains("body_transl_delta_pelv")) {
    // The MotionFix reference layout: one {mean, std} object per feature group.
    stats.scale = NormScale::kTwoSigma;
    for (const FeatureGroup& group : MotionFixFeatureGroups()) {
      if (!doc.contains(group.name))
        return DataLoss(path + ": missing feature group '" + group.name + "'");
      MP_ASSIGN_OR_RETURN(auto mean, FloatList(doc[group.name].value("mean", nlohmann::json()),
                                               path, std::string(group.name) + ".mean"));
      MP_ASSIGN_OR_RETURN(auto std, FloatList(doc[group.name].value("std", nlohmann::json()), path,
                                              std::string(group.name) + ".std"));
      if (mean.size() != static_cast<size_t>(group.end - group.begin) ||
          std.size() != mean.size()) {
        return DataLoss(path + ": group '" + group.name + "' should have " +
                        std::to_string(group.end - group.begin) + " entries");
      }
      stats.mean.insert(stats.mean.end(), mean.begin(), mean.end());
      stats.std.insert(stats.std.end(), std.begin(), std.end());
    }
  } else {
    // The SINC/TMR reference layout: "<key>_mean" and "<key>_std" entries with "values".
    if (key.empty())
      return InvalidArgument(path +
                             ": this statistics file needs a key (e.g. sinc_rfeats_babel-amass)");
    for (const char* suffix : {"_mean", "_std"}) {
      const std::string name = key + suffix;
      if (!doc.contains(name)) return DataLoss(path + ": no entry '" + name + "'");
      MP_ASSIGN_OR_RETURN(auto values, FloatList(doc[name].value("values", nlohmann::json()), path,
                                                 name + ".values"));
      (std::string(suffix) == "_mean" ? stats.mean : stats.std) = std::move(values);
    }
  }
  if (stats.mean.empty() || stats.mean.size() != stats.std.size()) {
    return DataLoss(path + ": mean and std must be non-empty and of equal length");
  }
  for (size_t c = 0; c < stats.std.size(); ++c) {
    if (!std::isfinite(stats.mean[c]) || !std::isfinite(stats.std[c]) || stats.std[c] < 0) {
      return DataLoss(path + ": entry " + std::to_string(c) +
                      " is not finite or has a negative std");
    }
  }
  return stats;
}

}  // namespace motionpipe
