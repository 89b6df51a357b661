// The data: section's names and checks.
#include "core/config_data.h"

#include <cmath>

#include "core/camera_rule.h"

#include "core/config_check.h"

namespace geo {

const std::vector<EnumName<DataFormat>>& enum_names(DataFormat) {
  static const std::vector<EnumName<DataFormat>> n{{DataFormat::kAuto, "auto"},
                                                   {DataFormat::kKittiRaw, "kitti_raw"},
                                                   {DataFormat::kPacked, "packed"},
                                                   {DataFormat::kSynthetic, "synthetic"},
                                                   {DataFormat::kVideo, "video"}};
  return n;
}

const std::vector<EnumName<BadSample>>& enum_names(BadSample) {
  static const std::vector<EnumName<BadSample>> n{{BadSample::kStop, "stop"}, {BadSample::kSkip, "skip"}};
  return n;
}

void DataConfig::validate(Checker& c) const {
  // Bounded where it is read: a network input of 4096x4096 already needs tens of GB to train.
  c.require(height >= 16 && height <= 4096 && height % 8 == 0, "height", height,
            "must be a multiple of 8 (4 pyramid scales) in 16..4096");
  c.require(width >= 16 && width <= 4096 && width % 8 == 0, "width", width,
            "must be a multiple of 8 (4 pyramid scales) in 16..4096");
  c.require(seq_length >= 3 && seq_length % 2 == 1, "seq_length", seq_length,
            "must be odd and >= 3 (target in the middle)");
  c.require(num_workers >= 0 && num_workers <= 64, "num_workers", num_workers, "must be in 0..64");
  c.require(one_of(val_split, {"list", "geonet"}), "val_split", val_split, "must be list or geonet");
  c.require(split != "odometry" || !sequences.empty(), "sequences", sequences,
            "must name at least one KITTI odometry sequence when data.split is odometry");
  c.require(!split.empty(), "split", split,
            "must not be empty (eigen_zhou, kitti_raw_stereo, raw_minus_kitti2015, odometry, ...)");
  c.section("augment", augment);
  c.section("synthetic", synthetic);
  c.require(format != DataFormat::kVideo || !videos.empty(), "videos", videos,
            "must name at least one video file or frame folder when data.format is video");
  // The clips' settings apply to data.videos only: given to other data they would go unused.
  const bool clips = uses_videos();
  c.require(clips || videos.empty(), "videos", videos,
            "data.format is " + to_text(format) + ", which trains on data.root, not on clips: set data.format=video " +
                "(or auto) to train on them, or leave data.videos empty");
  const std::string unused = "applies to data.videos only (data.format " + to_text(format) +
                             (format == DataFormat::kAuto ? " without clips" : "") + " reads " +
                             (format == DataFormat::kSynthetic ? "the in-memory world" : "data.root") +
                             ", whose camera comes with the data): remove it or train on clips";
  {
    Checker::Scope s(c, "camera");
    camera.validate(c);
    if (!clips)
      for (const auto& [key, value] : non_defaults(camera)) c.require(false, key.c_str(), Shown{value}, unused);
  }
  Checker::Scope s(c, "video");
  video.validate(c);
  if (!clips)
    for (const auto& [key, value] : non_defaults(video)) c.require(false, key.c_str(), Shown{value}, unused);
}

void CameraConfig::validate(Checker& c) const {
  const int given = !intrinsics.empty() + !calib_file.empty() + (fov_deg != 0);
  c.require(given <= 1, "intrinsics", intrinsics,
            "give one of camera.intrinsics, camera.calib_file or camera.fov_deg, not several");
  if (!intrinsics.empty()) {
    c.require(intrinsics.size() == 4, "intrinsics", intrinsics,
              "must be [fx, fy, cx, cy] in pixels of the original frames");
    if (intrinsics.size() == 4) {
      // The frames' size is known once a clip is opened (data/video/clip_camera.cpp checks again).
      const auto problem = camera_problem(intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]);
      c.require(problem.empty(), "intrinsics", intrinsics, problem);
    }
  }
  c.require(std::isfinite(fov_deg) && fov_deg >= 0 && fov_deg < 180, "fov_deg", fov_deg,
            "must be a horizontal field of view in (0, 180) degrees (0 = not given)");
}

void VideoDataConfig::validate(Checker& c) const {
  c.require(std::isfinite(fps) && fps >= 0 && fps <= 1000, "fps", fps, "must be in [0, 1000] (0 = every frame)");
  c.require(std::isfinite(source_fps) && source_fps >= 0 && source_fps <= 1000, "source_fps", source_fps,
            "must be in [0, 1000] (0 = unknown)");
  c.require(std::isfinite(static_threshold) && static_threshold >= 0 && static_threshold < 1, "static_threshold",
            static_threshold, "must be in [0, 1) (a fraction of changed pixels; 0 keeps every frame)");
  c.require(std::isfinite(standing_parallax) && standing_parallax >= 0 && standing_parallax <= 10, "standing_parallax",
            standing_parallax, "must be in [0, 10] pixels at a width of 416 (0 turns the standing-camera test off)");
  c.require(std::isfinite(standing_share) && standing_share > 0 && standing_share <= 1, "standing_share",
            standing_share,
            "must be in (0, 1] (the share of tracked features a rotation alone explains when the camera stands)");
  c.require(std::isfinite(val_fraction) && val_fraction >= 0 && val_fraction <= 0.5, "val_fraction", val_fraction,
            "must be in [0, 0.5]");
  c.require(val_block >= 3 && val_block <= 1000000, "val_block", val_block, "must be in 3..1000000 frames");
  c.require(std::isfinite(crop_y) && crop_y >= 0 && crop_y <= 1, "crop_y", crop_y, "must be in [0, 1]");
}

void SynthDataConfig::validate(Checker& c) const {
  c.require(one_of(preset, {"tiny", "kitti"}), "preset", preset, "must be tiny or kitti");
  c.require(seed >= 0, "seed", seed, "must be >= 0");
  c.require(drives >= 1 && drives <= 1000, "drives", drives, "must be in 1..1000");
  c.require(frames_per_drive >= 3 && frames_per_drive <= 100000, "frames_per_drive", frames_per_drive,
            "must be in 3..100000");
}

void AugmentConfig::validate(Checker& c) const {
  c.require(scale_max >= 1.0 && scale_max <= 2.0, "scale_max", scale_max, "must be in [1, 2] (GeoNet: 1.15)");
  c.require(photometric_prob >= 0 && photometric_prob <= 1, "photometric_prob", photometric_prob, "must be in [0, 1]");
  c.require(gamma_min > 0 && gamma_min <= gamma_max, "gamma_min", gamma_min, "must be > 0 and <= gamma_max");
  c.require(brightness_min > 0 && brightness_min <= brightness_max, "brightness_min", brightness_min,
            "must be > 0 and <= brightness_max");
  c.require(color_min > 0 && color_min <= color_max, "color_min", color_min, "must be > 0 and <= color_max");
}

}  // namespace geo
