#include "data/loader.h"

#include <chrono>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <numeric>
#include <random>

namespace geo {

Batch collate(const std::vector<Snippet>& snippets) {
  TORCH_CHECK(!snippets.empty(), "collate: no snippets");
  std::vector<torch::Tensor> tgt, srcs, K;
  Batch b;
  for (const auto& s : snippets) {
    const int64_t L = s.frames.size(0), mid = L / 2;
    tgt.push_back(s.frames[mid]);
    srcs.push_back(torch::cat({s.frames.slice(0, 0, mid), s.frames.slice(0, mid + 1, L)}));
    K.push_back(s.K.to(torch::kFloat32));
    b.ids.push_back(s.id);
  }
  b.tgt = torch::stack(tgt);
  b.srcs = torch::stack(srcs);
  b.K = torch::stack(K);
  return b;
}

Batch augment(Batch b, const AugmentConfig& c, uint64_t seed) {
  if (!c.enabled) return b;
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + 0x632BE59BD9B4E019ULL);
  auto U = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  const int64_t B = b.tgt.size(0), N = b.srcs.size(1), H = b.tgt.size(2), W = b.tgt.size(3);
  // Scale-crop (GeoNet random_scaling + random_cropping), same window for every frame and sample.
  const double sx = U(1.0, c.scale_max), sy = U(1.0, c.scale_max);
  const int64_t Hs = static_cast<int64_t>(H * sy), Ws = static_cast<int64_t>(W * sx);
  const int64_t oy = static_cast<int64_t>(U(0, static_cast<double>(Hs - H + 1)));
  const int64_t ox = static_cast<int64_t>(U(0, static_cast<double>(Ws - W + 1)));
  auto all = torch::cat({b.tgt.unsqueeze(1), b.srcs}, 1).reshape({B * (N + 1), 3, H, W});
  if (Hs != H || Ws != W) {
    namespace F = torch::nn::functional;
    all = F::interpolate(
        all,
        F::InterpolateFuncOptions().size(std::vector<int64_t>{Hs, Ws}).mode(torch::kBilinear).align_corners(false));
    all = all.slice(2, oy, oy + H).slice(3, ox, ox + W);
    // Exact for pixel centres at integers and align_corners=false: u' = (u + 0.5) s - 0.5 - offset,
    // with s the effective scale of the rounded size. GeoNet (data_loader.py: random_scaling) scales
    // by the drawn factor instead of the rounded size's and leaves out the half pixel: its intrinsics
    // are off by up to ~0.5 px at the image edges (a focal length off by up to f / W).
    const double ex = static_cast<double>(Ws) / W, ey = static_cast<double>(Hs) / H;
    auto K = b.K.clone();
    K.select(1, 0).select(1, 0).mul_(ex);
    K.select(1, 0).select(1, 2).add_(0.5).mul_(ex).sub_(0.5 + static_cast<double>(ox));
    K.select(1, 1).select(1, 1).mul_(ey);
    K.select(1, 1).select(1, 2).add_(0.5).mul_(ey).sub_(0.5 + static_cast<double>(oy));
    b.K = K;
  }
  if (U(0, 1) < c.photometric_prob) {  // GeoNet colour augmentation
    const double gamma = U(c.gamma_min, c.gamma_max), bright = U(c.brightness_min, c.brightness_max);
    auto colour = torch::tensor({U(c.color_min, c.color_max), U(c.color_min, c.color_max), U(c.color_min, c.color_max)},
                                all.options())
                      .view({1, 3, 1, 1});
    all = (all.clamp_min(0).pow(gamma) * bright * colour).clamp(0, 1);
  }
  all = all.reshape({B, N + 1, 3, H, W});
  b.tgt = all.select(1, 0).contiguous();
  b.srcs = all.slice(1, 1, N + 1).contiguous();
  return b;
}

size_t sample_at(uint64_t seed, size_t n, int64_t position) {
  const uint64_t epoch = static_cast<uint64_t>(position) / n;
  std::vector<size_t> perm(n);
  std::iota(perm.begin(), perm.end(), 0);
  std::mt19937_64 rng(seed * 1000003ULL + epoch);
  std::shuffle(perm.begin(), perm.end(), rng);
  return perm[static_cast<uint64_t>(position) % n];
}

BatchLoader::BatchLoader(std::shared_ptr<const SnippetSource> source, LoaderOptions options, int64_t first_batch)
    : source_(std::move(source)), options_(options), next_(first_batch), claimed_(first_batch) {
  TORCH_CHECK(source_ && source_->size() > 0, "the dataset is empty");
  for (int w = 0; w < options_.workers; ++w) threads_.emplace_back(&BatchLoader::work, this, w);
}

BatchLoader::~BatchLoader() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

Batch BatchLoader::make(int64_t k) const {
  const size_t n = source_->size();
  std::vector<Snippet> snippets;
  int64_t skipped = 0;
  // Per-epoch permutations are cheap to recompute for KITTI-sized lists (40k entries).
  for (int64_t j = 0; j < options_.batch_size; ++j) {
    const int64_t pos = (k * options_.world_size + options_.rank) * options_.batch_size + j;
    size_t idx = options_.shuffle ? sample_at(options_.seed, n, pos) : static_cast<size_t>(pos) % n;
    for (int attempt = 0;; ++attempt) {
      try {
        snippets.push_back(source_->get(idx));
        break;
      } catch (const std::exception& e) {
        if (!options_.skip_bad || attempt >= 10) throw;
        spdlog::warn("skipping bad sample '{}': {}", source_->id(idx), e.what());
        ++skipped;
        idx = (idx + 1) % n;
      }
    }
  }
  const auto draw = static_cast<uint64_t>(k * options_.world_size + options_.rank);  // k when not sharded
  Batch b = augment(collate(snippets), options_.augment, options_.seed * 7919ULL + draw);
  b.index = k;
  b.skipped = skipped;
  if (options_.pin_memory) {  // in the worker, off the training thread
    b.tgt = b.tgt.pin_memory();
    b.srcs = b.srcs.pin_memory();
    b.K = b.K.pin_memory();
  }
  return b;
}

void BatchLoader::work(int) {
  for (;;) {
    int64_t k;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [&] { return stop_ || claimed_ < next_ + options_.prefetch; });
      if (stop_) return;
      k = claimed_++;
    }
    Batch b;
    std::exception_ptr error;
    try {
      b = make(k);
    } catch (...) {
      error = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (error) errors_[k] = error;
      else ready_[k] = std::move(b);
    }
    cv_.notify_all();
  }
}

Batch BatchLoader::next() {
  if (threads_.empty()) return make(next_++);
  std::unique_lock<std::mutex> lock(mutex_);
  const int64_t k = next_;
  cv_.wait(lock, [&] { return ready_.count(k) || errors_.count(k); });
  if (errors_.count(k)) std::rethrow_exception(errors_[k]);
  Batch b = std::move(ready_[k]);
  ready_.erase(k);
  ++next_;
  lock.unlock();
  cv_.notify_all();
  return b;
}

LoaderOptions loader_options(const DataConfig& data, int64_t batch_size) {
  LoaderOptions o;
  o.batch_size = batch_size;
  o.workers = data.num_workers;
  o.skip_bad = data.on_bad_sample == BadSample::kSkip;
  o.augment = data.augment;
  return o;
}

double measure_throughput(std::shared_ptr<const SnippetSource> source, const LoaderOptions& options, int batches) {
  TORCH_CHECK(batches > 0, "measure_throughput: batches must be > 0");
  BatchLoader loader(std::move(source), options);
  loader.next();
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < batches; ++i) loader.next();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return batches * static_cast<double>(options.batch_size) / s;
}

}  // namespace geo
