// The process group (train/distributed.h) on LibTorch's c10d: rendezvous over its TCPStore, Gloo
// on the CPU and NCCL on CUDA, collectives with timeouts that name a lost process; without c10d,
// an error that says so.
#include "train/distributed.h"

#include "core/config.h"
#include "core/logging.h"
#include "core/runtime.h"

#include <spdlog/spdlog.h>
#include <torch/version.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <thread>

#include <signal.h>
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
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
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
          l.rank == 0
              ? "rank 0 could not open the rendezvous at " + where + " (MASTER_ADDR:MASTER_PORT; port in use, " +
                    "e.g. by another process also launched with RANK=0?) or not all " + std::to_string(l.world_size) +
                    " processes arrived within " + std::to_string(config.timeout_s) +
                    " s (each process needs its own RANK, " + "0.." + std::to_string(l.world_size - 1) +
                    "): " + message_of(e)
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
      throw std::runtime_error("rank " + std::to_string(rank_) + ": the rendezvous at " + where +
                               " failed: " + message_of(e));
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
        throw std::runtime_error("rank " + std::to_string(rank_) + ": rank " + std::to_string(r) +
                                 " did not register at " + where + " within run.distributed.timeout_s (" +
                                 std::to_string(timeout_s_) + " s): " + message_of(e));
      }
      // Rank 0's store must outlive the others' reads: each says it has read rank 0's world size,
      // and rank 0 waits for that (briefly) before leaving on a mismatch, so that every process
      // reports the mismatch instead of a closed connection.
      if (rank_ != 0) store_->set("geo/world_size_read/" + std::to_string(rank_), std::vector<uint8_t>{1});
      if (other != std::to_string(size_)) {
        if (rank_ == 0) {
          try {
            store_->wait({"geo/world_size_read/" + std::to_string(r)},
                         std::min(time_left(), std::chrono::milliseconds(5000)));
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
      throw std::runtime_error("rank " + std::to_string(l.rank) + ": could not form the " + backend +
                               " process group of " + std::to_string(l.world_size) + " at " + where + ": " +
                               message_of(e));
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
  void all_reduce_sum(std::vector<torch::Tensor>& tensors) override {
    all_reduce(tensors, c10d::ReduceOp::SUM, "all-reduce");
  }
  std::function<void()> start_all_reduce_sum(torch::Tensor& tensor) override {
    c10::intrusive_ptr<c10d::Work> work;
    std::vector<torch::Tensor> one{tensor};
    guarded("all-reduce", [&](auto& pg) { work = pg.allreduce(one, c10d::AllreduceOptions()); });
    return [this, work] { guarded("all-reduce", [&](auto&) { work->wait(); }); };
  }
  void all_reduce_max(std::vector<torch::Tensor>& tensors) override {
    all_reduce(tensors, c10d::ReduceOp::MAX, "all-reduce (max)");
  }

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
      throw std::runtime_error("rank " + std::to_string(rank_) + ": waiting for '" + key +
                               "' from rank 0 failed: " + message_of(e));
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
      throw std::runtime_error("rank " + std::to_string(rank_) + ": waiting for '" + key + "' of rank " +
                               std::to_string(r) + " failed: " + lost_processes() + ": " + message_of(e));
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

  template <class F>
  void guarded(const char* what, F&& f) {
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
                               " failed: " + lost_processes() +
                               " (or did not answer within run.distributed.timeout_s, " + std::to_string(timeout_s_) +
                               " s): " + message_of(e));
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

}  // namespace geo
