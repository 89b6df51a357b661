// Writes a synthetic world (data/synth/synth.h) in KITTI's on-disk formats (KITTI devkit formats) under
// one root, so every reader, the trainer and the evaluator run on it unchanged:
//   raw/<date>/calib_cam_to_cam.txt, calib_velo_to_cam.txt
//   raw/<date>/<date>_drive_NNNN_sync/image_02/data/%010d.png, velodyne_points/data/%010d.bin,
//       proj_depth/groundtruth/image_02/%010d.png (dense depth x 256), obj_map/image_02/%010d.png
//       (independently moving objects, as KITTI 2015's obj_map), poses.txt (camera 02 to world,
//       KITTI pose format, frame 0 = identity)
//   raw/splits/eigen_zhou/{train,val}_files.txt ("folder frame l"), raw/splits/eigen/test_files.txt
//       (image paths), raw/splits/eigen/test_scenes.txt
//   kitti2015/training/image_2/%06d_10.png, %06d_11.png, flow_occ/, flow_noc/ (16-bit flow PNG),
//       calib_cam_to_cam/%06d.txt, depth/%06d_10.png (dense depth x 256)
//   odometry/sequences/09/image_2/%06d.png, calib.txt, times.txt; odometry/poses/09.txt
#pragma once

#include "data/synth/synth.h"

#include <functional>
#include <string>

namespace geo {

// Writes everything; `progress(done, total, what)` is called after each rendered frame.
void write_synth_world(const std::string& root, const SynthOptions& options,
                       const std::function<void(int64_t, int64_t, const std::string&)>& progress = {});

// An upper bound of the bytes the world takes on disk (PNG compresses: about half of it in
// practice): every raw frame as an RGB image, a depth map and a Velodyne scan, flow pairs as three
// images and four ground-truth maps, the odometry frames as images.
double synth_world_bytes(const SynthOptions& options);

// Readies `root` for a new world before any rendering: refuses when the disk where it goes has less
// than half of synth_world_bytes free; a non-empty root needs `force`, and then only a world
// geo_synth wrote (its README.txt) is removed, whole, so that files a smaller world does not write
// are not scored with it. Returns whether an earlier world was removed.
bool prepare_synth_root(const std::string& root, const SynthOptions& options, bool force);

}  // namespace geo
