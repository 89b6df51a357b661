// Packed cache (geo_prepare): resized snippets stored as one uint8 record file plus a text index,
// read by the trainer without OpenCV and without decoding PNGs. Layout of a cache folder:
//   index.txt   "geo-packed 2", "height H", "width W", "seq_length L", "count N", "pack ID", then one
//               line a snippet: "fx fy cx cy id..." (intrinsics at H x W). ID names the geo_prepare
//               run: train/ and val/ of one cache must carry the same (version 1 had no pack line).
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

// The version in index.txt's first line; this geo writes 2 and reads 1 and 2, and refuses any other
// version with a message.
constexpr int kPackedFormatVersion = 2;

// A fresh identifier for the caches one geo_prepare run writes (time and random bits, hex).
std::string new_pack_id();

// True when `dir/index.txt` starts with the packed-cache header.
bool is_packed_cache(const std::string& dir);
// Whether `dir` holds any file of a packed cache (index.txt, frames.bin, or geo_prepare's
// frames.bin.tmp): such a folder is read as a cache, and a damaged one is an error, never skipped.
bool has_packed_cache_files(const std::string& dir);
// Removes those files from `dir` (geo_prepare, for a part an earlier run left); the folder stays.
void remove_packed_cache_files(const std::string& dir);
// Throws std::runtime_error naming `dir` when it holds frames but no index.txt (an interrupted
// geo_prepare).
void check_packed_cache_complete(const std::string& dir);

class PackedWriter {
 public:
  // Writes into `dir` (created); files appear under their final names only in finish(). `pack`:
  // the run's identifier (new_pack_id() when empty), the same for a cache's train/ and val/.
  PackedWriter(const std::string& dir, int64_t height, int64_t width, int64_t seq_length, std::string pack = "");
  void add(const Snippet& s);
  void finish();
  size_t count() const { return ids_.size(); }

 private:
  std::string dir_, pack_;
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
  // The geo_prepare run that wrote it ("" for a version-1 cache).
  const std::string& pack() const { return pack_; }

 private:
  std::string dir_, pack_;
  int64_t height_ = 0, width_ = 0, seq_length_ = 0;
  std::vector<std::string> ids_;
  std::vector<std::array<double, 4>> intrinsics_;
  mutable std::mutex mutex_;
  mutable std::ifstream frames_;
};

}  // namespace geo
