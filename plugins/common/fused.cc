#include "fused.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

// The loops are plain C++ vectorised by the compiler (omp simd; the file is built with
// -fno-math-errno -fno-trapping-math, without which sqrt and floor stay calls and nothing
// vectorises); each is built for AVX-512, AVX2 and the baseline and the CPU picks at load time
// (the build targets the baseline x86-64).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define MOTIONPIPE_CLONES \
  __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
// The GEMM tile is built for AVX2 and the baseline only (an AVX-512 CPU runs the AVX2 clone): it
// was measured on AVX2 alone, and GCC 12's AVX-512 clone of a first version kept the accumulators
// in memory.
#define MOTIONPIPE_CLONES_AVX2 __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define MOTIONPIPE_CLONES
#define MOTIONPIPE_CLONES_AVX2
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

// An element of a bf16 (raw 16-bit words) or float32 tensor, as float32 and back (bf16: rounded
// to nearest even).
inline float Load(uint16_t h) { return Bf16ToFloat(h); }
inline float Load(float f) { return f; }
template <typename T>
inline T Store(float f) {
  if constexpr (std::is_same_v<T, uint16_t>)
    return FloatToBf16(f);
  else
    return f;
}

template <typename T>
__attribute__((always_inline)) inline void GeluForwardLoop(const T* x, T* y, int64_t n) {
#pragma omp simd
  for (int64_t k = 0; k < n; ++k) {
    const float v = Load(x[k]);
    y[k] = Store<T>(v * GeluGate(v));
  }
}

// d/dx [x s(x)] with s = sigmoid(2u): s + 2 x s (1 - s) du/dx, du/dx = sqrt(2/pi) (1 + 3 c x^2);
// 1 - s as e s with e = e^(-2u), which keeps its relative precision where s nears 1.
template <typename T>
__attribute__((always_inline)) inline void GeluBackwardLoop(const T* x, const T* dy, T* dx,
                                                            int64_t n) {
#pragma omp simd
  for (int64_t k = 0; k < n; ++k) {
    const float v = Load(x[k]);
    const float e = Exp(-2.0f * kSqrt2OverPi * (v + kCubic * v * v * v));
    const float s = 1.0f / (1.0f + e);
    const float du = kSqrt2OverPi * (1.0f + 3.0f * kCubic * v * v);
    dx[k] = Store<T>(Load(dy[k]) * (s + 2.0f * v * s * (e * s) * du));
  }
}

MOTIONPIPE_CLONES void GeluForward(const uint16_t* x, uint16_t* y, int64_t n) {
  GeluForwardLoop(x, y, n);
}
MOTIONPIPE_CLONES void GeluForward(const float* x, float* y, int64_t n) {
  GeluForwardLoop(x, y, n);
}
MOTIONPIPE_CLONES void GeluBackward(const uint16_t* x, const uint16_t* dy, uint16_t* dx,
                                    int64_t n) {
  GeluBackwardLoop(x, dy, dx, n);
}
MOTIONPIPE_CLONES void GeluBackward(const float* x, const float* dy, float* dx, int64_t n) {
  GeluBackwardLoop(x, dy, dx, n);
}

constexpr int64_t kGrain = 1 << 15;  // elements per task of torch's intra-op pool

// A bf16 tensor's storage as raw 16-bit words.
const uint16_t* Bf16Data(const torch::Tensor& t) {
  return reinterpret_cast<const uint16_t*>(t.data_ptr<at::BFloat16>());
}
uint16_t* Bf16Data(torch::Tensor& t) {
  return reinterpret_cast<uint16_t*>(t.data_ptr<at::BFloat16>());
}

// A tensor's storage as the element type of the kernels: bf16 as raw 16-bit words, or float32.
template <typename T>
const T* Data(const torch::Tensor& t) {
  if constexpr (std::is_same_v<T, uint16_t>)
    return Bf16Data(t);
  else
    return t.data_ptr<float>();
}
template <typename T>
T* Data(torch::Tensor& t) {
  if constexpr (std::is_same_v<T, uint16_t>)
    return Bf16Data(t);
  else
    return t.data_ptr<float>();
}

// T: uint16_t for bf16 tensors, float for float32 ones.
template <typename T>
struct GeluTanhFunction : torch::autograd::Function<GeluTanhFunction<T>> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x) {
    const auto input = x.contiguous();
    auto y = torch::empty_like(input);
    const T* in = Data<T>(input);
    T* out = Data<T>(y);
    at::parallel_for(0, input.numel(), kGrain, [&](int64_t begin, int64_t end) {
      GeluForward(in + begin, out + begin, end - begin);
    });
    ctx->save_for_backward({input});
    return y;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto input = ctx->get_saved_variables()[0];
    const auto dy = grads[0].to(input.scalar_type()).contiguous();
    auto dx = torch::empty_like(input);
    const T* in = Data<T>(input);
    const T* g = Data<T>(dy);
    T* out = Data<T>(dx);
    at::parallel_for(0, input.numel(), kGrain, [&](int64_t begin, int64_t end) {
      GeluBackward(in + begin, g + begin, out + begin, end - begin);
    });
    return {dx};
  }
};

// adaLN-Zero's modulated LayerNorm over rows of d: for rows [begin, end) of x ([T*N, d], row
// r = t N + n), y = (x - mean) rstd (1 + scale[n]) + shift[n] (T: rounded to bf16 once, or kept
// float32); keeps each row's mean and 1/sqrt(var + eps) for the backward pass. Two passes over the
// row for the moments (the variance from the centred values).
template <typename T>
__attribute__((always_inline)) inline void ModulatedNormForwardLoop(
    const float* x, const T* scale, const T* shift, T* y, float* mean, float* rstd, int64_t begin,
    int64_t end, int64_t n, int64_t d, float eps) {
  for (int64_t r = begin; r < end; ++r) {
    const float* row = x + r * d;
    const T* s = scale + (r % n) * d;
    const T* b = shift + (r % n) * d;
    T* out = y + r * d;
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
      out[k] = Store<T>((row[k] - mu) * inv * (1.0f + Load(s[k])) + Load(b[k]));
    mean[r] = mu;
    rstd[r] = inv;
  }
}

// Its gradient over rows [begin, end), in memory order: with xhat = (x - mean) rstd and
// g = dy (1 + scale), dx = rstd (g - mean(g) - xhat mean(g xhat)); each row's dy xhat and dy are
// added to its batch element's float32 sums (sum_scale, sum_shift: [N, d]) for dscale and dshift.
template <typename T>
__attribute__((always_inline)) inline void ModulatedNormBackwardLoop(
    const float* x, const T* scale, const T* dy, const float* mean, const float* rstd, float* dx,
    float* sum_scale, float* sum_shift, int64_t begin, int64_t end, int64_t n, int64_t d) {
  for (int64_t r = begin; r < end; ++r) {
    const int64_t e = r % n;
    const T* s = scale + e * d;
    float* ss = sum_scale + e * d;
    float* sb = sum_shift + e * d;
    const float* row = x + r * d;
    const T* g_row = dy + r * d;
    float* out = dx + r * d;
    const float mu = mean[r], inv = rstd[r];
    float g_sum = 0, gx_sum = 0;
#pragma omp simd reduction(+ : g_sum, gx_sum)
    for (int64_t k = 0; k < d; ++k) {
      const float g = Load(g_row[k]);
      const float xhat = (row[k] - mu) * inv;
      const float gs = g * (1.0f + Load(s[k]));
      g_sum += gs;
      gx_sum += gs * xhat;
      ss[k] += g * xhat;
      sb[k] += g;
    }
    const float a = g_sum / static_cast<float>(d), c = gx_sum / static_cast<float>(d);
#pragma omp simd
    for (int64_t k = 0; k < d; ++k) {
      const float xhat = (row[k] - mu) * inv;
      out[k] = inv * (Load(g_row[k]) * (1.0f + Load(s[k])) - a - xhat * c);
    }
  }
}

// h = x + gate[n] y over rows [begin, end).
template <typename T>
__attribute__((always_inline)) inline void GatedResidualForwardLoop(const float* x, const T* gate,
                                                                    const T* y, float* h,
                                                                    int64_t begin, int64_t end,
                                                                    int64_t n, int64_t d) {
  for (int64_t r = begin; r < end; ++r) {
    const T* g = gate + (r % n) * d;
#pragma omp simd
    for (int64_t k = 0; k < d; ++k) h[r * d + k] = x[r * d + k] + Load(g[k]) * Load(y[r * d + k]);
  }
}

// Its gradient over rows [begin, end), in memory order: dy = dh gate (T: rounded to bf16, or
// float32); each row's dh y is added to its batch element's float32 sum ([N, d]) for dgate; dx is
// dh itself.
template <typename T>
__attribute__((always_inline)) inline void GatedResidualBackwardLoop(const float* dh, const T* gate,
                                                                     const T* y, T* dy, float* sum,
                                                                     int64_t begin, int64_t end,
                                                                     int64_t n, int64_t d) {
  for (int64_t r = begin; r < end; ++r) {
    const T* g = gate + (r % n) * d;
    float* acc = sum + (r % n) * d;
    const int64_t o = r * d;
#pragma omp simd
    for (int64_t k = 0; k < d; ++k) {
      const float v = dh[o + k];
      acc[k] += v * Load(y[o + k]);
      dy[o + k] = Store<T>(v * Load(g[k]));
    }
  }
}

// The loops above for bf16 (raw 16-bit words) and float32 modulation, each compiled for every
// target of MOTIONPIPE_CLONES.
MOTIONPIPE_CLONES void ModulatedNormForward(const float* x, const uint16_t* scale,
                                            const uint16_t* shift, uint16_t* y, float* mean,
                                            float* rstd, int64_t begin, int64_t end, int64_t n,
                                            int64_t d, float eps) {
  ModulatedNormForwardLoop(x, scale, shift, y, mean, rstd, begin, end, n, d, eps);
}
MOTIONPIPE_CLONES void ModulatedNormBackward(const float* x, const uint16_t* scale,
                                             const uint16_t* dy, const float* mean,
                                             const float* rstd, float* dx, float* sum_scale,
                                             float* sum_shift, int64_t begin, int64_t end,
                                             int64_t n, int64_t d) {
  ModulatedNormBackwardLoop(x, scale, dy, mean, rstd, dx, sum_scale, sum_shift, begin, end, n, d);
}
MOTIONPIPE_CLONES void GatedResidualForward(const float* x, const uint16_t* gate, const uint16_t* y,
                                            float* h, int64_t begin, int64_t end, int64_t n,
                                            int64_t d) {
  GatedResidualForwardLoop(x, gate, y, h, begin, end, n, d);
}
MOTIONPIPE_CLONES void GatedResidualBackward(const float* dh, const uint16_t* gate,
                                             const uint16_t* y, uint16_t* dy, float* sum,
                                             int64_t begin, int64_t end, int64_t n, int64_t d) {
  GatedResidualBackwardLoop(dh, gate, y, dy, sum, begin, end, n, d);
}
MOTIONPIPE_CLONES void ModulatedNormForward(const float* x, const float* scale, const float* shift,
                                            float* y, float* mean, float* rstd, int64_t begin,
                                            int64_t end, int64_t n, int64_t d, float eps) {
  ModulatedNormForwardLoop(x, scale, shift, y, mean, rstd, begin, end, n, d, eps);
}
MOTIONPIPE_CLONES void ModulatedNormBackward(const float* x, const float* scale, const float* dy,
                                             const float* mean, const float* rstd, float* dx,
                                             float* sum_scale, float* sum_shift, int64_t begin,
                                             int64_t end, int64_t n, int64_t d) {
  ModulatedNormBackwardLoop(x, scale, dy, mean, rstd, dx, sum_scale, sum_shift, begin, end, n, d);
}
MOTIONPIPE_CLONES void GatedResidualForward(const float* x, const float* gate, const float* y,
                                            float* h, int64_t begin, int64_t end, int64_t n,
                                            int64_t d) {
  GatedResidualForwardLoop(x, gate, y, h, begin, end, n, d);
}
MOTIONPIPE_CLONES void GatedResidualBackward(const float* dh, const float* gate, const float* y,
                                             float* dy, float* sum, int64_t begin, int64_t end,
                                             int64_t n, int64_t d) {
  GatedResidualBackwardLoop(dh, gate, y, dy, sum, begin, end, n, d);
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

// float32 sums into a tensor's storage: rounded to bf16 or copied.
MOTIONPIPE_CLONES void StoreSums(const float* in, uint16_t* out, int64_t count) {
#pragma omp simd
  for (int64_t k = 0; k < count; ++k) out[k] = FloatToBf16(in[k]);
}
void StoreSums(const float* in, float* out, int64_t count) { std::copy(in, in + count, out); }

// The tensor dtype of a kernel element type: bf16 for raw 16-bit words, else float32.
template <typename T>
constexpr torch::ScalarType kDtype = std::is_same_v<T, uint16_t> ? torch::kBFloat16 : torch::kFloat;

// adaLN's stream x must be [T, N, d] float32.
void CheckStream(const char* what, const torch::Tensor& x) {
  if (x.dim() != 3 || x.scalar_type() != torch::kFloat)
    throw std::invalid_argument(std::string(what) + " takes x as [T, N, d] float32, not " +
                                std::string(c10::toString(x.scalar_type())) + " of " +
                                std::to_string(x.dim()) + " dimensions");
}
// A per-element operand (scale, shift, gate) must be of `dtype` and [N, d] or [1, N, d];
// returned as a contiguous [N, d].
torch::Tensor PerElement(const char* what, const char* name, const torch::Tensor& v,
                         const torch::Tensor& x, torch::ScalarType dtype) {
  const int64_t n = x.size(1), d = x.size(2);
  const bool shape_ok = (v.dim() == 2 && v.size(0) == n && v.size(1) == d) ||
                        (v.dim() == 3 && v.size(0) == 1 && v.size(1) == n && v.size(2) == d);
  if (!shape_ok || v.scalar_type() != dtype)
    throw std::invalid_argument(std::string(what) + ": " + name + " must be " +
                                (dtype == torch::kBFloat16 ? "bf16" : "float32") +
                                " of [N, d] or [1, N, d] = [" + std::to_string(n) + ", " +
                                std::to_string(d) + "]");
  return v.reshape({n, d}).contiguous();
}

// T: uint16_t for bf16 modulation and output, float for float32 ones.
template <typename T>
struct ModulatedLayerNormFunction : torch::autograd::Function<ModulatedLayerNormFunction<T>> {
  static constexpr const char* kName =
      std::is_same_v<T, uint16_t> ? "ModulatedLayerNormBf16" : "ModulatedLayerNormFloat32";

  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x_in,
                               const torch::Tensor& scale_in, const torch::Tensor& shift_in,
                               double eps) {
    CheckStream(kName, x_in);
    const auto x = x_in.contiguous();
    const auto scale = PerElement(kName, "scale", scale_in, x, kDtype<T>);
    const auto shift = PerElement(kName, "shift", shift_in, x, kDtype<T>);
    const int64_t rows = x.size(0) * x.size(1), n = x.size(1), d = x.size(2);
    auto y = torch::empty(x.sizes(), x.options().dtype(kDtype<T>));
    auto mean = torch::empty({rows}, x.options());
    auto rstd = torch::empty({rows}, x.options());
    at::parallel_for(0, rows, std::max<int64_t>(1, kGrain / d), [&](int64_t begin, int64_t end) {
      ModulatedNormForward(x.data_ptr<float>(), Data<T>(scale), Data<T>(shift), Data<T>(y),
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
    const auto dy = grads[0].to(kDtype<T>).contiguous();
    const int64_t t_count = x.size(0), n = x.size(1), d = x.size(2);
    auto dx = torch::empty_like(x);
    auto dscale = torch::empty({n, d}, x.options().dtype(kDtype<T>));
    auto dshift = torch::empty({n, d}, x.options().dtype(kDtype<T>));
    const auto sums =
        RowsWithSums(t_count, n, 2 * n * d, [&](int64_t begin, int64_t end, float* acc) {
          ModulatedNormBackward(x.data_ptr<float>(), Data<T>(scale), Data<T>(dy),
                                mean.data_ptr<float>(), rstd.data_ptr<float>(),
                                dx.data_ptr<float>(), acc, acc + n * d, begin, end, n, d);
        });
    StoreSums(sums.data(), Data<T>(dscale), n * d);
    StoreSums(sums.data() + n * d, Data<T>(dshift), n * d);
    return {dx, dscale.view(ctx->saved_data["scale_sizes"].toIntVector()),
            dshift.view(ctx->saved_data["shift_sizes"].toIntVector()), torch::Tensor()};
  }
};

// T: uint16_t for bf16 gate and branch, float for float32 ones.
template <typename T>
struct GatedResidualFunction : torch::autograd::Function<GatedResidualFunction<T>> {
  static constexpr const char* kName =
      std::is_same_v<T, uint16_t> ? "GatedResidualBf16" : "GatedResidualFloat32";

  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x_in,
                               const torch::Tensor& gate_in, const torch::Tensor& y_in) {
    CheckStream(kName, x_in);
    const auto x = x_in.contiguous();
    const auto gate = PerElement(kName, "gate", gate_in, x, kDtype<T>);
    if (y_in.sizes() != x.sizes() || y_in.scalar_type() != kDtype<T>)
      throw std::invalid_argument(std::string(kName) + ": y must be " +
                                  (std::is_same_v<T, uint16_t> ? "bf16" : "float32") +
                                  " of x's shape");
    const auto y = y_in.contiguous();
    const int64_t rows = x.size(0) * x.size(1), n = x.size(1), d = x.size(2);
    auto h = torch::empty_like(x);
    at::parallel_for(0, rows, std::max<int64_t>(1, kGrain / d), [&](int64_t begin, int64_t end) {
      GatedResidualForward(x.data_ptr<float>(), Data<T>(gate), Data<T>(y), h.data_ptr<float>(),
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
      GatedResidualBackward(dh.data_ptr<float>(), Data<T>(gate), Data<T>(y), Data<T>(dy), acc,
                            begin, end, n, d);
    });
    StoreSums(sum.data(), Data<T>(dgate), n * d);
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

// ---- Multi-head self-attention's core in float32 (SelfAttentionFloat32) ----
//
// Per (example, head) matrix the products are small (L x L x Dh: 81 x 81 x 32 at the editors'
// training shape). LibTorch 1.13 without MKL runs bmm as a loop of per-matrix GEMM calls through
// tensor views (a select, as_strided and resolve_conj per operand and matrix) and the softmax, the
// key mask and the dropout as passes of their own; here each matrix's products, mask, softmax and
// dropout run in one pass through buffers that stay in cache.

using Vec8 = float __attribute__((vector_size(32)));  // 8 lanes: ymm under AVX2, two xmm below

// C[R x 16] = A[R x k] . B[k x 16], B's and C's row strides ldb and ldc: R rows of two 8-lane
// accumulators, A's entry broadcast against B's row (the register tile of a GEMM micro-kernel;
// 6 x 16 uses 12 of AVX2's 16 vector registers). A is row-major with row stride lda, or with
// kTransposedA stored as its transpose ([k x R], row stride lda), so that A^T B needs no copy. The
// loops over rows are unrolled by pragma: at -O2 GCC 12 otherwise keeps the accumulators on the
// stack (a third of the speed).
template <int R, bool kTransposedA>
__attribute__((always_inline)) inline void Tile(int64_t k, const float* a, int64_t lda,
                                                const float* b, int64_t ldb, float* c,
                                                int64_t ldc) {
  Vec8 lo[R], hi[R];
#pragma GCC unroll 8
  for (int r = 0; r < R; ++r) lo[r] = hi[r] = Vec8{};
  for (int64_t p = 0; p < k; ++p) {
    Vec8 b0, b1;  // unaligned loads (no helper returns a vector: that would change the ABI)
    std::memcpy(&b0, b + p * ldb, sizeof b0);
    std::memcpy(&b1, b + p * ldb + 8, sizeof b1);
#pragma GCC unroll 8
    for (int r = 0; r < R; ++r) {
      const float x = kTransposedA ? a[p * lda + r] : a[r * lda + p];
      lo[r] += x * b0;
      hi[r] += x * b1;
    }
  }
#pragma GCC unroll 8
  for (int r = 0; r < R; ++r) {
    std::memcpy(c + r * ldc, &lo[r], sizeof lo[r]);
    std::memcpy(c + r * ldc + 8, &hi[r], sizeof hi[r]);
  }
}

// The rows left after the 6-row tiles: `rows` (0 to R) through the tile unrolled for that count.
template <int R, bool kTransposedA>
__attribute__((always_inline)) inline void TailTile(int64_t rows, int64_t k, const float* a,
                                                    int64_t lda, const float* b, int64_t ldb,
                                                    float* c, int64_t ldc) {
  if constexpr (R > 0) {
    if (rows == R)
      Tile<R, kTransposedA>(k, a, lda, b, ldb, c, ldc);
    else
      TailTile<R - 1, kTransposedA>(rows, k, a, lda, b, ldb, c, ldc);
  }
}

// C[m x n] = A[m x k] . B[k x n] (A stored transposed with kTransposedA), row-major with strides
// lda, ldb, ldc (C overwritten): tiles of 6 x 16 and one of the rows left over, then the columns
// past the last multiple of 16 one at a time.
template <bool kTransposedA>
__attribute__((always_inline)) inline void Gemm(int64_t m, int64_t n, int64_t k, const float* a,
                                                int64_t lda, const float* b, int64_t ldb, float* c,
                                                int64_t ldc) {
  const auto row = [&](int64_t i) { return kTransposedA ? a + i : a + i * lda; };
  const int64_t n16 = n / 16 * 16;
  for (int64_t j = 0; j < n16; j += 16) {
    int64_t i = 0;
    for (; i + 6 <= m; i += 6)
      Tile<6, kTransposedA>(k, row(i), lda, b + j, ldb, c + i * ldc + j, ldc);
    TailTile<5, kTransposedA>(m - i, k, row(i), lda, b + j, ldb, c + i * ldc + j, ldc);
  }
  for (int64_t i = 0; i < m; ++i) {
    for (int64_t j = n16; j < n; ++j) {
      float sum = 0;
      for (int64_t p = 0; p < k; ++p)
        sum += (kTransposedA ? a[p * lda + i] : a[i * lda + p]) * b[p * ldb + j];
      c[i * ldc + j] = sum;
    }
  }
}

// C = A B.
MOTIONPIPE_CLONES_AVX2 void GemmNn(int64_t m, int64_t n, int64_t k, const float* a, int64_t lda,
                                   const float* b, int64_t ldb, float* c, int64_t ldc) {
  Gemm<false>(m, n, k, a, lda, b, ldb, c, ldc);
}

// C = A^T B, A given as [k x m] with row stride lda.
MOTIONPIPE_CLONES_AVX2 void GemmTn(int64_t m, int64_t n, int64_t k, const float* a, int64_t lda,
                                   const float* b, int64_t ldb, float* c, int64_t ldc) {
  Gemm<true>(m, n, k, a, lda, b, ldb, c, ldc);
}

// out[c x ldo] = in[r x c]^T (in's row stride ldi); out's columns r..ldo-1 set to 0.
void Transpose(const float* in, int64_t r, int64_t c, int64_t ldi, float* out, int64_t ldo) {
  for (int64_t j = 0; j < c; ++j) {
    float* row = out + j * ldo;
    for (int64_t i = 0; i < r; ++i) row[i] = in[i * ldi + j];
    std::fill(row + r, row + ldo, 0.0f);
  }
}

// One row of the attention weights: p = keep e^(s - max) / sum over the kept keys (keep[j] 1 for a
// key attended to, 0 for an ignored one; the max over kept keys only). A row with no kept key
// attends to every key equally (the finite large negative bias of the LibTorch route rounds every
// score to the same value). s and p may alias.
MOTIONPIPE_CLONES void SoftmaxRow(const float* s, const float* keep, float* p, int64_t l,
                                  bool any_kept) {
  if (!any_kept) {
    std::fill(p, p + l, 1.0f / static_cast<float>(l));
    return;
  }
  float top = -3.0e38f;
#pragma omp simd reduction(max : top)
  for (int64_t j = 0; j < l; ++j) top = std::max(top, keep[j] > 0 ? s[j] : -3.0e38f);
  float sum = 0;
#pragma omp simd reduction(+ : sum)
  for (int64_t j = 0; j < l; ++j) {
    const float e = keep[j] * Exp(s[j] - top);
    p[j] = e;
    sum += e;
  }
  const float inv = 1.0f / sum;
#pragma omp simd
  for (int64_t j = 0; j < l; ++j) p[j] *= inv;
}

// The softmax's backward for one row: ds = p (dp - sum_j dp p), in place over dp.
MOTIONPIPE_CLONES void SoftmaxBackwardRow(const float* p, float* dp, int64_t l) {
  float dot = 0;
#pragma omp simd reduction(+ : dot)
  for (int64_t j = 0; j < l; ++j) dot += dp[j] * p[j];
#pragma omp simd
  for (int64_t j = 0; j < l; ++j) dp[j] = p[j] * (dp[j] - dot);
}

MOTIONPIPE_CLONES void MultiplyInto(float* x, const float* y, int64_t n) {
#pragma omp simd
  for (int64_t j = 0; j < n; ++j) x[j] *= y[j];
}

// The shapes of one call: N examples of H heads, matrices of L x Dh (matrix b = n H + h), on the
// in_proj output qkv [L, N, 3 H Dh] (each token's q, k, v, each of H heads of Dh) and the output
// [L, N, H Dh]; ld_in and ld_out are their row strides (one token).
struct AttentionShape {
  int64_t n, heads, l, d, l16;  // d = Dh; l16: L rounded up to a multiple of 16 (scratch rows)
  int64_t width() const { return heads * d; }
  int64_t ld_in() const { return n * 3 * width(); }
  int64_t ld_out() const { return n * width(); }
  int64_t matrices() const { return n * heads; }
};

AttentionShape CheckAttention(const torch::Tensor& qkv, int64_t heads, const torch::Tensor& padding,
                              const torch::Tensor& dropout_mask) {
  if (qkv.scalar_type() != torch::kFloat || qkv.dim() != 3 || heads <= 0 ||
      qkv.size(2) % (3 * heads) != 0 || qkv.size(2) == 0)
    throw std::invalid_argument(
        "SelfAttentionFloat32: qkv must be float32 [L, N, 3 H Dh] for the given heads");
  const AttentionShape s{qkv.size(1), heads, qkv.size(0), qkv.size(2) / (3 * heads),
                         (qkv.size(0) + 15) / 16 * 16};
  if (padding.defined() &&
      (padding.scalar_type() != torch::kBool || padding.sizes() != torch::IntArrayRef({s.n, s.l})))
    throw std::invalid_argument("SelfAttentionFloat32: padding must be bool [N, L]");
  if (dropout_mask.defined() &&
      (dropout_mask.scalar_type() != torch::kFloat ||
       dropout_mask.sizes() != torch::IntArrayRef({s.matrices(), s.l, s.l})))
    throw std::invalid_argument(
        "SelfAttentionFloat32: the dropout mask must be float32 [N H, L, L]");
  return s;
}

// keep[n][j]: 1 where example n attends to key j, and whether any key of n is kept.
std::pair<std::vector<float>, std::vector<char>> KeptKeys(const torch::Tensor& padding,
                                                          const AttentionShape& s) {
  std::vector<float> keep(static_cast<size_t>(s.n * s.l), 1.0f);
  std::vector<char> any(static_cast<size_t>(s.n), 1);
  if (!padding.defined()) return {keep, any};
  const auto pad = padding.contiguous();
  const bool* ignored = pad.data_ptr<bool>();
  for (int64_t n = 0; n < s.n; ++n) {
    any[n] = 0;
    for (int64_t j = 0; j < s.l; ++j) {
      keep[n * s.l + j] = ignored[n * s.l + j] ? 0.0f : 1.0f;
      any[n] = static_cast<char>(any[n] || !ignored[n * s.l + j]);
    }
  }
  return {keep, any};
}

// One example's rows of qkv [L, N, 3 H Dh] to q, k, v [3, H, L, Dh] in a scratch (q multiplied by
// `scale` as ATen's q * scale rounds it), and back into d_qkv (dq multiplied by `scale` as
// autograd's MulBackward does). The example's rows lie 3 H Dh N floats apart (48 KiB at the
// editors' shape, a multiple of 4 KiB: every row in the same few sets of L1 and L2), so the
// products read their operands from the scratch, where they stay in cache, and each row of qkv is
// touched once per pass. Taking every head apart into [3, N H, L, Dh] first (LibTorch's route, or a
// pass of our own) moves the 4 MB twice more through memory.
// kGather: qkv's rows of example n into blk; else blk into them. The scale multiplies q's part
// on the way either way.
template <bool kGather>
void CopyExample(const AttentionShape& s, int64_t n, float scale, float* qkv, float* blk) {
  for (int64_t i = 0; i < s.l; ++i) {
    float* row = qkv + i * s.ld_in() + n * 3 * s.width();
    for (int64_t part = 0; part < 3; ++part)
      for (int64_t h = 0; h < s.heads; ++h) {
        float* wide = row + part * s.width() + h * s.d;
        float* narrow = blk + ((part * s.heads + h) * s.l + i) * s.d;
        const float* from = kGather ? wide : narrow;
        float* to = kGather ? narrow : wide;
        const float f = part == 0 ? scale : 1.0f;
        for (int64_t j = 0; j < s.d; ++j) to[j] = from[j] * f;
      }
  }
}
void GatherExample(const float* qkv, const AttentionShape& s, int64_t n, float scale, float* blk) {
  CopyExample<true>(s, n, scale, const_cast<float*>(qkv), blk);  // qkv only read
}
void ScatterExample(const float* blk, const AttentionShape& s, int64_t n, float scale, float* qkv) {
  CopyExample<false>(s, n, scale, qkv, const_cast<float*>(blk));  // blk only read
}
// One example's [H, L, Dh] from and to its rows of a [L, N, H Dh] tensor (the output, its
// gradient).
void GatherHeads(const float* wide, const AttentionShape& s, int64_t n, float* blk) {
  for (int64_t i = 0; i < s.l; ++i)
    for (int64_t h = 0; h < s.heads; ++h)
      std::copy_n(wide + i * s.ld_out() + n * s.width() + h * s.d, s.d, blk + (h * s.l + i) * s.d);
}
void ScatterHeads(const float* blk, const AttentionShape& s, int64_t n, float* wide) {
  for (int64_t i = 0; i < s.l; ++i)
    for (int64_t h = 0; h < s.heads; ++h)
      std::copy_n(blk + (h * s.l + i) * s.d, s.d, wide + i * s.ld_out() + n * s.width() + h * s.d);
}

struct AttentionFunction : torch::autograd::Function<AttentionFunction> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& qkv_in,
                               int64_t heads, const c10::optional<torch::Tensor>& padding_in,
                               const c10::optional<torch::Tensor>& mask_in) {
    // The optional arguments come as optionals: autograd's apply takes every Tensor argument for
    // an input of the graph, and an undefined one has no device to record.
    const torch::Tensor padding = padding_in.value_or(torch::Tensor());
    const torch::Tensor dropout_mask = mask_in.value_or(torch::Tensor());
    const AttentionShape s = CheckAttention(qkv_in, heads, padding, dropout_mask);
    const auto qkv = qkv_in.contiguous();
    const auto mask = dropout_mask.defined() ? dropout_mask.contiguous() : dropout_mask;
    const float scale = static_cast<float>(1.0 / std::sqrt(static_cast<double>(s.d)));
    auto out = torch::empty({s.l, s.n, s.width()}, qkv.options());
    auto weights = torch::empty({s.matrices(), s.l, s.l}, qkv.options());  // before dropout
    const auto [keep, any] = KeptKeys(padding, s);
    const float* in = qkv.data_ptr<float>();
    const float* md = mask.defined() ? mask.data_ptr<float>() : nullptr;
    float *od = out.data_ptr<float>(), *pd = weights.data_ptr<float>();
    const int64_t rows = s.l * s.d;  // one matrix of L x Dh
    at::parallel_for(0, s.n, 1, [&](int64_t begin, int64_t end) {
      std::vector<float> blk(static_cast<size_t>(3 * s.heads * rows)),
          heads_out(static_cast<size_t>(s.heads * rows)), kt(static_cast<size_t>(s.d * s.l16)),
          scores(s.l * s.l16);
      for (int64_t n = begin; n < end; ++n) {
        GatherExample(in, s, n, scale, blk.data());
        for (int64_t h = 0; h < s.heads; ++h) {
          const int64_t b = n * s.heads + h;
          const float* q = blk.data() + h * rows;
          const float* k = q + s.heads * rows;
          const float* v = k + s.heads * rows;
          Transpose(k, s.l, s.d, s.d, kt.data(), s.l16);
          GemmNn(s.l, s.l16, s.d, q, s.d, kt.data(), s.l16, scores.data(), s.l16);
          for (int64_t i = 0; i < s.l; ++i) {
            float* row = scores.data() + i * s.l16;
            float* p = pd + (b * s.l + i) * s.l;
            SoftmaxRow(row, keep.data() + n * s.l, p, s.l, any[n] != 0);
            std::copy(p, p + s.l, row);
            if (md) MultiplyInto(row, md + (b * s.l + i) * s.l, s.l);
          }
          GemmNn(s.l, s.d, s.l, scores.data(), s.l16, v, s.d, heads_out.data() + h * rows, s.d);
        }
        ScatterHeads(heads_out.data(), s, n, od);
      }
    });
    ctx->save_for_backward({qkv, weights, mask.defined() ? mask : torch::Tensor()});
    ctx->saved_data["heads"] = heads;
    return out;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &qkv = saved[0], &weights = saved[1], &mask = saved[2];
    const AttentionShape s = CheckAttention(qkv, ctx->saved_data["heads"].toInt(), {}, {});
    const auto d_out = grads[0].contiguous();
    auto d_qkv = torch::empty_like(qkv);  // every entry written below
    const float scale = static_cast<float>(1.0 / std::sqrt(static_cast<double>(s.d)));
    const float *in = qkv.data_ptr<float>(), *pd = weights.data_ptr<float>();
    const float* gd = d_out.data_ptr<float>();
    const float* md = mask.defined() ? mask.data_ptr<float>() : nullptr;
    float* dd = d_qkv.data_ptr<float>();
    const int64_t rows = s.l * s.d;
    at::parallel_for(0, s.n, 1, [&](int64_t begin, int64_t end) {
      std::vector<float> blk(static_cast<size_t>(3 * s.heads * rows)),
          d_blk(static_cast<size_t>(3 * s.heads * rows)), g(static_cast<size_t>(s.heads * rows)),
          vt(static_cast<size_t>(s.d * s.l16)), dp(s.l * s.l16);
      for (int64_t n = begin; n < end; ++n) {
        GatherExample(in, s, n, scale, blk.data());
        GatherHeads(gd, s, n, g.data());
        for (int64_t h = 0; h < s.heads; ++h) {
          const int64_t b = n * s.heads + h;
          const float* q = blk.data() + h * rows;  // scaled
          const float* k = q + s.heads * rows;
          const float* v = k + s.heads * rows;
          float* dq = d_blk.data() + h * rows;  // of the scaled q: ScatterExample applies the scale
          float* dk = dq + s.heads * rows;
          float* dv = dk + s.heads * rows;
          const float* go = g.data() + h * rows;  // dO
          const float* p = pd + b * s.l * s.l;
          // dV = (P o M)^T dO
          const float* weighted = p;  // the weights the values were summed with
          if (md) {                   // dp is free until dP below
            std::copy(p, p + s.l * s.l, dp.data());
            MultiplyInto(dp.data(), md + b * s.l * s.l, s.l * s.l);
            weighted = dp.data();
          }
          GemmTn(s.l, s.d, s.l, weighted, s.l, go, s.d, dv, s.d);
          // dP = (dO V^T) o M, then the softmax's backward in place: dS
          Transpose(v, s.l, s.d, s.d, vt.data(), s.l16);
          GemmNn(s.l, s.l16, s.d, go, s.d, vt.data(), s.l16, dp.data(), s.l16);
          for (int64_t i = 0; i < s.l; ++i) {
            float* row = dp.data() + i * s.l16;
            if (md) MultiplyInto(row, md + (b * s.l + i) * s.l, s.l);
            SoftmaxBackwardRow(p + i * s.l, row, s.l);
          }
          // dQ = dS K, dK = dS^T Q
          GemmNn(s.l, s.d, s.l, dp.data(), s.l16, k, s.d, dq, s.d);
          GemmTn(s.l, s.d, s.l, dp.data(), s.l16, q, s.d, dk, s.d);
        }
        ScatterExample(d_blk.data(), s, n, scale, dd);
      }
    });
    return {d_qkv, torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

torch::Tensor GeluTanhBf16(const torch::Tensor& x) {
  if (x.scalar_type() != torch::kBFloat16)
    throw std::invalid_argument("GeluTanhBf16 takes bf16, not " +
                                std::string(c10::toString(x.scalar_type())));
  return GeluTanhFunction<uint16_t>::apply(x);
}

torch::Tensor GeluTanhFloat32(const torch::Tensor& x) {
  if (x.scalar_type() != torch::kFloat)
    throw std::invalid_argument("GeluTanhFloat32 takes float32, not " +
                                std::string(c10::toString(x.scalar_type())));
  return GeluTanhFunction<float>::apply(x);
}

torch::Tensor ModulatedLayerNormBf16(const torch::Tensor& x, const torch::Tensor& scale,
                                     const torch::Tensor& shift, double eps) {
  return ModulatedLayerNormFunction<uint16_t>::apply(x, scale, shift, eps);
}

torch::Tensor ModulatedLayerNormFloat32(const torch::Tensor& x, const torch::Tensor& scale,
                                        const torch::Tensor& shift, double eps) {
  return ModulatedLayerNormFunction<float>::apply(x, scale, shift, eps);
}

torch::Tensor GatedResidualBf16(const torch::Tensor& x, const torch::Tensor& gate,
                                const torch::Tensor& y) {
  return GatedResidualFunction<uint16_t>::apply(x, gate, y);
}

torch::Tensor GatedResidualFloat32(const torch::Tensor& x, const torch::Tensor& gate,
                                   const torch::Tensor& y) {
  return GatedResidualFunction<float>::apply(x, gate, y);
}

torch::Tensor SelfAttentionFloat32(const torch::Tensor& qkv, int64_t heads,
                                   const torch::Tensor& padding,
                                   const torch::Tensor& dropout_mask) {
  return AttentionFunction::apply(
      qkv, heads, padding.defined() ? c10::optional<torch::Tensor>(padding) : c10::nullopt,
      dropout_mask.defined() ? c10::optional<torch::Tensor>(dropout_mask) : c10::nullopt);
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
