// The optimizer: section of a config (Adam's settings).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

struct OptimizerConfig {
  std::string type = "adam";  // Adam (paper Sec. 4.2)
  double beta1 = 0.9;         // paper Sec. 4.2
  double beta2 = 0.999;       // paper Sec. 4.2
  double eps = 1e-8;          // PyTorch / TensorFlow default
  double weight_decay = 0.0;  // none in the paper
  double grad_clip = 0.0;     // max global gradient norm; 0 = off (not in the paper)

  template <class V>
  void fields(V& v) {
    v("type", type);
    v("beta1", beta1);
    v("beta2", beta2);
    v("eps", eps);
    v("weight_decay", weight_decay);
    v("grad_clip", grad_clip);
  }
  void validate(Checker& c) const;
};

}  // namespace geo
