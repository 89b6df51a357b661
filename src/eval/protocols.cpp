#include "eval/protocols.h"

#include "core/logging.h"
#include "core/files.h"
#include "core/progress.h"
#include "data/kitti/calib.h"
#include "data/image_io.h"
#include "data/kitti/splits.h"
#include "data/text_io.h"
#include "data/kitti/training_lists.h"
#include "data/kitti/velodyne_depth.h"
#include "eval/metrics.h"
#include "eval/sources.h"
#include "geometry/pose.h"
#include "geometry/camera.h"
#include "geometry/road_plane.h"

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <filesystem>
#include <limits>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace geo {
namespace {

// The camera height to scale by: the one asked for, else the data root's record (a geo_synth world's
// camera_height.txt, at the world's root or above the split's), else KITTI's 1.65 m.
double camera_height_of(const EvalOptions& o, const std::string& root) {
  if (o.camera_height > 0) return o.camera_height;
  for (const auto& dir : {o.data_root, root + "/.."}) {
    const std::string file = dir + "/camera_height.txt";
    if (!fs::exists(file)) continue;
    std::istringstream in(read_text_file(file));
    double h = 0;
    if (!(in >> h) || !(h > 0) || !std::isfinite(h))
      throw std::runtime_error(file + ": expected the camera's height above the road in metres (a number > 0)");
    return h;
  }
  return 1.65;
}

std::string eigen_list(const EvalOptions& o, const std::string& root) {
  const std::string list = o.split_file.empty() ? find_split_file(root, "eigen", "test_files.txt") : o.split_file;
  if (list.empty()) throw std::runtime_error("no Eigen test list: give --split-file");
  return list;
}

// The Velodyne scan of a test line (checked to exist) and its calibration's projection.
struct EigenTestImage {
  std::string image, velodyne;
  RawCalib calib;
};
EigenTestImage eigen_test_image(const std::string& root, const SplitEntry& e, size_t line, const std::string& list) {
  EigenTestImage t{e.image_path(root), root + "/" + e.folder + "/velodyne_points/data/" + zero_padded(e.frame, 10) + ".bin",
                   read_raw_calib(root + "/" + e.date(), e.camera())};
  require_file(t.image, "test image (line " + std::to_string(line + 1) + " of " + list + ")");
  require_file(t.velodyne, "Velodyne scan");
  return t;
}

EvalResult eval_eigen(const EvalOptions& o, const std::string& root, PredictionSource& source) {
  const std::string list = eigen_list(o, root);
  const auto entries = read_split(list);
  EigenOptions eo;
  VelodyneDepthOptions vo;
  vo.matlab_offset = o.matlab_offset;
  std::vector<double> sums(7, 0.0);
  int64_t images = 0, pixels = 0;
  std::vector<std::string> without_gt;  // scans that give no valid pixel (empty, NaN, all out of range)
  int64_t non_finite_points = 0, scans_with_non_finite = 0;  // NaN/Inf points are left out, counted
  int64_t images_nonpositive = 0, pixels_nonpositive = 0;    // predicted depths <= 0, clamped, counted
  std::vector<double> median_ratios, agreements;  // median(gt)/median(pred); camera-height scale / that
  std::vector<std::string> without_plane;         // camera-height scaling: images whose road was not found
  const double camera_height = o.scaling == DepthScaling::kCameraHeight ? camera_height_of(o, root) : 0.0;
  std::string first_nonpositive;
  std::string first_non_finite;
  bool from_files = false;        // predictions from files, meant at the image's size
  int64_t predictions_resized = 0;  // of them, those of another size (resized bilinearly)
  std::string first_resized;
  // Where the data root marks moving objects (geo_synth's raw/<drive>/obj_map/image_0X/<frame>.png,
  // 0 = static), their pixels are also scored apart, at the whole image's scale, pooled over pixels.
  double moving_abs_rel_sum = 0, moving_a1_sum = 0;
  int64_t moving_pixels = 0, images_with_object_maps = 0;
  Progress progress("eigen", static_cast<int64_t>(entries.size()), 0, "images");
  for (size_t i = 0; i < entries.size(); ++i) {
    const auto test = eigen_test_image(root, entries[i], i, list);
    const std::string& image = test.image;
    const std::string& velo = test.velodyne;
    const auto& calib = test.calib;
    const DepthAnswer answer = source.depth(DepthQuery{i, entries.size(), list, image});
    const int64_t H = answer.height, W = answer.width;
    const torch::Tensor& depth = answer.depth;
    require_finite(depth, "the depth prediction for line " + std::to_string(i + 1) + " (" + image + ")");
    if (answer.from_file) {
      from_files = true;
      // A prediction file of another size is resized, counted and said; one whose shape is not the
      // image's (H and W swapped, another camera) is refused rather than stretched.
      const int64_t h = depth.size(0), w = depth.size(1);
      if (h != H || w != W) {
        const double aspect = (static_cast<double>(h) / w) / (static_cast<double>(H) / W);
        if (aspect > 1.2 || aspect < 1 / 1.2)
          throw std::runtime_error("the depth prediction for line " + std::to_string(i + 1) + " (" + image + ") is " +
                                   std::to_string(h) + "x" + std::to_string(w) + " (HxW) for an image of " +
                                   std::to_string(H) + "x" + std::to_string(W) + ": another shape" +
                                   (h == W && w == H ? " (H and W swapped)" : "") + "; nothing was scored");
        if (predictions_resized++ == 0)
          first_resized = std::to_string(i + 1) + " (" + std::to_string(h) + "x" + std::to_string(w) + " vs " +
                          std::to_string(H) + "x" + std::to_string(W) + ")";
      }
    }
    // Depths are positive: all <= 0 is no depth map (a disparity's sign, a log depth); some <= 0 are
    // clamped to 1e-3 as every protocol does, counted and reported.
    const int64_t nonpositive = (depth <= 0).sum().item<int64_t>();
    if (nonpositive == depth.numel())
      throw std::runtime_error("the depth prediction for line " + std::to_string(i + 1) + " (" + image +
                               ") is <= 0 everywhere: depths must be positive (a log depth or a negated "
                               "disparity?); nothing was scored");
    if (nonpositive > 0 && images_nonpositive++ == 0) first_nonpositive = std::to_string(i + 1);
    pixels_nonpositive += nonpositive;
    const auto points = read_velodyne(velo);
    if (const int64_t bad = count_non_finite_points(points); bad > 0) {
      non_finite_points += bad;
      if (scans_with_non_finite++ == 0) first_non_finite = velo;
    }
    const auto gt = velodyne_depth(points, calib.img_from_velo(), H, W, vo);
    EigenOptions image_eo = eo;
    image_eo.median_scaling = o.scaling == DepthScaling::kMedian;
    if (o.scaling == DepthScaling::kCameraHeight) {
      // The intrinsics of the prediction's size; the road plane fitted to the prediction alone.
      const auto K = resized_intrinsics(calib.K(), H, W, depth.size(0), depth.size(1));
      const auto plane = fit_road_plane(depth.clamp_min(1e-3), K);
      if (!plane.found) {
        without_plane.push_back(image + " (" + plane.why + ")");
        progress.update(static_cast<int64_t>(i + 1));
        continue;
      }
      image_eo.fixed_scale = camera_height_scale(plane, camera_height);
    }
    double applied = 1, ratio = 1;
    const auto err = eigen_image_errors(gt, depth.clamp_min(1e-3), image_eo, &applied, &ratio);
    if (err.pixels > 0) {
      median_ratios.push_back(ratio);
      if (o.scaling == DepthScaling::kCameraHeight) agreements.push_back(applied / ratio);
      const double v[7] = {err.abs_rel, err.sq_rel, err.rmse, err.rmse_log, err.a1, err.a2, err.a3};
      for (int k = 0; k < 7; ++k) sums[k] += v[k];
      ++images;
      pixels += err.pixels;
      const std::string objects = root + "/" + entries[i].folder + "/obj_map/image_0" +
                                  std::to_string(entries[i].camera()) + "/" + zero_padded(entries[i].frame, 10) + ".png";
      if (fs::exists(objects)) {
        const auto moving = read_object_map(objects) > 0;
        if (moving.size(0) != gt.size(0) || moving.size(1) != gt.size(1))
          throw std::runtime_error("object map '" + objects + "' is " + std::to_string(moving.size(0)) + "x" +
                                   std::to_string(moving.size(1)) + ", its image " + std::to_string(gt.size(0)) + "x" +
                                   std::to_string(gt.size(1)));
        ++images_with_object_maps;
        EigenOptions at_scale = eo;
        at_scale.median_scaling = false;
        at_scale.fixed_scale = applied;
        const auto m = eigen_image_errors(gt * moving.to(gt.dtype()), depth.clamp_min(1e-3), at_scale);
        moving_abs_rel_sum += m.abs_rel * static_cast<double>(m.pixels);
        moving_a1_sum += m.a1 * static_cast<double>(m.pixels);
        moving_pixels += m.pixels;
      }
    } else {
      without_gt.push_back(velo);
    }
    progress.update(static_cast<int64_t>(i + 1));
  }
  if (!without_gt.empty())
    spdlog::warn("{} of {} test images have no usable ground truth (no finite Velodyne point in the evaluated "
                 "region) and are left out of the means; first: {}",
                 without_gt.size(), entries.size(), without_gt.front());
  if (!without_plane.empty())
    spdlog::warn("camera-height scaling: no road plane in {} of {} test images, left out of the means; first: {}",
                 without_plane.size(), entries.size(), without_plane.front());
  if (images_nonpositive > 0)
    spdlog::warn("{} of {} depth predictions hold {} depths <= 0 (first: line {}), clamped to 1e-3 before scoring: "
                 "is the prediction a depth map?", images_nonpositive, entries.size(), pixels_nonpositive, first_nonpositive);
  if (non_finite_points > 0)
    spdlog::warn("{} Velodyne points in {} of {} scans have a NaN or infinite coordinate and are left out of the "
                 "ground truth; first: {}", non_finite_points, scans_with_non_finite, entries.size(), first_non_finite);
  EvalResult r;
  if (images == 0)
    throw std::runtime_error(without_plane.empty() ? "no test image had valid ground-truth pixels"
                                                   : "no test image had a road plane for camera-height scaling; first: " +
                                                         without_plane.front());
  std::set<std::string> drives;
  for (const auto& e : entries) drives.insert(e.scene());
  r.test_drives.assign(drives.begin(), drives.end());
  const char* names[7] = {"abs_rel", "sq_rel", "rmse", "rmse_log", "a1", "a2", "a3"};
  for (int k = 0; k < 7; ++k) r.metrics.emplace_back(names[k], sums[k] / static_cast<double>(images));
  // The spread of the scale (monodepth2's "scaling ratios"): median(gt)/median(pred) per image, and
  // with camera-height scaling how far its scale is from that ground-truth one (1 = the same).
  auto spread = [&](const std::string& name, const std::vector<double>& v) {
    if (v.empty()) return;
    const auto t = torch::tensor(v, torch::kFloat64);
    r.metrics.emplace_back(name + "_median", numpy_median(t));
    r.metrics.emplace_back(name + "_std", v.size() > 1 ? t.std(false).item<double>() : 0.0);
  };
  spread("scale_ratio", median_ratios);
  spread("scale_agreement", agreements);
  if (moving_pixels > 0) {
    r.metrics.emplace_back("moving_abs_rel", moving_abs_rel_sum / static_cast<double>(moving_pixels));
    r.metrics.emplace_back("moving_a1", moving_a1_sum / static_cast<double>(moving_pixels));
  }
  r.counts = {{"images", images}, {"pixels", pixels}, {"listed", static_cast<int64_t>(entries.size())},
              {"images_without_ground_truth", static_cast<int64_t>(without_gt.size())},
              {"velodyne_points_non_finite", non_finite_points},
              {"predictions_with_nonpositive_depth", images_nonpositive},
              {"images_without_road_plane", static_cast<int64_t>(without_plane.size())}};
  if (images_with_object_maps > 0) {
    r.counts.emplace_back("images_with_object_maps", images_with_object_maps);
    r.counts.emplace_back("moving_pixels", moving_pixels);
  }
  if (from_files) r.counts.emplace_back("predictions_resized", predictions_resized);
  if (predictions_resized > 0)
    spdlog::warn("{} of {} depth predictions differ in size from their image and were resized bilinearly; first: "
                 "line {}", predictions_resized, entries.size(), first_resized);
  return r;
}

// One flow's scores over the pairs: EPE and Fl on flow_occ ("all") and flow_noc averaged over the
// pairs (GeoNet's protocol), and on flow_occ's background and foreground pixels (obj_map = 0 / > 0)
// pooled over the pixels of all pairs (KITTI's devkit, Fl-bg / Fl-fg).
struct FlowScores {
  double epe_occ = 0, epe_noc = 0, fl_occ = 0, fl_noc = 0;
  FlowErrorSums bg, fg;
  bool with_objects = false;

  // flow: at the ground truth's size; foreground: [H,W] bool or undefined (no object map).
  void add(const FlowMap& occ, const FlowMap& noc, const torch::Tensor& foreground, const torch::Tensor& flow) {
    const auto o = flow_error_sums(occ.flow, occ.valid, flow), n = flow_error_sums(noc.flow, noc.valid, flow);
    epe_occ += o.epe();
    fl_occ += o.fl();
    epe_noc += n.epe();
    fl_noc += n.fl();
    if (!foreground.defined()) return;
    with_objects = true;
    const auto valid = occ.valid[0] > 0.5;
    bg += flow_error_sums(occ.flow, valid & ~foreground, flow);
    fg += flow_error_sums(occ.flow, valid & foreground, flow);
  }
  void put(EvalResult& r, const std::string& prefix, int64_t pairs) const {
    const double n = static_cast<double>(pairs);
    r.metrics.insert(r.metrics.end(), {{prefix + "epe_all", epe_occ / n}, {prefix + "epe_noc", epe_noc / n},
                                       {prefix + "fl_all", fl_occ / n}, {prefix + "fl_noc", fl_noc / n}});
    if (!with_objects) return;
    const double none = std::numeric_limits<double>::quiet_NaN();  // no such pixel: null in the JSON
    r.metrics.insert(r.metrics.end(), {{prefix + "epe_bg", bg.pixels ? bg.epe() : none},
                                       {prefix + "epe_fg", fg.pixels ? fg.epe() : none},
                                       {prefix + "fl_bg", bg.pixels ? bg.fl() : none},
                                       {prefix + "fl_fg", fg.pixels ? fg.fl() : none}});
  }
};

torch::Tensor flow_calib_K(const std::string& root, const std::string& name) {
  for (const auto& dir : {root + "/training/calib_cam_to_cam", root + "/../data_scene_flow_calib/training/calib_cam_to_cam"}) {
    const std::string p = dir + "/" + name + ".txt";
    if (fs::exists(p)) return read_key_values(p).projection("P_rect_02").slice(1, 0, 3);
  }
  throw std::runtime_error("calibration for pair " + name + " not found (looked in " + root +
                           "/training/calib_cam_to_cam/" + name + ".txt)");
}

EvalResult eval_kitti2015(const EvalOptions& o, const std::string& root, PredictionSource& source) {
  std::vector<std::string> names;
  if (!o.split_file.empty()) {
    for (const auto& line : read_lines(o.split_file)) {
      const auto base = fs::path(line).filename().string();  // 000123_10.png
      if (base.size() < 10 || base.substr(6) != "_10.png")
        throw std::runtime_error(o.split_file + ": expected lines like training/image_2/000123_10.png, got '" + line + "'");
      names.push_back(base.substr(0, 6));
    }
  } else {
    const std::string dir = root + "/training/image_2";
    if (!fs::is_directory(dir)) throw std::runtime_error("KITTI 2015 images not found: '" + dir + "' (--data-root)");
    for (const auto& e : fs::directory_iterator(dir)) {
      const auto f = e.path().filename().string();
      if (f.size() == 13 && f.substr(6) == "_10.png") names.push_back(f.substr(0, 6));
    }
    std::sort(names.begin(), names.end());
  }
  if (names.empty()) throw std::runtime_error("no flow pairs to evaluate under " + root);
  FlowScores full, rigid;
  int64_t with_previous = 0, with_objects = 0, px_occ = 0, px_noc = 0;
  std::vector<std::string> without_gt;  // pairs whose flow_occ or flow_noc has no valid pixel
  int64_t predictions_resized = 0;      // prediction files whose size differs from the ground truth
  std::string resized;                  // the first of them
  bool from_files = false;              // predictions meant at the ground truth's size
  const bool split_stages = source.model() && source.model()->has_flow();  // rigid flow apart from the full flow
  Progress progress("kitti2015", static_cast<int64_t>(names.size()), 0, "pairs");
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string t = root + "/training/image_2/" + names[i] + "_10.png";
    const std::string s = root + "/training/image_2/" + names[i] + "_11.png";
    const std::string gocc = root + "/training/flow_occ/" + names[i] + "_10.png";
    const std::string gnoc = root + "/training/flow_noc/" + names[i] + "_10.png";
    const std::string objects = root + "/training/obj_map/" + names[i] + "_10.png";
    for (const auto* p : {&t, &s, &gocc, &gnoc}) require_file(*p, "pair " + names[i]);
    const FlowAnswer answer =
        source.flow(FlowQuery{names[i], t, s, root + "/training/image_2/" + names[i] + "_09.png",
                              source.model() ? flow_calib_K(root, names[i]) : torch::Tensor()});
    const torch::Tensor& flow = answer.full;
    const torch::Tensor& rigid_flow = answer.rigid;
    const int64_t frame_h = answer.frame_height, frame_w = answer.frame_width;
    with_previous += answer.used_previous;
    from_files = from_files || answer.meant_at_ground_truth_size;
    require_finite(flow, "the flow prediction for pair " + names[i]);
    const auto occ = read_flow_png(gocc), noc = read_flow_png(gnoc);
    require_same_size(gnoc, noc.flow.size(1), noc.flow.size(2), gocc, occ.flow.size(1), occ.flow.size(2));
    if (frame_h > 0) require_same_size(gocc, occ.flow.size(1), occ.flow.size(2), t, frame_h, frame_w);
    // A file-based prediction is meant at the ground truth's size (KITTI's devkit rejects others):
    // geo rescales it like a model's output, loudly.
    if (answer.meant_at_ground_truth_size && (flow.size(1) != occ.flow.size(1) || flow.size(2) != occ.flow.size(2))) {
      if (resized.empty())
        resized = names[i] + " (" + std::to_string(flow.size(1)) + "x" + std::to_string(flow.size(2)) + " vs " +
                  std::to_string(occ.flow.size(1)) + "x" + std::to_string(occ.flow.size(2)) + ")";
      ++predictions_resized;
    }
    const int64_t n_occ = (occ.valid > 0.5).sum().item<int64_t>(), n_noc = (noc.valid > 0.5).sum().item<int64_t>();
    if (n_occ == 0 || n_noc == 0) {  // an all-invalid ground truth would count as EPE 0
      without_gt.push_back(names[i]);
      progress.update(static_cast<int64_t>(i + 1));
      continue;
    }
    torch::Tensor foreground;  // [H,W] bool: KITTI 2015's obj_map > 0
    if (fs::exists(objects)) {
      foreground = read_object_map(objects) > 0;
      if (foreground.size(0) != occ.flow.size(1) || foreground.size(1) != occ.flow.size(2))
        throw std::runtime_error("object map '" + objects + "' is " + std::to_string(foreground.size(0)) + "x" +
                                 std::to_string(foreground.size(1)) + ", its flow ground truth " +
                                 std::to_string(occ.flow.size(1)) + "x" + std::to_string(occ.flow.size(2)));
      ++with_objects;
    }
    const int64_t H = occ.flow.size(1), W = occ.flow.size(2);
    full.add(occ, noc, foreground, resize_flow(flow, H, W, o.flow_resize));
    if (split_stages) {
      require_finite(rigid_flow, "the rigid flow prediction for pair " + names[i]);
      rigid.add(occ, noc, foreground, resize_flow(rigid_flow, H, W, o.flow_resize));
    }
    px_occ += n_occ;
    px_noc += n_noc;
    progress.update(static_cast<int64_t>(i + 1));
  }
  const int64_t scored = static_cast<int64_t>(names.size() - without_gt.size());
  if (scored == 0) throw std::runtime_error("no flow pair under " + root + " has valid ground-truth pixels");
  if (!without_gt.empty())
    spdlog::warn("{} of {} pairs have no valid ground-truth pixel (flow_occ or flow_noc) and are left out of the "
                 "means; first: {}", without_gt.size(), names.size(), without_gt.front());
  if (predictions_resized > 0)
    spdlog::warn("{} of {} flow predictions differ in size from their ground truth and were resized ({}, vectors "
                 "scaled); first: {}", predictions_resized, names.size(),
                 o.flow_resize == FlowResize::kNearest ? "nearest" : "bilinear", resized);
  if (with_objects > 0 && with_objects < scored)
    spdlog::warn("{} of {} pairs have no object map (training/obj_map/<pair>_10.png): background and foreground "
                 "errors are over the other {} only", scored - with_objects, scored, with_objects);
  EvalResult r;
  full.put(r, "", scored);
  if (split_stages) rigid.put(r, "rigid_", scored);
  r.counts = {{"pairs", scored}, {"pixels_all", px_occ}, {"pixels_noc", px_noc},
              {"pairs_without_ground_truth", static_cast<int64_t>(without_gt.size())},
              {"pairs_with_object_map", with_objects}};
  if (with_objects > 0)
    r.counts.insert(r.counts.end(), {{"pixels_bg", full.bg.pixels}, {"pixels_fg", full.fg.pixels}});
  if (from_files) r.counts.emplace_back("predictions_resized", predictions_resized);
  if (source.model()) {
    r.counts.emplace_back("pairs_with_frame_09", with_previous);
    if (with_previous < static_cast<int64_t>(names.size()))
      spdlog::warn("{} of {} pairs have no previous frame (training/image_2/<pair>_09.png, KITTI 2015's multi-view "
                   "extension): the PoseNet saw the duplicate-frame snippet (tgt, tgt, src) for them",
                   static_cast<int64_t>(names.size()) - with_previous, names.size());
  }
  return r;
}

torch::Tensor positions(const torch::Tensor& poses) { return poses.slice(1, 0, 3).select(2, 3); }  // [N,3]

EvalResult eval_odometry(const EvalOptions& o, const std::string& root, PredictionSource& source) {
  const std::string seq = root + "/sequences/" + o.sequence, gt_path = root + "/poses/" + o.sequence + ".txt";
  require_file(gt_path, "ground-truth poses of sequence " + o.sequence);
  const auto gt = read_poses(gt_path);
  const int64_t n = gt.size(0);
  // Ground truth without motion: the whole sequence is refused; a static snippet (a stopped car)
  // scores ATE 0 whatever the prediction (the scale alignment scales it to nothing): counted, warned.
  if (!trajectory_moves(gt))
    throw std::runtime_error(gt_path + ": the ground truth has no motion (every position is the first): a trajectory "
                             "error means nothing; nothing was scored");
  const bool metric = source.model() && o.scaling == DepthScaling::kCameraHeight;
  const TrajectoryAnswer answer =
      source.trajectory(SequenceQuery{seq, o.sequence, gt_path, n, metric ? camera_height_of(o, root) : 0.0});
  const torch::Tensor& traj = answer.trajectory;
  // 5-frame PoseNets (GeoNet's odometry model): snippet c-2..c+2 predicted at once, cam_to_world of
  // its frames in the target's frame (the target's pose is the identity).
  const auto& snippet_poses = answer.snippet_poses;
  const torch::Tensor& metric_traj = answer.metric;  // camera-height: the trajectory in metres, no ground truth used
  const int64_t frames_with_road = answer.frames_with_road;
  require_finite(traj, source.model() ? std::string("the predicted trajectory") : "the trajectory " + source.name());
  if (!o.output_poses.empty()) write_poses(o.output_poses, traj);
  std::vector<int64_t> centres;
  if (!o.split_file.empty()) {
    for (const auto& e : read_split(o.split_file)) centres.push_back(e.frame);
  } else {
    for (int64_t i = 0; i < n; ++i) centres.push_back(i);
  }
  int64_t static_snippets = 0;
  std::vector<double> ates;
  for (int64_t c : centres) {
    if (c < 2 || c + 2 >= n) continue;  // snippets need two neighbours on each side
    auto rel = [&](const torch::Tensor& P, int64_t first) {  // positions in the snippet's first frame
      return positions(torch::inverse(P[first]).unsqueeze(0).matmul(P.slice(0, first, first + 5)));
    };
    // A 5-frame PoseNet is scored on its own snippet predictions (GeoNet's protocol); a 3-frame one
    // on the chained trajectory.
    const auto& own = snippet_poses[static_cast<size_t>(c)];
    if (rel(gt, c - 2).norm(2, 1).max().item<double>() < 1e-9) ++static_snippets;
    ates.push_back(snippet_ate(rel(gt, c - 2), own.defined() ? rel(own, 0) : rel(traj, c - 2)));
  }
  if (ates.empty()) throw std::runtime_error("sequence " + o.sequence + " has no 5-frame snippet");
  const auto t = torch::tensor(ates, torch::kFloat64);
  EvalResult r;
  r.metrics = {{"ate_mean", t.mean().item<double>()},
               {"ate_std", ates.size() > 1 ? t.std(false).item<double>() : 0.0},
               {"trajectory_rmse_sim3", aligned_trajectory_rmse(positions(gt), positions(traj))}};
  if (static_snippets > 0)
    spdlog::warn("{} of {} snippets have no ground-truth motion: they score ATE 0 whatever the prediction", static_snippets,
                 ates.size());
  // KITTI's own measures on the whole trajectory at the ground truth's scale (kitti-odom-eval's
  // --align scale: one least-squares factor, what a monocular trajectory needs).
  const auto [gt_aligned, traj_aligned] = align_trajectory_scale(gt, traj);
  const auto kitti = kitti_odometry_errors(gt_aligned, traj_aligned, o.segment_lengths);
  if (kitti.segments > 0) {
    r.metrics.emplace_back("t_err", kitti.t_err * 100);                  // %
    r.metrics.emplace_back("r_err", kitti.r_err * 180 / M_PI * 100);     // deg / 100 m
  } else {
    spdlog::warn("sequence {} is shorter than the shortest segment length ({} m): KITTI's t_err / r_err are not "
                 "computed (geo_eval --segment-lengths)", o.sequence,
                 o.segment_lengths.empty() ? 0.0 : *std::min_element(o.segment_lengths.begin(), o.segment_lengths.end()));
  }
  r.counts = {{"snippets", static_cast<int64_t>(ates.size())}, {"frames", n}, {"static_snippets", static_snippets},
              {"segments", kitti.segments}};
  if (metric_traj.defined()) {
    // Metres without ground truth: KITTI's measures on the trajectory as predicted (first frames
    // aligned, no scale fitted), and the factor the least-squares alignment would still apply.
    const auto g0 = torch::inverse(gt[0]).unsqueeze(0).matmul(gt.to(torch::kFloat64));
    const auto m0 = torch::inverse(metric_traj[0]).unsqueeze(0).matmul(metric_traj);
    const auto metric_kitti = kitti_odometry_errors(g0, m0, o.segment_lengths);
    if (metric_kitti.segments > 0) {
      r.metrics.emplace_back("metric_t_err", metric_kitti.t_err * 100);
      r.metrics.emplace_back("metric_r_err", metric_kitti.r_err * 180 / M_PI * 100);
    }
    r.metrics.emplace_back("metric_scale_error",
                           least_squares_scale(g0.slice(1, 0, 3).select(2, 3), m0.slice(1, 0, 3).select(2, 3), 0.0));
    r.counts.emplace_back("frames_with_road_plane", frames_with_road);
  }
  return r;
}


// A geo_synth world (its README.txt at `data_root` or above `root`): its kitti2015/ and odometry/
// scenes are rendered for them alone, none of them a raw drive.
bool is_synth_world(const std::string& data_root, const std::string& root) {
  for (const auto& dir : {data_root, root + "/.."}) {
    const std::string readme = dir + "/README.txt";
    if (fs::exists(readme) && read_text_file(readme).rfind("Synthetic KITTI-format world written by geo_synth", 0) == 0)
      return true;
  }
  return false;
}

// Which test drives the model trained on, its own run or any checkpoint of its init chain (each
// checkpoint records what its init was trained on): warned about and recorded in the result.
void check_training_drives(EvalResult& r, const Predictor& pred) {
  const auto& config = pred.training_config();
  if (!config) {
    r.training_drives_unknown = "the model carries no training config (a geo_export model file or an untrained model)";
    return;
  }
  struct Link {
    std::string what;  // "the model's training data (data.split X)" or "init 1 (data.split Y)"
    TrainingDrives drives;
  };
  std::vector<Link> links{{"the model's training data (data.split " + config->data.split + ")", training_drives(config->data)}};
  const auto& chain = pred.init_configs();
  for (size_t i = 0; i < chain.size(); ++i) {
    Link l;
    if (chain[i].rfind("unknown: ", 0) == 0) {
      l.what = "init " + std::to_string(i + 1);
      l.drives.unknown = "its weights started from a checkpoint whose training data is unknown: " + chain[i].substr(9);
    } else {
      const Config c = parse_config(chain[i], "init " + std::to_string(i + 1) + " of " + pred.path());
      l.what = "the data of the checkpoint it was initialised from" + std::string(i ? " (" + std::to_string(i + 1) + " links up)" : "") +
               " (data.split " + c.data.split + ")";
      l.drives = training_drives(c.data);
    }
    links.push_back(std::move(l));
  }
  std::set<std::string> leaked;
  for (const auto& l : links) {
    if (!l.drives.unknown.empty()) {  // a leak another link shows is still recorded
      if (r.training_drives_unknown.empty()) {
        r.training_drives_unknown = l.drives.unknown;
        spdlog::warn("cannot tell whether the model trained on test drives: {}", l.drives.unknown);
      }
      continue;
    }
    std::vector<std::string> here;
    for (const auto& d : r.test_drives)
      if (l.drives.drives.count(d)) here.push_back(d), leaked.insert(d);
    if (!here.empty())
      spdlog::warn("{} holds {} of the {} drives of this test set: {}. These results are measured on training drives; "
                   "train on data disjoint from the test set (README, KITTI)",
                   l.what, here.size(), r.test_drives.size(), join_list(here, ", "));
  }
  for (const auto& d : r.test_drives)
    if (leaked.count(d)) r.test_drives_in_training.push_back(d);
}

}  // namespace

EvalResult export_eigen_ground_truth(const EvalOptions& o, const std::string& dir) {
  if (!fs::is_directory(o.data_root)) throw std::runtime_error("data root '" + o.data_root + "' is not a directory (--data-root)");
  const std::string root = split_root("eigen", o.data_root);
  const std::string list = eigen_list(o, root);
  const auto entries = read_split(list);
  fs::create_directories(dir);
  VelodyneDepthOptions vo;
  vo.matlab_offset = o.matlab_offset;
  Progress progress("eigen ground truth", static_cast<int64_t>(entries.size()), 0, "images");
  for (size_t i = 0; i < entries.size(); ++i) {
    const auto test = eigen_test_image(root, entries[i], i, list);
    const auto img = read_image(test.image);
    const auto gt = velodyne_depth(read_velodyne(test.velodyne), test.calib.img_from_velo(), img.size(1), img.size(2), vo);
    write_depth_png(dir + "/" + zero_padded(static_cast<long long>(i), 6) + ".png", gt);
    progress.update(static_cast<int64_t>(i + 1));
  }
  EvalResult r;
  r.split = "eigen";
  r.source = "ground truth export";
  r.data_root = root;
  r.counts = {{"exported", static_cast<int64_t>(entries.size())}, {"listed", static_cast<int64_t>(entries.size())}};
  return r;
}

std::string split_root(const std::string& split, const std::string& root) {
  const std::string sub = split == "eigen" ? "/raw" : split == "kitti2015" ? "/kitti2015" : "/odometry";
  return fs::is_directory(root + sub) ? root + sub : root;
}

DepthScaling depth_scaling_named(const std::string& name) {
  if (name == "median") return DepthScaling::kMedian;
  if (name == "camera-height") return DepthScaling::kCameraHeight;
  if (name == "none") return DepthScaling::kNone;
  throw std::runtime_error("depth scaling '" + name + "': must be median, camera-height or none");
}

FlowResize flow_resize_named(const std::string& name) {
  if (name == "nearest") return FlowResize::kNearest;
  if (name == "bilinear") return FlowResize::kBilinear;
  throw std::runtime_error("flow resize '" + name + "': must be nearest or bilinear");
}

void check_eval_options(const EvalOptions& o) {
  if (o.split.empty()) throw std::runtime_error("--split is required (eigen, kitti2015 or odometry); see --help");
  if (o.split != "eigen" && o.split != "kitti2015" && o.split != "odometry")
    throw std::runtime_error("split '" + o.split + "': must be eigen, kitti2015 or odometry");
  if (o.scaling == DepthScaling::kCameraHeight && o.split == "kitti2015")
    throw std::runtime_error("--scaling camera-height is for --split eigen and odometry: flow has no scale to set");
  if (o.camera_height != 0 && o.scaling != DepthScaling::kCameraHeight)
    throw std::runtime_error(std::string("--camera-height is used by --scaling camera-height only (the scaling is '") +
                             (o.scaling == DepthScaling::kMedian ? "median" : "none") + "')");
}

EvalResult evaluate(const EvalOptions& o, PredictionSource& source) {
  Predictor* pred = source.model();
  if (!fs::is_directory(o.data_root)) throw std::runtime_error("data root '" + o.data_root + "' is not a directory (--data-root)");
  const std::string root = split_root(o.split, o.data_root);
  EvalResult r;
  if (o.split == "eigen") r = eval_eigen(o, root, source);
  else if (o.split == "kitti2015") r = eval_kitti2015(o, root, source);
  else if (o.split == "odometry") r = eval_odometry(o, root, source);
  else throw std::runtime_error("unknown split '" + o.split + "' (eigen, kitti2015, odometry)");
  r.split = o.split;
  if (o.split == "eigen" || (o.split == "odometry" && pred && o.scaling == DepthScaling::kCameraHeight))
    r.scaling = o.scaling == DepthScaling::kMedian ? "median"
                : o.scaling == DepthScaling::kNone ? "none"
                                                   : "camera-height " + std::to_string(camera_height_of(o, root)) + " m";
  r.source = source.name();
  if (pred) r.precision = pred->precision();
  r.data_root = root;
  if (o.split == "odometry") r.subset = "sequence " + o.sequence;
  if (!o.split_file.empty()) r.subset += (r.subset.empty() ? "list " : ", list ") + o.split_file;
  if (!is_synth_world(o.data_root, root)) {
    // Real KITTI: the 200 KITTI 2015 pairs come from the 29 raw drives of stereo/test_scenes_stereo.txt,
    // an odometry sequence 00-10 from one raw drive.
    if (o.split == "kitti2015") {
      const std::string scenes = find_split_file(root, "stereo", "test_scenes_stereo.txt");
      if (!scenes.empty())
        for (const auto& d : read_scene_list(scenes)) r.test_drives.push_back(d);
    } else if (o.split == "odometry") {
      if (const auto d = odometry_raw_drive(o.sequence); !d.empty()) r.test_drives.push_back(d);
    }
  }
  if (pred) check_training_drives(r, *pred);
  return r;
}

std::string EvalResult::json() const {
  std::ostringstream s;
  s.precision(9);
  auto q = [](const std::string& x) {
    std::string out = "\"";
    for (char c : x) out += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
    return out + "\"";
  };
  s << "{\n  \"split\": " << q(split) << ",\n  \"source\": " << q(source) << ",\n  \"data_root\": " << q(data_root);
  if (!scaling.empty()) s << ",\n  \"scaling\": " << q(scaling);
  if (!precision.empty()) s << ",\n  \"precision\": " << q(precision);
  if (!subset.empty()) s << ",\n  \"subset\": " << q(subset);
  s << ",\n  \"metrics\": {";
  for (size_t i = 0; i < metrics.size(); ++i) {  // JSON has no NaN/Inf: a non-finite metric is null
    s << (i ? ", " : "") << q(metrics[i].first) << ": ";
    if (std::isfinite(metrics[i].second)) s << metrics[i].second;
    else s << "null";
  }
  s << "},\n  \"counts\": {";
  for (size_t i = 0; i < counts.size(); ++i) s << (i ? ", " : "") << q(counts[i].first) << ": " << counts[i].second;
  s << "}";
  auto list = [&](const char* key, const std::vector<std::string>& items) {
    s << ",\n  \"" << key << "\": [";
    for (size_t i = 0; i < items.size(); ++i) s << (i ? ", " : "") << q(items[i]);
    s << "]";
  };
  list("test_drives", test_drives);
  list("test_drives_in_training", test_drives_in_training);
  if (!training_drives_unknown.empty()) s << ",\n  \"training_drives_unknown\": " << q(training_drives_unknown);
  s << "\n}\n";
  return s.str();
}

EvalResult read_result(const std::string& path) {
  YAML::Node n;
  try {
    n = YAML::LoadFile(path);
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot read results '" + path + "': " + e.what());
  }
  const auto not_results = [&](const std::string& why) {
    return std::runtime_error("'" + path + "' is not a geo_eval results file (--output of geo_eval): " + why);
  };
  if (!n.IsMap()) throw not_results("not a JSON object");
  for (const char* key : {"split", "metrics", "counts"})
    if (!n[key]) throw not_results(std::string("no '") + key + "'");
  EvalResult r;
  try {
    r.split = n["split"].as<std::string>();
    r.source = n["source"].as<std::string>("");
    r.data_root = n["data_root"].as<std::string>("");
    r.scaling = n["scaling"].as<std::string>("");
    r.precision = n["precision"].as<std::string>("");
    r.subset = n["subset"].as<std::string>("");
    if (!n["metrics"].IsMap() || !n["counts"].IsMap()) throw std::runtime_error("'metrics' and 'counts' must be objects");
    for (const auto& kv : n["metrics"])
      r.metrics.emplace_back(kv.first.as<std::string>(),
                             kv.second.IsNull() ? std::numeric_limits<double>::quiet_NaN() : kv.second.as<double>());
    for (const auto& kv : n["counts"]) r.counts.emplace_back(kv.first.as<std::string>(), kv.second.as<int64_t>());
    for (const auto& d : n["test_drives"]) r.test_drives.push_back(d.as<std::string>());
    for (const auto& d : n["test_drives_in_training"]) r.test_drives_in_training.push_back(d.as<std::string>());
    r.training_drives_unknown = n["training_drives_unknown"].as<std::string>("");
  } catch (const std::exception& e) {
    throw not_results(e.what());
  }
  if (r.split != "eigen" && r.split != "kitti2015" && r.split != "odometry")
    throw not_results("unknown split '" + r.split + "'");
  if (r.metrics.empty() || r.counts.empty()) throw not_results("no metrics or no counts");
  return r;
}

std::string format_results(const std::vector<EvalResult>& results, const std::vector<std::string>& names) {
  std::ostringstream s;
  std::vector<std::string> keys;
  for (const auto& r : results)
    for (const auto& m : r.metrics)
      if (std::find(keys.begin(), keys.end(), m.first) == keys.end()) keys.push_back(m.first);
  const auto column = [](const std::string& n) { return fmt::format(" {:>14}", n.size() > 14 ? n.substr(n.size() - 14) : n); };
  s << fmt::format("{:<22}", "metric");
  for (const auto& n : names) s << column(n);
  s << "\n";
  for (const auto& k : keys) {
    s << fmt::format("{:<22}", k);
    for (const auto& r : results) {
      auto it = std::find_if(r.metrics.begin(), r.metrics.end(), [&](const auto& m) { return m.first == k; });
      s << (it == r.metrics.end() ? fmt::format(" {:>14}", "-") : fmt::format(" {:>14.4f}", it->second));
    }
    s << "\n";
  }
  // What each column scored: the protocol's first count (images, pairs, snippets).
  const auto scored = [](const EvalResult& r) { return r.counts.empty() ? std::string("-") : std::to_string(r.counts[0].second) + " " + r.counts[0].first; };
  s << fmt::format("{:<22}", "scored");
  for (const auto& r : results) s << column(scored(r));
  s << "\n";
  for (size_t i = 0; i < results.size(); ++i) {
    s << names[i] << ":";
    for (const auto& c : results[i].counts) s << " " << c.first << " " << c.second;
    if (!results[i].test_drives_in_training.empty())
      s << " -- trained on " << results[i].test_drives_in_training.size() << " of the "
        << results[i].test_drives.size() << " test drives: " << join_list(results[i].test_drives_in_training, ", ");
    if (!results[i].training_drives_unknown.empty())
      s << " -- whether it trained on test drives is unknown: " << results[i].training_drives_unknown;
    s << "\n";
  }
  // Every difference other than the model, as a note: a column can only be read beside another
  // when they scored the same things the same way.
  const auto differ = [&](const std::string& what, const std::function<std::string(const EvalResult&)>& of) {
    bool same = true;
    for (const auto& r : results) same = same && of(r) == of(results[0]);
    if (same) return;
    s << "note: the columns differ in " << what << ":";
    for (size_t i = 0; i < results.size(); ++i) {
      const auto v = of(results[i]);
      s << (i ? "," : "") << " " << names[i] << " " << (v.empty() ? "(none)" : v);
    }
    s << "\n";
  };
  differ("split", [](const EvalResult& r) { return r.split; });
  differ("data root", [](const EvalResult& r) { return r.data_root; });
  differ("scaling", [](const EvalResult& r) { return r.scaling; });
  differ("precision", [](const EvalResult& r) { return r.precision; });
  differ("subset", [](const EvalResult& r) { return r.subset; });
  std::vector<std::string> count_keys;
  for (const auto& r : results)
    for (const auto& c : r.counts)
      if (std::find(count_keys.begin(), count_keys.end(), c.first) == count_keys.end()) count_keys.push_back(c.first);
  for (const auto& k : count_keys)
    differ("'" + k + "' (the metrics average over different sets)", [&](const EvalResult& r) {
      for (const auto& c : r.counts)
        if (c.first == k) return std::to_string(c.second);
      return std::string();
    });
  return s.str();
}

}  // namespace geo
