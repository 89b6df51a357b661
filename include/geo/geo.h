// geo's C++ inference API: depth, camera motion and optical flow from a trained geo model, inside
// your own program. Link geo::geo (find_package(geo)); LibTorch is its only public dependency.
//
//   #include <geo/geo.h>
//   geo::LoadOptions options;
//   options.device = "cuda";
//   geo::Model model = geo::Model::load("model.pt", options);  // a geo_export file or a training checkpoint
//   torch::Tensor depth = model.depth(image);             // [H,W] depth (up to scale) at the image's size
//   torch::Tensor motion = model.relative_pose(prev, cur); // [4,4]: points in prev's camera -> cur's camera
//   torch::Tensor metres = model.metric_depth(cur, 1.65);  // depth in metres from the camera's height
//   torch::Tensor step = model.metric_relative_pose(prev, cur, 1.65);  // translation in metres
//   torch::Tensor flow = model.flow(prev, cur);            // [2,H,W] pixels, prev -> cur
//
// Images: torch::Tensor [3,H,W] (or [B,3,H,W]), RGB, uint8 (0..255) or floating point in [0,1],
// any size: resized to the model's input and outputs resized back; or raw interleaved RGB bytes
// through geo::rgb8_image. Intrinsics ([3,3], pixels of the given image) are optional: without them
// KITTI's proportions are assumed (fx = 0.58 W, fy = 1.92 H, principal point at the centre).
//
// A Model is cheap to copy (shared weights) and safe to call from several threads at once; loading
// and calling touch no global state (no seeds; thread counts only when LoadOptions::threads asks).
// Every failure is a geo::Error naming what was wrong.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace geo {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct LoadOptions {
  std::string device = "cpu";  // cpu, cuda, cuda:N, or auto (CUDA when available)
  int threads = 0;             // > 0: set LibTorch's intra-op threads (process-wide); 0: leave them
  // What the networks compute in: "fp32"; "bf16" (weights and arithmetic in bfloat16, outputs
  // float32: ~1.6x faster on CPUs with AVX512-BF16 or AMX, depth within ~1% of fp32); "auto"
  // (bf16 on such a CPU, else fp32); "int8" (CPU: the DepthNet, PoseNet and FlowNet in int8,
  // calibrated on `calibration`; ~3x faster than fp32: see Model::quantize_int8).
  std::string precision = "fp32";
  // int8's calibration frames: see Model::quantize_int8. Not needed for a model file written in
  // int8, which keeps its calibration: an int8 model file (geo_export --int8) keeps its int8
  // kernels instead of the float ones and opens in int8 only; a file saved from an int8 model that
  // kept its float weights also opens in fp32 or bf16, and frames given here replace its calibration.
  std::vector<torch::Tensor> calibration;
  // With "int8": false lets the float kernels go as the int8 ones are made (inference only; see
  // Model::quantize_int8).
  bool keep_float_weights = true;
  // With another precision: a file that keeps an int8 calibration opens in int8 instead, with that
  // calibration (spec().precision says which), as with "int8"; for callers that calibrate int8
  // themselves when the file keeps none (geo_infer --precision int8).
  bool int8_when_calibrated = false;
};

// What a model expects and has (read from the file).
struct ModelSpec {
  int64_t height = 0, width = 0;    // network input size
  int64_t seq_length = 0;           // frames the PoseNet takes (3 or 5)
  int encoder_depth = 0;            // ResNet depth of DepthNet and FlowNet
  bool feature_refinement = false;  // FR attention blocks (the paper)
  bool has_flow = false;            // a FlowNet (else flow() is the rigid flow of depth and motion)
  std::string source;               // the file it was loaded from
  bool learns_intrinsics = false;   // its PoseNet predicts the camera (intrinsics() and the default
                                    // of every `intrinsics` argument below)
  std::string precision = "fp32";   // fp32, bf16 or int8 (LoadOptions::precision resolved)
};

// [3,H,W] uint8 tensor from interleaved RGB bytes (row stride in bytes; 0 = 3 * width). Copies.
torch::Tensor rgb8_image(const uint8_t* rgb, int64_t height, int64_t width, int64_t stride = 0);

// KITTI's proportions at height x width (fx = 0.58 W, fy = 1.92 H, principal point at the centre):
// the intrinsics assumed when none are given. [3,3] float64.
torch::Tensor kitti_like_intrinsics(int64_t height, int64_t width);

// A camera trajectory: camera-to-world poses [N+1,4,4] float64 with the first the identity (KITTI's
// pose files), chained from N motions [4,4] (frame i's camera -> frame i+1's, as relative_pose() and
// FlowParts::motion give them). `scales` (one per step, e.g. Model::sequence_scales) multiply each
// step's translation; empty: the network's own scale.
torch::Tensor chain_poses(const std::vector<torch::Tensor>& motions, const std::vector<double>& scales = {});

// Model::sequence_scales() from each frame's Model::road_scale() (0: no road): the median of the
// frames found within 5 on each side, else the nearest frame's. Throws geo::Error naming a frame
// with no road in any frame of the sequence.
std::vector<double> smooth_road_scales(const std::vector<double>& road_scales);

// A sequence's frames (one camera, in order) for Model::run_sequence and Model::sequence_scales:
// each a [3,H,W] image as Model's methods take them (uint8 or float in [0,1], any size, all the
// same). A source is read from the start as often as asked (metric scale takes a pass of its own),
// one frame at a time: a video of an hour needs no more memory than a few frames.
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // The next frame into `frame`; false after the last.
  virtual bool next(torch::Tensor& frame) = 0;
  // Back to the first frame.
  virtual void restart() = 0;
};

// Frames already in memory.
class TensorFrames : public FrameSource {
 public:
  explicit TensorFrames(std::vector<torch::Tensor> frames) : frames_(std::move(frames)) {}
  bool next(torch::Tensor& frame) override {
    if (i_ >= frames_.size()) return false;
    frame = frames_[i_++];
    return true;
  }
  void restart() override { i_ = 0; }

 private:
  std::vector<torch::Tensor> frames_;
  size_t i_ = 0;
};

// One frame of a sequence as Model::run_sequence hands it on, at the frame's size, on the CPU.
struct SequenceFrame {
  size_t index = 0;     // from 0
  torch::Tensor image;  // the frame as the source gave it
  torch::Tensor depth;  // [H,W] float: depth() times `scale`
  double scale = 1.0;   // the frame's factor (Model::sequence_scales; 1 without one)
  // To the next frame, for models of 3-frame snippets (undefined for the last frame and for 5-frame
  // models): the full and the rigid flow [2,H,W] (Model::flow_parts, the previous frame as the
  // snippet's first) and the motion [4,4] of this frame's camera into the next one's.
  torch::Tensor flow, rigid_flow, motion;
};

class Model {
 public:
  // A file written by geo_export, or a training checkpoint / run folder of geo_train.
  static Model load(const std::string& path, const LoadOptions& options = {});
  // Untrained networks (LibTorch's random initialisation; seed torch first for fixed weights) of a
  // geo config given as YAML text (a configs/*.yaml file's text): its model.*, data.height/width/
  // seq_length and loss.* keys decide them, absent keys take geo's defaults ("{}": the paper's model
  // at 128x416). For measuring speed or trying a program before a model is trained; spec().source
  // is "untrained". Throws geo::Error naming a malformed or unknown key.
  static Model create(const std::string& config_yaml, const LoadOptions& options = {});

  const ModelSpec& spec() const;
  torch::Device device() const;
  // Switches an fp32 model on the CPU to int8 (post-training quantization): the DepthNet, PoseNet
  // and FlowNet run on `frames` in fp32 while the range of every activation is recorded, then their
  // weights are quantized per channel and their activations to 8 bits with those ranges (the
  // PoseNet's last convolution and its pose and camera heads stay in float). Give frames like those the model will see,
  // in order (consecutive pairs calibrate the FlowNet and PoseNet: at least 2 frames for a model
  // with a FlowNet); a few frames suffice (8 is plenty). [3,H,W] uint8 or
  // float images, any size. Copies of this Model share the switch; not to be called while another
  // thread uses the model. Throws geo::Error on a bf16 or CUDA model, or too few frames. save()
  // then writes the calibration with the weights. No frames: the calibration a file written in int8
  // keeps (has_int8_calibration), without running the networks; else an Error.
  // keep_float_weights false: for inference only, each layer that runs in int8 lets go of its float
  // kernel once its int8 one is made (the PoseNet's float layers keep theirs): the model then holds
  // its kernels once, ~3/4 less memory (the paper's model ~470 MB less, and the peak stays the float
  // model's). It runs in int8 only from then on: save() writes an int8 model file (int8 kernels
  // instead of float ones: a quarter of the size, opening in int8 only, faster), and if quantizing
  // fails the model cannot run at all (load it again).
  void quantize_int8(const std::vector<torch::Tensor>& frames, bool keep_float_weights = true);
  bool float_weights_released() const;  // quantize_int8(..., false), or LoadOptions::keep_float_weights
  // Whether the file this model was loaded from keeps an int8 calibration (geo_export --int8, or
  // save() after quantize_int8): quantize_int8({}) then needs no frames.
  bool has_int8_calibration() const;
  // What the weights were trained with, as geo config YAML texts: the training checkpoint's own
  // config first, then those of the checkpoints its training started from (geo_train --init),
  // nearest first; a link that carried none reads "unknown: <why>". Empty for geo_export model
  // files and created models (they carry no training config).
  const std::vector<std::string>& training_configs() const;

  // Depth of each image, at the image's size: [H,W] for [3,H,W], [B,H,W] for [B,3,H,W].
  torch::Tensor depth(const torch::Tensor& image) const;
  // Depth in metres without ground truth: depth() scaled by camera_height / the height of the road
  // plane fitted to it (the lower part of the image must see a flat road; KITTI's camera: 1.65 m).
  // `scale` receives the factor(s) applied. Throws geo::Error naming why when no road is found.
  torch::Tensor metric_depth(const torch::Tensor& image, double camera_height, const torch::Tensor& intrinsics = {},
                             std::vector<double>* scale = nullptr) const;
  // Camera motion from `from` to `to`: the [4,4] transform of points in `from`'s camera frame into
  // `to`'s (translation up to the depth's scale). [B,4,4] for batches.
  torch::Tensor relative_pose(const torch::Tensor& from, const torch::Tensor& to,
                              const torch::Tensor& intrinsics = {}) const;
  // relative_pose() with its translation in metres: scaled by the factor metric_depth() finds for
  // `from` (the frame whose depth the PoseNet's translation shares its scale with). `scale`
  // receives the factor(s). Throws geo::Error naming why when no road is found.
  torch::Tensor metric_relative_pose(const torch::Tensor& from, const torch::Tensor& to, double camera_height,
                                     const torch::Tensor& intrinsics = {}, std::vector<double>* scale = nullptr) const;
  // The PoseNet on a whole snippet of spec().seq_length frames (target = the middle one): [L-1,4,4]
  // transforms from the target's camera into each other frame's, in order.
  torch::Tensor pose(const std::vector<torch::Tensor>& frames) const;
  // Optical flow from `from` to `to` in pixels of the given images: [2,H,W] ([B,2,H,W]): the rigid
  // flow of depth and motion plus the FlowNet's residual when the model has one. `previous`
  // (optional): the frame before `from`, so that the PoseNet sees a real snippet (previous, from, to)
  // instead of (from, from, to).
  torch::Tensor flow(const torch::Tensor& from, const torch::Tensor& to, const torch::Tensor& intrinsics = {},
                     const torch::Tensor& previous = {}) const;
  // flow() with, beside it, the rigid flow of depth and motion alone (no FlowNet residual): what
  // each of the paper's two stages contributes. Same shapes; equal when the model has no FlowNet.
  // The depth and motion the rigid flow was made of come with them, so that a caller that needs all
  // three (geo_infer) runs each network once per frame.
  struct FlowParts {
    torch::Tensor full, rigid;
    torch::Tensor depth;   // `from`'s depth: equal to depth(from)
    torch::Tensor motion;  // [4,4] ([B,4,4]): `from`'s camera -> `to`'s, equal to pose({previous, from, to})[1]
                           // (relative_pose(from, to) without `previous`; 3-frame models)
  };
  FlowParts flow_parts(const torch::Tensor& from, const torch::Tensor& to, const torch::Tensor& intrinsics = {},
                       const torch::Tensor& previous = {}) const;
  // The camera a model with spec().learns_intrinsics predicts for the pair (from, to), in pixels of
  // the given images: [3,3] ([B,3,3] for batches). Models that learn it use it wherever an
  // `intrinsics` argument is left out; others throw geo::Error (they assume KITTI's proportions).
  torch::Tensor intrinsics(const torch::Tensor& from, const torch::Tensor& to) const;

  // Metres per unit of depth for each frame of a sequence (one camera, in order): metric_depth()'s
  // factor per frame, smoothed over 11 frames (the median of the frames found within 5 on each
  // side), so that a frame whose road is hidden takes its neighbours'. `without_road` receives the
  // frames whose own road plane was not found. Throws geo::Error naming a frame with no road within
  // 5 frames. Multiply depth(frames[i]) by it; chain_poses() takes it per step.
  std::vector<double> sequence_scales(const std::vector<torch::Tensor>& frames, double camera_height,
                                      const torch::Tensor& intrinsics = {},
                                      std::vector<size_t>* without_road = nullptr) const;
  // One frame's own factor (metric_depth()'s, for one image [3,H,W]), 0 where no road plane is
  // found: a sequence too long to hold takes it frame by frame, then smooth_road_scales() gives
  // what sequence_scales() gives for the whole sequence.
  double road_scale(const torch::Tensor& frame, double camera_height, const torch::Tensor& intrinsics = {}) const;
  // sequence_scales() of the frames a source gives, read once, one at a time.
  std::vector<double> sequence_scales(FrameSource& frames, double camera_height, const torch::Tensor& intrinsics = {},
                                      std::vector<size_t>* without_road = nullptr) const;

  // A whole sequence, as geo_infer runs it: from the start of `frames`, each frame's depth (times
  // its entry of `scales`, e.g. sequence_scales(); empty: 1) and, with a next frame, the flow and
  // the motion to it (flow_parts(frame, next, intrinsics, previous): each network once per frame),
  // handed to `sink` in order (on the calling thread) while a few frames are held. On the CPU
  // several frames are computed at once, each on its own thread with a share of LibTorch's intra-op
  // threads (2 threads: 2 frames of one thread each; 16: 4 of 4), which a single frame at batch 1
  // cannot use well; at most that many + 3 frames are held. Returns the camera trajectory
  // (chain_poses of the motions, each step scaled by its first frame's factor): [N,4,4] float64
  // for N frames; undefined for one frame or a 5-frame model. `intrinsics`: as flow_parts takes them
  // (pixels of the frames). Throws geo::Error on no frame, frames of different sizes, or scales of
  // another count than the frames.
  torch::Tensor run_sequence(FrameSource& frames, const std::function<void(const SequenceFrame&)>& sink,
                             const std::vector<double>& scales = {}, const torch::Tensor& intrinsics = {}) const;

  // Writes the weights only (no optimiser, no training config) with the spec: geo_export.
  // `half`: weights stored as float16 (half the size; loaded back as float32). An int8 model's file
  // keeps its calibration too: loaded with precision "int8" it needs no frames; one that let go of
  // its float weights keeps its int8 kernels instead of them (see quantize_int8). Refuses (geo::Error)
  // the file this model was loaded from and, unless `force`, an existing file that is not a model
  // file (a training checkpoint holds the optimiser's state and the run's config, which this drops).
  void save(const std::string& path, bool half = false, bool force = false) const;

  struct Impl;

 private:
  explicit Model(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
  void check_int8_possible() const;  // throws geo::Error saying why this model cannot become int8
  std::shared_ptr<Impl> impl_;       // shared by copies; the networks are only read after loading
};

}  // namespace geo
