#include "data/synth/synth_writer.h"

#include "core/files.h"
#include "data/kitti/calib.h"
#include "data/image_io.h"
#include "data/text_io.h"
#include "geometry/pose.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;

namespace geo {
namespace {

// The first words of the README.txt every world starts with: how prepare_synth_root knows one.
const std::string kReadmeStart = "Synthetic KITTI-format world written by geo_synth";

// P = K [I | 0] for a rectified camera at the reference camera's centre.
torch::Tensor projection(const SynthOptions& o) {
  auto P = torch::zeros({3, 4}, torch::kFloat64);
  P.index_put_({torch::indexing::Slice(), torch::indexing::Slice(0, 3)}, o.intrinsics.K());
  return P;
}

std::string cam_to_cam_text(const SynthOptions& o) {
  std::ostringstream s;
  const std::string size = std::to_string(o.width) + " " + std::to_string(o.height);
  const std::string P = format_numbers(projection(o)), I = "1 0 0 0 1 0 0 0 1";
  s << "calib_time: 01-Jan-2011 00:00:00 (geo_synth)\ncorner_dist: 0\n";
  for (int c = 0; c < 4; ++c) {
    const std::string n = "0" + std::to_string(c);
    s << "S_" << n << ": " << size << "\nK_" << n << ": " << format_numbers(o.intrinsics.K()) << "\nD_" << n
      << ": 0 0 0 0 0\nR_" << n << ": " << I << "\nT_" << n << ": 0 0 0\nS_rect_" << n << ": " << size << "\nR_rect_"
      << n << ": " << I << "\nP_rect_" << n << ": " << P << "\n";
  }
  return s.str();
}

std::string velo_to_cam_text() {
  auto T = synth_cam_from_velo();
  using torch::indexing::Slice;
  return "calib_time: 01-Jan-2011 00:00:00 (geo_synth)\nR: " + format_numbers(T.index({Slice(0, 3), Slice(0, 3)})) +
         "\nT: " + format_numbers(T.index({Slice(0, 3), 3})) + "\ndelta_f: 0 0\ndelta_c: 0 0\n";
}

// Poses relative to the first frame: T_0^-1 T_i (KITTI odometry convention).
torch::Tensor relative_poses(const SynthScene& scene, int64_t first, int64_t count) {
  auto base = inverse_transform(scene.camera(first).matrix().unsqueeze(0));
  std::vector<torch::Tensor> out;
  for (int64_t i = 0; i < count; ++i) out.push_back(base.matmul(scene.camera(first + i).matrix().unsqueeze(0)));
  return torch::cat(out);
}

std::string join_lines(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

}  // namespace

void write_synth_world(const std::string& root, const SynthOptions& o,
                       const std::function<void(int64_t, int64_t, const std::string&)>& progress) {
  const int drives = o.train_drives + o.test_drives;
  const int64_t total = drives * o.frames_per_drive + 3 * o.flow_pairs + o.odometry_frames;
  int64_t done = 0;
  auto tick = [&](const std::string& what) {
    ++done;
    if (progress) progress(done, total, what);
  };
  const std::string raw = root + "/raw", date_dir = raw + "/" + kSynthDate;
  fs::create_directories(date_dir);
  write_file_atomic(date_dir + "/calib_cam_to_cam.txt", cam_to_cam_text(o));
  write_file_atomic(date_dir + "/calib_velo_to_cam.txt", velo_to_cam_text());

  std::vector<std::string> train, val, test, test_scenes;
  for (int d = 0; d < drives; ++d) {
    const bool is_test = d >= o.train_drives;
    const SynthScene scene(synth_drive_seed(o.seed, 0, d), o.frames_per_drive, o.turns, o.traffic);
    const std::string folder = synth_drive_folder(d + 1), dir = raw + "/" + folder;
    for (const char* sub :
         {"/image_02/data", "/velodyne_points/data", "/proj_depth/groundtruth/image_02", "/obj_map/image_02"})
      fs::create_directories(dir + sub);
    for (int64_t f = 0; f < o.frames_per_drive; ++f) {
      const auto frame = render_frame(scene, f, o);
      const std::string name = zero_padded(f, 10);
      write_image(dir + "/image_02/data/" + name + ".png", frame.image);
      write_depth_png(dir + "/proj_depth/groundtruth/image_02/" + name + ".png", frame.depth);
      write_object_map(dir + "/obj_map/image_02/" + name + ".png", synth_object_map(scene, frame.object));
      write_velodyne(dir + "/velodyne_points/data/" + name + ".bin", render_lidar(scene, f, o));
      if (f > 0 && f + 1 < o.frames_per_drive) {  // targets need both neighbours
        if (is_test) test.push_back(folder + "/image_02/data/" + name + ".png");
        else (synth_is_validation_frame(f) ? val : train).push_back(synth_snippet_id(d, f));
      }
      tick("drive " + std::to_string(d + 1));
    }
    write_poses(dir + "/poses.txt", relative_poses(scene, 0, o.frames_per_drive));
    std::string with_camera;
    for (const int v : synth_with_camera_objects(scene)) with_camera += std::to_string(v) + "\n";
    write_file_atomic(dir + "/obj_map/with_camera.txt", with_camera);
    if (is_test) test_scenes.push_back(folder.substr(folder.find('/') + 1, folder.size() - folder.find('/') - 6));
  }
  fs::create_directories(raw + "/splits/eigen_zhou");
  fs::create_directories(raw + "/splits/eigen");
  write_file_atomic(raw + "/splits/eigen_zhou/train_files.txt", join_lines(train));
  write_file_atomic(raw + "/splits/eigen_zhou/val_files.txt", join_lines(val));
  write_file_atomic(raw + "/splits/eigen/test_files.txt", join_lines(test));
  write_file_atomic(raw + "/splits/eigen/test_scenes.txt", join_lines(test_scenes));

  const std::string flow = root + "/kitti2015/training";
  for (const char* sub : {"/image_2", "/flow_occ", "/flow_noc", "/obj_map", "/calib_cam_to_cam", "/depth"})
    fs::create_directories(flow + sub);
  for (int i = 0; i < o.flow_pairs; ++i) {
    const SynthScene scene(synth_drive_seed(o.seed, 1, i), 40, o.turns, o.traffic);
    const int64_t f = 5 + (i * 7) % 30;
    const std::string name = zero_padded(i, 6);
    const auto before = render_frame(scene, f - 1, o);  // KITTI 2015's multi-view frame 09
    tick("flow pair");
    const auto a = render_frame(scene, f, o);
    tick("flow pair");
    const auto b = render_frame(scene, f + 1, o);
    tick("flow pair");
    const auto gt = render_flow(scene, f, o);
    write_image(flow + "/image_2/" + name + "_09.png", before.image);
    write_image(flow + "/image_2/" + name + "_10.png", a.image);
    write_image(flow + "/image_2/" + name + "_11.png", b.image);
    write_flow_png(flow + "/flow_occ/" + name + "_10.png", gt.flow, gt.valid_occ);
    write_flow_png(flow + "/flow_noc/" + name + "_10.png", gt.flow, gt.valid_noc);
    write_object_map(flow + "/obj_map/" + name + "_10.png", synth_object_map(scene, a.object));
    write_depth_png(flow + "/depth/" + name + "_10.png", a.depth);
    write_file_atomic(flow + "/calib_cam_to_cam/" + name + ".txt", cam_to_cam_text(o));
  }

  const std::string seq = root + "/odometry/sequences/09";
  fs::create_directories(seq + "/image_2");
  fs::create_directories(root + "/odometry/poses");
  const SynthScene odo(synth_drive_seed(o.seed, 2, 9), o.odometry_frames, o.turns, o.traffic);
  std::ostringstream times;
  for (int64_t f = 0; f < o.odometry_frames; ++f) {
    write_image(seq + "/image_2/" + zero_padded(f, 6) + ".png", render_frame(odo, f, o).image);
    char stamp[32];
    std::snprintf(stamp, sizeof stamp, "%e\n", 0.1 * static_cast<double>(f));  // 10 Hz
    times << stamp;
    tick("odometry");
  }
  const std::string P = format_numbers(projection(o));
  using torch::indexing::Slice;
  write_file_atomic(seq + "/calib.txt", "P0: " + P + "\nP1: " + P + "\nP2: " + P + "\nP3: " + P + "\nTr: " +
                                            format_numbers(synth_cam_from_velo().index({Slice(0, 3)})) + "\n");
  write_file_atomic(seq + "/times.txt", times.str());
  write_poses(root + "/odometry/poses/09.txt", relative_poses(odo, 0, o.odometry_frames));
  write_file_atomic(
      root + "/README.txt",
      kReadmeStart + " (preset " + o.preset + ", seed " + std::to_string(o.seed) + ", " + std::to_string(o.width) +
          "x" + std::to_string(o.height) + (o.traffic ? ", stop-and-go traffic" : "") +
          ").\nraw/ = KITTI raw layout with Eigen-style "
          "splits in raw/splits; kitti2015/ = KITTI 2015 flow layout (obj_map: the moving objects); odometry/ = "
          "KITTI odometry layout.\nMoving objects per raw frame: raw/<drive>/obj_map/image_02 (uint8, 0 "
          "static); raw/<drive>/obj_map/with_camera.txt: the values of those that keep their distance to the "
          "camera, one a line.\nDense ground-truth depth: raw/<drive>/proj_depth/"
          "groundtruth/image_02 and kitti2015/training/depth (uint16, depth x 256).\ncamera_height.txt = "
          "the camera's height above the road in metres (geo_eval --scaling camera-height).\n");
  std::ostringstream height;
  height << kSynthCameraHeight << "\n";
  write_file_atomic(root + "/camera_height.txt", height.str());
}

double synth_world_bytes(const SynthOptions& o) {
  const double image = 3.0 * o.height * o.width, scan = 16.0 * o.lidar_beams * (360.0 / o.lidar_azimuth_step_deg);
  const double frames = static_cast<double>(o.train_drives + o.test_drives) * static_cast<double>(o.frames_per_drive);
  return frames * (image + 3.0 * o.height * o.width + scan) +
         o.flow_pairs * (3 * image + 4 * 6.0 * o.height * o.width) + static_cast<double>(o.odometry_frames) * image;
}

bool prepare_synth_root(const std::string& root, const SynthOptions& options, bool force) {
  const double bytes = synth_world_bytes(options);
  fs::path probe = fs::absolute(root);
  while (!probe.empty() && !fs::exists(probe)) probe = probe.parent_path();
  std::error_code ec;
  const auto space = fs::space(probe, ec);
  if (!ec && bytes / 2 > static_cast<double>(space.available))
    throw std::runtime_error("this world needs about " + std::to_string(static_cast<int64_t>(bytes / 2e9)) + "-" +
                             std::to_string(static_cast<int64_t>(bytes / 1e9)) + " GB and " + probe.string() + " has " +
                             std::to_string(static_cast<int64_t>(space.available / 1000000000)) +
                             " GB free: fewer --drives, --frames, --flow-pairs or --odometry-frames");
  if (!fs::exists(root) || fs::is_empty(root)) return false;
  if (!force)
    throw std::runtime_error("--out '" + root + "' exists and is not empty (use --force to replace the world there)");
  std::ifstream readme(root + "/README.txt");
  std::string first;
  std::getline(readme, first);
  if (first.rfind(kReadmeStart, 0) != 0)
    throw std::runtime_error("--out '" + root +
                             "' is not empty and holds no world written by geo_synth (no README.txt "
                             "of one): --force replaces only such a world; choose another --out");
  for (const char* part : {"raw", "kitti2015", "odometry", "README.txt", "camera_height.txt"}) {
    std::string error;
    if (!remove_tree(root + "/" + part, &error))
      throw std::runtime_error("--force: could not remove the earlier world: " + error);
  }
  return true;
}

}  // namespace geo
