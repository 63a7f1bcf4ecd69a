// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/mpu6000/fake/mpu6000_emulator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

#include "core/imu.hpp"

namespace imucal::fake {

namespace reg = drivers::mpu6000;
using reg::Register;

namespace {

constexpr std::uint8_t addr(Register r) { return static_cast<std::uint8_t>(r); }

std::int16_t saturate(double counts) {
  const double r = std::nearbyint(counts);
  return static_cast<std::int16_t>(std::clamp(r, -32768.0, 32767.0));
}

}  // namespace

BusTiming BusTiming::spi() { return BusTiming{}; }

BusTiming BusTiming::i2c() {
  BusTiming t;
  t.bits_per_byte = 9.0;
  t.read_header_bytes = 3;
  t.write_header_bytes = 2;
  t.fixed_clock_hz = reg::kI2cSpeedHz;
  t.overhead_ns = 50'000;
  return t;
}

TimeNs BusTiming::transfer_ns(std::size_t payload_bytes, bool is_read, std::uint32_t speed_hz) const {
  if (!enabled) return 0;
  const std::uint32_t clock_hz = fixed_clock_hz != 0 ? fixed_clock_hz : std::max<std::uint32_t>(speed_hz, 1);
  const double bytes =
      static_cast<double>(payload_bytes + (is_read ? read_header_bytes : write_header_bytes));
  return overhead_ns + static_cast<TimeNs>(std::llround(bytes * bits_per_byte * 1e9 / clock_hz));
}

Mpu6000Emulator::Mpu6000Emulator(SensorSource source, EmulatorOptions options)
    : source_(std::move(source)), options_(options), now_ns_(options.start_ns) {
  reset_registers();
}

void Mpu6000Emulator::connect(SimDataReadyLine& line) {
  set_interrupt_sink([&line](TimeNs t_ns) { line.raise(t_ns); });
}

void Mpu6000Emulator::reset_registers() {
  regs_.fill(0);
  regs_[addr(Register::PWR_MGMT_1)] = reg::kPwrMgmt1ResetValue;
  regs_[addr(Register::WHO_AM_I)] = options_.who_am_i;
  for (int i = 0; i < 3; ++i) {
    const auto v = static_cast<std::uint16_t>(options_.factory_accel_offset[i]);
    regs_[addr(Register::XA_OFFS_H) + 2 * i] = static_cast<std::uint8_t>(v >> 8);
    regs_[addr(Register::XA_OFFS_H) + 2 * i + 1] = static_cast<std::uint8_t>(v & 0xFF);
  }
  const auto& a = options_.accel_test_code;
  const auto& g = options_.gyro_test_code;
  for (int i = 0; i < 3; ++i) {
    regs_[addr(Register::SELF_TEST_X) + i] =
        static_cast<std::uint8_t>(((a[i] >> 2) & 0x7) << 5 | (g[i] & 0x1F));
  }
  regs_[addr(Register::SELF_TEST_A)] =
      static_cast<std::uint8_t>((a[0] & 0x3) << 4 | (a[1] & 0x3) << 2 | (a[2] & 0x3));
  fifo_.clear();
  running_ = false;
}

bool Mpu6000Emulator::sleeping() const { return (regs_[addr(Register::PWR_MGMT_1)] & reg::SLEEP) != 0; }

bool Mpu6000Emulator::i2c_interface_disabled() const {
  return (regs_[addr(Register::USER_CTRL)] & reg::I2C_IF_DIS) != 0;
}

double Mpu6000Emulator::sample_rate_hz() const {
  const std::uint8_t dlpf = regs_[addr(Register::CONFIG)] & reg::DLPF_CFG;
  const double gyro_hz = (dlpf == 0 || dlpf == 7) ? reg::kGyroRateDlpfOffHz : reg::kGyroRateDlpfOnHz;
  return gyro_hz / (1.0 + regs_[addr(Register::SMPLRT_DIV)]);
}

std::array<double, 3> Mpu6000Emulator::accel_factory_trim() const {
  std::array<double, 3> ft{};
  for (int i = 0; i < 3; ++i) {
    const int code = options_.accel_test_code[i] & 0x1F;
    // RM 4.1: FT[Xa] = 4096 * 0.34 * (0.92 / 0.34)^((XA_TEST - 1) / (2^5 - 2)), 0 if XA_TEST == 0.
    ft[i] = code == 0 ? 0.0 : 4096.0 * 0.34 * std::pow(0.92 / 0.34, (code - 1.0) / 30.0);
  }
  return ft;
}

std::array<double, 3> Mpu6000Emulator::gyro_factory_trim() const {
  std::array<double, 3> ft{};
  for (int i = 0; i < 3; ++i) {
    const int code = options_.gyro_test_code[i] & 0x1F;
    // RM 4.1: FT[Xg] = 25 * 131 * 1.046^(XG_TEST - 1); FT[Yg] is negative.
    ft[i] = code == 0 ? 0.0 : 25.0 * 131.0 * std::pow(1.046, code - 1.0);
  }
  ft[1] = -ft[1];
  return ft;
}

void Mpu6000Emulator::restart_schedule() {
  const std::uint8_t dlpf = regs_[addr(Register::CONFIG)] & reg::DLPF_CFG;
  const TimeNs gyro_period_ns = (dlpf == 0 || dlpf == 7) ? 125'000 : 1'000'000;
  period_ns_ = gyro_period_ns * (1 + regs_[addr(Register::SMPLRT_DIV)]);
  origin_ns_ = now_ns_;
  next_k_ = 1;
  last_accel_tick_ = -1;
  running_ = true;
}

TimeNs Mpu6000Emulator::tick_host_ns(std::uint64_t k) const {
  const long double chip_ns = static_cast<long double>(k) * static_cast<long double>(period_ns_);
  return origin_ns_ + static_cast<TimeNs>(std::llround(chip_ns / (1.0L + options_.clock_ppm * 1e-6L)));
}

TimeNs Mpu6000Emulator::next_event_ns() const { return running_ ? tick_host_ns(next_k_) : kNever; }

void Mpu6000Emulator::advance_to(TimeNs host_t_ns) {
  while (running_) {
    const TimeNs t = tick_host_ns(next_k_);
    if (t > host_t_ns) break;
    now_ns_ = std::max(now_ns_, t);
    generate(next_k_++);
  }
  now_ns_ = std::max(now_ns_, host_t_ns);
}

void Mpu6000Emulator::generate(std::uint64_t k) {
  const TimeNs t_ns = tick_host_ns(k);
  SensorReading reading = source_(t_ns);
  // The accelerometer samples at 1 kHz of chip time; at higher sample rates its value repeats.
  const auto accel_tick = static_cast<std::int64_t>((static_cast<TimeNs>(k) * period_ns_) / 1'000'000);
  if (accel_tick != last_accel_tick_) {
    last_accel_tick_ = accel_tick;
    const long double chip_ns = static_cast<long double>(accel_tick) * 1e6L;
    accel_t_ns_ =
        origin_ns_ + static_cast<TimeNs>(std::llround(chip_ns / (1.0L + options_.clock_ppm * 1e-6L)));
    accel_si_ = accel_t_ns_ == t_ns ? reading.specific_force : source_(accel_t_ns_).specific_force;
  }
  reading.specific_force = accel_si_;

  const int afs = (regs_[addr(Register::ACCEL_CONFIG)] & reg::AFS_SEL) >> 3;
  const int fs = (regs_[addr(Register::GYRO_CONFIG)] & reg::FS_SEL) >> 3;
  const double lsb_per_g = 16384.0 / (1 << afs);
  const double lsb_per_dps = reg::gyro_lsb_per_dps(static_cast<reg::GyroRange>(fs));
  const std::uint8_t accel_st = regs_[addr(Register::ACCEL_CONFIG)];
  const std::uint8_t gyro_st = regs_[addr(Register::GYRO_CONFIG)];
  const auto ft_a = accel_factory_trim();
  const auto ft_g = gyro_factory_trim();

  TruthSample truth;
  truth.index = sample_index_++;
  truth.t_ns = t_ns;
  truth.accel_t_ns = accel_t_ns_;
  truth.reading = reading;
  for (int i = 0; i < 3; ++i) {
    const std::uint8_t st_bit = static_cast<std::uint8_t>(reg::Bit7 >> i);
    const auto off_reg = be16_reg(addr(Register::XA_OFFS_H) + 2 * i);
    // Accel offset registers count 1/2048 g with bit 0 reserved; the factory value is the
    // zero point of this emulator's source.
    const int accel_offset = ((off_reg & ~1) - (options_.factory_accel_offset[i] & ~1)) * (8 >> afs);
    double a = reading.specific_force[i] / kStandardGravity * lsb_per_g;
    if (accel_st & st_bit) a += ft_a[i] * options_.accel_self_test_gain * lsb_per_g / 4096.0;
    truth.accel[i] = saturate(std::nearbyint(a) + accel_offset);

    const auto gyro_off_reg = be16_reg(addr(Register::XG_OFFS_USRH) + 2 * i);
    // Gyro offset registers count 1/32.8 deg/s (4 LSB at +-250 dps).
    const double gyro_offset = std::nearbyint(
        gyro_off_reg * reg::gyro_output_counts_per_offset_count(static_cast<reg::GyroRange>(fs)));
    double w = reading.angular_rate[i] * 180.0 / std::numbers::pi * lsb_per_dps;
    if (gyro_st & st_bit) w += ft_g[i] * options_.gyro_self_test_gain * lsb_per_dps / 131.0;
    truth.gyro[i] = saturate(std::nearbyint(w) + gyro_offset);
  }
  truth.temp = saturate((reading.temperature_c - reg::kTempOffsetDegC) * reg::kTempLsbPerDegC);

  // Output registers 0x3B..0x48, big-endian.
  std::array<std::int16_t, 7> values = {truth.accel[0], truth.accel[1], truth.accel[2], truth.temp,
                                        truth.gyro[0],  truth.gyro[1],  truth.gyro[2]};
  for (int i = 0; i < 7; ++i) {
    const auto v = static_cast<std::uint16_t>(values[i]);
    regs_[addr(Register::ACCEL_XOUT_H) + 2 * i] = static_cast<std::uint8_t>(v >> 8);
    regs_[addr(Register::ACCEL_XOUT_H) + 2 * i + 1] = static_cast<std::uint8_t>(v & 0xFF);
  }

  const std::uint8_t fifo_en = regs_[addr(Register::FIFO_EN)];
  bool overflowed = false;
  if ((regs_[addr(Register::USER_CTRL)] & reg::FIFO_EN) && (fifo_en & 0xF8)) {
    const std::size_t before_overwritten = stats_.fifo_bytes_overwritten;
    auto push16 = [&](std::uint8_t first_reg) {
      push_fifo(regs_[first_reg]);
      push_fifo(regs_[first_reg + 1]);
    };
    if (fifo_en & reg::ACCEL_FIFO_EN) {
      for (int i = 0; i < 3; ++i) push16(static_cast<std::uint8_t>(addr(Register::ACCEL_XOUT_H) + 2 * i));
    }
    if (fifo_en & reg::TEMP_FIFO_EN) push16(addr(Register::TEMP_OUT_H));
    if (fifo_en & reg::XG_FIFO_EN) push16(addr(Register::GYRO_XOUT_H));
    if (fifo_en & reg::YG_FIFO_EN) push16(addr(Register::GYRO_YOUT_H));
    if (fifo_en & reg::ZG_FIFO_EN) push16(addr(Register::GYRO_ZOUT_H));
    truth.to_fifo = true;
    ++stats_.fifo_frames_written;
    overflowed = stats_.fifo_bytes_overwritten != before_overwritten;
    if (overflowed) regs_[addr(Register::INT_STATUS)] |= reg::FIFO_OFLOW_INT;
    stats_.max_fifo_bytes =
        std::max<std::uint16_t>(stats_.max_fifo_bytes, static_cast<std::uint16_t>(fifo_.size()));
  }
  regs_[addr(Register::INT_STATUS)] |= reg::DATA_RDY_INT;
  ++stats_.samples;
  if (options_.record_truth) truth_.push_back(truth);

  const std::uint8_t int_enable = regs_[addr(Register::INT_ENABLE)];
  if (sink_ && ((int_enable & reg::DATA_RDY_EN) || (overflowed && (int_enable & reg::FIFO_OFLOW_EN)))) {
    sink_(t_ns);
  }
}

std::int16_t Mpu6000Emulator::be16_reg(int first) const { return reg::be16(regs_[first], regs_[first + 1]); }

void Mpu6000Emulator::push_fifo(std::uint8_t byte) {
  fifo_.push_back(byte);
  // RM 4.30: when the FIFO is full, new data overwrites the oldest.
  while (fifo_.size() > reg::kFifoSizeBytes) {
    fifo_.pop_front();
    ++stats_.fifo_bytes_overwritten;
  }
}

void Mpu6000Emulator::spontaneous_reset() {
  ++stats_.spontaneous_resets;
  reset_registers();
}

bool Mpu6000Emulator::is_sensor_register(std::uint8_t a) const {
  return (a >= addr(Register::INT_STATUS) && a <= addr(Register::GYRO_ZOUT_L)) ||
         (a >= addr(Register::FIFO_COUNTH) && a <= addr(Register::FIFO_R_W));
}

Status Mpu6000Emulator::begin_transfer(std::size_t payload_bytes, bool is_read, std::uint8_t first_reg) {
  if (stall_ns_ > 0) {
    const TimeNs stall = stall_ns_;
    stall_ns_ = 0;
    advance_to(now_ns_ + stall);
  }
  ++bus_counters_.transfers;
  transfer_ns_ = options_.timing.transfer_ns(payload_bytes, is_read, speed_hz_);
  if (options_.bus == reg::BusKind::kSpi && speed_hz_ > reg::kSpiConfigSpeedHz) {
    bool sensor_only = is_read;
    if (is_read && first_reg != addr(Register::FIFO_R_W)) {
      for (std::size_t i = 0; i < payload_bytes && sensor_only; ++i) {
        sensor_only = is_sensor_register(static_cast<std::uint8_t>((first_reg + i) & 0x7F));
      }
    }
    if (!sensor_only) ++stats_.speed_violations;
  }
  if (fail_remaining_ > 0) {
    --fail_remaining_;
    ++stats_.injected_bus_errors;
    ++bus_counters_.transfer_errors;
    return make_error(Errc::kIo, "sim-mpu6000: injected bus error");
  }
  if (options_.bus == reg::BusKind::kI2c && i2c_interface_disabled()) {
    ++bus_counters_.transfer_errors;
    return make_error(Errc::kIo,
                      "sim-mpu6000: no ACK at 0x68 (I2C interface disabled by USER_CTRL.I2C_IF_DIS)");
  }
  return {};
}

void Mpu6000Emulator::end_transfer() {
  stats_.bus_busy_ns += transfer_ns_;
  advance_to(now_ns_ + transfer_ns_);
  transfer_ns_ = 0;
}

std::uint8_t Mpu6000Emulator::read_byte(std::uint8_t a) {
  switch (a) {
    case addr(Register::FIFO_COUNTH):
      return static_cast<std::uint8_t>(fifo_.size() >> 8);
    case addr(Register::FIFO_COUNTL):
      return static_cast<std::uint8_t>(fifo_.size() & 0xFF);
    case addr(Register::FIFO_R_W): {
      if (fifo_.empty()) {
        ++stats_.fifo_underreads;
        return 0;
      }
      const std::uint8_t b = fifo_.front();
      fifo_.pop_front();
      return b;
    }
    default:
      return regs_[a & 0x7F];
  }
}

Status Mpu6000Emulator::read(std::uint8_t first_reg, std::span<std::uint8_t> out) {
  const bool is_fifo = first_reg == addr(Register::FIFO_R_W);
  auto begun = begin_transfer(out.size(), true, first_reg);
  if (!begun.ok()) {
    if (is_fifo && options_.bus == reg::BusKind::kSpi) {
      // The transfer died half-way: the chip has clocked out (and dropped) half of the bytes.
      for (std::size_t i = 0; i < out.size() / 2 && !fifo_.empty(); ++i) fifo_.pop_front();
    }
    end_transfer();
    return begun;
  }
  if (now_ns_ < busy_until_ns_) {
    std::fill(out.begin(), out.end(), 0);
    end_transfer();
    return {};
  }
  std::optional<Corruption> corruption;
  std::size_t slip_at = 0;
  if (!corruption_.empty() && (corruption_.front().kind == Corruption::kStuckHigh || is_fifo)) {
    corruption = corruption_.front().kind;
    slip_at = std::min(corruption_.front().slip_at_byte, out.empty() ? 0 : out.size() - 1);
    corruption_.pop_front();
    ++stats_.injected_corruptions;
  }
  bool clear_int_status = false;
  for (std::size_t i = 0; i < out.size(); ++i) {
    const auto a = static_cast<std::uint8_t>(is_fifo ? first_reg : ((first_reg + i) & 0x7F));
    if (a == addr(Register::INT_STATUS)) clear_int_status = true;
    if (corruption == Corruption::kByteSlip && i == slip_at && !fifo_.empty()) fifo_.pop_front();
    out[i] = read_byte(a);
  }
  if (clear_int_status) regs_[addr(Register::INT_STATUS)] = 0;
  if (corruption == Corruption::kStuckHigh) std::fill(out.begin(), out.end(), 0xFF);
  end_transfer();
  return {};
}

Status Mpu6000Emulator::write(std::uint8_t r, std::uint8_t value) {
  auto begun = begin_transfer(1, false, r);
  if (!begun.ok()) {
    end_transfer();
    return begun;
  }
  if (now_ns_ >= busy_until_ns_) write_byte(r & 0x7F, value);
  end_transfer();
  return {};
}

void Mpu6000Emulator::write_byte(std::uint8_t a, std::uint8_t value) {
  switch (a) {
    case addr(Register::PWR_MGMT_1): {
      if (value & reg::DEVICE_RESET) {
        ++stats_.device_resets;
        reset_registers();
        busy_until_ns_ = now_ns_ + options_.reset_busy_ns;
        return;
      }
      regs_[a] = value;
      const bool awake = (value & reg::SLEEP) == 0;
      if (awake && !running_) restart_schedule();
      if (!awake) running_ = false;
      return;
    }
    case addr(Register::USER_CTRL):
      // RM 4.27: FIFO_RESET resets the FIFO when set while FIFO_EN is 0.
      if ((value & reg::FIFO_RESET) && !(value & reg::FIFO_EN)) {
        fifo_.clear();
        ++stats_.fifo_resets;
      }
      if (value & reg::SIG_COND_RESET) {
        for (int i = addr(Register::ACCEL_XOUT_H); i <= addr(Register::GYRO_ZOUT_L); ++i) regs_[i] = 0;
      }
      regs_[a] =
          value & static_cast<std::uint8_t>(~(reg::FIFO_RESET | reg::I2C_MST_RESET | reg::SIG_COND_RESET));
      return;
    case addr(Register::SIGNAL_PATH_RESET):
      for (int i = addr(Register::ACCEL_XOUT_H); i <= addr(Register::GYRO_ZOUT_L); ++i) regs_[i] = 0;
      regs_[a] = 0;
      return;
    case addr(Register::SMPLRT_DIV):
    case addr(Register::CONFIG): {
      const bool changed = regs_[a] != value;
      regs_[a] = value;
      if (changed && running_) restart_schedule();
      return;
    }
    case addr(Register::INT_STATUS):
    case addr(Register::FIFO_COUNTH):
    case addr(Register::FIFO_COUNTL):
    case addr(Register::FIFO_R_W):
    case addr(Register::WHO_AM_I):
      return;  // read-only here (FIFO writes are not modelled)
    default:
      if (a >= addr(Register::ACCEL_XOUT_H) && a <= addr(Register::GYRO_ZOUT_L)) return;
      regs_[a] = value;
  }
}

}  // namespace imucal::fake
