#pragma once
// Writes a simulated IMU session into a session log: a sim::Trajectory sampled at the IMU rate
// through the MPU-6000 error model (drivers/sim/imu_model.hpp), stored as raw int16 counts with
// the nominal conversion of the full-scale range, the script's segments as events, and the
// ground truth as YAML next to the log. Used by `imucal sim static|gsens|still`.

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "core/imu.hpp"
#include "core/result.hpp"
#include "drivers/sim/imu_model.hpp"
#include "drivers/sim/trajectory.hpp"
#include "drivers/sim/truth.hpp"

namespace imucal::acq {

/// A span of the recording whose samples are lost (the next recorded sample carries
/// kImuFlagGapBefore), for fixtures that exercise gap handling.
struct SampleDrop {
  double start_s = 0.0;  // from the start of the trajectory
  double duration_s = 0.0;
};

struct SimImuSessionOptions {
  std::string kind = "static";    // recorded as the truth's `kind` and in the metadata
  std::string script = "static";  // motion script name for the truth's trajectory summary
  int poses = 0;                  // held attitudes in the script (for the summary)
  std::uint64_t seed = 1;
  double imu_rate_hz = 100.0;  // 4..8000 Hz (MPU-6000 output rates)
  sim::ImuModelParams imu;     // the sensor; full-scale ranges inside
  bool params_from_file = false;
  std::vector<SampleDrop> drops;
  bool overwrite = false;  // replace an existing log and truth file

  [[nodiscard]] Status validate() const;
};

/// The stream description of a simulated MPU-6000: raw counts, nominal conversion from the
/// full-scale ranges (accel 9.80665 / LSB_per_g, gyro (pi/180) / LSB_per_dps per count), the
/// TEMP_OUT conversion, device "sim".
ImuStreamInfo sim_imu_stream_info(const sim::ImuModelParams& imu, double rate_hz);

/// Simulates `trajectory` and writes the log at `log_path` and the truth at `truth_path` (no
/// truth file when empty). `progress` (may be empty) receives the completed fraction. Returns
/// the truth that was written.
[[nodiscard]] Result<sim::SimTruth> write_sim_imu_session(const SimImuSessionOptions& options,
                                                          const sim::Trajectory& trajectory,
                                                          const std::string& log_path,
                                                          const std::string& truth_path,
                                                          const std::function<void(double)>& progress = {});

}  // namespace imucal::acq
