// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Ground truth of a simulated recording: the IMU model parameters, the corrections a calibration
// should find (in the canonical form of docs/conventions.md section 4 and in the Tedaldi form), and a
// summary of the motion. Written as YAML next to the log (LOG.imulog -> LOG.truth.yaml); the
// `imu:` section is also what `imucal sim --truth FILE` reads back, so a run can be repeated with
// fixed parameters. Format: docs/simulator.md.

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "core/imu_model.hpp"
#include "core/result.hpp"
#include "sim/imu_error_model.hpp"
#include "sim/trajectory.hpp"

namespace imucal::sim {

/// The correction that inverts the model at the turn-on biases, in the body frame (AOF):
/// a = A_a (a_raw - b_a), w = A_g (w_raw - b_g) - G a (core/imu_model.hpp). In SI form a_raw, w_raw
/// are the sensor outputs converted with the nominal full-scale sensitivity (m/s^2, rad/s); in
/// counts form they are the int16 counts and A maps counts to SI. G is (rad/s)/(m/s^2) in both.
CanonicalImuModel canonical_correction(const ImuModelParams& p, bool counts);
/// The Tedaldi form of the correction (Tedaldi et al. eqs. 2.6/2.7: a_O = T_a K_a (a_S + b_a),
/// w_O = T_g K_g (w_S + b_g), without the g-sensitivity, which the form cannot hold), for direct
/// comparison with a Tedaldi estimate. The frame O of this form has its z axis along the
/// accelerometer's z sensing axis and y in its y-z plane (what an upper-triangular T_a implies for
/// sensors that measure projections); it differs from the body frame by a rotation of the order
/// of the misalignments: R_canonical_aof maps O vectors to body vectors.
TedaldiConversion tedaldi_form(const ImuModelParams& p, bool counts);
/// The canonical correction expressed in Tedaldi's frame O (A_a upper-triangular there, G kept).
CanonicalImuModel canonical_in_tedaldi_frame(const ImuModelParams& p, bool counts);

struct TrajectorySummary {
  std::string script;  // "static", "gsens", "still", "checkerboard"
  double duration_s = 0.0;
  int poses = 0;
  std::vector<Segment> segments;
  double mean_accel_mps2 = 0.0;  // mean |a_world| (kinematic, no gravity) over the samples
  double mean_rate_radps = 0.0;  // mean |w_body| over the samples
  double max_accel_mps2 = 0.0;
  double max_rate_radps = 0.0;
};

/// What the recording realised (biases wander; samples may be dropped or saturate).
struct RecordingSummary {
  double imu_rate_hz = 0.0;
  std::int64_t samples = 0;
  std::int64_t dropped_samples = 0;
  std::int64_t accel_saturated = 0;
  std::int64_t gyro_saturated = 0;
  Eigen::Vector3d accel_bias_mean = Eigen::Vector3d::Zero();  // mean b_a(t) over the samples
  Eigen::Vector3d gyro_bias_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias_end = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias_end = Eigen::Vector3d::Zero();
  double temperature_start_c = 0.0;
  double temperature_end_c = 0.0;
};

struct SimTruth {
  std::string kind;  // the `imucal sim` variant
  std::uint64_t seed = 0;
  bool params_from_file = false;  // --truth was given
  ImuModelParams imu;
  TrajectorySummary trajectory;
  RecordingSummary recording;
};

/// The truth as a YAML document (software version included). Callers may add keys (e.g. the
/// camera) before writing it with write_truth_yaml().
YAML::Node truth_to_yaml(const SimTruth& truth);
[[nodiscard]] Status write_truth_yaml(const std::string& path, const YAML::Node& doc, bool overwrite);

/// The `imu:` section of a truth document <-> parameters.
YAML::Node imu_params_to_yaml(const ImuModelParams& p);
[[nodiscard]] Result<ImuModelParams> imu_params_from_yaml(const YAML::Node& node, const std::string& source);
/// Reads the IMU parameters of a truth file (the `imu:` section, or the whole document when it
/// has no such key). Validates them; errors say which key is wrong.
[[nodiscard]] Result<ImuModelParams> load_imu_params(const std::string& path);

/// LOG.imulog -> LOG.truth.yaml (other names get ".truth.yaml" appended).
std::string truth_path_for(const std::string& log_path);

}  // namespace imucal::sim
