// Transformer layers for the model plugins: the arithmetic of torch::nn::TransformerEncoderLayer
// and TransformerDecoderLayer (post-norm, GELU, sequence first), written out so that training is
// cheaper:
//  - dropout masks come from a xoshiro256+ stream seeded by torch's generator (torch's bernoulli_
//    draws a 64-bit mt19937 number per element, ~9% of a TEMOS step), same distribution;
//  - cross-attention to a memory of one token (TEMOS's decoder: memory = the latent z) is computed
//  in
//    closed form: softmax over one key is 1, so each head's output is its value projection of z,
//    scaled by the head's attention-dropout draw; no query/key projections or softmax are needed.
#pragma once

#include <torch/torch.h>

namespace motionpipe::nn {

// y = x W^T + b through ATen's linear, one addmm for a contiguous input of any rank (in autocast's
// dtype under bf16 autocast, bias included), instead of torch::nn::Linear::forward: LibTorch 1.13's
// C++ functional linear runs a matmul and then adds the bias in place in a second pass (under bf16
// autocast a float32 bias into the bf16 output, with a backward of its own). A DiT block's linears
// run 1.1-1.3 times as fast forward and backward this way (bench/mdt_bench; issue 15).
inline torch::Tensor ApplyLinear(const torch::nn::Linear& layer, const torch::Tensor& x) {
  return torch::linear(x, layer->weight, layer->bias);
}

// A Sequential's forward with ApplyLinear for its Linear modules.
torch::Tensor ApplySequential(torch::nn::Sequential layers, torch::Tensor x);

// Inverted dropout with a fast mask; identity when !training or p == 0.
torch::Tensor Dropout(const torch::Tensor& x, double p, bool training);
// The mask alone: entries 0 or 1/(1-p), float, of `sizes`.
torch::Tensor DropoutMask(at::IntArrayRef sizes, double p);

struct TransformerOptions {
  int64_t dim = 256, heads = 4, ff = 1024, layers = 2;
  double dropout = 0.1;
};

// Multi-head self-attention's core through ATen (the heads taken apart, baddbmm, softmax, bmm,
// the heads put back), the route for bf16 autocast and the reference for nn::SelfAttentionFloat32
// (fused.h), whose arguments it takes: qkv [L, N, 3 H Dh], padding [N, L] bool or undefined,
// dropout_mask [N H, L, L] or undefined; returns [L, N, H Dh].
torch::Tensor SelfAttentionThroughAten(const torch::Tensor& qkv, int64_t heads,
                                       const torch::Tensor& padding,
                                       const torch::Tensor& dropout_mask);

class SelfAttentionImpl : public torch::nn::Module {
 public:
  SelfAttentionImpl(int64_t dim, int64_t heads, double dropout);
  // x [L, N, dim], padding [N, L] (true = ignore that key) or undefined.
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& padding);

 private:
  int64_t heads_;
  double dropout_;
  torch::nn::Linear in_proj_{nullptr}, out_proj_{nullptr};
};
TORCH_MODULE(SelfAttention);

class EncoderLayerImpl : public torch::nn::Module {
 public:
  explicit EncoderLayerImpl(const TransformerOptions& o);
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& padding);

 private:
  TransformerOptions o_;
  SelfAttention attention_{nullptr};
  torch::nn::Linear linear1_{nullptr}, linear2_{nullptr};
  torch::nn::LayerNorm norm1_{nullptr}, norm2_{nullptr};
};
TORCH_MODULE(EncoderLayer);

class EncoderImpl : public torch::nn::Module {
 public:
  explicit EncoderImpl(const TransformerOptions& o);
  torch::Tensor forward(torch::Tensor x, const torch::Tensor& padding);

 private:
  torch::nn::ModuleList layers_;
};
TORCH_MODULE(Encoder);

// A decoder layer whose memory is one token per example: self-attention over the queries, the
// closed-form cross-attention to the memory, feed-forward.
class OneTokenDecoderLayerImpl : public torch::nn::Module {
 public:
  explicit OneTokenDecoderLayerImpl(const TransformerOptions& o);
  // x [T, N, dim], memory [N, dim], padding [N, T].
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& memory,
                        const torch::Tensor& padding);

 private:
  TransformerOptions o_;
  SelfAttention attention_{nullptr};
  torch::nn::Linear value_{nullptr},
      out_proj_{nullptr};  // cross-attention: value and output projections
  torch::nn::Linear linear1_{nullptr}, linear2_{nullptr};
  torch::nn::LayerNorm norm1_{nullptr}, norm2_{nullptr}, norm3_{nullptr};
};
TORCH_MODULE(OneTokenDecoderLayer);

class OneTokenDecoderImpl : public torch::nn::Module {
 public:
  explicit OneTokenDecoderImpl(const TransformerOptions& o);
  // modulation [layers, N, 2 * dim] (optional, FiLM): before layer k the queries become
  // x * (1 + scale_k) + shift_k, with [scale_k; shift_k] = modulation[k].
  torch::Tensor forward(torch::Tensor x, const torch::Tensor& memory, const torch::Tensor& padding,
                        const torch::Tensor& modulation = {});

 private:
  torch::nn::ModuleList layers_;
};
TORCH_MODULE(OneTokenDecoder);

}  // namespace motionpipe::nn
