// Which vector kernels LibTorch's matrix products run on this CPU, and the CPU features that decide
// it. OpenBLAS (LibTorch's float32 matrix products) picks its kernels once, when it is loaded, from
// the CPU it recognises; a CPU newer than the build (Debian 12's OpenBLAS 0.3.21 on an Intel Xeon
// of family 6, model 207) gets the generic Prescott (SSE3) kernels: float32 matrix products 5 times
// slower than its AVX-512 ones on the same core (bench/mdt_bench's sgemm figure: 17 against 96
// GFLOP/s). LibTorch reaches OpenBLAS only through the plugins (dlopen), so a process can ask for
// the right kernels before the first plugin loads: OPENBLAS_CORETYPE, read by OpenBLAS at load. A
// user's own OPENBLAS_CORETYPE is kept. (LibTorch's own element-wise kernels stay on their default,
// AVX2, on an AVX-512 CPU: asking for its AVX-512 ones, ATEN_CPU_CAPABILITY=avx512, was measured
// and gained nothing here; README "LibTorch's own AVX-512 kernels".)
#pragma once

#include <string>

namespace motionpipe {

// This CPU's vector units, from CPUID (and the OS saving their registers, XCR0): the one reader of
// CPU features for the host's kernel choice and the trainers' precision
// (plugins/common/precision.h).
struct CpuVectorUnits {
  bool avx2_fma = false;     // AVX2 and FMA3
  bool avx512 = false;       // AVX512 F, CD, BW, DQ and VL (OpenBLAS's SkylakeX kernels)
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

}  // namespace motionpipe
