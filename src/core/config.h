// Typed configuration: YAML parsed once into nested structs, validated, never mutated afterwards.
//
// Each struct lists its keys exactly once, in `fields(v)`: the same list drives parsing (unknown
// keys are errors naming the full key path), emitting the resolved config, and `--set key=value`
// overrides. Defaults are the paper's settings (GeoNet's where the paper is silent); the comment on each says where from.
#pragma once

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace geo {

// Thrown for every configuration problem; the message names the file, key, value and line.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Checker;  // collects validation failures with key paths and YAML lines (config_checks.cpp)

// Enumerated keys: read from YAML by name once, at parsing (an unknown name is a ConfigError listing
// the valid ones), written back by name, compared as values everywhere else.
template <class E> struct EnumName {
  E value;
  const char* name;
};
enum class Upsample { kNearest, kBilinear };
enum class LrScheduleKind { kConstant, kStep };
enum class DataFormat { kAuto, kKittiRaw, kPacked, kSynthetic, kVideo };
enum class Precision { kFp32, kTf32, kBf16 };
enum class BadSample { kStop, kSkip };
enum class Sampler { kZeros, kBorder };
enum class FlowMask { kOcclusion, kConsistency };
enum class FlowReduction { kPerSource, kGeoNet };
enum class Net { kDepth, kPose, kFlow };
const std::vector<EnumName<Upsample>>& enum_names(Upsample);
const std::vector<EnumName<LrScheduleKind>>& enum_names(LrScheduleKind);
const std::vector<EnumName<DataFormat>>& enum_names(DataFormat);
const std::vector<EnumName<Precision>>& enum_names(Precision);
const std::vector<EnumName<BadSample>>& enum_names(BadSample);
const std::vector<EnumName<Sampler>>& enum_names(Sampler);
const std::vector<EnumName<FlowMask>>& enum_names(FlowMask);
const std::vector<EnumName<FlowReduction>>& enum_names(FlowReduction);
const std::vector<EnumName<Net>>& enum_names(Net);

// The YAML name of an enumerated value ("nearest").
template <class E> const char* name_of(E value) {
  for (const auto& n : enum_names(E{}))
    if (n.value == value) return n.name;
  return "?";
}

// The networks a stage trains; YAML: a list of names, e.g. [depth, pose].
struct NetworkSet {
  bool depth = false, pose = false, flow = false;
  bool has(Net net) const { return net == Net::kDepth ? depth : net == Net::kPose ? pose : flow; }
  bool empty() const { return !depth && !pose && !flow; }
  std::vector<std::string> names() const;  // in the order depth, pose, flow
  bool operator==(const NetworkSet& o) const { return depth == o.depth && pose == o.pose && flow == o.flow; }
};

struct ModelConfig {
  int encoder_depth = 50;            // ResNet-50 encoder (paper Sec. 3.1); 18/34 for speed and tests
  bool use_fr = true;                // feature refinement on (paper); false = Table 4 "w/o FR"
  bool fr_encoder = true;            // FR after each residual stage, Refined1..4 (paper)
  bool fr_decoder = true;            // FR after each decoder stage, Refined5..10 (paper)
  int fr_ratio = 16;                 // channel-attention reduction ratio r (paper, CBAM)
  bool fr_spatial_bn = false;        // BatchNorm after the 7x7 spatial conv (CBAM's code; optional)
  Upsample upsample = Upsample::kNearest;  // decoder upsampling: nearest (GeoNet) or bilinear
  int num_scales = 4;                // scales the losses use: full, 1/2, 1/4, 1/8 (GeoNet's num_scales)
  // BatchNorm of every conv+BN layer. GeoNet uses TF-slim's batch_norm: epsilon 1e-3, decay 0.999
  // (= momentum 0.001 in PyTorch's convention) and scale=False (no learned gamma). LibTorch's
  // defaults are eps 1e-5, momentum 0.1, learned gamma.
  double bn_eps = 1e-3;              // GeoNet (slim); LibTorch: 1e-5
  double bn_momentum = 0.001;        // GeoNet (slim decay 0.999); LibTorch: 0.1
  bool bn_scale = false;             // learn gamma: GeoNet false (slim scale=False); LibTorch true
  // The FlowNet's prediction convs start at zero, so stage 2 starts from stage 1's flow (the full
  // flow is the rigid flow until the residual learns); GeoNet: Xavier, a random residual of a few
  // pixels that stage 2 first has to unlearn (docs/geonet_fidelity.md).
  bool flow_zero_init = false;
  // A head on the PoseNet predicts the camera (fx, fy, cx, cy) and the rigid warp uses it instead of
  // the data's intrinsics ("Depth from Videos in the Wild", Gordon et al., ICCV 2019): for footage
  // nobody calibrated. Off: the paper and GeoNet use the calibration. On by itself for data.videos
  // without data.camera.
  bool learn_intrinsics = false;

  template <class V> void fields(V& v) {
    v("encoder_depth", encoder_depth);
    v("use_fr", use_fr);
    v("fr_encoder", fr_encoder);
    v("fr_decoder", fr_decoder);
    v("fr_ratio", fr_ratio);
    v("fr_spatial_bn", fr_spatial_bn);
    v("upsample", upsample);
    v("num_scales", num_scales);
    v("bn_eps", bn_eps);
    v("bn_momentum", bn_momentum);
    v("bn_scale", bn_scale);
    v("flow_zero_init", flow_zero_init);
    v("learn_intrinsics", learn_intrinsics);
  }
  void validate(Checker& c) const;
};

struct AugmentConfig {
  bool enabled = true;              // GeoNet augmentation (data_loader.py)
  double scale_max = 1.15;          // scale x,y by U[1, scale_max] then random-crop back (GeoNet)
  double photometric_prob = 0.5;    // probability of photometric jitter per batch (GeoNet)
  double gamma_min = 0.8, gamma_max = 1.2;              // gamma U[0.8,1.2] (GeoNet)
  double brightness_min = 0.5, brightness_max = 2.0;    // brightness U[0.5,2] (GeoNet)
  double color_min = 0.8, color_max = 1.2;              // per-channel colour U[0.8,1.2] (GeoNet)

  template <class V> void fields(V& v) {
    v("enabled", enabled);
    v("scale_max", scale_max);
    v("photometric_prob", photometric_prob);
    v("gamma_min", gamma_min);
    v("gamma_max", gamma_max);
    v("brightness_min", brightness_min);
    v("brightness_max", brightness_max);
    v("color_min", color_min);
    v("color_max", color_max);
  }
  void validate(Checker& c) const;
};

// data.format synthetic: geo_synth's world rendered in memory at data.height x data.width (no files,
// no OpenCV): the training and validation snippets of the drives geo_synth would write.
struct SynthDataConfig {
  std::string preset = "tiny";       // tiny | kitti: the camera (intrinsics scaled to the training size)
  int64_t seed = 1;                  // the world (as geo_synth --seed)
  int drives = 3;                    // training drives (geo_synth's train_drives)
  int64_t frames_per_drive = 42;     // frames per drive (geo_synth's)

  template <class V> void fields(V& v) {
    v("preset", preset);
    v("seed", seed);
    v("drives", drives);
    v("frames_per_drive", frames_per_drive);
  }
  void validate(Checker& c) const;
};

// The camera of data.videos, in pixels of the original frames: one of intrinsics, calib_file or
// fov_deg (none: the error says which to give). Resizes and crops are applied to it by geo.
struct CameraConfig {
  std::vector<double> intrinsics;    // [fx, fy, cx, cy] in pixels of the original frames
  std::string calib_file;            // KITTI raw calib_cam_to_cam.txt (P_rect_02) or odometry calib.txt (P2)
  double fov_deg = 0;                // horizontal field of view in degrees (fx = fy, principal point centred)

  template <class V> void fields(V& v) {
    v("intrinsics", intrinsics);
    v("calib_file", calib_file);
    v("fov_deg", fov_deg);
  }
  bool given() const { return !intrinsics.empty() || !calib_file.empty() || fov_deg != 0; }
  void validate(Checker& c) const;
};

// How frames of data.videos become training snippets (data/video/frame_selection.h).
struct VideoDataConfig {
  double fps = 10;                   // target frame rate (KITTI's 10 fps); 0 = every frame
  double source_fps = 0;             // frame folders: their frame rate (0 = unknown: no rate subsampling)
  // A frame is static when the fraction of its pixels that changed (by more than 4/255 in a blurred
  // grey thumbnail) since the last kept frame is below this: parked, waiting at lights, a frozen
  // stream. Static frames are left out (GeoNet's static-frame list does so for KITTI); 0 keeps all.
  double static_threshold = 0.05;
  // A frame where enough pixels changed is still left out when the camera stood while other things
  // moved (a truck passing, the traffic ahead): when at least standing_share of the features tracked
  // from the last kept frame moved as a rotation of the camera alone explains, within
  // standing_parallax pixels at a width of 416 (the frame's crop, tracked at up to 416 columns;
  // data/video/camera_motion.h). 0 turns this off.
  double standing_parallax = 0.5;
  double standing_share = 0.5;
  double val_fraction = 0.1;         // frames held out for validation, as whole time blocks (GeoNet: 10%)
  int val_block = 100;               // frames per validation block (10 s at 10 fps)
  bool crop = true;                  // crop to the training aspect ratio before resizing (else stretch)
  double crop_y = 0.5;               // vertical position of the crop: 0 top, 0.5 centre, 1 bottom

  template <class V> void fields(V& v) {
    v("fps", fps);
    v("source_fps", source_fps);
    v("static_threshold", static_threshold);
    v("standing_parallax", standing_parallax);
    v("standing_share", standing_share);
    v("val_fraction", val_fraction);
    v("val_block", val_block);
    v("crop", crop);
    v("crop_y", crop_y);
  }
  void validate(Checker& c) const;
};

struct DataConfig {
  std::string root;                   // dataset root (KITTI raw, packed cache or a geo_synth world)
  DataFormat format = DataFormat::kAuto;  // auto | kitti_raw | packed | synthetic (no files; data.synthetic)
  // Training data of a task: eigen_zhou (depth; the paper's Eigen split), kitti_raw_stereo (flow,
  // GeoNet's: every raw drive on disk but the KITTI 2015 scenes, cameras 02 and 03),
  // raw_minus_kitti2015 (the eigen_zhou lists without the KITTI 2015 scenes), odometry (pose, GeoNet:
  // KITTI odometry `sequences`), or any split folder under configs/splits or <root>/splits.
  std::string split = "eigen_zhou";
  std::vector<std::string> sequences = {"00", "01", "02", "03", "04", "05", "06", "07", "08"};  // odometry split (GeoNet)
  std::string train_list;             // explicit training list; empty = <split>/train_files.txt
  std::string val_list;               // explicit validation list; empty = <split>/val_files.txt
  // Validation of KITTI raw splits: list (the split's validation list, e.g. eigen_zhou's
  // val_files.txt) or geonet (GeoNet's prepare_train_data: 10% of the training snippets, chosen by
  // a fixed hash, held out of training; neighbours of training frames, so an optimistic score).
  std::string val_split = "list";
  int height = 128;                   // training height (paper Sec. 4.2)
  int width = 416;                    // training width (paper Sec. 4.2)
  int seq_length = 3;                 // target in the middle + 2 sources (paper); 5 for odometry
  int num_workers = 2;                // loader threads prefetching batches
  // KITTI raw: leave out the frames of configs/splits/static_frames.txt (SfMLearner's, GeoNet's
  // remove_static). kitti_raw_stereo removes them from the frame list before snippets are formed
  // (a neighbour is the next frame that moves, as GeoNet); list splits drop static targets.
  bool remove_static = true;
  BadSample on_bad_sample = BadSample::kStop;  // stop | skip
  AugmentConfig augment;
  SynthDataConfig synthetic;          // data.format synthetic only
  // data.format video (or auto with videos given): video files (anything OpenCV's VideoCapture
  // reads) and folders of frames (any names, natural sort), one clip each.
  std::vector<std::string> videos;
  CameraConfig camera;                // the clips' camera (data.videos)
  VideoDataConfig video;              // frame rate, static frames, validation blocks (data.videos)

  template <class V> void fields(V& v) {
    v("root", root);
    v("format", format);
    v("split", split);
    v("sequences", sequences);
    v("train_list", train_list);
    v("val_list", val_list);
    v("val_split", val_split);
    v("height", height);
    v("width", width);
    v("seq_length", seq_length);
    v("num_workers", num_workers);
    v("remove_static", remove_static);
    v("on_bad_sample", on_bad_sample);
    v("augment", augment);
    v("synthetic", synthetic);
    v("videos", videos);
    v("camera", camera);
    v("video", video);
  }
  // The data are data.videos: data.format video, or auto with clips given (else data.root's).
  bool uses_videos() const { return format == DataFormat::kVideo || (format == DataFormat::kAuto && !videos.empty()); }
  void validate(Checker& c) const;
};

struct LossConfig {
  double ssim_alpha = 0.85;          // alpha*(1-SSIM)/2 + (1-alpha)*L1 (paper, GeoNet)
  double occ_alpha1 = 0.01;          // occlusion test, eq. 13 alpha1 (paper)
  double occ_alpha2 = 0.5;           // occlusion test, eq. 13 alpha2 (paper)
  double consistency_a = 3.0;        // geometric consistency bound a (eq. 15, GeoNet alpha)
  double consistency_b = 0.05;       // geometric consistency bound b (eq. 15, GeoNet beta)
  bool consistency_scale_factor = true;  // GeoNet multiplies the difference norm by 2^s
  // Range the images are mapped to before the photometric error, the smoothness edge weights and
  // the FlowNet's error channel: GeoNet computes them on its [-1,1] network input (so its L1 term
  // is twice the [0,1] one and its edge weights are exp(-2|grad I|) in [0,1] units); [0, 1] as
  // monodepth2.
  std::vector<double> image_range = {-1.0, 1.0};
  // Out-of-view samples of every warp: zeros (GeoNet's bilinear_sampler returns 0 outside
  // [0,W-1)x[0,H-1)) or border (clamped to the edge pixels).
  Sampler sampler = Sampler::kZeros;
  bool mask_out_of_view = false;     // drop samples that leave the image from L_br and L_fr (off: GeoNet)
  // Mask of the flow reconstruction L_fr: occlusion (paper eq. 13, alpha1/alpha2) or consistency
  // (GeoNet: the eq. 15 mask, consistency_a/consistency_b).
  FlowMask flow_mask = FlowMask::kOcclusion;
  // How L_fr averages over sources: per_source (the masked mean of each source, then the mean over
  // sources: one bad source cannot dominate) or geonet (GeoNet's build_losses: one masked mean over
  // all sources pooled, times num_source / 2, and no mask at all when the stage's l_fg is 0).
  FlowReduction flow_reduction = FlowReduction::kPerSource;
  bool min_reprojection = false;     // per-pixel minimum over sources (monodepth2; off)
  bool automask = false;             // auto-mask static pixels (monodepth2; off)
  // GeoNet's L_br carries a factor num_source / 2 (geonet_model.py: build_losses): 1 for 3-frame
  // snippets, 2 for the 5-frame odometry snippets, where it weighs L_br twice against L_ds.
  bool rigid_source_factor = true;
  // The FlowNet's inputs (rigid flow, rigid warp, its error) keep their gradient in stages that train
  // depth or pose with the flow (GeoNet's graph: L_fr, L_fs and L_fg reach the DepthNet and PoseNet
  // through them as well as through the rigid flow added to the residual); false: computed without.
  bool flow_input_gradient = true;

  template <class V> void fields(V& v) {
    v("ssim_alpha", ssim_alpha);
    v("occ_alpha1", occ_alpha1);
    v("occ_alpha2", occ_alpha2);
    v("consistency_a", consistency_a);
    v("consistency_b", consistency_b);
    v("consistency_scale_factor", consistency_scale_factor);
    v("image_range", image_range);
    v("sampler", sampler);
    v("mask_out_of_view", mask_out_of_view);
    v("flow_mask", flow_mask);
    v("flow_reduction", flow_reduction);
    v("min_reprojection", min_reprojection);
    v("automask", automask);
    v("rigid_source_factor", rigid_source_factor);
    v("flow_input_gradient", flow_input_gradient);
  }
  void validate(Checker& c) const;
};

// Weights of the total loss, eq. 16 (paper): l_br = 1, l_fr = 1, l_ds = 0.5, l_fs = 0.2, l_fg = 0.2.
struct LossWeights {
  double rigid = 1.0;              // l_br, rigid reconstruction
  double flow = 1.0;               // l_fr, flow reconstruction
  double disp_smooth = 0.5;        // l_ds, disparity smoothness
  double flow_smooth = 0.2;        // l_fs, flow smoothness
  double flow_consistency = 0.2;   // l_fg, geometric consistency
  // Nothing standing on the road lies beyond it (losses/ground_prior.h): 0 in the paper's recipe;
  // configs/video.yaml turns it on for traffic (cars moving with the camera).
  double ground = 0.0;

  template <class V> void fields(V& v) {
    v("rigid", rigid);
    v("flow", flow);
    v("disp_smooth", disp_smooth);
    v("flow_smooth", flow_smooth);
    v("flow_consistency", flow_consistency);
    v("ground", ground);
  }
  void validate(Checker& c) const;
};

// One training stage (paper Sec. 4.2). Stages are data, not flags.
struct StageConfig {
  std::string name = "stage1";
  int64_t iterations = 350000;       // stage 1: 350k (paper); stage 2: 1500k
  NetworkSet train = {true, true, false};  // networks updated: depth, pose, flow
  double learning_rate = 2e-4;       // Adam lr (paper Sec. 4.2)
  int batch_size = 4;                // paper Sec. 4.2
  LrScheduleKind lr_schedule = LrScheduleKind::kConstant;  // constant | step
  int64_t lr_step = 0;               // step schedule: multiply by lr_gamma every lr_step iterations
  double lr_gamma = 0.5;
  std::string init;                  // checkpoint (or run folder) to start from; empty = scratch
  // BatchNorm normalises with, and keeps, the running statistics of the init (eval mode) while the
  // weights train: fine-tuning on a few frames (geo_infer --refine), whose batch statistics would
  // replace what training on many frames measured.
  bool freeze_batch_norm = false;
  LossWeights weights;

  bool trains(Net net) const { return train.has(net); }
  bool uses_flow() const { return train.flow; }  // flow terms are computed only in stages training flow

  template <class V> void fields(V& v) {
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
    v("weights", weights);
  }
  void validate(Checker& c) const;
};

struct OptimizerConfig {
  std::string type = "adam";   // Adam (paper Sec. 4.2)
  double beta1 = 0.9;          // paper Sec. 4.2
  double beta2 = 0.999;        // paper Sec. 4.2
  double eps = 1e-8;           // PyTorch / TensorFlow default
  double weight_decay = 0.0;   // none in the paper
  double grad_clip = 0.0;      // max global gradient norm; 0 = off (not in the paper)

  template <class V> void fields(V& v) {
    v("type", type);
    v("beta1", beta1);
    v("beta2", beta2);
    v("eps", eps);
    v("weight_decay", weight_decay);
    v("grad_clip", grad_clip);
  }
  void validate(Checker& c) const;
};

struct LoggingConfig {
  std::string level = "info";        // trace | debug | info | warn | error
  int64_t interval = 100;            // progress line every N iterations
  int64_t summary_interval = 5000;   // visual summaries every N iterations (0 = off)
  int64_t checkpoint_interval = 5000;  // checkpoint every N iterations (and at the end)
  int64_t val_interval = 5000;       // validation every N iterations (0 = off)
  int keep_last = 3;                 // checkpoints kept besides the best
  int max_bad_steps = 10;            // stop after this many NaN/Inf steps in a row

  template <class V> void fields(V& v) {
    v("level", level);
    v("interval", interval);
    v("summary_interval", summary_interval);
    v("checkpoint_interval", checkpoint_interval);
    v("val_interval", val_interval);
    v("keep_last", keep_last);
    v("max_bad_steps", max_bad_steps);
  }
  void validate(Checker& c) const;
};

// Multi-process training on torch.distributed (c10d); used only when geo_train is launched with
// torchrun's or SLURM's environment (train/distributed.h). batch_size is per process.
struct DistributedConfig {
  std::string backend = "auto";  // auto (nccl on CUDA, gloo on CPU) | nccl | gloo
  int timeout_s = 1800;          // a collective waiting longer (a lost or hung peer) fails the run
  bool shard_data = true;        // each process reads its own shard of the stream; false = all read it all
  int64_t verify_interval = 0;   // every N steps compare a checksum of the weights across processes (0 = never)
  // BatchNorm statistics over the batches of all processes (PyTorch's SyncBatchNorm) instead of each
  // process's own (GeoNet at batch 4 per GPU; DDP's default). Costs two small all-reduces per
  // BatchNorm layer and step.
  bool sync_batchnorm = false;
  // Start each gradient bucket's all-reduce during backward, as soon as its gradients exist (as
  // DistributedDataParallel); false: all after backward.
  bool overlap = true;

  template <class V> void fields(V& v) {
    v("backend", backend);
    v("timeout_s", timeout_s);
    v("shard_data", shard_data);
    v("verify_interval", verify_interval);
    v("sync_batchnorm", sync_batchnorm);
    v("overlap", overlap);
  }
  void validate(Checker& c) const;
};

// A device name as geo's options and configs take it: auto, cpu, cuda or cuda:N (N digits), and
// what their errors say otherwise.
bool is_device_name(const std::string& name);
inline constexpr const char* kDeviceNameRule = "must be auto, cpu, cuda or cuda:N";

struct RunConfig {
  std::string name = "geo";     // run folder prefix
  std::string dir = "runs";     // parent folder of run folders
  int64_t seed = 42;            // seeds torch and the data pipeline
  std::string device = "auto";  // auto | cpu | cuda | cuda:N (core/runtime.h: select_device)
  int threads = 0;              // intra-op threads; 0 = all cores
  // Arithmetic of the networks (losses and warping stay fp32): fp32; tf32 (CUDA convolutions and
  // matrix products in TF32 on Ampere and later, PyTorch's default for convolutions; the same as
  // fp32 on CPU); bf16 (the networks under autocast to bfloat16 on CUDA and on CPU, TF32 elsewhere).
  Precision precision = Precision::kTf32;
  // CUDA: cuDNN's deterministic algorithms and no autotuning (run to run the same up to the atomic
  // additions of some backward kernels, e.g. grid_sample's; slower). No effect on CPU.
  bool deterministic = false;
  DistributedConfig distributed;

  template <class V> void fields(V& v) {
    v("name", name);
    v("dir", dir);
    v("seed", seed);
    v("device", device);
    v("threads", threads);
    v("precision", precision);
    v("deterministic", deterministic);
    v("distributed", distributed);
  }
  void validate(Checker& c) const;
};

struct Config {
  ModelConfig model;
  DataConfig data;
  LossConfig loss;
  std::vector<StageConfig> stages = {StageConfig{}};
  OptimizerConfig optimizer;
  LoggingConfig logging;
  RunConfig run;

  template <class V> void fields(V& v) {
    v("model", model);
    v("data", data);
    v("loss", loss);
    v("stages", stages);
    v("optimizer", optimizer);
    v("logging", logging);
    v("run", run);
  }

  // Throws ConfigError listing every problem found (key path, value, YAML line when known).
  void validate() const;

  // Where each key came from: "stages[0].learning_rate" -> 12 (1-based line), for messages.
  std::map<std::string, int> lines;
  std::string source;  // file the config was read from ("<string>" for text)
};

// Parses YAML text. `overrides` are "key.path=value" strings applied before typing (and so
// validated the same way). `source` names the text in messages.
Config parse_config(const std::string& yaml_text, const std::string& source = "<string>",
                    const std::vector<std::string>& overrides = {});

// Reads a YAML file (missing or unreadable file -> ConfigError naming the path).
Config load_config(const std::string& path, const std::vector<std::string>& overrides = {});

// Resolves a config argument: an existing path as given; otherwise a bare name (with or without
// .yaml) is looked up in the shipped configs/ folder. Throws naming every place it looked.
std::string resolve_config_path(const std::string& name);

// The shipped configs/ folder: GEO_CONFIG_DIR, else <prefix>/share/geo/configs beside an installed
// tool (cmake --install), else the source tree's configs/.
std::string shipped_config_dir();

// Every file and folder a config makes a command read: the config file itself, data.root, the
// training and validation lists, the clips, the camera's calibration file and each stage's init.
// What a command's outputs must not replace (core/files.h check_outputs).
std::vector<std::string> config_reads(const Config& config);

// The resolved config as YAML (every key, defaults included). parse_config(to_yaml(c)) == c.
std::string to_yaml(const Config& config);

// The keys whose values differ between two configs written by to_yaml, as "key: A vs B" lines
// (stages[1].batch_size: 4 vs 8), leaving out the keys in `ignore` (dotted paths, a section for all
// its keys).
std::vector<std::string> config_differences(const std::string& yaml_a, const std::string& yaml_b,
                                            const std::vector<std::string>& ignore = {});

}  // namespace geo
