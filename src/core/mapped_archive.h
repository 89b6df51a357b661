// A LibTorch archive with tensors beside it that are read where they lie in the file (memory-mapped,
// not copied): geo's int8 model files keep their int8 kernels (most of the file) this way, so that
// opening one touches no fresh memory for them and a second process shares the same pages.
//
// The file is a ZIP container written by LibTorch's own writer (records uncompressed and 64-byte
// aligned, each with its CRC-32):
//   geo_archive.pt   the LibTorch archive (torch::serialize::OutputArchive's bytes)
//   mapped.index     one line per tensor: name, scalar type (c10::ScalarType's number), sizes
//   mapped/<name>    the tensor's bytes (contiguous, the machine's byte order)
#pragma once

#include <torch/torch.h>

#include <map>
#include <string>

namespace geo {

// Writes `archive` and `tensors` (CPU; their bytes as they are, made contiguous) to `path` durably
// (core/files.h: write_file_durable). Names may not hold spaces, tabs or line breaks.
void save_archive_with_mapped(torch::serialize::OutputArchive& archive,
                              const std::map<std::string, torch::Tensor>& tensors, const std::string& path);

// Whether `path` is such a container (false for plain LibTorch archives and for files that are no
// ZIP archive).
bool has_mapped_tensors(const std::string& path);

// Such a file, opened: its archive read, every record's CRC-32 checked (core/zip_check.h), its
// tensors viewed in place: read-only views of the file's pages that keep the mapping alive (writing
// into one is a fault). Every error names the file.
struct MappedTensors {
  std::map<std::string, torch::Tensor> by_name;
  // The tensors whose names begin with `prefix`, the prefix taken off their names.
  std::map<std::string, torch::Tensor> under(const std::string& prefix) const;
};
struct MappedArchive {
  torch::serialize::InputArchive archive;
  MappedTensors tensors;
};
MappedArchive open_mapped_archive(const std::string& path);

}  // namespace geo
