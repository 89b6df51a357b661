#include "pipeline/networks.h"

#include <optional>

#include "geometry/camera.h"
#include "geometry/pose.h"
#include "geometry/warp.h"
#include "losses/photometric.h"
#include "losses/rigid_view.h"
#include "models/conv_bn.h"
#include "models/layers.h"

#include <yaml-cpp/yaml.h>

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
  o.zero_init_residual = m.flow_zero_init;
  return o;
}

PoseNetOptions pose_net_options(const NetworkSpec& spec) {
  PoseNetOptions o;
  o.seq_length = spec.seq_length;
  o.learn_intrinsics = spec.model.learn_intrinsics;
  return o;
}

FlowInputSettings FlowInputSettings::of(const LossConfig& loss) {
  return FlowInputSettings{loss.ssim_alpha, loss.image_range, loss.sampler};
}

LossConfig FlowInputSettings::as_loss_config() const {
  LossConfig l;
  l.ssim_alpha = ssim_alpha;
  l.image_range = image_range;
  l.sampler = sampler;
  return l;
}

NetworkSpec NetworkSpec::of(const Config& c) {
  NetworkSpec s;
  s.model = c.model;
  s.height = c.data.height;
  s.width = c.data.width;
  s.seq_length = c.data.seq_length;
  s.flow_input = FlowInputSettings::of(c.loss);
  return s;
}

std::string NetworkSpec::to_yaml() const {
  Config c;
  c.model = model;
  c.data.height = height;
  c.data.width = width;
  c.data.seq_length = seq_length;
  c.loss = flow_input.as_loss_config();
  const YAML::Node all = YAML::Load(geo::to_yaml(c));
  YAML::Node out;
  out["model"] = all["model"];
  for (const char* k : {"height", "width", "seq_length"}) out["data"][k] = all["data"][k];
  for (const char* k : {"ssim_alpha", "image_range", "sampler"}) out["loss"][k] = all["loss"][k];
  YAML::Emitter e;
  e << out;
  return e.c_str();
}

NetworkSpec NetworkSpec::parse(const std::string& yaml, const std::string& source) {
  return of(parse_config(yaml, source));
}

namespace {

// A new network's BatchNorm as the spec says (eps, momentum, and no trained scale without bn_scale).
void style_batchnorm(torch::nn::Module& m, const ModelConfig& model) {
  set_batchnorm_style(m, model.bn_eps, model.bn_momentum);
  if (!model.bn_scale)
    for (auto& gamma : batchnorm_scales(m)) gamma.set_requires_grad(false);
}

}  // namespace

Networks Networks::create(const NetworkSpec& spec, bool with_flow) {
  Networks n;
  n.spec = spec;
  n.depth = DepthNet(depth_net_options(spec.model));
  n.pose = PoseNet(pose_net_options(spec));
  if (with_flow) n.flow = FlowNet(flow_net_options(spec.model));
  style_batchnorm(*n.depth, spec.model);
  style_batchnorm(*n.pose, spec.model);
  if (n.flow) style_batchnorm(*n.flow, spec.model);
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
  if (!s.freeze_batch_norm) return;
  for (torch::nn::Module* net :
       {static_cast<torch::nn::Module*>(depth.get()), static_cast<torch::nn::Module*>(pose.get()),
        flow ? static_cast<torch::nn::Module*>(flow.get()) : nullptr})
    if (net)
      for (const auto& m : net->modules())
        if (m->as<SyncBatchNorm2d>()) m->eval();
}

void Networks::set_trainable(const StageConfig& s) {
  auto set = [&](torch::nn::Module& m, bool on) {
    for (auto& p : m.parameters()) p.set_requires_grad(on);
    if (!spec.model.bn_scale)
      for (auto& gamma : batchnorm_scales(m)) gamma.set_requires_grad(false);
  };
  set(*depth, s.trains(Net::kDepth));
  set(*pose, s.trains(Net::kPose));
  if (flow) set(*flow, s.trains(Net::kFlow));
}

DepthNet Networks::frozen_depth_copy() const {
  DepthNet copy(depth_net_options(spec.model));
  style_batchnorm(*copy, spec.model);
  torch::NoGradGuard no_grad;
  const auto params = depth->named_parameters();
  const auto buffers = depth->named_buffers();
  for (auto& p : copy->named_parameters()) p.value().copy_(params[p.key()]);
  for (auto& b : copy->named_buffers()) b.value().copy_(buffers[b.key()]);
  for (auto& p : copy->parameters()) p.set_requires_grad(false);
  copy->to(params.begin()->value().device());
  copy->eval();
  return copy;
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

std::string architecture_difference(const NetworkSpec& trained, const NetworkSpec& wanted) {
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
  cmp("model.learn_intrinsics", a.learn_intrinsics, b.learn_intrinsics);
  cmp("data.seq_length", trained.seq_length, wanted.seq_length);
  return out;
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

torch::Tensor rigid_flow_net_input(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& rigid_flow,
                                   const LossConfig& loss, torch::Tensor warped, torch::Tensor error_channels,
                                   bool keep_gradient) {
  std::optional<torch::NoGradGuard> no_grad;
  if (!keep_gradient) no_grad.emplace();
  if (!warped.defined() || !error_channels.defined()) {
    const auto view = rigid_view(to_loss_range(src, loss), to_loss_range(tgt, loss), rigid_flow, loss);
    warped = view.warp.image;
    error_channels = view.error_channels;
  }
  return flow_net_input(tgt, src, from_loss_range(warped, loss), rigid_flow, channel_l2_norm(error_channels));
}

PairPrediction predict_pair(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& K,
                            const torch::Tensor& prev) {
  TORCH_CHECK(tgt.dim() == 4 && tgt.size(1) == 3 && src.sizes() == tgt.sizes(), "predict_pair: tgt ", tgt.sizes(),
              " and src ", src.sizes(), " must both be [B,3,H,W]");
  const int64_t L = nets.pose->options.seq_length, before = (L - 1) / 2;
  std::vector<torch::Tensor> snippet;  // sources in time order around the target
  for (int64_t i = 0; i < L - 1; ++i) snippet.push_back(i < before ? (prev.defined() ? prev : tgt) : src);
  PairPrediction p;
  p.disp = nets.depth->forward(tgt).disp[0];
  const auto pose = nets.pose->predict(tgt, snippet);
  p.src_from_tgt = pose_vec_to_matrix(pose.poses.select(1, before));
  // The given camera, else the one the PoseNet learned (model.learn_intrinsics).
  p.K = K.defined() ? K : pose.K;
  TORCH_CHECK(p.K.defined(), "predict_pair: no intrinsics given and the model does not learn them");
  p.rigid_flow = rigid_flow(1.0 / p.disp, p.src_from_tgt, p.K);
  p.flow = p.rigid_flow;
  if (nets.flow)
    p.flow =
        p.rigid_flow +
        nets.flow->forward(rigid_flow_net_input(tgt, src, p.rigid_flow, nets.spec.flow_input.as_loss_config())).flow[0];
  return p;
}

GraphedPairPredictor::GraphedPairPredictor(Networks& nets, const torch::Device& device)
    : graph_(std::make_unique<CudaGraphCall>(
          [&nets](const std::vector<torch::Tensor>& in) {
            const PairPrediction p = predict_pair(nets, in[0], in[1], in[2]);
            return std::vector<torch::Tensor>{p.disp, p.src_from_tgt, p.rigid_flow, p.flow, p.K};
          },
          device)) {}

GraphedPairPredictor::~GraphedPairPredictor() = default;

PairPrediction GraphedPairPredictor::operator()(const torch::Tensor& tgt, const torch::Tensor& src,
                                                const torch::Tensor& K) {
  TORCH_CHECK(K.defined(), "GraphedPairPredictor: give the camera");
  const auto out = (*graph_)({tgt, src, K});
  return PairPrediction{out[0], out[1], out[2], out[3], out[4]};
}

}  // namespace geo
