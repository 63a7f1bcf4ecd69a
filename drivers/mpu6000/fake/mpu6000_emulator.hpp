// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// An MPU-6000 that speaks the register protocol as a RegisterBus, for tests, benchmarks and the
// virtual rig. It models what the driver depends on: reset values and DEVICE_RESET, sleep and
// wake, sample rate (gyro 8 kHz with the DLPF off, 1 kHz on; accel 1 kHz, repeated at 8 kHz;
// rate = gyro rate / (1 + SMPLRT_DIV)), full-scale ranges with quantization and saturation, the
// 1024-byte FIFO (oldest bytes overwritten on overflow, FIFO_OFLOW_INT), FIFO_COUNT, INT_STATUS
// (cleared by reading), offset and self-test registers, WHO_AM_I, its own oscillator (ppm
// offset against the host clock), the data-ready interrupt, and the bus time of every transfer.
// It does not model the DLPF's filtering or group delay: the sample source is responsible for
// the signal, the emulator for the protocol.
//
// Time is simulated host time (CLOCK_MONOTONIC ns) and moves only through advance_to() and the
// bus time of transfers. Every generated sample is recorded with its true time and exact counts
// (truth()), so tests can check what a driver delivers.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/bus/register_bus.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "drivers/mpu6000/registers.hpp"

namespace imucal::fake {

/// What the sensing elements see at one instant, in the chip's axes.
struct SensorReading {
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero();  // m/s^2
  Eigen::Vector3d angular_rate = Eigen::Vector3d::Zero();    // rad/s
  double temperature_c = 25.0;
};

/// Gives the reading at a true host time. Called once per gyro sample and once per accel sample.
using SensorSource = std::function<SensorReading(TimeNs t_ns)>;

/// Bus time of one transfer: (header + payload) bytes x bits_per_byte / clock + overhead.
struct BusTiming {
  bool enabled = true;
  double bits_per_byte = 8.0;
  std::uint32_t read_header_bytes = 1;   // SPI: the address byte
  std::uint32_t write_header_bytes = 1;  // SPI: the address byte (plus the value)
  std::uint32_t fixed_clock_hz = 0;      // 0: the clock set by set_speed_hz (SPI)
  TimeNs overhead_ns = 20'000;           // per transfer: driver, ioctl, chip-select

  /// spidev: 8 bits per byte, address byte, 20 us per ioctl.
  static BusTiming spi();
  /// i2c-dev at 400 kHz: 9 bits per byte (ACK), address+register (+address for reads), 50 us.
  static BusTiming i2c();
  TimeNs transfer_ns(std::size_t payload_bytes, bool is_read, std::uint32_t speed_hz) const;
};

struct EmulatorOptions {
  drivers::mpu6000::BusKind bus = drivers::mpu6000::BusKind::kSpi;
  BusTiming timing = BusTiming::spi();
  double clock_ppm = 0.0;  // chip oscillator error; positive: the chip samples faster
  TimeNs start_ns = 0;     // initial host time
  std::uint8_t who_am_i = drivers::mpu6000::WHOAMI;
  /// Factory accel offset register values (1/2048 g). With these the output is the source's value.
  std::array<std::int16_t, 3> factory_accel_offset = {-1854, 2210, 1369};
  /// Factory self-test codes (5 bits each) and how strongly the sensors respond relative to the
  /// trim they encode (1.0 passes, 0.5 or 1.3 fails the 14 % test).
  std::array<std::uint8_t, 3> accel_test_code = {16, 17, 15};
  std::array<std::uint8_t, 3> gyro_test_code = {13, 14, 12};
  double accel_self_test_gain = 1.0;
  double gyro_self_test_gain = 1.0;
  /// After DEVICE_RESET the chip ignores the bus (reads 0) for this long.
  TimeNs reset_busy_ns = 10'000'000;
  bool record_truth = true;
};

struct TruthSample {
  std::uint64_t index = 0;  // counts generated samples since construction
  TimeNs t_ns = 0;          // true host time of the gyro and temperature sample
  TimeNs accel_t_ns = 0;    // true host time of the accel value (older at 8 kHz: it repeats)
  SensorReading reading;    // gyro/temp at t_ns, specific force at accel_t_ns
  std::array<std::int16_t, 3> accel{};
  std::array<std::int16_t, 3> gyro{};
  std::int16_t temp = 0;
  bool to_fifo = false;  // written into the FIFO
};

enum class Corruption {
  kStuckHigh,  // the next read returns 0xFF bytes (MISO floating); FIFO bytes are still consumed
  kByteSlip,   // the next FIFO read loses one byte to a clock glitch: data misaligned from then on
};

/// What the emulator saw and injected.
struct EmulatorStats {
  std::uint64_t samples = 0;
  std::uint64_t fifo_frames_written = 0;
  std::uint64_t fifo_bytes_overwritten = 0;  // oldest bytes lost to overflow
  std::uint64_t fifo_underreads = 0;         // FIFO_R_W read while empty
  std::uint64_t speed_violations = 0;        // SPI above 1 MHz outside sensor/interrupt registers
  std::uint64_t injected_bus_errors = 0;
  std::uint64_t injected_corruptions = 0;
  std::uint64_t spontaneous_resets = 0;
  std::uint64_t device_resets = 0;  // DEVICE_RESET writes
  std::uint64_t fifo_resets = 0;    // FIFO_RESET writes
  TimeNs bus_busy_ns = 0;           // total bus time of all transfers
  std::uint16_t max_fifo_bytes = 0;
};

class Mpu6000Emulator : public drivers::RegisterBus, public SimTimeSource {
 public:
  explicit Mpu6000Emulator(SensorSource source, EmulatorOptions options = {});

  // RegisterBus. Each transfer takes bus time (BusTiming): the registers are accessed when it
  // starts, and time advances by its duration.
  [[nodiscard]] Status read(std::uint8_t reg, std::span<std::uint8_t> out) override;
  [[nodiscard]] Status write(std::uint8_t reg, std::uint8_t value) override;
  void set_speed_hz(std::uint32_t hz) override { speed_hz_ = hz; }
  std::string name() const override { return "sim-mpu6000"; }
  const drivers::BusCounters& counters() const override { return bus_counters_; }

  // SimTimeSource
  TimeNs now_ns() const override { return now_ns_; }
  TimeNs next_event_ns() const override;
  void advance_to(TimeNs host_t_ns) override;

  /// Where the INT pin goes (typically SimDataReadyLine::raise); called with the true time.
  void set_interrupt_sink(std::function<void(TimeNs true_t_ns)> sink) { sink_ = std::move(sink); }
  /// Connects a simulated data-ready line.
  void connect(SimDataReadyLine& line);

  // Fault injection.
  /// The next `n` transfers fail (Errc::kIo). A failed FIFO read has already clocked out half of
  /// the requested bytes, which are lost.
  void fail_next_transfers(int n) { fail_remaining_ += n; }
  /// kByteSlip: the FIFO byte at offset `slip_at_byte` of the next FIFO burst (clamped to its
  /// last byte) is clocked out of the FIFO but never reaches the host, which receives the next
  /// byte in its place.
  void corrupt_next_read(Corruption kind, std::size_t slip_at_byte = 0) {
    corruption_.push_back({kind, slip_at_byte});
  }
  /// The next transfer waits `stall_ns` for the bus first (another device holds it).
  void stall_next_transfer(TimeNs stall_ns) { stall_ns_ += stall_ns; }
  /// The chip resets itself now (brown-out): registers to reset values, FIFO cleared, asleep.
  void spontaneous_reset();
  /// Fault: a register changes by itself (an upset), bypassing the bus.
  void poke(drivers::mpu6000::Register reg, std::uint8_t value) {
    regs_[static_cast<std::uint8_t>(reg)] = value;
  }

  // Inspection.
  const std::vector<TruthSample>& truth() const { return truth_; }
  void clear_truth() { truth_.clear(); }
  const EmulatorStats& stats() const { return stats_; }
  std::uint8_t peek(drivers::mpu6000::Register reg) const { return regs_[static_cast<std::uint8_t>(reg)]; }
  std::size_t fifo_bytes() const { return fifo_.size(); }
  bool sleeping() const;
  bool i2c_interface_disabled() const;
  double sample_rate_hz() const;
  /// Factory trim (RM 4.1 formulas) the SELF_TEST registers encode, in counts at +-8 g / +-250 dps.
  std::array<double, 3> accel_factory_trim() const;
  std::array<double, 3> gyro_factory_trim() const;

 private:
  void reset_registers();
  void restart_schedule();
  TimeNs tick_host_ns(std::uint64_t k) const;
  void generate(std::uint64_t k);
  std::uint8_t read_byte(std::uint8_t addr);
  void write_byte(std::uint8_t addr, std::uint8_t value);
  void push_fifo(std::uint8_t byte);
  std::int16_t be16_reg(int first) const;
  bool is_sensor_register(std::uint8_t addr) const;
  [[nodiscard]] Status begin_transfer(std::size_t payload_bytes, bool is_read, std::uint8_t reg);
  void end_transfer();

  SensorSource source_;
  EmulatorOptions options_;
  std::function<void(TimeNs)> sink_;
  std::array<std::uint8_t, 128> regs_{};
  std::deque<std::uint8_t> fifo_;
  TimeNs now_ns_ = 0;
  TimeNs busy_until_ns_ = 0;  // DEVICE_RESET in progress
  TimeNs transfer_ns_ = 0;    // duration of the transfer in progress
  std::uint32_t speed_hz_ = drivers::mpu6000::kSpiConfigSpeedHz;
  // Sample schedule: tick k (k >= 1) at chip time k * period after the origin.
  bool running_ = false;
  TimeNs origin_ns_ = 0;
  TimeNs period_ns_ = 0;  // chip-time period
  std::uint64_t next_k_ = 1;
  std::int64_t last_accel_tick_ = -1;
  TimeNs accel_t_ns_ = 0;
  Eigen::Vector3d accel_si_ = Eigen::Vector3d::Zero();
  std::uint64_t sample_index_ = 0;
  int fail_remaining_ = 0;
  struct PendingCorruption {
    Corruption kind;
    std::size_t slip_at_byte;
  };
  std::deque<PendingCorruption> corruption_;
  TimeNs stall_ns_ = 0;
  drivers::BusCounters bus_counters_;
  EmulatorStats stats_;
  std::vector<TruthSample> truth_;
};

}  // namespace imucal::fake
