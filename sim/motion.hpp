// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Motion scripts of the virtual rig (sim::Trajectory implementations), deterministic under a
// seed. All motions are analytic: attitudes follow minimum-jerk (quintic) profiles along
// geodesics or smooth sinusoids through the SO(3) exponential, so body rates and accelerations
// are exact (see docs/simulator.md for the formulas).
//
//   make_static_protocol  initial still period, then N attitudes reached by hand-like rotations
//                         and held 1-4 s (Tedaldi et al. 2013, fig. 1.1 and section 3.5)
//   make_six_face         each face up in turn, held for the g-sensitivity experiment
//                         (Krebs 2012, section 5.2.3)
//   CheckerboardMotion    smooth 6-DoF motion in front of a vertical board (Krebs 5.1.1)
//   make_still            a long still recording (Allan variance)
//
// World W: z up, gravity (0, 0, -g). Body B: the IMU's accelerometer orthogonal frame.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/target.hpp"
#include "sim/trajectory.hpp"

namespace imucal::sim {

/// Small hand tremor: sinusoidal rotation and translation per axis at 6-11 Hz, applied over the
/// whole script when enabled (the rig is held by hand throughout).
struct TremorOptions {
  bool enabled = false;
  double rotation_amplitude_rad = 2e-4;   // per axis (rate amplitude ~0.01 rad/s)
  double translation_amplitude_m = 2e-5;  // per axis (acceleration amplitude ~0.05 m/s^2)
};

struct StaticProtocolOptions {
  double initial_still_s = 50.0;  // T_init
  int poses = 40;                 // N attitudes, 9..100
  double hold_min_s = 1.0;        // t_wait drawn uniformly in [hold_min_s, hold_max_s]
  double hold_max_s = 4.0;
  /// Speed of the moves between attitudes: 1 is a calm hand (peak rates ~1-2 rad/s); larger
  /// values make shorter, faster moves and higher lifts (3 exceeds +-250 deg/s and +-2 g).
  double excitation = 1.0;
  TremorOptions tremor;

  [[nodiscard]] Status validate() const;
};

struct SixFaceOptions {
  double hold_s = 30.0;  // per face
  double move_s = 3.0;   // per reorientation
  /// The faces held, as indices into six_face_names(), in that order (empty: all six in turn).
  std::vector<int> faces;
  /// Holds after those, each on a face other than the last one and turned about the vertical by
  /// 20-60 deg as well (as a hand puts a box down again), of revisit_hold_s each.
  int revisits = 0;
  double revisit_hold_s = 3.0;
  TremorOptions tremor;

  [[nodiscard]] Status validate() const;
};

struct StillOptions {
  double duration_s = 600.0;
  TremorOptions tremor;  // off: the rig rests on a table

  [[nodiscard]] Status validate() const;
};

/// Board placement and excitation of the checkerboard motion. The board stands vertically: its
/// centre at `board_centre_world`, its x axis along world +x, its y axis pointing down (world
/// -z), its z axis (x cross y) along world +y, away from the rig. The rig's nominal pose is
/// `standoff_m` in front of the board (world -y side) with the body z axis pointing at the board
/// centre, body x along the board's x and body y down: a camera mounted with its optical axis
/// near body z sees the board throughout.
struct CheckerboardMotionOptions {
  double duration_s = 90.0;
  double still_s = 2.0;  // at rest before and after the motion (for bias initialisation)
  double ramp_s = 2.0;   // smooth fade in/out of the motion
  /// Targets of the motion over the whole script (Krebs 5.1.1: 3.12 m/s^2 and 0.366 rad/s);
  /// `excitation` multiplies both.
  double mean_accel_mps2 = 3.12;
  double mean_rate_radps = 0.366;
  double excitation = 1.0;
  double standoff_m = 0.8;
  Eigen::Vector3d board_centre_world{0.0, 0.0, 1.2};
  TremorOptions tremor;

  [[nodiscard]] Status validate() const;
};

/// A script made of poses joined by minimum-jerk moves (static, six-face and still scripts).
class PoseScript : public Trajectory {
 public:
  struct Piece {
    TimeNs t0_ns = 0;
    TimeNs t1_ns = 0;
    Eigen::Quaterniond q0 = Eigen::Quaterniond::Identity();  // q_world_body at t0
    Eigen::Vector3d rotvec_body = Eigen::Vector3d::Zero();   // rotation over the piece, body frame
    Eigen::Vector3d p0 = Eigen::Vector3d::Zero();
    Eigen::Vector3d dp = Eigen::Vector3d::Zero();  // translation over the piece, world frame
    double lift_m = 0.0;                           // vertical bump in the middle of a move
  };

  PoseScript(std::vector<Piece> pieces, std::vector<Segment> segments, const TremorOptions& tremor,
             std::uint64_t seed, int poses);

  RigState at(TimeNs t_ns) const override;
  TimeNs start_ns() const override { return pieces_.front().t0_ns; }
  TimeNs end_ns() const override { return pieces_.back().t1_ns; }
  const std::vector<Segment>& segments() const override { return segments_; }
  /// Number of distinct held attitudes (poses or faces; 1 for a still script).
  int poses() const { return poses_; }

 private:
  std::vector<Piece> pieces_;
  std::vector<Segment> segments_;
  TremorOptions tremor_;
  Eigen::Vector3d tremor_freq_rot_hz_, tremor_phase_rot_, tremor_freq_pos_hz_, tremor_phase_pos_;
  int poses_;
};

[[nodiscard]] Result<std::unique_ptr<PoseScript>> make_static_protocol(const StaticProtocolOptions& options,
                                                                       std::uint64_t seed);
[[nodiscard]] Result<std::unique_ptr<PoseScript>> make_six_face(const SixFaceOptions& options,
                                                                std::uint64_t seed);
[[nodiscard]] Result<std::unique_ptr<PoseScript>> make_still(const StillOptions& options, std::uint64_t seed);

/// Names of the six faces in the order of make_six_face, e.g. "+z up".
const std::vector<std::string>& six_face_names();

class CheckerboardMotion : public Trajectory {
 public:
  /// Validates the options and builds the motion; amplitudes are scaled so that the mean
  /// |a_world| and mean |w_body| over the script match the targets.
  [[nodiscard]] static Result<std::unique_ptr<CheckerboardMotion>> create(
      const CheckerboardMotionOptions& options, std::uint64_t seed);

  RigState at(TimeNs t_ns) const override;
  TimeNs start_ns() const override { return 0; }
  TimeNs end_ns() const override { return end_ns_; }
  const std::vector<Segment>& segments() const override { return segments_; }

  const CheckerboardMotionOptions& options() const { return options_; }
  /// Board frame -> world for a target whose points are centred on the board centre, printed
  /// side towards the rig: a checkerboard (printed on its z < 0 side) with corner 0 at the top
  /// left seen from the rig, an AprilGrid (printed on z > 0, Kalibr's frame) with tag 0 at the
  /// bottom left.
  Eigen::Isometry3d T_world_board(const TargetDescription& target) const;
  /// Nominal (rest) pose of the body, q_world_body and p_world_body.
  Eigen::Quaterniond q_world_body_nominal() const;
  Eigen::Vector3d p_world_body_nominal() const;

 private:
  CheckerboardMotion() = default;
  struct Harmonic {
    Eigen::Vector3d amplitude = Eigen::Vector3d::Zero();
    Eigen::Vector3d freq_hz = Eigen::Vector3d::Zero();
    Eigen::Vector3d phase = Eigen::Vector3d::Zero();
  };
  /// Envelope-weighted sum of harmonics and its first two time derivatives.
  void evaluate(const std::vector<Harmonic>& hs, double scale, double t_s, Eigen::Vector3d* x,
                Eigen::Vector3d* xd, Eigen::Vector3d* xdd) const;
  RigState state_at(double t_s) const;

  CheckerboardMotionOptions options_;
  std::vector<Harmonic> translation_;
  std::vector<Harmonic> rotation_;
  double translation_scale_ = 1.0;
  double rotation_scale_ = 1.0;
  TimeNs end_ns_ = 0;
  std::vector<Segment> segments_;
  TremorOptions tremor_;
  Eigen::Vector3d tremor_freq_rot_hz_, tremor_phase_rot_, tremor_freq_pos_hz_, tremor_phase_pos_;
};

/// SO(3) helpers used by the scripts (exposed for tests).
Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi);
/// Right Jacobian J_r(phi): d/dt Exp(phi(t)) = Exp(phi) [J_r(phi) phi_dot]_x.
Eigen::Matrix3d so3_right_jacobian(const Eigen::Vector3d& phi);
/// Minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 and its derivatives, tau in [0,1].
void min_jerk(double tau, double* s, double* ds, double* dds);

}  // namespace imucal::sim
