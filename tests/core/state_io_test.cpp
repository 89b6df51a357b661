#include "core/state_io.h"
#include "core/zip_check.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <vector>

#include "test_util.h"

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
          EXPECT_NE(std::string(e.what()).find("/nonexistent/x.pt: no such file"), std::string::npos);
          throw;
        }
      },
      std::runtime_error);
  // NaN weights (a diverged run, saved with valid CRCs) are refused by key, and nothing is loaded.
  {
    Tiny nan_net(4);
    {
      torch::NoGradGuard no_grad;
      nan_net->fc1->bias[1] = std::nan("");
    }
    const auto nan_path = temp_path("nan.pt");
    geo::save_state(*nan_net, nan_path);
    Tiny c(4);
    const auto before = c->fc1->weight.clone();
    GEO_EXPECT_THROW_WITH(geo::load_state(*c, nan_path), "holds NaN or infinite values in fc1.bias",
                          "nothing was loaded");
    EXPECT_TRUE(torch::equal(before, c->fc1->weight));
    std::filesystem::remove(nan_path);
  }
  // A device or a folder given as a model is named as such, never read (/dev/zero has no end).
  GEO_EXPECT_THROW_WITH(geo::load_state(*a, "/dev/zero"), "/dev/zero: is a device, not a file");
  GEO_EXPECT_THROW_WITH(geo::load_state(*a, "/tmp"), "/tmp: is a folder, not a file");
  const auto path = temp_path("corrupt.pt");
  { std::ofstream(path) << "not a state file"; }
  EXPECT_THROW(geo::load_state(*a, path), std::runtime_error);
  std::filesystem::remove(path);
}

// ZIP's CRC-32 against its published check values (the 8-byte loop and the byte tail both run on
// the 43-byte sentence), and continued over pieces as over the whole.
TEST(StateIo, Crc32HasZipsCheckValues) {
  EXPECT_EQ(geo::crc32("123456789", 9), 0xCBF43926u);
  const std::string fox = "The quick brown fox jumps over the lazy dog";
  EXPECT_EQ(geo::crc32(fox.data(), fox.size()), 0x414FA339u);
  EXPECT_EQ(geo::crc32(fox.data() + 10, fox.size() - 10, geo::crc32(fox.data(), 10)), 0x414FA339u);
  EXPECT_EQ(geo::crc32("", 0), 0u);
}

// The CRC-32 of long buffers (where the carry-less-multiply folding runs on x86-64) against its
// definition, one bit at a time: every length from 0 to 300 bytes at three alignments, continued from
// a random register, and continued over pieces of odd sizes as over the whole.
TEST(StateIo, Crc32OfLongBuffersIsItsBitwiseDefinition) {
  const auto bitwise = [](const unsigned char* p, size_t n, uint32_t crc) {
    crc = ~crc;
    for (size_t i = 0; i < n; ++i) {
      crc ^= p[i];
      for (int k = 0; k < 8; ++k) crc = (crc & 1) ? 0xEDB88320u ^ (crc >> 1) : crc >> 1;
    }
    return ~crc;
  };
  std::mt19937 random(7);
  std::vector<unsigned char> bytes(70000);
  for (auto& b : bytes) b = static_cast<unsigned char>(random());
  for (size_t n = 0; n <= 300; ++n)
    for (size_t offset = 0; offset < 3; ++offset) {
      const uint32_t start = random();
      ASSERT_EQ(geo::crc32(bytes.data() + offset, n, start), bitwise(bytes.data() + offset, n, start))
          << n << " bytes at offset " << offset;
    }
  const uint32_t whole = bitwise(bytes.data(), bytes.size(), 0);
  EXPECT_EQ(geo::crc32(bytes.data(), bytes.size()), whole);
  uint32_t pieces = 0;
  for (size_t at = 0, n = 1; at < bytes.size(); at += n, n = n * 3 + 1)
    pieces = geo::crc32(bytes.data() + at, std::min(n, bytes.size() - at), pieces);
  EXPECT_EQ(pieces, whole);
}

// One byte altered inside a tensor: LibTorch would load it (its reader skips the CRCs); geo refuses
// it, naming the file and the record. The intact file still loads and checks.
TEST(StateIo, AFileAlteredInsideATensorIsRefused) {
  Tiny a(4);
  {
    torch::NoGradGuard no_grad;
    a->fc1->weight.fill_(1234.5f);
  }
  const auto path = temp_path("altered.pt");
  geo::save_state(*a, path);
  EXPECT_TRUE(geo::verify_zip_checksums(path));
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const float value = 1234.5f;
  const auto at = bytes.find(std::string(reinterpret_cast<const char*>(&value), sizeof value));
  ASSERT_NE(at, std::string::npos);
  bytes[at + 1] = static_cast<char>(bytes[at + 1] ^ 0x01);  // 1234.5 -> 1234.5 +- a few ulps
  { std::ofstream(path, std::ios::binary) << bytes; }
  Tiny b(4);
  try {
    geo::load_state(*b, path);
    ADD_FAILURE() << "an altered file loaded";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path + ": damaged file"), std::string::npos) << msg;
    EXPECT_NE(msg.find("fails its CRC-32 check"), std::string::npos) << msg;
  }
  std::filesystem::remove(path);
}

// LibTorch deflates its code/ records, and its reader checks no CRC of them either: a byte altered
// in one is found after inflating it, naming the file and the record.
TEST(StateIo, AnAlteredCompressedRecordIsRefused) {
  Tiny a(4);
  const auto path = temp_path("deflated.pt");
  geo::save_state(*a, path);
  EXPECT_TRUE(geo::verify_zip_checksums(path));  // the intact file, its compressed records included
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // The first compressed record (method 8) of the central directory; its data after the local
  // header's name and extra field (LibTorch's local headers leave the sizes to a data descriptor).
  const auto u16 = [&](size_t at) {
    return static_cast<size_t>(static_cast<unsigned char>(bytes[at])) |
           static_cast<size_t>(static_cast<unsigned char>(bytes[at + 1])) << 8;
  };
  const auto u32 = [&](size_t at) { return u16(at) | u16(at + 2) << 16; };
  size_t entry = 0;
  for (entry = bytes.find("PK\x01\x02"); entry != std::string::npos; entry = bytes.find("PK\x01\x02", entry + 4))
    if (u16(entry + 10) == 8) break;
  ASSERT_NE(entry, std::string::npos) << "no compressed record in a LibTorch archive";
  const std::string name = bytes.substr(entry + 46, u16(entry + 28));
  const size_t local = u32(entry + 42), size = u32(entry + 20);
  const size_t data = local + 30 + u16(local + 26) + u16(local + 28);
  ASSERT_GT(size, 4u);
  bytes[data + size / 2] = static_cast<char>(bytes[data + size / 2] ^ 0x10);
  { std::ofstream(path, std::ios::binary) << bytes; }
  GEO_EXPECT_THROW_WITH(geo::verify_zip_checksums(path), path + ": damaged file", "record '" + name + "'");
  Tiny b(4);
  GEO_EXPECT_THROW_WITH(geo::load_state(*b, path), path + ": damaged file", "record '" + name + "'");
  std::filesystem::remove(path);
}

}  // namespace
