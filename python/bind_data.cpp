// geo.synth (the synthetic world in memory, with its ground truth), geo.kitti (KITTI's calibration,
// Velodyne and pose files, Velodyne ground-truth depth) and geo.eval (the protocols' metrics on
// arrays): LibTorch only, in every build.
#include "bindings.h"

#include "data/kitti/calib.h"
#include "data/synth/synth.h"
#include "data/synth/synth_snippets.h"
#include "data/text_io.h"
#include "data/kitti/velodyne_depth.h"
#include "eval/metrics.h"
#include "geo/geo.h"
#include "geometry/road_plane.h"

#include <cmath>

namespace geo::python {

using namespace pybind11::literals;

namespace {

py::dict synth_world(int64_t frames, uint64_t seed, int drive, const std::string& preset, int64_t height, int64_t width,
                     int supersample, double turns, bool traffic, bool flow, bool lidar) {
  if (frames < 1 || frames > 10000) throw Error("frames must be in 1..10000 (got " + std::to_string(frames) + ")");
  if (drive < 0 || drive > 999) throw Error("drive must be in 0..999 (got " + std::to_string(drive) + ")");
  if (supersample < 1 || supersample > 8)
    throw Error("supersample must be in 1..8 (got " + std::to_string(supersample) + ")");
  if (!(turns > 0 && turns <= 10)) throw Error("turns must be in (0, 10] (got " + std::to_string(turns) + ")");
  SynthOptions base = SynthOptions::preset_named(preset);
  if ((height == 0) != (width == 0)) throw Error("give height and width together (or neither: the preset's size)");
  if (height && (height < 16 || height > 4096 || width < 16 || width > 4096))
    throw Error("height and width must be in 16..4096 (got " + std::to_string(height) + "x" + std::to_string(width) +
                ")");
  SynthOptions o = height ? synth_world_at(preset, height, width) : base;
  o.seed = seed, o.supersample = supersample, o.turns = turns, o.traffic = traffic;
  torch::Tensor images, depths, objects, poses, flows, noc, occ, moving;
  std::vector<torch::Tensor> scans;
  {
    py::gil_scoped_release release;
    const SynthScene scene(synth_drive_seed(seed, 0, drive), frames, turns, traffic);
    std::vector<torch::Tensor> im, de, ob, po, fl, nc, oc, mv;
    for (int64_t f = 0; f < frames; ++f) {
      auto frame = render_frame(scene, f, o);
      // As geo_synth's PNGs hold it (8-bit RGB).
      im.push_back((frame.image.clamp(0, 1) * 255).round().to(torch::kUInt8));
      de.push_back(frame.depth[0]);
      ob.push_back(frame.object);
      mv.push_back(synth_object_map(scene, frame.object) > 0);
      po.push_back(frame.pose.matrix());
      if (flow && f + 1 < frames) {
        auto sf = render_flow(scene, f, o);
        fl.push_back(sf.flow), nc.push_back(sf.valid_noc[0] > 0.5), oc.push_back(sf.valid_occ[0] > 0.5);
      }
      if (lidar) scans.push_back(render_lidar(scene, f, o));
    }
    images = torch::stack(im), depths = torch::stack(de), objects = torch::stack(ob), poses = torch::stack(po);
    moving = torch::stack(mv);
    if (!fl.empty()) flows = torch::stack(fl), noc = torch::stack(nc), occ = torch::stack(oc);
  }
  py::dict d;
  d["images"] = images;    // [N,3,H,W] uint8
  d["depths"] = depths;    // [N,H,W] float32 metres (camera z), 0 = sky
  d["objects"] = objects;  // [N,H,W] int32: box id, -1 road, -2 sky
  d["moving"] = moving;    // [N,H,W] bool: independently moving objects (KITTI 2015's obj_map > 0)
  d["poses"] = poses;      // [N,4,4] float64 camera-to-world
  d["intrinsics"] = o.intrinsics.K();
  d["camera_height"] = kSynthCameraHeight;
  if (flow && frames > 1) d["flow"] = flows, d["flow_noc"] = noc, d["flow_occ"] = occ;
  if (lidar) d["lidar"] = scans, d["cam_from_velo"] = synth_cam_from_velo();
  return d;
}

py::dict depth_metrics(py::handle gt, py::handle pred, py::object scaling, double min_depth, double max_depth,
                       bool garg_crop) {
  EigenOptions o;
  o.min_depth = min_depth, o.max_depth = max_depth, o.garg_crop = garg_crop;
  if (py::isinstance<py::str>(scaling)) {
    const auto s = py::cast<std::string>(scaling);
    if (s == "median") o.median_scaling = true;
    else if (s == "none") o.median_scaling = false;
    else
      throw Error("scaling must be 'median', 'none' or a number > 0 (a known scale, e.g. from road_scale()); got '" +
                  s + "'");
  } else {
    const double s = py::cast<double>(scaling);
    if (!(s > 0 && std::isfinite(s)))
      throw Error("scaling must be 'median', 'none' or a number > 0 (got " + std::to_string(s) + ")");
    o.median_scaling = false, o.fixed_scale = s;
  }
  const auto g = tensor_arg(gt, "gt"), p = tensor_arg(pred, "pred");
  if (g.dim() != 2 || p.dim() != 2) throw Error("gt and pred must be [H,W] depth maps (one image)");
  double scale = 0, ratio = 0;
  DepthErrors e;
  {
    py::gil_scoped_release release;
    e = eigen_image_errors(g.to(torch::kFloat32), p.to(torch::kFloat32), o, &scale, &ratio);
  }
  py::dict d = as_dict(e.as_map());
  d["pixels"] = e.pixels, d["scale"] = scale, d["median_ratio"] = ratio;
  return d;
}

}  // namespace

void bind_data(py::module_& m) {
  auto synth = m.def_submodule("synth", "geo's synthetic driving world, rendered in memory with exact ground truth.");
  synth.def("world", &synth_world, py::kw_only(), "frames"_a = 3, "seed"_a = 1, "drive"_a = 0, "preset"_a = "tiny",
            "height"_a = 0, "width"_a = 0, "supersample"_a = 3, "turns"_a = 1.0, "traffic"_a = false, "flow"_a = true,
            "lidar"_a = false,
            "Renders `frames` consecutive frames of training drive `drive` of the world `seed` (geo_synth's\n"
            "drive drive+1, frames 0..frames-1) at the preset's size (tiny 64x208, kitti 375x1242) or height x width.\n"
            "traffic: stop-and-go traffic (the camera stands for stretches, a car ahead keeps its gap, trucks\n"
            "overtake, oncoming cars).\n"
            "Returns a dict: images [N,3,H,W] uint8, depths [N,H,W] (metres, 0 = sky), objects [N,H,W],\n"
            "moving [N,H,W] bool (independently moving objects),\n"
            "poses [N,4,4] camera-to-world, intrinsics [3,3], camera_height (m); with flow: flow [N-1,2,H,W]\n"
            "(pixels, frame i -> i+1), flow_noc / flow_occ [N-1,H,W] bool; with lidar: lidar (N scans [M,4]),\n"
            "cam_from_velo [4,4].");

  auto kitti =
      m.def_submodule("kitti", "KITTI's file formats (calibration, Velodyne scans, poses) and ground-truth depth.");
  kitti.def(
      "read_calib",
      [](const std::string& path) {
        const auto kv = read_key_values(path);
        py::dict d;
        for (const auto& [k, v] : kv.values) d[py::str(k)] = torch::tensor(v, torch::kFloat64);
        return d;
      },
      "path"_a, "Any KITTI calibration file (\"KEY: numbers\" lines) as {key: float64 tensor}.");
  kitti.def(
      "read_raw_calib",
      [](const std::string& date_dir, int camera, bool need_velo) {
        const auto c = read_raw_calib(date_dir, camera, need_velo);
        py::dict d;
        d["P_rect"] = c.P_rect, d["R_rect"] = c.R_rect, d["K"] = c.K();
        d["width"] = c.width, d["height"] = c.height;
        if (c.cam_from_velo.defined()) d["cam_from_velo"] = c.cam_from_velo, d["img_from_velo"] = c.img_from_velo();
        return d;
      },
      "date_dir"_a, "camera"_a = 2, "need_velo"_a = true,
      "A KITTI raw date folder's calib_cam_to_cam.txt (and calib_velo_to_cam.txt) for colour camera 2 or 3:\n"
      "{P_rect [3,4], R_rect [4,4], K [3,3], width, height, cam_from_velo [4,4], img_from_velo [3,4]} (float64).");
  kitti.def("read_velodyne", &read_velodyne, "path"_a, "A Velodyne scan (.bin): [N,4] float32 x, y, z, reflectance.");
  kitti.def("read_poses", &read_poses, "path"_a,
            "A KITTI pose file (a 3x4 camera-to-world matrix a line): [N,4,4] float64.");
  kitti.def(
      "write_poses", [](const std::string& path, py::handle poses) { write_poses(path, tensor_arg(poses, "poses")); },
      "path"_a, "poses"_a, "Writes [N,4,4] (or [N,3,4]) poses as a KITTI pose file.");
  kitti.def(
      "velodyne_depth",
      [](py::handle points, py::handle img_from_velo, int64_t height, int64_t width, bool exact_pixels) {
        VelodyneDepthOptions o;
        o.matlab_offset = !exact_pixels;
        const auto p = tensor_arg(points, "points"), P = tensor_arg(img_from_velo, "img_from_velo");
        py::gil_scoped_release release;
        return velodyne_depth(p, P, height, width, o);
      },
      "points"_a, "img_from_velo"_a, "height"_a, "width"_a, py::kw_only(), "exact_pixels"_a = false,
      "The Eigen protocol's ground-truth depth [H,W] of a scan (0 = no point): depth = Velodyne x, pixel =\n"
      "round(x/z) - 1 as the reference code (exact_pixels: without the -1), the nearest point kept.");

  auto metrics = m.def_submodule(
      "eval",
      "The published protocols' metrics on arrays (as geo_eval computes them) and, with OpenCV, geo_eval's protocols.");
  metrics.def("depth_errors", &depth_metrics, "gt"_a, "pred"_a, py::kw_only(), "scaling"_a = py::str("median"),
              "min_depth"_a = 1e-3, "max_depth"_a = 80.0, "garg_crop"_a = true,
              "Eigen depth errors of one image: gt [H,W] (0 = no ground truth), pred [h,w] (resized bilinearly to\n"
              "gt's size). scaling: 'median' (median(gt)/median(pred), the papers'), 'none', or a number (e.g.\n"
              "road_scale()'s). Returns {abs_rel, sq_rel, rmse, rmse_log, a1, a2, a3, pixels, scale, median_ratio}.");
  metrics.def(
      "road_scale",
      [](py::handle depth, py::handle intrinsics, double camera_height) {
        const auto d = tensor_arg(depth, "depth"), K = tensor_arg(intrinsics, "intrinsics");
        RoadPlane plane;
        {
          py::gil_scoped_release release;
          plane = fit_road_plane(d.to(torch::kFloat32), K.to(torch::kFloat64));
        }
        if (!plane.found) throw Error("no road plane in the depth map's lower part: " + plane.why);
        return camera_height_scale(plane, camera_height);
      },
      "depth"_a, "intrinsics"_a, "camera_height"_a = 1.65,
      "The factor taking a depth map to metres: camera_height / the height of the road plane fitted to its lower\n"
      "part (geo_eval --scaling camera-height). geo.Error when no road is found.");
  metrics.def(
      "flow_errors",
      [](py::handle gt, py::handle valid, py::handle pred, const std::string& resize) {
        if (resize != "nearest" && resize != "bilinear")
          throw Error("resize must be 'nearest' or 'bilinear' (got '" + resize + "')");
        const auto g = tensor_arg(gt, "gt"), v = tensor_arg(valid, "valid"), p = tensor_arg(pred, "pred");
        FlowErrors e;
        {
          py::gil_scoped_release release;
          e = flow_errors(g.to(torch::kFloat32), v.to(torch::kFloat32), p.to(torch::kFloat32),
                          resize == "bilinear" ? FlowResize::kBilinear : FlowResize::kNearest);
        }
        return py::dict("epe"_a = e.epe, "fl"_a = e.fl, "pixels"_a = e.pixels);
      },
      "gt"_a, "valid"_a, "pred"_a, "resize"_a = "nearest",
      "KITTI flow errors: gt [2,H,W], valid [H,W] (bool or 0/1), pred [2,h,w] (resized to gt with u, v scaled;\n"
      "nearest as GeoNet). {epe: mean end-point error, fl: fraction with EPE > 3 px and > 5% of |gt|, pixels}.");
  metrics.def(
      "snippet_ate",
      [](py::handle gt, py::handle pred) {
        return snippet_ate(tensor_arg(gt, "gt").to(torch::kFloat64), tensor_arg(pred, "pred").to(torch::kFloat64));
      },
      "gt"_a, "pred"_a,
      "SfMLearner's snippet ATE of positions [N,3]: first positions aligned, one least-squares scale.");
  metrics.def(
      "trajectory_rmse",
      [](py::handle gt, py::handle pred) {
        return aligned_trajectory_rmse(tensor_arg(gt, "gt").to(torch::kFloat64),
                                       tensor_arg(pred, "pred").to(torch::kFloat64));
      },
      "gt"_a, "pred"_a, "RMS position error [N,3] after a Sim(3) (Umeyama) alignment.");
  metrics.def(
      "odometry_errors",
      [](py::handle gt, py::handle pred, std::vector<double> lengths, int64_t step, bool align_scale) {
        auto g = tensor_arg(gt, "gt").to(torch::kFloat64), p = tensor_arg(pred, "pred").to(torch::kFloat64);
        OdometryErrors e;
        {
          py::gil_scoped_release release;
          if (align_scale) std::tie(g, p) = align_trajectory_scale(g, p);
          e = kitti_odometry_errors(g, p, lengths, step);
        }
        return py::dict("t_err"_a = e.t_err, "r_err"_a = e.r_err, "segments"_a = e.segments,
                        "t_err_percent"_a = e.t_err * 100, "r_err_deg_per_100m"_a = e.r_err * 180 / M_PI * 100);
      },
      "gt"_a, "pred"_a, "lengths"_a = kKittiSegmentLengths, "step"_a = 10, py::kw_only(), "align_scale"_a = true,
      "KITTI odometry's t_err (m/m) and r_err (rad/m) of camera-to-world poses [N,4,4] over segments of `lengths`\n"
      "metres from every step-th frame (the devkit's; also as % and deg/100 m). align_scale: first express both in\n"
      "their first frame and scale the prediction by least squares (kitti-odom-eval's --align scale).");
}

}  // namespace geo::python
