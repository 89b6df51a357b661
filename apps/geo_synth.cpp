// geo_synth: renders a synthetic driving world with exact ground truth in KITTI's formats.
//   geo_synth --preset tiny --seed 1 --out /tmp/world
// Layout and conventions: src/data/synth/synth_writer.h. The trainer reads <out>/raw, geo_eval reads
// <out>/raw (eigen), <out>/kitti2015 (kitti2015) and <out>/odometry (odometry).
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <chrono>

#include "data/synth/synth_writer.h"
#include "data/video/frame_stream.h"
#include "data/video/video_clips.h"
#include "app_options.h"

namespace {

struct SynthCommand {
  std::string preset = "tiny", out, video;
  uint64_t seed = 1;
  int drives = -1, test_drives = -1, flow_pairs = -1, threads = 0;
  int64_t frames = -1, odometry_frames = -1;
  bool force = false, traffic = false;
  double turns = 1.0;

  geo::SynthOptions options() const {  // the preset with the options given
    auto o = geo::SynthOptions::preset_named(preset);
    o.seed = seed;
    o.threads = threads > 0 ? geo::thread_count(threads, "--threads") : 0;
    o.turns = turns;
    o.traffic = traffic;
    if (drives > 0) o.train_drives = drives;
    if (test_drives > 0) o.test_drives = test_drives;
    if (frames > 0) o.frames_per_drive = frames;
    if (flow_pairs >= 0) o.flow_pairs = flow_pairs;
    if (odometry_frames > 0) o.odometry_frames = odometry_frames;
    return o;
  }
};

void add_options(CLI::App& app, SynthCommand& c) {
  app.add_option("--preset", c.preset, "tiny (64x208, for CI and tests) or kitti (375x1242, KITTI intrinsics)")
      ->check(CLI::IsMember({"tiny", "kitti"}));
  app.add_option("--seed", c.seed, "world seed (0 .. 2^63-1): the same seed writes the same files")
      ->check(CLI::Range(uint64_t{0}, uint64_t{1} << 63));
  app.add_option("--out", c.out, "output root (created); holds raw/, kitti2015/, odometry/")->required();
  app.add_option("--drives", c.drives, "training drives, 1..1000 (default: preset's)")->check(CLI::Range(1, 1000));
  app.add_option("--test-drives", c.test_drives, "held-out test drives, 1..1000 (default: preset's)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--frames", c.frames, "frames per drive (default: preset's)")->check(CLI::Range(3, 100000));
  app.add_option("--flow-pairs", c.flow_pairs, "KITTI-2015-style flow pairs, 0..100000 (default: preset's)")
      ->check(CLI::Range(0, 100000));
  app.add_option("--odometry-frames", c.odometry_frames, "frames of odometry sequence 09 (default: preset's)")
      ->check(CLI::Range(5, 100000));
  app.add_option("--threads", c.threads, "render threads (0 = all cores)")->check(geo::app::non_negative());
  app.add_option("--turns", c.turns,
                 "how winding the road is: 1 gentle (~1 degree of heading per frame), "
                 "2 four times the heading change (a learned camera needs rotation to pin its focal length)")
      ->check(CLI::Range(0.1, 10.0));
  app.add_flag("--traffic", c.traffic,
               "stop-and-go city traffic: the camera stands for stretches of 6-14 frames, a car ahead in its "
               "lane keeps its gap, a truck overtakes on the right while the camera stands, oncoming cars on the "
               "left (obj_map/ marks every moving object)");
  app.add_flag("--force", c.force, "write into a non-empty --out");
  app.add_option("--video", c.video,
                 "also write the first training drive as a Motion-JPEG AVI at 10 fps (train on it with "
                 "data.videos and the camera printed at the end)");
}

int synthesise(const SynthCommand& c) {
  const auto o = c.options();
  const std::string& out = c.out;
  spdlog::info("geo_synth: {} frames, at most {:.2f} GB",
               (o.train_drives + o.test_drives) * o.frames_per_drive + 3 * o.flow_pairs + o.odometry_frames,
               geo::synth_world_bytes(o) / 1e9);
  if (geo::prepare_synth_root(out, o, c.force)) spdlog::info("--force: the earlier world in {} removed", out);
  spdlog::info(
      "geo_synth: preset {} ({}x{}), seed {}, {} training + {} test drives of {} frames, "
      "{} flow pairs, {} odometry frames -> {}",
      c.preset, o.width, o.height, o.seed, o.train_drives, o.test_drives, o.frames_per_drive, o.flow_pairs,
      o.odometry_frames, out);
  const auto t0 = std::chrono::steady_clock::now();
  int last_pct = -1;
  geo::write_synth_world(out, o, [&](int64_t done, int64_t total, const std::string& what) {
    const int pct = static_cast<int>(100 * done / total);
    if (pct / 10 != last_pct / 10 || done == total) {
      spdlog::info("  {:3d}% ({}/{} frames, {})", pct, done, total, what);
      last_pct = pct;
    }
  });
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::info("done in {:.1f} s: {}/raw (train with data.root={}/raw), {}/kitti2015, {}/odometry", s, out, out, out,
               out);
  if (!c.video.empty()) {
    const std::string frames = out + "/raw/" + geo::synth_drive_folder(1) + "/image_02/data";
    geo::write_video_file(geo::frame_files(frames), c.video, 10.0);
    const auto& k = o.intrinsics;
    spdlog::info(
        "video: {} ({} frames of {}, 10 fps): train with --set data.videos=[{}] "
        "--set data.camera.intrinsics=[{},{},{},{}]",
        c.video, o.frames_per_drive, frames, c.video, k.fx, k.fy, k.cx, k.cy);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return geo::app::run_command<SynthCommand>(
      argc, argv,
      "geo_synth: render a procedural driving world (road, facades, poles, boxes, moving cars) "
      "with exact ground truth, written in KITTI's raw, 2015-flow and odometry formats",
      add_options, synthesise);
}
