// One training update, the only implementation of it: geo_train's loop and geo_bench both run it.
// Also the learning-rate schedule and the one place the Adam optimiser is built (paper Sec. 4.2).
// LibTorch only.
#pragma once

#include "core/config.h"
#include "core/cuda_graph.h"
#include "train/distributed.h"
#include "train/compute_losses.h"

#include <map>
#include <memory>
#include <optional>

namespace geo {

// stages[].lr_schedule: constant, or step (x lr_gamma every lr_step iterations).
struct LrSchedule {
  double base = 2e-4;
  int64_t step = 0;  // 0 = constant
  double gamma = 1.0;

  static LrSchedule of(const StageConfig& stage);
  double at(int64_t iteration) const;  // the rate used for the update that makes `iteration` + 1
};

// torch::optim::Adam's update (same arithmetic, same state objects, same checkpoint format: the
// two load each other's state) done with multi-tensor (_foreach) operations: ~8 launches per
// update for all parameters instead of ~8 per parameter tensor (~300 tensors in GeoNet's
// ResNet-50 networks), which bounds a GPU step by launch overhead. Bit-identical to
// torch::optim::Adam on CPU. amsgrad groups fall back to torch::optim::Adam's loop.
class MultiTensorAdam : public torch::optim::Adam {
 public:
  using torch::optim::Adam::Adam;
  torch::Tensor step(LossClosure closure = nullptr) override;
};

// The state Adam (torch::optim::Adam or MultiTensorAdam) keeps for parameter `p`; nullptr before
// its first update.
const torch::optim::AdamParamState* adam_state_of(const torch::optim::Adam& adam, const torch::Tensor& p);

// Adam (MultiTensorAdam) with the config's betas, eps and weight decay over `parameters`.
std::unique_ptr<torch::optim::Adam> make_adam(const std::vector<torch::Tensor>& parameters, double lr,
                                              const OptimizerConfig& optimizer);

struct StepResult {
  bool finite = false;   // false: NaN/Inf loss or gradient; weights and Adam state untouched
  double grad_norm = 0;  // global L2 norm of the gradients before clipping (when finite)
  std::vector<std::pair<std::string, double>> losses;  // LossTerms::values() of this step
  std::vector<double> camera;  // model.learn_intrinsics: the batch's mean fx, fy, cx, cy (training pixels)
  StepOutput out;              // losses and intermediate maps (for logging and summaries)
};

// The global L2 norm of the defined gradients of `parameters`, on their device (one multi-tensor
// reduction); an undefined tensor when none has a gradient.
torch::Tensor gradient_norm(const std::vector<torch::Tensor>& parameters);

// Binds networks, config and one stage: sets the networks' modes and trainable parameters for the
// stage and builds Adam over them. run() does forward, loss (eq. 16), backward, the finiteness
// check, optional clipping (optimizer.grad_clip) and the Adam update, in one of three ways (Mode).
class TrainStep {
 public:
  enum class Mode {
    // Reads the device twice per step: all loss terms in one copy, then the gradient norm (one
    // multi-tensor reduction); the guard needs both on the host to skip backward and leave weights
    // and Adam untouched. CPU, multi-process training, run.cuda_graphs off.
    kEager,
    // No host read until the update is done: backward always runs, the finiteness check and the
    // clipping factor stay on the device, and LibTorch's fused Adam kernel (_fused_adam_: the same
    // update to rounding, one launch) skips the update where the check failed (found_inf), its step
    // counts on the device. Needs LibTorch >= 2.4; what kGraphed captures. On the CPU for tests
    // only: grid_sample's CPU backward does not survive the NaN coordinates of a NaN batch.
    kDeviceChecks,
    // kDeviceChecks run eagerly for two steps, then captured as one CUDA graph and replayed
    // (core/cuda_graph.h). CUDA with run.cuda_graphs on (the default), one process.
    kGraphed,
  };
  static bool device_checks_available();  // this LibTorch has the fused Adam kDeviceChecks needs

  TrainStep(Networks& nets, const Config& config, const StageConfig& stage);
  ~TrainStep();
  // tgt [B,3,H,W], srcs [B,N,3,H,W], K [B,3,3] on the networks' device.
  StepResult run(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K, double lr);
  torch::optim::Adam& optimizer() { return *adam_; }
  // Distributed training: gradients are averaged over the process group before the finiteness
  // check, clipping and Adam (a non-finite step on any process is skipped by all). `overlap`: each
  // bucket's all-reduce starts during backward, as soon as its gradients exist
  // (run.distributed.overlap); else all start after backward.
  void set_gradient_averager(GradientAverager* averager, bool overlap = false);
  // The depth anchor's teacher (compute_losses); nullptr (the default): no anchor term.
  void set_anchor(DepthNet teacher) { teacher_ = std::move(teacher); }
  // The mode the next run() uses: kGraphed on CUDA with run.cuda_graphs, one process and LibTorch's
  // fused Adam; else kEager. set_mode chooses another before the first run() (tests, geo_bench);
  // a mode this build or device cannot run throws.
  Mode mode() const;
  void set_mode(Mode mode);

 private:
  bool graphs_possible() const;  // a CUDA build, the networks on a CUDA device
  StepResult run_eager(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K, double lr);
  StepResult run_device_checks(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K, double lr);
  // The kDeviceChecks update on static inputs {tgt, srcs, K, lr}: {one float64 vector of the loss
  // terms, the gradient norm, 1 when skipped, and the learned camera's mean fx fy cx cy}.
  std::vector<torch::Tensor> device_update(const std::vector<torch::Tensor>& in);

  Networks& nets_;
  const Config& config_;
  StageConfig stage_;
  std::vector<torch::Tensor> params_;
  std::unique_ptr<torch::optim::Adam> adam_;
  GradientAverager* averager_ = nullptr;
  DepthNet teacher_{nullptr};
  bool overlap_ = false;
  std::optional<Mode> mode_;
  // kDeviceChecks / kGraphed: Adam's step count per parameter on the device (float, as the fused
  // kernel reads it), the graph, the names of the loss terms and the last update's maps.
  std::map<const void*, torch::Tensor> device_steps_;
  std::vector<torch::optim::AdamParamState*> device_states_;  // those the update advances
  std::unique_ptr<CudaGraphCall> graph_;
  std::vector<std::string> loss_names_;
  StepOutput device_out_, graph_out_;  // the last eager update's maps; the capture's
  bool device_updates_started_ = false;
  bool capturing_ = false;
};

}  // namespace geo
