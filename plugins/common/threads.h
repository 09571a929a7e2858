// Run-time settings for LibTorch in a worker: torch's intra-op pool, its inter-op pool and the BLAS
// (Debian's LibTorch uses the system OpenBLAS, pthreads build, whose own thread pool ignores
// torch::set_num_threads and spins on sched_yield beside the worker's threads), and the allocator.
#pragma once

#include <ATen/Version.h>
#include <dlfcn.h>
#include <malloc.h>
#include <torch/torch.h>

#include <algorithm>
#include <string>

#include "motionpipe/base/cpu_kernels.h"

namespace motionpipe::nn {

// glibc serves every block over 32 MiB with a fresh mmap and unmaps it on free, so a model whose
// activations are that large (attention scores of long sequences) pays page faults that zero the
// memory again on every step: half of the CPU time in system mode. Heap-only allocation with a
// high trim threshold lets the freed blocks be reused. Done once per process. The threshold holds
// for glibc's main heap only: a worker keeps every thread there (worker::UseMainHeapOnly).
inline void KeepLargeAllocations() {
  static const bool done = [] {
    mallopt(M_MMAP_MAX, 0);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
    return true;
  }();
  (void)done;
}

inline void SetTorchThreads(int threads) {
  KeepLargeAllocations();
  threads = std::max(1, threads);
  torch::set_num_threads(threads);
  using SetBlasThreads = void (*)(int);
  // The BLAS came in with LibTorch into this plugin's local scope: look for it by name as well.
  void* handles[] = {RTLD_DEFAULT, dlopen("libblas.so.3", RTLD_LAZY | RTLD_NOLOAD),
                     dlopen(kOpenBlasLibrary, RTLD_LAZY | RTLD_NOLOAD)};
  for (void* handle : handles) {
    if (!handle) continue;
    if (auto* set = reinterpret_cast<SetBlasThreads>(dlsym(handle, "openblas_set_num_threads"))) {
      set(threads);
      break;
    }
  }
}

// The vector kernels LibTorch's own operations run ("AVX512", "AVX2", "NO AVX"), as
// at::show_config() reports them: AVX2 on an AVX-512 CPU unless ATEN_CPU_CAPABILITY=avx512
// (LibTorch 1.13 made AVX-512 opt-in). LibTorch fixes them at its first dispatch: asking this fixes
// them too.
inline std::string AtenCapabilityInUse() {
  const std::string config = at::show_config();
  const std::string key = "CPU capability usage: ";
  const size_t found = config.find(key);
  if (found == std::string::npos) return "";
  const size_t begin = found + key.size();
  return config.substr(begin, config.find('\n', begin) - begin);
}

}  // namespace motionpipe::nn
