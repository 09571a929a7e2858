#include "transformer.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "fused.h"

namespace motionpipe::nn {

namespace {

uint64_t Rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

uint64_t SplitMix(uint64_t& state) {
  uint64_t z = (state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

}  // namespace

torch::Tensor DropoutMask(at::IntArrayRef sizes, double p) {
  auto mask = torch::empty(sizes, torch::kFloat32);
  // The stream's seed comes from torch's generator, so torch::manual_seed makes masks repeatable.
  uint64_t seed = static_cast<uint64_t>(
      torch::randint(std::numeric_limits<int64_t>::max(), {1}, torch::kInt64).item<int64_t>());
  uint64_t s[4];
  for (auto& word : s) word = SplitMix(seed);
  const float keep_value = static_cast<float>(1.0 / (1.0 - p));
  const auto threshold = static_cast<uint32_t>(std::min(4294967295.0, p * 4294967296.0));
  float* out = mask.data_ptr<float>();
  const int64_t n = mask.numel();
  int64_t i = 0;
  for (; i + 1 < n; i += 2) {  // xoshiro256+: two 32-bit uniforms per draw
    const uint64_t r = s[0] + s[3];
    const uint64_t t = s[1] << 17;
    s[2] ^= s[0], s[3] ^= s[1], s[1] ^= s[2], s[0] ^= s[3], s[2] ^= t, s[3] = Rotl(s[3], 45);
    out[i] = static_cast<uint32_t>(r >> 32) >= threshold ? keep_value : 0.0f;
    out[i + 1] = static_cast<uint32_t>(r) >= threshold ? keep_value : 0.0f;
  }
  if (i < n) out[i] = static_cast<uint32_t>((s[0] + s[3]) >> 32) >= threshold ? keep_value : 0.0f;
  return mask;
}

torch::Tensor Dropout(const torch::Tensor& x, double p, bool training) {
  if (!training || p <= 0) return x;
  return x * DropoutMask(x.sizes(), p);
}

torch::Tensor ApplySequential(torch::nn::Sequential layers, torch::Tensor x) {
  for (auto& module : *layers) {
    if (const auto* linear = dynamic_cast<const torch::nn::LinearImpl*>(module.ptr().get()))
      x = torch::linear(x, linear->weight, linear->bias);
    else
      x = module.forward(x);
  }
  return x;
}

SelfAttentionImpl::SelfAttentionImpl(int64_t dim, int64_t heads, double dropout)
    : heads_(heads), dropout_(dropout) {
  if (dim % heads != 0)
    throw std::invalid_argument("attention: dim " + std::to_string(dim) +
                                " is not divisible by heads " + std::to_string(heads));
  in_proj_ = register_module("in_proj", torch::nn::Linear(dim, 3 * dim));
  out_proj_ = register_module("out_proj", torch::nn::Linear(dim, dim));
  // torch::nn::MultiheadAttention's initialisation: Xavier-uniform input projection, zero biases.
  torch::NoGradGuard no_grad;
  torch::nn::init::xavier_uniform_(in_proj_->weight);
  in_proj_->bias.zero_();
  out_proj_->bias.zero_();
}

torch::Tensor SelfAttentionImpl::forward(const torch::Tensor& x, const torch::Tensor& padding) {
  const int64_t length = x.size(0);
  const auto qkv = ApplyLinear(in_proj_, x);  // [L, N, 3 dim]
  // The dropout mask is drawn before either route, so a seed gives the same masks in both.
  const auto mask = is_training() && dropout_ > 0
                        ? DropoutMask({x.size(1) * heads_, length, length}, dropout_)
                        : torch::Tensor();
  // float32: the same arithmetic in one pass per matrix (plugins/common/fused.h); under bf16
  // autocast qkv is bf16 and ATen's bmm takes it.
  const auto out = qkv.scalar_type() == torch::kFloat
                       ? SelfAttentionFloat32(qkv, heads_, padding, mask)
                       : SelfAttentionThroughAten(qkv, heads_, padding, mask);
  return ApplyLinear(out_proj_, out);
}

torch::Tensor SelfAttentionThroughAten(const torch::Tensor& qkv, int64_t heads,
                                       const torch::Tensor& padding,
                                       const torch::Tensor& dropout_mask) {
  const int64_t length = qkv.size(0), n = qkv.size(1), dim = qkv.size(2) / 3,
                head_dim = dim / heads;
  // [L, N, 3, H, Dh] -> q, k, v as [N*H, L, Dh]
  const auto split = qkv.view({length, n, 3, heads, head_dim})
                         .permute({2, 1, 3, 0, 4})
                         .reshape({3, n * heads, length, head_dim});
  // unbind, not split[0], split[1], split[2]: indexing's backward writes each gradient into a
  // zero-filled copy of the whole [3, N*H, L, Dh] and sums the three; unbind's stacks them once.
  const auto parts = split.unbind(0);
  const auto q = parts[0] * (1.0 / std::sqrt(static_cast<double>(head_dim)));
  const auto& k = parts[1];
  const auto& v = parts[2];
  torch::Tensor scores;
  if (padding.defined()) {
    // A large negative bias on ignored keys (finite: a row with every key ignored stays finite),
    // per example, broadcast over heads and queries.
    const auto bias = torch::zeros({n, 1, 1, length}, q.options())
                          .masked_fill(padding.view({n, 1, 1, length}), -1e9)
                          .expand({n, heads, 1, length})
                          .reshape({n * heads, 1, length});
    scores = torch::baddbmm(bias, q, k.transpose(1, 2));
  } else {
    scores = torch::bmm(q, k.transpose(1, 2));
  }
  auto weights = torch::softmax(scores, -1);
  if (dropout_mask.defined()) weights = weights * dropout_mask;  // float32 mask: as before
  return torch::bmm(weights, v)
      .view({n, heads, length, head_dim})
      .permute({2, 0, 1, 3})
      .reshape({length, n, dim});
}

EncoderLayerImpl::EncoderLayerImpl(const TransformerOptions& o) : o_(o) {
  attention_ = register_module("self_attn", SelfAttention(o.dim, o.heads, o.dropout));
  linear1_ = register_module("linear1", torch::nn::Linear(o.dim, o.ff));
  linear2_ = register_module("linear2", torch::nn::Linear(o.ff, o.dim));
  norm1_ = register_module("norm1", torch::nn::LayerNorm(torch::nn::LayerNormOptions({o.dim})));
  norm2_ = register_module("norm2", torch::nn::LayerNorm(torch::nn::LayerNormOptions({o.dim})));
}

torch::Tensor EncoderLayerImpl::forward(const torch::Tensor& x, const torch::Tensor& padding) {
  const bool train = is_training();
  auto h = norm1_->forward(x + Dropout(attention_->forward(x, padding), o_.dropout, train));
  const auto ff =
      ApplyLinear(linear2_, Dropout(torch::gelu(ApplyLinear(linear1_, h)), o_.dropout, train));
  return norm2_->forward(h + Dropout(ff, o_.dropout, train));
}

EncoderImpl::EncoderImpl(const TransformerOptions& o) {
  layers_ = register_module("layers", torch::nn::ModuleList());
  for (int64_t k = 0; k < o.layers; ++k) layers_->push_back(EncoderLayer(o));
}

torch::Tensor EncoderImpl::forward(torch::Tensor x, const torch::Tensor& padding) {
  for (const auto& layer : *layers_) x = layer->as<EncoderLayer>()->forward(x, padding);
  return x;
}

OneTokenDecoderLayerImpl::OneTokenDecoderLayerImpl(const TransformerOptions& o) : o_(o) {
  attention_ = register_module("self_attn", SelfAttention(o.dim, o.heads, o.dropout));
  value_ = register_module("cross_value", torch::nn::Linear(o.dim, o.dim));
  out_proj_ = register_module("cross_out_proj", torch::nn::Linear(o.dim, o.dim));
  linear1_ = register_module("linear1", torch::nn::Linear(o.dim, o.ff));
  linear2_ = register_module("linear2", torch::nn::Linear(o.ff, o.dim));
  norm1_ = register_module("norm1", torch::nn::LayerNorm(torch::nn::LayerNormOptions({o.dim})));
  norm2_ = register_module("norm2", torch::nn::LayerNorm(torch::nn::LayerNormOptions({o.dim})));
  norm3_ = register_module("norm3", torch::nn::LayerNorm(torch::nn::LayerNormOptions({o.dim})));
  // As the value third of MultiheadAttention's Xavier-uniform in_proj (fan-out 3*dim), zero biases.
  torch::NoGradGuard no_grad;
  const double bound = std::sqrt(6.0 / static_cast<double>(o.dim + 3 * o.dim));
  value_->weight.uniform_(-bound, bound);
  value_->bias.zero_();
  out_proj_->bias.zero_();
}

torch::Tensor OneTokenDecoderLayerImpl::forward(const torch::Tensor& x, const torch::Tensor& memory,
                                                const torch::Tensor& padding) {
  const bool train = is_training();
  const int64_t length = x.size(0), n = x.size(1), heads = o_.heads, head_dim = o_.dim / o_.heads;
  auto h = norm1_->forward(x + Dropout(attention_->forward(x, padding), o_.dropout, train));
  // Cross-attention to one memory token: head h's output is w[t,n,h] * v[n,h] with w = dropout(1).
  const auto v = ApplyLinear(value_, memory);  // [N, dim]
  torch::Tensor cross;
  if (train && o_.dropout > 0) {
    // out_proj applied per head: u[n,h,:] = W_o[:, h] v[n,h]; then sum_h w[t,n,h] u[n,h,:] + b.
    const auto w_o = out_proj_->weight.view({o_.dim, heads, head_dim});
    const auto u =
        torch::einsum("nhk,dhk->nhd", {v.view({n, heads, head_dim}), w_o});  // [N, H, dim]
    const auto w = DropoutMask({n, length, heads}, o_.dropout);              // [N, T, H]
    cross = torch::bmm(w, u).transpose(0, 1) + out_proj_->bias;              // [T, N, dim]
  } else {
    cross = ApplyLinear(out_proj_, v).unsqueeze(0).expand({length, n, o_.dim});
  }
  h = norm2_->forward(h + Dropout(cross, o_.dropout, train));
  const auto ff =
      ApplyLinear(linear2_, Dropout(torch::gelu(ApplyLinear(linear1_, h)), o_.dropout, train));
  return norm3_->forward(h + Dropout(ff, o_.dropout, train));
}

OneTokenDecoderImpl::OneTokenDecoderImpl(const TransformerOptions& o) {
  layers_ = register_module("layers", torch::nn::ModuleList());
  for (int64_t k = 0; k < o.layers; ++k) layers_->push_back(OneTokenDecoderLayer(o));
}

torch::Tensor OneTokenDecoderImpl::forward(torch::Tensor x, const torch::Tensor& memory,
                                           const torch::Tensor& padding,
                                           const torch::Tensor& modulation) {
  if (modulation.defined() && modulation.size(0) != static_cast<int64_t>(layers_->size()))
    throw std::invalid_argument("OneTokenDecoder: modulation needs one row per layer");
  int64_t k = 0;
  for (const auto& layer : *layers_) {
    if (modulation.defined()) {
      const auto scale_shift = modulation[k++].chunk(2, -1);  // [N, dim] each
      x = x * (1 + scale_shift[0]) + scale_shift[1];
    }
    x = layer->as<OneTokenDecoderLayer>()->forward(x, memory, padding);
  }
  return x;
}

}  // namespace motionpipe::nn
