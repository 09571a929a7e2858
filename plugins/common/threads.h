// Thread settings for LibTorch in a worker: torch's intra-op pool, its inter-op pool and the BLAS.
// Debian's LibTorch uses the system OpenBLAS (pthreads build), whose own thread pool ignores
// torch::set_num_threads and spins on sched_yield beside the worker's threads; it is sized here too.
#pragma once

#include <torch/torch.h>

#include <dlfcn.h>

#include <algorithm>

namespace motionpipe::nn {

inline void SetTorchThreads(int threads) {
  threads = std::max(1, threads);
  torch::set_num_threads(threads);
  using SetBlasThreads = void (*)(int);
  // The BLAS came in with LibTorch into this plugin's local scope: look for it by name as well.
  void* handles[] = {RTLD_DEFAULT, dlopen("libblas.so.3", RTLD_LAZY | RTLD_NOLOAD), dlopen("libopenblas.so.0", RTLD_LAZY | RTLD_NOLOAD)};
  for (void* handle : handles) {
    if (!handle) continue;
    if (auto* set = reinterpret_cast<SetBlasThreads>(dlsym(handle, "openblas_set_num_threads"))) {
      set(threads);
      break;
    }
  }
}

}  // namespace motionpipe::nn
