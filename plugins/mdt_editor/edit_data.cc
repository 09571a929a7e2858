#include "edit_data.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>

#include "motionpipe/features/motionfix207.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/similarity/filter.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::mdt {

namespace fs = std::filesystem;

EditDataOptions EditDataOptions::FromContext(const plugin::DataContext& context) {
  const auto& j = context.config;
  EditDataOptions o;
  o.filter = j.value("filter", o.filter);
  if (o.filter != "input" && o.filter != "none")
    throw std::invalid_argument("data.filter must be input or none");
  o.split =
      context.split == "val" ? j.value("val_split", std::string("val")) : j.value("split", o.split);
  o.max_frames = j.value("max_frames", o.max_frames);
  if (o.max_frames < 2) throw std::invalid_argument("data.max_frames must be at least 2");
  o.limit = j.value("limit", o.limit);
  if (o.limit < 0) throw std::invalid_argument("data.limit must be >= 0");
  return o;
}

FeatureMatrix EditFeatures(const Motion& motion, const float* joints) {
  return joints ? EncodeMotionFix207WithJoints(motion, joints)
                : EncodeMotionFix207(Skeleton::Smpl22(), motion);
}

AtNetworkRate ToNetworkRate(const Motion& motion, const float* joints, double fps) {
  AtNetworkRate out;
  if (fps <= 0 || !(motion.fps > 0) || SameFrameRate(motion.fps, fps) || motion.num_frames() == 0) {
    out.motion = motion;
    if (joints) out.joints.assign(joints, joints + motion.num_frames() * kNumJoints * 3);
    return out;
  }
  out.motion = ToModelRate(motion, fps);
  const int64_t k = WholeFrameStep(motion.fps, fps);
  out.step = k > 0 ? static_cast<double>(k) : motion.fps / fps;
  if (joints && k > 0) {
    for (int64_t f = 0; f < out.motion.num_frames(); ++f)
      out.joints.insert(out.joints.end(), joints + f * k * kNumJoints * 3,
                        joints + (f * k + 1) * kNumJoints * 3);
  }
  return out;
}

EditDataset::EditDataset(const EditDataOptions& options, const std::vector<std::string>& input_dirs)
    : options_(options) {
  // The filter's kept triplets and curves, by (file, row).
  std::map<std::pair<std::string, int64_t>, int64_t> curve_of;
  std::vector<std::pair<std::string, int64_t>> kept;
  for (const auto& dir : input_dirs) {
    const std::string path = dir + "/similarity.npz";
    if (!fs::exists(path)) continue;
    auto table = similarity::ReadSimilarity(path);
    if (!table.ok()) throw std::invalid_argument(table.status().message());
    for (size_t i = 0; i < table->ids.size(); ++i) {
      const int64_t begin = table->offsets[i], end = table->offsets[i + 1];
      const auto key = std::make_pair(table->files[i], table->rows[i]);
      curve_of[key] = static_cast<int64_t>(curves_.size());
      curves_.emplace_back(table->similarity.begin() + begin, table->similarity.begin() + end);
      if (table->splits[i] == options_.split) kept.push_back(key);
    }
  }
  // The triplet files: those the curves name, or (filter: none) every triplets file of the inputs.
  std::vector<std::string> paths;
  if (options_.filter == "none") {
    paths = StageTripletFiles(input_dirs);  // a corpus's result, not its tasks' same triplets too
    if (paths.empty())
      throw std::invalid_argument(
          "data.filter: none needs an input with triplet files (a corpus stage)");
  } else {
    if (curves_.empty())
      throw std::invalid_argument(
          "no similarity.npz in the inputs: give a filter stage as input (or data.filter: none)");
    for (const auto& [file, row] : kept) paths.push_back(file);
  }
  std::sort(paths.begin(), paths.end());
  paths.erase(std::unique(paths.begin(), paths.end()), paths.end());
  std::map<std::string, size_t> file_index;
  for (const auto& path : paths) {
    auto columns = ReadTripletColumns(path);
    if (!columns.ok()) throw std::invalid_argument(columns.status().message());
    file_index[path] = files_.size();
    files_.push_back(std::move(*columns));
  }
  if (options_.filter == "none") {
    for (size_t f = 0; f < files_.size(); ++f) {
      for (int64_t r = 0; r < files_[f].rows; ++r) {
        if (files_[f].splits[static_cast<size_t>(r)] != options_.split) continue;
        const auto it = curve_of.find({paths[f], files_[f].first_row + r});
        items_.push_back({f, r, it == curve_of.end() ? -1 : it->second});
      }
    }
  } else {
    for (const auto& key : kept)
      items_.push_back({file_index.at(key.first),
                        key.second - files_[file_index.at(key.first)].first_row, curve_of.at(key)});
  }
  if (options_.limit > 0 && static_cast<int64_t>(items_.size()) > options_.limit)
    items_.resize(static_cast<size_t>(options_.limit));
  for (const Item& item : items_) {
    const auto& c = files_[item.file];
    if (c.source.joints != kNumJoints || c.target.joints != kNumJoints) {
      throw std::invalid_argument(c.origin + ": triplet " + c.ids[static_cast<size_t>(item.row)] +
                                  " is not an SMPL-22 body");
    }
  }
  if (items_.empty())
    throw std::invalid_argument("no editing triplets in split '" + options_.split +
                                "' of the inputs");
}

const std::string& EditDataset::Id(int64_t index) const {
  const Item& item = items_.at(static_cast<size_t>(index));
  return files_[item.file].ids[static_cast<size_t>(item.row)];
}

Motion EditDataset::SideMotionOf(int64_t index, bool source) const {
  const Item& item = items_.at(static_cast<size_t>(index));
  return SideMotion(files_[item.file], item.row, source);
}

FeatureMatrix EditDataset::Features(const Item& item, bool source, double* step) const {
  const TripletColumns& c = files_[item.file];
  const TripletColumns::Side& side = source ? c.source : c.target;
  const int64_t begin = side.offsets[static_cast<size_t>(item.row)];
  const Motion m = SideMotion(c, item.row, source);
  const float* joints = side.positions && side.position_joints == kNumJoints
                            ? side.positions + begin * kNumJoints * 3
                            : nullptr;
  if (options_.fps <= 0) return EditFeatures(m, joints);
  const AtNetworkRate at = ToNetworkRate(m, joints, options_.fps);
  if (step) *step = at.step;
  return EditFeatures(at.motion, at.joints.empty() ? nullptr : at.joints.data());
}

namespace {

// [T, N, D] padded by repeating each example's last frame, and the padding mask [N, T].
std::pair<torch::Tensor, torch::Tensor> Pad(const std::vector<FeatureMatrix>& features,
                                            const torch::Tensor& mean,
                                            const torch::Tensor& stddev) {
  const auto n = static_cast<int64_t>(features.size());
  int64_t longest = 1;
  for (const auto& f : features) longest = std::max(longest, f.rows);
  auto out = torch::empty({longest, n, kMotionFixFeatureDim});
  auto padding = torch::zeros({n, longest}, torch::kBool);
  for (int64_t i = 0; i < n; ++i) {
    const auto& f = features[static_cast<size_t>(i)];
    auto x = (torch::from_blob(const_cast<float*>(f.data.data()), {f.rows, f.cols}) - mean) /
             NormalisationScale(stddev);
    out.select(1, i).narrow(0, 0, f.rows).copy_(x);
    if (f.rows < longest) {
      out.select(1, i)
          .narrow(0, f.rows, longest - f.rows)
          .copy_(x[f.rows - 1].expand({longest - f.rows, f.cols}));
      padding[i].narrow(0, f.rows, longest - f.rows).fill_(true);
    }
  }
  return {out, padding};
}

}  // namespace

plugin::Batch EditDataset::Get(const std::vector<int64_t>& indices, uint64_t) {
  plugin::Batch batch;
  std::vector<FeatureMatrix> sources, targets;
  std::vector<double> steps(indices.size(), 1.0);  // source frames per network frame
  for (int64_t index : indices) {
    const Item& item = items_[static_cast<size_t>(index)];
    FeatureMatrix s = Features(item, true, &steps[static_cast<size_t>(sources.size())]),
                  t = Features(item, false);
    // Crop both to max_frames (the first frames: the curve is indexed by source frame).
    if (s.rows > options_.max_frames)
      s.rows = options_.max_frames, s.data.resize(static_cast<size_t>(s.rows * s.cols));
    if (t.rows > options_.max_frames)
      t.rows = options_.max_frames, t.data.resize(static_cast<size_t>(t.rows * t.cols));
    sources.push_back(std::move(s));
    targets.push_back(std::move(t));
    batch.texts.push_back(files_[item.file].texts[static_cast<size_t>(item.row)]);
  }
  auto [source, source_padding] = Pad(sources, mean_, std_);
  auto [target, target_padding] = Pad(targets, mean_, std_);
  const auto n = static_cast<int64_t>(indices.size());
  auto classes = torch::full({n, source.size(0)}, -1, torch::kInt64);
  auto similarity = torch::full({n, source.size(0)}, -1.0f);
  for (int64_t i = 0; i < n; ++i) {
    const Item& item = items_[static_cast<size_t>(indices[static_cast<size_t>(i)])];
    if (item.curve < 0) continue;
    const auto& curve = curves_[static_cast<size_t>(item.curve)];
    const double step = steps[static_cast<size_t>(i)];
    for (int64_t f = 0; f < sources[static_cast<size_t>(i)].rows; ++f) {
      // The curve is indexed by the source's own frames (ToNetworkRate's floor(f step)).
      const auto at = static_cast<size_t>(std::floor(static_cast<double>(f) * step + 1e-9));
      if (at >= curve.size()) break;
      const float s = curve[at];
      similarity[i][f] = s;
      // eq. (10): K equal bins of S^N in [0, 1], the top bin closed.
      classes[i][f] = std::min<int64_t>(
          static_cast<int64_t>(s * static_cast<float>(options_.classes)), options_.classes - 1);
    }
  }
  batch.tensors = {{"source", source},   {"source_padding", source_padding},
                   {"target", target},   {"target_padding", target_padding},
                   {"classes", classes}, {"similarity", similarity}};
  batch.size = n;
  return batch;
}

constexpr double kConstantColumnVariance = 1e-12;

std::pair<torch::Tensor, torch::Tensor> EditDataset::ComputeStats(int64_t limit) const {
  // Over an even spread of the items, sources and targets alike (double sums).
  std::vector<double> sum(kMotionFixFeatureDim, 0.0), squares(kMotionFixFeatureDim, 0.0);
  int64_t count = 0;
  const auto n = static_cast<int64_t>(items_.size());
  const int64_t take = std::min(n, limit);
  for (int64_t k = 0; k < take; ++k) {
    const Item& item = items_[static_cast<size_t>(k * n / take)];
    for (bool source : {true, false}) {
      const FeatureMatrix f = Features(item, source);
      for (int64_t r = 0; r < f.rows; ++r) {
        for (int64_t c = 0; c < f.cols; ++c) {
          const double v = f.at(r, c);
          sum[static_cast<size_t>(c)] += v;
          squares[static_cast<size_t>(c)] += v * v;
        }
      }
      count += f.rows;
    }
  }
  auto mean = torch::zeros({kMotionFixFeatureDim}), stddev = torch::ones({kMotionFixFeatureDim});
  for (int64_t c = 0; c < kMotionFixFeatureDim; ++c) {
    const double m = sum[static_cast<size_t>(c)] / static_cast<double>(count);
    const double var =
        std::max(0.0, (squares[static_cast<size_t>(c)] - static_cast<double>(count) * m * m) /
                          static_cast<double>(std::max<int64_t>(1, count - 1)));
    mean[c] = m;
    // A column constant over the training motions (the procedural corpus never turns some joints:
    // 55 of 207 columns) carries nothing to normalise, and (x - mean) / (2 (0 + 1e-5)) would turn
    // any deviation of another motion (a real clip that turns those joints) into inputs of order
    // 1e4. Such a column keeps its scale: std 1 (issue 15, the CMU edit's jerk).
    stddev[c] = var < kConstantColumnVariance ? 1.0 : std::sqrt(var);
  }
  return {mean, stddev};
}

torch::Tensor EditDataset::FrameCovariance(const torch::Tensor& mean, const torch::Tensor& stddev,
                                           int64_t limit, torch::Tensor* frame_mean) const {
  auto scatter = torch::zeros({kMotionFixFeatureDim, kMotionFixFeatureDim}, torch::kFloat64);
  auto sum = torch::zeros({kMotionFixFeatureDim}, torch::kFloat64);
  int64_t count = 0;
  const auto n = static_cast<int64_t>(items_.size());
  const int64_t take = std::min(n, limit);
  const auto scale = NormalisationScale(stddev.to(torch::kFloat64));
  for (int64_t k = 0; k < take; ++k) {
    const Item& item = items_[static_cast<size_t>(k * n / take)];
    for (bool source : {true, false}) {
      const FeatureMatrix f = Features(item, source);
      const auto x =
          (torch::from_blob(const_cast<float*>(f.data.data()), {f.rows, f.cols}, torch::kFloat32)
               .to(torch::kFloat64) -
           mean.to(torch::kFloat64)) /
          scale;
      scatter += torch::matmul(x.t(), x);
      sum += x.sum(0);
      count += f.rows;
    }
  }
  if (count < 2) throw std::runtime_error("FrameCovariance: fewer than 2 training frames");
  const auto m = sum / static_cast<double>(count);
  if (frame_mean != nullptr) *frame_mean = m.to(torch::kFloat32);
  return ((scatter - static_cast<double>(count) * torch::outer(m, m)) /
          static_cast<double>(count - 1))
      .to(torch::kFloat32);
}

std::vector<std::string> EditDataset::AllTexts() const {
  std::vector<std::string> texts;
  for (const Item& item : items_)
    texts.push_back(files_[item.file].texts[static_cast<size_t>(item.row)]);
  return texts;
}

int64_t EditDataset::with_similarity() const {
  return std::count_if(items_.begin(), items_.end(), [](const Item& i) { return i.curve >= 0; });
}

}  // namespace motionpipe::mdt
