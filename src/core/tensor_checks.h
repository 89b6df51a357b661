// Tensor checks shared by every layer: shapes at public entry points (the message names the argument
// and the shape it got), and which tensors the hand-written CPU kernels take.
#pragma once

#include <torch/torch.h>

#include <initializer_list>

namespace geo {

// Checks `t.dim() == expected.size()` and every size that is not -1.
// Message: "depth must be [B,1,H,W] ... got [2, 3, 4]" style: "<name> must have shape
// [-1, 1, -1, -1] (-1 = any), got [2, 3, 4, 5]".
inline void check_shape(const torch::Tensor& t, const char* name, std::initializer_list<int64_t> expected) {
  TORCH_CHECK(t.defined(), name, " is undefined");
  bool ok = t.dim() == static_cast<int64_t>(expected.size());
  int64_t i = 0;
  for (int64_t e : expected) {
    if (!ok) break;
    ok = e < 0 || t.size(i) == e;
    ++i;
  }
  TORCH_CHECK(ok, name, " must have shape ", c10::IntArrayRef(expected), " (-1 = any), got ", t.sizes());
}

// Whether the hand-written CPU kernels (fused photometric error, FR pooling) take `t`: a CPU
// float32/float64 tensor; anything else goes through the composed tensor operations.
inline bool fused_cpu_kernel_applies(const torch::Tensor& t) {
  return t.device().is_cpu() && (t.scalar_type() == torch::kFloat32 || t.scalar_type() == torch::kFloat64);
}

}  // namespace geo
