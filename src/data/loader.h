// Batches for training: a deterministic sample order (a fresh permutation per epoch from the seed),
// GeoNet augmentation (data_loader.py) drawn from a generator seeded by (seed, batch index), and
// worker threads that prefetch batches while the trainer computes. Batch k depends only on the seed
// and k, so a resumed run sees exactly the batches an uninterrupted one would.
#pragma once

#include "core/config.h"
#include "data/snippets.h"

#include <condition_variable>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace geo {

struct Batch {
  torch::Tensor tgt;   // [B,3,H,W] in [0,1]
  torch::Tensor srcs;  // [B,L-1,3,H,W] in [0,1] (frames before the target, then after)
  torch::Tensor K;     // [B,3,3]
  std::vector<std::string> ids;
  int64_t index = 0;    // batch number in the stream
  int64_t skipped = 0;  // bad samples replaced (on_bad_sample: skip)
};

// Stacks snippets into a batch (target = the middle frame).
Batch collate(const std::vector<Snippet>& snippets);

// GeoNet augmentation of a whole batch, drawn from `seed`: scale x and y by U[1, scale_max] and crop
// a random window back to H x W (intrinsics adjusted); with probability photometric_prob, gamma,
// brightness and per-channel colour jitter, then clip to [0,1].
Batch augment(Batch batch, const AugmentConfig& config, uint64_t seed);

// Index of the sample at stream position `position` (epoch = position / N; per-epoch permutation).
size_t sample_at(uint64_t seed, size_t dataset_size, int64_t position);

struct LoaderOptions {
  int64_t batch_size = 4;
  uint64_t seed = 0;
  int workers = 2;   // 0 = load in the caller's thread
  int prefetch = 4;  // batches kept ready ahead
  bool shuffle = true;
  bool skip_bad = false;    // on_bad_sample: skip (log and use the next sample) vs stop (throw)
  AugmentConfig augment;    // augment.enabled = false: none
  bool pin_memory = false;  // batches in page-locked memory (CUDA training: asynchronous copies to the GPU)
  // Shard `rank` of `world_size` (distributed training): global batch k is the stream positions
  // [k*B*W, (k+1)*B*W); this process takes its B positions r*B.. of it, and its own augmentation
  // draw. world_size 1 is the single-process stream.
  int rank = 0;
  int world_size = 1;
};

// The loader settings of a config's data section for batches of `batch_size`: data.num_workers,
// data.on_bad_sample, data.augment (the trainer, validation, geo_prepare and geo_bench start here).
LoaderOptions loader_options(const DataConfig& data, int64_t batch_size);

class BatchLoader {
 public:
  BatchLoader(std::shared_ptr<const SnippetSource> source, LoaderOptions options, int64_t first_batch = 0);
  ~BatchLoader();
  BatchLoader(const BatchLoader&) = delete;
  BatchLoader& operator=(const BatchLoader&) = delete;

  // The next batch in order; rethrows a worker's error (naming the file) when skip_bad is off.
  Batch next();
  // Builds batch k synchronously (what the workers do).
  Batch make(int64_t k) const;

 private:
  void work(int worker);
  std::shared_ptr<const SnippetSource> source_;
  LoaderOptions options_;
  int64_t next_ = 0;     // next batch handed out
  int64_t claimed_ = 0;  // next batch a worker will build
  std::map<int64_t, Batch> ready_;
  std::map<int64_t, std::exception_ptr> errors_;
  bool stop_ = false;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<std::thread> threads_;
};

// Loader throughput in samples/s: `batches` batches timed after one warm-up batch (thread start,
// file cache). Used by geo_prepare --throughput and geo_bench.
double measure_throughput(std::shared_ptr<const SnippetSource> source, const LoaderOptions& options, int batches);

}  // namespace geo
