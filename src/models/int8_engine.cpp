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

namespace {

// Whether CPUID leaf 7, sub-leaf `subleaf`, sets `bit` of register EAX (0) or EDX (3) on this CPU
// (false away from x86-64).
bool cpuid7_bit(unsigned subleaf, int reg, unsigned bit) {
#if defined(__GNUC__) && defined(__x86_64__)
  unsigned r[4] = {0, 0, 0, 0};
  return __get_cpuid_count(7, subleaf, &r[0], &r[1], &r[2], &r[3]) && (r[reg] & (1u << bit));
#else
  (void)subleaf, (void)reg, (void)bit;
  return false;
#endif
}

}  // namespace

bool int8_reduced_range() {
#if defined(__GNUC__) && defined(__x86_64__)
  // AVX-VNNI (which __builtin_cpu_supports does not know in every GCC): sub-leaf 1, EAX bit 4.
  static const bool reduced = !cpuid7_bit(1, 0, 4) && !__builtin_cpu_supports("avx512vnni");
  return reduced;
#else
  return false;
#endif
}

bool int8_dilated_1x1() {
  static const bool amx = cpuid7_bit(0, 3, 25);  // AMX-INT8: sub-leaf 0, EDX bit 25
  return amx;
}

}  // namespace geo
