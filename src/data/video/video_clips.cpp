#include "data/video/video_clips.h"
#include "core/zip_check.h"
#include "data/cv_tensor.h"
#include "data/image_io.h"
#include "data/visual_outputs.h"

#include "data/video/camera_motion.h"
#include "data/video/clip_camera.h"
#include "data/video/frame_selection.h"
#include "data/video/frame_stream.h"
#include "geometry/camera.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <stdexcept>

namespace fs = std::filesystem;

namespace geo {

namespace {

constexpr int kJpegQuality = 95;  // frames of videos kept in memory: visually lossless, ~25 KB at 128x416

// One clip's chosen frames at the training size.
struct Clip {
  std::string path;
  std::vector<std::string> files;        // frame folder: the chosen frames' files
  std::vector<std::vector<uchar>> jpeg;  // video: the chosen frames, cropped and resized, as JPEG
  std::vector<int64_t> index;            // decoding-order number of each chosen frame
  CropWindow window;
  int64_t height = 0, width = 0;  // training size
  torch::Tensor K;                // [3,3] float32 at the training size
  int64_t total = 0;              // frames decoded
};

// BGR frame -> the training frame [3,H,W] float32 in [0,1]: crop to `window`, resize to H x W.
cv::Mat crop_resize(const cv::Mat& bgr, const CropWindow& w, int64_t height, int64_t width) {
  cv::Mat roi = bgr(
      cv::Rect(static_cast<int>(w.x0), static_cast<int>(w.y0), static_cast<int>(w.width), static_cast<int>(w.height)));
  cv::Mat out;
  const bool shrink = w.width > width || w.height > height;
  cv::resize(roi, out, cv::Size(static_cast<int>(width), static_cast<int>(height)), 0, 0,
             shrink ? cv::INTER_AREA : cv::INTER_LINEAR);
  return out;
}

cv::Mat read_colour(const std::string& path) {
  cv::Mat m = cv::imread(path, cv::IMREAD_COLOR);
  if (m.empty()) throw std::runtime_error("cannot read image '" + path + "' (missing, empty or not an image)");
  return m;
}

torch::Tensor clip_frame(const Clip& c, size_t i) {
  if (!c.jpeg.empty()) {
    cv::Mat m = cv::imdecode(c.jpeg.at(i), cv::IMREAD_COLOR);
    if (m.empty())
      throw std::runtime_error("clip '" + c.path + "': frame " + std::to_string(c.index.at(i)) + " cannot be decoded");
    return mat_to_tensor(m, c.path);
  }
  return mat_to_tensor(crop_resize(read_colour(c.files.at(i)), c.window, c.height, c.width), c.files.at(i));
}

class ClipSnippets : public SnippetSource {
 public:
  struct Item {
    size_t clip;
    std::vector<int64_t> positions;  // chosen-frame positions in the clip, target in the middle
  };
  ClipSnippets(std::shared_ptr<const std::vector<Clip>> clips, std::vector<Item> items, int64_t seq_length)
      : clips_(std::move(clips)), items_(std::move(items)), seq_length_(seq_length) {}
  size_t size() const override { return items_.size(); }
  int64_t seq_length() const override { return seq_length_; }
  std::string id(size_t index) const override {
    const auto& it = items_.at(index);
    const Clip& c = clips_->at(it.clip);
    const auto target = static_cast<size_t>(it.positions[it.positions.size() / 2]);
    // A folder's frame by its file, a video's by its number in decoding order (from 0).
    return c.files.empty() ? c.path + " frame " + std::to_string(c.index.at(target)) : c.files.at(target);
  }
  Snippet get(size_t index) const override {
    const auto& it = items_.at(index);
    const Clip& c = clips_->at(it.clip);
    std::vector<torch::Tensor> frames;
    for (int64_t p : it.positions) frames.push_back(clip_frame(c, static_cast<size_t>(p)));
    return {torch::stack(frames), c.K, id(index)};
  }

 private:
  std::shared_ptr<const std::vector<Clip>> clips_;
  std::vector<Item> items_;
  int64_t seq_length_;
};

std::string ordinal(int64_t n) {
  if (n == 1) return "every frame";
  const int64_t m100 = n % 100, m10 = n % 10;
  const char* suffix = (m100 >= 11 && m100 <= 13) ? "th" : m10 == 1 ? "st" : m10 == 2 ? "nd" : m10 == 3 ? "rd" : "th";
  return "every " + std::to_string(n) + suffix + " frame";
}

std::string fixed(double v, int digits) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

// Decodes one clip in a stream and chooses its frames.
Clip read_clip(const std::string& path, const DataConfig& d, std::string* report, std::string* warning) {
  Clip c;
  c.path = path;
  c.height = d.height;
  c.width = d.width;
  const auto& v = d.video;
  FrameStream stream(path, "clip");
  const double source_fps = stream.is_video() && v.source_fps == 0 ? stream.fps() : v.source_fps;
  FrameSelector selector(frame_rate_stride(source_fps, v.fps), v.static_threshold);
  const CameraMotionOptions standing{v.standing_parallax, v.standing_share};
  // The standing-camera test sees the crop window at up to kMotionWidth columns: at least the
  // training size's detail, and the same test whatever size the networks train at.
  int64_t motion_h = 0, motion_w = 0;
  std::optional<StandingCameraTest> standing_test;
  std::string name;
  cv::Mat m;
  while (true) {
    const int64_t idx = stream.index() + 1;
    const bool wanted = selector.wants(idx);
    if (!stream.next(name, wanted ? &m : nullptr)) break;  // a folder's unwanted files stay unread
    if (!wanted) {
      selector.offer(idx, {});
      continue;
    }
    if (!c.K.defined()) {
      // The crop window and the camera from the first frame's size, before the clip is decoded
      // further. No camera given: the networks learn it (model.learn_intrinsics, set by the config
      // for such data); the snippets carry a nominal one.
      const int64_t W0 = stream.width(), H0 = stream.height();
      c.window = v.crop ? crop_to_aspect(W0, H0, d.width, d.height, v.crop_y) : CropWindow{0, 0, W0, H0};
      const auto camera = clip_camera(d.camera, W0, H0, path, !d.camera.given());
      c.K = cropped_resized_intrinsics(camera, c.window, d.height, d.width).to(torch::kFloat32);
      motion_w = std::min<int64_t>(c.window.width, kMotionWidth);
      motion_h = std::max<int64_t>(8, (c.window.height * motion_w + c.window.width / 2) / c.window.width);
      if (v.standing_parallax > 0)
        standing_test.emplace(cropped_resized_intrinsics(camera, c.window, motion_h, motion_w), standing);
    }
    const cv::Mat small = crop_resize(m, c.window, d.height, d.width);
    cv::Mat grey;
    std::function<bool()> camera_moved;
    if (standing_test) {
      grey = motion_grey(crop_resize(m, c.window, motion_h, motion_w));
      camera_moved = [&] { return standing_test->moved(grey); };
    }
    const bool kept = selector.offer(idx, motion_thumbnail(mat_to_tensor(small, path)), camera_moved);
    if (standing_test) standing_test->looked_at(grey, kept);
    if (!kept) continue;
    c.index.push_back(idx);
    if (stream.is_video()) {  // kept in memory as JPEG; a folder's frames are read again from disk
      c.jpeg.emplace_back();
      cv::imencode(".jpg", small, c.jpeg.back(), {cv::IMWRITE_JPEG_QUALITY, kJpegQuality});
    } else {
      c.files.push_back(stream.files()[static_cast<size_t>(idx)]);
    }
  }
  const int64_t total = stream.index() + 1, W0 = stream.width(), H0 = stream.height();
  if (total == 0)
    throw std::runtime_error("clip '" + path + "': no frame could be decoded (an empty or damaged video)");
  const auto kept = static_cast<int64_t>(c.index.size());
  if (total < d.seq_length)
    throw std::runtime_error("clip '" + path + "' has " + std::to_string(total) + " frame" + (total == 1 ? "" : "s") +
                             ": a training snippet needs " + std::to_string(d.seq_length) + " (data.seq_length)");
  if (kept < d.seq_length)
    throw std::runtime_error(
        "clip '" + path + "': only " + std::to_string(kept) + " of its " + std::to_string(total) +
        " frames move (at most " + fixed(100 * selector.largest_change(), 1) + "% of the pixels changed between the " +
        "frames looked at; data.video.static_threshold is " + fixed(100 * v.static_threshold, 1) +
        "%): a clip without " +
        "camera motion teaches neither depth nor motion. Lower data.video.static_threshold if the camera does move");
  char fps_text[32];
  std::snprintf(fps_text, sizeof fps_text, "%.4g fps", source_fps);
  const std::string rate = source_fps > 0 ? fps_text : "rate unknown";
  const int64_t stride = frame_rate_stride(source_fps, v.fps);
  *report = "clip '" + path + "': " + std::to_string(total) + " frames (" + std::to_string(W0) + "x" +
            std::to_string(H0) + ", " + rate + "); " + ordinal(stride) +
            (stride > 1 ? " for " + fixed(v.fps, 0) + " fps" : "") + ", " +
            std::to_string(selector.skipped_static() + selector.skipped_standing()) + " static frames left out (" +
            std::to_string(selector.skipped_static()) + " with under " + fixed(100 * v.static_threshold, 1) +
            "% of the pixels changed, " + std::to_string(selector.skipped_standing()) +
            " with the camera standing while other things moved): " + std::to_string(kept) +
            " kept; the camera moved in " + fixed(100 * selector.moving_share(), 0) + "% of the frames looked at";
  if (selector.moving_share() < kFewMovingFrames)
    *warning = "clip '" + path + "': the camera moved in only " + fixed(100 * selector.moving_share(), 0) +
               "% of its " + std::to_string(selector.looked_at()) +
               " frames looked at (it stood in the others): such a clip is unlikely to teach depth. " + kHardClipAdvice;
  if (c.window.width != W0 || c.window.height != H0)
    *report += "; cropped to " + std::to_string(c.window.width) + "x" + std::to_string(c.window.height) + " at (" +
               std::to_string(c.window.x0) + ", " + std::to_string(c.window.y0) + ")";
  *report += d.camera.given() ? "; camera " + describe_camera(c.K.to(torch::kFloat64), d.width, d.height)
                              : "; camera not given: learned by the networks (model.learn_intrinsics)";
  c.total = total;
  return c;
}

// The clip's record line: its CRC-32 (core/zip_check.h) over a video file's bytes, or over a folder's
// kept files' names and sizes.
std::string clip_record(const Clip& c) {
  uint32_t h = 0;
  if (c.files.empty()) {  // a video: its file's bytes
    std::ifstream in(c.path, std::ios::binary);
    std::vector<char> buf(1 << 20);
    while (in) {
      in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
      h = crc32(buf.data(), static_cast<size_t>(in.gcount()), h);
    }
  }
  for (const auto& file : c.files) {
    const std::string name = fs::path(file).filename().string();
    std::error_code ec;
    const auto size = static_cast<uint64_t>(fs::file_size(file, ec));
    h = crc32(&size, sizeof size, crc32(name.data(), name.size(), h));
  }
  char digest[9];
  std::snprintf(digest, sizeof digest, "%08x", static_cast<unsigned>(h));
  return "clip '" + c.path + "': " + std::to_string(c.total) + " frames, " + std::to_string(c.index.size()) +
         " kept, digest " + digest;
}

}  // namespace

void write_video_file(const std::vector<std::string>& frames, const std::string& path, double fps) {
  if (frames.empty()) throw std::runtime_error("video '" + path + "': no frames to write");
  VideoWriter writer(path, fps);
  for (const auto& f : frames) {
    try {
      writer.write(read_image(f));
    } catch (const std::runtime_error& e) {
      throw std::runtime_error("'" + f + "': " + e.what());
    }
  }
  writer.close();
}

VideoData open_video_clips(const DataConfig& d) {
  if (d.videos.empty()) throw ConfigError("data.videos is empty: name video files or frame folders");
  auto clips = std::make_shared<std::vector<Clip>>();
  std::vector<ClipSnippets::Item> train, val;
  VideoData out;
  // One clip given twice (under any spelling of its path) would count its snippets twice.
  for (size_t i = 0; i < d.videos.size(); ++i)
    for (size_t j = 0; j < i; ++j) {
      std::error_code ec;
      if (d.videos[i] == d.videos[j] || fs::equivalent(d.videos[i], d.videos[j], ec))
        throw ConfigError("data.videos: '" + d.videos[j] + "' and '" + d.videos[i] + "' are the same clip (entries " +
                          std::to_string(j + 1) + " and " + std::to_string(i + 1) + "): give each clip once");
    }
  for (const auto& path : d.videos) {
    std::string line, warning;
    clips->push_back(read_clip(path, d, &line, &warning));
    if (!warning.empty()) out.warnings.push_back(warning);
    const size_t ci = clips->size() - 1;
    const auto n = static_cast<int64_t>(clips->back().index.size());
    const auto runs = split_clip(n, d.video.val_fraction, d.video.val_block, d.seq_length);
    size_t n_train = 0, n_val = 0;
    for (auto* set : {&runs.train, &runs.val}) {
      auto& items = set == &runs.train ? train : val;
      for (const auto& [r, p] : snippet_targets(*set, d.seq_length)) {
        ClipSnippets::Item item{ci, {}};
        for (int64_t o = -d.seq_length / 2; o <= d.seq_length / 2; ++o)
          item.positions.push_back((*set)[r][static_cast<size_t>(p + o)]);
        items.push_back(std::move(item));
        (set == &runs.train ? n_train : n_val)++;
      }
    }
    line += "; " + std::to_string(n_train) + " training snippets";
    if (n_val > 0)
      line += ", " + std::to_string(n_val) + " validation snippets in " + std::to_string(runs.val.size()) + " block" +
              (runs.val.size() == 1 ? "" : "s") + " (" + std::to_string(runs.edge_dropped) +
              " frames left out at their edges)";
    else
      line +=
          ", no validation block (clip too short for data.video.val_fraction " + fixed(d.video.val_fraction, 2) + ")";
    out.report.push_back(line);
    out.records.push_back(clip_record(clips->back()));
  }
  if (train.empty())
    throw ConfigError("data.videos: no training snippet of " + std::to_string(d.seq_length) + " frames in " +
                      std::to_string(d.videos.size()) + " clip(s): " + out.report.front());
  out.train = std::make_shared<ClipSnippets>(clips, std::move(train), d.seq_length);
  if (!val.empty()) out.val = std::make_shared<ClipSnippets>(clips, std::move(val), d.seq_length);
  return out;
}

}  // namespace geo
