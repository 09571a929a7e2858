// Editing triplets for training (SimMotionEdit sec. 3.2): the filter stage's kept triplets with
// their similarity curves, or (the "without SNR filtering" ablation) every triplet of the corpus,
// the similarity task then masked where the filter has no curve. Motions become normalised 207-d
// features on the fly (mean/std over the training split, 2 sigma as MotionFix), cropped to
// max_frames, padded by repeating the last frame.
//
// params.data: {filter: input | none, split: train, max_frames: 200, limit: 0}
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
  int64_t max_frames = 200;  // in the network's frames
  // The first `limit` triplets of the split (0: all): in file and row order with filter: none,
  // the triplets an `edit` stage with the same split and limit edits (issue 15's fitting
  // diagnostic); in the filter's order with filter: input.
  int64_t limit = 0;
  double fps = 0;  // the network's frame rate (the model's); 0: the data's
  int classes = 3;
  bool regression = false;
  static EditDataOptions FromContext(const plugin::DataContext& context);
};

// Motions -> 207-d features (stored joint positions when present).
FeatureMatrix EditFeatures(const Motion& motion, const float* joints);

// The features' normalisation (REFERENCE.md 2): x' = (x - mean) / NormalisationScale(std), the
// scale 2 (std + 1e-5) in the dtype of `stddev`; the network's outputs go back as x' scale + mean.
inline torch::Tensor NormalisationScale(const torch::Tensor& stddev) {
  return 2.0 * (stddev + 1e-5);
}

// The network's frame rate (EditorOptions::fps, issue 15: a step at 10 fps costs about a third of
// one at 30). A motion at `fps` (<= 0 or the motion's own: unchanged): a whole-number ratio keeps
// every k-th frame, as Resample by index, and the stored joints [T, 22, 3] of those frames when
// given; any other ratio interpolates (slerp) and leaves the joints to forward kinematics.
// `step` is the motion's frames per network frame: network frame f shows frame floor(f step).
struct AtNetworkRate {
  Motion motion;
  std::vector<float> joints;  // empty: forward kinematics
  double step = 1;
};
AtNetworkRate ToNetworkRate(const Motion& motion, const float* joints, double fps);
// The network's frames for a length, and the way back: FramesCovering and ResampleToFrames
// (motionpipe/motion/motion.h).

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
  // (2 std)), over the same motions as ComputeStats; their mean [207] in `frame_mean` if given.
  torch::Tensor FrameCovariance(const torch::Tensor& mean, const torch::Tensor& stddev,
                                int64_t limit = 400, torch::Tensor* frame_mean = nullptr) const;
  void SetStats(torch::Tensor mean, torch::Tensor std) {
    mean_ = std::move(mean), std_ = std::move(std);
  }
  std::vector<std::string> AllTexts() const;
  int64_t with_similarity() const;
  // Item `index`'s triplet id, and its source or target motion at the data's own rate.
  const std::string& Id(int64_t index) const;
  Motion SideMotionOf(int64_t index, bool source) const;

 private:
  struct Item {
    size_t file = 0;
    int64_t row = 0;
    int64_t curve = -1;  // index into the similarity curves, -1 = none
  };
  // At the network's rate; *step (optional) gets the data frames per network frame.
  FeatureMatrix Features(const Item& item, bool source, double* step = nullptr) const;
  EditDataOptions options_;
  std::vector<TripletColumns> files_;
  std::vector<Item> items_;
  std::vector<std::vector<float>> curves_;  // normalised similarity S^N per source frame
  torch::Tensor mean_, std_;
};

}  // namespace motionpipe::mdt
