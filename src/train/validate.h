// Validation of one stage on a held-out snippet list: the mean losses of what the stage trains,
// networks in eval mode, no augmentation. LibTorch only.
#pragma once

#include "core/config.h"
#include "data/snippets.h"
#include "train/compute_losses.h"

#include <functional>
#include <memory>
#include <optional>

namespace geo {

struct Validation {
  double rigid = 0;            // mean L_br (photometric, rigid flow)
  std::optional<double> flow;  // mean L_fr (photometric, full flow), when the stage trains flow
  // What selects the stage's best checkpoint: L_br when the stage trains depth or pose, plus L_fr
  // when it trains flow (a flow-only stage, GeoNet's, is ranked by L_fr alone: its frozen depth and
  // pose leave L_br constant).
  double score = 0;
  size_t snippets = 0;
  // loss.automask: the mean share of pixels a still frame explains better than the predicted
  // motion (RigidTerms::automasked), each snippet weighing the same.
  std::optional<double> automasked;
  bool interrupted = false;  // `stop` said so before the pass ended: no score
};

// Restores the stage's train/eval modes before returning. `stop`, asked before every batch, ends
// the pass early (a SIGTERM must not wait for a long validation: schedulers kill soon after it).
Validation validate(Networks& nets, std::shared_ptr<const SnippetSource> source, const StageConfig& stage,
                    const Config& config, const torch::Device& device, const std::function<bool()>& stop = nullptr);

}  // namespace geo
