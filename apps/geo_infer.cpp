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
// coloured point clouds of chosen frames.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>

#include "core/logging.h"
#include "core/progress.h"
#include "core/runtime.h"
#include "data/calib.h"
#include "data/image_io.h"
#include "data/point_cloud.h"
#include "data/text_io.h"
#include "data/visual_outputs.h"
#include "eval/metrics.h"
#include "app_options.h"
#include "geo/geo.h"

namespace fs = std::filesystem;

int main(int argc, char** argv) {
  CLI::App app{"geo_infer: depth, optical flow and camera trajectory of images, frame folders or videos"};
  std::string checkpoint, input, output, device = "auto";
  std::vector<double> intrinsics;
  int64_t max_frames = 0;
  app.add_option("--checkpoint", checkpoint, "checkpoint file, run folder or geo_export model file")->required();
  app.add_option("--input", input, "an image, a folder of frames (sorted by name) or a video file")->required();
  app.add_option("--output", output, "output folder (created)")->required();
  geo::app::add_device_option(app, device, "default: auto");
  std::string precision = "fp32";
  geo::app::add_precision_option(app, precision, {"fp32", "bf16", "auto"},
                                 "fp32, bf16 (faster on CPUs with AVX512-BF16/AMX, depth within ~1%) or auto (bf16 on such a CPU)");
  app.add_option("--intrinsics", intrinsics,
                 "fx fy cx cy of the input images in pixels (default: KITTI-like 0.58 W, 1.92 H, W/2, H/2)")
      ->expected(4);
  app.add_option("--max-frames", max_frames, "stop after this many frames (0 = all)");
  double camera_height = 0;
  app.add_option("--camera-height", camera_height,
                 "the camera's height above the road in metres (KITTI: 1.65): depth and trajectory in metres")
      ->check(geo::app::above_zero());
  std::string ground_truth;
  app.add_option("--ground-truth", ground_truth,
                 "KITTI pose file of the input's frames (odometry poses/XX.txt): drawn in trajectory.png beside the "
                 "estimate, scale-aligned")->check(CLI::ExistingFile);
  bool videos = false;
  app.add_flag("--videos", videos, "write disp.avi and flow.avi for a frame folder too (always for a video input)");
  std::vector<int64_t> ply_frames;
  app.add_option("--ply", ply_frames, "frame numbers (from 0) to write as coloured point clouds <name>.ply")
      ->check(geo::app::non_negative());
  double ply_max_depth = 0;
  app.add_option("--ply-max-depth", ply_max_depth,
                 "leave out points farther than this (default: 80 with --camera-height, else 20x the frame's median "
                 "depth: the sky)")->check(geo::app::above_zero());
  int threads = 0;
  app.add_option("--threads", threads, "LibTorch's intra-op threads (0 = all cores)")->check(geo::app::non_negative());
  bool timing = false;
  app.add_flag("--timing", timing, "print the time of each step (reading, networks, colour maps, encoding, ...) per frame");
  bool force = false;
  app.add_flag("--force", force, "write into a non-empty --output: geo_infer's earlier outputs there are removed first");
  CLI11_PARSE(app, argc, argv);
  return geo::app::run_tool([&] {
    geo::LoadOptions load;
    load.device = device;
    load.precision = precision;
    load.threads = threads;
    const auto started = std::chrono::steady_clock::now();
    auto seconds_since = [](std::chrono::steady_clock::time_point t) {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    };
    geo::StepTimes times;
    const geo::Model model = times.time("load the model", [&] { return geo::Model::load(checkpoint, load); });
    const int64_t h = model.spec().height, w = model.spec().width;
    // Frames as (name, image [1,3,h,w]) in order; the original size is kept for the intrinsics.
    std::vector<std::pair<std::string, torch::Tensor>> frames;
    double fps = 10;  // a frame folder's (KITTI's); a video's own
    int64_t H0 = 0, W0 = 0;
    std::string first_file;
    // One sequence, one camera: a frame of another size is refused (flow and motion across it mean
    // nothing, and the intrinsics are the first frame's).
    auto add_file = [&](const fs::path& p) {
      int64_t fh = 0, fw = 0;
      auto image = geo::read_image_resized(p.string(), h, w, &fh, &fw).unsqueeze(0);
      if (first_file.empty()) {
        first_file = p.string(), H0 = fh, W0 = fw;
      } else if (fh != H0 || fw != W0) {
        throw std::runtime_error(p.string() + " is " + std::to_string(fw) + "x" + std::to_string(fh) + " but " +
                                 first_file + " is " + std::to_string(W0) + "x" + std::to_string(H0) +
                                 ": the frames of one sequence must have one size");
      }
      frames.emplace_back(p.stem().string(), std::move(image));
    };
    const auto reading = std::chrono::steady_clock::now();
    if (fs::is_directory(input)) {
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(input)) {
        auto ext = e.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
        if (ext == ".png" || ext == ".jpg" || ext == ".jpeg") files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());
      if (files.empty()) throw std::runtime_error("no .png/.jpg images in '" + input + "'");
      for (size_t i = 1; i < files.size(); ++i)  // sorted: a shared stem sits next to its twin
        if (files[i].stem() == files[i - 1].stem())
          throw std::runtime_error("'" + files[i - 1].string() + "' and '" + files[i].string() +
                                   "' would write the same outputs (" + files[i].stem().string() +
                                   "-*.png): keep one of them in '" + input + "'");
      for (const auto& f : files) {
        if (max_frames > 0 && static_cast<int64_t>(frames.size()) >= max_frames) break;
        add_file(f);
      }
    } else if (!fs::exists(input)) {
      throw std::runtime_error("input '" + input + "' does not exist");
    } else {
      const auto ext = fs::path(input).extension().string();
      if (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".PNG" || ext == ".JPG") {
        add_file(input);
      } else {
        cv::VideoCapture cap(input);
        if (!cap.isOpened()) throw std::runtime_error("cannot open '" + input + "' as an image or a video");
        cv::Mat bgr;
        if (cap.get(cv::CAP_PROP_FPS) > 0) fps = cap.get(cv::CAP_PROP_FPS);
        videos = true;
        while (cap.read(bgr) && (max_frames <= 0 || static_cast<int64_t>(frames.size()) < max_frames)) {
          H0 = bgr.rows;
          W0 = bgr.cols;
          cv::Mat rgb, small;
          cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
          cv::resize(rgb, small, cv::Size(static_cast<int>(w), static_cast<int>(h)), 0, 0, cv::INTER_AREA);
          auto t = torch::from_blob(small.data, {small.rows, small.cols, 3}, torch::kUInt8)
                       .permute({2, 0, 1}).to(torch::kFloat32).div(255).unsqueeze(0).contiguous();
          char name[32];
          std::snprintf(name, sizeof name, "%06zu", frames.size());
          frames.emplace_back(name, t);
        }
        if (frames.empty()) throw std::runtime_error("video '" + input + "' has no readable frames");
      }
    }
    times.add("read, decode, resize frames", seconds_since(reading));
    if (fs::exists(output)) {
      std::error_code ec;
      if (fs::is_directory(input) && fs::equivalent(input, output, ec))
        throw std::runtime_error("--output '" + output + "' is the input folder: its outputs would be read as frames next time");
      if (!fs::is_directory(output)) throw std::runtime_error("--output '" + output + "' exists and is not a folder");
      if (!fs::is_empty(output)) {
        if (!force)
          throw std::runtime_error("--output '" + output + "' is not empty (--force replaces geo_infer's earlier outputs there)");
        // Only what geo_infer writes: an earlier, longer run's frames and trajectory must not mix with this one's.
        int64_t removed = 0;
        for (const auto& e : fs::directory_iterator(output)) {
          const auto name = e.path().filename().string();
          auto ends = [&](const std::string& tail) {
            return name.size() >= tail.size() && name.compare(name.size() - tail.size(), tail.size(), tail) == 0;
          };
          if (e.is_regular_file() && (ends("-disp.png") || ends("-depth.png") || ends("-flow.png") || ends(".ply") ||
                                      name == "trajectory.txt" || name == "trajectory.png" || name == "disp.avi" ||
                                      name == "flow.avi"))
            removed += fs::remove(e.path()) ? 1 : 0;
        }
        spdlog::info("--force: {} earlier output file(s) removed from {}", removed, output);
      }
    }
    fs::create_directories(output);
    spdlog::info("{} frame(s) from {} at {}x{} -> {}", frames.size(), input, w, h, output);
    if (frames.size() > 1 && model.spec().seq_length != 3)
      spdlog::warn("this model's PoseNet takes {}-frame snippets: geo_infer writes flow and trajectory.txt for "
                   "3-frame models only; depth is written for every frame", model.spec().seq_length);
    auto K = geo::kitti_like_intrinsics(h, w).unsqueeze(0);
    if (intrinsics.size() == 4) {
      geo::check_focal_lengths(intrinsics[0], intrinsics[1], "--intrinsics");
      if (!std::isfinite(intrinsics[2]) || !std::isfinite(intrinsics[3]))
        throw std::runtime_error("--intrinsics: cx, cy must be finite, got " + std::to_string(intrinsics[2]) + ", " +
                                 std::to_string(intrinsics[3]));
      const double sx = static_cast<double>(w) / W0, sy = static_cast<double>(h) / H0;
      K = torch::tensor({intrinsics[0] * sx, 0.0, intrinsics[2] * sx, 0.0, intrinsics[1] * sy, intrinsics[3] * sy,
                         0.0, 0.0, 1.0}).view({1, 3, 3});
    }
    if (intrinsics.size() != 4 && model.spec().learns_intrinsics) {
      // The camera the model learned: the mean of its prediction over the first pairs.
      std::vector<torch::Tensor> Ks;
      for (size_t i = 0; i < std::min<size_t>(frames.size(), 10); ++i)
        Ks.push_back(model.intrinsics(frames[i].second[0], frames[std::min(i + 1, frames.size() - 1)].second[0]));
      K = torch::stack(Ks).mean(0).unsqueeze(0);
      const double sx = static_cast<double>(W0) / w, sy = static_cast<double>(H0) / h;
      spdlog::info("learned camera: fx {:.1f} fy {:.1f} cx {:.1f} cy {:.1f} (pixels of the {}x{} input; give --intrinsics to "
                   "use another)", K[0][0][0].item<double>() * sx, K[0][1][1].item<double>() * sy,
                   K[0][0][2].item<double>() * sx, K[0][1][2].item<double>() * sy, W0, H0);
    }
    K = K.to(torch::kFloat32)[0];
    // Metric scale per frame from the road plane, smoothed over the sequence.
    std::vector<double> scales(frames.size(), 1.0);
    if (camera_height > 0) {
      std::vector<torch::Tensor> images;
      for (const auto& f : frames) images.push_back(f.second[0]);
      std::vector<size_t> without_road;
      scales = times.time("road planes (metric scale)", [&] {
        return model.sequence_scales(images, camera_height, intrinsics.size() == 4 || model.spec().learns_intrinsics ? K : torch::Tensor(),
                                     &without_road);
      });
      for (const auto i : without_road) spdlog::warn("{}: no road plane; its scale comes from its neighbours", frames[i].first);
      spdlog::info("metric scale from the camera height {} m: road plane found in {} of {} frames", camera_height,
                   frames.size() - without_road.size(), frames.size());
    }
    for (const auto f : ply_frames)
      if (f >= static_cast<int64_t>(frames.size()))
        throw std::runtime_error("--ply " + std::to_string(f) + ": the input has " + std::to_string(frames.size()) +
                                 " frames (numbered from 0)");
    const bool sequence = frames.size() > 1;
    std::optional<geo::VideoWriter> disp_video, flow_video;
    if (videos && sequence) {
      disp_video.emplace(output + "/disp.avi", fps);
      if (model.spec().seq_length == 3) flow_video.emplace(output + "/flow.avi", fps);
    }
    std::vector<torch::Tensor> motions;  // frame i's camera -> frame i+1's
    int64_t beyond_png = 0;  // depths that KITTI's 16-bit PNG (depth x 256) cannot hold
    for (size_t i = 0; i < frames.size(); ++i) {
      const auto& [name, img] = frames[i];
      // With a next frame, one flow_parts call gives this frame's depth, the flow and the motion:
      // each network runs once per frame.
      const bool pair = i + 1 < frames.size() && model.spec().seq_length == 3;
      geo::Model::FlowParts parts;
      if (pair)
        parts = times.time("depth, pose, flow", [&] {
          return model.flow_parts(img[0], frames[i + 1].second[0], K, i > 0 ? frames[i - 1].second[0] : torch::Tensor());
        });
      const auto depth = pair ? parts.depth.cpu() * scales[i]
                              : times.time("depth", [&] { return model.depth(img[0]).cpu() * scales[i]; });
      const auto disp_colour = times.time("colour maps", [&] { return geo::colorize_disparity(1.0 / depth); });
      times.time("PNG encode + write", [&] {
        geo::write_image(output + "/" + name + "-disp.png", disp_colour);
        geo::write_depth_png(output + "/" + name + "-depth.png", depth);
      });
      beyond_png += (depth > 255.99).sum().item<int64_t>();
      if (disp_video) times.time("video encode", [&] { disp_video->write(disp_colour); });
      if (std::find(ply_frames.begin(), ply_frames.end(), static_cast<int64_t>(i)) != ply_frames.end()) {
        const double limit = ply_max_depth > 0 ? ply_max_depth : camera_height > 0 ? 80.0 : 20 * depth.median().item<double>();
        const auto n = geo::write_point_cloud_ply(output + "/" + name + ".ply", depth, img[0].cpu(), K, limit);
        spdlog::info("{}/{}.ply: {} points (depth up to {:.3g})", output, name, n, limit);
      }
      if (pair) {
        const auto flow_colour = times.time("colour maps", [&] { return geo::colorize_flow(parts.full.cpu()); });
        times.time("PNG encode + write", [&] { geo::write_image(output + "/" + name + "-flow.png", flow_colour); });
        if (flow_video) times.time("video encode", [&] { flow_video->write(flow_colour); });
        motions.push_back(parts.motion);
      }
      if ((i + 1) % 10 == 0 || i + 1 == frames.size()) spdlog::info("  {}/{} frames", i + 1, frames.size());
    }
    const double beyond = static_cast<double>(beyond_png) / (static_cast<double>(frames.size()) * h * w);
    if (beyond > 0.01)
      spdlog::warn("{:.0f}% of the depths are beyond 256, the most a KITTI depth PNG holds: *-depth.png saturates there{}",
                   100 * beyond, camera_height > 0 ? fmt::format(" (is --camera-height {} in metres?)", camera_height) : "");
    std::string written = "*-disp.png, *-depth.png";
    const auto finishing = std::chrono::steady_clock::now();
    if (motions.size() + 1 == frames.size() && sequence) {
      scales.pop_back();  // one per step: each at its first frame's depth scale
      auto poses = geo::chain_poses(motions, scales);
      geo::write_poses(output + "/trajectory.txt", poses);
      torch::Tensor truth;
      if (!ground_truth.empty()) {
        truth = geo::read_poses(ground_truth);
        if (truth.size(0) < poses.size(0))
          throw std::runtime_error("--ground-truth '" + ground_truth + "' has " + std::to_string(truth.size(0)) +
                                   " poses for " + std::to_string(poses.size(0)) + " frames");
        std::tie(truth, poses) = geo::align_trajectory_scale(truth.slice(0, 0, poses.size(0)), poses);
      }
      geo::write_image(output + "/trajectory.png", geo::trajectory_plot(poses, truth));
      written += ", *-flow.png, trajectory.txt, trajectory.png";
    }
    if (disp_video) {
      disp_video->close();
      written += ", disp.avi";
    }
    if (flow_video) {
      flow_video->close();
      written += ", flow.avi";
    }
    times.add("trajectory, videos closed", seconds_since(finishing));
    spdlog::info("done: {}/{{{}}}", output, written);
    if (timing)
      std::printf("geo_infer --timing: %zu frame(s) at %lldx%lld, %s, %s\n%s", frames.size(), static_cast<long long>(w),
                  static_cast<long long>(h), model.spec().precision.c_str(), model.device().str().c_str(),
                  times.table(static_cast<int64_t>(frames.size()), "frame", seconds_since(started)).c_str());
    return 0;
  });
}
