// Preloaded into a test process (LD_PRELOAD), fills every block that posix_memalign hands out
// (LibTorch's CPU tensors and oneDNN's buffers) with all-ones bytes, a float/double/bfloat16 NaN.
// A kernel that reads memory it never wrote then gives NaN every time, instead of whatever the heap
// held before (usually finite garbage: wrong values that pass unnoticed, or fail depending on what
// ran earlier in the process).
#include <dlfcn.h>

#include <cstddef>
#include <cstring>

namespace {
using PosixMemalign = int (*)(void**, std::size_t, std::size_t);
}

extern "C" int posix_memalign(void** ptr, std::size_t alignment, std::size_t size) {
  static const auto real = reinterpret_cast<PosixMemalign>(dlsym(RTLD_NEXT, "posix_memalign"));
  const int rc = real(ptr, alignment, size);
  if (rc == 0 && *ptr != nullptr) std::memset(*ptr, 0xff, size);
  return rc;
}
