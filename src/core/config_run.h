// The run: section of a config (run folder, seed, device, precision, multi-process training).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

enum class Precision { kFp32, kTf32, kBf16 };
const std::vector<EnumName<Precision>>& enum_names(Precision);

// Multi-process training on torch.distributed (c10d); used only when geo_train is launched with
// torchrun's or SLURM's environment (train/distributed.h). batch_size is per process.
struct DistributedConfig {
  std::string backend = "auto";  // auto (nccl on CUDA, gloo on CPU) | nccl | gloo
  int timeout_s = 1800;          // a collective waiting longer (a lost or hung peer) fails the run
  bool shard_data = true;        // each process reads its own shard of the stream; false = all read it all
  int64_t verify_interval = 0;   // every N steps compare a checksum of the weights across processes (0 = never)
  // BatchNorm statistics over the batches of all processes (PyTorch's SyncBatchNorm) instead of each
  // process's own (GeoNet at batch 4 per GPU; DDP's default). Costs two small all-reduces per
  // BatchNorm layer and step.
  bool sync_batchnorm = false;
  // Start each gradient bucket's all-reduce during backward, as soon as its gradients exist (as
  // DistributedDataParallel); false: all after backward.
  bool overlap = true;

  template <class V>
  void fields(V& v) {
    v("backend", backend);
    v("timeout_s", timeout_s);
    v("shard_data", shard_data);
    v("verify_interval", verify_interval);
    v("sync_batchnorm", sync_batchnorm);
    v("overlap", overlap);
  }
  void validate(Checker& c) const;
};

// A device name as geo's options and configs take it: auto, cpu, cuda or cuda:N (N digits), and
// what their errors say otherwise.
bool is_device_name(const std::string& name);
inline constexpr const char* kDeviceNameRule = "must be auto, cpu, cuda or cuda:N";

struct RunConfig {
  std::string name = "geo";     // run folder prefix
  std::string dir = "runs";     // parent folder of run folders
  int64_t seed = 42;            // seeds torch and the data pipeline
  std::string device = "auto";  // auto | cpu | cuda | cuda:N (core/runtime.h: select_device)
  int threads = 0;              // intra-op threads; 0 = all cores
  // Arithmetic of the networks (losses and warping stay fp32): fp32; tf32 (CUDA convolutions and
  // matrix products in TF32 on Ampere and later, PyTorch's default for convolutions; the same as
  // fp32 on CPU); bf16 (the networks under autocast to bfloat16 on CUDA and on CPU, TF32 elsewhere).
  Precision precision = Precision::kTf32;
  // CUDA: cuDNN's deterministic algorithms and no autotuning (run to run the same up to the atomic
  // additions of some backward kernels, e.g. grid_sample's; slower). No effect on CPU.
  bool deterministic = false;
  // CUDA: each training step after the first two replays one CUDA graph of the whole update
  // (forward, losses, backward, clipping, Adam) instead of launching its kernels one by one; off:
  // the eager step (host-side checks between the kernels; for debugging). No effect on CPU and in
  // multi-process training.
  bool cuda_graphs = true;
  DistributedConfig distributed;

  template <class V>
  void fields(V& v) {
    v("name", name);
    v("dir", dir);
    v("seed", seed);
    v("device", device);
    v("threads", threads);
    v("precision", precision);
    v("deterministic", deterministic);
    v("cuda_graphs", cuda_graphs);
    v("distributed", distributed);
  }
  void validate(Checker& c) const;
};

}  // namespace geo
