// The pipeline layer: NetworkSpec, the checkpoint/model file format (pipeline/checkpoint.h).
#include "core/state_io.h"
#include "pipeline/checkpoint.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace geo {
namespace {

NetworkSpec unusual_spec() {
  NetworkSpec s;
  s.model.encoder_depth = 18;
  s.model.use_fr = false;
  s.model.fr_ratio = 8;
  s.model.bn_scale = true;
  s.model.bn_eps = 1e-5;
  s.model.upsample = Upsample::kBilinear;
  s.height = 32;
  s.width = 96;
  s.seq_length = 5;
  s.flow_input.ssim_alpha = 0.5;
  s.flow_input.image_range = {0.0, 1.0};
  s.flow_input.sampler = Sampler::kBorder;
  return s;
}

void expect_same_spec(const NetworkSpec& a, const NetworkSpec& b) {
  Config x, y;  // compared through their config YAML: every model key, none forgotten
  x.model = a.model;
  y.model = b.model;
  EXPECT_EQ(to_yaml(x), to_yaml(y));
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.seq_length, b.seq_length);
  EXPECT_EQ(a.flow_input.ssim_alpha, b.flow_input.ssim_alpha);
  EXPECT_EQ(a.flow_input.image_range, b.flow_input.image_range);
  EXPECT_EQ(a.flow_input.sampler, b.flow_input.sampler);
}

void expect_same_weights(const torch::nn::Module& a, const torch::nn::Module& b, double tol = 0) {
  const auto pa = a.named_parameters(), pb = b.named_parameters();
  ASSERT_EQ(pa.size(), pb.size());
  for (const auto& p : pa) {
    const auto& q = pb[p.key()];
    if (tol == 0) EXPECT_TRUE(torch::equal(p.value(), q)) << p.key();
    else EXPECT_TRUE(torch::allclose(p.value(), q, 0, tol)) << p.key();
  }
}

TEST(NetworkSpec, YamlRoundTripAndOfAWholeConfig) {
  const NetworkSpec s = unusual_spec();
  expect_same_spec(NetworkSpec::parse(s.to_yaml(), "spec.yaml"), s);
  // The spec holds nothing of training: its YAML has exactly the model, data and loss keys it needs.
  const std::string yaml = s.to_yaml();
  EXPECT_EQ(yaml.find("stages"), std::string::npos);
  EXPECT_EQ(yaml.find("occ_alpha1"), std::string::npos);
  EXPECT_NE(yaml.find("ssim_alpha: 0.5"), std::string::npos);
  // Of a config: the data and loss keys it names, the rest ignored.
  const Config c =
      parse_config("data: {height: 32, width: 96, seq_length: 5}\nloss: {ssim_alpha: 0.25, occ_alpha1: 0.5}\n");
  const NetworkSpec t = NetworkSpec::of(c);
  EXPECT_EQ(t.height, 32);
  EXPECT_EQ(t.seq_length, 5);
  EXPECT_EQ(t.flow_input.ssim_alpha, 0.25);
  EXPECT_THROW(NetworkSpec::parse("model: {encoder_depth: 19}\n", "bad.yaml"), std::runtime_error);
}

TEST(NetworkSpec, ArchitectureDifferenceNamesOnlyWhatChangesWeightShapes) {
  NetworkSpec a, b;
  a.model.encoder_depth = 18;
  a.seq_length = 5;
  EXPECT_EQ(architecture_difference(a, b), "model.encoder_depth 18 (wanted 50), data.seq_length 5 (wanted 3)");
  NetworkSpec c = b;
  c.height = 64;  // input size and the FlowNet input's settings do not change weight shapes
  c.flow_input.ssim_alpha = 0;
  EXPECT_EQ(architecture_difference(c, b), "");
}

struct Tiny {
  Config config = parse_config("model: {encoder_depth: 18}\ndata: {height: 32, width: 96}\n", "tiny.yaml");
  Networks nets;
  Tiny(bool flow = true) {
    torch::manual_seed(3);
    nets = Networks::create(NetworkSpec::of(config), flow);
  }
};

TEST(Checkpoint, TrainingCheckpointRoundTripWithTypedStateAndOptimizer) {
  Tiny t;
  auto w = torch::ones({3}).requires_grad_(true);
  torch::optim::Adam adam({w}, torch::optim::AdamOptions(0.1));
  w.mutable_grad() = torch::tensor({1.0f, -2.0f, 3.0f});
  adam.step();
  const std::string path = test::fresh_dir("pipeline_ckpt") + "/c.pt";
  {
    torch::serialize::OutputArchive a;
    write_checkpoint(a, CheckpointContents{t.nets, &adam, TrainState{1, 42, 0.25, 2}, t.config});
    save_archive(a, path);
  }
  CheckpointFile f(path);
  EXPECT_FALSE(f.is_model_file());
  EXPECT_TRUE(f.has_flow());
  ASSERT_TRUE(f.config());
  EXPECT_EQ(to_yaml(*f.config()), to_yaml(t.config));
  const TrainState s = f.train_state();
  EXPECT_EQ(s.stage, 1);
  EXPECT_EQ(s.iteration, 42);
  EXPECT_EQ(s.best_score, 0.25);
  EXPECT_EQ(s.world_size, 2);
  const Networks back = f.networks();
  expect_same_weights(*back.depth, *t.nets.depth);
  expect_same_weights(*back.flow, *t.nets.flow);
  // The optimizer's state: a step of the reloaded Adam equals a step of the original.
  auto v = torch::ones({3}).requires_grad_(true);
  {
    torch::NoGradGuard g;
    v.copy_(w);
  }
  torch::optim::Adam again({v}, torch::optim::AdamOptions(0.1));
  EXPECT_TRUE(f.load_optimizer(again));
  for (auto* p : {&w, &v}) p->mutable_grad() = torch::tensor({0.5f, 0.5f, -1.0f});
  adam.step();
  again.step();
  EXPECT_TRUE(torch::equal(w, v));
}

TEST(Checkpoint, CheckpointsWrittenBeforeTheTypedStateStillRead) {
  Tiny t(false);
  const std::string path = test::fresh_dir("pipeline_legacy") + "/old.pt";
  torch::serialize::OutputArchive a;
  write_checkpoint(a, CheckpointContents{t.nets, nullptr, TrainState{}, t.config});
  torch::serialize::OutputArchive old;  // the earlier format: float64 meta + int world_size
  for (const char* key : {"depth", "pose"}) {
    torch::serialize::OutputArchive sub;
    write_state(key == std::string("depth") ? static_cast<const torch::nn::Module&>(*t.nets.depth) : *t.nets.pose, sub);
    old.write(key, sub);
  }
  old.write("meta", torch::tensor({1.0, 7.0, 0.5}, torch::kFloat64));
  old.write("world_size", c10::IValue(static_cast<int64_t>(3)));
  old.write("config", c10::IValue(to_yaml(t.config)));
  save_archive(old, path);
  CheckpointFile f(path);
  const TrainState s = f.train_state();
  EXPECT_EQ(s.stage, 1);
  EXPECT_EQ(s.iteration, 7);
  EXPECT_EQ(s.best_score, 0.5);
  EXPECT_EQ(s.world_size, 3);
  EXPECT_FALSE(f.has_flow());
  expect_same_weights(*f.networks().depth, *t.nets.depth);
}

TEST(Checkpoint, ModelFileHoldsWeightsAndSpecOnly) {
  Tiny t;
  const std::string dir = test::fresh_dir("pipeline_model");
  write_model_file(dir + "/m.pt", t.nets, false);
  write_model_file(dir + "/h.pt", t.nets, true);
  CheckpointFile m(dir + "/m.pt"), h(dir + "/h.pt");
  EXPECT_TRUE(m.is_model_file());
  EXPECT_FALSE(m.config());
  expect_same_spec(m.spec(), t.nets.spec);
  expect_same_weights(*m.networks().flow, *t.nets.flow);
  expect_same_weights(*h.networks().depth, *t.nets.depth, 1e-3);  // float16: 11-bit mantissa
  try {
    m.train_state();
    ADD_FAILURE() << "a model file has no train state";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()),
              dir + "/m.pt: a geo_export model file, not a training checkpoint (it has no train state)");
  }
}

TEST(Checkpoint, ForeignAndDamagedFilesAreNamed) {
  const std::string dir = test::fresh_dir("pipeline_bad");
  {
    torch::serialize::OutputArchive a;
    a.write("weights", torch::ones({2}));
    save_archive(a, dir + "/foreign.pt");
  }
  CheckpointFile f(dir + "/foreign.pt");
  EXPECT_THROW(f.spec(), std::runtime_error);
  try {
    f.train_state();
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/foreign.pt: not a geo training checkpoint (no train state)");
  }
  {
    torch::serialize::OutputArchive a, state;
    state.write("stage", c10::IValue(1.5));  // a float where an integer belongs
    state.write("iteration", c10::IValue(static_cast<int64_t>(1)));
    state.write("best_score", c10::IValue(0.0));
    state.write("world_size", c10::IValue(static_cast<int64_t>(1)));
    a.write("train_state", state);
    save_archive(a, dir + "/typed.pt");
  }
  try {
    CheckpointFile(dir + "/typed.pt").train_state();
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/typed.pt: train_state holds values of the wrong types");
  }
  EXPECT_THROW(CheckpointFile(dir + "/missing.pt"), std::runtime_error);
}

}  // namespace
}  // namespace geo
