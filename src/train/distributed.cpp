// What the trainer does with a process group (train/distributed.h): the same weights, config and
// signals on every process, BatchNorm synchronised, the process's device.
#include "train/distributed.h"

#include "core/config.h"
#include "core/logging.h"
#include "core/runtime.h"

#include <spdlog/spdlog.h>

#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace geo {

std::shared_ptr<const SumAcrossProcesses> sum_across(ProcessGroup& group) {
  return std::make_shared<const SumAcrossProcesses>([&group](torch::Tensor& t) {
    std::vector<torch::Tensor> one = {t};
    group.all_reduce_sum(one);
  });
}

void broadcast_module(ProcessGroup& group, torch::nn::Module& module) {
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> tensors;
  for (const auto& p : module.parameters()) tensors.push_back(p.data());
  for (const auto& b : module.buffers()) tensors.push_back(b);
  group.broadcast(tensors, 0);
}

void verify_same_weights(ProcessGroup& group, const std::vector<torch::Tensor>& parameters, int64_t step) {
  torch::NoGradGuard no_grad;
  double sum = 0, sq = 0;
  for (const auto& p : parameters) {
    const auto d = p.detach().to(torch::kCPU, torch::kFloat64);
    sum += d.sum().item<double>();
    sq += d.pow(2).sum().item<double>();
  }
  auto hi = torch::tensor({sum, sq}, torch::kFloat64);
  if (!parameters.empty() && parameters[0].is_cuda()) hi = hi.to(parameters[0].device());  // NCCL reduces on the GPU
  auto lo = -hi;
  std::vector<torch::Tensor> both{hi, lo};
  group.all_reduce_max(both);
  hi = hi.cpu();
  lo = lo.cpu();
  if (hi[0].item<double>() != -lo[0].item<double>() || hi[1].item<double>() != -lo[1].item<double>())
    throw std::runtime_error("rank " + std::to_string(group.rank()) + ": the weights differ across processes at step " +
                             std::to_string(step) + " (run.distributed.verify_interval): checksums range over [" +
                             std::to_string(-lo[0].item<double>()) + ", " + std::to_string(hi[0].item<double>()) + "]");
}

// ---------------------------------------------------------------- a training process in a group

std::unique_ptr<ProcessGroup> join_launched_group(const DistributedConfig& config, const std::string& device_name,
                                                  const std::string& master_addr) {
  const LaunchInfo launch = launch_from_environment(nullptr, master_addr);
  if (!launch.distributed()) return std::make_unique<SingleProcess>();
  return ProcessGroup::connect(launch, config, select_device(device_name));
}

torch::Device process_device(const std::string& name, const ProcessGroup& group) {
  const torch::Device d = select_device(name);
  if (group.size() > 1 && d.is_cuda() && (name == "auto" || name == "cuda"))
    return select_device("cuda:" + std::to_string(group.local_rank()));
  return d;
}

int agreed_signal(ProcessGroup& group, int local, const torch::Device& device) {
  if (group.size() == 1) return local;
  std::vector<torch::Tensor> flag{torch::full(
      {1}, local, torch::TensorOptions(torch::kInt32).device(group.backend() == "nccl" ? device : torch::kCPU))};
  group.all_reduce_max(flag);
  return flag[0].cpu().item<int>();
}

void check_same_config(ProcessGroup& group, const std::string& config_yaml, const torch::Device& device) {
  // Each process's own: where it writes and logs, its device and threads, where its copy of the data is.
  static const std::vector<std::string> own = {
      "run.name",  "run.dir",     "run.device",       "run.threads",  "run.distributed.timeout_s",
      "data.root", "data.videos", "data.num_workers", "logging.level"};
  const auto configs = group.all_gather_strings("config", config_yaml);
  std::string report;
  for (int r = 1; r < group.size(); ++r) {
    const auto diff = config_differences(configs[0], configs[static_cast<size_t>(r)], own);
    if (!diff.empty()) report += "\n  rank " + std::to_string(r) + " vs rank 0: " + join_list(diff, "; ");
  }
  // Also the barrier that keeps rank 0's store alive until every process has read every config.
  if (agreed_signal(group, report.empty() ? 0 : 1, device) != 0)
    throw std::runtime_error("rank " + std::to_string(group.rank()) +
                             ": the processes were started with different "
                             "configurations (every rank must train the same run: same config and --set options):" +
                             report);
}

void broadcast_networks(ProcessGroup& group, Networks& nets) {
  broadcast_module(group, *nets.depth);
  broadcast_module(group, *nets.pose);
  if (nets.flow) broadcast_module(group, *nets.flow);
}

int synchronise_batchnorm(ProcessGroup& group, Networks& nets) {
  const auto sum = sum_across(group);
  int layers = set_batchnorm_sync(*nets.depth, sum) + set_batchnorm_sync(*nets.pose, sum);
  if (nets.flow) layers += set_batchnorm_sync(*nets.flow, sum);
  return layers;
}

}  // namespace geo
