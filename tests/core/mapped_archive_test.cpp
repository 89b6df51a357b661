// An archive with tensors read where they lie in the file (core/mapped_archive.h): the round trip,
// views of the file's own pages (the mapping lives as long as a tensor does), which files are such
// containers, and damaged or malformed ones refused naming the file and the record.
#include "core/mapped_archive.h"
#include "core/state_io.h"

#include <caffe2/serialize/inline_container.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "test_util.h"

namespace geo {
namespace {

// Whether this process maps `path` (/proc/self/maps names mapped files).
bool maps_file(const std::string& path) {
  std::ifstream maps("/proc/self/maps");
  const std::string canonical = std::filesystem::canonical(path).string();
  for (std::string line; std::getline(maps, line);)
    if (line.size() >= canonical.size() &&
        line.compare(line.size() - canonical.size(), canonical.size(), canonical) == 0)
      return true;
  return false;
}

std::map<std::string, torch::Tensor> some_tensors() {
  torch::manual_seed(3);
  return {{"k/a.weight", torch::randint(-127, 128, {3, 2, 3, 3}, torch::kInt8)},
          {"k/a.scales", torch::rand({3}, torch::kFloat64) + 0.1},
          {"k/a.bias", torch::randn({3})},
          {"k/empty", torch::zeros({0, 4})},
          {"scalar", torch::tensor(7, torch::kLong).reshape({})},
          {"strided", torch::arange(12, torch::kFloat32).reshape({3, 4}).t()}};  // stored contiguous
}

TEST(MappedArchive, RoundTripViewsTheFilesOwnPages) {
  const auto dir = test::fresh_dir("mapped_archive");
  const std::string path = dir + "/m.pt";
  const auto tensors = some_tensors();
  {
    torch::serialize::OutputArchive a;
    a.write("answer", c10::IValue(int64_t{42}));
    a.write("small", torch::ones({2}));
    save_archive_with_mapped(a, tensors, path);
  }
  EXPECT_TRUE(has_mapped_tensors(path));
  torch::Tensor kept;
  {
    auto opened = open_mapped_archive(path);
    c10::IValue answer;
    ASSERT_TRUE(opened.archive.try_read("answer", answer));
    EXPECT_EQ(answer.toInt(), 42);
    torch::Tensor small;
    opened.archive.read("small", small);
    EXPECT_TRUE(torch::equal(small, torch::ones({2})));
    ASSERT_EQ(opened.tensors.by_name.size(), tensors.size());
    for (const auto& [name, t] : tensors) {
      const auto& back = opened.tensors.by_name.at(name);
      EXPECT_EQ(back.scalar_type(), t.scalar_type()) << name;
      EXPECT_EQ(back.sizes(), t.sizes()) << name;
      EXPECT_TRUE(torch::equal(back, t)) << name;
    }
    const auto under = opened.tensors.under("k/");
    EXPECT_EQ(under.size(), 4u);
    EXPECT_TRUE(torch::equal(under.at("a.weight"), tensors.at("k/a.weight")));
    EXPECT_EQ(under.count("scalar"), 0u);
    EXPECT_TRUE(maps_file(path));
    kept = under.at("a.scales");
  }
  // One tensor still viewing it keeps the file mapped; the last one gone unmaps it.
  EXPECT_TRUE(maps_file(path));
  EXPECT_TRUE(torch::equal(kept, tensors.at("k/a.scales")));
  kept = torch::Tensor();
  EXPECT_FALSE(maps_file(path));
}

TEST(MappedArchive, PlainArchivesAndOtherFilesAreNoContainers) {
  const auto dir = test::fresh_dir("mapped_archive_other");
  torch::serialize::OutputArchive a;
  a.write("x", torch::ones({2}));
  save_archive(a, dir + "/plain.pt");
  EXPECT_FALSE(has_mapped_tensors(dir + "/plain.pt"));
  test::write_text(dir + "/text.pt", "not an archive");
  EXPECT_FALSE(has_mapped_tensors(dir + "/text.pt"));
  EXPECT_FALSE(has_mapped_tensors(dir));
  EXPECT_FALSE(has_mapped_tensors(dir + "/missing.pt"));
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/plain.pt"), "plain.pt: no record 'geo_archive.pt'");
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/missing.pt"), "missing.pt");
}

// A container written by hand: the archive, then `index` as its index and `records` beside it.
void write_container(const std::string& path, const std::string& index,
                     const std::map<std::string, std::string>& records) {
  torch::serialize::OutputArchive a;
  a.write("x", torch::ones({1}));
  std::string bytes;
  a.save_to([&](const void* d, size_t n) {
    bytes.append(static_cast<const char*>(d), n);
    return n;
  });
  caffe2::serialize::PyTorchStreamWriter w(path);
  w.writeRecord("geo_archive.pt", bytes.data(), bytes.size());
  w.writeRecord("mapped.index", index.data(), index.size());
  for (const auto& [name, data] : records) w.writeRecord("mapped/" + name, data.data(), data.size());
  w.writeEndOfFile();
}

TEST(MappedArchive, DamagedOrMalformedContainersAreRefusedNamingFileAndRecord) {
  const auto dir = test::fresh_dir("mapped_archive_damaged");
  const std::string path = dir + "/m.pt";
  torch::serialize::OutputArchive a;
  const auto weight = torch::full({64, 64}, 5, torch::kInt8);
  save_archive_with_mapped(a, {{"w", weight}}, path);
  // One byte of the tensor altered: its record fails its CRC-32, whatever else was read.
  std::string bytes = test::read_file(path);
  const std::string run(64, '\x05');
  const auto at = bytes.find(run);
  ASSERT_NE(at, std::string::npos);
  bytes[at + 10] = '\x06';
  test::write_text(dir + "/altered.pt", bytes);
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/altered.pt"), "altered.pt: damaged file",
                        "mapped/w' fails its CRC-32 check");
  // Cut short: named as damaged or unreadable, never read past its end.
  test::write_text(dir + "/cut.pt", bytes.substr(0, bytes.size() / 2));
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/cut.pt"), "cut.pt");
  // Index lines that do not match their records.
  const std::string four(4, '\0');
  write_container(dir + "/long.pt", "w 6 2\n", {{"w", four}});  // two float32 in 4 bytes
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/long.pt"), "long.pt: mapped.index line 1",
                        "tensor 'w' of 2 elements, its record 4 bytes");
  write_container(dir + "/huge.pt", "w 1 4 4611686018427387904 4\n", {{"w", four}});
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/huge.pt"), "mapped.index line 1", "sizes beyond its record");
  write_container(dir + "/type.pt", "w 99 4\n", {{"w", four}});
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/type.pt"), "mapped.index line 1", "not 'name type sizes...'");
  write_container(dir + "/quantized.pt", "w " + std::to_string(static_cast<int>(torch::kQInt8)) + " 4\n",
                  {{"w", four}});
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/quantized.pt"), "not a plain one");
  write_container(dir + "/missing.pt", "w 1 4\nv 1 4\n", {{"w", four}});
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/missing.pt"), "missing.pt: no record 'mapped/v'");
  write_container(dir + "/words.pt", "w 1 four\n", {{"w", four}});
  GEO_EXPECT_THROW_WITH(open_mapped_archive(dir + "/words.pt"), "line 1: not 'name type sizes...': 'w 1 four'");
  write_container(dir + "/ok.pt", "w 1 2 2\n", {{"w", four}});
  EXPECT_EQ(open_mapped_archive(dir + "/ok.pt").tensors.by_name.at("w").sizes(), (std::vector<int64_t>{2, 2}));
}

TEST(MappedArchive, NamesThatTheIndexCannotHoldAreRefusedBeforeWriting) {
  const auto dir = test::fresh_dir("mapped_archive_names");
  torch::serialize::OutputArchive a;
  for (const std::string name : {"a b", "a\tb", "a\nb", ""})
    GEO_EXPECT_THROW_WITH(save_archive_with_mapped(a, {{name, torch::ones({1})}}, dir + "/m.pt"),
                          "may not be empty or hold spaces");
  GEO_EXPECT_THROW_WITH(
      save_archive_with_mapped(a, {{"q", torch::quantize_per_tensor(torch::ones({2}), 0.1, 0, torch::kQInt8)}},
                               dir + "/m.pt"),
      "mapped tensor 'q' must be a CPU tensor of a plain type");
  EXPECT_FALSE(std::filesystem::exists(dir + "/m.pt"));
}

}  // namespace
}  // namespace geo
