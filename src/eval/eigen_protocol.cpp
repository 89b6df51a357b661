// The Eigen depth protocol (eval/protocols.h): Velodyne ground truth, Garg crop, scaling, and the
// moving objects apart where the data marks them; the ground-truth export.
#include "eval/protocol_parts.h"

#include "core/files.h"
#include "core/progress.h"
#include "data/image_io.h"
#include "data/kitti/calib.h"
#include "data/kitti/splits.h"
#include "data/kitti/velodyne_depth.h"
#include "data/text_io.h"
#include "eval/metrics.h"
#include "geometry/camera.h"
#include "geometry/road_plane.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace geo {

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

namespace {

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
  EigenTestImage t{e.image_path(root),
                   root + "/" + e.folder + "/velodyne_points/data/" + zero_padded(e.frame, 10) + ".bin",
                   read_raw_calib(root + "/" + e.date(), e.camera())};
  require_file(t.image, "test image (line " + std::to_string(line + 1) + " of " + list + ")");
  require_file(t.velodyne, "Velodyne scan");
  return t;
}

// What the Eigen protocol adds up over the test images, and what it says about them.
struct EigenTally {
  size_t listed = 0;
  std::vector<double> sums = std::vector<double>(7, 0.0);
  int64_t images = 0, pixels = 0;
  std::vector<std::string> without_gt;  // scans that give no valid pixel (empty, NaN, all out of range)
  int64_t non_finite_points = 0, scans_with_non_finite = 0;  // NaN/Inf points are left out, counted
  int64_t images_nonpositive = 0, pixels_nonpositive = 0;    // predicted depths <= 0, clamped, counted
  std::vector<double> median_ratios, agreements;             // median(gt)/median(pred); camera-height scale / that
  std::vector<std::string> without_plane;                    // camera-height scaling: images whose road was not found
  std::string first_nonpositive, first_non_finite, first_resized;
  bool from_files = false;          // predictions from files, meant at the image's size
  int64_t predictions_resized = 0;  // of them, those of another size (resized bilinearly)
  // Where the data root marks moving objects (geo_synth's raw/<drive>/obj_map/image_0X/<frame>.png,
  // 0 = static), their pixels are also scored apart, at the whole image's scale, pooled over pixels;
  // among them those of the objects that keep their distance to the camera, where
  // raw/<drive>/obj_map/with_camera.txt lists their values.
  struct Pooled {
    double abs_rel_sum = 0, a1_sum = 0;
    int64_t pixels = 0;
    void add(const DepthErrors& m) {
      abs_rel_sum += m.abs_rel * static_cast<double>(m.pixels);
      a1_sum += m.a1 * static_cast<double>(m.pixels);
      pixels += m.pixels;
    }
    // <name>_abs_rel and <name>_a1, where pixels were scored.
    void report(const std::string& name, EvalResult& r) const {
      if (pixels == 0) return;
      r.metrics.emplace_back(name + "_abs_rel", abs_rel_sum / static_cast<double>(pixels));
      r.metrics.emplace_back(name + "_a1", a1_sum / static_cast<double>(pixels));
    }
  };
  Pooled moving, with_camera;
  // Per image: how deep those cars came out against the static scene, (median(pred) / median(gt)) on
  // their pixels over the same on the static ones (object map 0); 1 is right, above 1 too far (what
  // self-supervised depth learns for a car keeping its distance), whatever the image's scale.
  std::vector<double> with_camera_depth_ratios;
  int64_t images_with_object_maps = 0, images_with_camera_lists = 0;
  std::map<std::string, std::optional<std::vector<int64_t>>> with_camera_lists;  // by list file, read once

  // A prediction of line i: finite, of the image's shape (a file of another size is resized, counted
  // and said; one of another shape refused), not <= 0 everywhere (some <= 0 are counted).
  void check_prediction(const DepthAnswer& answer, size_t i, const std::string& image) {
    const torch::Tensor& depth = answer.depth;
    const int64_t H = answer.height, W = answer.width;
    const std::string line = std::to_string(i + 1);
    require_finite(depth, "the depth prediction for line " + line + " (" + image + ")");
    if (answer.from_file) {
      from_files = true;
      const int64_t h = depth.size(0), w = depth.size(1);
      if (h != H || w != W) {
        const double aspect = (static_cast<double>(h) / w) / (static_cast<double>(H) / W);
        if (aspect > 1.2 || aspect < 1 / 1.2)
          throw std::runtime_error("the depth prediction for line " + line + " (" + image + ") is " +
                                   std::to_string(h) + "x" + std::to_string(w) + " (HxW) for an image of " +
                                   std::to_string(H) + "x" + std::to_string(W) + ": another shape" +
                                   (h == W && w == H ? " (H and W swapped)" : "") + "; nothing was scored");
        if (predictions_resized++ == 0)
          first_resized = line + " (" + std::to_string(h) + "x" + std::to_string(w) + " vs " + std::to_string(H) + "x" +
                          std::to_string(W) + ")";
      }
    }
    // Depths are positive: all <= 0 is no depth map (a disparity's sign, a log depth); some <= 0 are
    // clamped to 1e-3 as every protocol does, counted and reported.
    const int64_t nonpositive = (depth <= 0).sum().item<int64_t>();
    if (nonpositive == depth.numel())
      throw std::runtime_error("the depth prediction for line " + line + " (" + image +
                               ") is <= 0 everywhere: depths must be positive (a log depth or a negated "
                               "disparity?); nothing was scored");
    if (nonpositive > 0 && images_nonpositive++ == 0) first_nonpositive = line;
    pixels_nonpositive += nonpositive;
  }

  // A scan's points with a NaN or infinite coordinate, counted (the projection leaves them out).
  void count_scan(const torch::Tensor& points, const std::string& velo) {
    if (const int64_t bad = count_non_finite_points(points); bad > 0) {
      non_finite_points += bad;
      if (scans_with_non_finite++ == 0) first_non_finite = velo;
    }
  }

  // One image's errors (at the scale `applied`; `ratio`: median(gt)/median(pred)).
  void add(const DepthErrors& err, double applied, double ratio, bool camera_height) {
    median_ratios.push_back(ratio);
    if (camera_height) agreements.push_back(applied / ratio);
    const double v[7] = {err.abs_rel, err.sq_rel, err.rmse, err.rmse_log, err.a1, err.a2, err.a3};
    for (int k = 0; k < 7; ++k) sums[k] += v[k];
    ++images;
    pixels += err.pixels;
  }

  // The values a drive's with_camera.txt lists (null without the file), read once a file.
  const std::vector<int64_t>* with_camera_values(const std::string& list) {
    const auto known = with_camera_lists.find(list);
    if (known != with_camera_lists.end()) return known->second ? &*known->second : nullptr;
    std::optional<std::vector<int64_t>> values;
    if (fs::exists(list)) {
      values.emplace();
      for (const double v : parse_doubles(read_text_file(list), list)) {
        if (!(v >= 1 && v <= 255) || v != std::floor(v))
          throw std::runtime_error(list + ": '" + fmt::format("{}", v) +
                                   "' is not an object-map value (a whole number from 1 to 255)");
        values->push_back(static_cast<int64_t>(v));
      }
    }
    const auto& kept = with_camera_lists.emplace(list, std::move(values)).first->second;
    return kept ? &*kept : nullptr;
  }

  // The moving objects' pixels of an image whose object map exists, scored at the image's scale;
  // those of the objects `with_camera_list` names apart as well.
  void add_moving(const std::string& objects, const std::string& with_camera_list, const torch::Tensor& gt,
                  const torch::Tensor& depth, const EigenOptions& eo, double applied) {
    const auto map = read_object_map(objects);
    if (map.size(0) != gt.size(0) || map.size(1) != gt.size(1))
      throw std::runtime_error("object map '" + objects + "' is " + std::to_string(map.size(0)) + "x" +
                               std::to_string(map.size(1)) + ", its image " + std::to_string(gt.size(0)) + "x" +
                               std::to_string(gt.size(1)));
    ++images_with_object_maps;
    EigenOptions at_scale = eo;
    at_scale.median_scaling = false;
    at_scale.fixed_scale = applied;
    // The errors on `mask`'s pixels; `ratio`: median(gt) / median(pred) there (whatever the scale).
    const auto score = [&](const torch::Tensor& mask, double* ratio = nullptr) {
      return eigen_image_errors(gt * mask.to(gt.dtype()), depth, at_scale, nullptr, ratio);
    };
    moving.add(score(map > 0));
    const auto* values = with_camera_values(with_camera_list);
    if (!values) return;
    ++images_with_camera_lists;
    auto mask = torch::zeros_like(map, torch::kBool);
    for (const int64_t v : *values) mask |= map == v;
    double car = 0, scene = 0;
    const auto cars = score(mask, &car);
    with_camera.add(cars);
    if (cars.pixels > 0 && score(map == 0, &scene).pixels > 0) with_camera_depth_ratios.push_back(scene / car);
  }

  // What was left out, clamped or resized, said once each.
  void warn() const {
    if (!without_gt.empty())
      spdlog::warn(
          "{} of {} test images have no usable ground truth (no finite Velodyne point in the evaluated "
          "region) and are left out of the means; first: {}",
          without_gt.size(), listed, without_gt.front());
    if (!without_plane.empty())
      spdlog::warn("camera-height scaling: no road plane in {} of {} test images, left out of the means; first: {}",
                   without_plane.size(), listed, without_plane.front());
    if (images_nonpositive > 0)
      spdlog::warn(
          "{} of {} depth predictions hold {} depths <= 0 (first: line {}), clamped to 1e-3 before scoring: "
          "is the prediction a depth map?",
          images_nonpositive, listed, pixels_nonpositive, first_nonpositive);
    if (non_finite_points > 0)
      spdlog::warn(
          "{} Velodyne points in {} of {} scans have a NaN or infinite coordinate and are left out of the "
          "ground truth; first: {}",
          non_finite_points, scans_with_non_finite, listed, first_non_finite);
    if (predictions_resized > 0)
      spdlog::warn(
          "{} of {} depth predictions differ in size from their image and were resized bilinearly; first: "
          "line {}",
          predictions_resized, listed, first_resized);
  }

  // The means, the scale's spread and the counts.
  EvalResult result(const std::vector<SplitEntry>& entries) const {
    if (images == 0)
      throw std::runtime_error(without_plane.empty()
                                   ? "no test image had valid ground-truth pixels"
                                   : "no test image had a road plane for camera-height scaling; first: " +
                                         without_plane.front());
    EvalResult r;
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
    moving.report("moving", r);
    with_camera.report("with_camera", r);
    if (!with_camera_depth_ratios.empty())
      r.metrics.emplace_back("with_camera_depth_ratio",
                             numpy_median(torch::tensor(with_camera_depth_ratios, torch::kFloat64)));
    r.counts = {{"images", images},
                {"pixels", pixels},
                {"listed", static_cast<int64_t>(listed)},
                {"images_without_ground_truth", static_cast<int64_t>(without_gt.size())},
                {"velodyne_points_non_finite", non_finite_points},
                {"predictions_with_nonpositive_depth", images_nonpositive},
                {"images_without_road_plane", static_cast<int64_t>(without_plane.size())}};
    if (images_with_object_maps > 0) {
      r.counts.emplace_back("images_with_object_maps", images_with_object_maps);
      r.counts.emplace_back("moving_pixels", moving.pixels);
    }
    if (images_with_camera_lists > 0) r.counts.emplace_back("with_camera_pixels", with_camera.pixels);
    if (from_files) r.counts.emplace_back("predictions_resized", predictions_resized);
    return r;
  }
};

}  // namespace

EvalResult eval_eigen(const EvalOptions& o, const std::string& root, PredictionSource& source) {
  const std::string list = eigen_list(o, root);
  const auto entries = read_split(list);
  EigenOptions eo;
  eo.median_scaling = o.scaling == DepthScaling::kMedian;
  VelodyneDepthOptions vo;
  vo.matlab_offset = o.matlab_offset;
  const bool by_camera_height = o.scaling == DepthScaling::kCameraHeight;
  const double camera_height = by_camera_height ? camera_height_of(o, root) : 0.0;
  EigenTally tally;
  tally.listed = entries.size();
  Progress progress("eigen", static_cast<int64_t>(entries.size()), 0, "images");
  for (size_t i = 0; i < entries.size(); ++i) {
    const auto test = eigen_test_image(root, entries[i], i, list);
    const DepthAnswer answer = source.depth(DepthQuery{i, entries.size(), list, test.image});
    tally.check_prediction(answer, i, test.image);
    const torch::Tensor depth = answer.depth.clamp_min(1e-3);
    const auto points = read_velodyne(test.velodyne);
    tally.count_scan(points, test.velodyne);
    const auto gt = velodyne_depth(points, test.calib.img_from_velo(), answer.height, answer.width, vo);
    EigenOptions image_eo = eo;
    if (by_camera_height) {
      // The intrinsics of the prediction's size; the road plane fitted to the prediction alone.
      const auto K = resized_intrinsics(test.calib.K(), answer.height, answer.width, depth.size(0), depth.size(1));
      const auto plane = fit_road_plane(depth, K);
      if (!plane.found) {
        tally.without_plane.push_back(test.image + " (" + plane.why + ")");
        progress.update(static_cast<int64_t>(i + 1));
        continue;
      }
      image_eo.fixed_scale = camera_height_scale(plane, camera_height);
    }
    double applied = 1, ratio = 1;
    const auto err = eigen_image_errors(gt, depth, image_eo, &applied, &ratio);
    if (err.pixels > 0) {
      tally.add(err, applied, ratio, by_camera_height);
      const std::string objects = root + "/" + entries[i].folder + "/obj_map/image_0" +
                                  std::to_string(entries[i].camera()) + "/" + zero_padded(entries[i].frame, 10) +
                                  ".png";
      if (fs::exists(objects))
        tally.add_moving(objects, root + "/" + entries[i].folder + "/obj_map/with_camera.txt", gt, depth, eo, applied);
    } else {
      tally.without_gt.push_back(test.velodyne);
    }
    progress.update(static_cast<int64_t>(i + 1));
  }
  tally.warn();
  return tally.result(entries);
}

EvalResult export_eigen_ground_truth(const EvalOptions& o, const std::string& dir) {
  if (!fs::is_directory(o.data_root))
    throw std::runtime_error("data root '" + o.data_root + "' is not a directory (--data-root)");
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
    const auto gt =
        velodyne_depth(read_velodyne(test.velodyne), test.calib.img_from_velo(), img.size(1), img.size(2), vo);
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

}  // namespace geo
