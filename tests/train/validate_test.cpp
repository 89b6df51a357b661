// Validation (train/validate.h): every snippet counts once.
#include "train/validate.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>

#include <unistd.h>

#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

// Validation weighs every snippet once: 5 snippets in batches of 2 (the loader fills the last batch
// from the start of the list again) score the mean of the 5 validated one at a time. The PoseNet
// predicts no motion (its last layer zeroed), so every pixel stays in view and each snippet's loss
// is a mean over the same number of pixels: the mean of the 5 is then exact.
TEST(Validation, EverySnippetCountsOnce) {
  struct Fixed : SnippetSource {
    std::vector<Snippet> s;
    size_t size() const override { return s.size(); }
    Snippet get(size_t i) const override { return s.at(i); }
    std::string id(size_t i) const override { return std::to_string(i); }
    int64_t seq_length() const override { return 3; }
  };
  torch::manual_seed(4);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 1}\n");
  Networks n = Networks::create(NetworkSpec::of(c), false);
  {
    torch::NoGradGuard no_grad;
    n.pose->pred->weight.zero_();
    n.pose->pred->bias.zero_();
  }
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({3, 3});
  auto all = std::make_shared<Fixed>();
  for (int i = 0; i < 5; ++i)  // snippet 0 of high contrast: a loss unlike the others'
    all->s.push_back(Snippet{torch::rand({3, 3, 64, 128}) * (i == 0 ? 1.0 : 0.1), K, "s" + std::to_string(i)});
  StageConfig stage = c.stages[0];
  stage.batch_size = 2;
  const auto batched = validate(n, all, stage, c, torch::kCPU, nullptr);
  EXPECT_EQ(batched.snippets, 5u);
  stage.batch_size = 1;
  std::vector<double> each;
  for (int i = 0; i < 5; ++i) {
    auto one = std::make_shared<Fixed>();
    one->s = {all->s[static_cast<size_t>(i)]};
    each.push_back(validate(n, one, stage, c, torch::kCPU, nullptr).rigid);
  }
  const double sum = std::accumulate(each.begin(), each.end(), 0.0), mean = sum / 5;
  // The mean of the batch means, the wrapped snippet 0 counted twice, is measurably off.
  EXPECT_GT(std::abs((sum + each[0]) / 6 - mean), 1e-2 * mean);
  EXPECT_NEAR(batched.rigid, mean, 1e-5 * mean);
  EXPECT_EQ(batched.score, batched.rigid);  // a depth-and-pose stage is ranked by L_br
}

}  // namespace
}  // namespace geo
