// Fused CPU kernels for the hot spots of a small model's training step, each one pass over memory
// where LibTorch 1.13 makes several (issue 15: the claims runs must fit one sitting).
//  - GeluTanhBf16: DiT's tanh-GELU for bf16 activations under autocast, computed in float32 per
//    element and rounded to bf16 once, forward and backward, in one vectorised loop each.
//    LibTorch's own path (widen, float32 kernel, round) makes three passes and three temporaries
//    each way. GeluTanhFloat32: the same loops for float32 activations.
//  - ModulatedLayerNormBf16 and GatedResidualBf16: DiT's adaLN-Zero around each sub-layer
//    (LN(x) (1 + scale) + shift before it, x + gate y after it) for a float32 residual stream and
//    bf16 modulation under autocast, forward and backward in one pass each. LibTorch's route makes
//    a pass per operator (LayerNorm, add, mul, add, the cast to bf16 for the next linear), and in
//    backward as many again plus the sums over frames for the modulation's gradients.
//    ModulatedLayerNormFloat32 and GatedResidualFloat32: the same passes where the modulation and
//    the branch are float32 (a float32 step: a CPU without bf16 products).
//  - SelfAttentionFloat32: multi-head attention's core (scores, key mask, softmax, dropout,
//    weighted values) in float32, forward and backward, per (example, head) matrix in one pass
//    through cache-resident buffers with a register-tiled GEMM, reading q, k, v from in_proj's
//    output and writing the heads side by side for out_proj where they lie. LibTorch 1.13 built
//    without MKL runs its bmm as per-matrix GEMM calls through tensor views, the softmax, mask and
//    dropout as passes of their own, and the heads' split and merge as strided copies: where the
//    trainers run float32 (a CPU without bf16 products) that was about a quarter of an editor's
//    step (bench/mdt_bench's attention row).
//  - AdamWStep: gradient clipping by the global norm and torch::optim::AdamW's step in one pass per
//    parameter over (p, grad, exp_avg, exp_avg_sq), on the optimiser's own state, so checkpoints
//    stay torch::optim::AdamW's.
#pragma once

#include <torch/torch.h>

namespace motionpipe::nn {

// tanh-GELU, 0.5 x (1 + tanh(sqrt(2/pi) (x + 0.044715 x^3))), of a bf16 tensor: the float32
// function rounded to bf16 once (within one bf16 rounding of the exact values; LibTorch's float32
// kernel gives the same bf16 values but where its tanh rounds to -1 in the far negative tail), with
// its gradient. Other dtypes are an error (std::invalid_argument; use torch::gelu).
torch::Tensor GeluTanhBf16(const torch::Tensor& x);

// The same tanh-GELU of a float32 tensor, the same arithmetic in float32 without the rounding:
// within a few float32 roundings of torch::gelu(x, "tanh"), at less than half its time here
// (bench/mdt_bench's float32 GELU row: 2.5 ms against 5.5 for [2592 x 256] forward and backward),
// with its gradient. Other dtypes are an error (std::invalid_argument).
torch::Tensor GeluTanhFloat32(const torch::Tensor& x);

// adaLN's modulated LayerNorm (Peebles and Xie 2023, DiT eq. of adaLN-Zero): y = LN(x) (1 + scale)
// + shift over the last dimension, LN without affine parameters, with variance eps added. x is
// [T, N, d] float32; scale and shift are [N, d] or [1, N, d] bf16, the same for every t. y is bf16:
// the float32 expression rounded once (the linear after it under bf16 autocast would round it so),
// within one bf16 rounding of the exact values. Its gradient reaches x (float32), scale and shift
// (bf16; summed over t in float32, then rounded). Other dtypes or shapes are an error
// (std::invalid_argument).
torch::Tensor ModulatedLayerNormBf16(const torch::Tensor& x, const torch::Tensor& scale,
                                     const torch::Tensor& shift, double eps);

// adaLN-Zero's gated residual: h = x + gate y, x [T, N, d] float32, gate [N, d] or [1, N, d] bf16
// (the same for every t), y [T, N, d] bf16; h float32, the product not rounded to bf16 before the
// sum. Its gradient reaches x (float32), gate (bf16; summed over t in float32) and y (bf16). Other
// dtypes or shapes are an error (std::invalid_argument).
torch::Tensor GatedResidualBf16(const torch::Tensor& x, const torch::Tensor& gate,
                                const torch::Tensor& y);

// ModulatedLayerNormBf16's pass for float32 scale, shift and output (nothing rounded; the sums over
// t of the modulation's gradients in float32, as LibTorch's route makes them); the same values as
// LibTorch's LayerNorm, mul and add to float32 rounding. Other dtypes or shapes are an error
// (std::invalid_argument).
torch::Tensor ModulatedLayerNormFloat32(const torch::Tensor& x, const torch::Tensor& scale,
                                        const torch::Tensor& shift, double eps);

// GatedResidualBf16's pass for float32 gate and y: h = x + gate y, its gradient to x, gate (summed
// over t) and y, all float32. Other dtypes or shapes are an error (std::invalid_argument).
torch::Tensor GatedResidualFloat32(const torch::Tensor& x, const torch::Tensor& gate,
                                   const torch::Tensor& y);

// Multi-head self-attention's core, softmax(q k^T / sqrt(Dh) + mask) v per (example, head), on
// in_proj's output as it is: qkv [L, N, 3 H Dh] float32 (each token's q, k, v, each of H heads of
// Dh); returns [L, N, H Dh], the heads side by side as out_proj takes them. padding [N, L] bool
// (true: that key is ignored for every query and head of example n; undefined: none), a row whose
// every key is ignored attends to all equally. dropout_mask [N H, L, L] float32 (matrix n H + h;
// entries 0 or 1/(1-p), as nn::DropoutMask; undefined: none) multiplies the weights after the
// softmax. The gradient reaches qkv. The same float32 values as SelfAttentionThroughAten
// (transformer.h) computes by ATen, but for the order of the sums in the products. Other dtypes or
// shapes are an error (std::invalid_argument).
torch::Tensor SelfAttentionFloat32(const torch::Tensor& qkv, int64_t heads,
                                   const torch::Tensor& padding, const torch::Tensor& dropout_mask);

// One optimiser step of `optimizer` (a torch::optim::AdamW without amsgrad) at its groups' current
// options: when max_norm > 0 the gradients are first scaled as torch::nn::utils::clip_grad_norm_
// scales them (by max_norm / (norm + 1e-6) when that is below 1; the gradients themselves are not
// written). The same arithmetic as AdamW::step (LibTorch 1.13), state created as it creates it.
// Returns the gradients' global 2-norm before clipping. Parameters and gradients must be
// contiguous float32 (std::invalid_argument otherwise).
double AdamWStep(torch::optim::AdamW& optimizer, double max_norm);

}  // namespace motionpipe::nn
