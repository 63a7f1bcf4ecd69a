// SPDX-License-Identifier: BSD-3-Clause
// The MPU-6000 through the kernel's inv-mpu6050 IIO driver, without a kernel: a fake sysfs tree
// laid out as Linux 6.1's driver makes it (attributes, scan_elements, buffer/) and a FIFO
// standing for /dev/iio:deviceN, written with scans in the driver's layout (big-endian 16-bit
// data at scan indices 0..6, a little-endian 64-bit timestamp at index 7, 24 bytes a scan).
// tests/qemu/iio_guest.cpp meets the real driver.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <thread>

#include "acquisition/iio_acquisition.hpp"
#include "acquisition/recorder.hpp"
#include "app/rig/rig.hpp"
#include "drivers/iio/iio_imu.hpp"
#include "log/session_log.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;
using drivers::iio::IioImu;
using drivers::iio::IioImuOptions;
using drivers::iio::IioScan;

struct FakeIio {
  std::string root;  // holds sys/ and dev/
  std::string sys() const { return root + "/sys"; }
  std::string dev() const { return root + "/dev"; }
  std::string dir() const { return sys() + "/iio:device0"; }
  std::string attr(const std::string& name) const { return dir() + "/" + name; }
  std::string read(const std::string& name) const {
    std::string s = test::read_file(attr(name));
    while (!s.empty() && s.back() == '\n') s.pop_back();
    return s;
  }
};

// A tree as inv-mpu6050 makes it for an MPU-6000 on I2C bus 1 at 0x68, buffer off, the
// kernel's defaults (realtime stamps, 50 Hz, +-2 g, +-2000 deg/s).
// `base` is the test's scratch folder (test::scratch_dir() empties it: call that once a test).
FakeIio make_fake_iio(const std::string& base, const std::string& sub, const std::string& chip = "mpu6000",
                      bool buffer = true) {
  FakeIio f{base + "/" + sub};
  fs::remove_all(f.root);
  // As sysfs has it: /sys/bus/iio/devices/iio:device0 links to the device under its parent.
  const std::string real = f.root + "/devices/i2c-1/1-0068/iio:device0";
  fs::create_directories(real);
  fs::create_directories(f.sys());
  fs::create_directory_symlink(real, f.dir());
  fs::create_directories(f.dev());
  const std::vector<std::pair<std::string, std::string>> attrs = {
      {"name", chip},
      {"current_timestamp_clock", "realtime"},
      {"sampling_frequency", "50"},
      {"in_accel_scale", "0.000598"},
      {"in_anglvel_scale", "0.001064724"},
      {"in_temp_scale", "2.941176"},
      {"in_temp_offset", "12420"},
  };
  for (const auto& [k, v] : attrs) test::write_file(f.attr(k), v + "\n");
  // As the kernel's show copies it: with the NUL of sizeof("realtime\n").
  test::write_file(f.attr("current_timestamp_clock"), std::string("realtime\n\0", 10));
  for (const char* axis : {"x", "y", "z"}) {
    test::write_file(f.attr(std::string("in_accel_") + axis + "_calibbias"), "0\n");
    test::write_file(f.attr(std::string("in_anglvel_") + axis + "_calibbias"), "0\n");
  }
  if (buffer) {
    fs::create_directories(f.dir() + "/buffer");
    fs::create_directories(f.dir() + "/scan_elements");
    for (const auto& [k, v] : std::vector<std::pair<std::string, std::string>>{
             {"enable", "0"}, {"length", "480"}, {"watermark", "1"}})
      test::write_file(f.attr("buffer/" + k), v + "\n");
    const std::vector<std::pair<std::string, int>>
        channels = {{"in_accel_x", 0},   {"in_accel_y", 1},   {"in_accel_z", 2},   {"in_temp", 3},
                    {"in_anglvel_x", 4}, {"in_anglvel_y", 5}, {"in_anglvel_z", 6}, {"in_timestamp", 7},
                    {"in_magn_x", 8}};  // a channel imucal does not read (off after open)
    for (const auto& [c, index] : channels) {
      const std::string base = f.attr("scan_elements/" + c);
      test::write_file(base + "_en", c == "in_magn_x" ? "1\n" : "0\n");
      test::write_file(base + "_index", std::to_string(index) + "\n");
      test::write_file(base + "_type", c == "in_timestamp" ? "le:s64/64>>0\n" : "be:s16/16>>0\n");
    }
    EXPECT_EQ(::mkfifo((f.dev() + "/iio:device0").c_str(), 0600), 0);
  }
  return f;
}

IioImuOptions fake_options(const FakeIio& f) {
  IioImuOptions o;
  o.sysfs_root = f.sys();
  o.dev_root = f.dev();
  o.rate_hz = 200;
  o.accel_range = drivers::mpu6000::AccelRange::k4g;
  o.gyro_range = drivers::mpu6000::GyroRange::k500dps;
  return o;
}

// One scan in the driver's layout: accel 0..5, temp 6..7, gyro 8..13 (big-endian), padding,
// timestamp 16..23 (little-endian).
std::string encode_scan(const IioScan& s) {
  std::string b(24, '\0');
  auto put16 = [&](std::size_t at, std::int16_t v) {
    b[at] = static_cast<char>((static_cast<std::uint16_t>(v) >> 8) & 0xff);
    b[at + 1] = static_cast<char>(static_cast<std::uint16_t>(v) & 0xff);
  };
  for (std::size_t i = 0; i < 3; ++i) {
    put16(2 * i, s.accel[i]);
    put16(8 + 2 * i, s.gyro[i]);
  }
  put16(6, s.temp);
  for (std::size_t i = 0; i < 8; ++i)
    b[16 + i] = static_cast<char>((static_cast<std::uint64_t>(s.t_ns) >> (8 * i)) & 0xff);
  return b;
}

IioScan scan_at(TimeNs t_ns, std::int16_t k) {
  IioScan s;
  s.accel = {k, static_cast<std::int16_t>(-k), 8192};
  s.gyro = {static_cast<std::int16_t>(k / 2), -300, 32767};
  s.temp = -1234;
  s.t_ns = t_ns;
  return s;
}

// The writer's end of the FIFO, opened after the reader (IioImu::open) so that it does not block.
struct FifoWriter {
  int fd = -1;
  explicit FifoWriter(const FakeIio& f) {
    fd = ::open((f.dev() + "/iio:device0").c_str(), O_WRONLY | O_CLOEXEC);
  }
  ~FifoWriter() {
    if (fd >= 0) ::close(fd);
  }
  void write(const std::string& bytes) const {
    ASSERT_EQ(::write(fd, bytes.data(), bytes.size()), static_cast<ssize_t>(bytes.size()));
  }
};

TEST(IioImu, FindsTheKernelsDeviceAndNamesItsBus) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "a");
  const auto found = drivers::iio::find_inv_mpu_devices(f.sys());
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].id, "iio:device0");
  EXPECT_EQ(found[0].name, "mpu6000");
  EXPECT_EQ(found[0].parent, "1-0068");
  EXPECT_TRUE(found[0].has_buffer);
  EXPECT_TRUE(drivers::iio::find_inv_mpu_devices(f.root + "/nothing-here").empty());
  EXPECT_EQ(drivers::iio::bus_parent_name("/dev/i2c-1", true, 0x68), "1-0068");
  EXPECT_EQ(drivers::iio::bus_parent_name("/dev/i2c-10", true, 0x69), "10-0069");
  EXPECT_EQ(drivers::iio::bus_parent_name("/dev/spidev0.1", false, 0), "spi0.1");
  EXPECT_EQ(drivers::iio::bus_parent_name("/dev/ttyS0", false, 0), "");
}

TEST(IioImu, ScanTypesAndLayoutFollowTheKernel) {
  drivers::iio::ScanElement e;
  ASSERT_TRUE(drivers::iio::parse_scan_type("be:s16/16>>0", e));
  EXPECT_TRUE(e.big_endian);
  EXPECT_TRUE(e.is_signed);
  ASSERT_TRUE(drivers::iio::parse_scan_type("le:u12/16>>4", e));
  EXPECT_FALSE(e.big_endian);
  EXPECT_EQ(e.shift, 4);
  EXPECT_FALSE(drivers::iio::parse_scan_type("be:s16/16X2>>0", e));
  EXPECT_FALSE(drivers::iio::parse_scan_type("be:s20/16>>0", e));
  EXPECT_FALSE(drivers::iio::parse_scan_type("nonsense", e));
  // Seven 16-bit channels and a timestamp: the timestamp aligned to 8, 24 bytes.
  std::vector<drivers::iio::ScanElement> els(8);
  for (int i = 0; i < 8; ++i) {
    els[static_cast<std::size_t>(i)].index = 7 - i;  // out of order: sorted by index
    els[static_cast<std::size_t>(i)].storage_bits = i == 0 ? 64 : 16;
  }
  EXPECT_EQ(drivers::iio::layout_scan(els), 24u);
  EXPECT_EQ(els.back().offset, 16u);
  EXPECT_EQ(els[3].offset, 6u);
  // Accel only and a timestamp: 6 bytes, padded to 8, 16 in all.
  std::vector<drivers::iio::ScanElement> small(4);
  for (int i = 0; i < 4; ++i) {
    small[static_cast<std::size_t>(i)].index = i;
    small[static_cast<std::size_t>(i)].storage_bits = i == 3 ? 64 : 16;
  }
  EXPECT_EQ(drivers::iio::layout_scan(small), 16u);
  EXPECT_EQ(small[3].offset, 8u);
}

TEST(IioImu, OpenSetsTheClockRateScalesAndChannelsAndStartsTheBuffer) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "a");
  {
    auto imu = IioImu::open(fake_options(f));
    ASSERT_TRUE(imu.ok()) << imu.error().message;
    EXPECT_EQ(f.read("current_timestamp_clock"), "monotonic");
    EXPECT_EQ(f.read("sampling_frequency"), "200");
    EXPECT_EQ(f.read("in_accel_scale"), "0.001196");       // +-4 g
    EXPECT_EQ(f.read("in_anglvel_scale"), "0.000266181");  // +-500 deg/s
    for (const char* c : {"in_accel_x", "in_accel_z", "in_temp", "in_anglvel_y", "in_timestamp"})
      EXPECT_EQ(f.read(std::string("scan_elements/") + c + "_en"), "1") << c;
    EXPECT_EQ(f.read("scan_elements/in_magn_x_en"), "0");
    EXPECT_EQ(f.read("buffer/length"), "400");   // two seconds
    EXPECT_EQ(f.read("buffer/watermark"), "2");  // about 10 ms
    EXPECT_EQ(f.read("buffer/enable"), "1");
    EXPECT_EQ((*imu)->scan_bytes(), 24u);
    EXPECT_DOUBLE_EQ((*imu)->rate_hz(), 200.0);
    EXPECT_DOUBLE_EQ((*imu)->accel_scale(), 0.001196);
    EXPECT_NEAR((*imu)->temp_scale(), 1.0 / 340.0, 1e-6);
    EXPECT_NEAR((*imu)->temp_offset_c(), 36.53, 0.01);  // the datasheet's 35 C at -521 counts
    EXPECT_NE((*imu)->describe().find("mpu6000 on 1-0068"), std::string::npos);
  }
  EXPECT_EQ(f.read("buffer/enable"), "0");  // stopped when closed
}

TEST(IioImu, ReadDecodesWholeScansAndCarriesAPartOne) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "a");
  auto imu = IioImu::open(fake_options(f));
  ASSERT_TRUE(imu.ok()) << imu.error().message;
  FifoWriter w(f);
  ASSERT_GE(w.fd, 0);
  std::vector<IioScan> got;
  ASSERT_TRUE((*imu)->read(got).ok());
  EXPECT_TRUE(got.empty());
  const IioScan a = scan_at(1'234'567'890'123, 1000);
  const IioScan b = scan_at(1'234'572'890'123, -32768);
  const std::string both = encode_scan(a) + encode_scan(b);
  w.write(both.substr(0, 30));  // one scan and 6 bytes of the next
  ASSERT_TRUE((*imu)->read(got).ok());
  ASSERT_EQ(got.size(), 1u);
  w.write(both.substr(30));
  ASSERT_TRUE((*imu)->read(got).ok());
  ASSERT_EQ(got.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const IioScan& want = i == 0 ? a : b;
    EXPECT_EQ(got[i].accel, want.accel);
    EXPECT_EQ(got[i].gyro, want.gyro);
    EXPECT_EQ(got[i].temp, want.temp);
    EXPECT_EQ(got[i].t_ns, want.t_ns);
  }
  EXPECT_EQ((*imu)->stats().scans, 2u);
  EXPECT_EQ((*imu)->stats().partial_bytes, 6u);
}

TEST(IioImu, RefusalsSayWhatToDo) {
  const std::string base = test::scratch_dir();
  {
    FakeIio f = make_fake_iio(base, "none");
    IioImuOptions o = fake_options(f);
    o.parent = "2-0068";
    auto r = IioImu::open(o);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kNotFound);
    EXPECT_NE(r.error().message.find("found iio:device0 (mpu6000 on 1-0068)"), std::string::npos)
        << r.error().message;
    o.sysfs_root = f.root + "/empty";
    r = IioImu::open(o);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("imu.driver: direct"), std::string::npos) << r.error().message;
  }
  {
    const FakeIio f = make_fake_iio(base, "nobuffer", "mpu6000", false);
    auto r = IioImu::open(fake_options(f));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kUnsupported);
    EXPECT_NE(r.error().message.find("no buffer"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("interrupt"), std::string::npos);
  }
  {
    const FakeIio f = make_fake_iio(base, "6500", "mpu6500");
    auto r = IioImu::open(fake_options(f));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kUnsupported);
    EXPECT_NE(r.error().message.find("MPU-6000 and MPU-6050 only"), std::string::npos) << r.error().message;
  }
  {
    const FakeIio f = make_fake_iio(base, "busy");
    test::write_file(f.attr("buffer/enable"), "1\n");
    auto r = IioImu::open(fake_options(f));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kDevice);
    EXPECT_NE(r.error().message.find("another reader"), std::string::npos) << r.error().message;
  }
  {
    const FakeIio f = make_fake_iio(base, "rate");
    IioImuOptions o = fake_options(f);
    o.rate_hz = 2000;
    auto r = IioImu::open(o);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, Errc::kUnsupported);
    EXPECT_NE(r.error().message.find("4 to 1000 Hz"), std::string::npos) << r.error().message;
  }
}

TEST(IioImu, OffsetsGoThroughCalibbias) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "a");
  auto imu = IioImu::open(fake_options(f));
  ASSERT_TRUE(imu.ok()) << imu.error().message;
  drivers::mpu6000::OffsetRegisters regs;
  regs.accel = {-1200, 300, 5000};
  regs.gyro = {12, -7, 0};
  ASSERT_TRUE((*imu)->write_offsets(regs).ok());
  // On again after the writes, which pause it (the kernel refuses calibbias while it streams; a
  // plain file cannot, qemu.iio meets the refusal).
  EXPECT_EQ(f.read("buffer/enable"), "1");
  EXPECT_EQ(f.read("in_anglvel_y_calibbias"), "-7");
  EXPECT_EQ(f.read("in_accel_z_calibbias"), "5000");
  auto back = (*imu)->read_offsets();
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->accel, regs.accel);
  EXPECT_EQ(back->gyro, regs.gyro);
}

class TestClock final : public acq::AcquisitionClock {
 public:
  TimeNs now_ns() override { return monotonic_now_ns(); }
  void sleep_until(TimeNs) override {}
};

TEST(IioAcquisition, KernelStampsAreCheckedForHolesOrderAndClock) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "a");
  auto imu = IioImu::open(fake_options(f));
  ASSERT_TRUE(imu.ok()) << imu.error().message;
  FifoWriter w(f);
  TestClock clock;
  acq::IioAcquisition acquisition(**imu, clock, acq::MountingMap());
  // 200 Hz, the chip 1 % slow; samples 100..104 lost (a FIFO the kernel reset); sample 150's
  // stamp equal to its predecessor's.
  const TimeNs t0 = monotonic_now_ns() - 2 * kNsPerSecond;
  const double period = 5'050'000.0;
  std::string bytes;
  std::vector<TimeNs> sent;
  for (int n = 0; n < 300; ++n) {
    if (n >= 100 && n < 105) continue;
    TimeNs t = t0 + static_cast<TimeNs>(n * period);
    if (n == 150) t = sent.back();
    sent.push_back(t);
    bytes += encode_scan(scan_at(t, static_cast<std::int16_t>(n)));
  }
  w.write(bytes);
  std::vector<ImuSample> out;
  std::vector<ImuSample> all;
  for (int i = 0; i < 10 && all.size() < sent.size(); ++i) {
    ASSERT_TRUE(acquisition.service(out).ok());
    all.insert(all.end(), out.begin(), out.end());
  }
  ASSERT_EQ(all.size(), 295u);
  const auto timing = acquisition.timing_stats();
  EXPECT_EQ(timing.gaps, 1u);
  EXPECT_EQ(timing.samples_lost, 5u);
  EXPECT_EQ(timing.monotonic_clamps, 1u);
  EXPECT_TRUE(all[100].flags & kImuFlagGapBefore);  // sample 105, the first after the hole
  EXPECT_EQ(all[100].accel.x(), 105.0);
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (i != 100) {
      EXPECT_FALSE(all[i].flags & kImuFlagGapBefore) << i;
    }
    if (i > 0) {
      EXPECT_GT(all[i].t_ns, all[i - 1].t_ns) << i;
    }
  }
  EXPECT_TRUE(all[0].flags & kImuFlagGyroSaturated);  // gyro z 32767
  EXPECT_NEAR(acquisition.period_error_ppm(), 10'000.0, 100.0);
  const auto meta = nlohmann::json::parse(acquisition.timing_metadata(198.0));
  EXPECT_EQ(meta["samples_lost"], 5);
  EXPECT_NEAR(meta["interval_mean_ns"].get<double>(), period, 1.0);
  EXPECT_EQ(nlohmann::json::parse(acquisition.driver_metadata())["driver"], "iio");

  // Stamps on CLOCK_REALTIME (another program changed current_timestamp_clock): an error.
  const TimeNs realtime = monotonic_now_ns() + 1'700'000'000LL * kNsPerSecond;
  w.write(encode_scan(scan_at(realtime, 1)));
  const auto st = acquisition.service(out);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("CLOCK_MONOTONIC"), std::string::npos) << st.error().message;
}

TEST(IioAcquisition, SilenceRestartsTheBufferThenFails) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "a");
  IioImuOptions o = fake_options(f);
  o.rate_hz = 1000;
  auto imu = IioImu::open(o);
  ASSERT_TRUE(imu.ok()) << imu.error().message;
  FifoWriter w(f);
  struct StepClock final : acq::AcquisitionClock {
    TimeNs t = 0;
    TimeNs now_ns() override { return t; }
    void sleep_until(TimeNs) override {}
  } clock;
  clock.t = monotonic_now_ns();
  acq::IioAcquisition acquisition(**imu, clock, acq::MountingMap());
  std::vector<ImuSample> out;
  Status st;
  int calls = 0;
  while (st.ok() && calls < 10) {
    clock.t = acquisition.next_poll_ns();
    st = acquisition.service(out);
    ++calls;
  }
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, Errc::kDevice);
  EXPECT_NE(st.error().message.find("interrupt"), std::string::npos) << st.error().message;
  EXPECT_EQ((*imu)->stats().restarts, 3u);
  EXPECT_EQ(calls, 4);
}

RigConfig iio_rig_config(ImuDriver driver) {
  RigConfig c;
  c.imu.bus = ImuBus::kI2c;
  c.imu.device = "/dev/i2c-1";
  c.imu.i2c_address = 0x68;
  c.imu.driver = driver;
  c.imu.rate_hz = 200;
  c.imu.dlpf_hz = 98;
  c.imu.accel_range_g = 4;
  c.imu.gyro_range_dps = 500;
  return c;
}

TEST(IioRig, AutoUsesTheKernelsDriverWhenItOwnsTheConfiguredChip) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "auto");
  const app::IioPaths paths{f.sys(), f.dev()};
  RigConfig c = iio_rig_config(ImuDriver::kAuto);
  EXPECT_EQ(app::resolve_imu_driver(c.imu, paths), ImuDriver::kIio);
  c.imu.i2c_address = 0x69;  // another chip: the kernel's device is not this one
  EXPECT_EQ(app::resolve_imu_driver(c.imu, paths), ImuDriver::kDirect);
  c.imu.i2c_address = 0x68;
  EXPECT_EQ(app::resolve_imu_driver(c.imu, app::IioPaths{f.root + "/none", f.dev()}), ImuDriver::kDirect);
  c.imu.driver = ImuDriver::kDirect;
  EXPECT_EQ(app::resolve_imu_driver(c.imu, paths), ImuDriver::kDirect);

  c.imu.driver = ImuDriver::kAuto;
  auto rig = app::open_imu_rig(c, {}, paths);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_EQ((*rig)->driver(), nullptr);
  ASSERT_NE((*rig)->iio(), nullptr);
  EXPECT_EQ((*rig)->stream_info().device, "mpu6000@iio:device0");
  EXPECT_DOUBLE_EQ((*rig)->stream_info().accel.scale.x(), 0.001196);
  EXPECT_DOUBLE_EQ((*rig)->stream_info().gyro.scale.z(), 0.000266181);
  EXPECT_NE((*rig)->describe().find("inv-mpu6050"), std::string::npos);
  EXPECT_EQ((*rig)->source().wake_fd(), (*rig)->iio()->fd());

  // The kernel sets the filter from the rate: a configuration that says otherwise is refused.
  rig->reset();
  c.imu.dlpf_hz = 42;
  auto refused = app::open_imu_rig(c, {}, paths);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, Errc::kUnsupported);
  EXPECT_NE(refused.error().message.find("98 Hz at 200"), std::string::npos) << refused.error().message;
}

// A recording through the kernel's driver, on the event loop as `imucal record` runs it: a
// thread writes 200 Hz scans stamped now into the FIFO in 10 ms batches.
TEST(IioRig, RecordsASessionLogThroughTheKernelsDriver) {
  const std::string base = test::scratch_dir();
  const FakeIio f = make_fake_iio(base, "record");
  auto rig = app::open_imu_rig(iio_rig_config(ImuDriver::kIio), {}, app::IioPaths{f.sys(), f.dev()});
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  FifoWriter w(f);
  std::atomic<bool> stop{false};
  std::thread writer([&] {
    const TimeNs t0 = monotonic_now_ns();
    int n = 0;
    while (!stop) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      std::string bytes;
      const TimeNs now = monotonic_now_ns();
      for (; t0 + n * 5'000'000LL <= now; ++n) {
        if (n >= 60 && n < 63) continue;  // three samples the kernel dropped
        bytes += encode_scan(scan_at(t0 + n * 5'000'000LL, static_cast<std::int16_t>(n)));
      }
      if (!bytes.empty() && ::write(w.fd, bytes.data(), bytes.size()) < 0) break;
    }
  });
  acq::RecordOptions ro;
  ro.log_path = base + "/iio-record.imulog";
  ro.overwrite = true;
  ro.duration_s = 1.0;
  ro.stream_info = (*rig)->stream_info();
  ro.loop = acq::RecordLoop::kEventLoop;
  auto summary = acq::record_imu_session((*rig)->source(), ro);
  stop = true;
  writer.join();
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_GE(summary->samples, 190u);
  EXPECT_LE(summary->samples, 201u);
  EXPECT_EQ(summary->timing.samples_lost, 3u);
  EXPECT_EQ(summary->timing.gaps, 1u);
  EXPECT_NEAR(summary->rate_hz, 200.0, 6.0);

  auto reader = log::SessionLogReader::open(ro.log_path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  const auto& meta = (*reader)->metadata();
  ASSERT_TRUE(meta.count("imu.driver") && meta.count("imu.timing"));
  const auto driver = nlohmann::json::parse(meta.at("imu.driver"));
  EXPECT_EQ(driver["driver"], "iio");
  const auto timing = nlohmann::json::parse(meta.at("imu.timing"));
  EXPECT_EQ(timing["samples_lost"], 3);
  EXPECT_EQ(timing["source"], "kernel: inv-mpu6050 IIO buffer timestamps");
}

}  // namespace
}  // namespace imucal
