// Which vector kernels LibTorch runs on this CPU, chosen before the first plugin brings LibTorch
// in. Two choices are made when a library loads and can be wrong for a CPU these machines have:
// - OpenBLAS (LibTorch's float32 matrix products) picks its kernels once, when it is loaded, from
//   the CPU it recognises; a CPU newer than the build (Debian 12's OpenBLAS 0.3.21 on an Intel Xeon
//   of family 6, model 207) gets the generic Prescott (SSE3) kernels: float32 matrix products 5
//   times slower than its AVX-512 ones on the same core (bench/mdt_bench's sgemm figure: 17
//   against 96 GFLOP/s). Asked for through OPENBLAS_CORETYPE, read by OpenBLAS at load.
// - LibTorch 1.13's own element-wise and reduction kernels (layer norm, softmax, GELU, AdamW, the
//   casts of bf16 autocast) run their AVX2 builds on an AVX-512 CPU unless ATEN_CPU_CAPABILITY
//   asks for avx512: PyTorch made AVX-512 opt-in in 1.13 because older Intel cores lose clock
//   speed on it (pytorch/pytorch#80252). On the Intel Xeon above one process's training step is
//   1.1-1.4x as fast with them; two workers side by side gain within the noise (README "LibTorch's
//   own AVX-512 kernels"). Read by LibTorch at its first dispatch.
// A user's own OPENBLAS_CORETYPE or ATEN_CPU_CAPABILITY is kept (ATEN_CPU_CAPABILITY=avx2 turns the
// second off).
#pragma once

#include <string>

namespace motionpipe {

// This CPU's vector units, from CPUID (and the OS saving their registers, XCR0): the one reader of
// CPU features for the host's kernel choices and the trainers' precision
// (plugins/common/precision.h).
struct CpuVectorUnits {
  bool avx2_fma = false;     // AVX2 and FMA3
  bool avx512 = false;       // AVX512 F, CD, BW, DQ and VL (OpenBLAS's SkylakeX kernels, ATen's)
  bool avx512_bf16 = false;  // AVX512-BF16 with AVX512F: bf16 dot products
  bool amx_bf16 = false;     // AMX-BF16 (CPUID only)
};

// OpenBLAS's soname, as LibTorch's libblas.so.3 alternative brings it in (Debian's pthreads build).
inline constexpr char kOpenBlasLibrary[] = "libopenblas.so.0";

// The kernels the OpenBLAS behind `handle` (a dlopen handle, or RTLD_DEFAULT where it is linked)
// runs: openblas_get_corename(), or "" where there is no OpenBLAS there.
std::string OpenBlasCoreName(void* handle);

// This CPU's units, read once.
CpuVectorUnits DetectCpuVectorUnits();

// The OPENBLAS_CORETYPE to ask for when OpenBLAS chose `corename` on a CPU with `units`: empty when
// its choice already uses AVX2 (Haswell, Zen, SkylakeX, Cooperlake, ...: the library's own choice
// stands), else "SkylakeX" on an AVX-512 CPU and "Haswell" on an AVX2 one.
std::string BlasKernelsToAsk(const std::string& corename, const CpuVectorUnits& units);

// The ATEN_CPU_CAPABILITY to ask for on a CPU with `units`: "avx512" where it has AVX-512 (LibTorch
// needs F, BW, DQ, VL and FMA3), else empty (LibTorch's own choice, AVX2 or none, stands).
std::string AtenKernelsToAsk(const CpuVectorUnits& units);

struct BlasKernelChoice {
  std::string detected;  // OpenBLAS's own choice ("" when OpenBLAS is not on this machine)
  std::string asked;     // what OPENBLAS_CORETYPE now asks ("" when nothing was set)
  std::string note;      // why nothing could be asked, if so
};

// Before OpenBLAS is loaded in this process: loads it once to read its choice, unloads it and, when
// that choice is generic on a CPU with AVX2 or AVX-512, sets OPENBLAS_CORETYPE for the next load
// (and for child processes). Does nothing when OPENBLAS_CORETYPE is set. When OpenBLAS is already
// loaded it cannot change its kernels any more: the note says so (a process linked with LibTorch
// re-runs itself instead: bench/bench_util.h). Logs what it asked; safe to call more than once.
BlasKernelChoice PreferNativeBlasKernels();

// Sets ATEN_CPU_CAPABILITY=avx512 (for this process's LibTorch and its children) on an AVX-512 CPU
// where the user set none; returns the value LibTorch will read ("" when unset: its default).
// Takes effect only before LibTorch's first operation; logs what it asked, once.
std::string PreferNativeAtenKernels();

// Both, before the first plugin loads (the plugin host) or before main's first LibTorch operation.
inline void PreferNativeCpuKernels() {
  PreferNativeBlasKernels();
  PreferNativeAtenKernels();
}

}  // namespace motionpipe
