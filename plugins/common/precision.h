// Mixed precision for training on CPUs with bf16 matrix units (AVX512-BF16, AMX): while a
// `MixedPrecision` guard is alive, LibTorch's CPU autocast runs matrix products (linear, matmul,
// bmm, addmm, conv) in bfloat16 and keeps the numerically sensitive ops in float32; the weights,
// their gradients and the optimiser's moments stay float32 (they are never cast in place).
// Measured here (issue 15): a bf16 matrix product runs 2.2-2.4x as fast as OpenBLAS's float32 one
// on one core; how much of a training step that saves, bench/mdt_bench and bench/train_bench print
// (the bf16/f32 column). On a CPU without them (no AVX512-BF16, no AMX) LibTorch's bf16 products
// fall back to a reference path: 25x slower than float32 on a Zen 3 EPYC (issue 15), so a
// trainer asked for bf16 there runs in float32 (`EffectivePrecision`).
#pragma once

#include <ATen/autocast_mode.h>
#include <torch/torch.h>

#include <cstdint>
#include <stdexcept>
#include <string>

#include "motionpipe/base/cpu_kernels.h"

namespace motionpipe::nn {

enum class Precision { kFloat32, kBf16 };

// "float32" or "bf16"; anything else is an error naming the value and where it came from.
inline Precision ParsePrecision(const std::string& value, const std::string& where) {
  if (value == "float32") return Precision::kFloat32;
  if (value == "bf16") return Precision::kBf16;
  throw std::invalid_argument(where + " must be float32 or bf16, not '" + value + "'");
}

inline const char* PrecisionName(Precision p) { return p == Precision::kBf16 ? "bf16" : "float32"; }

// Whether this CPU multiplies bf16 natively: AVX512-BF16 on an AVX-512 CPU whose OS saves the
// AVX-512 state, or AMX-BF16 (motionpipe/base/cpu_kernels.h reads CPUID). Only x86 is read;
// elsewhere (an ARM CPU's BF16 extension included) it answers false, and bf16 runs as float32.
inline bool CpuHasNativeBf16() {
  const CpuVectorUnits units = DetectCpuVectorUnits();
  return units.avx512_bf16 || units.amx_bf16;
}

// What `CpuHasNativeBf16` found, in words for a benchmark's or a log's header.
inline const char* Bf16ProductsOnThisCpu() {
  return CpuHasNativeBf16()
             ? "native (AVX512-BF16 or AMX)"
             : "emulated (no AVX512-BF16, no AMX: the train stage runs float32 instead)";
}

// The precision a training runs in: bf16 only where the CPU multiplies bf16 natively; asked for
// bf16 elsewhere, float32 (the same losses within bf16's rounding, README "Training in bf16"),
// since emulated bf16 products cost many times float32's.
inline Precision EffectivePrecision(Precision requested, bool native_bf16) {
  return requested == Precision::kBf16 && !native_bf16 ? Precision::kFloat32 : requested;
}

// Scope guard: bf16 autocast on the CPU for the forward pass run inside it (the backward pass
// follows the dtypes the forward chose, so it may run outside). Restores the previous state and,
// when the outermost guard closes, frees the bf16 copies of the weights autocast cached for the
// scope (they are stale after the optimiser's step).
class MixedPrecision {
 public:
  explicit MixedPrecision(Precision p) : on_(p == Precision::kBf16) {
    if (!on_) return;
    was_enabled_ = at::autocast::is_cpu_enabled();
    was_dtype_ = at::autocast::get_autocast_cpu_dtype();
    at::autocast::set_cpu_enabled(true);
    at::autocast::set_autocast_cpu_dtype(at::kBFloat16);
    at::autocast::increment_nesting();
  }
  ~MixedPrecision() {
    if (!on_) return;
    if (at::autocast::decrement_nesting() == 0) at::autocast::clear_cache();
    at::autocast::set_cpu_enabled(was_enabled_);
    at::autocast::set_autocast_cpu_dtype(was_dtype_);
  }
  MixedPrecision(const MixedPrecision&) = delete;
  MixedPrecision& operator=(const MixedPrecision&) = delete;

 private:
  bool on_;
  bool was_enabled_ = false;
  at::ScalarType was_dtype_ = at::kBFloat16;
};

}  // namespace motionpipe::nn
