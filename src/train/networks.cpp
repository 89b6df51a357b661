#include "train/networks.h"

#include "core/runtime.h"

#include "core/state_io.h"
#include "geometry/camera.h"
#include "geometry/pose.h"
#include "geometry/warp.h"
#include "losses/photometric.h"
#include "models/layers.h"

#include <sstream>
#include <stdexcept>

namespace geo {

DepthNetOptions depth_net_options(const ModelConfig& m) {
  DepthNetOptions o;
  o.encoder_depth = m.encoder_depth;
  o.use_fr = m.use_fr;
  o.fr_encoder = m.fr_encoder;
  o.fr_decoder = m.fr_decoder;
  o.fr_ratio = m.fr_ratio;
  o.fr_spatial_bn = m.fr_spatial_bn;
  o.upsample = m.upsample == Upsample::kBilinear ? UpsampleMode::kBilinear : UpsampleMode::kNearest;
  return o;
}

FlowNetOptions flow_net_options(const ModelConfig& m) {
  FlowNetOptions o;
  o.backbone = depth_net_options(m);
  return o;
}

PoseNetOptions pose_net_options(const Config& c) {
  PoseNetOptions o;
  o.seq_length = c.data.seq_length;
  return o;
}

Networks Networks::create(const Config& c, bool with_flow) {
  Networks n;
  n.depth = DepthNet(depth_net_options(c.model));
  n.pose = PoseNet(pose_net_options(c));
  if (with_flow) n.flow = FlowNet(flow_net_options(c.model));
  n.learn_bn_scale = c.model.bn_scale;
  const std::vector<torch::nn::Module*> nets = {n.depth.ptr().get(), n.pose.ptr().get(),
                                                n.flow ? static_cast<torch::nn::Module*>(n.flow.ptr().get()) : nullptr};
  for (torch::nn::Module* m : nets) {
    if (!m) continue;
    set_batchnorm_style(*m, c.model.bn_eps, c.model.bn_momentum);
    if (!n.learn_bn_scale)
      for (auto& gamma : batchnorm_scales(*m)) gamma.set_requires_grad(false);
  }
  return n;
}

void Networks::to(const torch::Device& device) {
  depth->to(device);
  pose->to(device);
  if (flow) flow->to(device);
}

void Networks::set_modes(const StageConfig& s) {
  depth->train(s.trains(Net::kDepth));
  pose->train(s.trains(Net::kPose));
  if (flow) flow->train(s.trains(Net::kFlow));
}

void Networks::set_trainable(const StageConfig& s) {
  auto set = [&](torch::nn::Module& m, bool on) {
    for (auto& p : m.parameters()) p.set_requires_grad(on);
    if (!learn_bn_scale)
      for (auto& gamma : batchnorm_scales(m)) gamma.set_requires_grad(false);
  };
  set(*depth, s.trains(Net::kDepth));
  set(*pose, s.trains(Net::kPose));
  if (flow) set(*flow, s.trains(Net::kFlow));
}

std::vector<torch::Tensor> Networks::trainable_parameters() const {
  std::vector<torch::Tensor> out;
  auto add = [&](const torch::nn::Module& m) {
    for (const auto& p : m.parameters())
      if (p.requires_grad()) out.push_back(p);
  };
  add(*depth);
  add(*pose);
  if (flow) add(*flow);
  return out;
}

void Networks::save(torch::serialize::OutputArchive& archive, std::optional<torch::ScalarType> floating) const {
  auto put = [&](const char* key, const torch::nn::Module& m) {
    torch::serialize::OutputArchive sub;
    write_state(m, sub, floating);
    archive.write(key, sub);
  };
  put("depth", *depth);
  put("pose", *pose);
  if (flow) put("flow", *flow);
}

void Networks::load(torch::serialize::InputArchive& archive, const std::string& source,
                    bool allow_missing_flow) {
  auto get = [&](const char* key, torch::nn::Module& m) {
    torch::serialize::InputArchive sub;
    if (!archive.try_read(key, sub)) return false;
    read_state(m, sub, source + " [" + key + "]");
    return true;
  };
  if (!get("depth", *depth)) throw std::runtime_error(source + ": no DepthNet in this checkpoint");
  if (!get("pose", *pose)) throw std::runtime_error(source + ": no PoseNet in this checkpoint");
  if (flow && !get("flow", *flow) && !allow_missing_flow)
    throw std::runtime_error(source + ": no FlowNet in this checkpoint");
}

std::string architecture_difference(const Config& trained, const Config& wanted) {
  const auto& a = trained.model;
  const auto& b = wanted.model;
  std::string out;
  auto cmp = [&out](const char* key, auto x, auto y) {
    if (x == y) return;
    std::ostringstream os;
    os << std::boolalpha << (out.empty() ? "" : ", ") << key << " " << x << " (wanted " << y << ")";
    out += os.str();
  };
  cmp("model.encoder_depth", a.encoder_depth, b.encoder_depth);
  cmp("model.use_fr", a.use_fr, b.use_fr);
  if (a.use_fr && b.use_fr) {
    cmp("model.fr_encoder", a.fr_encoder, b.fr_encoder);
    cmp("model.fr_decoder", a.fr_decoder, b.fr_decoder);
    cmp("model.fr_ratio", a.fr_ratio, b.fr_ratio);
    cmp("model.fr_spatial_bn", a.fr_spatial_bn, b.fr_spatial_bn);
  }
  cmp("model.bn_scale", a.bn_scale, b.bn_scale);
  cmp("data.seq_length", trained.data.seq_length, wanted.data.seq_length);
  return out;
}

std::optional<Config> checkpoint_config(torch::serialize::InputArchive& archive, const std::string& source) {
  c10::IValue yaml;
  if (!archive.try_read("config", yaml) || !yaml.isString()) return std::nullopt;
  return parse_config(yaml.toStringRef(), source + " [config]");
}

void Networks::prepare_inference(bool fold, bool bf16) {
  const torch::Dtype dtype = bf16 ? torch::kBFloat16 : torch::kFloat32;
  auto prepare = [fold, dtype](torch::nn::Module& m, torch::Dtype& compute_dtype) {
    m.eval();
    if (fold) fold_batchnorm(m, dtype);  // from the float32 weights
    m.to(dtype);
    compute_dtype = dtype;
  };
  prepare(*depth, depth->compute_dtype);
  prepare(*pose, pose->compute_dtype);
  if (flow) prepare(*flow, flow->compute_dtype);  // null for checkpoints without a FlowNet
}

namespace {

// A network's forward in run.precision: under bf16 autocast for bf16. The networks return float32
// (their forward casts its outputs), so the losses, warping and geometry run in float32.
template <class F>
auto network_pass(const Config& config, const torch::Device& device, F forward) {
  Bf16Autocast autocast(config.run.precision == Precision::kBf16, device);
  return forward();
}

}  // namespace

StepOutput compute_losses(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& srcs,
                          const torch::Tensor& K, const StageConfig& stage, const Config& config) {
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
    in.poses = network_pass(config, tgt.device(), [&] { return nets.pose->forward(tgt, src_list); });
  }
  StepOutput out;
  out.tgt_disp = in.tgt_disp;
  out.rigid = rigid_terms(in, config.loss);
  if (!stage.uses_flow()) {
    out.losses = total_loss(out.rigid, nullptr, stage.weights);
    return out;
  }
  TORCH_CHECK(nets.flow, "the stage trains flow but no FlowNet was created");
  // Both directions of every source in one FlowNet pass: [fwd_0..fwd_N-1, bwd_0..bwd_N-1].
  std::vector<torch::Tensor> inputs;
  // The warps are in the loss range (loss.image_range); flow_net_input takes [0,1] images.
  for (int64_t i = 0; i < N; ++i)
    inputs.push_back(flow_net_input(tgt, src_list[i], from_loss_range(out.rigid.fwd_warp[i][0].detach(), config.loss),
                                    out.rigid.fwd_flow[i][0].detach(), out.rigid.fwd_error_norm[i].detach()));
  for (int64_t i = 0; i < N; ++i)
    inputs.push_back(flow_net_input(src_list[i], tgt, from_loss_range(out.rigid.bwd_warp[i][0].detach(), config.loss),
                                    out.rigid.bwd_flow[i][0].detach(), out.rigid.bwd_error_norm[i].detach()));
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
  out.flow = flow_terms(out.rigid, out.fwd_full, bwd_full, config.loss);
  out.losses = total_loss(out.rigid, &*out.flow, stage.weights);
  return out;
}

PairPrediction predict_pair(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& src,
                            const torch::Tensor& K, const LossConfig& loss, const torch::Tensor& prev) {
  TORCH_CHECK(tgt.dim() == 4 && tgt.size(1) == 3 && src.sizes() == tgt.sizes(), "predict_pair: tgt ",
              tgt.sizes(), " and src ", src.sizes(), " must both be [B,3,H,W]");
  const int64_t L = nets.pose->options.seq_length, before = (L - 1) / 2;
  std::vector<torch::Tensor> snippet;  // sources in time order around the target
  for (int64_t i = 0; i < L - 1; ++i) snippet.push_back(i < before ? (prev.defined() ? prev : tgt) : src);
  PairPrediction p;
  p.disp = nets.depth->forward(tgt).disp[0];
  p.src_from_tgt = pose_vec_to_matrix(nets.pose->forward(tgt, snippet).select(1, before));
  p.rigid_flow = rigid_flow(1.0 / p.disp, p.src_from_tgt, K);
  p.flow = p.rigid_flow;
  if (nets.flow) {
    // As in training (compute_losses): warp and error in the loss range.
    const auto warped = warp(to_loss_range(src, loss), p.rigid_flow, out_of_view(loss)).image;
    const auto error =
        channel_l2_norm(photometric_error_channels(warped, to_loss_range(tgt, loss), loss.ssim_alpha));
    p.flow = p.rigid_flow + nets.flow->forward(flow_net_input(tgt, src, from_loss_range(warped, loss),
                                                              p.rigid_flow, error)).flow[0];
  }
  return p;
}

}  // namespace geo
