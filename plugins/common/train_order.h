// What the train stage (plugins/train) draws for each step, in one place so that a replay of it
// (bench/tmr_quality.cc: the TMR trained by us and by the PyTorch-Python reference on the train
// stage's own stream) cannot drift from it: the learning-rate schedule, the order of the examples
// and each example's seed.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

#include "motionpipe/base/random.h"

namespace motionpipe::nn {

struct LearningRateSchedule {
  double lr = 3e-4, min_lr = 0;
  int64_t warmup = 100, steps = 1000;
  bool cosine = true;  // false: constant after the warm-up

  // Linear warm-up over `warmup` steps, then cosine from lr to min_lr over the rest of `steps`.
  double At(int64_t step) const {
    if (warmup > 0 && step < warmup)
      return lr * static_cast<double>(step + 1) / static_cast<double>(warmup);
    if (!cosine) return lr;
    const double progress = static_cast<double>(step - warmup) /
                            static_cast<double>(std::max<int64_t>(1, steps - warmup));
    return min_lr +
           0.5 * (lr - min_lr) * (1 + std::cos(3.14159265358979323846 * std::min(1.0, progress)));
  }
};

// The examples of a step's global batch: an order of the dataset shuffled once per epoch from the
// seed, and each example's own seed (its place in the global batch), so that ranks splitting a
// batch and resumed runs see the same examples with the same draws.
class EpochOrder {
 public:
  EpochOrder(int64_t examples, int64_t batch, uint64_t seed)
      : n_(examples), batch_(batch), seed_(seed) {}

  // Dataset indices of places first, first + stride, ... of the global batch of `step`.
  std::vector<int64_t> Indices(int64_t step, int64_t first = 0, int64_t stride = 1) {
    const int64_t per_epoch = std::max<int64_t>(1, n_ / batch_);
    const int64_t epoch = step / per_epoch;
    if (epoch != epoch_) {
      order_.resize(static_cast<size_t>(n_));
      std::iota(order_.begin(), order_.end(), 0);
      std::mt19937_64 rng(MixSeed(seed_, static_cast<uint64_t>(epoch)));
      std::shuffle(order_.begin(), order_.end(), rng);
      epoch_ = epoch;
    }
    std::vector<int64_t> indices;
    const int64_t base = (step % per_epoch) * batch_;
    for (int64_t k = first; k < batch_; k += stride)
      indices.push_back(order_[static_cast<size_t>((base + k) % n_)]);
    return indices;
  }

  // The seeds of the same places (non-negative int64).
  std::vector<int64_t> ExampleSeeds(int64_t step, int64_t first = 0, int64_t stride = 1) const {
    std::vector<int64_t> seeds;
    for (int64_t k = first; k < batch_; k += stride) {
      seeds.push_back(static_cast<int64_t>(
          MixSeed(MixSeed(seed_, static_cast<uint64_t>(step)), static_cast<uint64_t>(k)) >> 1));
    }
    return seeds;
  }

  // The dataset's seed for the batch of `step` (its augmentations and compositions).
  uint64_t BatchSeed(int64_t step) const { return MixSeed(seed_, static_cast<uint64_t>(step)); }

 private:
  int64_t n_, batch_;
  uint64_t seed_;
  std::vector<int64_t> order_;
  int64_t epoch_ = -1;
};

}  // namespace motionpipe::nn
