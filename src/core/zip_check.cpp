#include "core/zip_check.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <future>
#include <stdexcept>
#include <vector>

#if defined(__x86_64__) && (defined(__clang__) || defined(__GNUC__))
#include <immintrin.h>
#define GEO_CRC32_CLMUL 1
#endif

#include <caffe2/serialize/inline_container.h>
#include <c10/util/Exception.h>

#include "core/files.h"

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

#ifdef GEO_CRC32_CLMUL
namespace {

// The inverted CRC register `crc` carried over `size` bytes (a multiple of 16, at least 64) by
// folding with carry-less multiplication: four 128-bit lanes folded 512 bits ahead, then into one,
// then reduced to 32 bits by Barrett's method (Gopal et al., "Fast CRC Computation for Generic
// Polynomials Using PCLMULQDQ Instruction", Intel 2009; the constants are x^k mod P for the
// reflected polynomial). ~10x the table loop's speed: the check of a 168 MB model file was the
// longest part of opening it.
// x * k folded onto next: (x.lo * k.lo) ^ (x.hi * k.hi) ^ next.
__attribute__((target("pclmul,sse4.1"))) inline __m128i fold(__m128i x, __m128i k, __m128i next) {
  return _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x, k, 0x00), _mm_clmulepi64_si128(x, k, 0x11)), next);
}

__attribute__((target("pclmul,sse4.1"))) uint32_t crc32_folded(const unsigned char* p, size_t size, uint32_t crc) {
  const __m128i k1k2 = _mm_set_epi64x(0x01c6e41596, 0x0154442bd4);  // x^(4*128+32), x^(4*128-32) mod P
  const __m128i k3k4 = _mm_set_epi64x(0x00ccaa009e, 0x01751997d0);  // x^(128+32), x^(128-32) mod P
  const __m128i k5 = _mm_set_epi64x(0, 0x0163cd6124);               // x^64 mod P
  const __m128i poly = _mm_set_epi64x(0x01f7011641, 0x01db710641);  // mu = floor(x^64 / P), P'
  const __m128i low32 = _mm_setr_epi32(~0, 0, ~0, 0);
  const auto load = [](const unsigned char* q) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(q)); };
  __m128i x1 = _mm_xor_si128(load(p), _mm_cvtsi32_si128(static_cast<int>(crc)));
  __m128i x2 = load(p + 16), x3 = load(p + 32), x4 = load(p + 48);
  p += 64, size -= 64;
  for (; size >= 64; p += 64, size -= 64) {
    x1 = fold(x1, k1k2, load(p));
    x2 = fold(x2, k1k2, load(p + 16));
    x3 = fold(x3, k1k2, load(p + 32));
    x4 = fold(x4, k1k2, load(p + 48));
  }
  x1 = fold(fold(fold(x1, k3k4, x2), k3k4, x3), k3k4, x4);
  for (; size >= 16; p += 16, size -= 16) x1 = fold(x1, k3k4, load(p));
  // 128 -> 64 bits, 64 -> 32 bits, then Barrett's reduction.
  x1 = _mm_xor_si128(_mm_srli_si128(x1, 8), _mm_clmulepi64_si128(x1, k3k4, 0x10));
  x1 = _mm_xor_si128(_mm_srli_si128(x1, 4), _mm_clmulepi64_si128(_mm_and_si128(x1, low32), k5, 0x00));
  __m128i q = _mm_clmulepi64_si128(_mm_and_si128(x1, low32), poly, 0x10);
  q = _mm_clmulepi64_si128(_mm_and_si128(q, low32), poly, 0x00);
  return static_cast<uint32_t>(_mm_extract_epi32(_mm_xor_si128(x1, q), 1));
}

bool has_clmul() {
  static const bool yes = __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("sse4.1");
  return yes;
}

}  // namespace
#endif

uint32_t crc32(const void* data, size_t size, uint32_t crc) {
  const auto& t = crc_tables();
  const auto* p = static_cast<const unsigned char*>(data);
  crc = ~crc;
#ifdef GEO_CRC32_CLMUL
  if (size >= 64 && has_clmul()) {
    const size_t folded = size & ~size_t{15};
    crc = crc32_folded(p, folded, crc);
    p += folded, size -= folded;
  }
#endif
  for (; size >= 8; size -= 8, p += 8) {
    const uint32_t lo = crc ^ u32(p), hi = u32(p + 4);
    crc = t[7][lo & 0xFF] ^ t[6][(lo >> 8) & 0xFF] ^ t[5][(lo >> 16) & 0xFF] ^ t[4][lo >> 24] ^ t[3][hi & 0xFF] ^
          t[2][(hi >> 8) & 0xFF] ^ t[1][(hi >> 16) & 0xFF] ^ t[0][hi >> 24];
  }
  for (; size > 0; --size, ++p) crc = t[0][(crc ^ *p) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

namespace {

// The error for a damaged archive: what is wrong, and that the file cannot be trusted.
std::runtime_error damaged(const std::string& path, const std::string& what) {
  return std::runtime_error(path + ": damaged file (" + what +
                            "); it cannot be trusted: use another copy or an earlier checkpoint");
}

// The central directory of the ZIP archive in `f` (ZIP64 included); nullopt when it is no ZIP
// archive; throws naming the file when the directory is damaged.
std::optional<std::vector<ZipRecord>> read_directory(const File& f, const std::string& path) {
  // The end-of-central-directory record: the last 22 bytes (+ a comment of up to 64 KiB).
  const uint64_t tail_len = std::min<uint64_t>(f.size(), 22 + 65535);
  std::vector<unsigned char> tail(tail_len);
  if (tail_len < 22 || !f.read(f.size() - tail_len, tail.data(), tail_len)) return std::nullopt;
  size_t eocd = tail_len - 22 + 1;
  while (eocd-- > 0)
    if (u32(&tail[eocd]) == 0x06054b50u) break;
  if (eocd > tail_len) return std::nullopt;  // not a ZIP archive
  uint64_t entries = u16(&tail[eocd + 10]), cd_size = u32(&tail[eocd + 12]), cd_offset = u32(&tail[eocd + 16]);
  if (entries == 0xFFFF || cd_size == 0xFFFFFFFFu || cd_offset == 0xFFFFFFFFu) {
    // ZIP64: the locator just before the record points at the ZIP64 end record.
    const uint64_t eocd_at = f.size() - tail_len + eocd;
    unsigned char loc[20], end64[56];
    if (eocd_at < 20 || !f.read(eocd_at - 20, loc, 20) || u32(loc) != 0x07064b50u || !f.read(u64(loc + 8), end64, 56) ||
        u32(end64) != 0x06064b50u)
      throw damaged(path, "its ZIP64 directory is unreadable");
    entries = u64(end64 + 32), cd_size = u64(end64 + 40), cd_offset = u64(end64 + 48);
  }
  if (cd_size > f.size() || entries > cd_size / 46 + 1) throw damaged(path, "its directory lies outside the file");
  std::vector<unsigned char> cd(cd_size);
  if (!f.read(cd_offset, cd.data(), cd_size)) throw damaged(path, "truncated directory");
  std::vector<ZipRecord> records;
  size_t at = 0;
  for (uint64_t i = 0; i < entries; ++i) {
    if (at + 46 > cd.size() || u32(&cd[at]) != 0x02014b50u)
      throw damaged(path, "directory entry " + std::to_string(i) + " is corrupt");
    const unsigned char* e = &cd[at];
    const uint16_t method = u16(e + 10), name_len = u16(e + 28), extra_len = u16(e + 30), comment_len = u16(e + 32);
    ZipRecord r;
    r.crc = u32(e + 16);
    uint64_t comp = u32(e + 20), size = u32(e + 24), local = u32(e + 42);
    if (at + 46 + name_len + extra_len > cd.size())
      throw damaged(path, "directory entry " + std::to_string(i) + " is corrupt");
    r.name.assign(reinterpret_cast<const char*>(e + 46), name_len);
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
    r.size = size;
    r.stored = method == 0;
    if (r.stored) {  // where its bytes lie: after its local header
      unsigned char lh[30];
      if (!f.read(local, lh, 30) || u32(lh) != 0x04034b50u)
        throw damaged(path, "record '" + r.name + "' has no header");
      r.offset = local + 30 + u16(lh + 26) + u16(lh + 28);
      if (comp != size || r.offset > f.size() || size > f.size() - r.offset)
        throw damaged(path, "record '" + r.name + "' is truncated");
    }
    records.push_back(std::move(r));
  }
  return records;
}

}  // namespace

std::optional<std::vector<ZipRecord>> zip_directory(const std::string& path) {
  const File f(path);
  return read_directory(f, path);
}

bool verify_zip_checksums(const std::string& path) {
  const File f(path);
  const auto records = read_directory(f, path);
  if (!records) return false;
  std::vector<unsigned char> buffer(1 << 20);
  std::vector<const ZipRecord*> compressed;
  for (const auto& r : *records) {
    if (!r.stored) {  // deflated (LibTorch's code/ records, or a re-packed archive): checked below
      compressed.push_back(&r);
      continue;
    }
    uint32_t c = 0;
    for (uint64_t left = r.size, data = r.offset; left > 0;) {
      const size_t n = static_cast<size_t>(std::min<uint64_t>(left, buffer.size()));
      f.read(data, buffer.data(), n);
      c = crc32(buffer.data(), n, c);
      data += n, left -= n;
    }
    if (c != r.crc) throw damaged(path, "record '" + r.name + "' fails its CRC-32 check: bytes were altered");
  }
  if (!compressed.empty()) {
    // Inflated by LibTorch's own reader (which skips the CRCs), checked here. Its names leave out
    // the archive's top folder.
    try {
      caffe2::serialize::PyTorchStreamReader reader(path);
      for (const auto* c : compressed) {
        const auto& r = *c;
        const auto slash = r.name.find('/');
        try {
          auto [data, n] = reader.getRecord(slash == std::string::npos ? r.name : r.name.substr(slash + 1));
          if (n != r.size || crc32(data.get(), n) != r.crc)
            throw damaged(path, "record '" + r.name + "' fails its CRC-32 check: bytes were altered");
        } catch (const c10::Error& e) {
          throw damaged(path, "record '" + r.name + "' cannot be inflated: " + e.what_without_backtrace());
        }
      }
    } catch (const c10::Error& e) {
      throw damaged(path, "LibTorch cannot open it: " + std::string(e.what_without_backtrace()));
    }
  }
  return true;
}

void read_while_checked(const std::string& path, const std::function<void()>& read) {
  const std::string why = unreadable_file_reason(path);
  if (!why.empty()) throw std::runtime_error(path + ": " + why);
  auto checked = std::async(std::launch::async, [&path] { verify_zip_checksums(path); });
  std::exception_ptr error;
  try {
    read();
  } catch (...) {  // (what LibTorch makes of damaged bytes too: std::out_of_range, ...)
    error = std::current_exception();
  }
  checked.get();
  if (error) std::rethrow_exception(error);
}

}  // namespace geo
