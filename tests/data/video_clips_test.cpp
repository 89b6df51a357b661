// The user's own footage as training data (data/video/video_clips.h): frame folders and videos
// decoded once, subsampled, static frames left out, the camera following crop and resize, and the
// bad clips a user brings named with the file and the value.
#include "data/image_io.h"
#include "data/synth/synth.h"
#include "data/video/video_clips.h"

#include <gtest/gtest.h>

#include "test_util.h"

#include <filesystem>

namespace geo {
namespace {

// Frames 0..n-1 of one synthetic drive (64x208, the camera moves ~1 m a frame) as PNG files named
// frame1.png, frame2.png, ... (so that name order and natural order differ past frame9).
std::vector<std::string> write_drive(const std::string& dir, int64_t n, const std::vector<int64_t>& order = {}) {
  auto o = SynthOptions::preset_named("tiny");
  o.threads = 2;
  const SynthScene scene(7, n);
  std::vector<std::string> files;
  const auto frames = order.empty() ? [&] {
    std::vector<int64_t> all(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) all[static_cast<size_t>(i)] = i;
    return all;
  }() : order;
  std::filesystem::create_directories(dir);
  for (size_t i = 0; i < frames.size(); ++i) {
    files.push_back(dir + "/frame" + std::to_string(i + 1) + ".png");
    write_image(files.back(), render_frame(scene, frames[i], o).image);
  }
  return files;
}

DataConfig video_config(const std::vector<std::string>& clips) {
  DataConfig d;
  d.height = 64;
  d.width = 208;
  d.seq_length = 3;
  d.videos = clips;
  const SynthIntrinsics k;
  d.camera.intrinsics = {k.fx, k.fy, k.cx, k.cy};
  return d;
}

std::string error_of(const DataConfig& d) {
  try {
    open_video_clips(d);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(VideoClips, AFrameFolderInNaturalOrderWithoutItsStaticStretch) {
  const auto dir = test::fresh_dir("video_folder");
  // 12 moving frames, with frame 5 repeated 4 times after it (the camera waits): 16 files.
  const auto files = write_drive(dir + "/clip", 16, {0, 1, 2, 3, 4, 5, 5, 5, 5, 5, 6, 7, 8, 9, 10, 11});
  auto d = video_config({dir + "/clip"});
  const auto data = open_video_clips(d);
  ASSERT_EQ(data.report.size(), 1u);
  EXPECT_NE(data.report[0].find("16 frames (208x64, rate unknown); every frame, 4 static frames left out"),
            std::string::npos)
      << data.report[0];
  EXPECT_NE(data.report[0].find("12 kept"), std::string::npos) << data.report[0];
  // 12 frames are too few for a 10% validation block of 3: 10 training snippets.
  EXPECT_EQ(data.val, nullptr);
  ASSERT_EQ(data.train->size(), 10u);
  // Snippet 5 is centred on the first frame after the stop (frame11.png): its neighbours are the last
  // frame before the stop (frame6.png) and the next one (frame12.png), in natural order.
  const auto s = data.train->get(5);
  EXPECT_EQ(s.id, files[10]);
  EXPECT_TRUE(torch::allclose(s.frames[0], read_image(files[5]), 0, 1e-6));
  EXPECT_TRUE(torch::allclose(s.frames[1], read_image(files[10]), 0, 1e-6));
  EXPECT_TRUE(torch::allclose(s.frames[2], read_image(files[11]), 0, 1e-6));
  // The frames are the training size already: K is the camera's.
  const SynthIntrinsics k;
  EXPECT_TRUE(torch::allclose(s.K, k.K().to(torch::kFloat32)));
}

TEST(VideoClips, AVideoAtThirtyFramesASecondIsSubsampledToTen) {
  const auto dir = test::fresh_dir("video_file");
  const auto files = write_drive(dir + "/frames", 30);
  write_video_file(files, dir + "/drive.avi", 30);
  auto d = video_config({dir + "/drive.avi"});
  d.video.fps = 10;
  const auto data = open_video_clips(d);
  EXPECT_NE(data.report[0].find("30 frames (208x64, 30 fps); every 3rd frame for 10 fps, 0 static frames left out"),
            std::string::npos)
      << data.report[0];
  ASSERT_EQ(data.train->size(), 8u);  // frames 0, 3, ..., 27: 10 kept, 8 snippets
  const auto s = data.train->get(0);
  EXPECT_EQ(s.id, dir + "/drive.avi frame 3");
  // Motion-JPEG in the file, JPEG in memory: close to the rendered frames, not equal.
  for (int i = 0; i < 3; ++i)
    EXPECT_LT((s.frames[i] - read_image(files[static_cast<size_t>(3 * i)])).abs().mean().item<double>(), 0.03);
}

TEST(VideoClips, TheCameraFollowsTheCropToTheTrainingShape) {
  // 208x100 frames for 208x64 training: 64 rows from y0 = 18 (centred); cy moves by 18.
  const auto dir = test::fresh_dir("video_crop");
  torch::manual_seed(3);
  for (int i = 0; i < 5; ++i) write_image(dir + "/clip/" + std::to_string(i) + ".png", torch::rand({3, 100, 208}));
  auto d = video_config({dir + "/clip"});
  d.camera.intrinsics = {150, 151, 104, 50};
  const auto s = open_video_clips(d).train->get(0);
  EXPECT_FLOAT_EQ(s.K[0][0].item<float>(), 150);
  EXPECT_FLOAT_EQ(s.K[1][1].item<float>(), 151);
  EXPECT_FLOAT_EQ(s.K[0][2].item<float>(), 104);
  EXPECT_FLOAT_EQ(s.K[1][2].item<float>(), 50 - 18);
  EXPECT_TRUE(torch::allclose(s.frames[0], read_image(dir + "/clip/0.png").slice(1, 18, 82), 0, 1e-6));
  // Without cropping the frame is stretched: cy scales by 64/100.
  d.video.crop = false;
  EXPECT_FLOAT_EQ(open_video_clips(d).train->get(0).K[1][2].item<float>(), 50 * 0.64f);
}

TEST(VideoClips, BadClipsNameTheFileAndTheValue) {
  const auto dir = test::fresh_dir("video_bad");
  test::write_text(dir + "/empty.mp4", "");
  EXPECT_NE(error_of(video_config({dir + "/empty.mp4"})).find("clip '" + dir + "/empty.mp4'"), std::string::npos);
  test::write_text(dir + "/text.mp4", "not a video at all");
  EXPECT_NE(error_of(video_config({dir + "/text.mp4"})).find(dir + "/text.mp4"), std::string::npos);
  EXPECT_NE(error_of(video_config({dir + "/missing.mp4"})).find("does not exist"), std::string::npos);
  std::filesystem::create_directories(dir + "/nothing");
  EXPECT_NE(error_of(video_config({dir + "/nothing"})).find("holds no image files"), std::string::npos);
  write_drive(dir + "/one", 1);
  EXPECT_NE(error_of(video_config({dir + "/one"})).find("has 1 frame: a training snippet needs 3"), std::string::npos);
  // One clip twice, under two spellings: its snippets would count double.
  const std::string again = dir + "/../" + std::filesystem::path(dir).filename().string() + "/one/";
  const auto twice = error_of(video_config({dir + "/one", dir + "/nothing", again}));
  EXPECT_NE(twice.find("data.videos: '" + dir + "/one' and '" + dir + "/../"), std::string::npos) << twice;
  EXPECT_NE(twice.find("are the same clip (entries 1 and 3): give each clip once"), std::string::npos) << twice;
  // A clip without motion: the same frame five times.
  write_drive(dir + "/still", 5, {2, 2, 2, 2, 2});
  const auto still = error_of(video_config({dir + "/still"}));
  EXPECT_NE(still.find("only 1 of its 5 frames move (at most 0.0% of the pixels changed"), std::string::npos) << still;
  // Frames of changing size.
  write_drive(dir + "/sizes", 4);
  write_image(dir + "/sizes/frame3.png", torch::rand({3, 60, 200}));
  const auto sizes = error_of(video_config({dir + "/sizes"}));
  EXPECT_NE(sizes.find("'" + dir + "/sizes/frame3.png' is 200x60 but '" + dir + "/sizes/frame1.png' is 208x64"),
            std::string::npos)
      << sizes;
  // A corrupt frame.
  write_drive(dir + "/corrupt", 4);
  test::write_text(dir + "/corrupt/frame2.png", "garbage");
  EXPECT_NE(error_of(video_config({dir + "/corrupt"})).find("cannot read image '" + dir + "/corrupt/frame2.png'"),
            std::string::npos);
  // A link named like a frame that leads nowhere: not passed over (a frame would go missing).
  write_drive(dir + "/linked", 4);
  std::filesystem::remove(dir + "/linked/frame3.png");
  std::filesystem::create_symlink(dir + "/elsewhere.png", dir + "/linked/frame3.png");
  const auto linked = error_of(video_config({dir + "/linked"}));
  EXPECT_NE(linked.find("frame '" + dir + "/linked/frame3.png' in '" + dir + "/linked' is a link to nothing"),
            std::string::npos)
      << linked;
  // Absurd intrinsics name the key.
  auto d = video_config({dir + "/sizes"});
  d.camera.intrinsics = {0, 100, 104, 32};
  EXPECT_NE(error_of(d).find("data.camera.intrinsics: focal lengths fx = 0"), std::string::npos) << error_of(d);
}

// A video damaged in its middle (a few kilobytes overwritten) or cut short: refused, naming the clip
// and where it stops decoding, instead of training on the frames before the damage.
TEST(VideoClips, ADamagedOrCutVideoIsRefused) {
  const auto dir = test::fresh_dir("video_damaged");
  const auto files = write_drive(dir + "/frames", 24);
  write_video_file(files, dir + "/drive.avi", 10);
  const auto bytes = test::read_file(dir + "/drive.avi");
  auto damaged = bytes;
  for (size_t i = bytes.size() / 2; i < bytes.size() / 2 + 4096; ++i) damaged[i] = '\0';
  test::write_text(dir + "/damaged.avi", damaged);
  const auto middle = error_of(video_config({dir + "/damaged.avi"}));
  EXPECT_NE(middle.find("clip '" + dir + "/damaged.avi': "), std::string::npos) << middle;
  EXPECT_NE(middle.find(" be decoded"), std::string::npos) << middle;  // "only 22 of its 24 frames can be decoded" here
  test::write_text(dir + "/cut.avi", bytes.substr(0, bytes.size() / 2));
  const auto cut = error_of(video_config({dir + "/cut.avi"}));
  EXPECT_NE(cut.find("clip '" + dir + "/cut.avi': "), std::string::npos) << cut;
  EXPECT_NE(cut.find("can be decoded"), std::string::npos) << cut;
  EXPECT_EQ(error_of(video_config({dir + "/drive.avi"})), "");  // the whole file reads
}

}  // namespace
}  // namespace geo
