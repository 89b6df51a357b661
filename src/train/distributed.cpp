#include "train/distributed.h"

#include "core/config.h"
#include "core/logging.h"
#include "core/runtime.h"

#include <spdlog/spdlog.h>
#include <torch/version.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <limits>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <thread>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#ifdef GEO_WITH_C10D
#include <torch/csrc/distributed/c10d/PrefixStore.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#ifdef GEO_WITH_GLOO
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#endif
#ifdef GEO_WITH_NCCL
#include <torch/csrc/distributed/c10d/ProcessGroupNCCL.hpp>
#endif
#endif

namespace geo {
namespace {

int env_int(const std::string& key, const std::string& value, int lo, int hi) {
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(value.c_str(), &end, 10);
  if (value.empty() || errno != 0 || *end != '\0' || v < lo || v > hi)
    throw std::runtime_error("environment variable " + key + "='" + value + "' is not an integer in " +
                             std::to_string(lo) + ".." + std::to_string(hi));
  return static_cast<int>(v);
}

}  // namespace

int free_local_port() {
  const int sock = ::socket(AF_INET, SOCK_STREAM, 0);
  if (sock < 0) throw std::runtime_error("cannot open a socket to find a free port");
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t n = sizeof a;
  const bool ok = ::bind(sock, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
                  ::getsockname(sock, reinterpret_cast<sockaddr*>(&a), &n) == 0;
  ::close(sock);
  if (!ok) throw std::runtime_error("cannot find a free TCP port on 127.0.0.1");
  return ntohs(a.sin_port);
}

LaunchInfo launch_from_environment(const std::function<const char*(const char*)>& getenv_fn,
                                   const std::string& master_addr) {
  auto get = [&](const char* key) -> std::optional<std::string> {
    const char* v = getenv_fn ? getenv_fn(key) : std::getenv(key);
    if (!v || !*v) return std::nullopt;
    return std::string(v);
  };
  LaunchInfo l;
  const auto world = get("WORLD_SIZE"), rank = get("RANK");
  if (world || rank) {
    if (!world) throw std::runtime_error("RANK is set but WORLD_SIZE is not: launch with torchrun --no-python, or set both");
    if (!rank) throw std::runtime_error("WORLD_SIZE is set but RANK is not: launch with torchrun --no-python, or set both");
    l.world_size = env_int("WORLD_SIZE", *world, 1, 65536);
    l.rank = env_int("RANK", *rank, 0, l.world_size - 1);
    const auto local = get("LOCAL_RANK");
    l.local_rank = local ? env_int("LOCAL_RANK", *local, 0, 65535) : l.rank;
    l.launcher = "torchrun";
  } else if (const auto ntasks = get("SLURM_NTASKS")) {
    l.world_size = env_int("SLURM_NTASKS", *ntasks, 1, 65536);
    const auto procid = get("SLURM_PROCID");
    if (!procid) throw std::runtime_error("SLURM_NTASKS is set but SLURM_PROCID is not: start geo_train with srun");
    l.rank = env_int("SLURM_PROCID", *procid, 0, l.world_size - 1);
    const auto local = get("SLURM_LOCALID");
    l.local_rank = local ? env_int("SLURM_LOCALID", *local, 0, 65535) : 0;
    l.launcher = "slurm";
  }
  if (!l.distributed()) return l;
  const auto addr = get("MASTER_ADDR");
  l.master_addr = addr ? *addr : master_addr;
  if (l.master_addr.empty())
    throw std::runtime_error("MASTER_ADDR is not set (torchrun sets it; under SLURM export MASTER_ADDR=$(scontrol show "
                             "hostnames \"$SLURM_JOB_NODELIST\" | head -n1) or give --master-addr)");
  if (const auto port = get("MASTER_PORT")) l.master_port = env_int("MASTER_PORT", *port, 1, 65535);
  return l;
}

#ifdef GEO_WITH_C10D

#ifdef GEO_WITH_GLOO
bool distributed_available() { return true; }
#else
bool distributed_available() { return false; }
#endif
#ifdef GEO_WITH_NCCL
bool nccl_available() { return torch::cuda::is_available(); }
#else
bool nccl_available() { return false; }
#endif

namespace {

std::string message_of(const std::exception& e) {
  if (const auto* c = dynamic_cast<const c10::Error*>(&e)) return c->what_without_backtrace();
  return e.what();
}

// False for a PID that no longer runs: gone, or a zombie its parent has not collected yet.
bool process_alive(pid_t pid) {
  if (::kill(pid, 0) != 0 && errno == ESRCH) return false;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return true;  // no /proc: assume it runs
  const auto close = line.rfind(')');
  return close == std::string::npos || close + 2 >= line.size() || line[close + 2] != 'Z';
}

// A process that was killed is still being torn down when its sockets close and this process
// hears of it: give it until `end` to be gone before saying it is alive.
bool alive_after(pid_t pid, std::chrono::steady_clock::time_point end) {
  while (process_alive(pid)) {
    if (std::chrono::steady_clock::now() > end) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

class C10dGroup : public ProcessGroup {
 public:
  C10dGroup(const LaunchInfo& l, const DistributedConfig& config, const torch::Device& device)
      : rank_(l.rank), size_(l.world_size), local_rank_(l.local_rank), timeout_s_(config.timeout_s),
        master_(l.master_addr + ":" + std::to_string(l.master_port)) {
    const auto timeout = std::chrono::milliseconds(int64_t{1000} * config.timeout_s);
    // One deadline for the whole rendezvous: LibTorch 1.13's store stops waiting for missing
    // workers at the timeout without an error, so waiting again for their keys with the full
    // timeout would report a missing process only after twice run.distributed.timeout_s.
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    const auto time_left = [&] {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      return std::max(left, std::chrono::milliseconds(100));
    };
    const std::string where = l.master_addr + ":" + std::to_string(l.master_port);
    c10d::TCPStoreOptions so;
    so.port = static_cast<std::uint16_t>(l.master_port);
    so.isServer = l.rank == 0;
    so.numWorkers = static_cast<size_t>(l.world_size);
    so.waitWorkers = true;
    so.timeout = timeout;
    try {
      try {
        store_ = c10::make_intrusive<c10d::TCPStore>(l.master_addr, so);
      } catch (const std::exception& e) {
#if TORCH_VERSION_MAJOR > 2 || (TORCH_VERSION_MAJOR == 2 && TORCH_VERSION_MINOR >= 4)
        // LibTorch 2.4+ asks for the libuv store by default; builds without libuv (Debian's) refuse
        // it: the classic store then, as torchrun does with USE_LIBUV=0.
        if (std::string(e.what()).find("libuv") == std::string::npos) throw;
        so.useLibUV = false;
        store_ = c10::make_intrusive<c10d::TCPStore>(l.master_addr, so);
#else
        throw;
#endif
      }
    } catch (const std::exception& e) {
      throw std::runtime_error(
          l.rank == 0 ? "rank 0 could not open the rendezvous at " + where + " (MASTER_ADDR:MASTER_PORT; port in use, " +
                            "e.g. by another process also launched with RANK=0?) or not all " + std::to_string(l.world_size) +
                            " processes arrived within " + std::to_string(config.timeout_s) + " s (each process needs its own RANK, " +
                            "0.." + std::to_string(l.world_size - 1) + "): " + message_of(e)
                      : "rank " + std::to_string(l.rank) + " could not reach the rendezvous at " + where +
                            " within run.distributed.timeout_s (" + std::to_string(config.timeout_s) + " s): " + message_of(e));
    }
    // Who is who, for naming a lost process later (set before the group forms, so every key exists).
    try {
      char host[256] = {0};
      ::gethostname(host, sizeof host - 1);
      const std::string me = std::string(host) + " " + std::to_string(::getpid());
      store_->set("geo/proc/" + std::to_string(rank_), std::vector<uint8_t>(me.begin(), me.end()));
      const std::string size = std::to_string(size_);
      store_->set("geo/world_size/" + std::to_string(rank_), std::vector<uint8_t>(size.begin(), size.end()));
    } catch (const std::exception& e) {
      throw std::runtime_error("rank " + std::to_string(rank_) + ": the rendezvous at " + where + " failed: " + message_of(e));
    }
    // Every process launched with the same WORLD_SIZE, said at once (else Gloo's own enforce message,
    // or a wait for processes that never come): each compares with rank 0, rank 0 with each.
    const auto world_of = [&](int r) {
      const std::string key = "geo/world_size/" + std::to_string(r);
      store_->wait({key}, time_left());
      const auto v = store_->get(key);
      return std::string(v.begin(), v.end());
    };
    for (int r = rank_ == 0 ? 1 : 0; r < (rank_ == 0 ? size_ : 1); ++r) {
      std::string other;
      try {
        other = world_of(r);
      } catch (const std::exception& e) {
        throw std::runtime_error("rank " + std::to_string(rank_) + ": rank " + std::to_string(r) + " did not register at " +
                                 where + " within run.distributed.timeout_s (" + std::to_string(timeout_s_) +
                                 " s): " + message_of(e));
      }
      // Rank 0's store must outlive the others' reads: each says it has read rank 0's world size,
      // and rank 0 waits for that (briefly) before leaving on a mismatch, so that every process
      // reports the mismatch instead of a closed connection.
      if (rank_ != 0) store_->set("geo/world_size_read/" + std::to_string(rank_), std::vector<uint8_t>{1});
      if (other != std::to_string(size_)) {
        if (rank_ == 0) {
          try {
            store_->wait({"geo/world_size_read/" + std::to_string(r)}, std::min(time_left(), std::chrono::milliseconds(5000)));
          } catch (const std::exception&) {  // it may have gone: the message below is rank 0's either way
          }
        }
        throw std::runtime_error("WORLD_SIZE differs between the processes: rank " + std::to_string(rank_) + " has " +
                                 std::to_string(size_) + ", rank " + std::to_string(r) + " has " + other +
                                 " (launch every process of a run with the same WORLD_SIZE)");
      }
    }
    std::string backend = config.backend;
    if (backend == "auto") backend = device.is_cuda() && nccl_available() ? "nccl" : "gloo";
    backend_ = backend;
    auto pg_store = c10::make_intrusive<c10d::PrefixStore>("pg", store_);
    try {
      if (backend == "nccl") {
#ifdef GEO_WITH_NCCL
        auto o = c10d::ProcessGroupNCCL::Options::create();
        o->timeout = timeout;
        nccl_ = c10::make_intrusive<c10d::ProcessGroupNCCL>(pg_store, l.rank, l.world_size, o);
#else
        throw std::runtime_error("run.distributed.backend is nccl but this LibTorch has no NCCL (use gloo)");
#endif
      } else {
#ifdef GEO_WITH_GLOO
        auto o = c10d::ProcessGroupGloo::Options::create(timeout);
        const char* ifname = std::getenv("GLOO_SOCKET_IFNAME");
        if (ifname && *ifname) o->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(ifname));
        else if (l.master_addr == "127.0.0.1" || l.master_addr == "localhost")
          o->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1"));
        else o->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
        o->threads = 2;
        gloo_ = c10::make_intrusive<c10d::ProcessGroupGloo>(pg_store, l.rank, l.world_size, o);
#else
        throw std::runtime_error("run.distributed.backend is " + config.backend +
                                 (config.backend == "auto" ? " (gloo on CPU)" : "") +
                                 " but this geo was built without Gloo (its headers were not found at configure "
                                 "time; install libgloo-dev): use NCCL on GPUs (--device cuda)");
#endif
      }
    } catch (const std::exception& e) {
      throw std::runtime_error("rank " + std::to_string(l.rank) + ": could not form the " + backend + " process group of " +
                               std::to_string(l.world_size) + " at " + where + ": " + message_of(e));
    }
  }

  int rank() const override { return rank_; }
  int size() const override { return size_; }
  int local_rank() const override { return local_rank_; }
  std::string backend() const override { return backend_; }

  void broadcast(std::vector<torch::Tensor>& tensors, int root) override {
    c10d::BroadcastOptions o;
    o.rootRank = root;
    for (auto& t : tensors) {
      std::vector<torch::Tensor> one{t};
      guarded("broadcast", [&](auto& pg) { pg.broadcast(one, o)->wait(); });
    }
  }
  void all_reduce_sum(std::vector<torch::Tensor>& tensors) override { all_reduce(tensors, c10d::ReduceOp::SUM, "all-reduce"); }
  std::function<void()> start_all_reduce_sum(torch::Tensor& tensor) override {
    c10::intrusive_ptr<c10d::Work> work;
    std::vector<torch::Tensor> one{tensor};
    guarded("all-reduce", [&](auto& pg) { work = pg.allreduce(one, c10d::AllreduceOptions()); });
    return [this, work] { guarded("all-reduce", [&](auto&) { work->wait(); }); };
  }
  void all_reduce_max(std::vector<torch::Tensor>& tensors) override { all_reduce(tensors, c10d::ReduceOp::MAX, "all-reduce (max)"); }

  std::string share_from_rank0(const std::string& key, const std::string& value, bool failed) override {
    const std::string k = "geo/" + key;
    try {
      if (rank_ == 0) {
        std::string v = (failed ? "1" : "0") + value;
        store_->set(k, std::vector<uint8_t>(v.begin(), v.end()));
        return value;
      }
      const auto bytes = store_->get(k);
      const std::string v(bytes.begin(), bytes.end());
      if (v.empty() || v[0] == '1')
        throw std::runtime_error("rank 0 failed to start: " + (v.empty() ? std::string("?") : v.substr(1)));
      return v.substr(1);
    } catch (const std::runtime_error& e) {
      if (std::string(e.what()).rfind("rank 0 failed", 0) == 0) throw;
      throw std::runtime_error("rank " + std::to_string(rank_) + ": waiting for '" + key + "' from rank 0 failed: " + message_of(e));
    }
  }

  std::vector<std::string> all_gather_strings(const std::string& key, const std::string& value) override {
    const std::string k = "geo/" + key + "/";
    std::vector<std::string> out(static_cast<size_t>(size_));
    int r = rank_;
    try {
      store_->set(k + std::to_string(rank_), std::vector<uint8_t>(value.begin(), value.end()));
      for (r = 0; r < size_; ++r) {
        const auto bytes = store_->get(k + std::to_string(r));  // waits up to run.distributed.timeout_s
        out[static_cast<size_t>(r)].assign(bytes.begin(), bytes.end());
      }
    } catch (const std::exception& e) {
      throw std::runtime_error("rank " + std::to_string(rank_) + ": waiting for '" + key + "' of rank " + std::to_string(r) +
                               " failed: " + lost_processes() + ": " + message_of(e));
    }
    return out;
  }

 private:
  void all_reduce(std::vector<torch::Tensor>& tensors, c10d::ReduceOp op, const char* what) {
    c10d::AllreduceOptions o;
    o.reduceOp = op;
    // One tensor per call: Gloo and NCCL reduce a list across its elements too (one per device).
    std::vector<c10::intrusive_ptr<c10d::Work>> works;
    guarded(what, [&](auto& pg) {
      for (auto& t : tensors) {
        std::vector<torch::Tensor> one{t};
        works.push_back(pg.allreduce(one, o));
      }
      for (auto& w : works) w->wait();
    });
  }

  template <class F> void guarded(const char* what, F&& f) {
    try {
#ifdef GEO_WITH_NCCL
      if (nccl_) return f(*nccl_);
#endif
#ifdef GEO_WITH_GLOO
      if (gloo_) return f(*gloo_);
#endif
      throw std::logic_error("no process group");
    } catch (const std::exception& e) {
      throw std::runtime_error("rank " + std::to_string(rank_) + " of " + std::to_string(size_) + ": " + what +
                               " failed: " + lost_processes() + " (or did not answer within run.distributed.timeout_s, " +
                               std::to_string(timeout_s_) + " s): " + message_of(e));
    }
  }

  // Which processes are gone: those on this host are checked by PID; rank 0 gone takes the
  // rendezvous with it.
  std::string lost_processes() {
    char host[256] = {0};
    ::gethostname(host, sizeof host - 1);
    std::string gone, unknown;
    const auto grace_end = std::chrono::steady_clock::now() + std::chrono::seconds(2);  // for all ranks together
    for (int r = 0; r < size_; ++r) {
      if (r == rank_) continue;
      try {
        const auto bytes = store_->get("geo/proc/" + std::to_string(r));
        const std::string v(bytes.begin(), bytes.end());
        const auto space = v.rfind(' ');
        const std::string h = v.substr(0, space);
        const pid_t pid = static_cast<pid_t>(std::atol(v.c_str() + space + 1));
        if (h != host) unknown += (unknown.empty() ? "" : ", ") + std::to_string(r);
        else if (!alive_after(pid, grace_end))
          gone += (gone.empty() ? "" : ", ") + std::to_string(r) + " (pid " + std::to_string(pid) + ")";
      } catch (const std::exception&) {
        return "rank 0 (the rendezvous host, " + master_ + ") is gone";
      }
    }
    if (!gone.empty()) return "rank " + gone + " exited";
    if (!unknown.empty()) return "a process exited or hung (ranks on other hosts: " + unknown + ")";
    return "another process exited or hung";
  }

  int rank_, size_, local_rank_, timeout_s_;
  std::string master_;
  std::string backend_;
  c10::intrusive_ptr<c10d::Store> store_;
#ifdef GEO_WITH_GLOO
  c10::intrusive_ptr<c10d::ProcessGroupGloo> gloo_;
#endif
#ifdef GEO_WITH_NCCL
  c10::intrusive_ptr<c10d::ProcessGroupNCCL> nccl_;
#endif
};

}  // namespace

std::unique_ptr<ProcessGroup> ProcessGroup::connect(const LaunchInfo& launch, const DistributedConfig& config,
                                                    const torch::Device& device) {
  spdlog::info("rank {} of {} ({}): joining the process group at {}:{}", launch.rank, launch.world_size,
               launch.launcher, launch.master_addr, launch.master_port);
  return std::make_unique<C10dGroup>(launch, config, device);
}

#else  // no c10d in this LibTorch

bool distributed_available() { return false; }
bool nccl_available() { return false; }

std::unique_ptr<ProcessGroup> ProcessGroup::connect(const LaunchInfo& launch, const DistributedConfig&,
                                                    const torch::Device&) {
  throw std::runtime_error("launched as rank " + std::to_string(launch.rank) + " of " +
                           std::to_string(launch.world_size) + " (" + launch.launcher +
                           ") but this geo was built without torch.distributed (c10d and gloo headers not found "
                           "at configure time; install libgloo-dev or use a LibTorch that ships them)");
}

#endif

void GradientAverager::build(const std::vector<torch::Tensor>& parameters) {
  bool same = parameters.size() == params_.size();
  for (size_t i = 0; same && i < parameters.size(); ++i) same = parameters[i].is_same(params_[i]);
  if (same && !buckets_.empty()) return;
  detach();
  params_ = parameters;
  buckets_.clear();
  bucket_of_.assign(params_.size(), 0);
  slot_of_.assign(params_.size(), 0);
  bytes_ = 0;
  int64_t size = 0;
  for (size_t k = params_.size(); k-- > 0;) {  // reverse: the order backward produces gradients in
    const auto& p = params_[k];
    const int64_t n = p.numel(), item = static_cast<int64_t>(p.element_size());
    if (buckets_.empty() || (size > 0 && (size + n) * item > bucket_bytes_)) {
      buckets_.emplace_back();
      size = 0;
    }
    Bucket& b = buckets_.back();
    bucket_of_[k] = buckets_.size() - 1;
    slot_of_[k] = b.members.size();
    b.members.push_back(k);
    b.offsets.push_back(size);
    size += n;
  }
  for (auto& b : buckets_) {
    int64_t n = 0;
    for (size_t m : b.members) n += params_[m].numel();
    b.flat = torch::zeros({n}, params_[b.members[0]].options().requires_grad(false));
    bytes_ += n * static_cast<int64_t>(b.flat.element_size());
  }
}

void GradientAverager::attach(const std::vector<torch::Tensor>& parameters) {
  build(parameters);
  if (!hooks_.empty()) return;
  for (size_t i = 0; i < params_.size(); ++i)
    hooks_.push_back(params_[i].register_hook([this, i](torch::Tensor grad) { mark_ready(i, grad); }));
}

void GradientAverager::detach() {
  for (size_t i = 0; i < hooks_.size(); ++i) params_[i].remove_hook(hooks_[i]);
  hooks_.clear();
}

void GradientAverager::begin_step() {
  ready_.assign(params_.size(), 0);
  for (auto& b : buckets_) {
    b.ready = 0;
    b.started = false;
    b.wait = nullptr;
  }
  next_ = 0;
  started_early_ = 0;
}

void GradientAverager::start(Bucket& b, bool poison) {
  if (poison) b.flat.fill_(std::numeric_limits<float>::quiet_NaN());
  b.wait = group_.start_all_reduce_sum(b.flat);
  b.started = true;
}

void GradientAverager::mark_ready(size_t index, const torch::Tensor& grad) {
  if (ready_.size() != params_.size() || ready_[index]) return;  // outside a step, or a second backward
  Bucket& b = buckets_[bucket_of_[index]];
  b.flat.narrow(0, b.offsets[slot_of_[index]], params_[index].numel()).copy_(grad.detach().reshape(-1));
  ready_[index] = 1;
  ++b.ready;
  // In bucket order only: every process starts the same collectives in the same order.
  while (next_ < buckets_.size() && buckets_[next_].ready == buckets_[next_].members.size()) {
    start(buckets_[next_++], false);
    ++started_early_;
  }
}

void GradientAverager::finish(bool poison) {
  // What backward did not produce: the gradient as it stands, else zeros.
  for (; next_ < buckets_.size(); ++next_) {
    Bucket& b = buckets_[next_];
    for (size_t j = 0; j < b.members.size(); ++j) {
      const size_t i = b.members[j];
      if (ready_[i]) continue;
      auto slot = b.flat.narrow(0, b.offsets[j], params_[i].numel());
      if (params_[i].grad().defined()) slot.copy_(params_[i].grad().detach().reshape(-1));
      else slot.zero_();
    }
    start(b, poison);
  }
  const double world = static_cast<double>(group_.size());
  for (auto& b : buckets_) {
    b.wait();
    b.flat.div_(world);
    for (size_t j = 0; j < b.members.size(); ++j) {
      auto& p = params_[b.members[j]];
      if (p.grad().defined()) p.mutable_grad().view(-1).copy_(b.flat.narrow(0, b.offsets[j], p.numel()));
    }
  }
  ready_.clear();
}

void GradientAverager::average(const std::vector<torch::Tensor>& parameters, bool poison) {
  build(parameters);
  begin_step();
  finish(poison);
}

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
  if (!launch.distributed()) return nullptr;
  return ProcessGroup::connect(launch, config, select_device(device_name));
}

torch::Device process_device(const std::string& name, const ProcessGroup* group) {
  const torch::Device d = select_device(name);
  if (group && d.is_cuda() && (name == "auto" || name == "cuda"))
    return select_device("cuda:" + std::to_string(group->local_rank()));
  return d;
}

int agreed_signal(ProcessGroup* group, int local, const torch::Device& device) {
  if (!group) return local;
  std::vector<torch::Tensor> flag{torch::full(
      {1}, local, torch::TensorOptions(torch::kInt32).device(group->backend() == "nccl" ? device : torch::kCPU))};
  group->all_reduce_max(flag);
  return flag[0].cpu().item<int>();
}

void check_same_config(ProcessGroup& group, const std::string& config_yaml, const torch::Device& device) {
  // Each process's own: where it writes and logs, its device and threads, where its copy of the data is.
  static const std::vector<std::string> own = {"run.name",    "run.dir",     "run.device",       "run.threads",
                                               "run.distributed.timeout_s", "data.root", "data.videos",
                                               "data.num_workers", "logging.level"};
  const auto configs = group.all_gather_strings("config", config_yaml);
  std::string report;
  for (int r = 1; r < group.size(); ++r) {
    const auto diff = config_differences(configs[0], configs[static_cast<size_t>(r)], own);
    if (!diff.empty()) report += "\n  rank " + std::to_string(r) + " vs rank 0: " + join_list(diff, "; ");
  }
  // Also the barrier that keeps rank 0's store alive until every process has read every config.
  if (agreed_signal(&group, report.empty() ? 0 : 1, device) != 0)
    throw std::runtime_error("rank " + std::to_string(group.rank()) + ": the processes were started with different "
                             "configurations (every rank must train the same run: same config and --set options):" + report);
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
