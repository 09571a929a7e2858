// Counting a training step's matrix products and the machine's sgemm rate, for the benchmarks that
// give a step's achieved GFLOP/s beside the peak measured in the same run (issue 15: goal 60% at
// paper size).
#pragma once

#include <torch/torch.h>

#include <cstdint>

#include "bench_util.h"

namespace motionpipe::bench {

// Multiply-adds of one transformer layer over a batch of `n` sequences of `length` tokens: the
// four d x d projections and the two feed-forward matrices per token, and QK^T and AV per sequence.
inline double LayerMacs(double n, double length, double dim, double ff) {
  return n * (length * (4 * dim * dim + 2 * dim * ff) + 2 * length * length * dim);
}

// The machine's sgemm rate through LibTorch on the current threads: products of a long token axis
// (4,096 rows) by `dim` x 2 `dim`, the shape of a step's largest products, for about a second.
inline double SgemmGflops(int64_t dim) {
  const auto a = torch::randn({4096, dim}), b = torch::randn({dim, dim * 2});
  for (int k = 0; k < 3; ++k) (void)torch::mm(a, b);
  int64_t reps = 0;
  const auto started = Clock::now();
  while (Since(started) < 1.0) {
    (void)torch::mm(a, b);
    ++reps;
  }
  return 2.0 * 4096 * static_cast<double>(dim) * static_cast<double>(dim * 2) *
         static_cast<double>(reps) / Since(started) / 1e9;
}

}  // namespace motionpipe::bench
