// geo_synth's world as training data without files (data.format synthetic): the training and
// validation snippets of the drives that geo_synth writes under raw/ (same scenes, same frames, same
// split: synth.h's layout rules), rendered once in memory at the training size and quantised to 8
// bits as a PNG would be. At the preset's own size they equal what the trainer reads from
// geo_synth's files, bit for bit; at another size the camera's intrinsics are scaled to it (as
// when KITTI frames are resized) and the scene is rendered at that size. LibTorch only: this is the
// training data of a build without OpenCV (a GPU image) and of tests that need no files.
#pragma once

#include "data/snippets.h"
#include "data/synth/synth.h"

#include <memory>
#include <vector>

namespace geo {

struct SynthSnippetSets {
  std::shared_ptr<SnippetSource> train, val;
};

// `world`: preset, seed, train_drives and frames_per_drive are used; height/width are the training
// size. seq_length: odd, >= 3. Throws std::invalid_argument on bad options.
SynthSnippetSets render_synth_snippets(const SynthOptions& world, int64_t seq_length);

// The world of a preset at a training size: the preset's intrinsics scaled to height x width.
SynthOptions synth_world_at(const std::string& preset, int64_t height, int64_t width);

}  // namespace geo
