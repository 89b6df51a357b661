// The run: section's names and checks.
#include "core/config_run.h"

#include "core/config_check.h"

namespace geo {

const std::vector<EnumName<Precision>>& enum_names(Precision) {
  static const std::vector<EnumName<Precision>> n{
      {Precision::kFp32, "fp32"}, {Precision::kTf32, "tf32"}, {Precision::kBf16, "bf16"}};
  return n;
}

bool is_device_name(const std::string& name) {
  const bool cuda_n =
      name.rfind("cuda:", 0) == 0 && name.size() > 5 && name.find_first_not_of("0123456789", 5) == std::string::npos;
  return one_of(name, {"auto", "cpu", "cuda"}) || cuda_n;
}

void RunConfig::validate(Checker& c) const {
  c.require(!name.empty(), "name", name, "must not be empty");
  c.require(!dir.empty(), "dir", dir, "must not be empty");
  c.require(seed >= 0, "seed", seed, "must be >= 0");
  c.require(is_device_name(device), "device", device, kDeviceNameRule);
  c.require(threads >= 0 && threads <= 1024, "threads", threads, "must be in 0..1024 (0 = all cores)");
  c.section("distributed", distributed);
}

void DistributedConfig::validate(Checker& c) const {
  c.require(one_of(backend, {"auto", "nccl", "gloo"}), "backend", backend, "must be auto, nccl or gloo");
  c.require(timeout_s >= 1 && timeout_s <= 86400, "timeout_s", timeout_s, "must be in 1..86400 seconds");
  c.require(verify_interval >= 0 && verify_interval <= kMaxCount, "verify_interval", verify_interval,
            "must be in 0..1000000000000 (0 = never)");
}

}  // namespace geo
