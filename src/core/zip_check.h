// Integrity of LibTorch archives (checkpoints, model files): they are ZIP files whose records carry
// CRC-32s, which LibTorch's reader does not check (its miniz is built without the check), so a file
// with bytes altered inside a tensor would load and give slightly different numbers.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace geo {

// The CRC-32 of ZIP (IEEE 802.3, reflected), continuing from `crc` (0 for a new one).
uint32_t crc32(const void* data, size_t size, uint32_t crc = 0);

// Checks every record of the ZIP archive `path` against the CRC-32 and sizes of its central
// directory (ZIP64 included); compressed records (LibTorch deflates its code/ records) are
// inflated by LibTorch's reader and then checked. Throws std::runtime_error naming the file and the damaged record;
// a file that is no ZIP archive at all is left to the reader (returns false); true when checked.
bool verify_zip_checksums(const std::string& path);

// Runs `read` (which reads the archive `path`) while verify_zip_checksums checks it on another
// thread: bytes altered inside a tensor would load silently, as LibTorch's reader skips the CRCs.
// A damaged file is said first, then `read`'s own error. A missing file, a folder, a device or a
// FIFO is refused before either starts, naming it.
void read_while_checked(const std::string& path, const std::function<void()>& read);

// A record of a ZIP archive's central directory.
struct ZipRecord {
  std::string name;     // as the directory lists it (LibTorch's archives: under their top folder)
  uint32_t crc = 0;     // its CRC-32 as the directory lists it
  uint64_t size = 0;    // bytes, uncompressed
  bool stored = false;  // kept as it is (not compressed)
  uint64_t offset = 0;  // stored records: where their bytes begin in the file (checked to lie in it)
};
// The records of the ZIP archive `path` (ZIP64 included), nothing checked against their CRCs;
// nullopt for a file that is no ZIP archive; throws std::runtime_error naming the file when its
// directory or a stored record's header is damaged.
std::optional<std::vector<ZipRecord>> zip_directory(const std::string& path);

}  // namespace geo
