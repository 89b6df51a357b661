#include "models/int8_engine.h"

#include <ATen/Context.h>
#include <torch/version.h>

#include <algorithm>
#include <utility>
#include <vector>
#if defined(__GNUC__) && defined(__x86_64__)
#include <cpuid.h>
#endif

namespace geo {

std::string select_int8_engine() {
  const auto& supported = at::globalContext().supportedQEngines();
  for (const auto& [engine, name] : std::vector<std::pair<at::QEngine, const char*>> {
         {at::QEngine::ONEDNN, "onednn"},
#if TORCH_VERSION_MAJOR >= 2
             {at::QEngine::X86, "x86"},
#endif
             {at::QEngine::FBGEMM, "fbgemm"}, {
           at::QEngine::QNNPACK, "qnnpack"
         }
       })
    if (std::find(supported.begin(), supported.end(), engine) != supported.end()) {
      at::globalContext().setQEngine(engine);
      return name;
    }
  return "";
}

bool int8_reduced_range() {
#if defined(__GNUC__) && defined(__x86_64__)
  static const bool reduced = [] {
    // AVX-VNNI (which __builtin_cpu_supports does not know in every GCC): CPUID leaf 7, sub-leaf 1, EAX bit 4.
    unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
    const bool avx_vnni = __get_cpuid_count(7, 1, &eax, &ebx, &ecx, &edx) && (eax & (1u << 4));
    return !avx_vnni && !__builtin_cpu_supports("avx512vnni");
  }();
  return reduced;
#else
  return false;
#endif
}

bool int8_dilated_1x1() {
#if defined(__GNUC__) && defined(__x86_64__)
  static const bool amx = [] {
    // AMX-INT8: CPUID leaf 7, sub-leaf 0, EDX bit 25.
    unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
    return __get_cpuid_count(7, 0, &eax, &ebx, &ecx, &edx) && (edx & (1u << 25));
  }();
  return amx;
#else
  return false;
#endif
}

}  // namespace geo
