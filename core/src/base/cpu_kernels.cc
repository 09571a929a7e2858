#include "motionpipe/base/cpu_kernels.h"

#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#endif
#include <dlfcn.h>
#include <strings.h>

#include <cstdlib>

#include "motionpipe/base/log.h"

namespace motionpipe {

std::string OpenBlasCoreName(void* handle) {
  using CoreName = char* (*)();
  auto* name = reinterpret_cast<CoreName>(::dlsym(handle, "openblas_get_corename"));
  return name ? name() : "";
}

CpuVectorUnits DetectCpuVectorUnits() {
  static const CpuVectorUnits detected = [] {
    CpuVectorUnits units;
#if defined(__x86_64__) || defined(__i386__)
    unsigned a = 0, b = 0, c = 0, d = 0;
    if (!__get_cpuid_count(1, 0, &a, &b, &c, &d)) return units;
    const bool fma = c & (1u << 12), osxsave = c & (1u << 27), avx = c & (1u << 28);
    if (!osxsave || !avx) return units;
    unsigned xcr0_lo = 0, xcr0_hi = 0;
    __asm__("xgetbv" : "=a"(xcr0_lo), "=d"(xcr0_hi) : "c"(0));
    const bool ymm_saved = (xcr0_lo & 0x6u) == 0x6u;    // SSE and AVX state
    const bool zmm_saved = (xcr0_lo & 0xe6u) == 0xe6u;  // and opmask, ZMM0-15 upper, ZMM16-31
    if (!__get_cpuid_count(7, 0, &a, &b, &c, &d)) return units;
    const bool avx2 = b & (1u << 5);
    const bool avx512f = zmm_saved && (b & (1u << 16));
    units.avx2_fma = ymm_saved && avx2 && fma;
    const unsigned avx512_fcdbwdqvl =
        (1u << 16) | (1u << 17) | (1u << 28) | (1u << 30) | (1u << 31);
    units.avx512 = units.avx2_fma && zmm_saved && (b & avx512_fcdbwdqvl) == avx512_fcdbwdqvl;
    units.amx_bf16 = d & (1u << 22);  // leaf 7, EDX bit 22
    unsigned a1 = 0, b1 = 0, c1 = 0, d1 = 0;
    units.avx512_bf16 = avx512f && __get_cpuid_count(7, 1, &a1, &b1, &c1, &d1) && (a1 & (1u << 5));
#endif
    return units;
  }();
  return detected;
}

std::string BlasKernelsToAsk(const std::string& corename, const CpuVectorUnits& units) {
  // OpenBLAS's x86-64 cores whose kernels use AVX2 and FMA (its dynamic.c names).
  static const char* const kAvx2Cores[] = {"Haswell",        "Zen",      "SkylakeX", "Cooperlake",
                                           "SapphireRapids", "Excavator"};
  for (const char* core : kAvx2Cores) {
    if (!strcasecmp(corename.c_str(), core)) return "";
  }
  if (units.avx512) return "SkylakeX";
  if (units.avx2_fma) return "Haswell";
  return "";
}

BlasKernelChoice PreferNativeBlasKernels() {
  static const BlasKernelChoice choice = [] {
    BlasKernelChoice out;
    if (const char* set = std::getenv("OPENBLAS_CORETYPE"); set && *set) {
      out.asked = set;
      out.note = "OPENBLAS_CORETYPE is set";
      return out;
    }
    if (void* loaded = ::dlopen(kOpenBlasLibrary, RTLD_LAZY | RTLD_NOLOAD)) {
      ::dlclose(loaded);
      out.note = "OpenBLAS was already loaded";
      return out;
    }
    void* blas = ::dlopen(kOpenBlasLibrary, RTLD_LAZY | RTLD_LOCAL);
    if (!blas) {
      out.note = "no OpenBLAS on this machine";
      return out;
    }
    out.detected = OpenBlasCoreName(blas);
    ::dlclose(blas);
    const std::string ask = BlasKernelsToAsk(out.detected, DetectCpuVectorUnits());
    if (ask.empty()) return out;
    if (void* still = ::dlopen(kOpenBlasLibrary, RTLD_LAZY | RTLD_NOLOAD)) {
      ::dlclose(still);
      out.note = "OpenBLAS stayed loaded after its probe";
      MP_LOG(kWarn, "blas")
          << "OpenBLAS chose its " << out.detected
          << " kernels for this CPU and could not be reloaded: set OPENBLAS_CORETYPE=" << ask
          << " for float32 matrix products several times as fast";
      return out;
    }
    ::setenv("OPENBLAS_CORETYPE", ask.c_str(), 0);
    out.asked = ask;
    MP_LOG(kInfo, "blas") << "OpenBLAS chose its generic " << out.detected
                          << " kernels for this CPU, which has "
                          << (ask == "SkylakeX" ? "AVX-512" : "AVX2") << ": asking for " << ask
                          << " (OPENBLAS_CORETYPE)";
    return out;
  }();
  return choice;
}

}  // namespace motionpipe
