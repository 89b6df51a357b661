// The TensorBoard event writer (train/tensorboard.h): CRC-32C, event bytes by hand, a file read back.
#include "train/tensorboard.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>

#include <unistd.h>

#include "tensorboard_reader.h"
#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

TEST(TensorBoard, Crc32cOfTheStandardCheckString) {
  EXPECT_EQ(crc32c("123456789"), 0xE3069283u);  // the CRC-32C check value (RFC 3720 B.4)
  EXPECT_EQ(crc32c(""), 0u);
  const uint32_t c = 0xE3069283u;
  EXPECT_EQ(masked_crc32c("123456789"), ((c >> 15) | (c << 17)) + 0xa282ead8u);
}

TEST(TensorBoard, ScalarEventBytesByHand) {
  // Event{wall_time 0.0 (field 1, fixed64), step 3 (field 2), summary (5){value (1){tag "a" (1),
  // simple_value 1.0f (2, fixed32)}}}.
  const std::string e = encode_scalar_event(0.0, 3, "a", 1.0f);
  const std::string want = std::string("\x09", 1) + std::string(8, '\0') + "\x10\x03" + "\x2a\x0a" + "\x0a\x08" +
                           "\x0a\x01"
                           "a" +
                           "\x15" + std::string("\x00\x00\x80\x3f", 4);
  EXPECT_EQ(e, want);
  // The TFRecord around it: 8-byte length, its masked CRC, the payload, its masked CRC.
  const std::string r = tfrecord(e);
  ASSERT_EQ(r.size(), 8 + 4 + e.size() + 4);
  EXPECT_EQ(static_cast<unsigned char>(r[0]), e.size());
  EXPECT_EQ(r.substr(12, e.size()), e);
}

TEST(TensorBoard, WriterFileReadsBack) {
  const auto dir = test::fresh_dir("tb");
  std::string path;
  {
    EventWriter w(dir);
    path = w.path();
    w.add_scalar("loss/total", 7, 0.25);
    w.add_scalar("lr", 8, 2e-4);
    w.add_image("s1/disp", 9, std::string("\x89PNG\r\n\x1a\n", 8) + std::string(300, 'x'), 4, 5, 3);
    w.add_session_start(6);
    w.flush();
  }
  EXPECT_EQ(fs::path(path).filename().string().rfind("events.out.tfevents.", 0), 0u);
  const auto ev = test::read_tensorboard_file(path);
  ASSERT_EQ(ev.size(), 5u);
  EXPECT_EQ(ev[0].file_version, "brain.Event:2");
  ASSERT_EQ(ev[1].values.size(), 1u);
  EXPECT_EQ(ev[1].step, 7);
  EXPECT_EQ(ev[1].values[0].tag, "loss/total");
  EXPECT_EQ(ev[1].values[0].simple_value, 0.25f);
  EXPECT_EQ(ev[2].values[0].simple_value, 2e-4f);
  const auto& img = ev[3].values[0];
  EXPECT_TRUE(img.has_image);
  EXPECT_EQ(img.tag, "s1/disp");
  EXPECT_EQ(ev[3].step, 9);
  EXPECT_EQ(img.height, 4);
  EXPECT_EQ(img.width, 5);
  EXPECT_EQ(img.colorspace, 3);
  EXPECT_EQ(img.png.size(), 308u);
  EXPECT_EQ(ev[4].session_status, 1);  // START
  EXPECT_EQ(ev[4].step, 6);
  EXPECT_GT(ev[1].wall_time, 1.7e9);  // seconds since 1970
}

}  // namespace
}  // namespace geo
