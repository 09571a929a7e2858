// A learned clean-up of the legs of generated motion (issue 15; not in either paper): temporal
// convolutions trained on the corpus's own training motions to give back a motion's clean hip, knee
// and ankle rotations from corrupted ones, given the pelvis as it is (Holden 2018, "Robust solving
// of optical motion capture data by denoising", applied to the legs of generated motion). The
// corruptions imitate what the editors' legs carry (docs/EXPERIMENTS.md "A learned clean-up of the
// legs"): noise at a 10-fps network's frames interpolated to 30 fps, a slow offset, the legs drawn
// part of the way toward the triplet partner's, the legs' timing warped against the pelvis, the
// swing narrowed (legs that do not step), and the pelvis height drifted (the net then also gives a
// height correction). The loss: the rotations' matrix entries, the leg joints' world positions by
// forward kinematics, and the speed of the foot joints where the clean motion stands on them.
//
// A post-process and the corpus's prior, not a model of either paper: measured, it makes real
// mocap slide more (the CMU clips 0.37 -> 0.85-0.89 of contact frames).
#pragma once

#include <torch/torch.h>

#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "../api/model.hpp"
#include "../common/kinematics.h"
#include "motionpipe/base/status.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/math/rotation.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe::legs {

// The joints whose rotations move the feet (SMPL-22): hips, knees, ankles, left before right.
constexpr std::array<int, 6> kLegJoints = {1, 2, 4, 5, 7, 8};
constexpr int64_t kRootFeatures = 11;  // RootFeatures' width
constexpr int64_t kLegPositions = 6;   // knee, ankle, foot of each leg (LegPositions)

struct CleanupOptions {
  int64_t width = 256;
  std::vector<int64_t> dilations = {1, 2, 4, 8, 1};  // one residual block each (~2 s of context)
  bool height = false;  // also give back a correction of the pelvis height
  double fps = 30;      // the motions' rate (trained and applied at it)
  int64_t crop = 60;    // training window, frames
  // Corruption (training): the 10-fps key noise's spread (degrees; the slow offset up to 3x it),
  // the share of the batch with narrowed swings, the share with the legs drawn toward the
  // partner's (by up to `toward`), the share with warped timing.
  double degrees = 1;
  double shrink = 0;
  double toward_share = 0.5, toward = 0.4, warp_share = 0.3;
  // Loss weights: rotations, positions (m^2), contact feet's squared speed (m^2/s^2).
  double rotation_weight = 1, position_weight = 10, slide_weight = 0.1;
  static CleanupOptions FromJson(const nlohmann::json& j);  // std::invalid_argument on bad values
  nlohmann::json ToJson() const;
};

// Rotation matrices [..., 3, 3] of rotation vectors [..., 3], and back (angles below pi).
torch::Tensor Rodrigues(const torch::Tensor& v);
torch::Tensor LogMap(const torch::Tensor& r);
// The first two columns [..., 6] of rotation matrices (Zhou et al. 2019; the Python tool's
// convention, which the net's inputs keep), and back by Gram-Schmidt (plugins/common/kinematics.h).
inline torch::Tensor SixD(const torch::Tensor& r) {
  return nn::MatrixToSixD(r, nn::SixDAxes::kColumns);
}
inline torch::Tensor FromSixD(const torch::Tensor& x) {
  return nn::SixDToMatrix(x, nn::SixDAxes::kColumns);
}

// Per frame [B, T, 11], heading-free: the pelvis height, its velocity in the heading frame (m/s),
// the heading's angular speed (rad/s) and the pelvis orientation without heading (6D). trans
// [B, T, 3] (z-up), r0 [B, T, 3, 3] the global orientation.
torch::Tensor RootFeatures(const torch::Tensor& trans, const torch::Tensor& r0, double fps);

// World positions [B, T, 6, 3] of each leg's knee, ankle and foot joint (forward kinematics from
// the pelvis; `legs` [B, T, 6, 3, 3] in kLegJoints order).
torch::Tensor LegPositions(const torch::Tensor& trans, const torch::Tensor& r0,
                           const torch::Tensor& legs);

struct CleanupNetImpl : torch::nn::Module {
  explicit CleanupNetImpl(const CleanupOptions& options);
  // root [B, T, 11], legs [B, T, 6, 3, 3] -> the cleaned legs [B, T, 6, 3, 3] and the pelvis
  // height's correction [B, T] (metres; zeros without options.height).
  std::pair<torch::Tensor, torch::Tensor> forward(const torch::Tensor& root,
                                                  const torch::Tensor& legs);
  bool height = false;
  torch::nn::Conv1d in{nullptr}, out{nullptr};
  torch::nn::ModuleList blocks;
};
TORCH_MODULE(CleanupNet);

// A training window: clean and corrupted legs with their pelvis.
struct Window {
  torch::Tensor trans;        // [B, T, 3] clean pelvis
  torch::Tensor given_trans;  // [B, T, 3] the pelvis the net sees (height drifted with height)
  torch::Tensor r0;           // [B, T, 3, 3]
  torch::Tensor legs;         // [B, T, 6, 3, 3] clean
  torch::Tensor noisy;        // [B, T, 6, 3, 3] corrupted
};

// A number as people write it ("30", "29.97", "0.25"): frame rates and fractions in messages.
std::string NumberText(double value);

// The corruption of clean legs [B, T, 6, 3, 3] (partner: the partner motions' legs on the same
// frames), drawing from `generator`.
torch::Tensor Corrupt(const torch::Tensor& legs, const torch::Tensor& partner,
                      const CleanupOptions& options, at::Generator& generator);
// A pelvis height error [B, T] (metres): an offset of up to 5 cm, a drift of up to 15 cm over the
// window and a slow wobble of up to 5 cm (the edits drift up to 17 cm over 4 s and sink 3 cm on
// average; docs/EXPERIMENTS.md).
torch::Tensor HeightDrift(int64_t batch, int64_t frames, at::Generator& generator);
// Gaussian noise of `shape` [B, T, ...] filtered along time (sigma in frames, replicate edges),
// rescaled to unit spread.
torch::Tensor SmoothNoise(const std::vector<int64_t>& shape, double sigma_frames,
                          at::Generator& generator);

// The files a model's datasets read, each read once: the train stage makes a training and a
// validation dataset, which crop different parts (splits, held-out ends) of the same files.
// Keyed by path; motions at one frame rate (the model's).
class CleanupFiles {
 public:
  // The triplet file's columns, read on first use.
  Result<std::shared_ptr<const TripletColumns>> Triplets(const std::string& path);
  // The motion file's motions at `fps` (LoadMotionFile), read on first use.
  Result<std::shared_ptr<const std::vector<Motion>>> Motions(const std::string& path, double fps);
  // How many files were read from disk (not from this cache).
  int64_t reads() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return reads_;
  }

 private:
  // cache[key], loaded by `load` (a Result<T>) on first use; a failed load is not kept.
  template <typename Key, typename T, typename Load>
  Result<std::shared_ptr<const T>> Once(std::map<Key, std::shared_ptr<const T>>& cache,
                                        const Key& key, Load load) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (const auto it = cache.find(key); it != cache.end()) return it->second;
    auto loaded = load();
    if (!loaded.ok()) return loaded.status();
    ++reads_;
    return cache[key] = std::make_shared<const T>(std::move(*loaded));
  }

  mutable std::mutex mutex_;
  std::map<std::string, std::shared_ptr<const TripletColumns>> triplets_;
  std::map<std::pair<std::string, double>, std::shared_ptr<const std::vector<Motion>>> motions_;
  int64_t reads_ = 0;
};

// Training windows, cropped from either of two sources (or both):
//  - editing triplets, both sides of each triplet of a split (each side's partner: the other side):
//    data {split: train, val_split: val, limit: 0 (triplets of the split; 0 = all), triplets: a
//    directory with triplet files instead of the inputs' (a corpus stage's)};
//  - motion files, what a user has of real mocap: data {motions: a file or directory, or a list of
//    them (our clips layout, AMASS-style npz, BVH; LoadMotionFile, resampled to options.fps),
//    val_fraction: 0.1}. The last val_fraction of each motion's frames is held out for validation;
//    each motion's partner is the next one's same part (a lone motion's, its own).
// Windows are at least options.crop frames long: random crops, corrupted as CleanupOptions says,
// drawn from the batch's seed (the same batch for the same indices and seed).
// std::invalid_argument naming the file for data it cannot use.
class CleanupDataset : public plugin::Dataset {
 public:
  // files: where the data files are read (shared with the model's other datasets); a cache of
  // the dataset's own when null.
  CleanupDataset(const CleanupOptions& options, const plugin::DataContext& context,
                 std::shared_ptr<CleanupFiles> files = nullptr);
  int64_t size() const override { return static_cast<int64_t>(tracks_.size()); }
  // tensors: trans, given_trans [B, crop, 3], r0 [B, crop, 3, 3], legs, noisy [B, crop, 6, 3, 3].
  plugin::Batch Get(const std::vector<int64_t>& indices, uint64_t seed) override;

 private:
  // The frames a window may be cropped from ([frames, 22, 3] axis-angle poses, [frames, 3] pelvis)
  // and the partner whose legs the corruption draws toward on the same frames.
  struct Track {
    const float* poses = nullptr;
    const float* trans = nullptr;
    int64_t frames = 0;
    const float* partner_poses = nullptr;
    int64_t partner_frames = 0;
  };
  void AddTriplets(const nlohmann::json& config, const std::vector<std::string>& input_dirs,
                   const std::string& split);
  void AddMotions(const nlohmann::json& config, bool validation);
  // The rotation matrix (row-major) of an axis-angle triple.
  static void Write(float* to, const float* axis_angle) {
    const Mat3 r = AxisAngleToMatrix({axis_angle[0], axis_angle[1], axis_angle[2]});
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) to[i * 3 + j] = static_cast<float>(r[i][j]);
    }
  }

  CleanupOptions options_;
  std::shared_ptr<CleanupFiles> files_;  // holds what the tracks point into
  std::vector<Track> tracks_;
};

// Loss terms of one window: "rotation", "position", "slide" and their weighted sum "loss".
std::map<std::string, torch::Tensor> CleanupLosses(CleanupNet& net, const Window& window,
                                                   const CleanupOptions& options);

// The motion with its legs (and, with options.height, its pelvis height) cleaned; every other
// value as it was. Motions shorter than 8 frames are given back unchanged. InvalidArgument for a
// motion at another rate than options.fps.
Result<Motion> CleanLegs(CleanupNet& net, const CleanupOptions& options, const Motion& motion);

}  // namespace motionpipe::legs
