// HugePages: while alive, LibTorch's CPU allocator gives blocks of 2 MiB and more on 2 MiB
// boundaries (the kernel's transparent huge pages), the rest as before; LibTorch's comes back after.
#include "core/runtime.h"

#include <c10/core/CPUAllocator.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <optional>
#include <string>

namespace geo {
namespace {

constexpr int64_t kMiB = int64_t{1} << 20;

bool kernel_gives_huge_pages() {
  std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string modes;
  return std::getline(mode, modes) && modes.find("[never]") == std::string::npos;
}

uintptr_t address(const torch::Tensor& t) { return reinterpret_cast<uintptr_t>(t.data_ptr()); }

TEST(HugePages, OffInTheEnvironmentLeavesLibTorchsAllocator) {
  ::setenv("GEO_HUGE_PAGES", "0", 1);
  c10::Allocator* before = c10::GetCPUAllocator();
  {
    const HugePages huge;
    EXPECT_FALSE(huge.on());
    EXPECT_EQ(c10::GetCPUAllocator(), before);
  }
  ::unsetenv("GEO_HUGE_PAGES");
}

TEST(HugePages, LargeBlocksOnHugePageBoundariesAndSmallOnesAsBefore) {
  if (!kernel_gives_huge_pages()) GTEST_SKIP() << "transparent huge pages are off on this machine";
  c10::Allocator* libtorch = c10::GetCPUAllocator();
  std::optional<HugePages> huge;
  huge.emplace();
  ASSERT_TRUE(huge->on());
  EXPECT_NE(c10::GetCPUAllocator(), libtorch);
  // 3 MiB of floats: on a 2 MiB boundary, holding what is written.
  auto big = torch::arange(3 * kMiB / 4, torch::kFloat32);
  EXPECT_EQ(address(big) % (2 * kMiB), 0u);
  EXPECT_EQ(big[0].item<float>(), 0.0f);
  EXPECT_EQ(big[-1].item<float>(), static_cast<float>(3 * kMiB / 4 - 1));
  EXPECT_EQ(big.sum().item<double>(), (3.0 * kMiB / 4) * (3.0 * kMiB / 4 - 1) / 2);
  // 3.5 MiB: on a boundary too.
  auto other = torch::full({7 * kMiB / 2}, 7, torch::kUInt8);
  EXPECT_EQ(address(other) % (2 * kMiB), 0u);
  EXPECT_EQ(other.sum().item<int64_t>(), 7 * (7 * kMiB / 2));
  // A block just under 2 MiB and a small one: as LibTorch gives them (64-byte aligned at least).
  auto under = torch::ones({2 * kMiB - 64}, torch::kUInt8);
  auto small = torch::ones({10}, torch::kFloat64);
  EXPECT_EQ(address(under) % 64, 0u);
  EXPECT_EQ(under.sum().item<int64_t>(), 2 * kMiB - 64);
  EXPECT_EQ(small.sum().item<double>(), 10.0);
  // Raw blocks (what oneDNN asks for), freed with the allocator's raw deleter, of both kinds.
  c10::Allocator* alloc = c10::GetCPUAllocator();
  for (size_t bytes : {size_t{100}, size_t{5} << 20}) {
    void* p = alloc->raw_allocate(bytes);
    ASSERT_NE(p, nullptr);
    std::memset(p, 1, bytes);
    if (bytes >= (size_t{2} << 20)) {
      EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % (2 * kMiB), 0u);
    }
    alloc->raw_deallocate(p);
  }
  {  // one inside another: the inner changes nothing, the outer's allocator stays
    const HugePages inner;
    EXPECT_FALSE(inner.on());
  }
  EXPECT_EQ(c10::GetCPUAllocator(), alloc);
  // Gone: LibTorch's own again; what was allocated on huge pages is freed as any block.
  huge.reset();
  EXPECT_EQ(c10::GetCPUAllocator(), libtorch);
  big = torch::Tensor();
  other = torch::Tensor();
  auto after = torch::ones({3 * kMiB}, torch::kUInt8);
  EXPECT_EQ(after.sum().item<int64_t>(), 3 * kMiB);
}

}  // namespace
}  // namespace geo
