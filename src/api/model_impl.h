// What geo::Model's sources share (src/api, not installed): the model's state and the helpers that
// turn failures and given cameras into geo::Error.
#pragma once

#include "geo/geo.h"

#include "pipeline/networks.h"

#include <torch/torch.h>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace geo {

struct Model::Impl {
  Networks nets;  // and their NetworkSpec
  torch::Device device = torch::kCPU;
  ModelSpec spec;
  std::vector<std::string> training_configs;  // CheckpointFile::lineage() of a training checkpoint
  // The int8 calibration the file keeps, per network (a file written in int8), else nullopt.
  std::optional<torch::Tensor> depth_ranges, pose_ranges, flow_ranges;
  // An int8 model file's int8 kernels per network (CheckpointFile::int8_kernels), until quantizing
  // takes them; int8_only: the file keeps no float kernels.
  std::map<std::string, torch::Tensor> depth_kernels, pose_kernels, flow_kernels;
  bool int8_only = false;
  bool float_released = false;  // Model::release_float_weights
};

// Runs `f`, turning any failure into a geo::Error that says what was being done.
template <class Fn>
auto guarded(const std::string& what, Fn&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error&) {
    throw;
  } catch (const c10::Error& e) {
    std::string why = e.what_without_backtrace();
    throw Error(what + ": " + why.substr(0, why.find('\n')));
  } catch (const std::exception& e) {
    throw Error(what + ": " + e.what());
  }
}

// Given intrinsics [3,3] or [B,3,3] of H x W images as float64 on the CPU: finite, and each a
// plausible camera of such an image (camera_problem: the rule of every tool); throws Error.
torch::Tensor checked_intrinsics(const torch::Tensor& K, int64_t H, int64_t W, bool batch_allowed);

}  // namespace geo
