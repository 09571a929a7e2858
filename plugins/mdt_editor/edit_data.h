// Editing triplets for training (SimMotionEdit sec. 3.2): the filter stage's kept triplets with
// their similarity curves, or (the "without SNR filtering" ablation) every triplet of the corpus,
// the similarity task then masked where the filter has no curve. Motions become normalised 207-d
// features on the fly (mean/std over the training split, 2 sigma as MotionFix), cropped to
// max_frames, padded by repeating the last frame.
//
// params.data: {filter: input | none, split: train, max_frames: 200}
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

#include "../api/model.hpp"
#include "motionpipe/features/feature_matrix.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe::mdt {

struct EditDataOptions {
  std::string filter = "input";
  std::string split = "train";
  int64_t max_frames = 200;
  int classes = 3;
  bool regression = false;
  static EditDataOptions FromContext(const plugin::DataContext& context);
};

// Motions -> 207-d features (stored joint positions when present).
FeatureMatrix EditFeatures(const Motion& motion, const float* joints);

class EditDataset : public plugin::Dataset {
 public:
  explicit EditDataset(const EditDataOptions& options, const std::vector<std::string>& input_dirs);
  int64_t size() const override { return static_cast<int64_t>(items_.size()); }
  // tensors: source [Ts, N, 207], source_padding [N, Ts], target [Tt, N, 207], target_padding,
  // classes [N, Ts] int64 (-1 = no curve), similarity [N, Ts] float (-1 = no curve); texts.
  plugin::Batch Get(const std::vector<int64_t>& indices, uint64_t seed) override;
  // Mean and std (scale 2 sigma) over up to `limit` training motions (sources and targets); a
  // column constant over them gets std 1.
  std::pair<torch::Tensor, torch::Tensor> ComputeStats(int64_t limit = 400) const;
  // The covariance [207, 207] of the frames normalised with these statistics ((x - mean) /
  // (2 std)), over the same motions as ComputeStats.
  torch::Tensor FrameCovariance(const torch::Tensor& mean, const torch::Tensor& stddev,
                                int64_t limit = 400) const;
  void SetStats(torch::Tensor mean, torch::Tensor std) {
    mean_ = std::move(mean), std_ = std::move(std);
  }
  std::vector<std::string> AllTexts() const;
  int64_t with_similarity() const;

 private:
  struct Item {
    size_t file = 0;
    int64_t row = 0;
    int64_t curve = -1;  // index into the similarity curves, -1 = none
  };
  FeatureMatrix Features(const Item& item, bool source) const;
  EditDataOptions options_;
  std::vector<TripletColumns> files_;
  std::vector<Item> items_;
  std::vector<std::vector<float>> curves_;  // normalised similarity S^N per source frame
  torch::Tensor mean_, std_;
};

}  // namespace motionpipe::mdt
