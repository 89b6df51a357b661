// The stages: section of a config: each training stage (iterations, networks trained, learning
// rate, batch, the loss weights).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

enum class Net { kDepth, kPose, kFlow };
enum class LrScheduleKind { kConstant, kStep };
const std::vector<EnumName<Net>>& enum_names(Net);
const std::vector<EnumName<LrScheduleKind>>& enum_names(LrScheduleKind);

// The networks a stage trains; YAML: a list of names, e.g. [depth, pose].
struct NetworkSet {
  bool depth = false, pose = false, flow = false;
  bool has(Net net) const { return net == Net::kDepth ? depth : net == Net::kPose ? pose : flow; }
  bool empty() const { return !depth && !pose && !flow; }
  std::vector<std::string> names() const;  // in the order depth, pose, flow
  bool operator==(const NetworkSet& o) const { return depth == o.depth && pose == o.pose && flow == o.flow; }
};

// Weights of the total loss, eq. 16 (paper): l_br = 1, l_fr = 1, l_ds = 0.5, l_fs = 0.2, l_fg = 0.2.
struct LossWeights {
  double rigid = 1.0;             // l_br, rigid reconstruction
  double flow = 1.0;              // l_fr, flow reconstruction
  double disp_smooth = 0.5;       // l_ds, disparity smoothness
  double flow_smooth = 0.2;       // l_fs, flow smoothness
  double flow_consistency = 0.2;  // l_fg, geometric consistency
  // Nothing standing on the road lies beyond it (losses/ground_prior.h): 0 in the paper's recipe;
  // configs/video.yaml turns it on for traffic (cars moving with the camera).
  double ground = 0.0;
  // Depth held to the depth of the weights the stage starts from (losses/depth_anchor.h): 0 in the
  // paper's recipe; geo_infer --refine uses 1. A stage that starts from no trained weights (the
  // first stage without init or --init) has nothing to hold to: the term is then off, said once.
  double anchor = 0.0;

  template <class V>
  void fields(V& v) {
    v("rigid", rigid);
    v("flow", flow);
    v("disp_smooth", disp_smooth);
    v("flow_smooth", flow_smooth);
    v("flow_consistency", flow_consistency);
    v("ground", ground);
    v("anchor", anchor);
  }
  void validate(Checker& c) const;
};

// What helps a clip that is unlikely to teach depth (geo_train's warnings say it; docs/video.md).
inline constexpr const char* kHardClipAdvice =
    "A longer clip with more driving helps, or start from a model trained on forward driving: geo_train --init "
    "RUN, which holds that model's depth where the clip cannot teach it (stages[].hold_masked, docs/video.md)";

// One training stage (paper Sec. 4.2). Stages are data, not flags.
struct StageConfig {
  std::string name = "stage1";
  int64_t iterations = 350000;                             // stage 1: 350k (paper); stage 2: 1500k
  NetworkSet train = {true, true, false};                  // networks updated: depth, pose, flow
  double learning_rate = 2e-4;                             // Adam lr (paper Sec. 4.2)
  int batch_size = 4;                                      // paper Sec. 4.2
  LrScheduleKind lr_schedule = LrScheduleKind::kConstant;  // constant | step
  int64_t lr_step = 0;  // step schedule: multiply by lr_gamma every lr_step iterations
  double lr_gamma = 0.5;
  std::string init;  // checkpoint (or run folder) to start from; empty = scratch
  // BatchNorm normalises with, and keeps, the running statistics of the init (eval mode) while the
  // weights train: fine-tuning on a few frames (geo_infer --refine), whose batch statistics would
  // replace what training on many frames measured.
  bool freeze_batch_norm = false;
  // A clip the weights the stage starts from already explain no better than still frames teaches no
  // depth, and fine-tuning depth on it unlearns (docs/video.md: the real stop-and-go traffic frames).
  // A stage that trains depth and starts from trained weights (init, --init, or an earlier stage)
  // first measures, with those weights, the share of pixels auto-masking leaves out on up to
  // kHoldProbeSnippets training snippets (loss.automask); at this share or above the stage holds
  // depth (held_depth()). 0: never (the paper's recipe); configs/video.yaml: 0.65.
  double hold_masked = 0.0;
  LossWeights weights;

  bool trains(Net net) const { return train.has(net); }
  bool uses_flow() const { return train.flow; }  // flow terms are computed only in stages training flow

  template <class V>
  void fields(V& v) {
    v("name", name);
    v("iterations", iterations);
    v("train", train);
    v("learning_rate", learning_rate);
    v("batch_size", batch_size);
    v("lr_schedule", lr_schedule);
    v("lr_step", lr_step);
    v("lr_gamma", lr_gamma);
    v("init", init);
    v("freeze_batch_norm", freeze_batch_norm);
    v("hold_masked", hold_masked);
    v("weights", weights);
  }
  void validate(Checker& c) const;
  // This stage holding depth (hold_masked): the DepthNet is not trained (kept as the stage starts,
  // its BatchNorm statistics included, so no depth anchor); the other networks train as configured.
  // Without another network to train it is the stage as it is.
  StageConfig held_depth() const;
};

// How many training snippets, spread over the data, hold_masked's measurement looks at.
inline constexpr size_t kHoldProbeSnippets = 32;

}  // namespace geo
