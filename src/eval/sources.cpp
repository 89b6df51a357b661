#include "eval/sources.h"

#include <spdlog/spdlog.h>

#include "core/files.h"
#include "core/config.h"
#include "core/progress.h"
#include "data/kitti/calib.h"
#include "data/image_io.h"
#include "data/text_io.h"
#include "data/video/frame_stream.h"
#include "geometry/camera.h"
#include "geometry/road_plane.h"
#include "geometry/trajectory.h"

#include <algorithm>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <stdexcept>

namespace fs = std::filesystem;

namespace geo {

void require_file(const std::string& path, const std::string& what) {
  if (!fs::exists(path)) throw std::runtime_error(what + " not found: '" + path + "'");
}

void require_finite(const torch::Tensor& t, const std::string& what) {
  const auto bad = (~torch::isfinite(t)).sum().item<int64_t>();
  if (bad > 0)
    throw std::runtime_error(what + " holds " + std::to_string(bad) + " non-finite value(s) (NaN/Inf) of " +
                             std::to_string(t.numel()) + ": nothing was scored");
}

void require_same_size(const std::string& a, int64_t ha, int64_t wa, const std::string& b, int64_t hb, int64_t wb) {
  if (ha != hb || wa != wb)
    throw std::runtime_error(a + " is " + std::to_string(wa) + "x" + std::to_string(ha) + " but " + b + " is " +
                             std::to_string(wb) + "x" + std::to_string(hb) +
                             ": they must have one size; nothing was scored");
}

namespace {

// The test image's size, read from the image itself (the ground truth is projected at it).
std::pair<int64_t, int64_t> image_size(const std::string& path) {
  const auto img = read_image(path);
  return {img.size(1), img.size(2)};
}

class ModelSource : public PredictionSource {
 public:
  explicit ModelSource(Predictor& model) : m_(model) {}
  std::string name() const override { return m_.path(); }
  Predictor* model() override { return &m_; }

  DepthAnswer depth(const DepthQuery& q) override {
    DepthAnswer a;
    a.depth = m_.depth(input(q.image, &a.height, &a.width))[0][0].cpu();
    return a;
  }

  FlowAnswer flow(const FlowQuery& q) override {
    FlowAnswer out;
    int64_t H = 0, W = 0, H2 = 0, W2 = 0;
    const auto a = input(q.tgt, &H, &W), b = input(q.src, &H2, &W2);
    require_same_size(q.src, H2, W2, q.tgt, H, W);
    out.frame_height = H, out.frame_width = W;
    const auto K = resized_intrinsics(q.K, H, W, m_.height(), m_.width());
    // The frame before the pair (KITTI 2015's multi-view extension, image_2/%06d_09.png) gives the
    // PoseNet its real snippet (09, 10, 11), as GeoNet; without it (tgt, tgt, src).
    torch::Tensor prev;
    if (!q.prev.empty() && fs::exists(q.prev)) {
      int64_t H0 = 0, W0 = 0;
      prev = input(q.prev, &H0, &W0);
      require_same_size(q.prev, H0, W0, q.tgt, H, W);
      out.used_previous = true;
    }
    const auto parts = m_.flow(a, b, K.to(torch::kFloat32).unsqueeze(0), prev);
    out.full = parts.full[0].cpu();
    if (m_.has_flow()) out.rigid = parts.rigid[0].cpu();
    return out;
  }

  // The trajectory chained from the PoseNet's steps over the snippet around each frame (frames
  // clamped at the sequence's ends), reading each frame once and holding only the snippet's frames.
  TrajectoryAnswer trajectory(const SequenceQuery& q) override {
    const int64_t n = q.frames, L = m_.seq_length(), k = (L - 1) / 2;
    const std::string extra = q.folder + "/image_2/" + zero_padded(n, 6) + ".png";
    if (fs::exists(extra))
      throw std::runtime_error(q.gt_path + " holds " + std::to_string(n) + " poses but " + q.folder +
                               "/image_2 has more images (" + extra + " exists): the ground truth does not match");
    int64_t image_h = 0, image_w = 0;
    std::deque<torch::Tensor> window;  // frames first..first+size-1
    int64_t first = 0;
    auto frame = [&](int64_t f) {
      f = std::clamp<int64_t>(f, 0, n - 1);
      while (first + static_cast<int64_t>(window.size()) <= f) {
        const std::string p =
            q.folder + "/image_2/" + zero_padded(first + static_cast<int64_t>(window.size()), 6) + ".png";
        require_file(p, "odometry image");
        window.push_back(input(p, &image_h, &image_w));
      }
      return window[static_cast<size_t>(f - first)];
    };
    torch::Tensor K;  // the network's intrinsics, for the road plane
    std::vector<double> scales;
    TrajectoryAnswer out;
    out.snippet_poses.resize(static_cast<size_t>(n));
    TrajectoryChain chain;
    Progress progress("odometry " + q.name, n, 0, "frames");
    for (int64_t j = 0; j < n; ++j) {
      while (first < j - k) {  // frames no snippet needs any more
        window.pop_front();
        ++first;
      }
      std::vector<torch::Tensor> srcs;
      for (int64_t m = k; m >= 1; --m) srcs.push_back(frame(j - m));
      for (int64_t m = 1; m <= k; ++m) srcs.push_back(frame(j + m));
      const auto tgt = frame(j);
      const auto src_from_tgt = m_.pose(tgt, srcs)[0].cpu().to(torch::kFloat64);  // [L-1,4,4]
      if (j + 1 < n) chain.add_step(src_from_tgt[k]);  // T_{j+1 <- j}: the first source after the target
      if (L == 5 && j >= 2 && j + 2 < n) {
        std::vector<torch::Tensor> in_target;
        for (int64_t m = 0; m < 4; ++m) in_target.push_back(torch::inverse(src_from_tgt[m]));
        in_target.insert(in_target.begin() + 2, torch::eye(4, torch::kFloat64));
        out.snippet_poses[static_cast<size_t>(j)] = torch::stack(in_target);  // frames j-2..j+2
      }
      if (q.camera_height > 0) {
        if (!K.defined()) {
          K = resized_intrinsics(read_odometry_calib(q.folder + "/calib.txt").P[2].slice(1, 0, 3), image_h, image_w,
                                 m_.height(), m_.width());
        }
        const auto plane = fit_road_plane(m_.depth(tgt)[0][0].cpu(), K);
        scales.push_back(camera_height_scale(plane, q.camera_height));
        out.frames_with_road += plane.found;
      }
      progress.update(j + 1);
    }
    out.trajectory = chain.poses();
    if (q.camera_height > 0)  // each step at its frame's metric scale (as geo_infer --camera-height)
      out.metric = chain.poses(metric_scales(scales, [&](size_t j) {
        return "--scaling camera-height: no road plane in any frame near frame " + std::to_string(j) + " of sequence " +
               q.name + ": a metric trajectory needs a road in front of the camera";
      }));
    return out;
  }

 private:
  torch::Tensor input(const std::string& path, int64_t* H, int64_t* W) const {
    return read_image_resized(path, m_.height(), m_.width(), H, W).unsqueeze(0);
  }
  Predictor& m_;
};

class FileSource : public PredictionSource {
 public:
  explicit FileSource(std::string path) : path_(std::move(path)) {}
  std::string name() const override { return path_; }

  DepthAnswer depth(const DepthQuery& q) override {
    DepthAnswer a;
    std::tie(a.height, a.width) = image_size(q.image);
    a.from_file = true;
    const bool npy = path_.size() > 4 && path_.substr(path_.size() - 4) == ".npy";
    if (npy && !npy_.defined()) {
      npy_ = read_npy(path_);
      if (npy_.numel() == 0)
        throw std::runtime_error(path_ + ": the array has a zero dimension " + c10::str(npy_.sizes()) +
                                 ": no depth to score");
      if (npy_.dim() != 3 || npy_.size(0) != static_cast<int64_t>(q.count))
        throw std::runtime_error(path_ + ": expected [" + std::to_string(q.count) + ",H,W] depths (one per line of " +
                                 q.list + "), got " + c10::str(npy_.sizes()));
    }
    if (npy) {
      a.depth = npy_[static_cast<int64_t>(q.index)];
    } else {
      const std::string p = path_ + "/" + zero_padded(static_cast<long long>(q.index), 6) + ".png";
      require_file(p, "prediction for line " + std::to_string(q.index + 1));
      a.depth = read_depth_png(p)[0];
    }
    return a;
  }

  FlowAnswer flow(const FlowQuery& q) override {
    const std::string p = path_ + "/" + q.name + "_10.png";
    require_file(p, "flow prediction");
    FlowAnswer a;
    const auto map = read_flow_png(p);
    // KITTI's format marks each pixel valid or not: a prediction with no valid pixel holds no flow
    // (its vectors decode as zero) and is refused, never scored as zero flow.
    if (!(map.valid > 0.5).any().item<bool>())
      throw std::runtime_error(p +
                               ": no pixel of the flow prediction is marked valid (the third channel is 0 "
                               "everywhere): nothing to score; write valid = 1 where the flow is predicted");
    a.full = map.flow;
    a.meant_at_ground_truth_size = true;
    return a;
  }

  TrajectoryAnswer trajectory(const SequenceQuery& q) override {
    TrajectoryAnswer a;
    a.trajectory = read_poses(path_);
    if (a.trajectory.size(0) != q.frames)
      throw std::runtime_error(path_ + ": " + std::to_string(a.trajectory.size(0)) + " poses, the sequence has " +
                               std::to_string(q.frames));
    a.snippet_poses.resize(static_cast<size_t>(q.frames));
    return a;
  }

 private:
  std::string path_;
  torch::Tensor npy_;
};

class TrivialSource : public PredictionSource {
 public:
  std::string name() const override { return "trivial baseline"; }
  DepthAnswer depth(const DepthQuery& q) override {
    DepthAnswer a;
    std::tie(a.height, a.width) = image_size(q.image);
    a.depth = torch::ones({a.height, a.width});  // any constant: median scaling makes it the best constant
    return a;
  }
  FlowAnswer flow(const FlowQuery&) override {
    FlowAnswer a;
    a.full = torch::zeros({2, 1, 1});
    return a;
  }
  TrajectoryAnswer trajectory(const SequenceQuery& q) override {
    TrajectoryAnswer a;
    a.trajectory = torch::eye(4, torch::kFloat64).repeat({q.frames, 1, 1});
    a.snippet_poses.resize(static_cast<size_t>(q.frames));
    return a;
  }
};

}  // namespace

std::unique_ptr<PredictionSource> model_source(Predictor& model) { return std::make_unique<ModelSource>(model); }
std::unique_ptr<PredictionSource> file_source(const std::string& path) { return std::make_unique<FileSource>(path); }
std::unique_ptr<PredictionSource> trivial_source() { return std::make_unique<TrivialSource>(); }

ChosenSource choose_source(const SourceChoice& c) {
  ChosenSource out;
  const bool int8 = c.precision == "int8";
  if (c.calibration_frames < 1 || c.calibration_frames > 1000)
    throw std::runtime_error("--calibration-frames must be in 1..1000 (got " + std::to_string(c.calibration_frames) +
                             ")");
  if (!int8 && !c.calibration.empty())
    throw std::runtime_error("--calibration calibrates int8: it needs --precision int8 (or it would be ignored)");
  LoadOptions load;
  load.device = c.device;
  // int8: with the calibration a model file keeps, else calibrated once the model's input size is known.
  load.precision = int8 ? "fp32" : c.precision;
  load.int8_when_calibrated = int8 && c.calibration.empty();
  if (!c.untrained_config.empty()) {
    out.predictor = std::make_unique<Predictor>(load_config(resolve_config_path(c.untrained_config)), load);
  } else if (c.trivial) {
    out.source = trivial_source();
  } else if (!c.predictions.empty()) {
    out.source = file_source(c.predictions);
    out.reads = c.predictions;
  } else if (c.need_model || !c.checkpoint.empty()) {
    std::string checkpoint = c.checkpoint;
    if (checkpoint.empty()) {
      checkpoint = latest_run_checkpoint(c.runs);
      if (checkpoint.empty())
        throw std::runtime_error("no model: give --checkpoint FILE|RUN_DIR (no training run found under '" + c.runs +
                                 "'), or --predictions PATH");
    }
    out.predictor = std::make_unique<Predictor>(checkpoint, load);
    out.reads = out.predictor->path();
  }
  if (!out.predictor && c.precision != "fp32")
    throw std::runtime_error("--precision " + c.precision +
                             " is a model's (--checkpoint, --untrained): there is none to run");
  if (out.predictor && int8 && c.calibration.empty()) {
    if (out.predictor->precision() != "int8")
      throw std::runtime_error("--precision int8: " + out.predictor->path() +
                               " keeps no int8 calibration: give --calibration FRAMES, a folder of frames or a video "
                               "like those evaluated (its first --calibration-frames frames), or a model file written "
                               "by geo_export --int8");
    spdlog::info("int8: with the calibration {} keeps", out.predictor->path());
  } else if (out.predictor && int8) {
    const auto frames = first_frames(c.calibration, c.calibration_frames, out.predictor->height(),
                                     out.predictor->width(), "--calibration");
    out.predictor->quantize_int8(frames);
    spdlog::info("int8: calibrated on {} frame(s) of {}", frames.size(), c.calibration);
  }
  if (out.predictor) {
    spdlog::info("model {} ({}x{}, FlowNet {})", out.predictor->path(), out.predictor->width(), out.predictor->height(),
                 out.predictor->has_flow() ? "yes" : "no: rigid flow only");
    out.source = model_source(*out.predictor);
  }
  return out;
}

std::string eval_data_root(const std::string& given) {
  if (!given.empty()) return given;
  const char* env = std::getenv("GEO_KITTI_ROOT");
  const std::string root = env && *env ? env : "data/kitti";
  if (!fs::is_directory(root))
    throw std::runtime_error("no data root: '" + root + "' does not exist; give --data-root DIR or set GEO_KITTI_ROOT");
  return root;
}

std::vector<std::string> evaluation_reads(const SourceChoice& choice, const ChosenSource& chosen,
                                          const std::string& split_file) {
  return {chosen.reads, choice.checkpoint, choice.predictions, choice.untrained_config, choice.calibration, split_file};
}

}  // namespace geo
