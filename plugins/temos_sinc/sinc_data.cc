#include "sinc_data.h"

#include <cstdio>
#include <filesystem>
#include <set>
#include <stdexcept>

#include "motionpipe/base/random.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/sinc/texts.h"

namespace motionpipe::temos {

SincDataOptions SincDataOptions::FromContext(const plugin::DataContext& context) {
  const auto& j = context.config;
  SincDataOptions o;
  o.spans = j.value("spans", std::string());
  if (o.spans.empty()) {
    for (const auto& dir : context.input_dirs) {
      if (std::filesystem::exists(dir + "/spans.npz")) {
        o.spans = dir + "/spans.npz";
        break;
      }
    }
  }
  if (o.spans.empty())
    throw std::invalid_argument(
        "data.spans: no spans.npz (give data.spans or a `singles` input stage)");
  o.split =
      context.split == "val" ? j.value("val_split", std::string("val")) : j.value("split", o.split);
  o.singles = j.value("singles", o.singles);
  o.real_pairs = j.value("real_pairs", o.real_pairs);
  o.synthetic_p = j.value("synthetic_p", o.synthetic_p);
  const std::string parts = j.value("parts", std::string("labels"));
  if (parts != "labels" && parts != "random")
    throw std::invalid_argument("data.parts must be labels or random");
  o.parts = parts == "labels" ? sinc::PartSource::kLabels : sinc::PartSource::kRandom;
  auto crop = sinc::ParseCropMode(j.value("crop", std::string("first")));
  if (!crop.ok()) throw std::invalid_argument("data." + crop.status().message());
  o.crop = *crop;
  o.max_frames = j.value("max_frames", o.max_frames);
  o.augment_texts = j.value("augment_texts", o.augment_texts);
  o.limit = j.value("limit", o.limit);
  if (o.limit < 0) throw std::invalid_argument("data.limit must be >= 0");
  if (o.synthetic_p < 0 || o.synthetic_p > 1)
    throw std::invalid_argument("data.synthetic_p must be in [0, 1]");
  return o;
}

int64_t FramesPerNetworkFrame(double rate, double fps) {
  const int64_t k = WholeFrameStep(rate, fps);
  if (k == 0) {
    char message[160];
    std::snprintf(message, sizeof(message),
                  "fps %g: the spans' rate (%g fps) is not a whole multiple of the model's rate",
                  fps, rate);
    throw std::invalid_argument(message);
  }
  return k;
}

SincDataset::SincDataset(std::shared_ptr<const sinc::SpanTable> table,
                         const SincDataOptions& options)
    : table_(std::move(table)), options_(options) {
  for (int64_t i = 0; i < table_->size(); ++i) {
    if (!options_.split.empty() && table_->splits[static_cast<size_t>(i)] != options_.split)
      continue;
    if (table_->single(i) ? options_.singles : options_.real_pairs)
      items_.push_back(static_cast<int32_t>(i));
    if (options_.limit > 0 && static_cast<int64_t>(items_.size()) == options_.limit) break;
  }
  if (items_.empty())
    throw std::invalid_argument("no training examples in split '" + options_.split + "' of " +
                                options_.spans);
  for (const int32_t span : items_) {
    try {
      FramesPerNetworkFrame(table_->fps[static_cast<size_t>(span)], options_.fps);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(options_.spans + ": " + e.what());
    }
  }
  sinc::SynthOptions synth;
  synth.split = options_.split;
  synth.parts = options_.parts;
  synth.crop = options_.crop;
  sampler_ = std::make_unique<sinc::PairSampler>(*table_, synth);
}

Example SincDataset::Make(int64_t index, uint64_t seed) const {
  const int32_t span = items_[static_cast<size_t>(index)];
  Rng rng(MixSeed(seed, static_cast<uint64_t>(index)));
  Example ex;
  std::string a = table_->text_a[static_cast<size_t>(span)], b;
  const float* poses = nullptr;
  const float* trans = nullptr;
  sinc::PairRecipe recipe;
  bool composed = false;
  if (!table_->single(span)) {
    b = table_->text_b[static_cast<size_t>(span)];
  } else if (options_.synthetic_p > 0 && rng.Bernoulli(options_.synthetic_p) &&
             sampler_->DrawPartner(span, rng, &recipe)) {
    composed = true;
    b = table_->text_a[static_cast<size_t>(recipe.second)];
  }
  int64_t frames;
  if (composed) {
    const sinc::CompositionPlan plan =
        sinc::PlanComposition(table_->frames(recipe.first), recipe.first_parts,
                              table_->frames(recipe.second), recipe.second_parts, options_.crop);
    frames = plan.frames;
    ex.features.resize(static_cast<size_t>(frames * kTemosFeatureDim));
    sinc::MaterialiseFeatures(*table_, recipe, options_.crop, ex.features.data());
  } else {
    frames = table_->frames(span);
    poses = table_->poses + table_->offsets[static_cast<size_t>(span)] * kNumJoints * 3;
    trans = table_->trans + table_->offsets[static_cast<size_t>(span)] * 3;
    ex.features.resize(static_cast<size_t>(frames * kTemosFeatureDim));
    EncodeTemos135Fast(poses, trans, frames, ex.features.data());
  }
  const int64_t k = FramesPerNetworkFrame(
      table_->fps[static_cast<size_t>(composed ? recipe.first : span)], options_.fps);
  if (k > 1) frames = EveryKthTemos135(ex.features.data(), frames, k, ex.features.data());
  ex.frames = std::min<int64_t>(frames, options_.max_frames);
  ex.features.resize(static_cast<size_t>(ex.frames * kTemosFeatureDim));
  if (b.empty()) {
    ex.actions = {a};
    ex.text = a;
  } else {
    const bool swap = options_.augment_texts && rng.Bernoulli(0.5);
    if (swap) std::swap(a, b);
    ex.actions = {a, b};
    ex.text =
        options_.augment_texts
            ? sinc::PairText(a, b,
                             static_cast<sinc::PairPattern>(rng.Int(0, sinc::kNumPairPatterns - 1)))
            : sinc::EvalPairText(a, b);
  }
  return ex;
}

plugin::Batch SincDataset::Get(const std::vector<int64_t>& indices, uint64_t seed) {
  std::vector<Example> examples;
  int64_t longest = 1;
  for (const int64_t i : indices) {
    examples.push_back(Make(i, seed));
    longest = std::max(longest, examples.back().frames);
  }
  const auto n = static_cast<int64_t>(examples.size());
  auto features = torch::zeros({longest, n, kTemosFeatureDim});
  auto padding = torch::ones({n, longest}, torch::kBool);
  plugin::Batch batch;
  for (int64_t k = 0; k < n; ++k) {
    const Example& ex = examples[static_cast<size_t>(k)];
    auto x = torch::from_blob(const_cast<float*>(ex.features.data()), {ex.frames, kTemosFeatureDim})
                 .clone();
    if (mean_.defined()) x = (x - mean_) / (std_ + 1e-5);
    features.index_put_({torch::indexing::Slice(0, ex.frames), k}, x);
    padding.index_put_({k, torch::indexing::Slice(0, ex.frames)}, false);
    batch.texts.push_back(ex.text);
  }
  batch.tensors["features"] = features;
  batch.tensors["padding"] = padding;
  for (const Example& ex : examples) batch.groups.push_back(ex.actions);
  batch.size = n;
  return batch;
}

std::pair<torch::Tensor, torch::Tensor> SincDataset::ComputeStats() const {
  // Over the real motions of the items (compositions reuse the same rotations).
  std::vector<double> sum(kTemosFeatureDim, 0), sq(kTemosFeatureDim, 0);
  int64_t count = 0;
  std::vector<float> buffer;
  for (const int32_t span : items_) {
    int64_t frames = table_->frames(span);
    buffer.resize(static_cast<size_t>(frames * kTemosFeatureDim));
    EncodeTemos135Fast(table_->poses + table_->offsets[static_cast<size_t>(span)] * kNumJoints * 3,
                       table_->trans + table_->offsets[static_cast<size_t>(span)] * 3, frames,
                       buffer.data());
    // At the network's rate: its velocities span k frames.
    const int64_t k = FramesPerNetworkFrame(table_->fps[static_cast<size_t>(span)], options_.fps);
    if (k > 1) frames = EveryKthTemos135(buffer.data(), frames, k, buffer.data());
    for (int64_t f = 0; f < frames; ++f) {
      for (int d = 0; d < kTemosFeatureDim; ++d) {
        const double v = buffer[static_cast<size_t>(f * kTemosFeatureDim + d)];
        sum[static_cast<size_t>(d)] += v;
        sq[static_cast<size_t>(d)] += v * v;
      }
    }
    count += frames;
  }
  return StatsFromSums(sum, sq, count);
}

std::pair<torch::Tensor, torch::Tensor> StatsFromSums(const std::vector<double>& sum,
                                                      const std::vector<double>& squares,
                                                      int64_t count) {
  // The same rule as the editor's statistics (ConstantFeatureColumnsKeepUnitScale).
  constexpr double kConstantColumnVariance = 1e-12;
  const size_t dims = sum.size();
  std::vector<float> mean(dims), stddev(dims);
  for (size_t d = 0; d < dims; ++d) {
    const double m = sum[d] / static_cast<double>(std::max<int64_t>(1, count));
    const double var =
        std::max(squares[d] / static_cast<double>(std::max<int64_t>(1, count)) - m * m, 0.0);
    mean[d] = static_cast<float>(m);
    stddev[d] = static_cast<float>(var < kConstantColumnVariance ? 1.0 : std::sqrt(var));
  }
  return {torch::tensor(mean), torch::tensor(stddev)};
}

std::vector<std::string> SincDataset::AllTexts() const {
  std::set<std::string> texts;
  for (int64_t i = 0; i < table_->size(); ++i) {
    const std::string& a = table_->text_a[static_cast<size_t>(i)];
    texts.insert(a);
    texts.insert(sinc::GerundOfLabel(a));
    if (!table_->single(i)) {
      texts.insert(table_->text_b[static_cast<size_t>(i)]);
      texts.insert(sinc::GerundOfLabel(table_->text_b[static_cast<size_t>(i)]));
    }
  }
  texts.insert("while during simultaneously and at the same time");
  return std::vector<std::string>(texts.begin(), texts.end());
}

}  // namespace motionpipe::temos
