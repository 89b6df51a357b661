// geo::Model (include/geo/geo.h): the networks of a checkpoint or exported model file behind an
// inference-only API. Built on the pipeline layer (src/pipeline: Networks, predict_pair and the
// checkpoint format), as training and evaluation are, so inference is the computation geo_eval scores.
#include "geo/geo.h"

#include "core/camera_rule.h"
#include "core/lanes.h"
#include "core/runtime.h"
#include "geometry/pose.h"
#include "geometry/road_plane.h"
#include "geometry/trajectory.h"
#include "models/conv.h"
#include "models/int8.h"
#include "pipeline/checkpoint.h"
#include "pipeline/networks.h"
#include "api/model_impl.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include <cmath>
#include <filesystem>
#include <mutex>
#include <sstream>
#include <utility>

namespace geo {

namespace {

namespace fs = std::filesystem;
namespace F = torch::nn::functional;

ModelSpec public_spec(const NetworkSpec& s, bool has_flow, const std::string& source) {
  return ModelSpec{s.height,       s.width,  s.seq_length, s.model.encoder_depth,
                   s.model.use_fr, has_flow, source,       s.model.learn_intrinsics};
}

// LoadOptions::precision.
bool use_bf16(const std::string& precision, const torch::Device& device) {
  if (precision == "fp32" || precision == "int8") return false;
  if (precision == "bf16") return true;
  if (precision == "auto") return device.is_cpu() && cpu_has_fast_bf16();
  throw Error("precision '" + precision + "' is not one of fp32, bf16, auto, int8");
}

// Networks are created with random weights that the file then replaces: the process's random
// generator is left as it was (a library must not move its user's seeds).
Networks create_quietly(const NetworkSpec& spec, bool with_flow) {
  auto gen = at::detail::getDefaultCPUGenerator();
  at::Tensor state;
  {
    std::lock_guard<std::mutex> lock(gen.mutex());  // not held while creating: that draws from it
    state = gen.get_state();
  }
  Networks n = Networks::create(spec, with_flow);
  std::lock_guard<std::mutex> lock(gen.mutex());
  gen.set_state(state);
  return n;
}

// image [3,H,W] / [B,3,H,W], uint8 or float in [0,1] -> [B,3,h,w] float on the model's device.
torch::Tensor prepare(const Model::Impl& m, const torch::Tensor& image, int64_t* H, int64_t* W, bool* batched,
                      const char* what) {
  if (!image.defined()) throw Error(std::string(what) + ": the image tensor is undefined");
  if (!(image.dim() == 3 || image.dim() == 4) || image.size(-3) != 3)
    throw Error(std::string(what) + ": expected an RGB image [3,H,W] or a batch [B,3,H,W], got " +
                c10::str(image.sizes()));
  if (image.size(-1) < 1 || image.size(-2) < 1)
    throw Error(std::string(what) + ": the image is empty " + c10::str(image.sizes()));
  *batched = image.dim() == 4;
  auto x = *batched ? image : image.unsqueeze(0);
  *H = x.size(2);
  *W = x.size(3);
  if (x.scalar_type() == torch::kUInt8) {
    x = x.to(m.device, torch::kFloat32).div_(255);
  } else if (x.is_floating_point()) {
    x = x.to(m.device, torch::kFloat32);
    // One NaN pixel would make every depth NaN; 0..255 values in a float image would give depth of
    // another scale: both are refused by name rather than computed.
    // One pass and one device sync per image: NaN and infinity propagate into the range.
    const auto range = at::aminmax(x);
    const auto ends = torch::stack({std::get<0>(range), std::get<1>(range)}).to(torch::kCPU, torch::kFloat64);
    const double lo = ends[0].item<double>(), hi = ends[1].item<double>();
    if (!std::isfinite(lo) || !std::isfinite(hi))
      throw Error(std::string(what) + ": " + std::to_string((~torch::isfinite(x)).sum().item<int64_t>()) +
                  " pixel value(s) are NaN or infinite");
    if (lo < -1 || hi > 2)
      throw Error(std::string(what) + ": floating-point pixels must lie in [0, 1], this image spans [" + c10::str(lo) +
                  ", " + c10::str(hi) + "] (divide 0..255 values by 255, or pass uint8)");
  } else {
    throw Error(std::string(what) + ": pixels must be uint8 or floating point, got " + c10::toString(x.scalar_type()));
  }
  if (*H != m.spec.height || *W != m.spec.width)
    x = F::interpolate(x, F::InterpolateFuncOptions()
                              .size(std::vector<int64_t>{m.spec.height, m.spec.width})
                              .mode(torch::kBilinear)
                              .align_corners(false));
  return x.contiguous();
}

// Two images of one size (a pair for flow or the camera), prepared as prepare() does.
struct PreparedPair {
  torch::Tensor a, b;
  int64_t H = 0, W = 0;
  bool batched = false;
};
PreparedPair prepare_pair(const Model::Impl& m, const torch::Tensor& from, const torch::Tensor& to,
                          const std::string& what) {
  PreparedPair p;
  int64_t H2 = 0, W2 = 0;
  bool batched2 = false;
  p.a = prepare(m, from, &p.H, &p.W, &p.batched, (what + " (from)").c_str());
  p.b = prepare(m, to, &H2, &W2, &batched2, (what + " (to)").c_str());
  if (p.H != H2 || p.W != W2 || p.a.size(0) != p.b.size(0))
    throw Error("the two images differ in size: " + c10::str(from.sizes()) + " and " + c10::str(to.sizes()));
  return p;
}

// [B,3,3] intrinsics at the network's size from ones at H x W (or KITTI's proportions); undefined
// when none are given to a model that learns them (predict_pair then uses the learned ones).
torch::Tensor network_K(const Model::Impl& m, const torch::Tensor& K, int64_t B, int64_t H, int64_t W) {
  const double h = static_cast<double>(m.spec.height), w = static_cast<double>(m.spec.width);
  torch::Tensor k;
  if (!K.defined() && m.spec.learns_intrinsics) return {};
  if (!K.defined()) {
    k = kitti_like_intrinsics(m.spec.height, m.spec.width);
  } else {
    k = checked_intrinsics(K, H, W, true);
    k.select(-2, 0).mul_(w / static_cast<double>(W));
    k.select(-2, 1).mul_(h / static_cast<double>(H));
  }
  if (k.dim() == 2) k = k.unsqueeze(0).expand({B, 3, 3});
  return k.to(m.device, torch::kFloat32).contiguous();
}

// [B,C,h,w] -> [B,C,H,W] (bilinear).
torch::Tensor to_size(const torch::Tensor& x, int64_t H, int64_t W) {
  if (x.size(2) == H && x.size(3) == W) return x;
  return F::interpolate(
      x, F::InterpolateFuncOptions().size(std::vector<int64_t>{H, W}).mode(torch::kBilinear).align_corners(false));
}

}  // namespace

// Given intrinsics [3,3] or [B,3,3] of H x W images as float64 on the CPU: finite, and each a
// plausible camera of such an image (camera_problem: the rule of every tool); throws Error.
torch::Tensor checked_intrinsics(const torch::Tensor& K, int64_t H, int64_t W, bool batch_allowed) {
  const bool ok = (K.dim() == 2 && K.size(0) == 3 && K.size(1) == 3) ||
                  (batch_allowed && K.dim() == 3 && K.size(1) == 3 && K.size(2) == 3);
  if (!ok)
    throw Error(std::string("intrinsics must be [3,3]") + (batch_allowed ? " or [B,3,3]" : "") +
                " (pixels of the given image), got " + c10::str(K.sizes()));
  const auto k = K.to(torch::kCPU, torch::kFloat64).clone();
  if (!torch::isfinite(k).all().item<bool>()) throw Error("intrinsics hold NaN or infinity");
  const auto each = k.reshape({-1, 3, 3});
  for (int64_t b = 0; b < each.size(0); ++b) {
    const auto problem = camera_problem(each[b][0][0].item<double>(), each[b][1][1].item<double>(),
                                        each[b][0][2].item<double>(), each[b][1][2].item<double>(), W, H);
    if (!problem.empty()) throw Error("intrinsics: " + problem);
  }
  return k;
}

torch::Tensor rgb8_image(const uint8_t* rgb, int64_t height, int64_t width, int64_t stride) {
  if (!rgb) throw Error("rgb8_image: null pixel pointer");
  if (height < 1 || width < 1) throw Error("rgb8_image: size " + std::to_string(height) + "x" + std::to_string(width));
  if (stride == 0) stride = 3 * width;
  if (stride < 3 * width) throw Error("rgb8_image: row stride " + std::to_string(stride) + " < 3 x width");
  auto hwc = torch::from_blob(const_cast<uint8_t*>(rgb), {height, width, 3}, {stride, 3, 1}, torch::kUInt8);
  return hwc.permute({2, 0, 1}).contiguous();
}

namespace {

// Networks created and loaded -> on the device, eval mode, BatchNorm folded, in the precision asked
// (and LibTorch's threads set where the options ask).
void make_ready(Model::Impl& impl, const LoadOptions& options, bool has_flow, const std::string& source) {
  if (options.threads > 0) torch::set_num_threads(thread_count(options.threads, "threads"));
  impl.device = select_device(options.device);
  impl.nets.to(impl.device);
  const bool bf16 = use_bf16(options.precision, impl.device);
  impl.nets.prepare_inference(true, bf16);
  impl.spec = public_spec(impl.nets.spec, has_flow, source);
  impl.spec.precision = bf16 ? "bf16" : "fp32";
}

Error needs_calibration() {
  return Error(
      "precision 'int8' needs calibration frames (LoadOptions::calibration): a few frames like those the "
      "model will see (or a model file written in int8: geo_export --int8)");
}

}  // namespace

Model Model::create(const std::string& config_yaml, const LoadOptions& options) {
  return guarded("creating an untrained geo model", [&] {
    auto impl = std::make_shared<Impl>();
    impl->nets = Networks::create(NetworkSpec::parse(config_yaml, "the config given"), true);  // the caller seeds
    make_ready(*impl, options, true, "untrained");
    Model model(impl);
    if (options.precision == "int8") {
      if (options.calibration.empty()) throw needs_calibration();
      model.quantize_int8(options.calibration, options.keep_float_weights);
    }
    return model;
  });
}

const std::vector<std::string>& Model::training_configs() const { return impl_->training_configs; }

Model Model::load(const std::string& path, const LoadOptions& options) {
  return guarded("loading geo model '" + path + "'", [&] {
    const std::string file = fs::is_directory(path) ? resolve_checkpoint(path) : path;
    auto impl = std::make_shared<Impl>();
    bool has_flow = false;
    {  // the file's tensors are let go before folding and prepacking add their own copies
      CheckpointFile checkpoint(file);
      impl->int8_only = checkpoint.is_int8_only();
      if (impl->int8_only && options.precision != "int8" && !options.int8_when_calibrated)
        throw Error(file +
                    ": an int8 model file (geo_export --int8: int8 kernels, no float ones) opens in int8 only, "
                    "with the calibration it keeps (asked: " +
                    options.precision +
                    "): open it with precision int8 (geo_infer, geo_eval: --precision int8 without calibration "
                    "frames); for fp32 or bf16, export the checkpoint it came from without --int8");
      if (impl->int8_only && !options.calibration.empty())
        throw Error(file +
                    ": an int8 model file keeps the calibration its int8 kernels were made with: give no "
                    "calibration frames (or calibrate the checkpoint it came from)");
      has_flow = checkpoint.has_flow();
      {
        const UninitialisedWeights every_weight_is_read_next;
        impl->nets = create_quietly(checkpoint.spec(), has_flow);
      }
      checkpoint.load_networks(impl->nets, false, /*int8_kernels=*/true);  // (quantized below)
      if (checkpoint.config()) impl->training_configs = checkpoint.lineage();
      impl->depth_ranges = checkpoint.int8_ranges("depth");
      impl->pose_ranges = checkpoint.int8_ranges("pose");
      impl->flow_ranges = checkpoint.int8_ranges("flow");
      impl->depth_kernels = checkpoint.int8_kernels("depth");
      impl->pose_kernels = checkpoint.int8_kernels("pose");
      impl->flow_kernels = checkpoint.int8_kernels("flow");
    }
    make_ready(*impl, options, has_flow, file);
    Model model(impl);
    // int8: calibrated on the frames given, else with the file's own calibration.
    if (options.precision == "int8" || (options.int8_when_calibrated && model.has_int8_calibration()))
      model.quantize_int8(options.calibration, options.keep_float_weights);
    return model;
  });
}

bool Model::has_int8_calibration() const {
  return impl_->depth_ranges && impl_->pose_ranges && (impl_->flow_ranges || !impl_->nets.flow);
}

const ModelSpec& Model::spec() const { return impl_->spec; }

void Model::check_int8_possible() const {
  if (impl_->spec.precision == "int8") throw Error("the model is int8 already");
  if (impl_->spec.precision != "fp32")
    throw Error("int8 starts from an fp32 model, this one is " + impl_->spec.precision);
  if (!impl_->device.is_cpu()) throw Error("int8 runs on the CPU, this model is on " + impl_->device.str());
  if (select_int8_engine().empty()) throw Error("this LibTorch has no quantized engine (onednn, x86, fbgemm, qnnpack)");
}

void Model::quantize_int8(const std::vector<torch::Tensor>& frames, bool keep_float_weights) {
  guarded("geo::Model::quantize_int8", [&] {
    auto& nets = impl_->nets;
    const bool release = !keep_float_weights || impl_->int8_only;  // (an int8 model file has none to keep)
    // The networks into int8 (quantize_one: with the file's ranges, or those observed); from the
    // first kernel let go on, there is no float model to go back to.
    const auto quantize_all = [&](const auto& quantize_one) {
      if (release) impl_->float_released = true;
      try {
        // The networks are independent: quantized side by side, a network a lane (packing a kernel for
        // oneDNN is serial work: on 2 cores the DepthNet's and the FlowNet's together take the time of
        // the larger).
        std::vector<std::future<void>> done;
        {
          Lanes lanes(plan_lanes(impl_->device.is_cpu() ? at::get_num_threads() : 1, 2));
          done.push_back(lanes.submit([&] { quantize_one(*nets.depth->net, impl_->depth_ranges); }));
          if (nets.flow) done.push_back(lanes.submit([&] { quantize_one(*nets.flow->net, impl_->flow_ranges); }));
          done.push_back(lanes.submit([&] { quantize_one(*nets.pose, impl_->pose_ranges); }));
          for (auto& d : done) d.wait();
        }
        for (auto& d : done) d.get();  // (the first error)
      } catch (const std::exception& e) {
        if (!release) throw;
        throw Error(std::string(e.what()) + " (its float weights were let go as it went: load the model again)");
      }
      impl_->spec.precision = "int8";
#ifdef __GLIBC__
      if (release) malloc_trim(0);  // what quantizing freed lies amid the heap: give its pages back
#endif
    };
    if (frames.empty()) {  // the calibration the file keeps
      const std::string& file = impl_->spec.source;
      if (!impl_->depth_ranges) throw needs_calibration();
      if (nets.flow && !impl_->flow_ranges)
        throw Error(file + " keeps int8 ranges of its DepthNet but not of its FlowNet");
      if (!impl_->pose_ranges)
        throw Error(file +
                    " keeps int8 ranges of its DepthNet but not of its PoseNet (an int8 file of an earlier geo): "
                    "calibrate it again (geo_export --int8, or LoadOptions::calibration)");
      check_int8_possible();
      const int64_t H = impl_->spec.height, W = impl_->spec.width;
      // An int8 model file's kernels as they are (taken: they are then held once, packed).
      const auto kernels_of = [&](const torch::nn::Module& net) -> std::map<std::string, torch::Tensor>& {
        if (&net == nets.pose.get()) return impl_->pose_kernels;
        return &net == nets.depth->net.get() ? impl_->depth_kernels : impl_->flow_kernels;
      };
      quantize_all([&](auto& net, const auto& ranges) {
        geo::quantize_int8(net, *ranges, H, W, release, std::exchange(kernels_of(net), {}));
      });
      return;
    }
    if (impl_->int8_only)
      throw Error(impl_->spec.source +
                  ": an int8 model file is calibrated already (its int8 kernels were made with it)");
    check_int8_possible();
    const size_t needed = nets.flow ? 2 : 1;
    if (frames.size() < needed)
      throw Error(std::to_string(frames.size()) +
                  " calibration frame(s): a model with a FlowNet needs at least 2 "
                  "(consecutive), one without at least 1");
    std::vector<EncoderDecoderImpl*> nets_int8{nets.depth->net.get()};
    if (nets.flow) nets_int8.push_back(nets.flow->net.get());
    try {
      for (auto* n : nets_int8) observe_int8(*n);
      observe_int8(*nets.pose);
      if (nets.flow) {  // the FlowNet sees what flow() gives it: rigid flow of depth and motion
        for (size_t i = 0; i + 1 < frames.size(); ++i) flow_parts(frames[i], frames[i + 1]);
        depth(frames.back());
      } else {
        for (const auto& f : frames) depth(f);
      }
      // The PoseNet sees pairs (relative_pose, flow: `from` repeated) and snippets of consecutive frames (pose).
      const size_t L = static_cast<size_t>(impl_->spec.seq_length);
      for (size_t i = 0; i + 1 < frames.size(); ++i) relative_pose(frames[i], frames[i + 1]);
      if (frames.size() == 1) relative_pose(frames[0], frames[0]);
      for (size_t i = 0; i + L <= frames.size(); ++i)
        pose(std::vector<torch::Tensor>(frames.begin() + static_cast<std::ptrdiff_t>(i),
                                        frames.begin() + static_cast<std::ptrdiff_t>(i + L)));
      quantize_all([&](auto& net, const auto&) { geo::quantize_int8(net, release); });
    } catch (...) {
      if (!impl_->float_released) {  // as it was
        for (auto* n : nets_int8) n->int8.reset();
        nets.pose->int8.reset();
      }
      throw;
    }
  });
}

bool Model::float_weights_released() const { return impl_->float_released; }

torch::Device Model::device() const { return impl_->device; }

torch::Tensor Model::depth(const torch::Tensor& image) const {
  return guarded("geo::Model::depth", [&] {
    torch::InferenceMode guard;
    int64_t H = 0, W = 0;
    bool batched = false;
    const auto x = prepare(*impl_, image, &H, &W, &batched, "depth");
    const auto disp = impl_->nets.depth->forward(x).disp[0];  // [B,1,h,w]
    auto depth = to_size(1.0 / disp, H, W).squeeze(1);
    return batched ? depth : depth[0];
  });
}

torch::Tensor Model::pose(const std::vector<torch::Tensor>& frames) const {
  return guarded("geo::Model::pose", [&] {
    const auto L = static_cast<size_t>(impl_->spec.seq_length);
    if (frames.size() != L)
      throw Error("the PoseNet of this model takes " + std::to_string(L) + " frames, got " +
                  std::to_string(frames.size()));
    torch::InferenceMode guard;
    std::vector<torch::Tensor> x;
    int64_t H = 0, W = 0;
    bool batched = false;
    for (size_t i = 0; i < L; ++i) {
      int64_t h = 0, w = 0;
      x.push_back(prepare(*impl_, frames[i], i == 0 ? &H : &h, i == 0 ? &W : &w, &batched, "pose"));
      if (i > 0 && (h != H || w != W || x[i].size(0) != x[0].size(0)))
        throw Error("frame " + std::to_string(i) + " is " + c10::str(frames[i].sizes()) + " but frame 0 is " +
                    c10::str(frames[0].sizes()) +
                    ": the frames of a snippet (or pair) must have one size, from one camera");
    }
    const size_t k = L / 2;
    std::vector<torch::Tensor> srcs;
    for (size_t i = 0; i < L; ++i)
      if (i != k) srcs.push_back(x[i]);
    const auto vec = impl_->nets.pose->forward(x[k], srcs);  // [B,L-1,6]
    const int64_t B = vec.size(0), N = vec.size(1);
    const auto T = pose_vec_to_matrix(vec.reshape({B * N, 6})).view({B, N, 4, 4});
    return batched ? T : T[0];
  });
}

torch::Tensor Model::relative_pose(const torch::Tensor& from, const torch::Tensor& to,
                                   const torch::Tensor& intrinsics) const {
  (void)intrinsics;  // the PoseNet sees images only; kept for symmetry with flow()
  return guarded("geo::Model::relative_pose", [&] {
    // A snippet with `from` as the target, repeated before it, and `to` after it.
    const auto L = impl_->spec.seq_length, k = L / 2;
    std::vector<torch::Tensor> snippet;
    for (int64_t i = 0; i < L; ++i) snippet.push_back(i <= k ? from : to);
    const auto T = pose(snippet);
    return T.select(T.dim() == 4 ? 1 : 0, k);  // the first frame after the target: `to`
  });
}

torch::Tensor Model::metric_relative_pose(const torch::Tensor& from, const torch::Tensor& to, double camera_height,
                                          const torch::Tensor& intrinsics, std::vector<double>* scale) const {
  std::vector<double> factors;
  metric_depth(from, camera_height, intrinsics, &factors);  // a geo::Error when `from` shows no road
  auto T = relative_pose(from, to, intrinsics);
  return guarded("geo::Model::metric_relative_pose", [&] {
    torch::InferenceMode guard;
    T = T.clone();
    const auto batched = T.dim() == 3 ? T : T.unsqueeze(0);  // a view: scaling it scales T
    for (int64_t b = 0; b < batched.size(0); ++b)
      batched[b].slice(0, 0, 3).select(1, 3).mul_(factors.at(static_cast<size_t>(b)));
    if (scale) *scale = factors;
    return T;
  });
}

torch::Tensor Model::flow(const torch::Tensor& from, const torch::Tensor& to, const torch::Tensor& intrinsics,
                          const torch::Tensor& previous) const {
  return flow_parts(from, to, intrinsics, previous).full;
}

Model::FlowParts Model::flow_parts(const torch::Tensor& from, const torch::Tensor& to, const torch::Tensor& intrinsics,
                                   const torch::Tensor& previous) const {
  return guarded("geo::Model::flow", [&] {
    torch::InferenceMode guard;
    const auto pair = prepare_pair(*impl_, from, to, "flow");
    const auto& a = pair.a;
    const auto& b = pair.b;
    const int64_t H = pair.H, W = pair.W;  // (plain variables: the lambda below captures them)
    const bool batched = pair.batched;
    const auto K = network_K(*impl_, intrinsics, a.size(0), H, W);
    torch::Tensor prev;
    if (previous.defined()) {
      int64_t H3 = 0, W3 = 0;
      bool batched3 = false;
      prev = prepare(*impl_, previous, &H3, &W3, &batched3, "flow (previous)");
    }
    const auto p = predict_pair(impl_->nets, a, b, K, prev);
    auto at_image_size = [&](torch::Tensor f) {  // [B,2,h,w] network pixels -> the images' pixels
      if (f.size(2) != H || f.size(3) != W) {
        f = to_size(f, H, W);
        f.select(1, 0).mul_(static_cast<double>(W) / static_cast<double>(impl_->spec.width));
        f.select(1, 1).mul_(static_cast<double>(H) / static_cast<double>(impl_->spec.height));
      }
      return batched ? f : f[0];
    };
    const auto depth = to_size(1.0 / p.disp, H, W).squeeze(1);  // as depth()
    return FlowParts{at_image_size(p.flow), at_image_size(p.rigid_flow), batched ? depth : depth[0],
                     batched ? p.src_from_tgt : p.src_from_tgt[0]};
  });
}

torch::Tensor Model::intrinsics(const torch::Tensor& from, const torch::Tensor& to) const {
  return guarded("geo::Model::intrinsics", [&] {
    if (!impl_->spec.learns_intrinsics)
      throw Error(
          "this model does not learn the camera (trained with model.learn_intrinsics off): give the intrinsics");
    torch::InferenceMode guard;
    const auto [a, b, H, W, batched] = prepare_pair(*impl_, from, to, "intrinsics");
    const auto L = impl_->spec.seq_length, k = L / 2;
    std::vector<torch::Tensor> srcs;  // as relative_pose: `from` repeated before the target, `to` after
    for (int64_t i = 0; i < L - 1; ++i) srcs.push_back(i < k ? a : b);
    auto K = impl_->nets.pose->predict(a, srcs).K.to(torch::kCPU, torch::kFloat64);  // network pixels
    K.select(1, 0).mul_(static_cast<double>(W) / static_cast<double>(impl_->spec.width));
    K.select(1, 1).mul_(static_cast<double>(H) / static_cast<double>(impl_->spec.height));
    return batched ? K : K[0];
  });
}

void Model::save(const std::string& path, bool half, bool force) const {
  guarded("writing geo model '" + path + "'", [&] {
    // An int8 model without its float kernels is written as an int8 model file (its int8 kernels).
    if (impl_->float_released && impl_->spec.precision != "int8")
      throw Error(
          "quantizing this model to int8 failed part of the way, its float weights partly let go: load it again");
    check_model_file_target("path", path, impl_->spec.source, force);
    write_model_file(path, impl_->nets, half);
  });
}

}  // namespace geo
