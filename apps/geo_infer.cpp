// geo_infer: what a trained model sees, for an image, a folder of frames or a video.
//   geo_infer --checkpoint runs/x|model.pt --input frame.png|frames/|clip.mp4 --output out/
// Writes per frame <name>-disp.png (colour-mapped disparity) and <name>-depth.png (uint16, depth x
// 256 in the network's scale, which monocular training leaves unknown); for consecutive frames also
// <name>-flow.png (colour wheel, full flow to the next frame) and trajectory.txt (KITTI pose file,
// camera-to-world, chained from the PoseNet's relative poses). With --camera-height (metres above
// the road, KITTI: 1.65) depth and trajectory are in metres: each frame's scale from the road plane
// fitted to its depth, smoothed over 11 frames (frames without a road take their neighbours').
// A sequence also gets trajectory.png (top view; with --ground-truth the KITTI pose file drawn
// beside it, scale-aligned) and, from a video or with --videos, disp.avi and flow.avi; --ply writes
// coloured point clouds of chosen frames. Frames are read as they are needed (at most three at a
// time, those of one snippet), so an hour of video takes the memory of a few frames.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>

#include <unistd.h>

#include "core/camera_rule.h"
#include "core/logging.h"
#include "core/output_folder.h"
#include "core/files.h"
#include "core/progress.h"
#include "data/kitti/calib.h"
#include "data/cv_tensor.h"
#include "data/image_io.h"
#include "data/point_cloud.h"
#include "data/text_io.h"
#include "data/video/frame_stream.h"
#include "data/visual_outputs.h"
#include "eval/metrics.h"
#include "infer/report.h"
#include "train/refine.h"
#include "app_options.h"
#include "open_model.h"
#include "geo/geo.h"

namespace fs = std::filesystem;

namespace {

struct InferOptions {
  std::string checkpoint, input, output, device = "auto", precision = "fp32", ground_truth;
  std::vector<double> intrinsics;
  std::vector<int64_t> ply_frames;
  int64_t max_frames = 0, calibration_frames = 0;  // 0: 8 with --precision int8
  int64_t refine = 0;                              // 0: off
  std::string refine_run;
  double refine_anchor = geo::kRefineAnchor;
  bool refine_anchor_given = false;  // (even at its default: it means nothing without --refine)
  double camera_height = 0, ply_max_depth = 0;
  int threads = 0;
  bool videos = false, timing = false, force = false, report = false;
};

void add_options(CLI::App& app, InferOptions& o) {
  app.add_option("--checkpoint", o.checkpoint, "checkpoint file, run folder or geo_export model file")->required();
  app.add_option("--input", o.input, "an image, a folder of frames (natural order: 2 before 10) or a video file")
      ->required();
  app.add_option("--output", o.output, "output folder (created)")->required();
  geo::app::add_device_option(app, o.device, "default: auto");
  geo::app::add_precision_option(
      app, o.precision, {"fp32", "bf16", "auto", "int8"},
      "fp32, bf16 (faster on CPUs with AVX512-BF16/AMX, depth within ~1%), auto (bf16 on such a "
      "CPU) or int8 (CPU: the networks in int8, with the calibration a geo_export --int8 file keeps, else "
      "calibrated on the input's first frames)");
  app.add_option("--calibration-frames", o.calibration_frames,
                 "with --precision int8: calibrate on this many of the input's first frames, 1..1000 (default: 8, "
                 "and none for a model file that keeps its calibration; an int8 model file cannot be calibrated again)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--intrinsics", o.intrinsics,
                 "fx fy cx cy of the input images in pixels (default: KITTI-like 0.58 W, 1.92 H, W/2, H/2)")
      ->expected(4);
  app.add_option("--max-frames", o.max_frames, "stop after this many frames (0 = all)");
  app.add_option("--camera-height", o.camera_height,
                 "the camera's height above the road in metres (KITTI: 1.65): depth and trajectory in metres")
      ->check(geo::app::above_zero());
  app.add_option("--ground-truth", o.ground_truth,
                 "KITTI pose file of the input's frames (odometry poses/XX.txt): drawn in trajectory.png beside the "
                 "estimate, scale-aligned")
      ->check(CLI::ExistingFile);
  app.add_flag("--videos", o.videos, "write disp.avi and flow.avi for a frame folder too (always for a video input)");
  app.add_option("--ply", o.ply_frames, "frame numbers (from 0) to write as coloured point clouds <name>.ply")
      ->check(geo::app::non_negative());
  app.add_option("--ply-max-depth", o.ply_max_depth,
                 "leave out points farther than this (default: 80 with --camera-height, else 20x the frame's median "
                 "depth: the sky)")
      ->check(geo::app::above_zero());
  app.add_option("--threads", o.threads, "LibTorch's intra-op threads (0 = all cores)")
      ->check(geo::app::non_negative());
  app.add_flag("--timing", o.timing,
               "print the time of each step (reading, networks, colour maps, encoding, ...) per frame");
  app.add_flag("--report", o.report,
               "also write report.html: input, disparity and flow side by side (up to 60 frames spread over the clip, "
               "each input as <name>-input.jpg), the trajectory, the camera, the scale and the time of each step; "
               "it opens offline in any browser");
  app.add_option("--refine", o.refine,
                 "first train this many iterations on the input itself (test-time refinement: depth and pose adapt "
                 "to the clip, with configs/video.yaml's settings and the camera of --intrinsics or the model's), then "
                 "predict with the refined networks; for short or hard clips (docs/video.md)")
      ->check(CLI::Range(int64_t{1}, int64_t{1000000}));
  app.add_option("--refine-anchor", o.refine_anchor,
                 "with --refine: how strongly depth is held to the model's own (stages[].weights.anchor): 1 keeps "
                 "what the model learned where the clip teaches little (traffic moving with the camera); 0 lets the "
                 "clip reshape depth freely (docs/video.md)")
      ->check(CLI::Range(0.0, 1000.0))
      ->each([&o](const std::string&) { o.refine_anchor_given = true; });
  app.add_option("--refine-run", o.refine_run,
                 "with --refine: the refinement's run folder, kept (train.log, checkpoints, refined.pt: a model file "
                 "for later runs); default: a temporary folder, removed at the end");
  app.add_flag("--force", o.force,
               "write into a non-empty --output: the files geo_infer wrote there before (geo_infer-outputs.txt lists "
               "them) are removed first, nothing else");
}

// The input as geo_infer names its frames, known before any output is written: each frame's name
// (at most --max-frames) and the rate.
struct Input {
  std::vector<std::string> names;
  double fps = 10;  // a frame folder's (KITTI's); a video's own
  bool video = false;
  size_t size() const { return names.size(); }
};

// The input's frames in order, one at a time, at the model's size: uint8 [3,h,w] for 8-bit input
// (a quarter of float's memory; geo::Model takes it as it is), float [0,1] for 16-bit frames.
class FrameReader {
 public:
  FrameReader(const InferOptions& o, int64_t h, int64_t w) : o_(o), stream_(o.input, "--input"), h_(h), w_(w) {}
  // The next frame; false after the last (or --max-frames). With `image` null a frame folder's file
  // is passed over unread (a video's frame is decoded all the same: nothing else counts them).
  bool next(std::string& name, torch::Tensor* image) {
    if (o_.max_frames > 0 && stream_.index() + 1 >= o_.max_frames) return false;
    cv::Mat m;
    if (!stream_.next(name, image ? &m : nullptr)) return false;
    if (image) *image = geo::resized_mat_to_frame(m, h_, w_, o_.input + " [" + name + "]");
    return true;
  }
  const geo::FrameStream& stream() const { return stream_; }

 private:
  const InferOptions& o_;
  geo::FrameStream stream_;
  int64_t h_, w_;
};

// The input surveyed: its frames' names and rate. `each`, when given, receives every frame
// (at the model's size) as it is decoded; otherwise a frame folder's files are
// not read (a video is decoded through: nothing else counts its frames).
Input survey(const InferOptions& o, int64_t h, int64_t w, const std::function<void(const torch::Tensor&)>& each = {}) {
  FrameReader reader(o, h, w);
  // Two files of one name (000001.png, 000001.jpg) would write the same outputs.
  std::map<std::string, std::string> by_name;
  for (const auto& f : reader.stream().files()) {
    const auto [it, fresh] = by_name.emplace(fs::path(f).stem().string(), f);
    if (!fresh)
      throw std::runtime_error("'" + std::min(it->second, f) + "' and '" + std::max(it->second, f) +
                               "' would write the same outputs (" + it->first + "-*.png): keep one of them in '" +
                               o.input + "'");
  }
  Input input;
  input.video = reader.stream().is_video();
  if (reader.stream().fps() > 0) input.fps = reader.stream().fps();
  std::string name;
  torch::Tensor image;
  while (reader.next(name, each ? &image : nullptr)) {
    if (each) each(image);
    input.names.push_back(name);
  }
  if (input.names.empty())
    throw std::runtime_error("--input '" + o.input + "': no frame could be decoded (an empty or damaged video)");
  return input;
}

// The files write_outputs writes, by name: recorded in --output before any is written, so that
// --force later removes exactly these (geo_infer-outputs.txt) and never a file of the user's.
std::vector<std::string> planned_outputs(const InferOptions& o, const geo::Model& model, const Input& frames) {
  const bool sequence = frames.size() > 1, three = model.spec().seq_length == 3;
  std::vector<std::string> names;
  for (size_t i = 0; i < frames.size(); ++i) {
    const auto& name = frames.names[i];
    names.insert(names.end(), {name + "-disp.png", name + "-depth.png"});
    if (i + 1 < frames.size() && three) names.push_back(name + "-flow.png");
    if (std::find(o.ply_frames.begin(), o.ply_frames.end(), static_cast<int64_t>(i)) != o.ply_frames.end())
      names.push_back(name + ".ply");
  }
  if (sequence && three) names.insert(names.end(), {"trajectory.txt", "trajectory.png"});
  if (o.report) {
    names.push_back("report.html");
    for (const size_t i : geo::infer::report_rows(frames.size()))
      names.push_back(geo::infer::input_image_name(frames.names[i]));
  }
  if ((o.videos || frames.video) && sequence) {
    names.push_back("disp.avi");
    if (three) names.push_back("flow.avi");
  }
  return names;
}

// The folders the input's frames are read from: a frame folder, or the folder of a single image.
std::vector<std::string> frame_folders(const InferOptions& o, bool video) {
  if (fs::is_directory(o.input)) return {o.input};
  if (!video) return {fs::absolute(o.input).parent_path().string()};
  return {};
}

// --output: created; refused when it is the folder the frames come from (a frame folder, or the
// folder of a single image), or when it holds something (unless --force, which removes what
// geo_infer's manifest there says it wrote: an earlier, longer run's frames must not mix in).
void prepare_output(const InferOptions& o, const geo::Model& model, const Input& frames) {
  const int64_t removed =
      geo::prepare_output_folder(o.output, "--output", "geo_infer-outputs.txt", planned_outputs(o, model, frames),
                                 o.force, frame_folders(o, frames.video));
  if (o.force) spdlog::info("--force: {} earlier output file(s) of geo_infer removed from {}", removed, o.output);
}

// --intrinsics against the input's size (geo's one camera rule).
void check_intrinsics(const InferOptions& o, int64_t height, int64_t width) {
  const auto& in = o.intrinsics;
  const auto problem = geo::camera_problem(in[0], in[1], in[2], in[3], width, height);
  if (!problem.empty()) throw std::runtime_error("--intrinsics: " + problem + " ('" + o.input + "')");
}

// The input's frame size (its first frame, as decoded), {height, width}.
std::pair<int64_t, int64_t> input_size(const InferOptions& o) {
  FrameReader first(o, 1, 1);
  std::string name;
  torch::Tensor image;
  if (!first.next(name, &image))
    throw std::runtime_error("--input '" + o.input + "': no frame could be decoded (an empty or damaged video)");
  return {first.stream().height(), first.stream().width()};
}

// The camera [3,3] at the model's size: --intrinsics (pixels of the input) scaled, else the camera
// a model that learns it predicts (the mean over the first pairs), else a KITTI-like one.
torch::Tensor camera(const InferOptions& o, const geo::Model& model, int64_t height, int64_t width, int64_t h,
                     int64_t w) {
  const double W0 = static_cast<double>(width), H0 = static_cast<double>(height);
  if (o.intrinsics.size() == 4) {
    const auto& in = o.intrinsics;
    check_intrinsics(o, height, width);
    const double sx = w / W0, sy = h / H0;
    return torch::tensor({in[0] * sx, 0.0, in[2] * sx, 0.0, in[1] * sy, in[3] * sy, 0.0, 0.0, 1.0})
        .view({3, 3})
        .to(torch::kFloat32);
  }
  if (!model.spec().learns_intrinsics) return geo::kitti_like_intrinsics(h, w).to(torch::kFloat32);
  const auto first =
      geo::first_frames(o.input, o.max_frames > 0 ? std::min<int64_t>(o.max_frames, 11) : 11, h, w, "--input");
  std::vector<torch::Tensor> Ks;
  for (size_t i = 0; i < std::min<size_t>(first.size(), 10); ++i)
    Ks.push_back(model.intrinsics(first[i], first[std::min(i + 1, first.size() - 1)]));
  const auto K = torch::stack(Ks).mean(0).to(torch::kFloat32);
  const double sx = W0 / w, sy = H0 / h;
  spdlog::info(
      "learned camera: fx {:.1f} fy {:.1f} cx {:.1f} cy {:.1f} (pixels of the {}x{} input; give --intrinsics to "
      "use another)",
      K[0][0].item<double>() * sx, K[1][1].item<double>() * sy, K[0][2].item<double>() * sx,
      K[1][2].item<double>() * sy, width, height);
  return K;
}

// The input surveyed (see survey) and each frame's metric scale from the road plane, smoothed over
// the sequence (all 1 without --camera-height): one pass of the DepthNet over the frames, holding
// one frame at a time.
std::pair<Input, std::vector<double>> survey_and_scales(const InferOptions& o, const geo::Model& model,
                                                        const torch::Tensor& K, geo::StepTimes& times) {
  const int64_t h = model.spec().height, w = model.spec().width;
  if (o.camera_height <= 0) {
    auto input = times.time("survey the input (frame names)", [&] { return survey(o, h, w); });
    const std::vector<double> ones(input.size(), 1.0);
    return {std::move(input), ones};
  }
  std::vector<double> per_frame;
  const bool own_camera = o.intrinsics.size() == 4 || model.spec().learns_intrinsics;
  auto input = times.time("road planes (metric scale)", [&] {
    return survey(o, h, w, [&](const torch::Tensor& image) {
      per_frame.push_back(model.road_scale(image, o.camera_height, own_camera ? K : torch::Tensor()));
    });
  });
  int64_t with_road = 0;
  for (size_t i = 0; i < per_frame.size(); ++i) {
    if (per_frame[i] > 0) ++with_road;
    else spdlog::warn("{}: no road plane; its scale comes from its neighbours", input.names[i]);
  }
  spdlog::info("metric scale from the camera height {} m: road plane found in {} of {} frames", o.camera_height,
               with_road, input.size());
  auto scales = geo::smooth_road_scales(per_frame);
  return {std::move(input), std::move(scales)};
}

// --ground-truth's poses of the input's frames, read and checked before anything is computed or
// written: a pose per frame, and motion to align the trajectory's scale to. Undefined without it.
torch::Tensor ground_truth_of(const InferOptions& o, const Input& frames) {
  if (o.ground_truth.empty()) return {};
  const auto truth = geo::read_poses(o.ground_truth);
  const auto n = static_cast<int64_t>(frames.size());
  if (truth.size(0) < n)
    throw std::runtime_error("--ground-truth '" + o.ground_truth + "' has " + std::to_string(truth.size(0)) +
                             " poses for " + std::to_string(n) + " frames");
  if (n > 1 && !geo::trajectory_moves(truth.slice(0, 0, n)))
    throw std::runtime_error("--ground-truth '" + o.ground_truth + "': no motion over the input's " +
                             std::to_string(n) +
                             " frames (every position is the first): nothing to align the trajectory's scale to");
  return truth.slice(0, 0, n);
}

// The input's frames for geo::Model::run_sequence, read again as they are needed (the previous,
// the current and the next): each must be the survey's frame of that place (the input must not
// have changed since), its reading timed.
class SurveyedFrames : public geo::FrameSource {
 public:
  SurveyedFrames(const InferOptions& o, const Input& frames, int64_t h, int64_t w, geo::StepTimes& times)
      : o_(o), frames_(frames), h_(h), w_(w), times_(times) {}
  bool next(torch::Tensor& image) override {
    if (i_ == frames_.size()) return false;
    std::string name;
    const auto started = std::chrono::steady_clock::now();
    const bool got = times_.time("read, decode, resize frames", [&] { return reader_->next(name, &image); });
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (!got || name != frames_.names[i_])
      throw std::runtime_error("--input '" + o_.input + "' changed while geo_infer read it: frame " +
                               std::to_string(i_) + " was '" + frames_.names[i_] + "', now " +
                               (got ? "'" + name + "'" : "none"));
    ++i_;
    return true;
  }
  void restart() override {
    reader_.emplace(o_, h_, w_);
    i_ = 0;
  }
  double seconds = 0;  // spent reading

 private:
  const InferOptions& o_;
  const Input& frames_;
  int64_t h_, w_;
  geo::StepTimes& times_;
  std::optional<FrameReader> reader_;
  size_t i_ = 0;
};

// Per frame (geo::Model::run_sequence: depth, and with a next frame the flow and the motion, each
// network once per frame): colour maps, PNGs, videos, point clouds; then the trajectory. Returns
// what was written.
std::string write_outputs(const InferOptions& o, const geo::Model& model, const Input& frames, const torch::Tensor& K,
                          const std::vector<double>& scales, const torch::Tensor& truth, geo::StepTimes& times) {
  const int64_t h = model.spec().height, w = model.spec().width;
  const bool sequence = frames.size() > 1, three = model.spec().seq_length == 3;
  std::optional<geo::VideoWriter> disp_video, flow_video;
  if ((o.videos || frames.video) && sequence) {
    disp_video.emplace(o.output + "/disp.avi", frames.fps);
    if (three) flow_video.emplace(o.output + "/flow.avi", frames.fps);
  }
  const auto rows = o.report ? geo::infer::report_rows(frames.size()) : std::vector<size_t>();
  int64_t beyond_png = 0;  // depths that KITTI's 16-bit PNG (depth x 256) cannot hold
  double outside = 0;      // seconds spent reading frames and writing outputs (the rest is the networks')
  const auto write = [&](const geo::SequenceFrame& f) {
    const auto started = std::chrono::steady_clock::now();
    const auto& name = frames.names[f.index];
    const auto disp_colour = times.time("colour maps", [&] { return geo::colorize_disparity(1.0 / f.depth); });
    times.time("PNG encode + write", [&] {
      geo::write_image(o.output + "/" + name + "-disp.png", disp_colour);
      geo::write_depth_png(o.output + "/" + name + "-depth.png", f.depth);
    });
    beyond_png += (f.depth > 255.99).sum().item<int64_t>();
    if (std::binary_search(rows.begin(), rows.end(), f.index))
      times.time("report: input frames (JPEG)",
                 [&] { geo::write_image(o.output + "/" + geo::infer::input_image_name(name), f.image); });
    if (disp_video) times.time("video encode", [&] { disp_video->write(disp_colour); });
    if (std::find(o.ply_frames.begin(), o.ply_frames.end(), static_cast<int64_t>(f.index)) != o.ply_frames.end()) {
      const double limit = o.ply_max_depth > 0   ? o.ply_max_depth
                           : o.camera_height > 0 ? 80.0
                                                 : 20 * f.depth.median().item<double>();
      const auto n = geo::write_point_cloud_ply(o.output + "/" + name + ".ply", f.depth, f.image, K, limit);
      spdlog::info("{}/{}.ply: {} points (depth up to {:.3g})", o.output, name, n, limit);
    }
    if (f.flow.defined()) {
      const auto flow_colour = times.time("colour maps", [&] { return geo::colorize_flow(f.flow); });
      times.time("PNG encode + write", [&] { geo::write_image(o.output + "/" + name + "-flow.png", flow_colour); });
      if (flow_video) times.time("video encode", [&] { flow_video->write(flow_colour); });
    }
    if ((f.index + 1) % 10 == 0 || f.index + 1 == frames.size())
      spdlog::info("  {}/{} frames", f.index + 1, frames.size());
    outside += std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  };
  SurveyedFrames source(o, frames, h, w, times);
  const auto started = std::chrono::steady_clock::now();
  auto poses = model.run_sequence(source, write, scales, K);
  const double all = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  times.add(three && sequence ? "depth, pose, flow" : "depth", all - outside - source.seconds);
  const double beyond = static_cast<double>(beyond_png) / (static_cast<double>(frames.size()) * h * w);
  if (beyond > 0.01)
    spdlog::warn(
        "{:.0f}% of the depths are beyond 256, the most a KITTI depth PNG holds: *-depth.png saturates there{}",
        100 * beyond, o.camera_height > 0 ? fmt::format(" (is --camera-height {} in metres?)", o.camera_height) : "");
  std::string written = "*-disp.png, *-depth.png";
  const auto finishing = std::chrono::steady_clock::now();
  if (poses.defined()) {
    geo::write_poses(o.output + "/trajectory.txt", poses);
    if (truth.defined()) std::tie(std::ignore, poses) = geo::align_trajectory_scale(truth, poses);
    geo::write_image(o.output + "/trajectory.png", geo::trajectory_plot(poses, truth));
    written += ", *-flow.png, trajectory.txt, trajectory.png";
  }
  for (const auto& [video, file] : {std::pair{&disp_video, ", disp.avi"}, std::pair{&flow_video, ", flow.avi"}})
    if (*video) {
      (*video)->close();
      written += file;
    }
  times.add("trajectory, videos closed",
            std::chrono::duration<double>(std::chrono::steady_clock::now() - finishing).count());
  return written;
}

// --report: report.html, from what was written (the rows' input frames among it) and the timing.
void write_report(const InferOptions& o, const geo::Model& model, const Input& frames, const torch::Tensor& K,
                  std::pair<int64_t, int64_t> input_size, bool ground_truth, const std::string& timing) {
  const int64_t h = model.spec().height, w = model.spec().width;
  const bool sequence = frames.size() > 1, three = model.spec().seq_length == 3;
  geo::infer::Report r;
  r.input = o.input;
  r.checkpoint =
      o.checkpoint + (o.refine > 0 ? " refined on the input (--refine " + std::to_string(o.refine) + ")" : "");
  r.precision = model.spec().precision;
  r.device = model.device().str();
  r.frames = static_cast<int64_t>(frames.size());
  r.width = w;
  r.height = h;
  std::tie(r.input_height, r.input_width) = input_size;
  const double sx = static_cast<double>(r.input_width) / w, sy = static_cast<double>(r.input_height) / h;
  const auto k = K.to(torch::kFloat64).cpu();
  r.camera = {k[0][0].item<double>() * sx, k[1][1].item<double>() * sy, k[0][2].item<double>() * sx,
              k[1][2].item<double>() * sy};
  r.camera_source = o.intrinsics.size() == 4 ? "--intrinsics"
                    : model.spec().learns_intrinsics
                        ? "learned by the model"
                        : "KITTI-like default: fx 0.58 W, fy 1.92 H, centred; --intrinsics gives yours";
  r.camera_height = o.camera_height;
  r.trajectory = sequence && three;
  r.ground_truth = ground_truth;
  for (const size_t i : geo::infer::report_rows(frames.size())) {
    r.rows.push_back(frames.names[i]);
    r.row_flow.push_back(three && i + 1 < frames.size());
  }
  r.timing = timing;
  geo::write_file_atomic(o.output + "/report.html", geo::infer::report_html(r));
}

// --refine's run folder when --refine-run names none: a temporary one, removed at the end (the log
// file the training opened there released first).
struct ScratchRun {
  std::string path;
  ~ScratchRun() {
    if (path.empty()) return;
    geo::setup_logging("info");
    geo::remove_tree(path);
  }
};

// --refine: the model trained on the input first; returns the refined model file ("" when a
// signal stopped the training). Whatever can refuse the run is checked before the training: the
// output folder, a clip to train on, the camera.
std::string refined_model(const InferOptions& o, geo::StepTimes& times, ScratchRun& scratch) {
  const bool video = fs::is_regular_file(o.input) && geo::FrameStream(o.input, "--input").is_video();
  if (!video && !fs::is_directory(o.input))
    throw std::runtime_error("--refine " + std::to_string(o.refine) + " trains on a clip: '" + o.input +
                             "' is a single image (give a video or a folder of frames)");
  geo::check_output_folder(o.output, "--output", o.force, frame_folders(o, video));
  if (!o.refine_run.empty() && fs::exists(o.refine_run) &&
      !(fs::is_directory(o.refine_run) && fs::is_empty(o.refine_run)))
    throw std::runtime_error("--refine-run '" + o.refine_run + "' exists and is not an empty folder: give a new one");
  const auto [height, width] = input_size(o);
  geo::RefineOptions r;
  r.checkpoint = o.checkpoint;
  r.input = o.input;
  r.iterations = o.refine;
  r.anchor = o.refine_anchor;
  r.intrinsics = o.intrinsics;
  if (r.intrinsics.empty()) {  // geo_infer's KITTI-like camera, in pixels of the input
    const auto K = geo::kitti_like_intrinsics(height, width).to(torch::kFloat64);
    r.intrinsics = {K[0][0].item<double>(), K[1][1].item<double>(), K[0][2].item<double>(), K[1][2].item<double>()};
  } else {
    check_intrinsics(o, height, width);
  }
  r.device = o.device;
  r.threads = o.threads;
  r.option = "--refine";
  if (o.refine_run.empty()) {
    const auto stamp = std::chrono::steady_clock::now().time_since_epoch().count();
    scratch.path =
        (fs::temp_directory_path() / ("geo_infer-refine-" + std::to_string(::getpid()) + "-" + std::to_string(stamp)))
            .string();
  }
  r.run_dir = o.refine_run.empty() ? scratch.path : o.refine_run;
  auto refined = times.time("refine: train on the input", [&] { return geo::refine(r); });
  geo::setup_logging("info");  // the run's train.log released
  return refined;
}

// The whole command: (refine,) load, read, infer, write, report.
int infer(const InferOptions& o) {
  const auto started = std::chrono::steady_clock::now();
  geo::StepTimes times;
  if (!o.refine_run.empty() && o.refine == 0)
    throw std::runtime_error("--refine-run '" + o.refine_run + "' keeps the run of --refine N: give --refine too");
  if (o.refine_anchor_given && o.refine == 0)
    throw std::runtime_error("--refine-anchor " + fmt::format("{:g}", o.refine_anchor) +
                             " weighs a term of --refine N: give --refine too");
  ScratchRun scratch;
  const std::string checkpoint = o.refine > 0 ? refined_model(o, times, scratch) : o.checkpoint;
  if (checkpoint.empty()) return 130;  // interrupted: the refinement's checkpoint is in its run folder
  geo::LoadOptions load;
  load.device = o.device;
  const bool int8 = o.precision == "int8";
  if (o.calibration_frames > 0 && !int8)
    throw std::runtime_error("--calibration-frames calibrates int8: it needs --precision int8 (got " + o.precision +
                             ")");
  const int64_t calibration_frames = o.calibration_frames > 0 ? o.calibration_frames : 8;
  // int8: with the calibration the file keeps, else calibrated on the input's frames once they are read.
  load.precision = int8 ? "fp32" : o.precision;
  load.int8_when_calibrated = int8 && o.calibration_frames == 0;
  load.keep_float_weights = !int8;  // geo_infer never saves the model: the float kernels go as the int8 ones come
  load.threads = o.threads;
  geo::Model model = times.time("open the model", [&] { return geo::app::open_model(checkpoint, load); });
  const int64_t h = model.spec().height, w = model.spec().width;
  if (model.spec().precision == "int8") {
    spdlog::info("int8: with the calibration {} keeps (--calibration-frames N calibrates on the input instead)",
                 o.checkpoint);
  } else if (int8) {
    const int64_t n = o.max_frames > 0 ? std::min(o.max_frames, calibration_frames) : calibration_frames;
    const auto calibration =
        times.time("read, decode, resize frames", [&] { return geo::first_frames(o.input, n, h, w, "--input"); });
    if (model.spec().has_flow && calibration.size() < 2)
      throw std::runtime_error(
          "--precision int8: this model's FlowNet calibrates on pairs: give at least 2 frames "
          "(--calibration-frames, and an input of 2 or more frames)");
    times.time("int8 calibration", [&] { model.quantize_int8(calibration, false); });
    spdlog::info(
        "int8: calibrated on the first {} frame(s) of the input{}", calibration.size(),
        model.has_int8_calibration() || o.calibration_frames > 0
            ? ""
            : " (on every run: geo_export --int8 --calibration FRAMES writes a model that keeps its calibration)");
  }
  // The input's size (its first frame), the camera, then its frames counted and named (with
  // --camera-height, each frame's metric scale on the way), all before anything is written.
  const auto [height, width] = input_size(o);
  const auto K = camera(o, model, height, width, h, w);
  const auto [frames, scales] = survey_and_scales(o, model, K, times);
  for (const auto f : o.ply_frames)
    if (f >= static_cast<int64_t>(frames.size()))
      throw std::runtime_error("--ply " + std::to_string(f) + ": the input has " + std::to_string(frames.size()) +
                               " frames (numbered from 0)");
  const auto truth = ground_truth_of(o, frames);
  if (o.videos && frames.size() < 2) spdlog::warn("--videos: the input is a single frame; no video is written");
  prepare_output(o, model, frames);
  spdlog::info("{} frame(s) from {} at {}x{} -> {}", frames.size(), o.input, w, h, o.output);
  if (frames.size() > 1 && model.spec().seq_length != 3)
    spdlog::warn(
        "this model's PoseNet takes {}-frame snippets: geo_infer writes flow and trajectory.txt for "
        "3-frame models only; depth is written for every frame",
        model.spec().seq_length);
  geo::DeferredSync to_disk;  // the outputs reach the disk together, not file by file (core/files.h)
  std::string written = write_outputs(o, model, frames, K, scales, truth, times);
  times.time("flush to disk", [&] { to_disk.commit(); });
  const std::string table =
      times.table(static_cast<int64_t>(frames.size()), "frame",
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  if (o.report) {
    write_report(o, model, frames, K, {height, width}, truth.defined(), table);
    to_disk.commit();
    written += ", report.html";
  }
  spdlog::info("done: {}/{{{}}}", o.output, written);
  if (o.timing)
    std::printf("geo_infer --timing: %zu frame(s) at %lldx%lld, %s, %s\n%s", frames.size(), static_cast<long long>(w),
                static_cast<long long>(h), model.spec().precision.c_str(), model.device().str().c_str(), table.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return geo::app::run_command<InferOptions>(
      argc, argv, "geo_infer: depth, optical flow and camera trajectory of images, frame folders or videos",
      add_options, infer);
}
