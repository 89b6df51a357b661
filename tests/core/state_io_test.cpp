#include "core/state_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace {

struct TinyImpl : torch::nn::Module {
  explicit TinyImpl(int hidden) {
    fc1 = register_module("fc1", torch::nn::Linear(3, hidden));
    bn = register_module("bn", torch::nn::BatchNorm1d(hidden));
  }
  torch::Tensor forward(torch::Tensor x) { return bn(fc1(x)); }
  torch::nn::Linear fc1{nullptr};
  torch::nn::BatchNorm1d bn{nullptr};
};
TORCH_MODULE(Tiny);

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("geo_state_io_" + name)).string();
}

TEST(StateIo, SaveLoadGivesIdenticalOutputs) {
  torch::manual_seed(1);
  Tiny a(4), b(4);
  a->train();
  a->forward(torch::randn({8, 3}));  // moves BN running stats away from their init
  a->eval();
  b->eval();
  const auto path = temp_path("ok.pt");
  geo::save_state(*a, path);
  geo::load_state(*b, path);
  const auto x = torch::randn({5, 3});
  EXPECT_TRUE(torch::equal(a->forward(x), b->forward(x)));
  EXPECT_TRUE(torch::equal(a->bn->running_mean, b->bn->running_mean));
  std::filesystem::remove(path);
}

TEST(StateIo, MismatchListsOffendingKeysAndLoadsNothing) {
  Tiny a(4), wider(5);
  const auto path = temp_path("mismatch.pt");
  geo::save_state(*a, path);
  const auto before = wider->fc1->weight.clone();
  try {
    geo::load_state(*wider, path);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("shape mismatches"), std::string::npos) << msg;
    EXPECT_NE(msg.find("fc1.weight"), std::string::npos) << msg;
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
  }
  EXPECT_TRUE(torch::equal(before, wider->fc1->weight));

  torch::nn::Linear other(3, 4);  // keys "weight", "bias": all unexpected; fc1.* missing
  const auto path2 = temp_path("other.pt");
  geo::save_state(*other, path2);
  try {
    geo::load_state(*a, path2);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("missing keys: bn.bias"), std::string::npos) << msg;
    EXPECT_NE(msg.find("unexpected keys: bias, weight"), std::string::npos) << msg;
  }
  std::filesystem::remove(path);
  std::filesystem::remove(path2);
}

TEST(StateIo, MissingAndCorruptFilesAreNamed) {
  Tiny a(4);
  EXPECT_THROW(
      {
        try {
          geo::load_state(*a, "/nonexistent/x.pt");
        } catch (const std::runtime_error& e) {
          EXPECT_NE(std::string(e.what()).find("/nonexistent/x.pt: no such file"),
                    std::string::npos);
          throw;
        }
      },
      std::runtime_error);
  const auto path = temp_path("corrupt.pt");
  { std::ofstream(path) << "not a state file"; }
  EXPECT_THROW(geo::load_state(*a, path), std::runtime_error);
  std::filesystem::remove(path);
}

}  // namespace
