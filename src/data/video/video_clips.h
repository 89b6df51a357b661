// Training snippets from the user's own footage (data.videos): video files (anything OpenCV's
// VideoCapture reads) and folders of frames (any names, natural sort). Each clip is decoded once, in
// a stream: frame-rate subsampling, static frames and validation blocks as frame_selection.h; every
// frame cropped to the training aspect ratio (data.video.crop) and resized, the camera's K following
// both. Videos keep only their chosen frames, at the training size, as JPEG (quality 95) in memory
// (~25 KB a frame at 128x416: a 20-minute clip at 10 fps ~300 MB); frame folders are read from disk
// when a snippet is asked for. geo_prepare packs either into a cache. Needs OpenCV.
#pragma once

#include "core/config.h"
#include "data/snippets.h"

#include <memory>
#include <string>
#include <vector>

namespace geo {

struct VideoData {
  std::shared_ptr<SnippetSource> train, val;  // val null when no clip holds a validation block
  std::vector<std::string> report;            // a line per clip: what was kept and why
  std::vector<std::string> warnings;          // clips unlikely to teach depth, with what helps
  // A line per clip saying which frames it gave: its path, frames decoded and kept, and a digest of
  // the clip (a video's: its file's bytes; a folder's: its kept files' names and sizes).
  // geo_train records them with a run and refuses to resume on a clip that changed.
  std::vector<std::string> records;
};

// Opens data.videos with data.camera and data.video. Throws (ConfigError or std::runtime_error)
// naming the clip and the value: an unreadable or empty video, a folder without images, frames of
// changing size, fewer moving frames than one snippet, a camera that cannot be right. Without
// data.camera the snippets carry a nominal 90-degree camera, for networks that learn theirs.
VideoData open_video_clips(const DataConfig& data);

// Encodes image files (all one size) as a Motion-JPEG AVI at `fps` (OpenCV's own encoder, present in
// every OpenCV build): geo_synth --video, and clips for tests. Throws naming the file.
void write_video_file(const std::vector<std::string>& frames, const std::string& path, double fps);

}  // namespace geo
