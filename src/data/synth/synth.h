// A procedural driving world with exact ground truth: a road plane, building facades on
// both sides, poles and boxes at 5-80 m, and independently moving cars, seen by a pinhole camera
// that drives forward about 1 m per frame with gentle turns. With `traffic`, stop-and-go city
// traffic instead: the camera stands for stretches and starts again, a car ahead in its lane keeps
// its gap (moving with the camera: the case self-supervised depth learns as infinitely far), a
// truck overtakes on the right while the camera stands, and oncoming cars pass on the left. Rendered by exact ray casting with
// supersampling; every texture is a deterministic function of the surface point (solid noise,
// stripes, windows, lane marks), so images of one point agree across frames.
//
// Conventions: camera x right, y down, z forward; world = camera of frame 0 at the origin before
// the path's lateral offset; pixel centres at integer coordinates (as in src/geometry). Depth is the
// camera z of the point seen through the pixel centre, 0 for sky. Torch is used only for outputs.
#pragma once

#include <torch/torch.h>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace geo {

struct SynthIntrinsics {
  double fx = 120.8, fy = 123.1, cx = 102.1, cy = 29.5;
  torch::Tensor K() const;  // [3,3] float64
};

struct SynthOptions {
  std::string preset = "tiny";
  int64_t height = 64, width = 208;
  SynthIntrinsics intrinsics;
  int supersample = 3;   // rays per pixel = supersample^2 (anti-aliasing)
  int train_drives = 3;  // drives for training/validation
  int test_drives = 1;   // drives held out (listed as test scenes)
  int64_t frames_per_drive = 42;
  int flow_pairs = 20;           // KITTI-2015-style pairs
  int64_t odometry_frames = 60;  // one odometry sequence ("09")
  int lidar_beams = 64;          // Velodyne HDL-64E has 64, from -24.8 to +2 degrees
  double lidar_azimuth_step_deg = 0.2;
  uint64_t seed = 1;
  int threads = 0;       // 0 = all cores
  double turns = 1.0;    // how winding the road is: the sway's frequency x turns (heading
                         // change per frame x turns^2); rotation is what pins a learned focal length
  bool traffic = false;  // stop-and-go traffic (SynthScene): standing stretches, a car ahead
                         // keeping its gap, overtaking trucks, oncoming cars

  // "tiny" (64x208, CI) or "kitti" (375x1242, KITTI's intrinsics). Unknown names throw.
  static SynthOptions preset_named(const std::string& name);
};

struct Vec3 {
  double x = 0, y = 0, z = 0;
};

// Camera-to-world rigid transform: R (row-major 3x3) and centre c.
struct RigidPose {
  std::array<double, 9> R{1, 0, 0, 0, 1, 0, 0, 0, 1};
  Vec3 c;
  torch::Tensor matrix() const;  // [4,4] float64
};

struct SynthBox {
  Vec3 lo, hi;                  // extent at frame 0
  Vec3 velocity;                // metres per frame (0 for static objects)
  bool follows_camera = false;  // moves along z with the camera's travel (a car keeping its gap)
  int material = 0;             // 1 wall, 2 pole, 3 box, 4 car, 5 backdrop (0 = ground plane)
  std::array<float, 3> colour{0.5f, 0.5f, 0.5f};
  double texture_scale = 1.0;
};

// One drive: static layout, movers and the camera path. Deterministic from (seed, length).
// The synthetic camera's height above the road in metres (KITTI's), written into each world.
inline constexpr double kSynthCameraHeight = 1.65;

class SynthScene {
 public:
  // `turns` > 0 scales the sway's frequency (1: gentle turns, up to ~1 degree of heading per frame);
  // `traffic`: stop-and-go traffic (see the top of this file).
  SynthScene(uint64_t seed, int64_t frames, double turns = 1.0, bool traffic = false);

  RigidPose camera(int64_t frame) const;  // camera-to-world at `frame`
  // Metres the camera has driven along the road by `frame` (frame >= 0); the camera stands between
  // two frames of equal travel (only with traffic).
  double travel(int64_t frame) const;
  bool camera_moves(int64_t frame) const { return frame > 0 && travel(frame) != travel(frame - 1); }  // since frame-1
  const std::vector<SynthBox>& boxes() const { return boxes_; }
  // Whether box `id` moves independently of the static world (KITTI 2015's obj_map objects).
  bool is_moving(int id) const;
  // Displacement of box `id` at `frame` from where it stands at frame 0.
  Vec3 offset(int id, int64_t frame) const;

  struct Hit {
    double t = 0;  // ray parameter (camera z for camera rays, metres for unit rays)
    int id = -2;   // box index, -1 ground, -2 nothing (sky)
    Vec3 point;    // world point
    Vec3 normal;
  };
  Hit cast(const Vec3& origin, const Vec3& dir, int64_t frame, double t_max = 1e9) const;
  // Colour of a hit at `frame` (texture in the object's own frame, fixed Lambertian shading).
  std::array<float, 3> shade(const Hit& hit, int64_t frame) const;
  // Where the surface point `p` (on object id, at `frame`) is at frame `frame + df`.
  Vec3 move(const Vec3& p, int id, int64_t frame, int64_t df) const;

 private:
  uint64_t seed_;
  double speed_, sway_amp_, sway_period_, sway_phase_;
  std::vector<double> travel_;  // traffic: metres driven by each frame (empty: speed_ x frame)
  std::vector<SynthBox> boxes_;
  static constexpr double kCameraHeight = kSynthCameraHeight;  // ground plane y (camera y points down)
};

struct SynthFrame {
  torch::Tensor image;   // [3,H,W] float32 in [0,1]
  torch::Tensor depth;   // [1,H,W] float32, camera z in metres, 0 = sky
  torch::Tensor object;  // [H,W] int32, box id, -1 ground, -2 sky
  RigidPose pose;        // camera-to-world
};
SynthFrame render_frame(const SynthScene& scene, int64_t frame, const SynthOptions& options);
// KITTI 2015's obj_map of a frame: 0 = static scene (ground, buildings, poles, boxes, sky),
// k = the k-th moving object of the scene (1-based, in box order) -> [H,W] uint8.
torch::Tensor synth_object_map(const SynthScene& scene, const torch::Tensor& object);
// The object-map values (as in synth_object_map) of the objects that move with the camera, keeping
// their distance (the car ahead in traffic), ascending; empty without traffic. geo_synth writes them
// to raw/<drive>/obj_map/with_camera.txt, one a line, and geo_eval scores their pixels apart.
std::vector<int> synth_with_camera_objects(const SynthScene& scene);

struct SynthFlow {
  torch::Tensor flow;       // [2,H,W] float32 from `frame` to `frame + 1`, pixels
  torch::Tensor valid_occ;  // [1,H,W] in-view at frame+1 (occluded included), KITTI flow_occ
  torch::Tensor valid_noc;  // [1,H,W] in-view and visible at frame+1, KITTI flow_noc
};
SynthFlow render_flow(const SynthScene& scene, int64_t frame, const SynthOptions& options);

// Velodyne-like scan at `frame` in the LiDAR frame (x forward, y left, z up): [N,4] float32
// (x, y, z, reflectance), range <= 120 m. The LiDAR sits at synth_cam_from_velo() from the camera.
torch::Tensor render_lidar(const SynthScene& scene, int64_t frame, const SynthOptions& options);
torch::Tensor synth_cam_from_velo();  // [4,4] float64

// The world's layout, shared by geo_synth's files (synth_writer.h) and the in-memory snippets
// (synth_snippets.h), so that both hold the same drives, frames and split:
// The date folder used for synthetic drives.
inline const char* kSynthDate = "2011_01_01";
// Drive folder name for drive number n, from 1 ("2011_01_01/2011_01_01_drive_0001_sync").
std::string synth_drive_folder(int drive);
// The scene seed of drive `index` of a kind (0 raw drives, 1 KITTI 2015 pairs, 2 odometry).
uint64_t synth_drive_seed(uint64_t seed, int kind, int64_t index);
// Targets of the training drives go to validation when frame % 10 == 5, else to training.
inline bool synth_is_validation_frame(int64_t frame) { return frame % 10 == 5; }
// A split-list line / snippet id of drive index d (from 0), frame f: "<folder> <f> l".
std::string synth_snippet_id(int drive_index, int64_t frame);

}  // namespace geo
