#include "train/tensorboard.h"

#include <unistd.h>

#include <array>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace geo {
namespace {

const std::array<uint32_t, 256>& crc_table() {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? (c >> 1) ^ 0x82F63B78u : c >> 1;  // reflected 0x1EDC6F41
      t[i] = c;
    }
    return t;
  }();
  return table;
}

// Protocol-buffer wire format: key = (field << 3) | wire type; 0 varint, 1 fixed64, 2 bytes, 5 fixed32.
void varint(std::string& out, uint64_t v) {
  while (v >= 0x80) {
    out.push_back(static_cast<char>((v & 0x7F) | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<char>(v));
}
void key(std::string& out, int field, int wire) { varint(out, static_cast<uint64_t>(field) << 3 | wire); }
template <class T>
void fixed(std::string& out, T v) {  // little-endian (x86, ARM)
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}
void bytes_field(std::string& out, int field, const std::string& bytes) {
  key(out, field, 2);
  varint(out, bytes.size());
  out += bytes;
}
void varint_field(std::string& out, int field, int64_t v) {
  key(out, field, 0);
  varint(out, static_cast<uint64_t>(v));
}

std::string event(double wall_time, int64_t step) {
  std::string e;
  key(e, 1, 1);
  fixed(e, wall_time);
  varint_field(e, 2, step);
  return e;
}

std::string with_summary_value(std::string e, const std::string& value) {
  std::string summary;
  bytes_field(summary, 1, value);
  bytes_field(e, 5, summary);
  return e;
}

double now() { return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count(); }

}  // namespace

uint32_t crc32c(const std::string& bytes) {
  const auto& t = crc_table();
  uint32_t c = 0xFFFFFFFFu;
  for (unsigned char b : bytes) c = t[(c ^ b) & 0xFF] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

uint32_t masked_crc32c(const std::string& bytes) {
  const uint32_t c = crc32c(bytes);
  return ((c >> 15) | (c << 17)) + 0xa282ead8u;
}

std::string tfrecord(const std::string& payload) {
  std::string len;
  fixed(len, static_cast<uint64_t>(payload.size()));
  std::string out = len;
  fixed(out, masked_crc32c(len));
  out += payload;
  fixed(out, masked_crc32c(payload));
  return out;
}

std::string encode_scalar_event(double wall_time, int64_t step, const std::string& tag, float value) {
  std::string v;
  bytes_field(v, 1, tag);
  key(v, 2, 5);
  fixed(v, value);
  return with_summary_value(event(wall_time, step), v);
}

std::string encode_image_event(double wall_time, int64_t step, const std::string& tag, const std::string& png,
                               int height, int width, int channels) {
  std::string image;
  varint_field(image, 1, height);
  varint_field(image, 2, width);
  varint_field(image, 3, channels);
  bytes_field(image, 4, png);
  std::string v;
  bytes_field(v, 1, tag);
  bytes_field(v, 4, image);
  return with_summary_value(event(wall_time, step), v);
}

std::string encode_session_start_event(double wall_time, int64_t step) {
  std::string log;
  varint_field(log, 1, 1);  // SessionLog.status = START
  std::string e = event(wall_time, step);
  bytes_field(e, 6, log);
  return e;
}

std::string encode_file_version_event(double wall_time) {
  std::string e = event(wall_time, 0);
  bytes_field(e, 3, "brain.Event:2");
  return e;
}

EventWriter::EventWriter(const std::string& dir) {
  std::filesystem::create_directories(dir);
  char host[256] = "localhost";
  gethostname(host, sizeof host - 1);
  const std::string base = dir + "/events.out.tfevents." + std::to_string(static_cast<long long>(now())) + "." + host;
  path_ = base;
  for (int n = 2; std::filesystem::exists(path_); ++n) path_ = base + "." + std::to_string(n);
  out_.open(path_, std::ios::binary);
  if (!out_) throw std::runtime_error("cannot write TensorBoard events file " + path_);
  write(encode_file_version_event(now()));
}

void EventWriter::add_scalar(const std::string& tag, int64_t step, double value) {
  write(encode_scalar_event(now(), step, tag, static_cast<float>(value)));
}

void EventWriter::add_image(const std::string& tag, int64_t step, const std::string& png, int height, int width,
                            int channels) {
  write(encode_image_event(now(), step, tag, png, height, width, channels));
}

void EventWriter::add_session_start(int64_t step) { write(encode_session_start_event(now(), step)); }

void EventWriter::flush() {
  out_.flush();
  if (!out_) throw std::runtime_error("cannot write TensorBoard events file " + path_);
}

void EventWriter::write(const std::string& e) {
  out_ << tfrecord(e);
  if (!out_) throw std::runtime_error("cannot write TensorBoard events file " + path_);
}

}  // namespace geo
