// A reader of TensorBoard event files for the tests: TFRecord framing with both masked CRC-32C
// checks, and a protobuf decoder of the Event / Summary fields geo writes. Any violation fails the
// calling test through gtest's ADD_FAILURE and stops reading.
#pragma once

#include "train/tensorboard.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "test_util.h"

namespace geo::test {

struct TbValue {
  std::string tag;
  bool has_simple = false;
  float simple_value = 0;
  bool has_image = false;
  int64_t height = 0, width = 0, colorspace = 0;
  std::string png;
};

struct TbEvent {
  double wall_time = 0;
  int64_t step = 0;
  std::string file_version;
  int64_t session_status = 0;
  std::vector<TbValue> values;
};

class ProtoReader {
 public:
  explicit ProtoReader(const std::string& b) : b_(b) {}
  bool done() const { return pos_ >= b_.size(); }
  uint64_t varint() {
    uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (pos_ >= b_.size()) throw std::runtime_error("truncated varint");
      const auto c = static_cast<unsigned char>(b_[pos_++]);
      v |= static_cast<uint64_t>(c & 0x7F) << shift;
      if (!(c & 0x80)) return v;
    }
    throw std::runtime_error("varint too long");
  }
  template <class T>
  T fixed() {
    if (pos_ + sizeof(T) > b_.size()) throw std::runtime_error("truncated fixed field");
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string bytes() {
    const auto n = varint();
    if (pos_ + n > b_.size()) throw std::runtime_error("truncated bytes field");
    std::string s = b_.substr(pos_, n);
    pos_ += n;
    return s;
  }
  void skip(int wire) {
    if (wire == 0) varint();
    else if (wire == 1) fixed<uint64_t>();
    else if (wire == 2) bytes();
    else if (wire == 5) fixed<uint32_t>();
    else throw std::runtime_error("unknown wire type " + std::to_string(wire));
  }

 private:
  const std::string& b_;
  size_t pos_ = 0;
};

inline TbValue decode_value(const std::string& b) {
  TbValue v;
  ProtoReader r(b);
  while (!r.done()) {
    const auto key = r.varint();
    const int field = static_cast<int>(key >> 3), wire = static_cast<int>(key & 7);
    if (field == 1 && wire == 2) v.tag = r.bytes();
    else if (field == 2 && wire == 5) {
      v.has_simple = true;
      v.simple_value = r.fixed<float>();
    } else if (field == 4 && wire == 2) {
      v.has_image = true;
      const std::string img = r.bytes();
      ProtoReader ir(img);
      while (!ir.done()) {
        const auto k = ir.varint();
        const int f = static_cast<int>(k >> 3), w = static_cast<int>(k & 7);
        if (f == 1 && w == 0) v.height = static_cast<int64_t>(ir.varint());
        else if (f == 2 && w == 0) v.width = static_cast<int64_t>(ir.varint());
        else if (f == 3 && w == 0) v.colorspace = static_cast<int64_t>(ir.varint());
        else if (f == 4 && w == 2) v.png = ir.bytes();
        else ir.skip(w);
      }
    } else r.skip(wire);
  }
  return v;
}

inline TbEvent decode_event(const std::string& b) {
  TbEvent e;
  ProtoReader r(b);
  while (!r.done()) {
    const auto key = r.varint();
    const int field = static_cast<int>(key >> 3), wire = static_cast<int>(key & 7);
    if (field == 1 && wire == 1) e.wall_time = r.fixed<double>();
    else if (field == 2 && wire == 0) e.step = static_cast<int64_t>(r.varint());
    else if (field == 3 && wire == 2) e.file_version = r.bytes();
    else if (field == 5 && wire == 2) {
      const std::string summary = r.bytes();
      ProtoReader sr(summary);
      while (!sr.done()) {
        const auto k = sr.varint();
        if ((k >> 3) == 1 && (k & 7) == 2) e.values.push_back(decode_value(sr.bytes()));
        else sr.skip(static_cast<int>(k & 7));
      }
    } else if (field == 6 && wire == 2) {
      const std::string log = r.bytes();
      ProtoReader lr(log);
      while (!lr.done()) {
        const auto k = lr.varint();
        if ((k >> 3) == 1 && (k & 7) == 0) e.session_status = static_cast<int64_t>(lr.varint());
        else lr.skip(static_cast<int>(k & 7));
      }
    } else r.skip(wire);
  }
  return e;
}

// Every record of one file, its framing and CRCs checked.
inline std::vector<TbEvent> read_tensorboard_file(const std::string& path) {
  const std::string data = read_file(path);
  std::vector<TbEvent> events;
  size_t pos = 0;
  while (pos < data.size()) {
    if (pos + 12 > data.size()) {
      ADD_FAILURE() << path << ": truncated record header at " << pos;
      break;
    }
    const std::string len_bytes = data.substr(pos, 8);
    uint64_t len;
    uint32_t len_crc, data_crc;
    std::memcpy(&len, len_bytes.data(), 8);
    std::memcpy(&len_crc, data.data() + pos + 8, 4);
    if (len_crc != masked_crc32c(len_bytes)) {
      ADD_FAILURE() << path << ": length CRC mismatch at " << pos;
      break;
    }
    if (pos + 12 + len + 4 > data.size()) {
      ADD_FAILURE() << path << ": truncated record at " << pos;
      break;
    }
    const std::string payload = data.substr(pos + 12, len);
    std::memcpy(&data_crc, data.data() + pos + 12 + len, 4);
    if (data_crc != masked_crc32c(payload)) {
      ADD_FAILURE() << path << ": data CRC mismatch at " << pos;
      break;
    }
    try {
      events.push_back(decode_event(payload));
    } catch (const std::exception& e) {
      ADD_FAILURE() << path << ": bad protobuf at " << pos << ": " << e.what();
      break;
    }
    pos += 12 + len + 4;
  }
  return events;
}

// All events.out.tfevents.* files of a folder, in name order.
inline std::vector<TbEvent> read_tensorboard_dir(const std::string& dir) {
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().rfind("events.out.tfevents.", 0) == 0) files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  EXPECT_FALSE(files.empty()) << "no events file in " << dir;
  std::vector<TbEvent> all;
  for (const auto& f : files) {
    auto ev = read_tensorboard_file(f);
    EXPECT_FALSE(ev.empty()) << f;
    if (!ev.empty()) {
      EXPECT_EQ(ev.front().file_version, "brain.Event:2") << f;
    }
    all.insert(all.end(), ev.begin(), ev.end());
  }
  return all;
}

}  // namespace geo::test
