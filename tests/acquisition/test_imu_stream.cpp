// SPDX-License-Identifier: BSD-3-Clause
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <mutex>
#include <thread>
#include <vector>

#include "acquisition/imu_stream.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::acq {
namespace {

/// A writer that records what it gets; can be slowed down or made to fail.
class FakeWriter final : public log::SessionLogWriter {
 public:
  Status set_metadata(const std::string&, const std::string&) override { return {}; }
  Result<int> add_imu_stream(const ImuStreamInfo&) override { return 3; }
  Result<int> add_camera_stream(const CameraStreamInfo&) override { return 4; }
  Status append_imu(int stream_id, std::span<const ImuSample> samples) override {
    if (delay_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
    std::lock_guard<std::mutex> lock(mutex);
    if (fail_after >= 0 && static_cast<long>(samples_seen.size()) >= fail_after) {
      return make_error(Errc::kIo, "disk full");
    }
    for (const auto& s : samples) samples_seen.push_back(s);
    ids.push_back(stream_id);
    ++appends;
    return {};
  }
  Status append_frame(int, const CameraFrame&) override { return {}; }
  Status append_event(const log::Event& e) override {
    std::lock_guard<std::mutex> lock(mutex);
    events.push_back(e);
    return {};
  }
  Status flush() override {
    ++flushes;
    return {};
  }
  Status close() override { return {}; }

  std::mutex mutex;
  std::vector<ImuSample> samples_seen;
  std::vector<int> ids;
  std::vector<log::Event> events;
  int appends = 0;
  std::atomic<int> flushes{0};
  int delay_ms = 0;
  long fail_after = -1;
};

std::vector<ImuSample> make_samples(std::int64_t first, std::size_t n) {
  std::vector<ImuSample> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    v[i].t_ns = (first + static_cast<std::int64_t>(i)) * 1'000'000;
    v[i].gyro.x() = static_cast<double>(first + static_cast<std::int64_t>(i));
  }
  return v;
}

TEST(ImuStream, FeedsConsumersAndLogInOrder) {
  FakeWriter writer;
  ImuStream stream;
  auto a = stream.add_consumer("display", 4096);
  auto b = stream.add_consumer("detector", 4096);
  ASSERT_TRUE(stream.start_log(writer, 3).ok());
  for (int k = 0; k < 100; ++k) {
    const auto batch = make_samples(k * 10, 10);
    stream.publish(batch);
  }
  log::Event e;
  e.kind = "note";
  e.message = "hello";
  stream.post_event(e);
  ASSERT_TRUE(stream.stop().ok());

  ASSERT_EQ(writer.samples_seen.size(), 1000u);
  for (std::size_t i = 0; i < 1000; ++i) EXPECT_EQ(writer.samples_seen[i].gyro.x(), static_cast<double>(i));
  for (int id : writer.ids) EXPECT_EQ(id, 3);
  ASSERT_EQ(writer.events.size(), 1u);
  EXPECT_EQ(writer.events[0].message, "hello");
  EXPECT_GE(writer.flushes.load(), 1);
  for (auto* c : {a.get(), b.get()}) {
    std::vector<ImuSample> out(2000);
    ASSERT_EQ(c->pop(out), 1000u);
    for (std::size_t i = 0; i < 1000; ++i) EXPECT_EQ(out[i].gyro.x(), static_cast<double>(i));
    EXPECT_EQ(c->dropped(), 0u);
  }
  const auto st = stream.stats();
  EXPECT_EQ(st.published, 1000u);
  EXPECT_EQ(st.log_written, 1000u);
  EXPECT_EQ(st.log_dropped, 0u);
  EXPECT_EQ(st.events_written, 1u);
}

// A consumer that does not read loses samples, and the loss is counted; the others, and the
// log, are unaffected.
TEST(ImuStream, FullConsumerRingIsCountedNotSilent) {
  FakeWriter writer;
  ImuStream stream;
  auto slow = stream.add_consumer("slow", 64);
  auto fast = stream.add_consumer("fast", 64);
  ASSERT_TRUE(stream.start_log(writer, 3).ok());
  std::vector<ImuSample> out(64);
  std::uint64_t fast_got = 0;
  for (int k = 0; k < 50; ++k) {
    stream.publish(make_samples(k * 10, 10));
    fast_got += fast->pop(out);
  }
  ASSERT_TRUE(stream.stop().ok());
  EXPECT_EQ(slow->delivered(), 64u);
  EXPECT_EQ(slow->dropped(), 500u - 64u);
  EXPECT_EQ(fast_got, 500u);
  EXPECT_EQ(fast->dropped(), 0u);
  EXPECT_EQ(writer.samples_seen.size(), 500u);
  const auto st = stream.stats();
  ASSERT_EQ(st.consumers.size(), 2u);
  EXPECT_EQ(st.consumers[0].name, "slow");
  EXPECT_EQ(st.consumers[0].dropped, 436u);
}

// A stalled storage must not stall the producer: publish() returns at once, the log ring
// absorbs what fits, and the overflow is counted.
TEST(ImuStream, SlowWriterNeverBlocksProducer) {
  FakeWriter writer;
  writer.delay_ms = 50;
  ImuStreamOptions o;
  o.log_queue_capacity = 256;
  o.log_batch_max = 64;
  ImuStream stream(o);
  ASSERT_TRUE(stream.start_log(writer, 3).ok());
  for (int k = 0; k < 100; ++k) stream.publish(make_samples(k * 10, 10));
  // All 1000 were offered while the writer sat in its first 50 ms append.
  const auto mid = stream.stats();
  EXPECT_EQ(mid.published, 1000u);
  EXPECT_GT(mid.log_dropped, 0u);
  ASSERT_TRUE(stream.stop().ok());
  const auto st = stream.stats();
  EXPECT_EQ(st.log_written + st.log_dropped, 1000u);
  EXPECT_EQ(writer.samples_seen.size(), st.log_written);
  // What was written is in order, without duplicates.
  for (std::size_t i = 1; i < writer.samples_seen.size(); ++i) {
    EXPECT_LT(writer.samples_seen[i - 1].t_ns, writer.samples_seen[i].t_ns);
  }
}

TEST(ImuStream, WriteErrorIsReportedByStop) {
  FakeWriter writer;
  writer.fail_after = 100;
  ImuStreamOptions o;
  o.log_batch_max = 50;
  ImuStream stream(o);
  ASSERT_TRUE(stream.start_log(writer, 3).ok());
  for (int k = 0; k < 30; ++k) {
    stream.publish(make_samples(k * 10, 10));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const auto s = stream.stop();
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, Errc::kIo);
  EXPECT_NE(s.error().message.find("disk full"), std::string::npos);
  EXPECT_TRUE(stream.log_failed());
  const auto st = stream.stats();
  EXPECT_EQ(st.log_written + st.log_dropped, 300u);
}

// Producer and consumers on their own threads: nothing lost when the rings are large enough.
TEST(ImuStream, ThreadedConsumersSeeEverySample) {
  FakeWriter writer;
  ImuStream stream;
  auto c1 = stream.add_consumer("c1", 1 << 14);
  ASSERT_TRUE(stream.start_log(writer, 3).ok());
  constexpr std::size_t kTotal = 20'000;
  std::atomic<bool> ok{true};
  std::thread reader([&] {
    std::vector<ImuSample> out(256);
    std::size_t got = 0;
    while (got < kTotal) {
      const std::size_t n = c1->pop(out);
      for (std::size_t i = 0; i < n; ++i) {
        if (out[i].gyro.x() != static_cast<double>(got + i)) ok = false;
      }
      got += n;
      if (n == 0) std::this_thread::yield();
    }
  });
  for (std::size_t k = 0; k < kTotal / 8; ++k) {
    stream.publish(make_samples(static_cast<std::int64_t>(k * 8), 8));
    if (k % 64 == 0) std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  reader.join();
  ASSERT_TRUE(stream.stop().ok());
  EXPECT_TRUE(ok);
  EXPECT_EQ(c1->dropped(), 0u);
  EXPECT_EQ(writer.samples_seen.size(), kTotal);
}

// With the SQLite session log: what the stream writes reads back.
TEST(ImuStream, WritesASessionLog) {
  const std::string path = test::scratch_dir() + "/stream.imulog";
  auto w = log::SessionLogWriter::create(path);
  ASSERT_TRUE(w.ok()) << w.error().message;
  ImuStreamInfo info;
  info.name = "imu0";
  info.rate_hz = 1000;
  auto id = (*w)->add_imu_stream(info);
  ASSERT_TRUE(id.ok());
  {
    ImuStream stream;
    ASSERT_TRUE(stream.start_log(**w, *id).ok());
    for (int k = 0; k < 50; ++k) stream.publish(make_samples(k * 20, 20));
    ASSERT_TRUE(stream.stop().ok());
  }
  ASSERT_TRUE((*w)->close().ok());
  auto r = log::SessionLogReader::open(path);
  ASSERT_TRUE(r.ok()) << r.error().message;
  auto samples = (*r)->read_imu(*id);
  ASSERT_TRUE(samples.ok());
  ASSERT_EQ(samples->size(), 1000u);
  EXPECT_EQ((*samples)[999].gyro.x(), 999.0);
  EXPECT_EQ((*samples)[999].t_ns, 999'000'000);
}

}  // namespace
}  // namespace imucal::acq
