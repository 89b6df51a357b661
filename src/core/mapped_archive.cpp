#include "core/mapped_archive.h"

#include "core/files.h"
#include "core/zip_check.h"

#include <caffe2/serialize/inline_container.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <stdexcept>

namespace geo {
namespace {

constexpr const char* kArchive = "geo_archive.pt";
constexpr const char* kIndex = "mapped.index";
constexpr const char* kTensors = "mapped/";

// A record's name without the container's top folder (LibTorch's writer puts every record under one).
std::string without_top_folder(const std::string& name) {
  const auto slash = name.find('/');
  return slash == std::string::npos ? name : name.substr(slash + 1);
}

// The file mapped read-only; unmapped when the last tensor viewing it goes.
struct Mapping {
  const unsigned char* data = nullptr;
  size_t size = 0;
  Mapping(const std::string& path, size_t expected) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) != 0 || static_cast<uint64_t>(st.st_size) != expected) {
      ::close(fd);
      throw std::runtime_error(path + ": changed while it was being opened");
    }
    size = expected;
    // MAP_POPULATE: the pages that are in the page cache are mapped in one call rather than fault
    // by fault (a read-only mapping: nothing is copied).
    void* p = size == 0 ? nullptr : ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE | MAP_POPULATE, fd, 0);
    const int error = errno;
    ::close(fd);
    if (p == MAP_FAILED) throw std::runtime_error(path + ": cannot map it into memory: " + std::strerror(error));
    data = static_cast<const unsigned char*>(p);
  }
  ~Mapping() {
    if (data) ::munmap(const_cast<unsigned char*>(data), size);
  }
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;
};

// The index's line for one tensor: "name type d0 d1 ...".
std::string index_line(const std::string& name, const torch::Tensor& t) {
  std::string line = name + " " + std::to_string(static_cast<int>(t.scalar_type()));
  for (const auto d : t.sizes()) line += " " + std::to_string(d);
  return line + "\n";
}

}  // namespace

void save_archive_with_mapped(torch::serialize::OutputArchive& archive,
                              const std::map<std::string, torch::Tensor>& tensors, const std::string& path) {
  std::string bytes;
  archive.save_to([&](const void* data, size_t n) {
    bytes.append(static_cast<const char*>(data), n);
    return n;
  });
  std::string index;
  for (const auto& [name, t] : tensors) {
    TORCH_CHECK(!name.empty() && name.find_first_of(" \t\r\n") == std::string::npos,
                "a mapped tensor's name may not be empty or hold spaces, tabs or line breaks: '", name, "'");
    TORCH_CHECK(t.defined() && t.device().is_cpu() && !t.is_quantized(), "mapped tensor '", name,
                "' must be a CPU tensor of a plain type");
    index += index_line(name, t);
  }
  write_file_durable(path, [&](const ChunkWriter& write) {
    caffe2::serialize::PyTorchStreamWriter writer([&](const void* data, size_t n) {
      write(data, n);
      return n;
    });
    writer.writeRecord(kArchive, bytes.data(), bytes.size());
    writer.writeRecord(kIndex, index.data(), index.size());
    for (const auto& [name, t] : tensors) {
      const auto dense = t.contiguous();
      writer.writeRecord(kTensors + name, dense.data_ptr(), dense.nbytes());
    }
    writer.writeEndOfFile();
  });
}

bool has_mapped_tensors(const std::string& path) {
  if (!unreadable_file_reason(path).empty()) return false;
  const auto records = zip_directory(path);
  if (!records) return false;
  for (const auto& r : *records)
    if (without_top_folder(r.name) == kArchive) return true;
  return false;
}

MappedArchive open_mapped_archive(const std::string& path) {
  MappedArchive out;
  read_while_checked(path, [&] {
    const auto records = zip_directory(path);
    if (!records) throw std::runtime_error(path + ": not a ZIP archive");
    std::map<std::string, ZipRecord> by_name;
    for (const auto& r : *records) by_name[without_top_folder(r.name)] = r;
    const auto record = [&](const std::string& name) -> const ZipRecord& {
      const auto it = by_name.find(name);
      if (it == by_name.end()) throw std::runtime_error(path + ": no record '" + name + "'");
      if (!it->second.stored) throw std::runtime_error(path + ": record '" + name + "' is compressed");
      return it->second;
    };
    const auto file_size = static_cast<size_t>(std::filesystem::file_size(path));
    const auto mapping = std::make_shared<Mapping>(path, file_size);
    const auto bytes = [&](const ZipRecord& r) { return reinterpret_cast<const char*>(mapping->data + r.offset); };
    const auto& archive = record(kArchive);
    try {
      out.archive.load_from(bytes(archive), archive.size);
    } catch (const c10::Error& e) {
      const std::string what = e.what_without_backtrace();
      throw std::runtime_error(path + ": its archive is not readable (" + what.substr(0, what.find('\n')) + ")");
    }
    const auto& index = record(kIndex);
    std::istringstream lines(std::string(bytes(index), index.size));
    std::string line;
    for (int number = 1; std::getline(lines, line); ++number) {
      std::istringstream fields(line);
      std::string name;
      int type = -1;
      fields >> name >> type;
      const std::string where = path + ": " + kIndex + " line " + std::to_string(number);
      if (name.empty() || type < 0 || type >= static_cast<int>(c10::ScalarType::NumOptions))
        throw std::runtime_error(where + ": not 'name type sizes...': '" + line + "'");
      const auto dtype = static_cast<c10::ScalarType>(type);
      if (c10::isQIntType(dtype) || dtype == c10::ScalarType::Undefined)
        throw std::runtime_error(where + ": tensor '" + name + "' of type " + std::to_string(type) +
                                 ", not a plain one");
      const auto& r = record(kTensors + name);
      std::vector<int64_t> sizes;
      uint64_t numel = 1;
      for (int64_t d; fields >> d;) {
        if (d < 0 || (d > 0 && numel > r.size / static_cast<uint64_t>(d)))
          throw std::runtime_error(where + ": tensor '" + name + "' has sizes beyond its record");
        sizes.push_back(d);
        numel *= static_cast<uint64_t>(d);
      }
      if (!fields.eof()) throw std::runtime_error(where + ": not 'name type sizes...': '" + line + "'");
      if (numel * c10::elementSize(dtype) != r.size)
        throw std::runtime_error(where + ": tensor '" + name + "' of " + std::to_string(numel) +
                                 " elements, its record " + std::to_string(r.size) + " bytes");
      void* data = const_cast<char*>(bytes(r));
      out.tensors.by_name[name] = torch::from_blob(
          data, sizes, [mapping](void*) {}, torch::TensorOptions().dtype(dtype));
    }
  });
  return out;
}

std::map<std::string, torch::Tensor> MappedTensors::under(const std::string& prefix) const {
  std::map<std::string, torch::Tensor> out;
  for (auto it = by_name.lower_bound(prefix); it != by_name.end() && it->first.rfind(prefix, 0) == 0; ++it)
    out[it->first.substr(prefix.size())] = it->second;
  return out;
}

}  // namespace geo
