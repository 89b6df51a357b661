#include "core/runtime.h"

#include <cstdlib>
#include <cstring>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace geo {

void keep_freed_memory() {
  const char* env = std::getenv("GEO_KEEP_MEMORY");
  if (env && std::strcmp(env, "0") == 0) return;
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);                   // large blocks from the heap, reusable after free
  mallopt(M_TRIM_THRESHOLD, -1);            // and never trimmed (-1: "disables trimming", mallopt(3))
  mallopt(M_TOP_PAD, 64 << 20);             // grow the heap in 64 MiB steps
#endif
}

}  // namespace geo
