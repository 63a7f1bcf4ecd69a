// SPDX-License-Identifier: BSD-3-Clause
#include "drivers/mpu6000/mpu6000.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
#include <sstream>

#include "core/text_format.hpp"

namespace imucal::drivers::mpu6000 {

namespace {

// Datasheet delays.
// RM 4.28 (PWR_MGMT_1, note on SPI): DEVICE_RESET, wait 100 ms, SIGNAL_PATH_RESET, wait 100 ms.
constexpr TimeNs kResetDelayNs = 100'000'000;
constexpr TimeNs kSignalPathResetDelayNs = 100'000'000;
// PS 6.1: gyroscope start-up time from sleep, 30 ms (the PLL clock follows the X gyro).
constexpr TimeNs kGyroStartupNs = 30'000'000;
// Retry spacing for failed steps, and how long a reset may take before it is retried.
constexpr TimeNs kRetryDelayNs = 10'000'000;
constexpr TimeNs kWaitForResetTimeoutNs = 1'000'000'000;
constexpr int kMaxConfigureAttempts = 3;
constexpr int kMaxWhoAmIMismatches = 3;
constexpr int kMaxFailedResets = 5;
constexpr int kMaxConsecutiveFailures = 10;
// Time between reading FIFO_COUNT and the start of the FIFO burst that the watermark allows for.
constexpr TimeNs kReadLatencyNs = 1'000'000;
// Operating range, PS 6.4: -40..85 deg C.
constexpr double kMinTempC = -40.0;
constexpr double kMaxTempC = 85.0;

constexpr std::uint8_t u8(Register r) { return static_cast<std::uint8_t>(r); }

std::int16_t temp_raw(double t_c) {
  return static_cast<std::int16_t>(std::lround((t_c - kTempOffsetDegC) * kTempLsbPerDegC));
}

}  // namespace

double Settings::accel_scale_si() const { return kStandardGravity / accel_lsb_per_g(accel_range); }

double Settings::gyro_scale_si() const { return std::numbers::pi / 180.0 / gyro_lsb_per_dps(gyro_range); }

std::uint16_t Settings::fifo_watermark_bytes() const {
  const double frames_in_latency = std::ceil(sample_rate_hz() * ns_to_s(kReadLatencyNs));
  const double wm = kFifoSizeBytes - FIFO::kFrameBytes * (1.0 + frames_in_latency);
  return static_cast<std::uint16_t>(std::max(wm, static_cast<double>(FIFO::kFrameBytes)));
}

Status Settings::validate() const {
  auto fail = [](const std::string& m) -> Status { return make_error(Errc::kInvalidArgument, m); };
  if (dlpf_cfg > 6) return fail("dlpf_cfg " + std::to_string(dlpf_cfg) + " is reserved; use 0..6");
  if (read_interval_ns <= 0) return fail("read_interval_ns must be positive");
  // At a read the FIFO holds what arrived in one interval, one frame more for the sampling
  // phase, and the frame the previous read left behind.
  const double bytes_per_interval = sample_rate_hz() * ns_to_s(read_interval_ns) * FIFO::kFrameBytes;
  if (bytes_per_interval + 2 * FIFO::kFrameBytes > fifo_watermark_bytes()) {
    return fail("read interval " + std::to_string(read_interval_ns / 1000) + " us is too long for " +
                std::to_string(sample_rate_hz()) +
                " Hz: " + std::to_string(static_cast<int>(bytes_per_interval)) +
                " bytes would arrive per read against a FIFO watermark of " +
                std::to_string(fifo_watermark_bytes()) + " bytes; read more often or raise SMPLRT_DIV");
  }
  if (bus == BusKind::kSpi && config_speed_hz > kSpiConfigSpeedHz) {
    return fail("SPI configuration clock " + std::to_string(config_speed_hz) +
                " Hz exceeds the 1 MHz limit (PS 6.5)");
  }
  if (bus == BusKind::kSpi && fifo_speed_hz > kSpiSensorSpeedHz) {
    return fail("SPI sensor clock " + std::to_string(fifo_speed_hz) +
                " Hz exceeds the 20 MHz limit (PS 6.5)");
  }
  if (config_check_interval_ns <= 0) return fail("config_check_interval_ns must be positive");
  if (!(max_temperature_step_c > 0)) return fail("max_temperature_step_c must be positive");
  return {};
}

ImuStreamInfo make_stream_info(const Settings& s, const std::string& device) {
  ImuStreamInfo info;
  info.units = ImuUnits::kRaw;
  info.rate_hz = s.sample_rate_hz();
  info.accel.scale = Eigen::Vector3d::Constant(s.accel_scale_si());
  info.gyro.scale = Eigen::Vector3d::Constant(s.gyro_scale_si());
  info.temperature_scale = 1.0 / kTempLsbPerDegC;
  info.temperature_offset = kTempOffsetDegC;
  info.accel_full_scale_g = accel_full_scale_g(s.accel_range);
  info.gyro_full_scale_dps = gyro_full_scale_dps(s.gyro_range);
  info.dlpf_hz = s.dlpf_cfg <= 6 ? kDlpfGyroBandwidthHz[s.dlpf_cfg] : 0;
  info.device = device;
  return info;
}

const char* state_name(State state) {
  switch (state) {
    case State::kReset:
      return "Reset";
    case State::kWaitForReset:
      return "WaitForReset";
    case State::kConfigure:
      return "Configure";
    case State::kStream:
      return "Stream";
  }
  return "?";
}

bool SelfTestResult::pass() const {
  return std::all_of(accel.begin(), accel.end(), [](const SelfTestAxis& a) { return a.pass; }) &&
         std::all_of(gyro.begin(), gyro.end(), [](const SelfTestAxis& a) { return a.pass; });
}

std::string SelfTestResult::summary() const {
  std::ostringstream os;
  os.precision(3);
  const char* axes = "xyz";
  for (int i = 0; i < 3; ++i) {
    os << "accel " << axes[i] << " " << (accel[i].change * 100.0) << "%" << (accel[i].pass ? "" : " FAIL")
       << ", ";
  }
  for (int i = 0; i < 3; ++i) {
    os << "gyro " << axes[i] << " " << (gyro[i].change * 100.0) << "%" << (gyro[i].pass ? "" : " FAIL");
    if (i < 2) os << ", ";
  }
  return os.str();
}

Mpu6000::Mpu6000(RegisterBus& bus, Settings settings) : bus_(bus), settings_(settings) {
  const bool spi = settings_.bus == BusKind::kSpi;
  const auto fs = static_cast<std::uint8_t>(static_cast<std::uint8_t>(settings_.gyro_range) << 3);
  const auto afs = static_cast<std::uint8_t>(static_cast<std::uint8_t>(settings_.accel_range) << 3);
  const std::uint8_t dlpf = settings_.dlpf_cfg & DLPF_CFG;
  config_ = {
      {Register::PWR_MGMT_1, CLKSEL_PLL_GYRO_X,
       static_cast<std::uint8_t>(DEVICE_RESET | SLEEP | CYCLE | TEMP_DIS | (CLKSEL & ~CLKSEL_PLL_GYRO_X))},
      {Register::PWR_MGMT_2, 0, 0xFF},
      // RM 4.27: on SPI the I2C interface is disabled (I2C_IF_DIS); on I2C it must stay enabled.
      {Register::USER_CTRL, static_cast<std::uint8_t>(FIFO_EN | (spi ? I2C_IF_DIS : 0)),
       static_cast<std::uint8_t>(I2C_MST_EN | (spi ? 0 : I2C_IF_DIS))},
      {Register::SMPLRT_DIV, settings_.smplrt_div, static_cast<std::uint8_t>(~settings_.smplrt_div)},
      {Register::CONFIG, dlpf, static_cast<std::uint8_t>(EXT_SYNC_SET | (DLPF_CFG & ~dlpf))},
      {Register::GYRO_CONFIG, fs, static_cast<std::uint8_t>(XG_ST | YG_ST | ZG_ST | (FS_SEL & ~fs))},
      {Register::ACCEL_CONFIG, afs, static_cast<std::uint8_t>(XA_ST | YA_ST | ZA_ST | (AFS_SEL & ~afs))},
      {Register::FIFO_EN,
       static_cast<std::uint8_t>(TEMP_FIFO_EN | XG_FIFO_EN | YG_FIFO_EN | ZG_FIFO_EN | ACCEL_FIFO_EN),
       static_cast<std::uint8_t>(SLV2_FIFO_EN | SLV1_FIFO_EN | SLV0_FIFO_EN)},
      // Active high, push-pull, 50 us pulse per data-ready; status cleared by reading INT_STATUS.
      {Register::INT_PIN_CFG, 0,
       static_cast<std::uint8_t>(INT_LEVEL | INT_OPEN | LATCH_INT_EN | INT_RD_CLEAR | FSYNC_INT_EN |
                                 I2C_BYPASS_EN)},
      // Only data-ready drives the pin: every edge then marks a sample.
      {Register::INT_ENABLE, DATA_RDY_EN, static_cast<std::uint8_t>(FIFO_OFLOW_EN | I2C_MST_INT_EN)},
  };
}

Status Mpu6000::write_reg(Register reg, std::uint8_t value) {
  auto s = bus_.write(u8(reg), value);
  if (!s.ok()) ++counters_.bad_transfers;
  return s;
}

Result<std::uint8_t> Mpu6000::read_reg(Register reg) {
  auto v = bus_.read_u8(u8(reg));
  if (!v.ok()) ++counters_.bad_transfers;
  return v;
}

Status Mpu6000::apply_row(const ConfigRow& row) {
  auto v = read_reg(row.reg);
  if (!v.ok()) return v.error();
  const auto value = static_cast<std::uint8_t>((*v & ~row.clear_bits) | row.set_bits);
  return write_reg(row.reg, value);
}

Result<bool> Mpu6000::check_row(const ConfigRow& row) {
  auto v = read_reg(row.reg);
  if (!v.ok()) return v.error();
  return (*v & row.set_bits) == row.set_bits && (*v & row.clear_bits) == 0;
}

Status Mpu6000::probe() {
  bus_.set_speed_hz(settings_.config_speed_hz);
  auto who = read_reg(Register::WHO_AM_I);
  if (!who.ok()) return who.error().context("MPU-6000 on " + bus_.name() + ": reading WHO_AM_I failed");
  if (*who != WHOAMI) {
    return make_error(Errc::kDevice,
                      "MPU-6000 on " + bus_.name() + ": WHO_AM_I reads " + format_hex(*who, 2) +
                          ", expected " + format_hex(WHOAMI, 2) +
                          "; check the bus, chip select and wiring, or whether this is another chip");
  }
  return {};
}

void Mpu6000::enter(State s, TimeNs at_ns) {
  state_ = s;
  state_t_ns_ = at_ns;
  wake_t_ns_ = at_ns;
  substep_ = 0;
  attempts_ = 0;
}

void Mpu6000::request_reset(TimeNs now_ns) {
  if (state_ == State::kStream) pending_flags_ |= kImuFlagGapBefore | kImuFlagDeviceReset;
  enter(State::kReset, now_ns);
}

Status Mpu6000::reset_fifo() {
  // RM 4.27: FIFO_RESET acts while FIFO_EN is 0; then enable the FIFO again.
  bus_.set_speed_hz(settings_.config_speed_hz);
  const ConfigRow& user_ctrl = config_[2];
  const auto base = static_cast<std::uint8_t>(user_ctrl.set_bits & ~FIFO_EN);
  IMUCAL_TRY(write_reg(Register::USER_CTRL, static_cast<std::uint8_t>(base | FIFO_RESET)));
  IMUCAL_TRY(write_reg(Register::USER_CTRL, user_ctrl.set_bits));
  return {};
}

std::optional<std::uint16_t> Mpu6000::read_fifo_count() {
  std::array<std::uint8_t, 2> bytes{};
  if (!bus_.read(u8(Register::FIFO_COUNTH), bytes).ok()) {
    ++counters_.bad_transfers;
    return std::nullopt;
  }
  return static_cast<std::uint16_t>((bytes[0] << 8) | bytes[1]);
}

void Mpu6000::on_edge(const DataReadyEdge& edge) {
  if (state_ != State::kStream) {
    last_edge_seq_ = edge.sequence;
    return;
  }
  if (last_edge_seq_ && edge.sequence <= *last_edge_seq_) return;  // seen already
  if (last_edge_seq_ && edge.sequence > *last_edge_seq_ + 1) {
    counters_.missed_data_ready += edge.sequence - *last_edge_seq_ - 1;
  }
  last_edge_seq_ = edge.sequence;
}

Result<PollResult> Mpu6000::poll(TimeNs now_ns, std::optional<DataReadyEdge> edge) {
  if (state_ == State::kStream) return poll_stream(now_ns, edge);
  if (edge) last_edge_seq_ = edge->sequence;
  if (now_ns < wake_t_ns_) return PollResult{std::nullopt, wake_t_ns_};
  switch (state_) {
    case State::kReset:
      return poll_reset(now_ns);
    case State::kWaitForReset:
      return poll_wait_for_reset(now_ns);
    case State::kConfigure:
      return poll_configure(now_ns);
    case State::kStream:
      break;
  }
  return make_error(Errc::kInternal, "MPU-6000 driver in an unknown state");
}

Result<PollResult> Mpu6000::poll_reset(TimeNs now_ns) {
  if (failed_resets_ >= kMaxFailedResets) {
    return make_error(Errc::kDevice, "MPU-6000 on " + bus_.name() + " did not come up after " +
                                         std::to_string(kMaxFailedResets) + " resets (last problem: " +
                                         last_problem_ + "); check power and wiring");
  }
  ++counters_.resets;
  ++failed_resets_;
  bus_.set_speed_hz(settings_.config_speed_hz);
  if (!write_reg(Register::PWR_MGMT_1, DEVICE_RESET).ok()) {
    last_problem_ = "writing DEVICE_RESET failed";
    wake_t_ns_ = now_ns + kRetryDelayNs;
    return PollResult{std::nullopt, wake_t_ns_};
  }
  enter(State::kWaitForReset, now_ns);
  wake_t_ns_ = now_ns + kResetDelayNs;
  return PollResult{std::nullopt, wake_t_ns_};
}

Result<PollResult> Mpu6000::poll_wait_for_reset(TimeNs now_ns) {
  bus_.set_speed_hz(settings_.config_speed_hz);
  auto retry = [&](const std::string& problem) -> Result<PollResult> {
    last_problem_ = problem;
    ++attempts_;
    if (now_ns - state_t_ns_ > kWaitForResetTimeoutNs) {
      enter(State::kReset, now_ns);
      return PollResult{std::nullopt, now_ns};
    }
    wake_t_ns_ = now_ns + kRetryDelayNs;
    return PollResult{std::nullopt, wake_t_ns_};
  };
  if (substep_ == 0) {
    auto who = read_reg(Register::WHO_AM_I);
    if (!who.ok()) return retry("reading WHO_AM_I failed: " + who.error().message);
    if (*who != WHOAMI) {
      if (++who_mismatches_ >= kMaxWhoAmIMismatches) {
        return make_error(Errc::kDevice,
                          "MPU-6000 on " + bus_.name() + ": WHO_AM_I reads " + format_hex(*who, 2) +
                              ", expected " + format_hex(WHOAMI, 2) +
                              "; check the bus, chip select and wiring, or whether this is another chip");
      }
      return retry("WHO_AM_I reads " + format_hex(*who, 2));
    }
    who_mismatches_ = 0;
    auto pwr = read_reg(Register::PWR_MGMT_1);
    if (!pwr.ok()) return retry("reading PWR_MGMT_1 failed: " + pwr.error().message);
    if (*pwr != kPwrMgmt1ResetValue)
      return retry("PWR_MGMT_1 reads " + format_hex(*pwr, 2) + " after reset, expected 0x40");
    if (!write_reg(Register::SIGNAL_PATH_RESET, GYRO_RESET | ACCEL_RESET | TEMP_RESET).ok()) {
      return retry("writing SIGNAL_PATH_RESET failed");
    }
    substep_ = 1;
    wake_t_ns_ = now_ns + kSignalPathResetDelayNs;
    return PollResult{std::nullopt, wake_t_ns_};
  }
  // Wake with the PLL clock; on SPI disable the I2C interface right away (RM 4.27).
  if (!write_reg(Register::PWR_MGMT_1, CLKSEL_PLL_GYRO_X).ok()) return retry("waking the chip failed");
  if (settings_.bus == BusKind::kSpi && !write_reg(Register::USER_CTRL, I2C_IF_DIS).ok()) {
    return retry("writing USER_CTRL failed");
  }
  enter(State::kConfigure, now_ns);
  wake_t_ns_ = now_ns + kGyroStartupNs;
  return PollResult{std::nullopt, wake_t_ns_};
}

Result<PollResult> Mpu6000::poll_configure(TimeNs now_ns) {
  bus_.set_speed_hz(settings_.config_speed_hz);
  bool ok = true;
  for (const auto& row : config_) {
    if (!apply_row(row).ok()) {
      ok = false;
      last_problem_ = "writing configuration failed";
      break;
    }
  }
  if (ok) {
    for (const auto& row : config_) {
      auto good = check_row(row);
      if (!good.ok() || !*good) {
        ok = false;
        if (good.ok()) ++counters_.config_mismatches;
        last_problem_ = "register " + format_hex(u8(row.reg), 2) + " did not read back as configured";
        break;
      }
    }
  }
  if (ok && !reset_fifo().ok()) {
    ok = false;
    last_problem_ = "resetting the FIFO failed";
  }
  if (!ok) {
    if (++attempts_ >= kMaxConfigureAttempts) {
      enter(State::kReset, now_ns);
      return PollResult{std::nullopt, now_ns};
    }
    wake_t_ns_ = now_ns + kRetryDelayNs;
    return PollResult{std::nullopt, wake_t_ns_};
  }
  // Seed the temperature check from the data registers (a sensor register: fast clock allowed).
  bus_.set_speed_hz(settings_.fifo_speed_hz);
  std::array<std::uint8_t, 2> t{};
  if (bus_.read(u8(Register::TEMP_OUT_H), t).ok()) {
    const std::int16_t raw = be16(t[0], t[1]);
    if (raw >= temp_raw(kMinTempC) && raw <= temp_raw(kMaxTempC) && !(raw == 0 && !last_temp_))
      last_temp_ = raw;
  }
  pending_flags_ |= kImuFlagDeviceReset;
  enter(State::kStream, now_ns);
  failed_resets_ = 0;
  consecutive_failures_ = 0;
  last_check_t_ns_ = now_ns;
  last_data_t_ns_ = now_ns;
  return PollResult{std::nullopt, now_ns + settings_.read_interval_ns};
}

void Mpu6000::discard_and_reset_fifo(FifoBatch& batch, std::uint32_t frames) {
  batch.frames_discarded += frames;
  counters_.frames_discarded += frames;
  ++counters_.fifo_resets;
  pending_flags_ |= kImuFlagGapBefore | kImuFlagDeviceReset;
  batch.flags |= kImuFlagGapBefore | kImuFlagDeviceReset;
  fifo_reset_needed_ = !reset_fifo().ok();
  if (fifo_reset_needed_) ++consecutive_failures_;
}

Result<PollResult> Mpu6000::poll_stream(TimeNs now_ns, std::optional<DataReadyEdge> edge) {
  PollResult result;
  result.next_poll_ns = now_ns + settings_.read_interval_ns;
  FifoBatch& batch = result.batch.emplace();
  batch.read_t_ns = now_ns;
  batch.edge = edge;
  if (edge) on_edge(*edge);
  // A step that ends the poll: a failure counts towards a reset, anything else stands as is.
  auto finish = [&](StreamStep step) {
    if (step == StreamStep::kFailed) count_failure(now_ns, result);
    return result;
  };

  // One configuration row per interval, rotating (a chip that reset itself shows up here).
  if (now_ns - last_check_t_ns_ >= settings_.config_check_interval_ns) {
    if (const StreamStep step = check_next_config_row(now_ns, result); step != StreamStep::kContinue)
      return finish(step);
  }
  if (fifo_reset_needed_) {
    fifo_reset_needed_ = !reset_fifo().ok();
    if (fifo_reset_needed_) return finish(StreamStep::kFailed);
  }
  std::uint16_t count = 0;
  if (const StreamStep step = check_fifo_count(now_ns, result, count); step != StreamStep::kContinue)
    return finish(step);

  // Read every frame but the newest: it stays in the FIFO and is read first next time.
  const std::size_t frames = count / FIFO::kFrameBytes - 1;
  buffer_.resize(frames * FIFO::kFrameBytes);
  if (!bus_.read(u8(Register::FIFO_R_W), buffer_).ok()) {
    ++counters_.bad_transfers;
    // A failed burst may have consumed part of the FIFO: its alignment is unknown.
    discard_and_reset_fifo(batch, count / FIFO::kFrameBytes);
    return finish(StreamStep::kFailed);
  }
  consecutive_failures_ = 0;
  std::uint32_t frames_after = 0;
  if (const StreamStep step = verify_fifo_after_burst(count, frames, batch, frames_after);
      step != StreamStep::kContinue)
    return finish(step);
  decode_frames(frames, frames_after, batch);
  return result;
}

void Mpu6000::count_failure(TimeNs now_ns, PollResult& result) {
  if (++consecutive_failures_ >= kMaxConsecutiveFailures) {
    last_problem_ = std::to_string(kMaxConsecutiveFailures) + " consecutive failed reads";
    result.batch->flags |= pending_flags_;
    request_reset(now_ns);
    result.next_poll_ns = now_ns;
  }
}

Mpu6000::StreamStep Mpu6000::check_next_config_row(TimeNs now_ns, PollResult& result) {
  last_check_t_ns_ = now_ns;
  bus_.set_speed_hz(settings_.config_speed_hz);
  const ConfigRow& row = config_[checked_row_];
  auto good = check_row(row);
  if (!good.ok()) return StreamStep::kFailed;
  bool lost = !*good;
  if (lost) {
    // Read again: a corrupted transfer is not a lost configuration.
    auto again = check_row(row);
    if (!again.ok()) return StreamStep::kFailed;
    lost = !*again;
    if (!lost) ++counters_.bad_transfers;
  }
  if (lost) {
    ++counters_.config_mismatches;
    last_problem_ = "register " + format_hex(u8(row.reg), 2) + " lost its configuration";
    request_reset(now_ns);
    result.batch->flags |= kImuFlagGapBefore | kImuFlagDeviceReset;
    result.next_poll_ns = now_ns;
    return StreamStep::kDone;
  }
  checked_row_ = (checked_row_ + 1) % config_.size();
  return StreamStep::kContinue;
}

Mpu6000::StreamStep Mpu6000::check_fifo_count(TimeNs now_ns, PollResult& result, std::uint16_t& count) {
  FifoBatch& batch = *result.batch;
  bus_.set_speed_hz(settings_.fifo_speed_hz);
  const std::optional<std::uint16_t> counted = read_fifo_count();
  if (!counted) return StreamStep::kFailed;  // nothing read, nothing lost: the data waits in the FIFO
  count = *counted;
  batch.fifo_bytes = count;
  // More than the frame a read keeps back: the chip is writing (even if what follows is a reset).
  if (count > FIFO::kFrameBytes) last_data_t_ns_ = now_ns;

  if (count > kFifoSizeBytes) {
    ++counters_.bad_fifo_counts;  // impossible value: the transfer itself was bad
    discard_and_reset_fifo(batch, 0);
    return StreamStep::kFailed;
  }
  if (count == kFifoSizeBytes) {
    ++counters_.fifo_overflows;  // full: the oldest data has been overwritten, alignment is lost
    discard_and_reset_fifo(batch, count / FIFO::kFrameBytes);
    return StreamStep::kDone;
  }
  if (count % FIFO::kFrameBytes != 0) {
    ++counters_.bad_fifo_counts;
    discard_and_reset_fifo(batch, count / FIFO::kFrameBytes);
    return StreamStep::kDone;
  }
  batch.frames_left = count / FIFO::kFrameBytes;
  if (count <= FIFO::kFrameBytes) {
    // Empty, or a single frame, which is kept back: nothing to read yet.
    consecutive_failures_ = 0;
    const TimeNs timeout_ns = std::max<TimeNs>(50'000'000, 10 * settings_.sample_period_ns());
    if (now_ns - last_data_t_ns_ > timeout_ns) {
      ++counters_.no_data_timeouts;
      last_problem_ = "no FIFO data while streaming";
      request_reset(now_ns);
      batch.flags |= kImuFlagGapBefore | kImuFlagDeviceReset;
      result.next_poll_ns = now_ns;
    }
    return StreamStep::kDone;
  }
  if (count > settings_.fifo_watermark_bytes()) {
    // Reading this late risks reading data the chip is overwriting: drop it cleanly instead.
    discard_and_reset_fifo(batch, count / FIFO::kFrameBytes);
    return StreamStep::kDone;
  }
  return StreamStep::kContinue;
}

Mpu6000::StreamStep Mpu6000::verify_fifo_after_burst(std::uint16_t count, std::size_t frames,
                                                     FifoBatch& batch, std::uint32_t& frames_after) {
  // The FIFO now holds the frame left behind plus the frames written since FIFO_COUNT was read:
  // (1 + m) * 14 bytes, m >= 0, whatever m is. A byte lost on the bus during this burst (or
  // gained) leaves the count one byte off a whole number of frames, wherever in the burst it
  // happened, and the frames just read misaligned from that byte on even where their
  // temperature field happens to look plausible. Without a verified count nothing is passed on.
  std::optional<std::uint16_t> after;
  for (int attempt = 0; attempt < 2 && !(after && *after <= kFifoSizeBytes); ++attempt) {
    after = read_fifo_count();
    if (after && *after > kFifoSizeBytes) ++counters_.bad_fifo_counts;
  }
  if (!after || *after > kFifoSizeBytes) {
    last_problem_ = "FIFO count after a read could not be read";
    discard_and_reset_fifo(batch, static_cast<std::uint32_t>(count / FIFO::kFrameBytes));
    return StreamStep::kFailed;
  }
  const std::uint16_t count_after = *after;
  // Frames in the FIFO now, counting one that lost a byte.
  frames_after = (count_after + FIFO::kFrameBytes - 1) / FIFO::kFrameBytes;
  if (count_after == kFifoSizeBytes) {
    ++counters_.fifo_overflows;  // filled up during the burst: what was read may have been overwritten
    last_problem_ = "FIFO overflowed during a read";
    discard_and_reset_fifo(batch, static_cast<std::uint32_t>(frames + count_after / FIFO::kFrameBytes));
    return StreamStep::kDone;
  }
  if (count_after < FIFO::kFrameBytes || count_after % FIFO::kFrameBytes != 0) {
    ++counters_.bad_fifo_counts;
    last_problem_ = "FIFO misaligned after a read";
    discard_and_reset_fifo(batch, static_cast<std::uint32_t>(frames) + frames_after);
    return StreamStep::kDone;
  }
  return StreamStep::kContinue;
}

void Mpu6000::decode_frames(std::size_t frames, std::uint32_t frames_after, FifoBatch& batch) {
  const auto max_step = static_cast<int>(std::lround(settings_.max_temperature_step_c * kTempLsbPerDegC));
  batch.samples.reserve(frames);
  for (std::size_t i = 0; i < frames; ++i) {
    const std::uint8_t* f = buffer_.data() + i * FIFO::kFrameBytes;
    const bool all_ones = std::all_of(f, f + FIFO::kFrameBytes, [](std::uint8_t b) { return b == 0xFF; });
    const bool all_zero = std::all_of(f, f + FIFO::kFrameBytes, [](std::uint8_t b) { return b == 0x00; });
    FIFO::DATA d;
    std::memcpy(&d, f, sizeof d);
    RawSample s;
    s.accel = {be16(d.ACCEL_XOUT_H, d.ACCEL_XOUT_L), be16(d.ACCEL_YOUT_H, d.ACCEL_YOUT_L),
               be16(d.ACCEL_ZOUT_H, d.ACCEL_ZOUT_L)};
    s.temp = be16(d.TEMP_OUT_H, d.TEMP_OUT_L);
    s.gyro = {be16(d.GYRO_XOUT_H, d.GYRO_XOUT_L), be16(d.GYRO_YOUT_H, d.GYRO_YOUT_L),
              be16(d.GYRO_ZOUT_H, d.GYRO_ZOUT_L)};
    const bool temp_in_range = s.temp >= temp_raw(kMinTempC) && s.temp <= temp_raw(kMaxTempC);
    const bool temp_jump = last_temp_ && std::abs(static_cast<int>(s.temp) - *last_temp_) > max_step;
    if (all_ones || all_zero || !temp_in_range || temp_jump) {
      ++counters_.implausible_data;
      last_problem_ = "implausible FIFO data (misaligned or corrupted frame)";
      discard_and_reset_fifo(batch, static_cast<std::uint32_t>(frames - i) + frames_after);
      break;
    }
    last_temp_ = s.temp;
    auto saturated = [](const std::array<std::int16_t, 3>& v) {
      return std::any_of(v.begin(), v.end(), [](std::int16_t x) { return x == 32767 || x == -32768; });
    };
    if (saturated(s.accel)) s.flags |= kImuFlagAccelSaturated;
    if (saturated(s.gyro)) s.flags |= kImuFlagGyroSaturated;
    if (pending_flags_) {
      s.flags |= pending_flags_;
      batch.flags |= pending_flags_;
      pending_flags_ = kImuFlagNone;
    }
    batch.samples.push_back(s);
  }
  batch.frames_left -= static_cast<std::uint32_t>(batch.samples.size());
  counters_.samples += batch.samples.size();
}

Result<std::array<double, 6>> Mpu6000::average_outputs(int samples, const DelayFn& delay) {
  std::array<double, 6> sum{};
  bus_.set_speed_hz(settings_.fifo_speed_hz);
  for (int n = 0; n < samples; ++n) {
    delay(settings_.sample_period_ns());
    std::array<std::uint8_t, 14> raw{};
    auto s = bus_.read(u8(Register::ACCEL_XOUT_H), raw);
    if (!s.ok()) {
      ++counters_.bad_transfers;
      return s.error().context("self-test: reading the sensor registers");
    }
    for (int i = 0; i < 3; ++i) {
      sum[i] += be16(raw[2 * i], raw[2 * i + 1]);
      sum[3 + i] += be16(raw[8 + 2 * i], raw[8 + 2 * i + 1]);
    }
  }
  for (auto& v : sum) v /= samples;
  return sum;
}

Result<SelfTestResult> Mpu6000::self_test(const DelayFn& delay) {
  if (state_ != State::kStream) {
    return make_error(Errc::kInvalidArgument,
                      std::string("MPU-6000 self-test needs a configured device (state is ") +
                          state_name(state_) + "); call poll() until it streams");
  }
  constexpr int kSamples = 50;
  // Settling after a range or self-test change; the datasheet gives no figure, so this waits
  // well beyond the slowest DLPF setting's delay (19 ms at 5 Hz, RM 4.3).
  constexpr TimeNs kSettleNs = 50'000'000;
  bus_.set_speed_hz(settings_.config_speed_hz);
  // RM 4.1: gyro self-test at +-250 dps, accel self-test at +-8 g.
  const std::uint8_t accel_8g = static_cast<std::uint8_t>(static_cast<std::uint8_t>(AccelRange::k8g) << 3);
  auto run = [&]() -> Result<SelfTestResult> {
    IMUCAL_TRY(write_reg(Register::GYRO_CONFIG, 0));
    IMUCAL_TRY(write_reg(Register::ACCEL_CONFIG, accel_8g));
    delay(kSettleNs);
    auto off = average_outputs(kSamples, delay);
    if (!off.ok()) return off.error();
    bus_.set_speed_hz(settings_.config_speed_hz);
    IMUCAL_TRY(write_reg(Register::GYRO_CONFIG, XG_ST | YG_ST | ZG_ST));
    IMUCAL_TRY(
        write_reg(Register::ACCEL_CONFIG, static_cast<std::uint8_t>(XA_ST | YA_ST | ZA_ST | accel_8g)));
    delay(kSettleNs);
    auto on = average_outputs(kSamples, delay);
    if (!on.ok()) return on.error();
    bus_.set_speed_hz(settings_.config_speed_hz);
    IMUCAL_TRY(write_reg(Register::GYRO_CONFIG, 0));
    IMUCAL_TRY(write_reg(Register::ACCEL_CONFIG, accel_8g));
    std::array<std::uint8_t, 4> st{};
    auto s = bus_.read(u8(Register::SELF_TEST_X), st);
    if (!s.ok()) {
      ++counters_.bad_transfers;
      return s.error().context("self-test: reading SELF_TEST registers");
    }
    SelfTestResult r;
    for (int i = 0; i < 3; ++i) {
      const int xa_test = ((st[i] >> 5) & 0x7) << 2 | ((st[3] >> (4 - 2 * i)) & 0x3);
      const int xg_test = st[i] & 0x1F;
      // RM 4.1 factory trim: accel FT = 4096 * 0.34 * (0.92/0.34)^((A_TEST-1)/(2^5-2)),
      // gyro FT = 25 * 131 * 1.046^(G_TEST-1) (negative for Y); 0 when the code is 0.
      const double ft_a = xa_test == 0 ? 0.0 : 4096.0 * 0.34 * std::pow(0.92 / 0.34, (xa_test - 1.0) / 30.0);
      double ft_g = xg_test == 0 ? 0.0 : 25.0 * 131.0 * std::pow(1.046, xg_test - 1.0);
      if (i == 1) ft_g = -ft_g;
      auto judge = [](double ft, double str) {
        SelfTestAxis a;
        a.factory_trim = ft;
        a.response = str;
        a.change = ft != 0.0 ? (str - ft) / ft : std::numeric_limits<double>::infinity();
        a.pass = ft != 0.0 && std::abs(a.change) <= 0.14;  // PS 6.1, 6.2: +-14 %
        return a;
      };
      r.accel[i] = judge(ft_a, (*on)[i] - (*off)[i]);
      r.gyro[i] = judge(ft_g, (*on)[3 + i] - (*off)[3 + i]);
    }
    return r;
  };
  auto result = run();
  // Whatever happened, configure again: the ranges and the FIFO are back to the settings.
  pending_flags_ |= kImuFlagGapBefore | kImuFlagDeviceReset;
  enter(State::kConfigure, state_t_ns_);
  wake_t_ns_ = std::numeric_limits<TimeNs>::min();
  return result;
}

std::int16_t gyro_offset_register_for_bias(double bias_counts, GyroRange range) {
  const double value = -bias_counts / gyro_output_counts_per_offset_count(range);
  if (!std::isfinite(value)) return 0;
  return static_cast<std::int16_t>(std::clamp(std::round(value), -32768.0, 32767.0));
}

Result<OffsetRegisters> Mpu6000::read_offsets() {
  bus_.set_speed_hz(settings_.config_speed_hz);
  std::array<std::uint8_t, 6> a{};
  std::array<std::uint8_t, 6> g{};
  if (auto s = bus_.read(u8(Register::XA_OFFS_H), a); !s.ok()) {
    ++counters_.bad_transfers;
    return s.error().context("reading accel offset registers");
  }
  if (auto s = bus_.read(u8(Register::XG_OFFS_USRH), g); !s.ok()) {
    ++counters_.bad_transfers;
    return s.error().context("reading gyro offset registers");
  }
  OffsetRegisters o;
  for (int i = 0; i < 3; ++i) {
    o.accel[i] = be16(a[2 * i], a[2 * i + 1]);
    o.gyro[i] = be16(g[2 * i], g[2 * i + 1]);
  }
  return o;
}

Status Mpu6000::write_offsets(const OffsetRegisters& offsets) {
  auto current = read_offsets();
  if (!current.ok()) return current.error();
  OffsetRegisters want = offsets;
  for (int i = 0; i < 3; ++i) {
    // Bit 0 of each accel offset is reserved (temperature compensation): keep the chip's.
    want.accel[i] = static_cast<std::int16_t>((offsets.accel[i] & ~1) | (current->accel[i] & 1));
  }
  bus_.set_speed_hz(settings_.config_speed_hz);
  for (int i = 0; i < 3; ++i) {
    const auto a = static_cast<std::uint16_t>(want.accel[i]);
    const auto g = static_cast<std::uint16_t>(want.gyro[i]);
    const auto a_reg = static_cast<Register>(u8(Register::XA_OFFS_H) + 2 * i);
    const auto g_reg = static_cast<Register>(u8(Register::XG_OFFS_USRH) + 2 * i);
    IMUCAL_TRY(write_reg(a_reg, static_cast<std::uint8_t>(a >> 8)));
    IMUCAL_TRY(write_reg(static_cast<Register>(u8(a_reg) + 1), static_cast<std::uint8_t>(a & 0xFF)));
    IMUCAL_TRY(write_reg(g_reg, static_cast<std::uint8_t>(g >> 8)));
    IMUCAL_TRY(write_reg(static_cast<Register>(u8(g_reg) + 1), static_cast<std::uint8_t>(g & 0xFF)));
  }
  auto back = read_offsets();
  if (!back.ok()) return back.error();
  if (back->accel != want.accel || back->gyro != want.gyro) {
    return make_error(Errc::kDevice,
                      "MPU-6000 on " + bus_.name() +
                          ": offset registers did not read back as written; the bus may be unreliable");
  }
  return {};
}

std::string Mpu6000::status_line() const {
  const Counters& c = counters_;
  std::ostringstream os;
  os << "state=" << state_name(state_) << " samples=" << c.samples << " bad_transfers=" << c.bad_transfers
     << " fifo_overflows=" << c.fifo_overflows << " fifo_resets=" << c.fifo_resets
     << " bad_fifo_counts=" << c.bad_fifo_counts << " implausible=" << c.implausible_data
     << " config_mismatches=" << c.config_mismatches << " resets=" << c.resets
     << " missed_drdy=" << c.missed_data_ready << " no_data=" << c.no_data_timeouts
     << " frames_discarded=" << c.frames_discarded;
  return os.str();
}

}  // namespace imucal::drivers::mpu6000
