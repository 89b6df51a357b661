#include "core/zip_check.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <vector>

#include <caffe2/serialize/inline_container.h>
#include <c10/util/Exception.h>

namespace geo {
namespace {

// Slicing-by-8 tables of the reflected polynomial 0xEDB88320 (the classic byte table is t[0]).
const std::array<std::array<uint32_t, 256>, 8>& crc_tables() {
  static const auto tables = [] {
    std::array<std::array<uint32_t, 256>, 8> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; ++i)
      for (size_t s = 1; s < 8; ++s) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFF];
    return t;
  }();
  return tables;
}

uint16_t u16(const unsigned char* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }
uint32_t u32(const unsigned char* p) { return u16(p) | (static_cast<uint32_t>(u16(p + 2)) << 16); }
uint64_t u64(const unsigned char* p) { return u32(p) | (static_cast<uint64_t>(u32(p + 4)) << 32); }

class File {
 public:
  explicit File(const std::string& path) : path_(path), fd_(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {
    if (fd_ < 0) throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    size_ = ::fstat(fd_, &st) == 0 ? static_cast<uint64_t>(st.st_size) : 0;
  }
  ~File() { ::close(fd_); }
  File(const File&) = delete;
  File& operator=(const File&) = delete;
  uint64_t size() const { return size_; }
  // Reads exactly n bytes at `offset`; false past the end.
  bool read(uint64_t offset, void* out, size_t n) const {
    if (offset > size_ || n > size_ - offset) return false;
    auto* p = static_cast<unsigned char*>(out);
    while (n > 0) {
      const ssize_t r = ::pread(fd_, p, n, static_cast<off_t>(offset));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) throw std::runtime_error(path_ + ": read error: " + std::strerror(errno));
      p += r, offset += static_cast<uint64_t>(r), n -= static_cast<size_t>(r);
    }
    return true;
  }

 private:
  std::string path_;
  int fd_;
  uint64_t size_ = 0;
};

}  // namespace

uint32_t crc32(const void* data, size_t size, uint32_t crc) {
  const auto& t = crc_tables();
  const auto* p = static_cast<const unsigned char*>(data);
  crc = ~crc;
  for (; size >= 8; size -= 8, p += 8) {
    const uint32_t lo = crc ^ u32(p), hi = u32(p + 4);
    crc = t[7][lo & 0xFF] ^ t[6][(lo >> 8) & 0xFF] ^ t[5][(lo >> 16) & 0xFF] ^ t[4][lo >> 24] ^ t[3][hi & 0xFF] ^
          t[2][(hi >> 8) & 0xFF] ^ t[1][(hi >> 16) & 0xFF] ^ t[0][hi >> 24];
  }
  for (; size > 0; --size, ++p) crc = t[0][(crc ^ *p) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

bool verify_zip_checksums(const std::string& path) {
  const File f(path);
  // The end-of-central-directory record: the last 22 bytes (+ a comment of up to 64 KiB).
  const uint64_t tail_len = std::min<uint64_t>(f.size(), 22 + 65535);
  std::vector<unsigned char> tail(tail_len);
  if (tail_len < 22 || !f.read(f.size() - tail_len, tail.data(), tail_len)) return false;
  size_t eocd = tail_len - 22 + 1;
  while (eocd-- > 0)
    if (u32(&tail[eocd]) == 0x06054b50u) break;
  if (eocd > tail_len) return false;  // not a ZIP archive
  const std::string damaged = path + ": damaged file (";
  const std::string advice = "); it cannot be trusted: use another copy or an earlier checkpoint";
  uint64_t entries = u16(&tail[eocd + 10]), cd_size = u32(&tail[eocd + 12]), cd_offset = u32(&tail[eocd + 16]);
  if (entries == 0xFFFF || cd_size == 0xFFFFFFFFu || cd_offset == 0xFFFFFFFFu) {
    // ZIP64: the locator just before the record points at the ZIP64 end record.
    const uint64_t eocd_at = f.size() - tail_len + eocd;
    unsigned char loc[20], end64[56];
    if (eocd_at < 20 || !f.read(eocd_at - 20, loc, 20) || u32(loc) != 0x07064b50u || !f.read(u64(loc + 8), end64, 56) ||
        u32(end64) != 0x06064b50u)
      throw std::runtime_error(damaged + "its ZIP64 directory is unreadable" + advice);
    entries = u64(end64 + 32), cd_size = u64(end64 + 40), cd_offset = u64(end64 + 48);
  }
  if (cd_size > f.size() || entries > cd_size / 46 + 1)
    throw std::runtime_error(damaged + "its directory lies outside the file" + advice);
  std::vector<unsigned char> cd(cd_size);
  if (!f.read(cd_offset, cd.data(), cd_size)) throw std::runtime_error(damaged + "truncated directory" + advice);
  std::vector<unsigned char> buffer(1 << 20);
  struct Compressed {
    std::string name;
    uint32_t crc;
    uint64_t size;
  };
  std::vector<Compressed> compressed;
  size_t at = 0;
  for (uint64_t i = 0; i < entries; ++i) {
    if (at + 46 > cd.size() || u32(&cd[at]) != 0x02014b50u)
      throw std::runtime_error(damaged + "directory entry " + std::to_string(i) + " is corrupt" + advice);
    const unsigned char* e = &cd[at];
    const uint16_t method = u16(e + 10), name_len = u16(e + 28), extra_len = u16(e + 30), comment_len = u16(e + 32);
    const uint32_t crc = u32(e + 16);
    uint64_t comp = u32(e + 20), size = u32(e + 24), local = u32(e + 42);
    if (at + 46 + name_len + extra_len > cd.size())
      throw std::runtime_error(damaged + "directory entry " + std::to_string(i) + " is corrupt" + advice);
    const std::string name(reinterpret_cast<const char*>(e + 46), name_len);
    // ZIP64 extra field: the 64-bit values of whichever of the three fields are 0xFFFFFFFF.
    for (size_t x = 46 + name_len; x + 4 <= 46u + name_len + extra_len;) {
      const uint16_t id = u16(e + x), len = u16(e + x + 2);
      if (id == 0x0001) {
        size_t v = x + 4;
        if (size == 0xFFFFFFFFu && v + 8 <= x + 4 + len) size = u64(e + v), v += 8;
        if (comp == 0xFFFFFFFFu && v + 8 <= x + 4 + len) comp = u64(e + v), v += 8;
        if (local == 0xFFFFFFFFu && v + 8 <= x + 4 + len) local = u64(e + v);
      }
      x += 4 + len;
    }
    at += 46 + name_len + extra_len + comment_len;
    if (method != 0) {  // deflated (LibTorch's code/ records, or a re-packed archive): checked below
      compressed.push_back({name, crc, size});
      continue;
    }
    unsigned char lh[30];
    if (!f.read(local, lh, 30) || u32(lh) != 0x04034b50u)
      throw std::runtime_error(damaged + "record '" + name + "' has no header" + advice);
    uint64_t data = local + 30 + u16(lh + 26) + u16(lh + 28);
    if (comp != size || data > f.size() || size > f.size() - data)
      throw std::runtime_error(damaged + "record '" + name + "' is truncated" + advice);
    uint32_t c = 0;
    for (uint64_t left = size; left > 0;) {
      const size_t n = static_cast<size_t>(std::min<uint64_t>(left, buffer.size()));
      f.read(data, buffer.data(), n);
      c = crc32(buffer.data(), n, c);
      data += n, left -= n;
    }
    if (c != crc)
      throw std::runtime_error(damaged + "record '" + name + "' fails its CRC-32 check: bytes were altered" + advice);
  }
  if (!compressed.empty()) {
    // Inflated by LibTorch's own reader (which skips the CRCs), checked here. Its names leave out
    // the archive's top folder.
    try {
      caffe2::serialize::PyTorchStreamReader reader(path);
      for (const auto& r : compressed) {
        const auto slash = r.name.find('/');
        try {
          auto [data, n] = reader.getRecord(slash == std::string::npos ? r.name : r.name.substr(slash + 1));
          if (n != r.size || crc32(data.get(), n) != r.crc)
            throw std::runtime_error(damaged + "record '" + r.name + "' fails its CRC-32 check: bytes were altered" +
                                     advice);
        } catch (const c10::Error& e) {
          throw std::runtime_error(damaged + "record '" + r.name +
                                   "' cannot be inflated: " + e.what_without_backtrace() + advice);
        }
      }
    } catch (const c10::Error& e) {
      throw std::runtime_error(damaged + "LibTorch cannot open it: " + std::string(e.what_without_backtrace()) +
                               advice);
    }
  }
  return true;
}

}  // namespace geo
