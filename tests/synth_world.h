// A small geo_synth world for tests: one training and one test drive of `frames` frames, a few
// flow pairs and a short odometry sequence, at the tiny preset's 64x208.
#pragma once

#include "data/synth/synth_writer.h"
#include "test_util.h"

namespace geo::test {

// The tiny preset (64x208) rendered on 2 threads.
inline SynthOptions tiny_options() {
  auto o = SynthOptions::preset_named("tiny");
  o.threads = 2;
  return o;
}

// `traffic`: stop-and-go traffic (SynthOptions::traffic).
inline std::string write_small_world(const std::string& name, int64_t frames, int flow_pairs, int64_t odometry_frames,
                                     bool traffic = false) {
  auto o = SynthOptions::preset_named("tiny");
  o.traffic = traffic;
  o.train_drives = 1;
  o.test_drives = 1;
  o.frames_per_drive = frames;
  o.flow_pairs = flow_pairs;
  o.odometry_frames = odometry_frames;
  const auto dir = fresh_dir(name);
  write_synth_world(dir, o);
  return dir;
}

}  // namespace geo::test
