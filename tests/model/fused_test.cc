// The fused kernels of plugins/common/fused.h against LibTorch's own operators on the same inputs.
#include "../../plugins/common/fused.h"

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <functional>
#include <limits>
#include <sstream>

#include "../../plugins/common/transformer.h"

namespace motionpipe::nn {
namespace {

// One bf16 unit in the last place at v (8 significant bits).
torch::Tensor Bf16Ulp(const torch::Tensor& v) {
  return torch::pow(2.0, torch::floor(torch::log2(v.abs().clamp_min(1e-30))) - 7);
}

// tanh-GELU in float64 written as x sigmoid(2u) = 0.5 x (1 + tanh u), which keeps its relative
// precision in the negative tail (where 1 + tanh u cancels), and its derivative
// sigmoid(2u) + 2 x sigmoid(2u) (1 - sigmoid(2u)) du/dx.
torch::Tensor ExactGelu(const torch::Tensor& x) {
  const auto u = std::sqrt(2 / M_PI) * (x + 0.044715 * x.pow(3));
  return x * torch::sigmoid(2 * u);
}
torch::Tensor ExactGeluDerivative(const torch::Tensor& x) {
  const auto s = torch::sigmoid(2 * std::sqrt(2 / M_PI) * (x + 0.044715 * x.pow(3)));
  return s + 2 * x * s * (1 - s) * std::sqrt(2 / M_PI) * (1 + 3 * 0.044715 * x.pow(2));
}

// tanh-GELU of a bf16 tensor: the float32 function rounded once. Against LibTorch's float32 kernel
// rounded to bf16 (what mdt::GeluTanh computed before): equal but for a few roundings where
// |x| < 4, within one bf16 rounding of the float64 values everywhere (LibTorch's is not in the far
// negative tail: tanh rounds to -1 there and the result to 0), and no farther from them on
// average; the gradient as near the float64 derivative as the float32 kernel's, rounded.
TEST(Fused, GeluTanhBf16IsTheFloat32FunctionRoundedOnce) {
  torch::manual_seed(11);
  // Not a multiple of any vector width; more than one task of the intra-op pool.
  const auto x = (3 * torch::randn({100003})).to(torch::kBFloat16).requires_grad_();
  const auto y = GeluTanhBf16(x);
  ASSERT_EQ(y.scalar_type(), torch::kBFloat16);
  const auto reference = torch::gelu(x.detach().to(torch::kFloat), "tanh").to(torch::kBFloat16);
  const auto x64 = x.detach().to(torch::kFloat64);
  const auto exact = ExactGelu(x64);
  const auto inner = x64.abs().lt(4);
  const auto differ = y.ne(reference).logical_and(inner);
  EXPECT_LT(differ.sum().item<double>(), 0.01 * inner.sum().item<double>());
  const auto gap = (y.to(torch::kFloat64) - exact).abs();
  EXPECT_TRUE(gap.le(Bf16Ulp(exact) * 1.01 + 1e-30).all().item<bool>());
  const auto error = [&](const torch::Tensor& v) {
    return (v.to(torch::kFloat64) - exact).abs().mean().item<double>();
  };
  EXPECT_LE(error(y.detach()), error(reference) * 1.01);

  const auto dy = torch::randn({100003}).to(torch::kBFloat16);
  const auto dx = torch::autograd::grad({y}, {x}, {dy})[0];
  ASSERT_EQ(dx.scalar_type(), torch::kBFloat16);
  const auto x32 = x.detach().to(torch::kFloat).requires_grad_();
  const auto dx32 =
      torch::autograd::grad({torch::gelu(x32, "tanh")}, {x32}, {dy.to(torch::kFloat)})[0].to(
          torch::kBFloat16);
  const auto dx64 = dy.to(torch::kFloat64) * ExactGeluDerivative(x64);
  const auto grad_error = [&](const torch::Tensor& v) {
    return (v.to(torch::kFloat64) - dx64).abs().mean().item<double>();
  };
  EXPECT_LE(grad_error(dx), grad_error(dx32) * 1.01);
  // Where the derivative crosses 0 (x near -0.75) float32's absolute rounding shows: allow it.
  const auto slack = 1e-6 * dy.to(torch::kFloat64).abs();
  EXPECT_TRUE(
      (dx.to(torch::kFloat64) - dx64).abs().le(Bf16Ulp(dx64) * 1.01 + slack).all().item<bool>());
}

TEST(Fused, GeluTanhBf16KeepsTheEdgesOfItsDomain) {
  const float inf = std::numeric_limits<float>::infinity();
  const auto x = torch::tensor({0.0f, 200.0f, -200.0f, inf, std::nanf("")}).to(torch::kBFloat16);
  const auto y = GeluTanhBf16(x).to(torch::kFloat);
  EXPECT_EQ(y[0].item<float>(), 0.0f);
  EXPECT_EQ(y[1].item<float>(), 200.0f);
  EXPECT_LE(std::abs(y[2].item<float>()), 1e-30f);
  EXPECT_EQ(y[3].item<float>(), inf);
  EXPECT_TRUE(std::isnan(y[4].item<float>()));
  EXPECT_THROW(GeluTanhBf16(torch::ones({3})), std::invalid_argument);
}

// tanh-GELU of a float32 tensor: within a few float32 roundings of the float64 function and of
// LibTorch's float32 kernel, no farther from float64 on average than LibTorch's; the gradient as
// near the float64 derivative as LibTorch's float32 one; the edges of the domain kept.
TEST(Fused, GeluTanhFloat32IsTheFunction) {
  torch::manual_seed(12);
  const auto x = (3 * torch::randn({100003})).requires_grad_();
  const auto y = GeluTanhFloat32(x);
  ASSERT_EQ(y.scalar_type(), torch::kFloat);
  const auto x64 = x.detach().to(torch::kFloat64);
  const auto exact = ExactGelu(x64);
  const auto reference = torch::gelu(x.detach(), "tanh");
  // Relative to the value, with an absolute floor of 1e-6 of the input's scale (GELU passes
  // through 0, and its far negative tail is tiny).
  const auto bound = 8 * 1.2e-7 * exact.abs() + 1e-6 * x64.abs();
  EXPECT_TRUE((y.detach().to(torch::kFloat64) - exact).abs().le(bound).all().item<bool>());
  EXPECT_TRUE((reference.to(torch::kFloat64) - exact).abs().le(bound).all().item<bool>());
  const auto error = [&](const torch::Tensor& v) {
    return (v.to(torch::kFloat64) - exact).abs().mean().item<double>();
  };
  EXPECT_LE(error(y.detach()), error(reference) * 1.5);

  const auto dy = torch::randn({100003});
  const auto dx = torch::autograd::grad({y}, {x}, {dy})[0];
  const auto x32 = x.detach().requires_grad_();
  const auto dx32 = torch::autograd::grad({torch::gelu(x32, "tanh")}, {x32}, {dy})[0];
  const auto dx64 = dy.to(torch::kFloat64) * ExactGeluDerivative(x64);
  const auto grad_error = [&](const torch::Tensor& v) {
    return (v.to(torch::kFloat64) - dx64).abs().mean().item<double>();
  };
  EXPECT_LE(grad_error(dx), grad_error(dx32) * 1.5);
  EXPECT_LT((dx.to(torch::kFloat64) - dx64).abs().max().item<double>(),
            1e-5 * dy.abs().max().item<double>());

  const float inf = std::numeric_limits<float>::infinity();
  const auto edges = GeluTanhFloat32(torch::tensor({0.0f, 200.0f, -200.0f, inf, std::nanf("")}));
  EXPECT_EQ(edges[0].item<float>(), 0.0f);
  EXPECT_EQ(edges[1].item<float>(), 200.0f);
  EXPECT_LE(std::abs(edges[2].item<float>()), 1e-30f);
  EXPECT_EQ(edges[3].item<float>(), inf);
  EXPECT_TRUE(std::isnan(edges[4].item<float>()));
  EXPECT_THROW(GeluTanhFloat32(torch::ones({3}, torch::kBFloat16)), std::invalid_argument);
}

// adaLN's modulated LayerNorm against the float64 expression LN(x) (1 + scale) + shift: the output
// within one bf16 rounding (plus the float32 moments' rounding), the gradients to x as float32's
// precision allows, to scale and shift (sums over t) within one bf16 rounding; on a stream far
// from centred (the moments must be taken from the centred values), shapes that are no multiple of
// a vector width and more than one task of the intra-op pool.
TEST(Fused, ModulatedLayerNormBf16IsTheFloat32ExpressionRoundedOnce) {
  torch::manual_seed(12);
  const int64_t t = 9, n = 33, d = 129;
  const auto x = (3 + 2 * torch::randn({t, n, d})).requires_grad_();
  const auto scale = (0.5 * torch::randn({1, n, d})).to(torch::kBFloat16).requires_grad_();
  const auto shift = (0.5 * torch::randn({1, n, d})).to(torch::kBFloat16).requires_grad_();
  const auto y = ModulatedLayerNormBf16(x, scale, shift, 1e-6);
  ASSERT_EQ(y.scalar_type(), torch::kBFloat16);
  ASSERT_EQ(y.sizes(), x.sizes());

  const auto x64 = x.detach().to(torch::kFloat64).requires_grad_();
  const auto s64 = scale.detach().to(torch::kFloat64).requires_grad_();
  const auto b64 = shift.detach().to(torch::kFloat64).requires_grad_();
  const auto exact = torch::layer_norm(x64, {d}, {}, {}, 1e-6) * (1 + s64) + b64;
  const auto gap = (y.to(torch::kFloat64) - exact.detach()).abs();
  EXPECT_TRUE(gap.le(Bf16Ulp(exact.detach()) * 1.01 + 1e-5).all().item<bool>());

  const auto dy = torch::randn({t, n, d}).to(torch::kBFloat16);
  const auto grads = torch::autograd::grad({y}, {x, scale, shift}, {dy});
  ASSERT_EQ(grads[0].scalar_type(), torch::kFloat32);
  ASSERT_EQ(grads[1].scalar_type(), torch::kBFloat16);
  ASSERT_EQ(grads[1].sizes(), scale.sizes());
  ASSERT_EQ(grads[2].sizes(), shift.sizes());
  const auto exact_grads =
      torch::autograd::grad({exact}, {x64, s64, b64}, {dy.to(torch::kFloat64)});
  const double dx_scale = exact_grads[0].abs().max().item<double>();
  EXPECT_LT((grads[0].to(torch::kFloat64) - exact_grads[0]).abs().max().item<double>(),
            1e-5 * dx_scale);
  for (int k = 1; k < 3; ++k) {
    const auto want = exact_grads[k];
    const auto got = grads[k].to(torch::kFloat64);
    EXPECT_TRUE((got - want).abs().le(Bf16Ulp(want) * 1.01 + 1e-4).all().item<bool>()) << k;
  }
  // [N, d] modulation is the same as [1, N, d].
  EXPECT_TRUE(torch::equal(
      y, ModulatedLayerNormBf16(x.detach(), scale.detach()[0], shift.detach()[0], 1e-6)));
  // What it refuses, by name.
  EXPECT_THROW(
      ModulatedLayerNormBf16(x.detach(), scale.detach().to(torch::kFloat), shift.detach(), 1e-6),
      std::invalid_argument);
  EXPECT_THROW(
      ModulatedLayerNormBf16(x.detach().to(torch::kBFloat16), scale.detach(), shift.detach(), 1e-6),
      std::invalid_argument);
  EXPECT_THROW(
      ModulatedLayerNormBf16(x.detach(), scale.detach().narrow(2, 0, d - 1), shift.detach(), 1e-6),
      std::invalid_argument);
}

// adaLN-Zero's gated residual x + gate y against float64: h to float32's rounding (the product is
// not rounded to bf16 first), dx = dh, dgate (a sum over t) and dy within one bf16 rounding.
TEST(Fused, GatedResidualBf16IsTheFloat32Expression) {
  torch::manual_seed(13);
  const int64_t t = 9, n = 33, d = 129;
  const auto x = torch::randn({t, n, d}).requires_grad_();
  const auto gate = torch::randn({1, n, d}).to(torch::kBFloat16).requires_grad_();
  const auto y = torch::randn({t, n, d}).to(torch::kBFloat16).requires_grad_();
  const auto h = GatedResidualBf16(x, gate, y);
  ASSERT_EQ(h.scalar_type(), torch::kFloat32);
  const auto x64 = x.detach().to(torch::kFloat64).requires_grad_();
  const auto g64 = gate.detach().to(torch::kFloat64).requires_grad_();
  const auto y64 = y.detach().to(torch::kFloat64).requires_grad_();
  const auto exact = x64 + g64 * y64;
  EXPECT_LT((h.to(torch::kFloat64) - exact.detach()).abs().max().item<double>(),
            1e-6 * exact.detach().abs().max().item<double>());

  const auto dh = torch::randn({t, n, d});
  const auto grads = torch::autograd::grad({h}, {x, gate, y}, {dh});
  const auto exact_grads =
      torch::autograd::grad({exact}, {x64, g64, y64}, {dh.to(torch::kFloat64)});
  EXPECT_TRUE(torch::equal(grads[0], dh));
  ASSERT_EQ(grads[1].scalar_type(), torch::kBFloat16);
  ASSERT_EQ(grads[1].sizes(), gate.sizes());
  ASSERT_EQ(grads[2].scalar_type(), torch::kBFloat16);
  for (int k = 1; k < 3; ++k) {
    const auto want = exact_grads[k];
    const auto got = grads[k].to(torch::kFloat64);
    EXPECT_TRUE((got - want).abs().le(Bf16Ulp(want) * 1.01 + 1e-4).all().item<bool>()) << k;
  }
  EXPECT_THROW(GatedResidualBf16(x.detach(), gate.detach(), y.detach().to(torch::kFloat)),
               std::invalid_argument);
  EXPECT_THROW(GatedResidualBf16(x.detach(), gate.detach(), y.detach().narrow(0, 0, t - 1)),
               std::invalid_argument);
}

// The float32 adaLN kernels against float64 and LibTorch's float32 route, forward and backward, on
// the shapes of the bf16 tests: the output, dx and the modulation's gradients (sums over t) within
// a few float32 roundings of the float64 values and no farther from them than LibTorch's; the
// [N, d] operand the same as [1, N, d]; other dtypes refused by name.
TEST(Fused, AdaLnFloat32KernelsAreTheExpressionsInFloat32) {
  torch::manual_seed(14);
  const int64_t t = 9, n = 33, d = 129;
  const auto x = (3 + 2 * torch::randn({t, n, d})).requires_grad_();
  const auto scale = (0.5 * torch::randn({1, n, d})).requires_grad_();
  const auto shift = (0.5 * torch::randn({1, n, d})).requires_grad_();
  const auto dy = torch::randn({t, n, d});
  const auto y = ModulatedLayerNormFloat32(x, scale, shift, 1e-6);
  ASSERT_EQ(y.scalar_type(), torch::kFloat32);
  const auto grads = torch::autograd::grad({y}, {x, scale, shift}, {dy});
  const auto ours = std::vector<torch::Tensor>{y.detach(), grads[0], grads[1], grads[2]};

  const auto x32 = x.detach().requires_grad_(), s32 = scale.detach().requires_grad_(),
             b32 = shift.detach().requires_grad_();
  const auto y32 = torch::layer_norm(x32, {d}, {}, {}, 1e-6) * (1 + s32) + b32;
  const auto grads32 = torch::autograd::grad({y32}, {x32, s32, b32}, {dy});
  const auto torch32 = std::vector<torch::Tensor>{y32.detach(), grads32[0], grads32[1], grads32[2]};

  const auto x64 = x.detach().to(torch::kFloat64).requires_grad_();
  const auto s64 = scale.detach().to(torch::kFloat64).requires_grad_();
  const auto b64 = shift.detach().to(torch::kFloat64).requires_grad_();
  const auto y64 = torch::layer_norm(x64, {d}, {}, {}, 1e-6) * (1 + s64) + b64;
  const auto grads64 = torch::autograd::grad({y64}, {x64, s64, b64}, {dy.to(torch::kFloat64)});
  const auto exact = std::vector<torch::Tensor>{y64.detach(), grads64[0], grads64[1], grads64[2]};
  for (size_t k = 0; k < exact.size(); ++k) {
    ASSERT_EQ(ours[k].sizes(), exact[k].sizes()) << k;
    ASSERT_EQ(ours[k].scalar_type(), torch::kFloat32) << k;
    const double top = exact[k].abs().max().item<double>();
    const auto gap = [&](const torch::Tensor& v) {
      return (v.to(torch::kFloat64) - exact[k]).abs().max().item<double>();
    };
    EXPECT_LT(gap(ours[k]), 1e-5 * top) << k;
    EXPECT_LE(gap(ours[k]), 4 * gap(torch32[k]) + 1e-6 * top) << k;
  }
  EXPECT_TRUE(torch::equal(
      y, ModulatedLayerNormFloat32(x.detach(), scale.detach()[0], shift.detach()[0], 1e-6)));

  const auto gate = torch::randn({1, n, d}).requires_grad_();
  const auto branch = torch::randn({t, n, d}).requires_grad_();
  const auto stream = torch::randn({t, n, d}).requires_grad_();
  const auto h = GatedResidualFloat32(stream, gate, branch);
  ASSERT_EQ(h.scalar_type(), torch::kFloat32);
  EXPECT_TRUE(torch::allclose(h, stream + gate * branch, 1e-6, 1e-6));
  const auto dh = torch::randn({t, n, d});
  const auto gated = torch::autograd::grad({h}, {stream, gate, branch}, {dh});
  const auto g64 = gate.detach().to(torch::kFloat64), v64 = branch.detach().to(torch::kFloat64);
  const auto dh64 = dh.to(torch::kFloat64);
  EXPECT_TRUE(torch::equal(gated[0], dh));
  EXPECT_LT((gated[1].to(torch::kFloat64) - (dh64 * v64).sum(0, true)).abs().max().item<double>(),
            1e-5 * (dh64 * v64).abs().sum(0).max().item<double>());
  EXPECT_LT((gated[2].to(torch::kFloat64) - dh64 * g64).abs().max().item<double>(), 1e-6);

  EXPECT_THROW(ModulatedLayerNormFloat32(x.detach(), scale.detach().to(torch::kBFloat16),
                                         shift.detach(), 1e-6),
               std::invalid_argument);
  EXPECT_THROW(
      GatedResidualFloat32(stream.detach(), gate.detach(), branch.detach().to(torch::kBFloat16)),
      std::invalid_argument);
  EXPECT_THROW(
      GatedResidualFloat32(stream.detach().to(torch::kFloat64), gate.detach(), branch.detach()),
      std::invalid_argument);
}

// Clipping by the global norm and AdamW's step in one pass: the same parameters, moments and step
// counts as torch::nn::utils::clip_grad_norm_ followed by torch::optim::AdamW::step, over steps
// that clip and steps that do not, with decoupled weight decay; a parameter without a gradient is
// left alone and gets no state.
TEST(Fused, AdamWStepIsLibTorchsClipAndAdamW) {
  torch::manual_seed(3);
  const std::vector<std::vector<int64_t>> shapes = {{37, 19}, {19}, {5, 3, 7}, {1}};
  std::vector<torch::Tensor> ours, theirs;
  for (const auto& shape : shapes) {
    const auto p = torch::randn(shape);
    ours.push_back(p.clone().requires_grad_());
    theirs.push_back(p.clone().requires_grad_());
  }
  const auto options = torch::optim::AdamWOptions(1e-2).betas({0.9, 0.99}).weight_decay(0.1);
  torch::optim::AdamW fused(ours, options), reference(theirs, options);
  const double max_norm = 1.0;
  for (int step = 0; step < 6; ++step) {
    const double scale = step % 2 == 0 ? 5.0 : 0.01;  // clipped, not clipped
    for (size_t k = 0; k + 1 < shapes.size(); ++k) {
      const auto g = scale * torch::randn(shapes[k]);
      ours[k].mutable_grad() = g.clone();
      theirs[k].mutable_grad() = g.clone();
    }
    const double norm = AdamWStep(fused, max_norm);
    const double their_norm = torch::nn::utils::clip_grad_norm_(theirs, max_norm);
    reference.step();
    EXPECT_NEAR(norm, their_norm, 1e-5 * their_norm);
    for (size_t k = 0; k < shapes.size(); ++k) {
      EXPECT_TRUE(torch::allclose(ours[k], theirs[k], 1e-5, 1e-6)) << "parameter " << k;
    }
  }
  const auto key = [](const torch::Tensor& p) {
    return c10::guts::to_string(p.unsafeGetTensorImpl());
  };
  for (size_t k = 0; k + 1 < shapes.size(); ++k) {
    const auto& a = static_cast<torch::optim::AdamWParamState&>(*fused.state().at(key(ours[k])));
    const auto& b =
        static_cast<torch::optim::AdamWParamState&>(*reference.state().at(key(theirs[k])));
    EXPECT_EQ(a.step(), 6);
    EXPECT_EQ(b.step(), 6);
    EXPECT_TRUE(torch::allclose(a.exp_avg(), b.exp_avg(), 1e-5, 1e-7));
    EXPECT_TRUE(torch::allclose(a.exp_avg_sq(), b.exp_avg_sq(), 1e-5, 1e-9));
  }
  EXPECT_EQ(fused.state().count(key(ours.back())), 0u);

  // Its state is AdamW's: a checkpoint of it resumes in a plain torch::optim::AdamW.
  std::stringstream saved;
  torch::save(fused, saved);
  torch::optim::AdamW resumed(ours, options);
  torch::load(resumed, saved);
  const auto& a = static_cast<torch::optim::AdamWParamState&>(*resumed.state().at(key(ours[0])));
  EXPECT_EQ(a.step(), 6);
}

// Self-attention's core (softmax(q k^T / sqrt(Dh) + mask) v per example and head) in float32
// through the fused kernel, on in_proj's output [L, N, 3 H Dh] as it lies, against the ATen route
// in float64 on the same input: the output [L, N, H Dh] and the gradient of qkv, with keys ignored
// by padding and a dropout mask, at the editors' training shape (81 tokens, 4 heads of 32) and at
// shapes that are no multiple of the kernel's tile (7 tokens, heads of 24; one token). Each float32
// result is within 2e-5 of float64's relative to the largest entry, as ATen's float32 is; a wrong
// head layout (q, k, v or the heads read from the wrong columns) is off by order one.
TEST(Fused, SelfAttentionFloat32IsTheAtenRoute) {
  torch::manual_seed(5);
  struct Case {
    int64_t n, heads, length, head_dim;
    bool padded, dropout;
  };
  for (const Case& c : {Case{4, 4, 81, 32, true, false}, Case{3, 2, 7, 24, true, true},
                        Case{2, 3, 1, 8, false, false}, Case{2, 2, 33, 16, false, true}}) {
    SCOPED_TRACE("L " + std::to_string(c.length) + " Dh " + std::to_string(c.head_dim));
    const int64_t width = c.heads * c.head_dim;
    const auto qkv = torch::randn({c.length, c.n, 3 * width}).requires_grad_();
    torch::Tensor padding, mask;
    if (c.padded) {  // example n ignores its last n + 1 keys (none left of a 1-token example)
      padding = torch::zeros({c.n, c.length}, torch::kBool);
      for (int64_t e = 0; e < c.n; ++e)
        padding[e]
            .narrow(0, std::max<int64_t>(0, c.length - e - 1), std::min(c.length, e + 1))
            .fill_(true);
    }
    if (c.dropout) mask = DropoutMask({c.n * c.heads, c.length, c.length}, 0.25);
    const auto out = SelfAttentionFloat32(qkv, c.heads, padding, mask);
    ASSERT_EQ(out.sizes(), torch::IntArrayRef({c.length, c.n, width}));
    ASSERT_EQ(out.scalar_type(), torch::kFloat);
    const auto dout = torch::randn_like(out);
    const auto grad = torch::autograd::grad({out}, {qkv}, {dout})[0];

    const auto qkv64 = qkv.detach().to(torch::kFloat64).requires_grad_();
    const auto mask64 = mask.defined() ? mask.to(torch::kFloat64) : mask;
    const auto out64 = SelfAttentionThroughAten(qkv64, c.heads, padding, mask64);
    const auto grad64 = torch::autograd::grad({out64}, {qkv64}, {dout.to(torch::kFloat64)})[0];
    const auto out32 = SelfAttentionThroughAten(qkv, c.heads, padding, mask);
    const auto grad32 = torch::autograd::grad({out32}, {qkv}, {dout})[0];
    const auto gap = [](const torch::Tensor& x, const torch::Tensor& exact) {
      // (one key: the softmax is constant and q's and k's gradients are exactly 0)
      const double largest = std::max(exact.abs().max().item<double>(), 1e-30);
      return (x.to(torch::kFloat64) - exact).abs().max().item<double>() / largest;
    };
    EXPECT_LT(gap(out, out64), 2e-5);
    EXPECT_LT(gap(out32, out64), 2e-5);     // the bound holds for ATen's float32 too
    for (int part = 0; part < 3; ++part) {  // q, k, v
      SCOPED_TRACE("gradient " + std::to_string(part));
      const auto cols = [&](const torch::Tensor& g) { return g.narrow(2, part * width, width); };
      EXPECT_LT(gap(cols(grad), cols(grad64)), 2e-5);
      EXPECT_LT(gap(cols(grad32), cols(grad64)), 2e-5);
    }
  }
}

// A query whose every key is ignored attends to all keys equally (the ATen route's finite bias
// rounds every float32 score to the same value), ignored keys get no weight and no gradient, and
// bad arguments are errors that say what was wrong.
TEST(Fused, SelfAttentionFloat32IgnoresPaddedKeysAndRejectsBadArguments) {
  torch::manual_seed(6);
  // One head of 8: qkv [L 5, N 2, 24] from q, k, v [N, L, 8].
  const auto q = torch::randn({2, 5, 8}), k = torch::randn({2, 5, 8}), v = torch::randn({2, 5, 8});
  const auto qkv = torch::cat({q, k, v}, 2).transpose(0, 1).contiguous().requires_grad_();
  auto padding = torch::zeros({2, 5}, torch::kBool);
  padding[0].fill_(true);                  // example 0: every key ignored
  padding[1].narrow(0, 3, 2).fill_(true);  // example 1: keys 3 and 4
  const auto out = SelfAttentionFloat32(qkv, 1, padding, {});
  EXPECT_TRUE(torch::allclose(out.select(1, 0), v[0].mean(0).expand({5, 8}), 1e-5, 1e-6));
  const auto kept = torch::softmax(torch::mm(q[1], k[1].narrow(0, 0, 3).t()) / std::sqrt(8.0), -1)
                        .mm(v[1].narrow(0, 0, 3));  // example 1 with its first 3 keys alone
  EXPECT_TRUE(torch::allclose(out.select(1, 1), kept, 1e-5, 1e-6));
  const auto grad = torch::autograd::grad({out.sum()}, {qkv})[0];
  EXPECT_EQ(grad.select(1, 1).narrow(0, 3, 2).narrow(1, 8, 16).abs().max().item<float>(), 0.0f)
      << "ignored keys and their values get no gradient";

  const auto message = [&](const std::function<void()>& f) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(
      message([&] { SelfAttentionFloat32(qkv.to(torch::kFloat64), 1, {}, {}); }).find("float32"),
      std::string::npos);
  EXPECT_NE(message([&] { SelfAttentionFloat32(qkv, 5, {}, {}); }).find("heads"),
            std::string::npos);
  EXPECT_NE(message([&] {
              SelfAttentionFloat32(qkv, 1, torch::zeros({3, 5}, torch::kBool), {});
            }).find("padding"),
            std::string::npos);
  EXPECT_NE(message([&] {
              SelfAttentionFloat32(qkv, 1, {}, torch::ones({2, 5, 4}));
            }).find("dropout"),
            std::string::npos);
}

}  // namespace
}  // namespace motionpipe::nn
