// Multi-process launch (train/distributed.h): the rank, world size and rendezvous address from the
// launcher's environment (torchrun's variables, Slurm's), and a free port for a local launch.
#include "train/distributed.h"

#include <cerrno>
#include <cstdlib>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

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
    if (!world)
      throw std::runtime_error("RANK is set but WORLD_SIZE is not: launch with torchrun --no-python, or set both");
    if (!rank)
      throw std::runtime_error("WORLD_SIZE is set but RANK is not: launch with torchrun --no-python, or set both");
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
    throw std::runtime_error(
        "MASTER_ADDR is not set (torchrun sets it; under SLURM export MASTER_ADDR=$(scontrol show "
        "hostnames \"$SLURM_JOB_NODELIST\" | head -n1) or give --master-addr)");
  if (const auto port = get("MASTER_PORT")) l.master_port = env_int("MASTER_PORT", *port, 1, 65535);
  return l;
}

}  // namespace geo
