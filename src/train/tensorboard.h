// TensorBoard event files written without TensorFlow or protobuf: the TFRecord framing
// (length, masked CRC-32C of the length, payload, masked CRC-32C of the payload) around hand-encoded
// `Event` / `Summary` protocol-buffer messages (tensorflow/core/util/event.proto, summary.proto).
// Open with `tensorboard --logdir runs`. LibTorch-free.
#pragma once

#include <cstdint>
#include <fstream>
#include <string>

namespace geo {

// CRC-32C (Castagnoli), and TFRecord's mask of it: ((crc >> 15) | (crc << 17)) + 0xa282ead8.
uint32_t crc32c(const std::string& bytes);
uint32_t masked_crc32c(const std::string& bytes);

// The protobuf encodings TensorBoard reads (field numbers from event.proto / summary.proto):
//   Event { double wall_time = 1; int64 step = 2; string file_version = 3; Summary summary = 5;
//           SessionLog session_log = 6; }
//   Summary { repeated Value value = 1; }  Value { string tag = 1; float simple_value = 2;
//           Image image = 4; }  Image { int32 height = 1; int32 width = 2; int32 colorspace = 3;
//           bytes encoded_image_string = 4; }  SessionLog { SessionStatus status = 1; } (START = 1)
std::string encode_scalar_event(double wall_time, int64_t step, const std::string& tag, float value);
std::string encode_image_event(double wall_time, int64_t step, const std::string& tag, const std::string& png,
                               int height, int width, int channels);
// SessionLog START at `step`: TensorBoard then drops events of the same file set logged after
// `step` by an earlier, interrupted process (what a resumed run needs).
std::string encode_session_start_event(double wall_time, int64_t step);
std::string encode_file_version_event(double wall_time);

// One TFRecord: length (8 bytes LE), masked CRC of the length (4), payload, masked CRC of it (4).
std::string tfrecord(const std::string& payload);

// Appends events to <dir>/events.out.tfevents.<unix time>.<host>[.<n>] (a new file per writer, as
// TensorFlow does). Throws std::runtime_error naming the file when it cannot be written.
class EventWriter {
 public:
  explicit EventWriter(const std::string& dir);
  void add_scalar(const std::string& tag, int64_t step, double value);
  // `png`: a PNG file's bytes; channels 1 (grey), 3 (RGB) or 4 (RGBA).
  void add_image(const std::string& tag, int64_t step, const std::string& png, int height, int width, int channels);
  void add_session_start(int64_t step);
  void flush();
  const std::string& path() const { return path_; }

 private:
  void write(const std::string& event);
  std::string path_;
  std::ofstream out_;
};

}  // namespace geo
