// Saving and loading a module's parameters and buffers by name (state-dict keys are a file
// format). Loading is strict: missing or unexpected keys and shape mismatches are errors that
// list the offending names; nothing is partially loaded.
#pragma once

#include <torch/torch.h>

#include <optional>
#include <string>

namespace geo {

// Writes every named parameter and buffer of `module` to `path` (save_archive: durable, atomic).
void save_state(const torch::nn::Module& module, const std::string& path);

// Loads `path` into `module`, copying onto the module's device and dtype.
void load_state(torch::nn::Module& module, const std::string& path);

// Writes an archive to `path` durably (core/files.h: write_file_durable): a failed write names the
// path and the OS error and leaves the file that stood there untouched.
void save_archive(torch::serialize::OutputArchive& archive, const std::string& path);

// Opens a LibTorch archive (state file, checkpoint); a missing, truncated or foreign file throws
// std::runtime_error naming the path (never LibTorch's stack trace).
torch::serialize::InputArchive open_archive(const std::string& path);

// Same, into / out of an archive under a key prefix (for checkpoints holding several networks).
// `floating`: store floating-point tensors in this type (e.g. kHalf for small exported models);
// read_state converts them back to the module's type.
void write_state(const torch::nn::Module& module, torch::serialize::OutputArchive& archive,
                 std::optional<torch::ScalarType> floating = std::nullopt);
// `allow_empty`: a tensor the file keeps empty (0 elements: a kernel an int8 model file leaves out)
// is taken as it is, whatever the module's shape.
void read_state(torch::nn::Module& module, torch::serialize::InputArchive& archive, const std::string& what,
                bool allow_empty = false);

}  // namespace geo
