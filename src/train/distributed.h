// Data-parallel training across processes on torch.distributed's C++ engine (c10d): a TCPStore for
// rendezvous, ProcessGroupGloo on CPUs and ProcessGroupNCCL on GPUs. geo_train becomes one process of
// a group when launched the way PyTorch users launch DDP jobs:
//   torchrun --no-python --nproc_per_node=N geo_train --config ...   (RANK, WORLD_SIZE, LOCAL_RANK,
//                                                                      MASTER_ADDR, MASTER_PORT)
//   srun geo_train --config ...                                      (SLURM_PROCID, SLURM_NTASKS,
//                                                                      SLURM_LOCALID; MASTER_ADDR and
//                                                                      MASTER_PORT from the environment)
// Without those variables (or with a world size of 1) geo_train is the single-process trainer.
//
// Semantics, as PyTorch's DistributedDataParallel: batch_size is per process; every process starts
// from rank 0's weights; gradients are averaged over processes (all-reduce on flattened buckets), so
// the weights stay bit-identical; BatchNorm uses each process's own batch statistics (running
// statistics saved are rank 0's); each process reads its own disjoint shard of the deterministic
// stream (run.distributed.shard_data). Only rank 0 writes the run folder and validates.
// LibTorch only; c10d parts are compiled when LibTorch ships them (GEO_WITH_C10D).
#pragma once

#include "core/config.h"
#include "models/conv_bn.h"
#include "pipeline/networks.h"

#include <torch/torch.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace geo {

// Where this process stands in a launch. world_size 1 = not distributed.
struct LaunchInfo {
  int rank = 0;
  int world_size = 1;
  int local_rank = 0;       // the GPU this process uses (cuda:local_rank)
  std::string master_addr;  // the rendezvous host (rank 0 listens there)
  int master_port = 29500;
  std::string launcher;  // "torchrun", "slurm" or "" (single process)
  bool distributed() const { return world_size > 1; }
};

// Reads torchrun's variables (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT), else SLURM's
// (SLURM_PROCID, SLURM_NTASKS, SLURM_LOCALID, with MASTER_ADDR/MASTER_PORT from the environment or
// `master_addr`). Incomplete or inconsistent variables are an error naming them.
LaunchInfo launch_from_environment(const std::function<const char*(const char*)>& getenv_fn = nullptr,
                                   const std::string& master_addr = "");

// A TCP port on 127.0.0.1 that nobody listens on now (asked from the OS), for single-machine groups
// (tests, geo_bench).
int free_local_port();

// True when this build can run distributed on CPU (LibTorch's c10d with Gloo); NCCL needs a CUDA
// LibTorch built with it and a GPU (a pip wheel's LibTorch has NCCL but no Gloo headers).
bool distributed_available();
bool nccl_available();

// One process group. Every call is collective: all processes make it, in the same order. A peer
// that exits or stops responding makes the call fail within run.distributed.timeout_s with a
// std::runtime_error naming this rank and the operation.
class ProcessGroup {
 public:
  // Connects (rank 0 listens on master_addr:master_port). backend "auto": NCCL for a CUDA device
  // when available, else Gloo.
  static std::unique_ptr<ProcessGroup> connect(const LaunchInfo& launch, const DistributedConfig& config,
                                               const torch::Device& device);
  virtual ~ProcessGroup() = default;

  virtual int rank() const = 0;
  virtual int size() const = 0;
  virtual int local_rank() const = 0;  // the GPU index on this machine (LOCAL_RANK, SLURM_LOCALID)
  virtual std::string backend() const = 0;
  // Tensors of rank `root` copied into everyone's (in place).
  virtual void broadcast(std::vector<torch::Tensor>& tensors, int root = 0) = 0;
  // Element-wise sum / maximum over processes, in place.
  virtual void all_reduce_sum(std::vector<torch::Tensor>& tensors) = 0;
  virtual void all_reduce_max(std::vector<torch::Tensor>& tensors) = 0;
  // An in-place sum started now, finished by calling the returned function (once). Starts are
  // collectives: every process starts the same sums in the same order. By default the sum runs at
  // once; c10d groups return while Gloo's threads / NCCL's stream work on it.
  virtual std::function<void()> start_all_reduce_sum(torch::Tensor& tensor) {
    std::vector<torch::Tensor> one{tensor};
    all_reduce_sum(one);
    return [] {};
  }
  // A short string shared from rank 0 (e.g. the run folder); rank 0 passes it, the others get it.
  // `failed` on rank 0 makes the others throw with `value` as the reason.
  virtual std::string share_from_rank0(const std::string& key, const std::string& value, bool failed = false) = 0;
  // Every process's `value` (index: rank), to every process. Not a barrier: a process may go on
  // before the others have read its value.
  virtual std::vector<std::string> all_gather_strings(const std::string& key, const std::string& value) = 0;
};

// The group of a process that trains alone: rank 0 of 1, on GPU 0; every collective leaves the
// tensors as they are (a sum over one process), share_from_rank0 returns the value given (a failure
// is the caller's own, thrown by it), all_gather_strings the one value. The trainer's code is the
// same for one process and for many.
class SingleProcess : public ProcessGroup {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  int local_rank() const override { return 0; }
  std::string backend() const override { return "none"; }
  void broadcast(std::vector<torch::Tensor>&, int) override {}
  void all_reduce_sum(std::vector<torch::Tensor>&) override {}
  void all_reduce_max(std::vector<torch::Tensor>&) override {}
  std::string share_from_rank0(const std::string&, const std::string& value, bool) override { return value; }
  std::vector<std::string> all_gather_strings(const std::string&, const std::string& value) override { return {value}; }
};

// Averages gradients over the group on flattened buckets of at most `bucket_bytes` (one all-reduce
// per bucket instead of one per tensor), in place, as DistributedDataParallel does. Buckets are
// filled in reverse parameter order (the order backward computes gradients in). Parameters without a
// gradient contribute zeros and get none.
//
// Two ways to use it:
//   average(parameters): after backward, all buckets at once.
//   attach(parameters) once, then per step begin_step(), backward, finish(): gradient hooks copy
//   each gradient into its bucket as backward computes it and start the bucket's all-reduce as soon
//   as the bucket is complete (buckets start in the same order on every process), so communication
//   overlaps the rest of backward; finish() starts what is left and waits for all.
class GradientAverager {
 public:
  GradientAverager(ProcessGroup& group, int64_t bucket_bytes = 25 << 20) : group_(group), bucket_bytes_(bucket_bytes) {}
  ~GradientAverager() { detach(); }
  GradientAverager(const GradientAverager&) = delete;
  GradientAverager& operator=(const GradientAverager&) = delete;

  // `poison`: this process's step is not finite; its contribution is NaN so that every process
  // sees a non-finite average and skips the same step.
  void average(const std::vector<torch::Tensor>& parameters, bool poison = false);

  void attach(const std::vector<torch::Tensor>& parameters);  // registers the gradient hooks
  void detach();                                              // removes them
  void begin_step();
  void finish(bool poison = false);

  int64_t buckets() const { return static_cast<int64_t>(buckets_.size()); }
  int64_t bytes() const { return bytes_; }
  // Buckets whose all-reduce started during backward (from a gradient hook) in the last step.
  int64_t started_during_backward() const { return started_early_; }

 private:
  struct Bucket {
    std::vector<size_t> members;   // indices into params_
    std::vector<int64_t> offsets;  // of each member in `flat`
    torch::Tensor flat;
    size_t ready = 0;
    bool started = false;
    std::function<void()> wait;
  };
  void build(const std::vector<torch::Tensor>& parameters);
  void mark_ready(size_t index, const torch::Tensor& grad);
  void start(Bucket& b, bool poison);

  ProcessGroup& group_;
  int64_t bucket_bytes_;
  std::vector<torch::Tensor> params_;
  std::vector<size_t> bucket_of_;  // param index -> bucket
  std::vector<size_t> slot_of_;    // param index -> member position in its bucket
  std::vector<char> ready_;        // param index -> gradient copied this step
  std::vector<Bucket> buckets_;
  size_t next_ = 0;              // the next bucket to start
  std::vector<unsigned> hooks_;  // hook handles of params_ (attached)
  int64_t bytes_ = 0, started_early_ = 0;
};

// An in-place sum over the group (all_reduce_sum of one tensor) for synchronised BatchNorm
// (models/sync_batch_norm.h: set_batchnorm_sync). The group must outlive it.
std::shared_ptr<const SumAcrossProcesses> sum_across(ProcessGroup& group);

// rank 0's parameters and buffers copied into every process's module.
void broadcast_module(ProcessGroup& group, torch::nn::Module& module);

// A checksum of the parameters that is equal across processes exactly when the weights are (sum
// and sum of squares, in float64); compared with all_reduce_max/min, a difference is an error.
void verify_same_weights(ProcessGroup& group, const std::vector<torch::Tensor>& parameters, int64_t step);

// What a training process does as part of a group:

// This process's group: the launched group when it was started as one process of several (torchrun,
// srun: the environment says so), else a SingleProcess. `device_name`: run.device or --device.
std::unique_ptr<ProcessGroup> join_launched_group(const DistributedConfig& config, const std::string& device_name,
                                                  const std::string& master_addr);
// This process's device: `name` as select_device reads it, except that "cuda" or "auto" with CUDA
// in a group of several is this process's own GPU, cuda:LOCAL_RANK.
torch::Device process_device(const std::string& name, const ProcessGroup& group);
// The signal (SIGINT/SIGTERM number, 0 for none) any process of the group received, agreed on at
// the same step by one tiny all-reduce, so that all processes stop at the step rank 0 checkpoints.
// `local` alone for a single process.
int agreed_signal(ProcessGroup& group, int local, const torch::Device& device);
// Every process trains with the same configuration: the configs (to_yaml) are compared at start-up,
// and a difference outside the keys that are each process's own (run.name, run.dir, run.device,
// run.threads, run.distributed.timeout_s, data.root, data.videos, data.num_workers, logging.level)
// fails every process with the ranks and keys that differ, before any data is read.
void check_same_config(ProcessGroup& group, const std::string& config_yaml, const torch::Device& device);
// rank 0's weights and buffers in every process's networks.
void broadcast_networks(ProcessGroup& group, Networks& nets);
// Every BatchNorm of the networks synchronised across the group; returns how many layers.
int synchronise_batchnorm(ProcessGroup& group, Networks& nets);

}  // namespace geo
