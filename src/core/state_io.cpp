#include "core/state_io.h"

#include "core/files.h"
#include "core/zip_check.h"

#include <filesystem>
#include <set>
#include <stdexcept>
#include <unistd.h>

namespace geo {

namespace {
std::map<std::string, torch::Tensor> state_of(const torch::nn::Module& module) {
  std::map<std::string, torch::Tensor> state;
  for (const auto& p : module.named_parameters(/*recurse=*/true)) state[p.key()] = p.value();
  for (const auto& b : module.named_buffers(/*recurse=*/true)) state[b.key()] = b.value();
  return state;
}

std::string list(const std::vector<std::string>& names, size_t max_shown = 20) {
  std::string s;
  for (size_t i = 0; i < names.size() && i < max_shown; ++i) s += (i ? ", " : "") + names[i];
  if (names.size() > max_shown) s += ", ... (" + std::to_string(names.size()) + " in all)";
  return s;
}
}  // namespace

void write_state(const torch::nn::Module& module, torch::serialize::OutputArchive& archive,
                 std::optional<torch::ScalarType> floating) {
  for (const auto& [name, tensor] : state_of(module)) {
    auto t = tensor.detach().cpu();
    if (floating && t.is_floating_point()) t = t.to(*floating);
    archive.write(name, t);
  }
}

void read_state(torch::nn::Module& module, torch::serialize::InputArchive& archive, const std::string& what,
                bool allow_empty) {
  auto state = state_of(module);
  const auto keys = archive.keys();
  const std::set<std::string> in_file(keys.begin(), keys.end());
  std::vector<std::string> missing, unexpected, mismatched;
  for (const auto& kv : state)
    if (!in_file.count(kv.first)) missing.push_back(kv.first);
  for (const auto& k : keys)
    if (!state.count(k)) unexpected.push_back(k);
  std::map<std::string, torch::Tensor> loaded;
  for (const auto& [name, target] : state) {
    if (!in_file.count(name)) continue;
    torch::Tensor t;
    archive.read(name, t);
    if (t.sizes() != target.sizes() && !(allow_empty && t.numel() == 0)) {
      std::ostringstream os;
      os << name << " (file " << t.sizes() << ", model " << target.sizes() << ")";
      mismatched.push_back(os.str());
    }
    loaded[name] = t;
  }
  // Weights that are NaN or infinite (a diverged run saved with valid CRCs) would predict nothing
  // but NaN, written out as zero depth: refused by name.
  std::vector<std::string> non_finite;
  // (A finite sum, one pass, says so for all but sums beyond float's range, checked element by element.)
  for (const auto& [name, t] : loaded)
    if (t.is_floating_point() && !std::isfinite(t.sum().item<double>()) && !torch::isfinite(t).all().item<bool>())
      non_finite.push_back(name);
  if (!non_finite.empty())
    throw std::runtime_error(what + ": holds NaN or infinite values in " + list(non_finite) +
                             " (nothing was loaded; a run that diverged: use an earlier checkpoint)");
  if (!missing.empty() || !unexpected.empty() || !mismatched.empty()) {
    std::string msg = what + ": does not match the network (nothing was loaded)";
    if (!missing.empty()) msg += "\n  missing keys: " + list(missing);
    if (!unexpected.empty()) msg += "\n  unexpected keys: " + list(unexpected);
    if (!mismatched.empty()) msg += "\n  shape mismatches: " + list(mismatched);
    throw std::runtime_error(msg);
  }
  torch::NoGradGuard no_grad;
  for (auto& [name, target] : state) {
    const auto& t = loaded[name];
    // A tensor of the file that owns its storage and is laid out as the target is taken as it is
    // (no second copy of the weights, no pass over them); any other (float16 in a model file,
    // another device, a view) is copied.
    const bool whole = t.is_contiguous() && t.storage_offset() == 0 &&
                       t.storage().nbytes() == static_cast<size_t>(t.numel()) * t.element_size();
    if (t.numel() == 0 && target.numel() != 0) target.set_data(torch::empty({0}, target.options()));
    else if (whole && t.dtype() == target.dtype() && t.device() == target.device()) target.set_data(t);
    else target.copy_(t);
  }
}

void save_archive(torch::serialize::OutputArchive& archive, const std::string& path) {
  // Streamed through write_file_durable's checked writes: LibTorch's own file writer throws from a
  // destructor when the disk fills up, which aborts the process.
  write_file_durable(path, [&](const ChunkWriter& write) {
    archive.save_to([&](const void* data, size_t n) {
      write(data, n);
      return n;
    });
  });
}

void save_state(const torch::nn::Module& module, const std::string& path) {
  torch::serialize::OutputArchive archive;
  write_state(module, archive);
  save_archive(archive, path);
}

torch::serialize::InputArchive open_archive(const std::string& path) {
  torch::serialize::InputArchive archive;
  read_while_checked(path, [&] {
    try {
      archive.load_from(path);
    } catch (const c10::Error& e) {
      const std::string what = e.what_without_backtrace();
      throw std::runtime_error(path + ": not a readable geo/LibTorch file, truncated or of another kind (" +
                               what.substr(0, what.find('\n')) + ")");
    }
  });
  return archive;
}

void load_state(torch::nn::Module& module, const std::string& path) {
  auto archive = open_archive(path);
  read_state(module, archive, path);
}

}  // namespace geo
