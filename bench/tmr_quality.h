// Time to a retrieval quality (issue 15): the minutes of training until the demo's TMR evaluator
// retrieves the test split's single actions from their texts at R@1 `bar` (text-to-motion, in
// batches of 32), for our trainer and for the PyTorch-Python reference
// (bench/reference/tmr_ref.py) trained the same way: the same corpus, initial weights, batches
// (the train stage's order, crops, texts, token ids, near-duplicate masks, reparameterisation
// noise), learning-rate schedule, clipping and AdamW; only the dropout masks differ. Both sets of
// test embeddings are scored by the evaluation's eval::Retrieval.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace motionpipe::bench {

// A TEMOS/TMR size: the demo's (configs/demo.yaml's evaluator) and the paper's (TEMOS and TMR:
// latent 256, 6 layers, 4 heads, feed-forward 1024), with our learned text encoder's layers.
struct TemosSize {
  std::string name;
  int64_t latent, layers, heads, ff, text_layers;
};

inline const std::vector<TemosSize>& TemosSizes() {
  static const std::vector<TemosSize> sizes = {{"demo", 128, 2, 4, 512, 1},
                                               {"paper", 256, 6, 4, 1024, 2}};
  return sizes;
}

struct QualityArgs {
  std::string spans;  // a `singles` stage's spans.npz; empty: made by the demo's corpus + singles
  std::string size = "demo";  // a TemosSizes() name; every other setting is the demo evaluator's
  int64_t steps = 400, every = 50, threads = 1;
  uint64_t seed = 101;  // the training's (initial weights, batch order, draws): the demo's
  double bar = 40;
  bool bf16 = false;  // both trainers' forward passes under bf16 autocast (where the CPU has bf16
                      // products; elsewhere float32, as the train stage runs it)
  bool reference = true;
  std::string dir = "/tmp/motionpipe_tmr_quality";
};

void BenchTimeToQuality(const QualityArgs& args);

}  // namespace motionpipe::bench
