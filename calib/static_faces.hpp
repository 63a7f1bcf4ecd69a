// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The six faces of a rig held still with one axis up, as the static calibration sees them: which
// face each static pose lies on, which faces a recording lacks (in the operator's words), and the
// known-orientation accelerometer fit that PX4 and ArduPilot use for a six-face recording (each
// pose taken as lying exactly on its face, gravity along that face's axis; a full 3x3 matrix and
// offset by linear least squares). No solver library.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/imu_model.hpp"

namespace imucal::calib {

/// Faces in the order +x, -x, +y, -y, +z, -z: face f is "up" when the accelerometer reads +g
/// along (-1)^f times axis f / 2 (the rig then rests on the opposite face).
inline constexpr int kFaceCount = 6;

/// "+x up" ... "-z up".
std::string face_name(int face);
/// How an operator puts the rig that way: "+X up (resting on its -X face)".
std::string face_in_words(int face);

/// The face each direction (a unit vector of the specific force in the sensor's axes) lies on, or
/// -1 when it is tilted from every face by more than max_angle_rad.
std::vector<int> assign_faces(const std::vector<Eigen::Vector3d>& directions, double max_angle_rad);

/// How many of the directions lie on each face.
std::array<int, kFaceCount> face_counts(const std::vector<int>& faces);

/// The faces without a pose, in the operator's words, joined by commas; empty when all six have one.
std::string missing_faces_in_words(const std::array<int, kFaceCount>& counts);

/// Known-orientation fit of the accelerometer: for every pose k on face f_k, g e_{f_k} =
/// A (m_k - b) + noise, A a full 3x3 matrix. A = Q T K (Q a rotation between the faces and the
/// accelerometer's frame, T K upper triangular as in Tedaldi's eq. 2.2), so the result is the
/// Tedaldi triad (T, K, b with Tedaldi's sign) in the frame O of the magnitude form, and Q.
struct KnownOrientationFit {
  bool ok = false;
  std::string error;  // why not, when !ok
  TedaldiTriad triad;
  /// Covariance of [alpha_yz, alpha_zy, alpha_zx, s_x, s_y, s_z, b_x, b_y, b_z] (eq. 3.2's order,
  /// the bias in Tedaldi's sign), from the residual variance of each output axis.
  Eigen::Matrix<double, 9, 9> covariance = Eigen::Matrix<double, 9, 9>::Zero();
  /// Rotation from the accelerometer's frame O to the faces' frame, and its angle, rad.
  Eigen::Matrix3d Q = Eigen::Matrix3d::Identity();
  double q_angle_rad = 0.0;
  /// Angle between each pose's calibrated specific force and its face's axis, rad: how flat the
  /// poses lay on their faces.
  std::vector<double> direction_error_rad;
  double direction_rms_rad = 0.0;
  int residuals = 0;    // 3 per pose
  int parameters = 12;  // A and its offset
};

/// Fits the known-orientation form to the static means (input units) of the poses on `faces`
/// (one per mean, -1 = not on a face: left out). Needs every face at least once.
KnownOrientationFit fit_known_orientation(const std::vector<Eigen::Vector3d>& means,
                                          const std::vector<int>& faces, double gravity_mps2);

}  // namespace imucal::calib
