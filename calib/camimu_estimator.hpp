// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The camera-IMU estimator (calib/camimu_calibration.hpp runs it): its state, the solver's
// callbacks and the Estimator class. Internal to calib: camimu_calibration.cpp holds the
// initialisation and the solve, camimu_result.cpp what is reported from a solution (covariance,
// undetermined directions, the result, the checks against the prior, the signal fit, excitation).

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "calib/camimu_calibration.hpp"
#include "calib/camimu_init.hpp"
#include "calib/camimu_residuals.hpp"
#include "calib/marginal_covariance.hpp"

namespace imucal::calib::camimu {

using Arr3 = std::array<double, 3>;
/// Below this the corner noise is not believed (quantisation of the stored corners, model error).
inline constexpr double kMinCornerSigmaPx = 0.005;
// Frames whose pose is checked against the gyro are compared with the others this close (s).
inline constexpr double kPoseCheckWindowS = 0.5;
inline constexpr int kPreliminaryIterations = 12;
// How far each stage is converged (docs/camimu-calibration.md, "Speed"): relative decrease of the
// cost in an iteration below which it stops. The first stage only brings the trajectory near (1 %);
// a stage whose weights are re-estimated afterwards stops at 1e-4; the stage whose result is
// reported at 1e-7 (about 0.01 of a cost near 1e5, a change of the parameters far below their
// sigmas).
inline constexpr double kPreliminaryTolerance = 1e-2;
inline constexpr double kIntermediateTolerance = 1e-4;
inline constexpr double kFinalTolerance = 1e-7;
// The shutter test (choose_shutter) frees the line delay on the frames that hold this share of its
// information at the global solution, at least this many (docs/camimu-calibration.md, "Rolling
// shutter"); a rolling verdict then solves every frame rolling.
inline constexpr double kShutterTestShare = 0.75;
inline constexpr int kShutterTestMinFrames = 200;
// The first stage takes IMU samples at this rate at most (every k-th sample): it only brings the
// trajectory near, and the IMU residuals set its cost. It keeps at least
// kPreliminaryImuPerKnot samples in each knot interval: with two (100 Hz against knots 20 ms
// apart) a wiggle of the spline between them is seen by no residual, grows in the first stage's
// steps, and the next stage starts from a cost 1e8 times the first stage's end and needs 30
// iterations to undo it (docs/camimu-calibration.md, "Speed").
inline constexpr double kPreliminaryImuRateHz = 100.0;
inline constexpr double kPreliminaryImuPerKnot = 4.0;
using Arr4 = std::array<double, 4>;

inline Arr4 to_quat(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  return {q.x(), q.y(), q.z(), q.w()};
}
inline Arr3 to_arr(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
/// A 3x3 matrix's entries row by row (the layout of the B_g block).
inline Eigen::Matrix<double, 9, 1> row_major(const Eigen::Matrix3d& M) {
  return Eigen::Map<const Eigen::Matrix<double, 9, 1>>(Eigen::Matrix3d(M.transpose()).data());
}
inline Eigen::Map<Eigen::Vector3d> vec(Arr3& a) { return Eigen::Map<Eigen::Vector3d>(a.data()); }
inline Eigen::Map<const Eigen::Vector3d> vec(const Arr3& a) {
  return Eigen::Map<const Eigen::Vector3d>(a.data());
}

struct CameraState {
  Arr4 q_ci{0, 0, 0, 1};
  Arr3 t_ci{0, 0, 0};
  double shift = 0.0;
  std::vector<FramePose> poses;
  std::vector<TimeNs> rejected;  // frames whose pose contradicts the gyro, ascending
  TimeshiftEstimate xcorr;
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  // of the rotation alignment
  double sigma_px = 0.3;                                // corner noise, per coordinate
  // The shutter: rolling frames have a line delay block (held when line_delay_fixed); `plan`
  // says what run() does with it (CamImuShutterOptions).
  enum class ShutterPlan { kGlobal, kHeld, kEstimate, kChoose };
  ShutterPlan shutter_plan = ShutterPlan::kGlobal;
  bool rolling = false;
  /// The shutter test's frames read out row by row (ascending stamps; empty: every frame when
  /// rolling): choose_shutter tests on the frames that carry most of the line delay's information.
  std::vector<TimeNs> rolling_frames;
  bool line_delay_fixed = true;
  double line_delay = 0.0;  // s per row
  std::string shutter_choice;
};

/// Everything the solver moves, at stable addresses.
template <int N>
struct State {
  SplineTiming<N> pose, bias;
  std::vector<Arr4> q;
  std::vector<Arr3> p, ba, bg;
  Arr3 g{0, 0, -9.80665};
  Arr3 Sa{1, 1, 1}, Ma{0, 0, 0}, Sg{1, 1, 1}, Mg{0, 0, 0};
  Arr4 C{0, 0, 0, 1};
  std::array<double, 9> B{};
  std::vector<CameraState> cams;
};

class ProgressCallback final : public ceres::IterationCallback {
 public:
  ProgressCallback(const CamImuProgressFn& fn, std::string stage) : fn_(fn), stage_(std::move(stage)) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (fn_) fn_({stage_, s.iteration, s.cost, s.gradient_max_norm});
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const CamImuProgressFn& fn_;
  std::string stage_;
};

/// Ends a solve (successfully) as soon as `stop()` holds for the current iterate.
class StopWhen final : public ceres::IterationCallback {
 public:
  explicit StopWhen(std::function<bool()> stop) : stop_(std::move(stop)) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    return s.step_is_successful && stop_() ? ceres::SOLVER_TERMINATE_SUCCESSFULLY : ceres::SOLVER_CONTINUE;
  }

 private:
  std::function<bool()> stop_;
};

/// The residuals of a built problem, kept for what is computed from it afterwards: the robust
/// covariance's clusters, the reported residuals and signals, the prior's cost.
template <int N>
struct BuiltProblem {
  std::vector<const FrameResidual<N>*> frames;
  std::vector<std::size_t> frame_camera;
  std::vector<TimeNs> frame_t_ns;  // each frame's stamp
  std::vector<std::vector<double*>> frame_blocks;
  std::vector<const ImuResidual<N>*> imu_residuals;
  std::vector<std::vector<double*>> imu_blocks;
  std::vector<std::size_t> imu_index;  // imu_ sample of each IMU residual
  /// Every frame and IMU residual with its time (s), for the robust covariance's clusters.
  std::vector<std::pair<ceres::ResidualBlockId, double>> timed_residuals;
  struct Prior {
    const ceres::CostFunction* cost;
    double* block;
  };
  std::vector<Prior> priors;
};

template <int N>
class Estimator {
 public:
  Estimator(const std::vector<CamImuSample>& imu, const std::vector<CamImuCameraInput>& cameras,
            const TargetDescription& target, const CamImuOptions& options, const CamImuProgressFn& progress)
      : imu_(imu), cameras_(cameras), points_(target.points()), opt_(options), progress_(progress) {}

  Result<CamImuCalibrationResult> run();

 private:
  Status initialise();
  Status initialise_camera(std::size_t c, const GyroLookup& gyro);
  /// A warning per camera naming the frames left out for contradicting the gyro.
  void warn_rejected_frames();
  void initialise_spline(std::size_t ref);
  /// The problem at the current values; every `imu_stride`-th IMU sample (the first stage
  /// takes fewer). Returns its residuals.
  BuiltProblem<N> build(ceres::Problem* problem, bool extended, int imu_stride = 1);
  /// One stage to the relative cost tolerance `tolerance` (kPreliminaryTolerance, ...).
  Status solve(bool extended, const std::string& stage, ceres::Solver::Summary* summary,
               double tolerance = kFinalTolerance);
  /// The marginal covariance of the calibration's blocks at the current solution, computed once
  /// per solution (the Wald statistic and the reported sigmas share it); nullptr when the problem
  /// cannot be evaluated there.
  const MarginalCovariance* solution_covariance();
  /// The problem built again at the current values, without solving (after a state is restored).
  void rebuild(bool extended, int imu_stride = 1);
  /// The stages after the first (and the model choice): weighted anew by the noise the residuals
  /// show until the weights hold, the last to kFinalTolerance.
  Status reweighted_stages(bool automatic, ceres::Solver::Summary* summary);
  bool frames_in_window() const;
  /// Each camera's shutter plan from the options and its camera file (initialise()).
  void plan_shutters();
  /// After the global solution: the line delay of the cameras that estimate or choose it freed
  /// and solved; rolling kept where asked for or where the evidence shows it (BIC), else the
  /// global solution restored. Leaves the chosen model solved and the reasons in shutter_choice.
  Status choose_shutter(bool extended, ceres::Solver::Summary* summary);
  /// The frames the shutter test reads out row by row, per tested camera (CameraState::
  /// rolling_frames): by the line delay's information at the global solution, the fewest that
  /// hold kShutterTestShare of it (at least kShutterTestMinFrames). A sentence for the verdict,
  /// empty when every frame is tested.
  std::string pick_shutter_test_frames(const std::vector<std::size_t>& tested);
  /// Basic or extended by the evidence (kAuto): the drop of the data cost that freeing the
  /// intrinsics buys against the parameters it costs (BIC). Leaves the chosen model solved.
  Status choose_model(ceres::Solver::Summary* summary);
  /// The IMU's per-sample sigmas from the residuals when they disagree with the given figures
  /// by more than a factor two (else the given ones); true when a sigma moved by more than 10 %.
  bool reestimate_imu_noise();
  /// The prior's standard deviation of every intrinsic (CamImuIntrinsicsPrior about prior0_),
  /// whether the block is free or not.
  KrebsImuSigma prior_sigmas() const;
  /// The prior terms of the free intrinsic blocks (extended model, prior enabled), added to
  /// `priors`.
  void add_priors(ceres::Problem* problem, std::vector<typename BuiltProblem<N>::Prior>* priors);
  /// The cost of the prior terms of problem_ (0 without).
  double prior_cost() const;
  /// The Wald statistic of the free intrinsics against their start with the data's information
  /// alone (see choose_model); NaN when the covariance leaves a direction undetermined. `*k`
  /// receives their count.
  double wald_statistic(int* k);
  /// Warnings for intrinsics far from their prior or outside physical bounds, and the names of
  /// those the prior mostly set.
  void check_against_prior(CamImuCalibrationResult* out);
  /// The name of one tangent coordinate of an estimated block, for undetermined directions.
  std::string coordinate_name(const double* block, int index) const;
  std::string describe(const MarginalCovariance::Direction& dir) const;
  /// The corner noise of each camera from the current residuals (1.4826 x median |component|);
  /// true when it moved by more than 10 % for any camera.
  bool reestimate_corner_sigma();
  void covariance(CamImuCalibrationResult* out);
  /// The scores (J^T dr) of every camera's held intrinsics moved along the columns of a square
  /// root of their covariance (CamImuCameraInput::intrinsics_covariance), for
  /// MarginalCovariance's held inputs; empty when no camera has one or opt_.propagate_intrinsics
  /// is off.
  std::vector<MarginalCovariance::HeldScore> held_intrinsics() const;
  void fill_result(CamImuCalibrationResult* out);
  /// Measured and predicted IMU signals of the problem as it stands.
  ImuSignalFit signal_fit(const std::string& model) const;
  double t_s(TimeNs t) const { return static_cast<double>(t - t0_ns_) * 1e-9; }

  const std::vector<CamImuSample>& imu_;
  const std::vector<CamImuCameraInput>& cameras_;
  std::vector<Eigen::Vector3d> points_;
  CamImuOptions opt_;
  const CamImuProgressFn& progress_;
  TimeNs t0_ns_ = 0;
  State<N> st_;
  BuiltProblem<N> built_;                               // the residuals of problem_
  KrebsImuModel prior0_;                                // the prior's centre (the starting model)
  CamImuModelKind model_ = CamImuModelKind::kExtended;  // the model solved (kAuto resolved)
  std::string model_choice_;
  CamImuQuality quality_;
  std::vector<std::string> warnings_;
  std::unique_ptr<ceres::Problem> problem_;
  std::unique_ptr<MarginalCovariance> covariance_;  // of the current solution; reset by a solve
  bool covariance_failed_ = false;
  double covariance_compute_s_ = 0.0;  // wall time of the last computation of covariance_
};

/// Columns l_j with sum_j l_j l_j^T = the 10 x 10 covariance of a camera's [fu fv pu pv,
/// projection (2), distortion (4)] (its eigenvectors times the square roots of the positive
/// eigenvalues); coordinates whose
/// variance is NaN (not determined by the camera's solve) are left out. Empty for an empty or
/// malformed matrix.
std::vector<Eigen::VectorXd> intrinsics_directions(const Eigen::MatrixXd& covariance);

/// Excitation per body axis and the observability warnings it implies.
void excitation(const std::vector<CamImuSample>& imu, const Eigen::Vector3d& b_g, CamImuQuality* q,
                std::vector<std::string>* warnings);

}  // namespace imucal::calib::camimu
