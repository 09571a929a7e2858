#include "fused.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

// The loops are plain C++ vectorised by the compiler (omp simd; the file is built with
// -fno-math-errno -fno-trapping-math, without which sqrt and floor stay calls and nothing
// vectorises); each is built for AVX-512, AVX2 and the baseline and the CPU picks at load time
// (the build targets the baseline x86-64).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define MOTIONPIPE_CLONES \
  __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define MOTIONPIPE_CLONES
#endif

namespace motionpipe::nn {

namespace {

constexpr float kSqrt2OverPi = 0.7978845608028654f;
constexpr float kCubic = 0.044715f;  // GELU's tanh approximation (Hendrycks and Gimpel 2016)

inline float Bf16ToFloat(uint16_t h) {
  return std::bit_cast<float>(static_cast<uint32_t>(h) << 16);
}

// Round to nearest even, as c10::BFloat16 rounds; a NaN stays a (quiet) NaN.
inline uint16_t FloatToBf16(float f) {
  const uint32_t u = std::bit_cast<uint32_t>(f);
  const uint32_t rounded = (u + 0x7FFFu + ((u >> 16) & 1u)) >> 16;
  return static_cast<uint16_t>(std::isnan(f) ? 0x7FC0u : rounded);
}

// e^v in float32 without a call, so that a loop over it vectorises: v clamped to [-87, 88] (the
// results stay normal), e^v = 2^n e^r with n = round(v / ln 2) and r = v - n ln 2 (ln 2 in two
// parts, so r is exact to float rounding), |r| <= ln(2) / 2, e^r by its Taylor series to r^7
// (truncation below 1e-8 relative); 2^n written into the exponent bits.
inline float Exp(float v) {
  v = v > -87.0f ? v : -87.0f;  // a NaN becomes -87: the caller's product carries the NaN on
  v = v < 88.0f ? v : 88.0f;
  const float n = std::floor(v * 1.44269504f + 0.5f);
  const float r = (v - n * 0.693145752f) - n * 1.42860677e-6f;
  float p = 1.0f / 5040;
  p = p * r + 1.0f / 720;
  p = p * r + 1.0f / 120;
  p = p * r + 1.0f / 24;
  p = p * r + 1.0f / 6;
  p = p * r + 0.5f;
  p = p * r + 1.0f;
  p = p * r + 1.0f;
  const int32_t exponent = (static_cast<int32_t>(n) + 127) << 23;
  return p * std::bit_cast<float>(exponent);
}

// 0.5 (1 + tanh u) = 1 / (1 + e^(-2u)), u = sqrt(2/pi) (x + 0.044715 x^3): GELU's gate written
// as a sigmoid, which has no cancellation near u = 0 or for large |u|.
inline float GeluGate(float x) {
  const float u = kSqrt2OverPi * (x + kCubic * x * x * x);
  return 1.0f / (1.0f + Exp(-2.0f * u));
}

MOTIONPIPE_CLONES void GeluForward(const uint16_t* x, uint16_t* y, int64_t n) {
#pragma omp simd
  for (int64_t k = 0; k < n; ++k) {
    const float v = Bf16ToFloat(x[k]);
    y[k] = FloatToBf16(v * GeluGate(v));
  }
}

// d/dx [x s(x)] with s = sigmoid(2u): s + 2 x s (1 - s) du/dx, du/dx = sqrt(2/pi) (1 + 3 c x^2).
MOTIONPIPE_CLONES void GeluBackward(const uint16_t* x, const uint16_t* dy, uint16_t* dx,
                                    int64_t n) {
#pragma omp simd
  for (int64_t k = 0; k < n; ++k) {
    const float v = Bf16ToFloat(x[k]);
    const float s = GeluGate(v);
    const float du = kSqrt2OverPi * (1.0f + 3.0f * kCubic * v * v);
    dx[k] = FloatToBf16(Bf16ToFloat(dy[k]) * (s + 2.0f * v * s * (1.0f - s) * du));
  }
}

constexpr int64_t kGrain = 1 << 15;  // elements per task of torch's intra-op pool

// A bf16 tensor's storage as raw 16-bit words.
const uint16_t* Bf16Data(const torch::Tensor& t) {
  return reinterpret_cast<const uint16_t*>(t.data_ptr<at::BFloat16>());
}
uint16_t* Bf16Data(torch::Tensor& t) {
  return reinterpret_cast<uint16_t*>(t.data_ptr<at::BFloat16>());
}

struct GeluTanhFunction : torch::autograd::Function<GeluTanhFunction> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x) {
    const auto input = x.contiguous();
    auto y = torch::empty_like(input);
    const uint16_t* in = Bf16Data(input);
    uint16_t* out = Bf16Data(y);
    at::parallel_for(0, input.numel(), kGrain, [&](int64_t begin, int64_t end) {
      GeluForward(in + begin, out + begin, end - begin);
    });
    ctx->save_for_backward({input});
    return y;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto input = ctx->get_saved_variables()[0];
    const auto dy = grads[0].to(torch::kBFloat16).contiguous();
    auto dx = torch::empty_like(input);
    const uint16_t* in = Bf16Data(input);
    const uint16_t* g = Bf16Data(dy);
    uint16_t* out = Bf16Data(dx);
    at::parallel_for(0, input.numel(), kGrain, [&](int64_t begin, int64_t end) {
      GeluBackward(in + begin, g + begin, out + begin, end - begin);
    });
    return {dx};
  }
};

// adaLN-Zero's modulated LayerNorm over rows of d: for rows [begin, end) of x ([T*N, d], row
// r = t N + n), y = (x - mean) rstd (1 + scale[n]) + shift[n] rounded to bf16; keeps each row's
// mean and 1/sqrt(var + eps) for the backward pass. Two passes over the row for the moments (the
// variance from the centred values).
MOTIONPIPE_CLONES void ModulatedNormForward(const float* x, const uint16_t* scale,
                                            const uint16_t* shift, uint16_t* y, float* mean,
                                            float* rstd, int64_t begin, int64_t end, int64_t n,
                                            int64_t d, float eps) {
  for (int64_t r = begin; r < end; ++r) {
    const float* row = x + r * d;
    const uint16_t* s = scale + (r % n) * d;
    const uint16_t* b = shift + (r % n) * d;
    uint16_t* out = y + r * d;
    float sum = 0;
#pragma omp simd reduction(+ : sum)
    for (int64_t k = 0; k < d; ++k) sum += row[k];
    const float mu = sum / static_cast<float>(d);
    float squares = 0;
#pragma omp simd reduction(+ : squares)
    for (int64_t k = 0; k < d; ++k) squares += (row[k] - mu) * (row[k] - mu);
    const float inv = 1.0f / std::sqrt(squares / static_cast<float>(d) + eps);
#pragma omp simd
    for (int64_t k = 0; k < d; ++k)
      out[k] = FloatToBf16((row[k] - mu) * inv * (1.0f + Bf16ToFloat(s[k])) + Bf16ToFloat(b[k]));
    mean[r] = mu;
    rstd[r] = inv;
  }
}

// Its gradient over rows [begin, end), in memory order: with xhat = (x - mean) rstd and
// g = dy (1 + scale), dx = rstd (g - mean(g) - xhat mean(g xhat)); each row's dy xhat and dy are
// added to its batch element's float32 sums (sum_scale, sum_shift: [N, d]) for dscale and dshift.
MOTIONPIPE_CLONES void ModulatedNormBackward(const float* x, const uint16_t* scale,
                                             const uint16_t* dy, const float* mean,
                                             const float* rstd, float* dx, float* sum_scale,
                                             float* sum_shift, int64_t begin, int64_t end,
                                             int64_t n, int64_t d) {
  for (int64_t r = begin; r < end; ++r) {
    const int64_t e = r % n;
    const uint16_t* s = scale + e * d;
    float* ss = sum_scale + e * d;
    float* sb = sum_shift + e * d;
    const float* row = x + r * d;
    const uint16_t* g_row = dy + r * d;
    float* out = dx + r * d;
    const float mu = mean[r], inv = rstd[r];
    float g_sum = 0, gx_sum = 0;
#pragma omp simd reduction(+ : g_sum, gx_sum)
    for (int64_t k = 0; k < d; ++k) {
      const float g = Bf16ToFloat(g_row[k]);
      const float xhat = (row[k] - mu) * inv;
      const float gs = g * (1.0f + Bf16ToFloat(s[k]));
      g_sum += gs;
      gx_sum += gs * xhat;
      ss[k] += g * xhat;
      sb[k] += g;
    }
    const float a = g_sum / static_cast<float>(d), c = gx_sum / static_cast<float>(d);
#pragma omp simd
    for (int64_t k = 0; k < d; ++k) {
      const float xhat = (row[k] - mu) * inv;
      out[k] = inv * (Bf16ToFloat(g_row[k]) * (1.0f + Bf16ToFloat(s[k])) - a - xhat * c);
    }
  }
}

// h = x + gate[n] y over rows [begin, end).
MOTIONPIPE_CLONES void GatedResidualForward(const float* x, const uint16_t* gate, const uint16_t* y,
                                            float* h, int64_t begin, int64_t end, int64_t n,
                                            int64_t d) {
  for (int64_t r = begin; r < end; ++r) {
    const uint16_t* g = gate + (r % n) * d;
#pragma omp simd
    for (int64_t k = 0; k < d; ++k)
      h[r * d + k] = x[r * d + k] + Bf16ToFloat(g[k]) * Bf16ToFloat(y[r * d + k]);
  }
}

// Its gradient over rows [begin, end), in memory order: dy = dh gate (rounded); each row's dh y is
// added to its batch element's float32 sum ([N, d]) for dgate; dx is dh itself.
MOTIONPIPE_CLONES void GatedResidualBackward(const float* dh, const uint16_t* gate,
                                             const uint16_t* y, uint16_t* dy, float* sum,
                                             int64_t begin, int64_t end, int64_t n, int64_t d) {
  for (int64_t r = begin; r < end; ++r) {
    const uint16_t* g = gate + (r % n) * d;
    float* acc = sum + (r % n) * d;
    const int64_t o = r * d;
#pragma omp simd
    for (int64_t k = 0; k < d; ++k) {
      const float v = dh[o + k];
      acc[k] += v * Bf16ToFloat(y[o + k]);
      dy[o + k] = FloatToBf16(v * Bf16ToFloat(g[k]));
    }
  }
}

// Runs `rows_kernel(begin, end, sums)` over the rows of [T, N, d] in at most one chunk of whole
// frames per intra-op thread, each chunk adding into its own zeroed float32 buffer of `width`
// values, and returns the buffers summed in chunk order (the same result for a thread count).
template <typename F>
std::vector<float> RowsWithSums(int64_t t_count, int64_t n, int64_t width, F&& rows_kernel) {
  const int64_t chunks = std::max<int64_t>(1, std::min<int64_t>(at::get_num_threads(), t_count));
  std::vector<float> sums(static_cast<size_t>(chunks * width), 0.0f);
  at::parallel_for(0, chunks, 1, [&](int64_t begin, int64_t end) {
    for (int64_t c = begin; c < end; ++c)
      rows_kernel(c * t_count / chunks * n, (c + 1) * t_count / chunks * n,
                  sums.data() + c * width);
  });
  for (int64_t c = 1; c < chunks; ++c)
    for (int64_t k = 0; k < width; ++k)
      sums[static_cast<size_t>(k)] += sums[static_cast<size_t>(c * width + k)];
  sums.resize(static_cast<size_t>(width));
  return sums;
}

MOTIONPIPE_CLONES void RoundToBf16(const float* in, uint16_t* out, int64_t count) {
#pragma omp simd
  for (int64_t k = 0; k < count; ++k) out[k] = FloatToBf16(in[k]);
}

// adaLN's stream x must be [T, N, d] float32.
void CheckStream(const char* what, const torch::Tensor& x) {
  if (x.dim() != 3 || x.scalar_type() != torch::kFloat)
    throw std::invalid_argument(std::string(what) + " takes x as [T, N, d] float32, not " +
                                std::string(c10::toString(x.scalar_type())) + " of " +
                                std::to_string(x.dim()) + " dimensions");
}
// A per-element operand (scale, shift, gate) must be bf16 of [N, d] or [1, N, d]; returned as a
// contiguous [N, d].
torch::Tensor PerElement(const char* what, const char* name, const torch::Tensor& v,
                         const torch::Tensor& x) {
  const int64_t n = x.size(1), d = x.size(2);
  const bool shape_ok = (v.dim() == 2 && v.size(0) == n && v.size(1) == d) ||
                        (v.dim() == 3 && v.size(0) == 1 && v.size(1) == n && v.size(2) == d);
  if (!shape_ok || v.scalar_type() != torch::kBFloat16)
    throw std::invalid_argument(std::string(what) + ": " + name +
                                " must be bf16 of [N, d] or [1, N, d] = [" + std::to_string(n) +
                                ", " + std::to_string(d) + "]");
  return v.reshape({n, d}).contiguous();
}

struct ModulatedLayerNormFunction : torch::autograd::Function<ModulatedLayerNormFunction> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x_in,
                               const torch::Tensor& scale_in, const torch::Tensor& shift_in,
                               double eps) {
    const auto x = x_in.contiguous();
    const auto scale = PerElement("ModulatedLayerNormBf16", "scale", scale_in, x);
    const auto shift = PerElement("ModulatedLayerNormBf16", "shift", shift_in, x);
    const int64_t rows = x.size(0) * x.size(1), n = x.size(1), d = x.size(2);
    auto y = torch::empty(x.sizes(), x.options().dtype(torch::kBFloat16));
    auto mean = torch::empty({rows}, x.options());
    auto rstd = torch::empty({rows}, x.options());
    at::parallel_for(0, rows, std::max<int64_t>(1, kGrain / d), [&](int64_t begin, int64_t end) {
      ModulatedNormForward(x.data_ptr<float>(), Bf16Data(scale), Bf16Data(shift), Bf16Data(y),
                           mean.data_ptr<float>(), rstd.data_ptr<float>(), begin, end, n, d,
                           static_cast<float>(eps));
    });
    ctx->save_for_backward({x, scale, mean, rstd});
    ctx->saved_data["scale_sizes"] = scale_in.sizes().vec();
    ctx->saved_data["shift_sizes"] = shift_in.sizes().vec();
    return y;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &x = saved[0], &scale = saved[1], &mean = saved[2], &rstd = saved[3];
    const auto dy = grads[0].to(torch::kBFloat16).contiguous();
    const int64_t t_count = x.size(0), n = x.size(1), d = x.size(2);
    auto dx = torch::empty_like(x);
    auto dscale = torch::empty({n, d}, x.options().dtype(torch::kBFloat16));
    auto dshift = torch::empty({n, d}, x.options().dtype(torch::kBFloat16));
    const auto sums =
        RowsWithSums(t_count, n, 2 * n * d, [&](int64_t begin, int64_t end, float* acc) {
          ModulatedNormBackward(x.data_ptr<float>(), Bf16Data(scale), Bf16Data(dy),
                                mean.data_ptr<float>(), rstd.data_ptr<float>(),
                                dx.data_ptr<float>(), acc, acc + n * d, begin, end, n, d);
        });
    RoundToBf16(sums.data(), Bf16Data(dscale), n * d);
    RoundToBf16(sums.data() + n * d, Bf16Data(dshift), n * d);
    return {dx, dscale.view(ctx->saved_data["scale_sizes"].toIntVector()),
            dshift.view(ctx->saved_data["shift_sizes"].toIntVector()), torch::Tensor()};
  }
};

struct GatedResidualFunction : torch::autograd::Function<GatedResidualFunction> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x_in,
                               const torch::Tensor& gate_in, const torch::Tensor& y_in) {
    const auto x = x_in.contiguous();
    const auto gate = PerElement("GatedResidualBf16", "gate", gate_in, x);
    if (y_in.sizes() != x.sizes() || y_in.scalar_type() != torch::kBFloat16)
      throw std::invalid_argument("GatedResidualBf16: y must be bf16 of x's shape");
    const auto y = y_in.contiguous();
    const int64_t rows = x.size(0) * x.size(1), n = x.size(1), d = x.size(2);
    auto h = torch::empty_like(x);
    at::parallel_for(0, rows, std::max<int64_t>(1, kGrain / d), [&](int64_t begin, int64_t end) {
      GatedResidualForward(x.data_ptr<float>(), Bf16Data(gate), Bf16Data(y), h.data_ptr<float>(),
                           begin, end, n, d);
    });
    ctx->save_for_backward({gate, y});
    ctx->saved_data["gate_sizes"] = gate_in.sizes().vec();
    return h;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &gate = saved[0], &y = saved[1];
    const auto dh = grads[0].to(torch::kFloat).contiguous();
    const int64_t t_count = y.size(0), n = y.size(1), d = y.size(2);
    auto dy = torch::empty_like(y);
    auto dgate = torch::empty({n, d}, y.options());
    const auto sum = RowsWithSums(t_count, n, n * d, [&](int64_t begin, int64_t end, float* acc) {
      GatedResidualBackward(dh.data_ptr<float>(), Bf16Data(gate), Bf16Data(y), Bf16Data(dy), acc,
                            begin, end, n, d);
    });
    RoundToBf16(sum.data(), Bf16Data(dgate), n * d);
    return {dh, dgate.view(ctx->saved_data["gate_sizes"].toIntVector()), dy};
  }
};

// Sum of squares in double (the per-parameter float norms of clip_grad_norm_, without rounding).
MOTIONPIPE_CLONES double SquaredNorm(const float* g, int64_t n) {
  double sum = 0;
#pragma omp simd reduction(+ : sum)
  for (int64_t k = 0; k < n; ++k) sum += static_cast<double>(g[k]) * g[k];
  return sum;
}

struct AdamWScalars {
  float decay;  // 1 - lr weight_decay (decoupled weight decay)
  float clip;   // the gradient's scale
  float beta1, beta2;
  float inv_bias2;  // sqrt(1 - beta2^t), divided by
  float step_size;  // lr / (1 - beta1^t)
  float eps;
};

// AdamW::step's arithmetic for one parameter, in the order LibTorch applies it:
// p *= 1 - lr wd; m = b1 m + (1 - b1) g; v = b2 v + (1 - b2) g^2;
// p -= step_size m / (sqrt(v) / sqrt(1 - b2^t) + eps).
MOTIONPIPE_CLONES void AdamWKernel(float* p, const float* grad, float* m, float* v, int64_t n,
                                   AdamWScalars s) {
  const float one_minus_beta1 = 1.0f - s.beta1, one_minus_beta2 = 1.0f - s.beta2;
#pragma omp simd
  for (int64_t k = 0; k < n; ++k) {
    const float g = grad[k] * s.clip;
    const float mk = m[k] * s.beta1 + g * one_minus_beta1;
    const float vk = v[k] * s.beta2 + g * g * one_minus_beta2;
    m[k] = mk;
    v[k] = vk;
    p[k] = p[k] * s.decay - s.step_size * (mk / (std::sqrt(vk) / s.inv_bias2 + s.eps));
  }
}

}  // namespace

torch::Tensor GeluTanhBf16(const torch::Tensor& x) {
  if (x.scalar_type() != torch::kBFloat16)
    throw std::invalid_argument("GeluTanhBf16 takes bf16, not " +
                                std::string(c10::toString(x.scalar_type())));
  return GeluTanhFunction::apply(x);
}

torch::Tensor ModulatedLayerNormBf16(const torch::Tensor& x, const torch::Tensor& scale,
                                     const torch::Tensor& shift, double eps) {
  CheckStream("ModulatedLayerNormBf16", x);
  return ModulatedLayerNormFunction::apply(x, scale, shift, eps);
}

torch::Tensor GatedResidualBf16(const torch::Tensor& x, const torch::Tensor& gate,
                                const torch::Tensor& y) {
  CheckStream("GatedResidualBf16", x);
  return GatedResidualFunction::apply(x, gate, y);
}

double AdamWStep(torch::optim::AdamW& optimizer, double max_norm) {
  torch::NoGradGuard no_grad;
  double squares = 0;
  for (auto& group : optimizer.param_groups()) {
    for (auto& p : group.params()) {
      if (!p.grad().defined()) continue;
      const auto& g = p.grad();
      if (g.scalar_type() != torch::kFloat || !g.is_contiguous() || !p.is_contiguous())
        throw std::invalid_argument("AdamWStep takes contiguous float32 parameters and gradients");
      squares += SquaredNorm(g.data_ptr<float>(), g.numel());
    }
  }
  const double norm = std::sqrt(squares);
  const double clip = max_norm > 0 ? std::min(1.0, max_norm / (norm + 1e-6)) : 1.0;
  auto& state = optimizer.state();
  for (auto& group : optimizer.param_groups()) {
    const auto& options = static_cast<const torch::optim::AdamWOptions&>(group.options());
    if (options.amsgrad()) throw std::invalid_argument("AdamWStep has no amsgrad");
    const double beta1 = std::get<0>(options.betas()), beta2 = std::get<1>(options.betas());
    for (auto& p : group.params()) {
      if (!p.grad().defined()) continue;
      const std::string key = c10::guts::to_string(p.unsafeGetTensorImpl());
      auto found = state.find(key);
      if (found == state.end()) {
        auto fresh = std::make_unique<torch::optim::AdamWParamState>();
        fresh->step(0);
        fresh->exp_avg(torch::zeros_like(p, torch::MemoryFormat::Preserve));
        fresh->exp_avg_sq(torch::zeros_like(p, torch::MemoryFormat::Preserve));
        found = state.emplace(key, std::move(fresh)).first;
      }
      auto& s = static_cast<torch::optim::AdamWParamState&>(*found->second);
      s.step(s.step() + 1);
      const auto t = static_cast<double>(s.step());
      const AdamWScalars scalars{static_cast<float>(1 - options.lr() * options.weight_decay()),
                                 static_cast<float>(clip),
                                 static_cast<float>(beta1),
                                 static_cast<float>(beta2),
                                 static_cast<float>(std::sqrt(1 - std::pow(beta2, t))),
                                 static_cast<float>(options.lr() / (1 - std::pow(beta1, t))),
                                 static_cast<float>(options.eps())};
      float* data = p.detach().data_ptr<float>();
      const float* grad = p.grad().data_ptr<float>();
      float* m = s.exp_avg().data_ptr<float>();
      float* v = s.exp_avg_sq().data_ptr<float>();
      at::parallel_for(0, p.numel(), kGrain, [&](int64_t begin, int64_t end) {
        AdamWKernel(data + begin, grad + begin, m + begin, v + begin, end - begin, scalars);
      });
    }
  }
  return norm;
}

}  // namespace motionpipe::nn
