// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// MPU-6000 driver: a clock-agnostic state machine over a RegisterBus.
//
//   Reset -> WaitForReset -> Configure -> Stream
//
// The caller owns the clock and the data-ready line: it calls poll(now_ns, edge) whenever an
// edge arrives or at the latest at PollResult::next_poll_ns, and receives the FIFO contents as
// raw counts. Problems while streaming (bad transfers, FIFO overflow, odd FIFO counts,
// implausible data, configuration lost) are counted per cause, recovered from by a FIFO or chip
// reset, and marked in the output with kImuFlagGapBefore / kImuFlagDeviceReset; the damaged data
// itself is never passed on. Only unrecoverable conditions (wrong WHO_AM_I, a device that stays
// silent through repeated resets) come back as errors.

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "core/time.hpp"
#include "drivers/bus/register_bus.hpp"
#include "drivers/gpio/data_ready_line.hpp"
#include "drivers/mpu6000/registers.hpp"

namespace imucal::drivers::mpu6000 {

enum class BusKind { kSpi, kI2c };

/// Device settings. Rates: sample rate = gyro output rate / (1 + smplrt_div), gyro output rate
/// 8 kHz with dlpf_cfg 0, 1 kHz with dlpf_cfg 1..6 (RM 4.2).
struct Settings {
  BusKind bus = BusKind::kSpi;
  AccelRange accel_range = AccelRange::k16g;
  GyroRange gyro_range = GyroRange::k2000dps;
  std::uint8_t dlpf_cfg = 1;    // 0..6, see kDlpfGyroBandwidthHz
  std::uint8_t smplrt_div = 0;  // sample rate divider
  /// The longest interval at which the caller promises to call poll() while streaming. It sets
  /// the FIFO watermark and must leave room in the FIFO (validate()).
  TimeNs read_interval_ns = 2'000'000;
  /// SPI clocks: configuration registers at 1 MHz, sensor/FIFO reads up to 20 MHz (PS 6.5).
  std::uint32_t config_speed_hz = kSpiConfigSpeedHz;
  std::uint32_t fifo_speed_hz = kSpiSensorSpeedHz;
  /// One configuration row is re-read and verified at this interval while streaming.
  TimeNs config_check_interval_ns = 100'000'000;
  /// Largest plausible change of the temperature between consecutive samples, deg C.
  double max_temperature_step_c = 2.0;

  std::uint32_t gyro_rate_hz() const { return (dlpf_cfg == 0 || dlpf_cfg == 7) ? 8000 : 1000; }
  double sample_rate_hz() const { return static_cast<double>(gyro_rate_hz()) / (1.0 + smplrt_div); }
  TimeNs sample_period_ns() const {
    return static_cast<TimeNs>((1'000'000'000ll / gyro_rate_hz()) * (1 + smplrt_div));
  }
  /// Accel SI per count: m/s^2 per LSB (standard gravity). Gyro: rad/s per LSB.
  double accel_scale_si() const;
  double gyro_scale_si() const;
  /// FIFO level (bytes) above which unread data could be overwritten before the read completes;
  /// the driver resets the FIFO instead of reading it (see docs/mpu6000.md).
  std::uint16_t fifo_watermark_bytes() const;

  /// An error that says why when the combination cannot work (e.g. the FIFO would overflow
  /// within one read interval).
  [[nodiscard]] Status validate() const;
};

/// Nominal raw->SI description of the stream this driver produces (units kRaw).
ImuStreamInfo make_stream_info(const Settings& settings, const std::string& device);

/// One sample as read from the FIFO, in device counts and the device's axis order (x, y, z).
struct RawSample {
  std::array<std::int16_t, 3> accel{};
  std::array<std::int16_t, 3> gyro{};
  std::int16_t temp = 0;
  std::uint32_t flags = kImuFlagNone;  // ImuFlag bits: gap / reset before this sample, saturation
};

/// The result of one FIFO read. The newest frame counted in FIFO_COUNT is not read: it stays in
/// the FIFO so that the count after the burst shows any byte lost or gained on the bus, and it
/// comes out first in the next read. `frames_left` says how many frames newer than the batch's
/// last sample the FIFO held when its count was read (1 normally; more when a damaged frame made
/// the driver stop early and reset the FIFO): the data-ready edge belongs to the newest of them.
struct FifoBatch {
  TimeNs read_t_ns = 0;                // host time passed to poll(), just before FIFO_COUNT was read
  std::optional<DataReadyEdge> edge;   // the edge passed to poll(), if any
  std::uint16_t fifo_bytes = 0;        // FIFO_COUNT read in this poll (before the data was read)
  std::vector<RawSample> samples;      // oldest first; sampled frames_left periods before the newest
  std::uint32_t frames_left = 0;       // frames counted in fifo_bytes that are newer than samples
  std::uint32_t flags = kImuFlagNone;  // union of what happened before samples[0] (gap, reset)
  std::uint32_t frames_discarded = 0;  // whole frames dropped in this poll (FIFO reset, bad data)
};

enum class State { kReset, kWaitForReset, kConfigure, kStream };
const char* state_name(State state);

/// Failure counters per cause, for status output.
struct Counters {
  std::uint64_t bad_transfers = 0;      // a bus read or write failed
  std::uint64_t fifo_overflows = 0;     // FIFO full (count 1024 or FIFO_OFLOW_INT)
  std::uint64_t fifo_resets = 0;        // FIFO resets while streaming (any cause)
  std::uint64_t bad_fifo_counts = 0;    // FIFO_COUNT > 1024 or not whole frames (before or after a burst)
  std::uint64_t implausible_data = 0;   // temperature jump / out of range, blank frame
  std::uint64_t config_mismatches = 0;  // a configuration row read back wrong
  std::uint64_t resets = 0;             // chip resets (first start included)
  std::uint64_t missed_data_ready = 0;  // gaps in the data-ready edge sequence
  std::uint64_t no_data_timeouts = 0;   // no FIFO data for too long while streaming
  std::uint64_t samples = 0;            // good samples delivered
  std::uint64_t frames_discarded = 0;   // frames dropped by the above
};

struct PollResult {
  std::optional<FifoBatch> batch;  // set in Stream when the FIFO was read (possibly empty)
  TimeNs next_poll_ns = 0;         // call poll() again at the latest at this time
};

/// Offset registers as stored: accel in 1/2048 g (bit 0 reserved, preserved on write), gyro in
/// 1/32.8 deg/s. The chip adds them to its outputs (scaled to the configured range).
struct OffsetRegisters {
  std::array<std::int16_t, 3> accel{};
  std::array<std::int16_t, 3> gyro{};
};

/// The gyro offset register value that cancels a bias of `bias_counts` output counts at range
/// `range` (reg::gyro_output_counts_per_offset_count), rounded to the nearest register count and
/// held within int16.
std::int16_t gyro_offset_register_for_bias(double bias_counts, GyroRange range);

struct SelfTestAxis {
  double factory_trim = 0.0;  // FT, counts at the self-test range
  double response = 0.0;      // STR = output(self-test on) - output(self-test off), counts
  double change = 0.0;        // (STR - FT) / FT
  bool pass = false;          // |change| <= 14 %
};

struct SelfTestResult {
  std::array<SelfTestAxis, 3> accel;
  std::array<SelfTestAxis, 3> gyro;
  bool pass() const;
  std::string summary() const;
};

/// Waits `delay_ns` of the caller's clock (real sleep on a rig, advancing time in simulation).
using DelayFn = std::function<void(TimeNs delay_ns)>;

class Mpu6000 {
 public:
  /// The bus is borrowed and must outlive the driver.
  Mpu6000(RegisterBus& bus, Settings settings);

  /// Reads WHO_AM_I at the configuration clock. Errors: bus failure, or kDevice naming the value.
  [[nodiscard]] Status probe();

  /// Advances the state machine. `edge` is the latest data-ready edge since the previous call;
  /// it is passed on in the batch for timestamping. Callers that collect several edges per poll
  /// report each with on_edge() so that edges lost by the host are counted.
  [[nodiscard]] Result<PollResult> poll(TimeNs now_ns, std::optional<DataReadyEdge> edge = std::nullopt);

  /// Notes a data-ready edge: a jump in its sequence number counts as missed_data_ready.
  void on_edge(const DataReadyEdge& edge);

  /// Datasheet self-test (RM 4.1, PS 6.1/6.2): factory trim from SELF_TEST_*, response with
  /// self-test enabled minus disabled, pass within +-14 %. Runs outside streaming; afterwards the
  /// driver reconfigures (state Configure). `delay` waits on the caller's clock.
  [[nodiscard]] Result<SelfTestResult> self_test(const DelayFn& delay);

  [[nodiscard]] Result<OffsetRegisters> read_offsets();
  [[nodiscard]] Status write_offsets(const OffsetRegisters& offsets);

  State state() const { return state_; }
  const Counters& counters() const { return counters_; }
  const Settings& settings() const { return settings_; }
  /// One line of counters for status output.
  std::string status_line() const;

  struct ConfigRow {
    Register reg;
    std::uint8_t set_bits;
    std::uint8_t clear_bits;
  };
  const std::vector<ConfigRow>& config_rows() const { return config_; }

 private:
  [[nodiscard]] Status write_reg(Register reg, std::uint8_t value);
  [[nodiscard]] Result<std::uint8_t> read_reg(Register reg);
  [[nodiscard]] Status apply_row(const ConfigRow& row);
  /// Ok(true) when the register holds the row's bits.
  [[nodiscard]] Result<bool> check_row(const ConfigRow& row);
  void enter(State s, TimeNs at_ns);
  void request_reset(TimeNs now_ns);
  [[nodiscard]] Status reset_fifo();
  /// Reads FIFO_COUNT (fast clock); nullopt after a failed transfer.
  std::optional<std::uint16_t> read_fifo_count();
  Result<PollResult> poll_reset(TimeNs now_ns);
  Result<PollResult> poll_wait_for_reset(TimeNs now_ns);
  Result<PollResult> poll_configure(TimeNs now_ns);
  Result<PollResult> poll_stream(TimeNs now_ns, std::optional<DataReadyEdge> edge);
  // The steps of a streaming poll. kDone ends the poll with the result as it stands, kFailed
  // ends it as a failed read (count_failure: enough in a row reset the chip).
  enum class StreamStep { kContinue, kDone, kFailed };
  void count_failure(TimeNs now_ns, PollResult& result);
  StreamStep check_next_config_row(TimeNs now_ns, PollResult& result);
  /// Reads FIFO_COUNT into `count`; kContinue when it holds frames to read now.
  StreamStep check_fifo_count(TimeNs now_ns, PollResult& result, std::uint16_t& count);
  /// After the burst of `frames` frames (of `count` bytes counted): FIFO_COUNT must again be a
  /// whole number of frames. `frames_after` receives the frames now in the FIFO.
  StreamStep verify_fifo_after_burst(std::uint16_t count, std::size_t frames, FifoBatch& batch,
                                     std::uint32_t& frames_after);
  /// Turns the frames read into samples, up to the first implausible one.
  void decode_frames(std::size_t frames, std::uint32_t frames_after, FifoBatch& batch);
  void discard_and_reset_fifo(FifoBatch& batch, std::uint32_t frames);
  [[nodiscard]] Result<std::array<double, 6>> average_outputs(int samples, const DelayFn& delay);

  RegisterBus& bus_;
  Settings settings_;
  std::vector<ConfigRow> config_;
  State state_ = State::kReset;
  TimeNs state_t_ns_ = 0;  // when the current state was entered
  TimeNs wake_t_ns_ = 0;   // do nothing in this state before this time (datasheet delays)
  int substep_ = 0;
  int attempts_ = 0;       // failed attempts in the current state
  int failed_resets_ = 0;  // consecutive resets that did not reach Stream
  int consecutive_failures_ = 0;
  int who_mismatches_ = 0;
  std::string last_problem_ = "none";
  std::size_t checked_row_ = 0;
  TimeNs last_check_t_ns_ = 0;
  TimeNs last_data_t_ns_ = 0;
  std::optional<std::uint64_t> last_edge_seq_;
  std::optional<std::int16_t> last_temp_;
  std::uint32_t pending_flags_ = kImuFlagNone;
  bool fifo_reset_needed_ = false;
  Counters counters_;
  std::vector<std::uint8_t> buffer_;
};

}  // namespace imucal::drivers::mpu6000
