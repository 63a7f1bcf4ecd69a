// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Writes a simulated IMU session into a session log: the virtual rig moves along a
// sim::Trajectory, the MPU-6000 error model (sim/imu_error_model.hpp) turns the motion into
// what the sensing elements see, and the samples reach the log the way they do on a rig: through
// the register emulator, the data-ready line, the driver and the acquisition loop (sim/rig.hpp),
// as raw int16 counts with per-sample timestamps reconstructed from the data-ready edges. The
// script's segments become events, and the ground truth is written as YAML next to the log.
// Used by `imucal sim static|gsens|still|camimu`.

#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "acquisition/camera_acquisition.hpp"
#include "acquisition/camera_stream.hpp"
#include "core/frame.hpp"
#include "core/imu.hpp"
#include "core/progress.hpp"
#include "core/result.hpp"
#include "drivers/camera/camera.hpp"
#include "drivers/gpio/fake/sim_data_ready.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/rig.hpp"
#include "sim/trajectory.hpp"
#include "sim/truth.hpp"

namespace imucal::sim {

/// A span during which the host does not read the chip (a stalled process or a held bus), for
/// fixtures that exercise gap handling. The chip keeps sampling; what its 1024-byte FIFO cannot
/// hold (more than 73 samples) is lost, the driver detects the overflow, resets the FIFO and the
/// next recorded sample carries kImuFlagGapBefore. Shorter stalls lose nothing.
struct SampleDrop {
  double start_s = 0.0;  // from the start of the trajectory
  double duration_s = 0.0;
};

/// How the simulated chip is read (sim/rig.hpp): the bus, the chip's oscillator error and the
/// data-ready timing.
struct SimImuPath {
  drivers::mpu6000::BusKind bus = drivers::mpu6000::BusKind::kSpi;
  /// Against the host clock, ppm; the default is a chip 1.5 % slow (rig.hpp).
  double clock_ppm = kDefaultClockPpm;
  fake::DataReadyTiming data_ready;  // 20 us mean latency, 30 us RMS jitter
};

/// A camera of a simulated session (the virtual camera, drivers/camera/fake), recorded through
/// the same camera path as a rig's: its frames are dequeued after every acquisition step, copied
/// into the camera stream and encoded into the log by the stream's encoder thread.
struct SimSessionCamera {
  CameraStreamInfo info;            // name, backend, device as the log describes them
  acq::CameraStreamOptions stream;  // encoding; the session sets the time offset and waits when full
  /// Builds the camera on the rig's host clock, once it exists; host time = trajectory time +
  /// host_offset_ns.
  std::function<Result<std::unique_ptr<drivers::camera::Camera>>(std::function<TimeNs()> host_clock,
                                                                 TimeNs host_offset_ns)>
      make;
  /// Receives the camera's counters at the end of the session (may be null).
  acq::CameraAcquisitionStats* stats_out = nullptr;
};

struct SimImuSessionOptions {
  std::string kind = "static";    // recorded as the truth's `kind` and in the metadata
  std::string script = "static";  // motion script name for the truth's trajectory summary
  int poses = 0;                  // held attitudes in the script (for the summary)
  std::uint64_t seed = 1;
  double imu_rate_hz = 100.0;  // an exact MPU-6000 rate: 8000 / n or 1000 / n Hz, n = 1..256
  sim::ImuModelParams imu;     // the sensor; full-scale ranges inside
  SimImuPath path;             // bus, chip clock, data-ready timing
  bool params_from_file = false;
  std::vector<SampleDrop> drops;
  bool overwrite = false;  // replace an existing log and truth file
  std::vector<SimSessionCamera> cameras;
  /// Merged into the rig_config metadata under "camera" (empty: none).
  std::string rig_camera_json;
  /// Further metadata for the log.
  std::vector<std::pair<std::string, std::string>> metadata;

  [[nodiscard]] Status validate() const;
};

/// The driver settings of the simulated session: the rate (an error names the nearest rates the
/// chip can produce), the DLPF chosen for it, the full-scale ranges of `options.imu`.
[[nodiscard]] Result<drivers::mpu6000::Settings> sim_driver_settings(const SimImuSessionOptions& options);

/// Fails with kAlreadyExists naming the first of `paths` (empty ones skipped) that exists,
/// unless `overwrite`: the simulated session writers check all their outputs before writing any.
[[nodiscard]] Status refuse_existing_outputs(std::initializer_list<std::string> paths, bool overwrite);

/// Simulates `trajectory` and writes the log at `log_path` and the truth at `truth_path` (no
/// truth file when empty). `progress` (may be empty) receives the completed fraction. Returns
/// the truth that was written.
[[nodiscard]] Result<sim::SimTruth> write_sim_imu_session(const SimImuSessionOptions& options,
                                                          const sim::Trajectory& trajectory,
                                                          const std::string& log_path,
                                                          const std::string& truth_path,
                                                          const ProgressFn& progress = {});

}  // namespace imucal::sim
