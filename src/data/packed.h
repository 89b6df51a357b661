// Packed cache (geo_prepare): resized snippets stored as one uint8 record file plus a text index,
// read by the trainer without OpenCV and without decoding PNGs. Layout of a cache folder:
//   index.txt   "geo-packed 1", "height H", "width W", "seq_length L", "count N", then one line a
//               snippet: "fx fy cx cy id..." (intrinsics at H x W)
//   frames.bin  N records of L*3*H*W bytes (uint8, [L,3,H,W], RGB)
#pragma once

#include "data/snippets.h"

#include <array>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace geo {

// The version in index.txt's first line; a cache of another version is refused with a message.
constexpr int kPackedFormatVersion = 1;

// True when `dir/index.txt` starts with the packed-cache header.
bool is_packed_cache(const std::string& dir);
// Whether `dir` holds any file of a packed cache (index.txt, frames.bin, or geo_prepare's
// frames.bin.tmp): such a folder is read as a cache, and a damaged one is an error, never skipped.
bool has_packed_cache_files(const std::string& dir);
// Throws std::runtime_error naming `dir` when it holds frames but no index.txt (an interrupted
// geo_prepare).
void check_packed_cache_complete(const std::string& dir);

class PackedWriter {
 public:
  // Writes into `dir` (created); files appear under their final names only in finish().
  PackedWriter(const std::string& dir, int64_t height, int64_t width, int64_t seq_length);
  void add(const Snippet& s);
  void finish();
  size_t count() const { return ids_.size(); }

 private:
  std::string dir_;
  int64_t height_, width_, seq_length_;
  std::ofstream frames_;
  std::vector<std::string> ids_;
  std::vector<std::array<double, 4>> intrinsics_;
};

class PackedSnippets : public SnippetSource {
 public:
  explicit PackedSnippets(const std::string& dir);
  size_t size() const override { return ids_.size(); }
  Snippet get(size_t index) const override;
  std::string id(size_t index) const override { return ids_.at(index); }
  int64_t seq_length() const override { return seq_length_; }
  int64_t height() const { return height_; }
  int64_t width() const { return width_; }

 private:
  std::string dir_;
  int64_t height_ = 0, width_ = 0, seq_length_ = 0;
  std::vector<std::string> ids_;
  std::vector<std::array<double, 4>> intrinsics_;
  mutable std::mutex mutex_;
  mutable std::ifstream frames_;
};

}  // namespace geo
