// SINC's training data (paper sec. 3.2-3.3): real singles, real pairs and synthetic pairs composed
// on the fly, from the spans table of the `singles` stage. Each example's randomness (whether a
// single is composed, its partner, the text pattern) comes from the batch seed and the example
// index, so ranks and resumed runs see the same examples.
//
// params.data: {spans: PATH (default: an input stage's spans.npz), split: train, singles: true,
// real_pairs: true, synthetic_p: 0.5 (probability that a real single is composed with a partner),
// parts: labels | random, crop: first | centre, max_frames: 200, augment_texts: true, limit: 0}
// and the model's frame rate (the config's `fps`, set by the model, not a data key).
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

#include "../api/model.hpp"
#include "motionpipe/sinc/spans.h"
#include "motionpipe/sinc/synth.h"

namespace motionpipe::temos {

struct SincDataOptions {
  std::string spans;
  std::string split = "train";
  bool singles = true;
  bool real_pairs = true;
  double synthetic_p = 0.5;
  sinc::PartSource parts = sinc::PartSource::kLabels;
  sinc::CropMode crop = sinc::CropMode::kFirst;
  int64_t max_frames = 200;  // in the network's frames
  bool augment_texts = true;
  // The network's frame rate (the model config's `fps`; 0: the data's own). The spans' rate must be
  // a whole multiple of it: every k-th frame is kept (EveryKthTemos135), as Resample by index.
  double fps = 0;
  // The first `limit` examples of the split in the table's order (0: all): the spans a generate
  // stage with the same split, kind and limit reads, so that a model fitted to a few motions can be
  // asked to give them back (issue 15: can the decoder make a gait at all?).
  int64_t limit = 0;
  static SincDataOptions FromContext(const plugin::DataContext& context);
};

// Data frames per network frame: 1 when `fps` is 0 or `rate` itself, else rate / fps, which must
// be a whole number (std::invalid_argument naming both rates otherwise).
int64_t FramesPerNetworkFrame(double rate, double fps);

// One example before batching.
struct Example {
  std::vector<float> features;  // [frames, 135] at the network's rate, not normalised
  int64_t frames = 0;
  std::vector<std::string> actions;  // the action texts (1 or 2)
  std::string text;                  // the augmented text of the whole example
};

// Per-feature mean and std from sums of values and squares over `count` frames. A feature constant
// over them (the procedural corpus never turns some joints: their 135-d columns have spread 0)
// keeps std 1: x / (0 + 1e-5) would turn a 0.002 rad wobble of another motion into inputs of 200,
// and the demo's TMR scored a copy of the source with 0.1 degree of noise at chance (issue 15).
std::pair<torch::Tensor, torch::Tensor> StatsFromSums(const std::vector<double>& sum,
                                                      const std::vector<double>& squares,
                                                      int64_t count);

class SincDataset : public plugin::Dataset {
 public:
  SincDataset(std::shared_ptr<const sinc::SpanTable> table, const SincDataOptions& options);
  int64_t size() const override { return static_cast<int64_t>(items_.size()); }
  Example Make(int64_t index, uint64_t seed) const;
  // Features [T, N, 135] normalised with mean/std, padding [N, T], texts.
  plugin::Batch Get(const std::vector<int64_t>& indices, uint64_t seed) override;
  void SetStats(torch::Tensor mean, torch::Tensor std) {
    mean_ = std::move(mean), std_ = std::move(std);
  }
  // Per-feature mean and std over the items' real motions (computed once, before training), by
  // StatsFromSums.
  std::pair<torch::Tensor, torch::Tensor> ComputeStats() const;
  // Every text an example can carry (for the tokenizer).
  std::vector<std::string> AllTexts() const;

 private:
  std::shared_ptr<const sinc::SpanTable> table_;
  SincDataOptions options_;
  std::vector<int32_t> items_;
  std::unique_ptr<sinc::PairSampler> sampler_;
  torch::Tensor mean_, std_;
};

}  // namespace motionpipe::temos
