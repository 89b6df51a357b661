#include "core/runtime.h"

#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include <torch/cuda.h>
#include <torch/version.h>
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

namespace geo {

torch::Device select_device(const std::string& name) {
  if (name == "auto") return torch::cuda::is_available() ? torch::Device(torch::kCUDA, 0) : torch::Device(torch::kCPU);
  if (name == "cpu") return torch::kCPU;
  if (name == "cuda" || name.rfind("cuda:", 0) == 0) {
    if (!torch::cuda::is_available())
      throw std::runtime_error("device '" + name + "' requested, but CUDA is not available here (LibTorch " +
                               std::string(TORCH_VERSION) +
                               " built without CUDA, or no GPU visible); use --device cpu or auto");
    torch::Device d(torch::kCUDA, 0);
    if (name.size() > 5) {
      try {
        d = torch::Device(name);
      } catch (const c10::Error&) {
        throw std::runtime_error("device '" + name + "' is not a device name (auto, cpu, cuda, cuda:N)");
      }
    }
    const auto count = static_cast<int64_t>(torch::cuda::device_count());
    if (d.index() >= count)
      throw std::runtime_error("device '" + name + "': this machine has " + std::to_string(count) + " CUDA device(s)");
    return d;
  }
  throw std::runtime_error("device '" + name + "' is not one of auto, cpu, cuda, cuda:N");
}

}  // namespace geo
