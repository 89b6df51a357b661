#include "train/compute_losses.h"

#include "core/runtime.h"
#include "losses/depth_anchor.h"
#include "losses/ground_prior.h"
#include "losses/photometric.h"

namespace geo {
namespace {

// A network's forward in run.precision: under bf16 autocast for bf16. The networks return float32
// (their forward casts its outputs), so the losses, warping and geometry run in float32.
template <class F>
auto network_pass(const Config& config, const torch::Device& device, F forward) {
  Bf16Autocast autocast(config.run.precision == Precision::kBf16, device);
  return forward();
}

}  // namespace

StepOutput compute_losses(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K,
                          const StageConfig& stage, const Config& config, DepthNet teacher) {
  const int64_t B = tgt.size(0), N = srcs.size(1);
  std::vector<torch::Tensor> src_list;
  for (int64_t i = 0; i < N; ++i) src_list.push_back(srcs.select(1, i));

  LossInputs in;
  in.tgt = tgt;
  in.srcs = src_list;
  in.K = K;
  {
    // One DepthNet pass over every frame of the snippet (target first, then the sources).
    std::optional<torch::NoGradGuard> frozen;
    if (!stage.trains(Net::kDepth)) frozen.emplace();
    auto frames = torch::cat({tgt.unsqueeze(1), srcs}, 1).flatten(0, 1);  // [B*(N+1),3,H,W]
    auto disp = network_pass(config, tgt.device(), [&] { return nets.depth->forward(frames).disp; });
    // model.num_scales: the losses use the finest num_scales predictions (GeoNet's num_scales).
    disp.resize(std::min(disp.size(), static_cast<size_t>(config.model.num_scales)));
    in.src_disp.assign(N, {});
    for (auto& d : disp) {
      auto per = d.view({B, N + 1, 1, d.size(2), d.size(3)});
      in.tgt_disp.push_back(per.select(1, 0));
      for (int64_t i = 0; i < N; ++i) in.src_disp[i].push_back(per.select(1, i + 1));
    }
  }
  {
    std::optional<torch::NoGradGuard> frozen;
    if (!stage.trains(Net::kPose)) frozen.emplace();
    auto pose = network_pass(config, tgt.device(), [&] { return nets.pose->predict(tgt, src_list); });
    in.poses = pose.poses;
    // model.learn_intrinsics: every warp uses the camera the PoseNet predicts; the data's is ignored.
    if (pose.K.defined()) in.K = pose.K;
  }
  StepOutput out;
  if (nets.pose->options.learn_intrinsics) out.K = in.K;
  out.tgt_disp = in.tgt_disp;
  out.rigid = rigid_terms(in, config.loss);
  const torch::Tensor ground = stage.weights.ground > 0 ? ground_prior(in.tgt_disp[0], in.K) : torch::Tensor();
  torch::Tensor anchor;
  if (teacher && stage.weights.anchor > 0) {
    const torch::Tensor taught = [&] {
      torch::NoGradGuard no_grad;
      return network_pass(config, tgt.device(), [&] { return teacher->forward(tgt).disp[0]; });
    }();
    anchor = depth_anchor(in.tgt_disp[0], taught);
  }
  if (!stage.uses_flow()) {
    out.losses = total_loss(out.rigid, nullptr, stage.weights, ground, anchor);
    return out;
  }
  TORCH_CHECK(nets.flow, "the stage trains flow but no FlowNet was created");
  // Both directions of every source in one FlowNet pass: [fwd_0..fwd_N-1, bwd_0..bwd_N-1].
  // GeoNet's graph (loss.flow_input_gradient): the FlowNet's inputs carry the rigid step's gradient
  // when the stage trains depth or pose with the flow.
  const bool keep = config.loss.flow_input_gradient && (stage.trains(Net::kDepth) || stage.trains(Net::kPose));
  std::vector<torch::Tensor> inputs;
  for (int64_t i = 0; i < N; ++i)
    inputs.push_back(rigid_flow_net_input(tgt, src_list[i], out.rigid.fwd_flow[i][0], config.loss,
                                          out.rigid.fwd_warp[i][0], out.rigid.fwd_error_channels[i], keep));
  for (int64_t i = 0; i < N; ++i)
    inputs.push_back(rigid_flow_net_input(src_list[i], tgt, out.rigid.bwd_flow[i][0], config.loss,
                                          out.rigid.bwd_warp[i][0], out.rigid.bwd_error_channels[i], keep));
  std::optional<torch::NoGradGuard> frozen;
  if (!stage.trains(Net::kFlow)) frozen.emplace();
  auto residual = network_pass(config, tgt.device(), [&] { return nets.flow->forward(torch::cat(inputs, 0)).flow; });
  PerSourceScale<torch::Tensor> bwd_full(N);
  out.fwd_full.assign(N, {});
  const int64_t S = static_cast<int64_t>(out.rigid.fwd_flow[0].size());
  for (int64_t s = 0; s < S && s < static_cast<int64_t>(residual.size()); ++s) {
    auto parts = residual[s].chunk(2 * N, 0);
    for (int64_t i = 0; i < N; ++i) {
      out.fwd_full[i].push_back(parts[i] + out.rigid.fwd_flow[i][s]);
      bwd_full[i].push_back(parts[N + i] + out.rigid.bwd_flow[i][s]);
    }
  }
  frozen.reset();
  out.flow = flow_terms(out.rigid, out.fwd_full, bwd_full, config.loss, stage.weights.flow_consistency);
  out.losses = total_loss(out.rigid, &*out.flow, stage.weights, ground, anchor);
  return out;
}

}  // namespace geo
