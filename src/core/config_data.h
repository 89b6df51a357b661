// The data: section of a config (what is trained on: KITTI raw, packed caches, the synthetic world,
// videos; sizes, augmentation).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

enum class DataFormat { kAuto, kKittiRaw, kPacked, kSynthetic, kVideo };
enum class BadSample { kStop, kSkip };
const std::vector<EnumName<DataFormat>>& enum_names(DataFormat);
const std::vector<EnumName<BadSample>>& enum_names(BadSample);

struct AugmentConfig {
  bool enabled = true;                                // GeoNet augmentation (data_loader.py)
  double scale_max = 1.15;                            // scale x,y by U[1, scale_max] then random-crop back (GeoNet)
  double photometric_prob = 0.5;                      // probability of photometric jitter per batch (GeoNet)
  double gamma_min = 0.8, gamma_max = 1.2;            // gamma U[0.8,1.2] (GeoNet)
  double brightness_min = 0.5, brightness_max = 2.0;  // brightness U[0.5,2] (GeoNet)
  double color_min = 0.8, color_max = 1.2;            // per-channel colour U[0.8,1.2] (GeoNet)

  template <class V>
  void fields(V& v) {
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
  std::string preset = "tiny";    // tiny | kitti: the camera (intrinsics scaled to the training size)
  int64_t seed = 1;               // the world (as geo_synth --seed)
  int drives = 3;                 // training drives (geo_synth's train_drives)
  int64_t frames_per_drive = 42;  // frames per drive (geo_synth's)

  template <class V>
  void fields(V& v) {
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
  std::vector<double> intrinsics;  // [fx, fy, cx, cy] in pixels of the original frames
  std::string calib_file;          // KITTI raw calib_cam_to_cam.txt (P_rect_02) or odometry calib.txt (P2)
  double fov_deg = 0;              // horizontal field of view in degrees (fx = fy, principal point centred)

  template <class V>
  void fields(V& v) {
    v("intrinsics", intrinsics);
    v("calib_file", calib_file);
    v("fov_deg", fov_deg);
  }
  bool given() const { return !intrinsics.empty() || !calib_file.empty() || fov_deg != 0; }
  void validate(Checker& c) const;
};

// How frames of data.videos become training snippets (data/video/frame_selection.h).
struct VideoDataConfig {
  double fps = 10;        // target frame rate (KITTI's 10 fps); 0 = every frame
  double source_fps = 0;  // frame folders: their frame rate (0 = unknown: no rate subsampling)
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
  double val_fraction = 0.1;  // frames held out for validation, as whole time blocks (GeoNet: 10%)
  int val_block = 100;        // frames per validation block (10 s at 10 fps)
  bool crop = true;           // crop to the training aspect ratio before resizing (else stretch)
  double crop_y = 0.5;        // vertical position of the crop: 0 top, 0.5 centre, 1 bottom

  template <class V>
  void fields(V& v) {
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
  std::string root;                       // dataset root (KITTI raw, packed cache or a geo_synth world)
  DataFormat format = DataFormat::kAuto;  // auto | kitti_raw | packed | synthetic (no files; data.synthetic)
  // Training data of a task: eigen_zhou (depth; the paper's Eigen split), kitti_raw_stereo (flow,
  // GeoNet's: every raw drive on disk but the KITTI 2015 scenes, cameras 02 and 03),
  // raw_minus_kitti2015 (the eigen_zhou lists without the KITTI 2015 scenes), odometry (pose, GeoNet:
  // KITTI odometry `sequences`), or any split folder under configs/splits or <root>/splits.
  std::string split = "eigen_zhou";
  std::vector<std::string> sequences = {"00", "01", "02", "03", "04",
                                        "05", "06", "07", "08"};  // odometry split (GeoNet)
  std::string train_list;  // explicit training list; empty = <split>/train_files.txt
  std::string val_list;    // explicit validation list; empty = <split>/val_files.txt
  // Validation of KITTI raw splits: list (the split's validation list, e.g. eigen_zhou's
  // val_files.txt) or geonet (GeoNet's prepare_train_data: 10% of the training snippets, chosen by
  // a fixed hash, held out of training; neighbours of training frames, so an optimistic score).
  std::string val_split = "list";
  int height = 128;     // training height (paper Sec. 4.2)
  int width = 416;      // training width (paper Sec. 4.2)
  int seq_length = 3;   // target in the middle + 2 sources (paper); 5 for odometry
  int num_workers = 2;  // loader threads prefetching batches
  // KITTI raw: leave out the frames of configs/splits/static_frames.txt (SfMLearner's, GeoNet's
  // remove_static). kitti_raw_stereo removes them from the frame list before snippets are formed
  // (a neighbour is the next frame that moves, as GeoNet); list splits drop static targets.
  bool remove_static = true;
  BadSample on_bad_sample = BadSample::kStop;  // stop | skip
  AugmentConfig augment;
  SynthDataConfig synthetic;  // data.format synthetic only
  // data.format video (or auto with videos given): video files (anything OpenCV's VideoCapture
  // reads) and folders of frames (any names, natural sort), one clip each.
  std::vector<std::string> videos;
  CameraConfig camera;    // the clips' camera (data.videos)
  VideoDataConfig video;  // frame rate, static frames, validation blocks (data.videos)

  template <class V>
  void fields(V& v) {
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

}  // namespace geo
