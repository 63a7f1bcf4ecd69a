// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The inputs of the camera-IMU calibration that need no solver, so the program can read and check
// them before it loads the camera module: the cameras of a camchain YAML and the log streams
// they belong to, the IMU noise of a Kalibr imu.yaml, a prior IMU calibration (imucal's static
// result) and a g-sensitivity as the Krebs model's initial and fixed values, the names of the
// blocks to fix. Formats and conversions: docs/camimu-calibration.md, "Inputs".

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "app/calibration_check.hpp"
#include "calib/camera_intrinsics.hpp"
#include "calib/camimu_calibration.hpp"
#include "core/camera_model.hpp"
#include "core/frame.hpp"
#include "core/imu.hpp"
#include "core/imu_model.hpp"
#include "core/result.hpp"

namespace imucal::app {

/// One camera of a camchain YAML (`cam0:` ... `camN:` as `imucal calibrate camera` or Kalibr
/// write them).
struct CamchainCamera {
  std::string name;    // the key in the file: cam0, cam1, ...
  std::string source;  // the file
  CameraModel camera;
  std::string camera_stream;  // `imucal: camera_stream:` (written by imucal calibrate camera)
  std::string rostopic;       // Kalibr's topic, e.g. /cam0/image_raw
  /// Kalibr's cam_overlaps: the cameras it shares views with, numbered as the cameras of all
  /// files together (cam0, cam1, ... in the order given); empty when the file has none.
  std::optional<std::vector<int>> cam_overlaps;
  /// Kalibr's T_cn_cnm1 (camN >= 1 of a chain) and, from imucal's chain, its 6 x 6 covariance
  /// (`imucal: T_cn_cnm1_covariance:`, rotation about camN's axes then translation).
  std::optional<Eigen::Isometry3d> T_cn_cnm1;
  std::optional<Eigen::Matrix<double, 6, 6>> T_cn_cnm1_covariance;
  /// The intrinsics' covariance in the solves' 10 x 10 layout [fu fv pu pv, projection (2),
  /// distortion (4)] (the file's `imucal: intrinsics_covariance:` is in Kalibr's order of the
  /// model's parameters, NaN where it says null) and what it came from; empty when
  /// the file has none (a Kalibr camchain; sigmas alone are not used, the source then says why).
  Eigen::MatrixXd intrinsics_covariance;
  std::string intrinsics_covariance_source;
  /// The file (or --stamp-row) names the row the frames' stamps refer to (`stamp_row`); else it
  /// is taken from the log's camera stream (stamp_row_from_stream).
  bool stamp_row_given = false;
  /// Set by read_camchain_files: the camera before it in the list is the one before it in the
  /// same file, so T_cn_cnm1 relates the two.
  bool follows_in_file = false;
};

/// What the log's camera stream says its stamps refer to (CameraStreamInfo::timestamp_source,
/// core/camera_model.hpp stamp_row_of_timestamp_source), set into *shutter unless `given` (the
/// camera file or --stamp-row named the row): then a warning when the two differ. `who` names
/// the camera in the texts. Returns {note, warning}, either empty when there is nothing to say.
std::pair<std::string, std::string> stamp_row_from_stream(const CameraStreamInfo& stream, bool given,
                                                          const std::string& who, Shutter* shutter);

/// A camera solved in this process (a session's camera step): its intrinsics' covariance as
/// read_camchain reads it from the file that step writes (none when it was not determined).
void set_intrinsics_covariance(const calib::CameraIntrinsicsResult& solved, CamchainCamera* camera);

/// The cameras of a camchain YAML in the order cam0, cam1, ... Errors: kNotFound (unreadable
/// file), kCorrupt (not YAML, no cam0, a malformed camera).
[[nodiscard]] Result<std::vector<CamchainCamera>> read_camchain(const std::string& path);

/// The cameras of several camchain YAMLs, renamed cam0, cam1, ... in order, each with its file
/// and key as its source. kInvalidArgument (with the remedy "camera") when none is given.
[[nodiscard]] Result<std::vector<CamchainCamera>> read_camchain_files(const std::vector<std::string>& paths);

/// The log's camera stream of each camchain camera: the one named by its `camera_stream`, else by
/// its rostopic (/NAME/image_raw, /NAME/image or NAME), else, with one camera in the file and one
/// stream in the log, that stream. Two cameras on one stream are refused. kNotFound names the
/// streams the log holds.
[[nodiscard]] Result<std::vector<int>> match_camera_streams(const std::vector<CamchainCamera>& cameras,
                                                            const std::map<int, CameraStreamInfo>& streams);

/// The four noise figures of a Kalibr imu.yaml (flat, as Kalibr reads it and `imucal allan`
/// writes it, or under `imu0:` as kalibr_calibrate_imu_camera and `calibrate camimu` write it).
/// Errors: kNotFound, kCorrupt (a figure missing, not a positive number).
[[nodiscard]] Result<calib::CamImuNoise> read_kalibr_imu_noise(const std::string& path);

/// What else a Kalibr imu.yaml says, where it says it: the IMU's topic and its rate, which the
/// camera-IMU result's imu.yaml gives back as they were given.
struct KalibrImuTopic {
  std::string rostopic;      // empty: not given
  double update_rate = 0.0;  // Hz; 0: not given
};
/// kCorrupt when `rostopic` is not text or `update_rate` not a positive number.
[[nodiscard]] Result<KalibrImuTopic> read_kalibr_imu_topic(const std::string& path);

/// The ROS topic of a log's stream: the bag topic it was imported from (device "rosbag:TOPIC"),
/// else the one Kalibr's tools give it (/NAME/image_raw for a camera, /NAME for an IMU).
std::string camera_rostopic(const CameraStreamInfo& stream);
std::string imu_rostopic(const ImuStreamInfo& stream);

/// The IMU stream imported from the ROS bag topic `topic` (its device "rosbag:TOPIC"), or the
/// stream named as the topic (`/imu0` and `imu0` name imu0); empty when none is.
std::string imu_stream_of_topic(const std::map<int, ImuStreamInfo>& streams, const std::string& topic);

/// A canonical model for the stream's input values re-expressed for its nominal SI values
/// (si = scale .* (raw - offset), ImuStreamInfo::accel/gyro): A' = A diag(scale)^-1,
/// b' = scale .* (b - offset), G unchanged. The identity for an SI stream.
CanonicalImuModel canonical_on_nominal_si(const CanonicalImuModel& model, const ImuStreamInfo& info);
/// The inverse: a model on nominal SI values for the stream's input values.
CanonicalImuModel canonical_on_input_units(const CanonicalImuModel& model_si, const ImuStreamInfo& info);

/// The Krebs g-sensitivity B_g (raw rad/s per m/s^2 of the acceleration in the gyro frame) that
/// gives the canonical g-sensitivity `G_body` (rad/s per m/s^2, in the Krebs body frame) with
/// the model's S_g, M_g and C_bg: from w_raw = S_g M_g C_bg^T w + B_g C_bg^T a + b_g,
/// G = A_g B_g C_bg^T with A_g = C_bg (S_g M_g)^-1, so B_g = S_g M_g C_bg^T G C_bg.
Eigen::Matrix3d krebs_gsens_from_canonical(const Eigen::Matrix3d& G_body, const KrebsImuModel& model);

/// A g-sensitivity read with `--gsens FILE` (app::read_gsens_matrix) and, when the file is a
/// full static result, its model: its frame is the one G is expressed in.
struct GsensInput {
  std::string path;
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  std::optional<NamedCalibration> frame;
};
[[nodiscard]] Result<GsensInput> read_gsens_input(const std::string& path);

/// What prior calibrations make of the IMU model: the initial Krebs model and the blocks they fix.
struct ImuPrior {
  std::optional<KrebsImuModel> init;
  calib::CamImuFixed fixed;  // S_a, M_a, S_g, M_g, C_bg from the intrinsics; B_g from a G
  std::vector<std::string> notes;
};

/// The Krebs model of a static result (`--imu-intrinsics`, converted to the stream's nominal SI)
/// and of a g-sensitivity (`--gsens`), on the stream `info`. The intrinsics fix S_a, M_a, S_g,
/// M_g, C_bg and, when they hold a g-sensitivity (G not zero), B_g; a --gsens G replaces theirs,
/// rotated from its file's frame into the Krebs body frame, and fixes B_g. Errors:
/// kInvalidArgument (units of the file not those of the stream, a singular model).
[[nodiscard]] Result<ImuPrior> imu_prior(const std::optional<NamedCalibration>& intrinsics,
                                         const std::optional<GsensInput>& gsens, const ImuStreamInfo& info);

/// The covariance (rad^2, about the Krebs body axes) of the body frame a held static calibration
/// defines, from its factors' standard deviations: the gyro's map into the body frame
/// (R_canonical_body^T A_g, the body frame set by the accelerometer's axes) is recomputed with
/// each scale and misalignment moved by its sigma, and the rotation it turns by is summed in
/// squares (the factors taken as independent). A camera's rotation against the IMU, solved with
/// that calibration held, is off by the same rotation. NaN when a moved factor's sigma is not
/// determined.
Eigen::Matrix3d held_axes_covariance(const NamedCalibration::Spread& spread);

/// The IMU samples on the stream's nominal SI (ImuStreamInfo::accel/gyro to_si), as the
/// estimator takes them; samples flagged saturated are left out and counted in `*saturated`.
std::vector<calib::CamImuSample> camimu_samples(const std::vector<ImuSample>& samples,
                                                const ImuStreamInfo& info, std::size_t* saturated);

/// The block names of --fix: S_a, M_a, S_g, M_g, C_bg, B_g, T_cam_imu, timeshift.
[[nodiscard]] Status set_fixed_block(const std::string& name, calib::CamImuFixed* fixed);
/// The names of the fixed blocks, in the order above.
std::vector<std::string> fixed_block_names(const calib::CamImuFixed& fixed);
/// Both sets of fixed blocks.
calib::CamImuFixed merge_fixed(const calib::CamImuFixed& a, const calib::CamImuFixed& b);

}  // namespace imucal::app
