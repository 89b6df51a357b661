// The networks of a config as training and inference get them (pipeline/networks.h).
#include "pipeline/networks.h"
#include "core/config.h"
#include "models/sync_batch_norm.h"

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

TEST(StageNetworks, GeoNetBatchNormByDefaultAndTrainableSetOncePerStage) {
  Config c = parse_config("model: {encoder_depth: 18}\n");
  Networks n = Networks::create(NetworkSpec::of(c), true);
  int bns = 0;
  for (const auto& m : n.depth->modules())
    if (const auto* bn = m->as<SyncBatchNorm2d>()) {
      ++bns;
      EXPECT_EQ(bn->options.eps(), 1e-3);               // slim's epsilon
      EXPECT_EQ(bn->options.momentum().value(), 1e-3);  // slim's decay 0.999
      EXPECT_FALSE(bn->weight.requires_grad());         // scale=False: gamma stays 1
    }
  EXPECT_GT(bns, 20);
  StageConfig flow_only;
  flow_only.train = NetworkSet{false, false, true};
  n.set_trainable(flow_only);
  const auto params = n.trainable_parameters();
  int64_t flow_trainable = 0;
  for (const auto& p : n.flow->parameters()) flow_trainable += p.requires_grad();
  EXPECT_EQ(static_cast<int64_t>(params.size()), flow_trainable);
  EXPECT_EQ(static_cast<int64_t>(n.flow->parameters().size() - batchnorm_scales(*n.flow).size()), flow_trainable);
  for (const auto& p : n.depth->parameters()) EXPECT_FALSE(p.requires_grad());
  // trainable_parameters() only reads: calling it again changes nothing.
  EXPECT_EQ(n.trainable_parameters().size(), params.size());

  // LibTorch's convention as the option: learned gamma, eps 1e-5, momentum 0.1.
  c = parse_config("model: {encoder_depth: 18, bn_eps: 1.0e-5, bn_momentum: 0.1, bn_scale: true}\n");
  Networks t = Networks::create(NetworkSpec::of(c), false);
  t.set_trainable(c.stages[0]);
  EXPECT_EQ(t.trainable_parameters().size(), t.depth->parameters().size() + t.pose->parameters().size());
  for (const auto& m : t.pose->modules())
    if (const auto* bn = m->as<SyncBatchNorm2d>()) {
      EXPECT_EQ(bn->options.momentum().value(), 0.1);
    }
}

}  // namespace
}  // namespace geo
