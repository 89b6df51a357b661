#include "data/packed/packed.h"

#include "core/files.h"
#include "data/text_io.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>

namespace fs = std::filesystem;

namespace geo {

bool is_packed_cache(const std::string& dir) {
  std::ifstream in(dir + "/index.txt");
  std::string first;
  return in && std::getline(in, first) && first.rfind("geo-packed", 0) == 0;
}

namespace {
constexpr const char* kCacheFiles[] = {"/index.txt", "/frames.bin", "/frames.bin.tmp"};
}  // namespace

bool has_packed_cache_files(const std::string& dir) {
  std::error_code ec;
  for (const char* f : kCacheFiles)
    if (fs::exists(dir + f, ec)) return true;
  return false;
}

void remove_packed_cache_files(const std::string& dir) {
  for (const char* f : kCacheFiles) fs::remove(dir + f);
}

void check_packed_cache_complete(const std::string& dir) {
  std::error_code ec;
  if (fs::exists(dir + "/index.txt", ec)) return;  // PackedSnippets checks what it holds
  if (has_packed_cache_files(dir))
    throw std::runtime_error(
        "packed cache " + dir + " is incomplete: it has " +
        (fs::exists(dir + "/frames.bin", ec) ? "frames.bin" : "frames.bin.tmp") +
        " but no index.txt (geo_prepare did not finish): re-run geo_prepare, or remove the folder");
}

std::string new_pack_id() {
  std::random_device rd;
  const auto now = std::chrono::system_clock::now().time_since_epoch().count();
  std::ostringstream s;
  s << std::hex << now << "-" << rd() << rd();
  return s.str();
}

PackedWriter::PackedWriter(const std::string& dir, int64_t height, int64_t width, int64_t seq_length, std::string pack)
    : dir_(dir), pack_(pack.empty() ? new_pack_id() : std::move(pack)), height_(height), width_(width),
      seq_length_(seq_length) {
  if (pack_.find_first_of(" \t\r\n") != std::string::npos)
    throw std::invalid_argument("packed cache identifier '" + pack_ + "' holds white space");
  fs::create_directories(dir);
  frames_.open(dir + "/frames.bin.tmp", std::ios::binary | std::ios::trunc);
  if (!frames_) throw std::runtime_error(dir + "/frames.bin.tmp: cannot open for writing");
}

void PackedWriter::add(const Snippet& s) {
  TORCH_CHECK(s.frames.dim() == 4 && s.frames.size(0) == seq_length_ && s.frames.size(1) == 3 &&
                  s.frames.size(2) == height_ && s.frames.size(3) == width_,
              "snippet '", s.id, "' must be [", seq_length_, ",3,", height_, ",", width_, "], got ", s.frames.sizes());
  auto u8 = (s.frames.clamp(0, 1) * 255).round().to(torch::kUInt8).contiguous();
  frames_.write(reinterpret_cast<const char*>(u8.data_ptr<uint8_t>()), u8.numel());
  if (!frames_) throw std::runtime_error(dir_ + "/frames.bin.tmp: write failed (disk full?)");
  auto K = s.K.to(torch::kFloat64);
  intrinsics_.push_back(
      {K[0][0].item<double>(), K[1][1].item<double>(), K[0][2].item<double>(), K[1][2].item<double>()});
  ids_.push_back(s.id);
}

void PackedWriter::finish() {
  frames_.close();
  if (!frames_) throw std::runtime_error(dir_ + "/frames.bin.tmp: write failed");
  std::ostringstream idx;
  idx.precision(10);
  idx << "geo-packed " << kPackedFormatVersion << "\nheight " << height_ << "\nwidth " << width_ << "\nseq_length "
      << seq_length_ << "\ncount " << ids_.size() << "\npack " << pack_ << "\n";
  for (size_t i = 0; i < ids_.size(); ++i)
    idx << intrinsics_[i][0] << " " << intrinsics_[i][1] << " " << intrinsics_[i][2] << " " << intrinsics_[i][3] << " "
        << ids_[i] << "\n";
  fs::rename(dir_ + "/frames.bin.tmp", dir_ + "/frames.bin");
  write_file_atomic(dir_ + "/index.txt", idx.str());
}

PackedSnippets::PackedSnippets(const std::string& dir) : dir_(dir) {
  check_packed_cache_complete(dir);
  const std::string index = dir + "/index.txt";
  std::istringstream in(read_text_file(index));
  std::string line, key;
  int format_version = 0;
  std::getline(in, line);
  if (line.rfind("geo-packed", 0) != 0)
    throw std::runtime_error(index + ": not a geo packed cache (first line '" + line + "')");
  {
    std::istringstream ls(line.substr(10));
    int version = 0;
    std::string rest;
    if (!(ls >> version) || (ls >> rest))
      throw std::runtime_error(index + ": malformed first line '" + line + "' (expected 'geo-packed " +
                               std::to_string(kPackedFormatVersion) + "')");
    if (version != 1 && version != kPackedFormatVersion)
      throw std::runtime_error(index + ": packed cache format version " + std::to_string(version) +
                               ", this geo reads 1 and " + std::to_string(kPackedFormatVersion) +
                               " (re-run geo_prepare with this geo)");
    format_version = version;
  }
  int64_t count = -1;
  const char* keys[] = {"height", "width", "seq_length", "count"};
  int k = 0;
  for (auto* field : {&height_, &width_, &seq_length_, &count}) {
    std::getline(in, line);
    std::istringstream ls(line);
    if (!(ls >> key >> *field) || key != keys[k] || *field < 0)
      throw std::runtime_error(index + ": malformed header line '" + line + "' (expected '" + keys[k] + " N')");
    ++k;
  }
  // Bounds that keep the record size arithmetic far from overflow: 16k x 16k images, 64 frames.
  if (height_ < 1 || width_ < 1 || height_ > 16384 || width_ > 16384 || seq_length_ < 2 || seq_length_ > 64 ||
      count > std::numeric_limits<int64_t>::max() / (seq_length_ * 3 * height_ * width_))
    throw std::runtime_error(index + ": implausible header (height " + std::to_string(height_) + ", width " +
                             std::to_string(width_) + ", seq_length " + std::to_string(seq_length_) + ", count " +
                             std::to_string(count) + ")");
  int line_no = 5;
  if (format_version >= 2) {
    std::getline(in, line);
    std::istringstream ls(line);
    std::string rest;
    if (!(ls >> key >> pack_) || key != "pack" || (ls >> rest))
      throw std::runtime_error(index + ": malformed header line '" + line + "' (expected 'pack ID')");
    ++line_no;
  }
  while (std::getline(in, line)) {
    ++line_no;
    if (trim(line).empty()) continue;
    std::istringstream ls(line);
    std::array<double, 4> k{};
    if (!(ls >> k[0] >> k[1] >> k[2] >> k[3]))
      throw std::runtime_error(index + " line " + std::to_string(line_no) + ": expected 'fx fy cx cy id'");
    std::string id;
    std::getline(ls, id);
    // Intrinsics of an image at most 16k pixels wide: positive focal lengths, finite values.
    const bool plausible = k[0] > 0 && k[1] > 0 && std::all_of(k.begin(), k.end(), [](double x) {
                             return std::isfinite(x) && std::abs(x) < 1e6;
                           });
    if (!plausible)
      throw std::runtime_error(index + " line " + std::to_string(line_no) + ": implausible intrinsics '" + trim(line) +
                               "'");
    intrinsics_.push_back(k);
    ids_.push_back(trim(id));
  }
  if (static_cast<int64_t>(ids_.size()) != count)
    throw std::runtime_error(index + ": header says " + std::to_string(count) + " snippets, found " +
                             std::to_string(ids_.size()));
  const std::string bin = dir + "/frames.bin";
  const auto expected = static_cast<uintmax_t>(count * seq_length_ * 3 * height_ * width_);
  if (!fs::exists(bin) || fs::file_size(bin) != expected)
    throw std::runtime_error(bin + ": missing or wrong size (expected " + std::to_string(expected) +
                             " bytes; re-run geo_prepare)");
  frames_.open(bin, std::ios::binary);
}

Snippet PackedSnippets::get(size_t index) const {
  const int64_t record = seq_length_ * 3 * height_ * width_;
  auto u8 = torch::empty({seq_length_, 3, height_, width_}, torch::kUInt8);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    frames_.seekg(static_cast<std::streamoff>(index) * record);
    frames_.read(reinterpret_cast<char*>(u8.data_ptr<uint8_t>()), record);
    if (!frames_) throw std::runtime_error(dir_ + "/frames.bin: cannot read snippet " + std::to_string(index));
  }
  const auto& k = intrinsics_.at(index);
  Snippet s;
  s.frames = u8.to(torch::kFloat32).div_(255);
  s.K = torch::tensor({k[0], 0.0, k[2], 0.0, k[1], k[3], 0.0, 0.0, 1.0}, torch::kFloat32).reshape({3, 3});
  s.id = ids_[index];
  return s;
}

}  // namespace geo
