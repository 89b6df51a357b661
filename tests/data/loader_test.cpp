// The batch stream: determinism and exact resumption, augmentation consistent with the
// intrinsics, bad-sample policies, and the packed cache round trip.
#include "data/loader.h"
#include "data/packed/packed.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace geo {
namespace {

// Snippet i: frames filled with a horizontal ramp (value = u / W) plus i / 100, K = identity-like.
class FakeSource : public SnippetSource {
 public:
  explicit FakeSource(size_t n, int bad = -1) : n_(n), bad_(bad) {}
  size_t size() const override { return n_; }
  int64_t seq_length() const override { return 3; }
  std::string id(size_t i) const override { return "fake " + std::to_string(i); }
  Snippet get(size_t i) const override {
    if (static_cast<int>(i) == bad_) throw std::runtime_error("fake.png: cannot decode image");
    auto ramp = torch::arange(16, torch::kFloat32).div(16).view({1, 1, 1, 16}).expand({3, 3, 8, 16});
    return {(ramp * 0.5 + static_cast<double>(i) / 100).contiguous(),
            torch::tensor({10.f, 0.f, 0.f, 0.f, 10.f, 0.f, 0.f, 0.f, 1.f}).view({3, 3}), id(i)};
  }

 private:
  size_t n_;
  int bad_;
};

LoaderOptions options(int workers) {
  LoaderOptions o;
  o.batch_size = 3;
  o.seed = 5;
  o.workers = workers;
  o.augment.photometric_prob = 0.5;
  return o;
}

// A quick look at a whole dataset (stages[].hold_masked's measurement): evenly spread, the first
// and the last included, in order; a source no larger than asked is itself.
TEST(SpreadSnippets, PicksEvenlyFromFirstToLast) {
  const auto source = std::make_shared<FakeSource>(10);
  const auto four = spread_snippets(source, 4);
  ASSERT_EQ(four->size(), 4u);
  std::vector<std::string> ids;
  for (size_t i = 0; i < four->size(); ++i) ids.push_back(four->id(i));
  EXPECT_EQ(ids, (std::vector<std::string>{"fake 0", "fake 3", "fake 6", "fake 9"}));
  EXPECT_EQ(four->get(2).id, "fake 6");
  EXPECT_TRUE(torch::equal(four->get(2).frames, source->get(6).frames));
  EXPECT_EQ(four->seq_length(), 3);
  EXPECT_EQ(spread_snippets(source, 1)->id(0), "fake 0");
  EXPECT_EQ(spread_snippets(source, 10), source);
  EXPECT_EQ(spread_snippets(source, 32), source);
  EXPECT_THROW(spread_snippets(source, 0), std::invalid_argument);
}

TEST(Loader, EveryEpochIsAPermutation) {
  std::vector<int> seen(7, 0);
  for (int64_t p = 7; p < 14; ++p) ++seen[sample_at(3, 7, p)];
  for (int c : seen) EXPECT_EQ(c, 1);
}

TEST(Loader, ShardsOfAWorldPartitionTheSingleProcessStream) {
  // Distributed: the W shards of batch k hold exactly the samples of the single-process stream's
  // batch k with W times the batch size (the same global positions), each once.
  auto src = std::make_shared<FakeSource>(10);
  auto single = options(0);
  single.batch_size = 6;
  BatchLoader whole(src, single);
  std::vector<std::unique_ptr<BatchLoader>> shards;
  for (int r = 0; r < 2; ++r) {
    auto o = options(r);  // rank 1 with a worker thread: sharding does not depend on threads
    o.rank = r;
    o.world_size = 2;
    shards.push_back(std::make_unique<BatchLoader>(src, o));
  }
  for (int k = 0; k < 4; ++k) {  // across epochs (10 samples, 6 a global batch)
    const auto w = whole.next();
    const auto a = shards[0]->next(), b = shards[1]->next();
    std::vector<std::string> joined = a.ids;
    joined.insert(joined.end(), b.ids.begin(), b.ids.end());
    EXPECT_EQ(joined, w.ids) << "batch " << k;
    EXPECT_EQ(a.index, k);
  }
  // world_size 1 is the single-process stream itself.
  auto o1 = options(0);
  o1.world_size = 1;
  BatchLoader plain(src, options(0)), one(src, o1);
  EXPECT_EQ(plain.next().ids, one.next().ids);
}

TEST(Loader, SameBatchesWithWorkersAndAfterResume) {
  auto src = std::make_shared<FakeSource>(10);
  BatchLoader serial(src, options(0)), threaded(src, options(2));
  std::vector<Batch> first;
  for (int k = 0; k < 6; ++k) {
    auto a = serial.next(), b = threaded.next();
    EXPECT_EQ(a.index, k);
    EXPECT_EQ(a.ids, b.ids);
    EXPECT_TRUE(torch::equal(a.tgt, b.tgt));
    EXPECT_TRUE(torch::equal(a.K, b.K));
    first.push_back(a);
  }
  BatchLoader resumed(src, options(2), 4);  // as after a restart at batch 4
  for (int k = 4; k < 6; ++k) {
    auto b = resumed.next();
    EXPECT_EQ(b.ids, first[k].ids);
    EXPECT_TRUE(torch::equal(b.srcs, first[k].srcs));
  }
}

TEST(Loader, ScaleCropKeepsIntrinsicsConsistent) {
  FakeSource src(1);
  AugmentConfig c;
  c.photometric_prob = 0;
  for (uint64_t seed = 0; seed < 5; ++seed) {
    const auto b = augment(collate({src.get(0)}), c, seed);
    const double fx = b.K[0][0][0].item<double>(), cx = b.K[0][0][2].item<double>();
    const double sx = fx / 10.0;
    EXPECT_GE(sx, 1.0);
    EXPECT_LE(sx, 1.15);
    // The ramp encodes the original column u = 32 * value; K maps new column u' to (u' - cx) / sx.
    for (int u : {3, 8, 12}) {
      const double original = b.tgt[0][0][4][u].item<double>() * 32;
      EXPECT_NEAR(original, (u - cx) / sx, 1e-4) << "seed " << seed << " column " << u;
    }
  }
}

// GeoNet's colour augmentation, one draw per batch for every frame: out = clamp(in^gamma x
// brightness x colour_c, 0, 1). Ranges of one value make it hand-computable: 0.25^2 x 1.5 x 1.2 =
// 0.1125 and 0.9 -> clamped to 1, in the target and every source alike; K untouched (no scaling).
TEST(Loader, PhotometricAugmentationIsGammaBrightnessColourOnEveryFrame) {
  Batch b;
  b.tgt = torch::full({1, 3, 2, 2}, 0.25f);
  b.srcs = torch::full({1, 2, 3, 2, 2}, 0.25f);
  b.srcs[0][1][2][1][1] = 0.9f;
  b.K = torch::eye(3).unsqueeze(0);
  AugmentConfig c;
  c.scale_max = 1.0;
  c.photometric_prob = 1.0;
  c.gamma_min = c.gamma_max = 2.0;
  c.brightness_min = c.brightness_max = 1.5;
  c.color_min = c.color_max = 1.2;
  const auto out = augment(b, c, 3);
  EXPECT_TRUE(torch::allclose(out.tgt, torch::full({1, 3, 2, 2}, 0.1125f), 0, 1e-6));
  auto want = torch::full({1, 2, 3, 2, 2}, 0.1125f);
  want[0][1][2][1][1] = 1.0f;
  EXPECT_TRUE(torch::allclose(out.srcs, want, 0, 1e-6));
  EXPECT_TRUE(torch::equal(out.K, b.K));
  // GeoNet's ranges: a draw differs per seed, but stays one transform for all frames (equal inputs
  // give equal outputs across target and sources, to the last bits of pow's vectorised and scalar
  // paths), per-channel colour included.
  AugmentConfig g;
  g.scale_max = 1.0;
  g.photometric_prob = 1.0;
  const auto x = torch::rand({1, 3, 4, 4});
  Batch same;
  same.tgt = x.clone();
  same.srcs = torch::stack({x[0], x[0]}).unsqueeze(0);
  same.K = b.K;
  const auto a1 = augment(same, g, 11), a2 = augment(same, g, 12);
  EXPECT_TRUE(torch::allclose(a1.srcs[0][0], a1.tgt[0], 0, 1e-6));
  EXPECT_TRUE(torch::allclose(a1.srcs[0][1], a1.tgt[0], 0, 1e-6));
  EXPECT_FALSE(torch::equal(a1.tgt, a2.tgt));
  EXPECT_FALSE(torch::equal(a1.tgt, x));
  // Probability 0: nothing changes.
  g.photometric_prob = 0.0;
  EXPECT_TRUE(torch::equal(augment(same, g, 11).tgt, x));
}

TEST(Loader, BadSampleStopsWithItsNameOrIsSkipped) {
  auto src = std::make_shared<FakeSource>(4, 2);
  auto o = options(0);
  o.batch_size = 4;  // every batch contains sample 2
  BatchLoader stop(src, o);
  GEO_EXPECT_THROW_WITH(stop.next(), "fake.png");
  o.skip_bad = true;
  BatchLoader skip(src, o);
  const auto b = skip.next();
  EXPECT_EQ(b.skipped, 1);
  EXPECT_EQ(b.tgt.size(0), 4);
}

TEST(Packed, RoundTripAndCorruptionMessages) {
  const auto dir = test::fresh_dir("packed");
  FakeSource src(3);
  PackedWriter w(dir + "/cache", 8, 16, 3);
  for (size_t i = 0; i < 3; ++i) w.add(src.get(i));
  w.finish();
  EXPECT_TRUE(is_packed_cache(dir + "/cache"));
  PackedSnippets p(dir + "/cache");
  ASSERT_EQ(p.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const auto a = src.get(i), b = p.get(i);
    EXPECT_EQ(b.id, a.id);
    EXPECT_LE((a.frames - b.frames).abs().max().item<double>(), 0.5 / 255 + 1e-6);
    EXPECT_TRUE(torch::equal(a.K, b.K));
  }
  // The index's first line carries the format version: another version is refused, by number.
  const std::string index = test::read_file(dir + "/cache/index.txt");
  ASSERT_EQ(index.rfind("geo-packed 2\n", 0), 0u);
  EXPECT_FALSE(p.pack().empty());
  test::write_text(dir + "/cache/index.txt", "geo-packed 3\n" + index.substr(13));
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/cache"), "format version 3", "this geo reads 1 and 2");
  test::write_text(dir + "/cache/index.txt", "geo-packed one\n" + index.substr(13));
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/cache"), "index.txt", "malformed first line");
  // Header values whose record size would overflow are refused before any arithmetic.
  test::write_text(dir + "/cache/index.txt",
                   "geo-packed 2\nheight 16384\nwidth 16384\nseq_length 64\ncount 9000000000\n");
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/cache"), "index.txt", "implausible header");
  test::write_text(dir + "/cache/index.txt", "geo-packed 2\nwidth 8\nheight 16\nseq_length 3\ncount 3\n");
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/cache"), "'width 8'", "expected 'height N'");
  test::write_text(dir + "/cache/index.txt", "geo-packed 2\nheight 8\nwidth 16\nseq_length 3\ncount 3\npack a b\n");
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/cache"), "'pack a b'", "expected 'pack ID'");
  test::write_text(dir + "/cache/index.txt", index);
  std::filesystem::resize_file(dir + "/cache/frames.bin", 100);
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/cache"), "frames.bin", "wrong size");
  GEO_EXPECT_THROW_WITH(PackedSnippets(dir + "/none"), "index.txt", "cannot open");
}

}  // namespace
}  // namespace geo
