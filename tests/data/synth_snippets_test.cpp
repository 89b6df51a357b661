// The synthetic world in memory (data.format synthetic): geo_synth's drives, split and frames
// without files, quantised as a PNG holds them, intrinsics scaled to the training size.
#include "data/synth/synth_snippets.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace geo {
namespace {

SynthOptions small_world(int64_t height = 64, int64_t width = 208) {
  auto o = synth_world_at("tiny", height, width);
  o.train_drives = 2;
  o.frames_per_drive = 12;
  return o;
}

TEST(SynthSnippets, GeoSynthsSplitAndIds) {
  const auto sets = render_synth_snippets(small_world(), 3);
  // Targets 1..10 of each drive (both neighbours present); frame 5 goes to validation.
  ASSERT_EQ(sets.train->size(), 18u);
  ASSERT_EQ(sets.val->size(), 2u);
  EXPECT_EQ(sets.train->id(0), "2011_01_01/2011_01_01_drive_0001_sync 1 l");
  EXPECT_EQ(sets.train->id(4), "2011_01_01/2011_01_01_drive_0001_sync 6 l");  // 5 is validation
  EXPECT_EQ(sets.train->id(9), "2011_01_01/2011_01_01_drive_0002_sync 1 l");
  EXPECT_EQ(sets.val->id(1), "2011_01_01/2011_01_01_drive_0002_sync 5 l");
  EXPECT_EQ(sets.train->seq_length(), 3);
  // 5-frame snippets need two neighbours each side: targets 2..9, frame 5 to validation.
  const auto five = render_synth_snippets(small_world(), 5);
  EXPECT_EQ(five.train->size(), 14u);
  EXPECT_EQ(five.train->get(0).frames.size(0), 5);
  EXPECT_EQ(five.train->id(0), "2011_01_01/2011_01_01_drive_0001_sync 2 l");
  GEO_EXPECT_THROW_WITH(render_synth_snippets(small_world(), 4), "seq_length 4 must be odd");
  EXPECT_THROW(sets.train->get(18), std::out_of_range);
}

TEST(SynthSnippets, FramesAreSharedEightBitImagesOfTheTrainingSize) {
  const auto sets = render_synth_snippets(small_world(), 3);
  const auto a = sets.train->get(0), b = sets.train->get(1);  // targets 1 and 2 of drive 1
  ASSERT_EQ(a.frames.sizes(), torch::IntArrayRef({3, 3, 64, 208}));
  EXPECT_TRUE(torch::equal(a.frames[1], b.frames[0]));
  EXPECT_TRUE(torch::equal(a.frames[2], b.frames[1]));
  EXPECT_FALSE(torch::equal(a.frames[0], a.frames[1]));  // the camera moves
  const auto levels = a.frames * 255;
  EXPECT_LT((levels - levels.round()).abs().max().item<double>(), 1e-4);
  EXPECT_GE(a.frames.min().item<double>(), 0.0);
  EXPECT_LE(a.frames.max().item<double>(), 1.0);
  EXPECT_EQ(a.id, sets.train->id(0));
}

TEST(SynthSnippets, IntrinsicsFollowTheTrainingSize) {
  // The tiny preset is KITTI's camera at 64x208; at 128x416 every entry of K doubles.
  const auto tiny = render_synth_snippets(small_world(), 3).train->get(0);
  const auto twice = render_synth_snippets(small_world(128, 416), 3).train->get(0);
  EXPECT_NEAR(tiny.K[0][0].item<double>(), 721.5377 * 208 / 1242, 1e-4);
  EXPECT_NEAR(tiny.K[1][2].item<double>(), 172.854 * 64 / 375, 1e-4);
  EXPECT_TRUE(torch::allclose(twice.K.narrow(0, 0, 2), tiny.K.narrow(0, 0, 2) * 2));
  EXPECT_EQ(twice.K[2][2].item<float>(), 1.0f);
  EXPECT_EQ(twice.frames.sizes(), torch::IntArrayRef({3, 3, 128, 416}));
}

}  // namespace
}  // namespace geo
