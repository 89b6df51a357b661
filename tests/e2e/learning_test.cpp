// The learning check: a short stage-1 training on a tiny synthetic world must beat the
// untrained network and trivial baselines on held-out data: depth AbsRel (median-scaled, Eigen
// protocol on the held-out drive), pose ATE (5-frame snippets of an unseen sequence), and flow EPE
// (rigid flow from depth and pose, on unseen pairs). If the photometric loss did not drive learning
// (e.g. replaced by zero), none of these would improve.
#include "core/config.h"
#include "data/synth_writer.h"
#include "eval/protocols.h"
#include "train/trainer.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include "test_util.h"

namespace geo {
namespace {

double metric(const EvalResult& r, const std::string& name) {
  for (const auto& [k, v] : r.metrics)
    if (k == name) return v;
  ADD_FAILURE() << "no metric " << name;
  return 0;
}

TEST(Learning, ShortTrainingBeatsUntrainedAndTrivialBaselines) {
  const auto root = test::fresh_dir("learning");
  auto o = SynthOptions::preset_named("tiny");
  o.seed = 1;
  o.flow_pairs = 10;
  o.odometry_frames = 30;
  write_synth_world(root + "/world", o);
  // bn_momentum 0.1 (LibTorch's): GeoNet's 0.001 averages BatchNorm's running statistics over
  // ~1000 batches, so after 300 iterations evaluation would still use near-initial statistics.
  const std::string yaml = R"(
model: {encoder_depth: 18, bn_momentum: 0.1}
data: {height: 64, width: 208, num_workers: 1, augment: {enabled: false}}
stages:
  - {name: stage1, iterations: 300, train: [depth, pose], batch_size: 4, learning_rate: 5.0e-4}
logging: {interval: 50, summary_interval: 0, checkpoint_interval: 300, val_interval: 0}
run: {seed: 1, threads: 2}
)";
  const auto cfg = parse_config(yaml, "learning.yaml", {"data.root=" + root + "/world/raw"});
  TrainOptions t;
  t.run_dir = root + "/run";
  ASSERT_EQ(train(cfg, t), 0);

  Predictor trained(t.run_dir, "cpu"), untrained(cfg, "cpu");
  auto eval = [&](const std::string& split, Predictor* p, bool trivial) {
    EvalOptions e;
    e.split = split;
    e.data_root = root + "/world";
    e.trivial = trivial;
    return evaluate(e, p);
  };
  struct Check {
    const char* split;
    const char* metric;
    double margin;  // trained must be below margin x the better baseline
  };
  for (const Check c : {Check{"eigen", "abs_rel", 0.92}, Check{"odometry", "ate_mean", 0.5},
                        Check{"kitti2015", "epe_all", 0.8}}) {
    const double tr = metric(eval(c.split, &trained, false), c.metric);
    const double un = metric(eval(c.split, &untrained, false), c.metric);
    const double tv = metric(eval(c.split, nullptr, true), c.metric);
    std::printf("learning check %-9s %-8s trained %.4f  untrained %.4f  trivial %.4f\n", c.split, c.metric, tr, un, tv);
    EXPECT_LT(tr, c.margin * std::min(un, tv)) << c.split << " " << c.metric;
  }
}

}  // namespace
}  // namespace geo
