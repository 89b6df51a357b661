// Shape checks at public entry points: the message names the argument and the shape it got.
#pragma once

#include <torch/torch.h>

#include <initializer_list>

namespace geo {

// Checks `t.dim() == expected.size()` and every size that is not -1.
// Message: "depth must be [B,1,H,W] ... got [2, 3, 4]" style: "<name> must have shape
// [-1, 1, -1, -1] (-1 = any), got [2, 3, 4, 5]".
inline void check_shape(const torch::Tensor& t, const char* name,
                        std::initializer_list<int64_t> expected) {
  TORCH_CHECK(t.defined(), name, " is undefined");
  bool ok = t.dim() == static_cast<int64_t>(expected.size());
  int64_t i = 0;
  for (int64_t e : expected) {
    if (!ok) break;
    ok = e < 0 || t.size(i) == e;
    ++i;
  }
  TORCH_CHECK(ok, name, " must have shape ", c10::IntArrayRef(expected), " (-1 = any), got ",
              t.sizes());
}

}  // namespace geo
