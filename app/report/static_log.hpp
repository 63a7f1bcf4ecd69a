// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// What a static report takes from the log beside the result (internal to app/report): the
// samples of the calibrated stream, the result's static intervals located in them, and per-pose
// quality figures recomputed with calib/quality.hpp (the result JSON has only their means), from
// the result's model and the stream's nominal conversion; no solver is run.

#include <Eigen/Core>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/report/gnuplot.hpp"
#include "core/imu.hpp"
#include "core/result.hpp"

namespace imucal::app::report {

struct StaticLogData {
  ImuStreamInfo info;
  std::vector<ImuSample> samples;
  std::string damage_warning;  // empty for an intact log
  struct Pose {
    std::size_t begin = 0, end = 0;  // samples [begin, end]
    Eigen::Vector3d mean_raw = Eigen::Vector3d::Zero();
    Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // calibrated, unit
  };
  std::vector<Pose> poses;
  bool before_available = false;  // the stream has a nominal accelerometer conversion
  std::vector<double> magnitude_after_mps2, magnitude_before_mps2;  // per pose
  std::vector<double> direction_after_rad, direction_before_rad;    // per motion k -> k+1
};

/// Reads the log's stream named by the result and recomputes the per-pose figures. Errors name
/// the log; kCorrupt when the result's intervals are not in the log (another log given).
[[nodiscard]] Result<StaticLogData> static_log_data(const nlohmann::json& result,
                                                    const std::string& log_path);

/// The accelerometer (`gyro` false, m/s^2) or gyroscope (deg/s) signal on the nominal conversion,
/// with the static intervals shaded.
Figure signal_figure(const StaticLogData& data, bool gyro);
/// | |a| - g | per pose, before (nominal) and after calibration, log scale.
Figure magnitude_figure(const StaticLogData& data);
/// Gravity direction error per motion, before and after, log scale.
Figure direction_figure(const StaticLogData& data);
/// The calibrated gravity directions of the poses on the unit sphere.
Figure sphere_figure(const StaticLogData& data);

}  // namespace imucal::app::report
