// The C++ inference API (include/geo/geo.h): the same numbers as the networks run directly on a
// training checkpoint (and the evaluation's Predictor, a layer over it), exported files that give exactly the checkpoint's outputs (float16: stated
// bound), any input size, thread-safe concurrent calls, the process's random generator untouched,
// and geo::Error for every misuse.
#include "geo/geo.h"

#include "core/config.h"
#include "core/mapped_archive.h"
#include "core/runtime.h"
#include "core/state_io.h"
#include "data/image_io.h"
#include "data/text_io.h"
#include "eval/predictor.h"
#include "geometry/pose.h"
#include "pipeline/checkpoint.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <thread>

#include "synth_world.h"
#include "test_util.h"

namespace geo {
namespace {

// A training checkpoint as geo_train writes one (networks + config), with untrained weights.
const std::string& checkpoint() {
  static const std::string path = [] {
    const Config c = parse_config("model: {encoder_depth: 18}\ndata: {height: 64, width: 208}\n", "api.yaml");
    torch::manual_seed(1);
    Networks nets = Networks::create(NetworkSpec::of(c), true);
    torch::serialize::OutputArchive a;
    write_checkpoint(a, CheckpointContents{nets, nullptr, TrainState{}, c});
    const std::string p = test::fresh_dir("api") + "/ckpt.pt";
    save_archive(a, p);
    return p;
  }();
  return path;
}

torch::Tensor image(int64_t H, int64_t W, double shift = 0) {
  return (torch::linspace(0, 1, 3 * H * W).view({3, H, W}) + shift).remainder(1.0);
}

// The networks of the checkpoint, run directly (what the evaluation ran before it used the API).
struct Direct {
  Networks nets;
  Direct() {
    nets = CheckpointFile(checkpoint()).networks();
    nets.prepare_inference(true);
  }
};

TEST(Api, SameDepthPoseAndFlowAsTheNetworksThemselves) {
  const Model m = Model::load(checkpoint());
  Direct d;
  EXPECT_EQ(m.spec().height, 64);
  EXPECT_EQ(m.spec().seq_length, 3);
  EXPECT_TRUE(m.spec().has_flow);
  torch::NoGradGuard no_grad;
  const auto a = image(64, 208), b = image(64, 208, 0.1);
  EXPECT_TRUE(torch::equal(m.depth(a), (1.0 / d.nets.depth->forward(a.unsqueeze(0)).disp[0])[0][0]));
  const auto vec = d.nets.pose->forward(a.unsqueeze(0), {a.unsqueeze(0), b.unsqueeze(0)});  // (a, a, b)
  EXPECT_TRUE(torch::equal(m.relative_pose(a, b), pose_vec_to_matrix(vec[0])[1]));
  // The rigid flow is the projection of a's depth moved by the camera motion, computed here in
  // float64 from depth() and relative_pose(): p' = K (R z K^-1 p + t), flow = p'/z' - p.
  const auto K = torch::tensor({100.f, 0.f, 104.f, 0.f, 100.f, 32.f, 0.f, 0.f, 1.f}).view({3, 3});
  const auto parts = m.flow_parts(a, b, K);
  EXPECT_TRUE(torch::equal(m.flow(a, b, K), parts.full));
  // The depth and motion the rigid flow was made of, exactly as depth() and relative_pose() give them.
  EXPECT_TRUE(torch::equal(parts.depth, m.depth(a)));
  EXPECT_TRUE(torch::equal(parts.motion, m.relative_pose(a, b)));
  const auto Kd = K.to(torch::kFloat64);
  const auto T = m.relative_pose(a, b).to(torch::kFloat64);
  const auto xs = torch::arange(208, torch::kFloat64).view({1, 208}).expand({64, 208});
  const auto ys = torch::arange(64, torch::kFloat64).view({64, 1}).expand({64, 208});
  const auto pix = torch::stack({xs, ys, torch::ones_like(xs)}).reshape({3, -1});
  const auto cam = torch::inverse(Kd).matmul(pix) * m.depth(a).to(torch::kFloat64).reshape({1, -1});
  const auto proj = Kd.matmul(T.slice(0, 0, 3).slice(1, 0, 3).matmul(cam) + T.slice(0, 0, 3).slice(1, 3, 4));
  const auto rigid = (proj.slice(0, 0, 2) / proj.slice(0, 2, 3) - pix.slice(0, 0, 2)).reshape({2, 64, 208});
  const double rigid_error = (parts.rigid.to(torch::kFloat64) - rigid).abs().max().item<double>();
  std::printf("rigid flow against the hand projection: max %.3g px (flow up to %.3g px)\n", rigid_error,
              rigid.abs().max().item<double>());
  EXPECT_LT(rigid_error, 1e-3);
  EXPECT_FALSE(torch::equal(parts.full, parts.rigid));  // the FlowNet's residual is there
  EXPECT_EQ(m.pose({b, a, b}).sizes(), (torch::IntArrayRef{2, 4, 4}));
  // The evaluation's Predictor is this API in the protocols' shapes.
  Predictor p(checkpoint(), "cpu");
  EXPECT_TRUE(torch::equal(p.depth(a.unsqueeze(0))[0][0], m.depth(a)));
  EXPECT_TRUE(torch::equal(p.pose(a.unsqueeze(0), {b.unsqueeze(0), b.unsqueeze(0)})[0], m.pose({b, a, b})));
  // uint8 pixels are the same image as float / 255.
  const auto u8 = (a * 255).round().to(torch::kUInt8);
  EXPECT_TRUE(torch::equal(m.depth(u8), m.depth(u8.to(torch::kFloat32) / 255)));
}

TEST(Api, AnyInputSizeAndBatches) {
  const Model m = Model::load(checkpoint());
  EXPECT_EQ(m.depth(image(100, 300)).sizes(), (torch::IntArrayRef{100, 300}));
  EXPECT_EQ(m.depth(torch::stack({image(64, 208), image(64, 208, 0.2)})).sizes(), (torch::IntArrayRef{2, 64, 208}));
  // Flow of images twice as wide is in pixels of that width: x doubled, y unchanged. Each column
  // repeated twice halves back (bilinear) to exactly the model's input, so the wide flow is exactly
  // the model's flow resized to 64x416 with its x component doubled (swapped factors would fail).
  const auto a = image(64, 208), b = image(64, 208, 0.1);
  const auto small = m.flow(a, b);
  const auto wide = [](const torch::Tensor& x) { return x.repeat_interleave(2, 2); };
  ASSERT_TRUE(torch::equal(
      torch::nn::functional::interpolate(wide(a).unsqueeze(0), torch::nn::functional::InterpolateFuncOptions()
                                                                   .size(std::vector<int64_t>{64, 208})
                                                                   .mode(torch::kBilinear)
                                                                   .align_corners(false))[0],
      a));
  const auto big = m.flow(wide(a), wide(b));
  EXPECT_EQ(big.sizes(), (torch::IntArrayRef{2, 64, 416}));
  const auto expected =
      torch::nn::functional::interpolate(small.unsqueeze(0), torch::nn::functional::InterpolateFuncOptions()
                                                                 .size(std::vector<int64_t>{64, 416})
                                                                 .mode(torch::kBilinear)
                                                                 .align_corners(false))[0] *
      torch::tensor({2.f, 1.f}).view({2, 1, 1});
  EXPECT_LT((big - expected).abs().max().item<double>(), 1e-4);
  EXPECT_GT(big[0].abs().mean().item<double>(), 0.1);  // a flow whose x component matters
}

// run_sequence: each frame's depth and, to the next frame, flow_parts with the previous frame as the
// snippet's first; the trajectory is chain_poses of the motions; scales multiply depth and steps.
// With 2 intra-op threads two frames are computed at once with one thread each (core/lanes.h): the
// same as the calls made with one thread, handed on in order.
TEST(Api, RunSequenceIsTheCallsFrameByFrame) {
  const Model m = Model::load(checkpoint());
  const std::vector<torch::Tensor> frames{image(64, 208), image(64, 208, 0.1), image(64, 208, 0.25),
                                          image(64, 208, 0.3)};
  TensorFrames source(frames);
  std::vector<SequenceFrame> seen;
  std::vector<int> sink_threads;
  const int threads = torch::get_num_threads();
  torch::set_num_threads(2);
  const auto poses = m.run_sequence(source, [&](const SequenceFrame& f) {
    seen.push_back(f);
    sink_threads.push_back(torch::get_num_threads());
  });
  EXPECT_EQ(torch::get_num_threads(), 2);
  EXPECT_EQ(sink_threads, std::vector<int>(4, 1));  // lanes were at work (the caller keeps one thread)
  torch::set_num_threads(1);
  ASSERT_EQ(seen.size(), 4u);
  std::vector<torch::Tensor> motions;
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(seen[i].index, i);
    EXPECT_TRUE(torch::equal(seen[i].image, frames[i]));
    EXPECT_EQ(seen[i].scale, 1.0);
    if (i == 3) {
      EXPECT_TRUE(torch::equal(seen[i].depth, m.depth(frames[i])));
      EXPECT_FALSE(seen[i].flow.defined() || seen[i].motion.defined() || seen[i].rigid_flow.defined());
      continue;
    }
    const auto parts = m.flow_parts(frames[i], frames[i + 1], {}, i > 0 ? frames[i - 1] : torch::Tensor());
    EXPECT_TRUE(torch::equal(seen[i].depth, parts.depth)) << i;
    EXPECT_TRUE(torch::equal(seen[i].flow, parts.full)) << i;
    EXPECT_TRUE(torch::equal(seen[i].rigid_flow, parts.rigid)) << i;
    EXPECT_TRUE(torch::equal(seen[i].motion, parts.motion)) << i;
    motions.push_back(parts.motion);
  }
  ASSERT_TRUE(poses.defined());
  EXPECT_TRUE(torch::equal(poses, chain_poses(motions)));
  // Scales: depth times its frame's, each step's translation times its first frame's.
  std::vector<SequenceFrame> scaled;
  const auto scaled_poses =
      m.run_sequence(source, [&](const SequenceFrame& f) { scaled.push_back(f); }, {2.0, 3.0, 4.0, 5.0});
  EXPECT_TRUE(torch::allclose(scaled[3].depth, 5 * seen[3].depth, 1e-6, 0));
  EXPECT_TRUE(torch::equal(scaled_poses, chain_poses(motions, {2.0, 3.0, 4.0})));
  // One frame: depth, no trajectory.
  TensorFrames one({frames[0]});
  size_t calls = 0;
  EXPECT_FALSE(m.run_sequence(one, [&](const SequenceFrame&) { ++calls; }).defined());
  EXPECT_EQ(calls, 1u);
  // What is refused, by name.
  const auto nothing = [](const SequenceFrame&) {};
  TensorFrames none({});
  GEO_EXPECT_THROW_WITH(m.run_sequence(none, nothing), "no frame");
  TensorFrames mixed({frames[0], image(32, 104)});
  GEO_EXPECT_THROW_WITH(m.run_sequence(mixed, nothing), "frame 1 is [3, 32, 104], expected [3, 64, 208]");
  GEO_EXPECT_THROW_WITH(m.run_sequence(source, nothing, {1.0, 1.0, 1.0, 1.0, 1.0}), "5 scales for 4 frames");
  GEO_EXPECT_THROW_WITH(m.run_sequence(source, nothing, {1.0}), "1 scales for a sequence of more");
  torch::set_num_threads(2);  // thrown while frames were computed ahead: refused the same way
  GEO_EXPECT_THROW_WITH(m.run_sequence(source, nothing, {1.0}), "1 scales for a sequence of more");
  GEO_EXPECT_THROW_WITH(m.run_sequence(source,
                                       [](const SequenceFrame& f) {
                                         if (f.index == 1) throw Error("the sink failed at frame 1");
                                       }),
                        "the sink failed at frame 1");
  EXPECT_EQ(torch::get_num_threads(), 2);
  torch::set_num_threads(threads);
}

TEST(Api, ExportedFilesGiveTheCheckpointsOutputs) {
  const Model m = Model::load(checkpoint());
  const auto dir = test::fresh_dir("api_export");
  m.save(dir + "/m.pt");
  m.save(dir + "/m16.pt", true);
  const Model e = Model::load(dir + "/m.pt"), h = Model::load(dir + "/m16.pt");
  const auto a = image(64, 208), b = image(64, 208, 0.1);
  EXPECT_TRUE(torch::equal(e.depth(a), m.depth(a)));
  EXPECT_TRUE(torch::equal(e.flow(a, b), m.flow(a, b)));
  EXPECT_TRUE(torch::equal(e.relative_pose(a, b), m.relative_pose(a, b)));
  const double rel = ((h.depth(a) - m.depth(a)).abs().max() / m.depth(a).abs().max()).item<double>();
  EXPECT_LT(rel, 1e-3) << "float16 weights";
  std::printf("float16 export: depth differs by %.2g relative\n", rel);
  EXPECT_LT(std::filesystem::file_size(dir + "/m.pt"), std::filesystem::file_size(checkpoint()) + 1);
  // float16: half the bytes, plus the archive's per-tensor records (under 1 % here).
  EXPECT_LT(static_cast<double>(std::filesystem::file_size(dir + "/m16.pt")) * 2,
            static_cast<double>(std::filesystem::file_size(dir + "/m.pt")) * 1.01);
}

// An int8 model's file keeps its calibration: loaded in int8 without frames it computes exactly what
// the calibrated model computed, loaded in fp32 what the fp32 model did; a file without one needs frames.
TEST(Api, Int8FilesKeepTheirCalibration) {
  const auto a = image(64, 208), b = image(64, 208, 0.1), c = image(64, 208, 0.2);
  const Model fp32 = Model::load(checkpoint());
  Model int8 = Model::load(checkpoint());
  int8.quantize_int8({a, b, c});
  EXPECT_EQ(int8.spec().precision, "int8");
  EXPECT_FALSE(torch::equal(int8.depth(a), fp32.depth(a)));  // it did compute in int8
  EXPECT_FALSE(torch::equal(int8.pose({a, b, c}), fp32.pose({a, b, c})));
  const auto dir = test::fresh_dir("api_int8");
  int8.save(dir + "/int8.pt");
  LoadOptions o;
  o.precision = "int8";
  const Model back = Model::load(dir + "/int8.pt", o);
  EXPECT_EQ(back.spec().precision, "int8");
  EXPECT_TRUE(torch::equal(back.depth(a), int8.depth(a)));
  EXPECT_TRUE(torch::equal(back.flow(a, b), int8.flow(a, b)));
  EXPECT_TRUE(torch::equal(back.pose({a, b, c}), int8.pose({a, b, c})));
  EXPECT_TRUE(torch::equal(Model::load(dir + "/int8.pt").depth(a), fp32.depth(a)));
  EXPECT_TRUE(torch::equal(Model::load(dir + "/int8.pt").pose({a, b, c}), fp32.pose({a, b, c})));
  GEO_EXPECT_THROW_WITH(Model::load(checkpoint(), o), "precision 'int8' needs calibration frames");
  GEO_EXPECT_THROW_WITH(int8.quantize_int8({a, b}), "int8 already");
  // Loaded in fp32, a file written in int8 says it keeps its calibration and turns int8 without frames
  // (geo_infer --precision int8 then calibrates nothing); a training checkpoint keeps none.
  Model later = Model::load(dir + "/int8.pt");
  EXPECT_TRUE(later.has_int8_calibration());
  later.quantize_int8({});
  EXPECT_EQ(later.spec().precision, "int8");
  EXPECT_TRUE(torch::equal(later.depth(a), int8.depth(a)));
  EXPECT_TRUE(torch::equal(later.pose({a, b, c}), int8.pose({a, b, c})));
  // Inference only: the float kernels go as the int8 ones come, the outputs are the same bit for
  // bit; from the file's calibration or from frames.
  Model lean = Model::load(dir + "/int8.pt");
  lean.quantize_int8({}, false);
  EXPECT_TRUE(lean.float_weights_released());
  EXPECT_FALSE(later.float_weights_released());
  EXPECT_TRUE(torch::equal(lean.depth(a), int8.depth(a)));
  EXPECT_TRUE(torch::equal(lean.pose({a, b, c}), int8.pose({a, b, c})));  // (its last conv in float, kept)
  EXPECT_TRUE(torch::equal(lean.flow(a, b), later.flow(a, b)));
  // Saved, such a model is an int8 model file: its int8 kernels instead of the float ones (under
  // half the size here: the float PoseNet layer and FR stay), opening in int8 only, at once, the same
  // bit for bit; loading it otherwise or calibrating it again is refused naming it.
  lean.save(dir + "/lean.pt");
  EXPECT_LT(std::filesystem::file_size(dir + "/lean.pt") * 2, std::filesystem::file_size(dir + "/int8.pt"));
  const Model opened = Model::load(dir + "/lean.pt", o);
  EXPECT_EQ(opened.spec().precision, "int8");
  EXPECT_TRUE(opened.float_weights_released());
  EXPECT_TRUE(torch::equal(opened.depth(a), int8.depth(a)));
  EXPECT_TRUE(torch::equal(opened.flow(a, b), int8.flow(a, b)));
  EXPECT_TRUE(torch::equal(opened.pose({a, b, c}), int8.pose({a, b, c})));
  LoadOptions when_calibrated;  // (geo_infer --precision int8)
  when_calibrated.int8_when_calibrated = true;
  EXPECT_EQ(Model::load(dir + "/lean.pt", when_calibrated).spec().precision, "int8");
  EXPECT_EQ(Model::load(dir + "/int8.pt", when_calibrated).spec().precision, "int8");
  EXPECT_EQ(Model::load(checkpoint(), when_calibrated).spec().precision, "fp32");
  GEO_EXPECT_THROW_WITH(Model::load(dir + "/lean.pt"), "lean.pt: an int8 model file");
  LoadOptions bf16;
  bf16.precision = "bf16";
  GEO_EXPECT_THROW_WITH(Model::load(dir + "/lean.pt", bf16), "opens in int8 only");
  LoadOptions recalibrate = o;
  recalibrate.calibration = {a, b};
  GEO_EXPECT_THROW_WITH(Model::load(dir + "/lean.pt", recalibrate), "give no calibration frames");
  opened.save(dir + "/lean2.pt");  // written again from its int8 kernels: the same model
  EXPECT_TRUE(torch::equal(Model::load(dir + "/lean2.pt", o).depth(a), int8.depth(a)));
  LoadOptions lean_options = o;
  lean_options.keep_float_weights = false;
  const Model lean_load = Model::load(dir + "/int8.pt", lean_options);
  EXPECT_TRUE(lean_load.float_weights_released());
  EXPECT_TRUE(torch::equal(lean_load.depth(a), int8.depth(a)));
  Model lean_frames = Model::load(checkpoint());
  lean_frames.quantize_int8({a, b, c}, false);
  EXPECT_TRUE(torch::equal(lean_frames.depth(a), int8.depth(a)));
  EXPECT_TRUE(torch::equal(lean_frames.flow(a, b), int8.flow(a, b)));
  Model plain = Model::load(checkpoint());
  EXPECT_FALSE(plain.has_int8_calibration());
  GEO_EXPECT_THROW_WITH(plain.quantize_int8({}), "precision 'int8' needs calibration frames");
  o.calibration = {a};
  GEO_EXPECT_THROW_WITH(Model::load(checkpoint(), o), "at least 2");
}

// An int8 model file as geo wrote it before its kernels were read in place ("geo-model 2": each
// network's kernels in a sub-archive of the LibTorch archive) opens as it did, to the same numbers as
// the file written now (core/mapped_archive.h). A format name that does not match its container is
// refused naming the file.
TEST(Api, Int8ModelFilesOfEarlierGeoStillOpen) {
  torch::manual_seed(2);
  const auto a = torch::rand({3, 64, 208}), b = torch::rand({3, 64, 208}), c = torch::rand({3, 64, 208});
  Model lean = Model::load(checkpoint());
  lean.quantize_int8({a, b, c}, false);
  const auto dir = test::fresh_dir("api_int8_earlier");
  lean.save(dir + "/now.pt");
  EXPECT_TRUE(has_mapped_tensors(dir + "/now.pt"));
  {  // the earlier layout, made of the pieces of the file written now
    CheckpointFile now(dir + "/now.pt");
    Networks nets = Networks::create(now.spec(), now.has_flow());
    now.load_networks(nets, false, /*int8_kernels=*/true);
    torch::serialize::OutputArchive earlier;
    earlier.write("geo_model_format", c10::IValue(std::string("geo-model 2 (int8 kernels)")));
    earlier.write("spec", c10::IValue(now.spec().to_yaml()));
    const auto put = [&](const std::string& name, const torch::nn::Module& module) {
      torch::serialize::OutputArchive state, kernels;
      write_state(module, state);
      earlier.write(name, state);
      earlier.write("int8_" + name, *now.int8_ranges(name));
      for (const auto& [k, t] : now.int8_kernels(name)) kernels.write(k, t.clone());
      earlier.write("int8_kernels_" + name, kernels);
    };
    put("depth", *nets.depth);
    put("pose", *nets.pose);
    put("flow", *nets.flow);
    save_archive(earlier, dir + "/earlier.pt");
  }
  EXPECT_FALSE(has_mapped_tensors(dir + "/earlier.pt"));
  LoadOptions o;
  o.precision = "int8";
  const Model earlier = Model::load(dir + "/earlier.pt", o);
  EXPECT_TRUE(torch::equal(earlier.depth(a), lean.depth(a)));
  EXPECT_TRUE(torch::equal(earlier.flow(a, b), lean.flow(a, b)));
  EXPECT_TRUE(torch::equal(earlier.pose({a, b, c}), lean.pose({a, b, c})));
  torch::serialize::OutputArchive mislabelled;
  mislabelled.write("geo_model_format", c10::IValue(std::string("geo-model 3 (int8 kernels, mapped)")));
  mislabelled.write("spec", c10::IValue(CheckpointFile(dir + "/now.pt").spec().to_yaml()));
  save_archive(mislabelled, dir + "/mislabelled.pt");
  GEO_EXPECT_THROW_WITH(CheckpointFile(dir + "/mislabelled.pt"), "mislabelled.pt: model file format 'geo-model 3",
                        "without its mapped kernels");
}

TEST(Api, CreatedModelsAreTheConfigsNetworksAndOnlyCheckpointsCarryTrainingConfigs) {
  const std::string yaml = "model: {encoder_depth: 18}\ndata: {height: 64, width: 208}\n";
  const Model trained = Model::load(checkpoint());  // its networks: created from `yaml` after manual_seed(1)
  torch::manual_seed(1);
  const Model created = Model::create(yaml);
  EXPECT_EQ(created.spec().source, "untrained");
  EXPECT_EQ(created.spec().encoder_depth, 18);
  EXPECT_EQ(created.spec().width, 208);
  EXPECT_TRUE(created.spec().has_flow);
  const auto a = image(64, 208), b = image(64, 208, 0.1);
  EXPECT_TRUE(torch::equal(created.depth(a), trained.depth(a)));
  EXPECT_TRUE(torch::equal(created.flow(a, b), trained.flow(a, b)));
  // Only a training checkpoint says what it was trained with: its config, whole.
  ASSERT_EQ(trained.training_configs().size(), 1u);
  EXPECT_EQ(trained.training_configs()[0], to_yaml(parse_config(yaml)));
  EXPECT_TRUE(created.training_configs().empty());
  const std::string exported = test::fresh_dir("api_create") + "/m.pt";
  trained.save(exported);
  EXPECT_TRUE(Model::load(exported).training_configs().empty());
  // A key the config does not have is named.
  try {
    Model::create("model: {encoder_dept: 18}");
    ADD_FAILURE() << "no error for an unknown key";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("encoder_dept"), std::string::npos) << e.what();
  }
}

TEST(Api, ConcurrentCallsAndNoGlobalState) {
  const std::string& file = checkpoint();  // written first: writing it seeds and draws
  torch::manual_seed(5);
  const auto expected = torch::rand({4});
  torch::manual_seed(5);
  const Model m = Model::load(file);
  EXPECT_TRUE(torch::equal(torch::rand({4}), expected)) << "loading moved the process's random generator";
  const auto a = image(64, 208);
  const auto serial = m.depth(a);
  std::vector<torch::Tensor> out(4);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) threads.emplace_back([&, t] { out[t] = m.depth(a); });
  for (auto& t : threads) t.join();
  for (const auto& o : out) EXPECT_TRUE(torch::equal(o, serial));
}

TEST(Api, MisuseIsAGeoErrorThatSaysWhat) {
  const Model m = Model::load(checkpoint());
  auto expect_error = [](const std::function<void()>& f, const std::string& fragment) {
    try {
      f();
      ADD_FAILURE() << "no error; expected '" << fragment << "'";
    } catch (const geo::Error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expect_error([&] { m.depth(torch::zeros({1, 64, 208})); }, "expected an RGB image [3,H,W]");
  expect_error([&] { m.depth(torch::zeros({3, 64, 208}, torch::kInt32)); }, "uint8 or floating point");
  auto nan_pixel = image(64, 208);
  nan_pixel[1][10][20] = std::nan("");
  expect_error([&] { m.depth(nan_pixel); }, "1 pixel value(s) are NaN or infinite");
  expect_error([&] { m.depth(image(64, 208) * 255); }, "floating-point pixels must lie in [0, 1]");
  expect_error([&] { m.pose({image(64, 208)}); }, "takes 3 frames, got 1");
  expect_error([&] { m.flow(image(64, 208), image(32, 208)); }, "differ in size");
  expect_error(
      [&] { m.relative_pose(image(64, 208), image(32, 208)); },
      "frame 2 is [3, 32, 208] but frame 0 is [3, 64, 208]: the frames of a snippet (or pair) must have one size");
  expect_error([&] { m.pose({image(64, 208), image(64, 208), image(64, 200)}); }, "frame 2 is [3, 64, 200]");
  expect_error(
      [&] {
        m.flow(image(64, 208), image(64, 208), torch::zeros({3, 3}));
      },
      "intrinsics: focal lengths fx = 0, fy = 0 are not plausible");
  const auto outside = torch::tensor({100.0, 0.0, -500.0, 0.0, 100.0, 9000.0, 0.0, 0.0, 1.0}).view({3, 3});
  expect_error([&] { m.flow(image(64, 208), image(64, 208), outside); },
               "intrinsics: principal point (-500, 9000) lies outside the 208x64 frame");
  expect_error([&] { m.metric_depth(image(64, 208), 1.65, outside); }, "principal point (-500, 9000) lies outside");
  expect_error([] { Model::load("/nonexistent/model.pt"); }, "/nonexistent/model.pt: no such file");
  const auto dir = test::fresh_dir("api_bad");
  test::write_text(dir + "/x.pt", "not a model");
  expect_error([&] { Model::load(dir + "/x.pt"); }, "not a readable geo/LibTorch file");
  expect_error([] { rgb8_image(nullptr, 2, 2); }, "null pixel pointer");
}

TEST(Api, Rgb8ImagesWithRowPadding) {
  const uint8_t px[] = {1, 2, 3, 4,  5,  6,  0, 0,  // row 0: two pixels, 2 bytes of padding
                        7, 8, 9, 10, 11, 12, 0, 0};
  const auto t = rgb8_image(px, 2, 2, 8);
  EXPECT_EQ(t.sizes(), (torch::IntArrayRef{3, 2, 2}));
  EXPECT_EQ(t[0][1][0].item<int>(), 7);  // R of row 1, column 0
  EXPECT_EQ(t[2][0][1].item<int>(), 6);  // B of row 0, column 1
}

// LoadOptions::precision bf16: weights and arithmetic in bfloat16, outputs float32, close to fp32.
TEST(Api, Bf16PrecisionStaysCloseToFp32) {
  const Model fp32 = Model::load(checkpoint());
  LoadOptions o;
  o.precision = "bf16";
  const Model bf16 = Model::load(checkpoint(), o);
  EXPECT_EQ(fp32.spec().precision, "fp32");
  EXPECT_EQ(bf16.spec().precision, "bf16");
  const auto a = image(64, 208), b = image(64, 208, 0.1);
  const auto d32 = fp32.depth(a), d16 = bf16.depth(a);
  EXPECT_EQ(d16.scalar_type(), torch::kFloat32);
  const auto rel = ((d16 - d32).abs() / d32);
  std::cout << "bf16 depth vs fp32: mean relative difference " << rel.mean().item<double>() << ", max "
            << rel.max().item<double>() << "\n";
  EXPECT_LT(rel.mean().item<double>(), 0.01);
  EXPECT_LT(rel.max().item<double>(), 0.05);
  EXPECT_FALSE(torch::equal(d16, d32));  // it did compute in bfloat16
  const auto K = torch::tensor({100.f, 0.f, 104.f, 0.f, 100.f, 32.f, 0.f, 0.f, 1.f}).view({3, 3});
  const auto f32 = fp32.flow(a, b, K), f16 = bf16.flow(a, b, K);
  EXPECT_LT((f16 - f32).abs().mean().item<double>(), 0.05);  // pixels
  EXPECT_LT((bf16.relative_pose(a, b) - fp32.relative_pose(a, b)).abs().max().item<double>(), 1e-3);
  o.precision = "auto";
  EXPECT_EQ(Model::load(checkpoint(), o).spec().precision, cpu_has_fast_bf16() ? "bf16" : "fp32");
  o.precision = "fp16";
  GEO_EXPECT_THROW_WITH(Model::load(checkpoint(), o), "precision 'fp16'", "fp32, bf16, auto");
}

// geo_infer on a folder of frames: per frame depth and disparity, per consecutive pair the flow, and
// the chained trajectory (one pose per frame); a frame of another size in the folder is refused.
TEST(GeoInfer, WritesDepthFlowAndTrajectoryAndRefusesMixedFrameSizes) {
  const auto dir = test::fresh_dir("geo_infer");
  for (int i = 0; i < 3; ++i) write_image(dir + "/frames/00000" + std::to_string(i) + ".png", image(64, 208, 0.1 * i));
  const std::string tool = test::apps_dir() + "/geo_infer --checkpoint " + checkpoint() + " --device cpu --input ";
  ASSERT_EQ(std::system((tool + dir + "/frames --output " + dir + "/out > " + dir + "/log 2>&1").c_str()), 0)
      << test::read_file(dir + "/log");
  for (const char* f : {"000000-depth.png", "000002-disp.png", "000000-flow.png", "000001-flow.png"})
    EXPECT_TRUE(std::filesystem::exists(dir + "/out/" + f)) << f;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out/000002-flow.png"));  // the last frame has no next
  const auto trajectory = read_poses(dir + "/out/trajectory.txt");
  EXPECT_EQ(trajectory.size(0), 3);
  EXPECT_TRUE(torch::allclose(trajectory[0], torch::eye(4, torch::kFloat64)));
  EXPECT_EQ(read_image(dir + "/out/trajectory.png").size(1), 640);
  EXPECT_FALSE(std::filesystem::exists(dir + "/out/disp.avi"));  // a folder: videos on request

  // Videos, a point cloud and the ground truth in the plot; a pose file too short is refused.
  write_poses(dir + "/gt.txt", trajectory);
  ASSERT_EQ(std::system((tool + dir + "/frames --output " + dir + "/out3 --videos --ply 1 --ground-truth " + dir +
                         "/gt.txt > " + dir + "/log 2>&1")
                            .c_str()),
            0)
      << test::read_file(dir + "/log");
  for (const char* f : {"disp.avi", "flow.avi", "000001.ply", "trajectory.png"})
    EXPECT_TRUE(std::filesystem::exists(dir + "/out3/" + f)) << f;
  EXPECT_NE(test::read_file(dir + "/out3/000001.ply").find("element vertex "), std::string::npos);
  write_poses(dir + "/short.txt", trajectory.slice(0, 0, 2));
  EXPECT_NE(std::system((tool + dir + "/frames --output " + dir + "/out4 --ground-truth " + dir + "/short.txt > " +
                         dir + "/log 2>&1")
                            .c_str()),
            0);
  EXPECT_NE(test::read_file(dir + "/log").find(dir + "/short.txt' has 2 poses for 3 frames"), std::string::npos)
      << test::read_file(dir + "/log");
  EXPECT_NE(std::system((tool + dir + "/frames --output " + dir + "/out5 --ply 3 > " + dir + "/log 2>&1").c_str()), 0);
  EXPECT_NE(test::read_file(dir + "/log").find("--ply 3: the input has 3 frames"), std::string::npos);

  // Nothing read is overwritten and nothing stale stays: a used --output needs --force, which clears
  // geo_infer's earlier outputs (a single frame leaves no trajectory of an earlier sequence behind)
  // and nothing else; the input folder is never the output; two frames of one name are refused.
  auto run = [&](const std::string& args) {
    return std::system((test::apps_dir() + "/geo_infer --checkpoint " + checkpoint() + " --device cpu " + args + " > " +
                        dir + "/log 2>&1")
                           .c_str());
  };
  EXPECT_NE(run("--input " + dir + "/frames/000000.png --output " + dir + "/out3"), 0);
  EXPECT_NE(test::read_file(dir + "/log").find("--output '" + dir + "/out3' is not empty (--force"), std::string::npos)
      << test::read_file(dir + "/log");
  // Files of the user's named like geo_infer's outputs stay: --force removes what geo_infer's
  // manifest (geo_infer-outputs.txt) says it wrote, and nothing else.
  for (const char* mine : {"notes.txt", "lidar.ply", "notes-depth.png"})
    test::write_text(dir + "/out3/" + mine, "mine");
  ASSERT_EQ(run("--input " + dir + "/frames/000000.png --output " + dir + "/out3 --force"), 0)
      << test::read_file(dir + "/log");
  for (const char* gone : {"trajectory.txt", "trajectory.png", "disp.avi", "000001.ply", "000001-disp.png"})
    EXPECT_FALSE(std::filesystem::exists(dir + "/out3/" + std::string(gone))) << gone;
  EXPECT_TRUE(std::filesystem::exists(dir + "/out3/000000-disp.png"));
  for (const char* mine : {"notes.txt", "lidar.ply", "notes-depth.png"})
    EXPECT_EQ(test::read_file(dir + "/out3/" + mine), "mine") << mine;
  EXPECT_EQ(test::read_file(dir + "/out3/geo_infer-outputs.txt"), "000000-disp.png\n000000-depth.png\n");
  // An output name that is a file of the user's: refused before anything is removed or written.
  test::write_text(dir + "/mine/trajectory.txt", "my poses");
  EXPECT_NE(run("--input " + dir + "/frames --output " + dir + "/mine --force"), 0);
  EXPECT_NE(test::read_file(dir + "/log").find("holds 'trajectory.txt', which this tool did not write"),
            std::string::npos)
      << test::read_file(dir + "/log");
  EXPECT_EQ(test::read_file(dir + "/mine/trajectory.txt"), "my poses");
  EXPECT_FALSE(std::filesystem::exists(dir + "/mine/000000-disp.png"));
  // The camera rule of every tool: a principal point far outside the frames is refused.
  EXPECT_NE(run("--input " + dir + "/frames --output " + dir + "/out7 --intrinsics 100 100 -500 9000"), 0);
  EXPECT_NE(
      test::read_file(dir + "/log").find("--intrinsics: principal point (-500, 9000) lies outside the 208x64 frame"),
      std::string::npos)
      << test::read_file(dir + "/log");
  // Never among the frames: the input folder, or the folder of a single image.
  EXPECT_NE(run("--input " + dir + "/frames --output " + dir + "/frames/ --force"), 0);
  EXPECT_NE(test::read_file(dir + "/log").find("is the folder the input's frames are read from"), std::string::npos)
      << test::read_file(dir + "/log");
  EXPECT_NE(run("--input " + dir + "/frames/000000.png --output " + dir + "/frames/../frames --force"), 0);
  EXPECT_NE(test::read_file(dir + "/log").find("is the folder the input's frames are read from"), std::string::npos)
      << test::read_file(dir + "/log");
  EXPECT_FALSE(std::filesystem::exists(dir + "/frames/000000-disp.png"));
  std::filesystem::create_directories(dir + "/twins");
  write_image(dir + "/twins/000001.png", image(64, 208, 0.1));
  write_image(dir + "/twins/000001.jpg", image(64, 208, 0.1));
  EXPECT_NE(run("--input " + dir + "/twins --output " + dir + "/out6"), 0);
  EXPECT_NE(test::read_file(dir + "/log")
                .find("'" + dir + "/twins/000001.jpg' and '" + dir + "/twins/000001.png' would write the same outputs"),
            std::string::npos)
      << test::read_file(dir + "/log");

  // int8, calibrated on the input's first frames, with the time of each step; --calibration-frames
  // alone would be ignored: refused.
  ASSERT_EQ(run("--input " + dir + "/frames --output " + dir + "/out_int8 --precision int8 --timing"), 0)
      << test::read_file(dir + "/log");
  EXPECT_NE(test::read_file(dir + "/log").find("int8: calibrated on the first 3 frame(s)"), std::string::npos);
  EXPECT_NE(test::read_file(dir + "/log").find("int8 calibration"), std::string::npos) << test::read_file(dir + "/log");
  EXPECT_TRUE(std::filesystem::exists(dir + "/out_int8/000001-flow.png"));
  EXPECT_NE(run("--input " + dir + "/frames --output " + dir + "/out7 --calibration-frames 2"), 0);
  EXPECT_NE(test::read_file(dir + "/log").find("--calibration-frames calibrates int8: it needs --precision int8"),
            std::string::npos)
      << test::read_file(dir + "/log");

  write_image(dir + "/frames/000003.png", image(32, 104));
  EXPECT_NE(std::system((tool + dir + "/frames --output " + dir + "/out2 > " + dir + "/log 2>&1").c_str()), 0);
  const std::string log = test::read_file(dir + "/log");
  EXPECT_NE(log.find("'" + dir + "/frames/000003.png' is 104x32 but '" + dir + "/frames/000000.png' is 208x64"),
            std::string::npos)
      << log;
}

// geo_infer --refine N: the networks trained on the input first (depth and pose; the FlowNet kept as
// it was), then the outputs of the refined model, which --refine-run keeps as refined.pt. Everything
// that can refuse the run is refused before the training.
TEST(GeoInfer, RefinesOnTheInputFirst) {
  const auto world = test::write_small_world("geo_infer_refine_world", 8, 0, 5);
  const std::string clip = world + "/raw/2011_01_01/2011_01_01_drive_0001_sync/image_02/data";
  ASSERT_TRUE(std::filesystem::is_directory(clip)) << clip;
  const auto dir = test::fresh_dir("geo_infer_refine");
  auto run = [&](const std::string& args) {
    return std::system(
        (test::apps_dir() + "/geo_infer --device cpu --threads 2 " + args + " > " + dir + "/log 2>&1").c_str());
  };
  const std::string source = "--checkpoint " + checkpoint() + " --input " + clip;
  ASSERT_EQ(run(source + " --output " + dir + "/refined --refine 2 --refine-run " + dir + "/run"), 0)
      << test::read_file(dir + "/log");
  EXPECT_NE(test::read_file(dir + "/log")
                .find("stage refine (1/1): training [depth, pose] for 2 iterations from 0, batch 4, lr 0.0001"),
            std::string::npos)
      << test::read_file(dir + "/log");
  EXPECT_NE(
      test::read_file(dir + "/log").find("stage refine: depth held to the weights it starts from (weights.anchor 1"),
      std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(dir + "/run/anchor-refine.pt"));
  const std::string model = dir + "/run/refined.pt";
  ASSERT_TRUE(std::filesystem::exists(model));
  ASSERT_EQ(run("--checkpoint " + model + " --input " + clip + " --output " + dir + "/again"), 0)
      << test::read_file(dir + "/log");
  ASSERT_EQ(run(source + " --output " + dir + "/plain"), 0) << test::read_file(dir + "/log");
  for (const char* f : {"0000000000-depth.png", "0000000007-depth.png", "0000000003-flow.png", "trajectory.txt"}) {
    EXPECT_EQ(test::read_file(dir + "/refined/" + f), test::read_file(dir + "/again/" + f)) << f;
    EXPECT_NE(test::read_file(dir + "/refined/" + f), test::read_file(dir + "/plain/" + f)) << f;
  }
  // Depth and pose trained; the FlowNet is the source's, bit for bit.
  const auto before = CheckpointFile(checkpoint()).networks(), after = CheckpointFile(model).networks();
  auto same = [](const torch::nn::Module& a, const torch::nn::Module& b) {
    const auto pa = a.named_parameters(), pb = b.named_parameters();
    for (const auto& p : pa)
      if (!torch::equal(p.value(), pb[p.key()])) return false;
    return true;
  };
  ASSERT_TRUE(after.flow);
  EXPECT_TRUE(same(*before.flow, *after.flow));
  EXPECT_FALSE(same(*before.depth, *after.depth));
  EXPECT_FALSE(same(*before.pose, *after.pose));
  EXPECT_FALSE(std::filesystem::exists(dir + "/refined/run"));  // the run folder lies where it was told

  // Refused, before any training: no steps, a single image, a clip shorter than a snippet, a
  // used output folder or run folder, --refine-run or --refine-anchor alone, a negative anchor.
  auto refused = [&](const std::string& args, const std::string& message) {
    EXPECT_NE(run(args), 0) << args;
    const auto log = test::read_file(dir + "/log");
    EXPECT_NE(log.find(message), std::string::npos) << log;
    EXPECT_EQ(log.find("training ["), std::string::npos) << log;
  };
  refused(source + " --output " + dir + "/o1 --refine 0", "--refine: Value 0 not in range 1 to 1000000");
  refused("--checkpoint " + checkpoint() + " --input " + clip + "/0000000000.png --output " + dir + "/o1 --refine 2",
          "--refine 2 trains on a clip: '" + clip + "/0000000000.png' is a single image");
  std::filesystem::create_directories(dir + "/two");
  for (const char* f : {"0000000000.png", "0000000001.png"}) std::filesystem::copy(clip + "/" + f, dir + "/two/" + f);
  refused("--checkpoint " + checkpoint() + " --input " + dir + "/two --output " + dir + "/o1 --refine 2",
          "--refine 2: clip '" + dir + "/two' has 2 frames: a training snippet needs 3");
  refused(source + " --output " + dir + "/plain --refine 2 --refine-run " + dir + "/run2",
          "--output '" + dir + "/plain' is not empty");
  EXPECT_FALSE(std::filesystem::exists(dir + "/run2"));
  refused(source + " --output " + dir + "/o1 --refine 2 --refine-run " + dir + "/run",
          "--refine-run '" + dir + "/run' exists and is not an empty folder");
  refused(source + " --output " + dir + "/o1 --refine-run " + dir + "/run3",
          "keeps the run of --refine N: give --refine too");
  refused(source + " --output " + dir + "/o1 --refine-anchor 0.5", "--refine-anchor 0.5 weighs a term of --refine N");
  refused(source + " --output " + dir + "/o1 --refine-anchor 1", "--refine-anchor 1 weighs a term of --refine N");
  refused(source + " --output " + dir + "/o1 --refine 2 --refine-anchor -1", "--refine-anchor: Value -1 not in range");
}

}  // namespace
}  // namespace geo
