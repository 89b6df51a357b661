// int8 inference (models/int8.h): FR on 8-bit features against the float FR, a calibrated DepthNet,
// FlowNet and PoseNet against their float selves, and what is refused.
#include <gtest/gtest.h>

#include "models/conv_bn.h"
#include "models/depth_net.h"
#include "models/flow_net.h"
#include "models/int8.h"
#include "models/pose_net.h"

namespace {

bool has_int8() { return !geo::select_int8_engine().empty(); }

// The error allowed against a network's spread: 10% with 8-bit activations, 15% with 7 (CPUs
// without VNNI, int8_reduced_range: half the levels; seen 12.5% there).
double tolerance() { return geo::int8_reduced_range() ? 0.15 : 0.1; }

// Random BatchNorm statistics and affines, so that folded networks are not the identity's.
void randomize_batchnorm(torch::nn::Module& m) {
  torch::NoGradGuard no_grad;
  for (auto& b : m.named_buffers())
    if (b.key().find("running_var") != std::string::npos) b.value().uniform_(0.5, 2.0);
    else if (b.key().find("running_mean") != std::string::npos) b.value().normal_(0, 0.1);
}

// geo's quantization of a float tensor into NHWC bytes: by hand, and ATen's on random values (no ties).
TEST(Int8, QuantizingToNhwcIsAtensQuantization) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  // scale 0.5, zero point 10: -10 -> -20 + 10 clamped to 0; 1.2 -> 2.4 -> 2 + 10 = 12; 1.3 -> 13;
  // 200 -> 410 clamped to 255; 0 -> 10.
  const auto hand =
      geo::quantize_to_nhwc(torch::tensor({-10.f, 1.2f, 1.3f, 200.f, 0.f, 0.f}).view({1, 2, 1, 3}), 0.5, 10);
  EXPECT_TRUE(hand.is_contiguous(at::MemoryFormat::ChannelsLast));
  EXPECT_TRUE(
      torch::equal(hand.int_repr().contiguous().flatten(), torch::tensor({0, 12, 13, 255, 10, 10}, torch::kUInt8)));
  torch::manual_seed(5);
  const auto x = torch::randn({2, 9, 13, 70}) * 3;  // 9 channels: the PoseNet's snippet
  const auto mine = geo::quantize_to_nhwc(x, 0.037, 117), aten = at::quantize_per_tensor(x, 0.037, 117, torch::kQUInt8);
  EXPECT_EQ(mine.q_scale(), 0.037);
  EXPECT_EQ(mine.q_zero_point(), 117);
  EXPECT_TRUE(torch::equal(mine.int_repr().contiguous(), aten.int_repr().contiguous()));
}

// Weights per output channel: ATen's quantization with max|w_c| / 127 scales, exactly (random
// kernels, a zero channel, a 1x1 kernel, a float16 one).
TEST(Int8, WeightsQuantizePerChannelAsAten) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(8);
  auto w = torch::randn({17, 9, 3, 3}) * torch::rand({17, 1, 1, 1}) * 4;
  w[3].zero_();
  for (const auto& k : {w, torch::randn({5, 64, 1, 1}), torch::randn({6, 4, 7, 7}).to(torch::kHalf)}) {
    const auto mine = geo::quantize_weight_per_channel(k);
    const auto f = k.to(torch::kFloat32);
    const auto scales = (f.abs().amax({1, 2, 3}) / 127.0).clamp_min(1e-12).to(torch::kFloat64);
    const auto aten = at::quantize_per_channel(f, scales, torch::zeros({f.size(0)}, torch::kLong), 0, torch::kQInt8);
    EXPECT_TRUE(torch::equal(mine.q_per_channel_scales(), aten.q_per_channel_scales()));
    EXPECT_TRUE(torch::equal(mine.q_per_channel_zero_points(), aten.q_per_channel_zero_points()));
    EXPECT_TRUE(torch::equal(mine.int_repr(), aten.int_repr())) << k.sizes();
    EXPECT_EQ(mine.q_per_channel_axis(), 0);
  }
  // With a per-channel factor (BatchNorm's folding): the bytes and scales of quantizing the product
  // made in float32, though the product is never made.
  const auto factor = torch::rand({17}) * 3 - 1;
  factor[5] = 0;
  const auto folded = w * factor.view({-1, 1, 1, 1});
  const auto mine = geo::quantize_weight_per_channel(w, factor), product = geo::quantize_weight_per_channel(folded);
  EXPECT_TRUE(torch::equal(mine.q_per_channel_scales(), product.q_per_channel_scales()));
  EXPECT_TRUE(torch::equal(mine.int_repr(), product.int_repr()));
  const auto scales = (folded.abs().amax({1, 2, 3}) / 127.0).clamp_min(1e-12).to(torch::kFloat64);
  EXPECT_TRUE(torch::equal(
      mine.int_repr(),
      at::quantize_per_channel(folded, scales, torch::zeros({17}, torch::kLong), 0, torch::kQInt8).int_repr()));
  EXPECT_THROW(geo::quantize_weight_per_channel(w, torch::ones({16})), c10::Error);
}

// Concatenation with requantization: the float concatenation of the dequantized parts, quantized
// with the output's scale, within one step (rounding), and a part of the output's own scale copied.
TEST(Int8, ConcatenatingRequantizesEachPart) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(6);
  const auto a = geo::quantize_to_nhwc(torch::rand({2, 32, 5, 7}) * 4, 4.0 / 255, 0);
  const auto b = geo::quantize_to_nhwc(torch::randn({2, 17, 5, 7}), 0.02, 128);
  const auto c = geo::quantize_to_nhwc(torch::randn({2, 1, 5, 7}) * 3, 0.05, 100);
  const auto mine = geo::cat_int8({a, b, c}, 0.05, 100);
  ASSERT_EQ(mine.sizes(), torch::IntArrayRef({2, 50, 5, 7}));
  EXPECT_TRUE(mine.is_contiguous(at::MemoryFormat::ChannelsLast));
  const auto reference = at::quantize_per_tensor(torch::cat({a.dequantize(), b.dequantize(), c.dequantize()}, 1), 0.05,
                                                 100, torch::kQUInt8);
  const auto diff = (mine.int_repr().to(torch::kInt32) - reference.int_repr().to(torch::kInt32)).abs();
  EXPECT_LE(diff.max().item<int>(), 1);
  EXPECT_LT(diff.to(torch::kFloat32).mean().item<double>(), 0.02);
  EXPECT_TRUE(torch::equal(mine.int_repr().narrow(1, 49, 1), c.int_repr()));  // the same scale: copied
}

TEST(Int8, FeatureRefinementIsTheFloatOneWithinOneStep) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(3);
  geo::FeatureRefinement fr(geo::FeatureRefinementOptions(32));
  fr->eval();
  torch::NoGradGuard no_grad;
  for (const int64_t zero_point : {0, 17}) {
    const auto x = torch::rand({2, 32, 5, 7}) * 3;
    const auto q =
        at::quantize_per_tensor(x.contiguous(at::MemoryFormat::ChannelsLast), 0.02, zero_point, torch::kQUInt8);
    const double out_scale = 0.015;
    const auto mine = geo::int8_feature_refinement(*fr, q, out_scale, 3);
    EXPECT_EQ(mine.q_scale(), out_scale);
    EXPECT_EQ(mine.q_zero_point(), 3);
    // The float FR of the same 8-bit values, quantized as the int8 one is.
    const auto expected = at::quantize_per_tensor(fr(q.dequantize()), out_scale, 3, torch::kQUInt8);
    const auto diff = (mine.int_repr().to(torch::kInt) - expected.int_repr().to(torch::kInt)).abs();
    EXPECT_LE(diff.max().item<int>(), 1) << "zero point " << zero_point;  // rounding of float sums
    EXPECT_LT(diff.to(torch::kFloat).mean().item<float>(), 0.05) << "zero point " << zero_point;
  }
}

// DepthNet (ResNet-18 with FR, as the tests train it): calibrated on 4 images, then run in int8 on
// 2 others. Observing computes what the float network computes; int8 follows it.
TEST(Int8, CalibratedDepthNetFollowsTheFloatOne) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(5);
  geo::DepthNetOptions o;
  o.encoder_depth = 18;
  geo::DepthNet net(o);
  randomize_batchnorm(*net);
  net->eval();
  geo::fold_batchnorm(*net);
  torch::NoGradGuard no_grad;
  const auto images = torch::rand({6, 3, 64, 96});
  const auto reference = net(images.narrow(0, 4, 2)).disp;

  geo::observe_int8(*net->net);
  const auto observed = net(images.narrow(0, 0, 4)).disp;
  const auto plain = net->net->int8;
  EXPECT_FALSE(plain->quantized());
  // Points: input, conv1, 8 blocks (ResNet-18: 2 convs + sum, 7 of them with a projection: all but
  // the first, GeoNet putting the stride in the last block of a stage), 4 encoder FRs;
  // 6 decoder stages (upconv, concatenation, iconv, FR), 3 upsampled predictions, 4 predictions.
  EXPECT_EQ(plain->points(), 1 + 1 + (8 * 3 + 7) + 4 + 6 * 4 + 3 + 4);
  net->net->int8.reset();
  const auto again = net(images.narrow(0, 0, 4)).disp;
  // One graph (models/graph.h) for both: observing computes exactly the float forward.
  for (size_t s = 0; s < 4; ++s) EXPECT_TRUE(torch::equal(observed[s], again[s])) << s;

  net->net->int8 = plain;
  geo::quantize_int8(*net->net);
  EXPECT_TRUE(plain->quantized());
  const auto int8 = net(images.narrow(0, 4, 2)).disp;
  for (size_t s = 0; s < 4; ++s) {
    ASSERT_EQ(int8[s].sizes(), reference[s].sizes());
    EXPECT_EQ(int8[s].scalar_type(), torch::kFloat32);
    // Disparity's spread across pixels is what depth is made of: int8's error against it.
    const double spread = (reference[s] - reference[s].mean()).abs().mean().item<double>();
    const double error = (int8[s] - reference[s]).abs().mean().item<double>();
    EXPECT_LT(error, tolerance() * spread) << "scale " << s << ": error " << error << ", spread " << spread;
  }
  // Inference only: quantized from its ranges letting every float kernel go (each layer and head
  // runs in int8), the same outputs.
  const auto ranges = plain->ranges();
  net->net->int8.reset();
  geo::quantize_int8(*net->net, ranges, 64, 96, /*release_float=*/true);
  for (const auto& m : net->modules()) {
    if (const auto* cb = m->as<geo::ConvBnImpl>()) {
      EXPECT_EQ(cb->conv->weight.numel(), 0);
    }
  }
  for (const auto& p : net->net->pred) EXPECT_EQ(p->weight.numel(), 0);
  const auto released = net(images.narrow(0, 4, 2)).disp;
  for (size_t s = 0; s < 4; ++s) EXPECT_TRUE(torch::equal(released[s], int8[s])) << s;
}

TEST(Int8, FlowNetFollowsTheFloatOne) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(8);
  geo::FlowNetOptions o;
  o.backbone.encoder_depth = 18;
  o.backbone.use_fr = false;
  o.zero_init_residual = false;
  geo::FlowNet net(o);
  randomize_batchnorm(*net);
  net->eval();
  geo::fold_batchnorm(*net);
  torch::NoGradGuard no_grad;
  const auto inputs = torch::rand({4, 12, 32, 64}) * 2 - 1;
  const auto reference = net(inputs.narrow(0, 3, 1)).flow;
  geo::observe_int8(*net->net);
  net(inputs.narrow(0, 0, 3));
  geo::quantize_int8(*net->net);
  const auto int8 = net(inputs.narrow(0, 3, 1)).flow;
  for (size_t s = 0; s < 4; ++s) {
    const double spread = (reference[s] - reference[s].mean()).abs().mean().item<double>();
    const double error = (int8[s] - reference[s]).abs().mean().item<double>();
    EXPECT_LT(error, tolerance() * spread) << "scale " << s << ": error " << error << ", spread " << spread;
  }
}

// PoseNet (with the learned camera): conv1..conv6 in int8 (7 points: the snippet and each of their
// outputs), conv7 and the pose and camera heads in float on the dequantized features.
TEST(Int8, PoseNetFollowsTheFloatOne) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(9);
  geo::PoseNetOptions o;
  o.learn_intrinsics = true;
  geo::PoseNet net(o);
  randomize_batchnorm(*net);
  {  // a camera head of its own (it starts at zero)
    torch::NoGradGuard no_grad;
    net->intrinsics->weight.normal_(0, 0.05);
  }
  net->eval();
  geo::fold_batchnorm(*net);
  torch::NoGradGuard no_grad;
  const auto frames = torch::rand({6, 3, 3, 64, 128});  // snippet, frame, RGB, H, W
  auto snippet = [&](int64_t i) {
    return std::make_pair(frames[i][1].unsqueeze(0),
                          std::vector<torch::Tensor>{frames[i][0].unsqueeze(0), frames[i][2].unsqueeze(0)});
  };
  std::vector<geo::PoseOutput> reference;
  for (int64_t i = 4; i < 6; ++i) reference.push_back(net->predict(snippet(i).first, snippet(i).second));
  geo::observe_int8(*net);
  for (int64_t i = 0; i < 4; ++i) net->predict(snippet(i).first, snippet(i).second);
  // Observing is the float forward.
  EXPECT_TRUE(torch::allclose(net->predict(snippet(4).first, snippet(4).second).poses, reference[0].poses));
  geo::quantize_int8(*net);
  EXPECT_EQ(net->int8->points(), 7);
  const auto spread = torch::cat({reference[0].poses, reference[1].poses}).std().item<double>();
  for (int64_t i = 4; i < 6; ++i) {
    const auto got = net->predict(snippet(i).first, snippet(i).second);
    const auto& want = reference[static_cast<size_t>(i - 4)];
    const double error = (got.poses - want.poses).abs().mean().item<double>();
    EXPECT_LT(error, 0.05 * spread) << "snippet " << i << ": error " << error << ", spread " << spread;
    EXPECT_TRUE(torch::allclose(got.K, want.K, 0.02)) << got.K << want.K;
  }
  // A file's ranges give the same network back.
  const auto ranges = net->int8->ranges();
  const auto before = net->predict(snippet(5).first, snippet(5).second).poses;
  net->int8.reset();
  geo::quantize_int8(*net, ranges, 64, 128);
  EXPECT_TRUE(torch::equal(net->predict(snippet(5).first, snippet(5).second).poses, before));
  const auto kept = net->int8;
  EXPECT_THROW(geo::quantize_int8(*net, ranges.narrow(0, 0, 6), 64, 128), c10::Error);
  EXPECT_EQ(net->int8, kept);  // a refused calibration changes nothing
  net->int8.reset();
  try {
    geo::quantize_int8(*net, torch::cat({ranges, ranges.narrow(0, 0, 1)}), 64, 128, /*release_float=*/true);
    ADD_FAILURE() << "8 ranges taken for a network of 7 points";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("8 calibrated ranges for a network of 7 quantized points"), std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(net->int8);  // ... and leaves the float network as it was
  EXPECT_FALSE(net->convs[0]->float_kernel_released());
  // Inference only: conv1-conv6's float kernels go, conv7 (run in float) and the heads keep theirs;
  // the same poses and camera bit for bit, and a released layer refuses to run in float.
  geo::quantize_int8(*net, ranges, 64, 128);
  const auto K = net->predict(snippet(5).first, snippet(5).second).K;
  net->int8.reset();
  geo::quantize_int8(*net, ranges, 64, 128, /*release_float=*/true);
  for (size_t i = 0; i + 1 < net->convs.size(); ++i) {
    EXPECT_TRUE(net->convs[i]->float_kernel_released()) << "conv" << i + 1;
    EXPECT_EQ(net->convs[i]->conv->weight.numel(), 0) << "conv" << i + 1;
  }
  EXPECT_FALSE(net->convs.back()->float_kernel_released());
  EXPECT_EQ(net->convs.back()->conv->weight.numel(), 256 * 256 * 9);
  EXPECT_GT(net->pred->weight.numel(), 0);
  EXPECT_TRUE(torch::equal(net->predict(snippet(5).first, snippet(5).second).poses, before));
  EXPECT_TRUE(torch::equal(net->predict(snippet(5).first, snippet(5).second).K, K));
  try {
    net->convs[0]->forward(torch::rand({1, 9, 64, 128}));
    ADD_FAILURE() << "a released layer ran in float";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("let go for int8-only inference"), std::string::npos) << e.what();
  }
  // Its int8 kernels (what an int8 model file keeps): conv1..conv6, each an int8 weight of its
  // layer's shape with a scale per output channel and the folded bias; given back to a network
  // without float kernels, the same poses bit for bit. Kernels missing, of another shape or type,
  // or of no layer are refused naming them, the network left as it was.
  const auto kernels = net->int8->kernels();
  EXPECT_EQ(kernels.size(), 6u * 3u);
  EXPECT_EQ(kernels.at("conv1.weight").scalar_type(), torch::kInt8);
  EXPECT_EQ(kernels.at("conv1.weight").sizes(), torch::IntArrayRef({16, 9, 7, 7}));
  EXPECT_EQ(kernels.at("conv6.scales").scalar_type(), torch::kFloat64);
  net->int8.reset();  // (its float kernels are gone: only the given ones can make it int8 again)
  geo::quantize_int8(*net, ranges, 64, 128, true, kernels);
  EXPECT_TRUE(torch::equal(net->predict(snippet(5).first, snippet(5).second).poses, before));
  const auto refused = [&](std::map<std::string, torch::Tensor> given, const std::string& why) {
    net->int8.reset();
    try {
      geo::quantize_int8(*net, ranges, 64, 128, true, given);
      ADD_FAILURE() << "taken: " << why;
    } catch (const c10::Error& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
    EXPECT_FALSE(net->int8);
  };
  auto missing = kernels;
  missing.erase("conv3.scales");
  refused(missing, "no kernel 'conv3.scales' for the network's layer 'conv3'");
  auto extra = kernels;
  extra["conv7.weight"] = kernels.at("conv6.weight");
  refused(extra, "kernels for no layer of the network: conv7.weight");
  auto reshaped = kernels;
  reshaped["conv2.weight"] = kernels.at("conv2.weight").flatten();
  refused(reshaped, "kernel 'conv2.weight' is Char [");
  auto in_float = kernels;
  in_float["conv2.weight"] = kernels.at("conv2.weight").to(torch::kFloat32);
  refused(in_float, "kernel 'conv2.weight' is Float");
  auto zero_scale = kernels;
  zero_scale["conv4.scales"] = torch::zeros_like(kernels.at("conv4.scales"));
  refused(zero_scale, "'conv4.scales' must be");
}

TEST(Int8, QuantizingNeedsCalibrationAFoldedNetworkAndInference) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  geo::DepthNetOptions o;
  o.encoder_depth = 18;
  o.use_fr = false;
  geo::DepthNet net(o);
  net->eval();
  EXPECT_THROW(geo::quantize_int8(*net->net), c10::Error);  // not observed
  geo::observe_int8(*net->net);
  EXPECT_THROW(geo::quantize_int8(*net->net), c10::Error);  // observed nothing
  torch::NoGradGuard no_grad;
  net(torch::rand({1, 3, 32, 64}));
  EXPECT_THROW(geo::quantize_int8(*net->net), c10::Error);  // BatchNorm not folded
  net->train();
  EXPECT_THROW(net(torch::rand({1, 3, 32, 64})), c10::Error);  // int8 is for inference
}

}  // namespace

// int8 at every size a model may have (multiples of 8 from 16, odd multiples and shapes taller than
// wide included) and on every calibration a user may give (1-3 frames, random, black or constant grey):
// the DepthNet with FR, the FlowNet with FR and the PoseNet with its camera, calibrated, run, then
// quantized again from their ranges as a model file does. Outputs are finite and of the float
// network's shapes; scripts/fuzz.sh runs this under AddressSanitizer and UBSan, where any memory
// error fails it.
TEST(Int8, EverySizeAndCalibrationIsMemorySafe) {
  if (!has_int8()) GTEST_SKIP() << "this LibTorch has no quantized engine";
  torch::manual_seed(11);
  geo::DepthNetOptions d;
  d.encoder_depth = 18;
  geo::DepthNet depth(d);
  geo::FlowNetOptions f;
  f.backbone.encoder_depth = 18;
  f.zero_init_residual = false;
  geo::FlowNet flow(f);
  geo::PoseNetOptions p;
  p.learn_intrinsics = true;
  geo::PoseNet pose(p);
  for (torch::nn::Module* m :
       {static_cast<torch::nn::Module*>(depth.get()), static_cast<torch::nn::Module*>(flow.get()),
        static_cast<torch::nn::Module*>(pose.get())}) {
    randomize_batchnorm(*m);
    m->eval();
    geo::fold_batchnorm(*m);
  }
  torch::NoGradGuard no_grad;
  const std::vector<std::pair<int64_t, int64_t>> sizes = {{16, 16}, {24, 40}, {32, 96}, {40, 24}, {33, 97}};
  for (const auto& [H, W] : sizes) {
    const std::vector<torch::Tensor> calibrations = {torch::rand({1, 3, 3, H, W}), torch::zeros({2, 3, 3, H, W}),
                                                     torch::full({3, 3, 3, H, W}, 0.5)};
    for (size_t k = 0; k < calibrations.size(); ++k) {
      SCOPED_TRACE(std::to_string(H) + "x" + std::to_string(W) + ", calibration " + std::to_string(k));
      const auto& frames = calibrations[k];  // [N, frame, RGB, H, W]
      const auto test = torch::rand({2, 3, 3, H, W});
      auto finite = [](const std::vector<torch::Tensor>& out, const std::vector<torch::Tensor>& want) {
        ASSERT_EQ(out.size(), want.size());
        for (size_t s = 0; s < out.size(); ++s) {
          EXPECT_EQ(out[s].sizes(), want[s].sizes()) << s;
          EXPECT_TRUE(torch::isfinite(out[s]).all().item<bool>()) << s;
        }
      };
      // DepthNet on the middle frames.
      depth->net->int8.reset();
      const auto depth_want = depth(test.select(1, 1)).disp;
      geo::observe_int8(*depth->net);
      depth(frames.select(1, 1));
      geo::quantize_int8(*depth->net);
      finite(depth(test.select(1, 1)).disp, depth_want);
      const auto depth_ranges = depth->net->int8->ranges();
      depth->net->int8.reset();
      geo::quantize_int8(*depth->net, depth_ranges, H, W);
      finite(depth(test.select(1, 1)).disp, depth_want);
      // FlowNet on 12 channels built from the frames (what the pipeline stacks, in [-1, 1]).
      auto flow_in = [](const torch::Tensor& s) {
        return torch::cat({s.select(1, 1), s.select(1, 2), s.select(1, 0), s.select(1, 1).narrow(1, 0, 3)}, 1) * 2 - 1;
      };
      flow->net->int8.reset();
      const auto flow_want = flow(flow_in(test)).flow;
      geo::observe_int8(*flow->net);
      flow(flow_in(frames));
      geo::quantize_int8(*flow->net);
      finite(flow(flow_in(test)).flow, flow_want);
      // PoseNet on the snippets.
      pose->int8.reset();
      auto snippet = [](const torch::Tensor& s) {
        return std::make_pair(s.select(1, 1), std::vector<torch::Tensor>{s.select(1, 0), s.select(1, 2)});
      };
      const auto pose_want = pose->predict(snippet(test).first, snippet(test).second);
      geo::observe_int8(*pose);
      pose->predict(snippet(frames).first, snippet(frames).second);
      geo::quantize_int8(*pose);
      const auto got = pose->predict(snippet(test).first, snippet(test).second);
      finite({got.poses, got.K}, {pose_want.poses, pose_want.K});
      const auto pose_ranges = pose->int8->ranges();
      pose->int8.reset();
      geo::quantize_int8(*pose, pose_ranges, H, W);
      const auto again = pose->predict(snippet(test).first, snippet(test).second);
      finite({again.poses, again.K}, {pose_want.poses, pose_want.K});
    }
  }
}
