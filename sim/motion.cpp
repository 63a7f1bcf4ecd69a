// SPDX-License-Identifier: BSD-3-Clause
#include "sim/motion.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "sim/motion_random.hpp"

namespace imucal::sim {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
// Sub-stream salts: the motion of a script never shares random numbers with the IMU model.
constexpr std::uint64_t kSaltMotion = 11;
constexpr std::uint64_t kSaltTremor = 12;

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

/// Smooth bump b(tau) = 64 tau^3 (1 - tau)^3 (peak 1 at tau = 1/2; value, slope and curvature
/// zero at both ends) and its derivatives.
void bump(double tau, double* b, double* db, double* ddb) {
  const double u = 1.0 - tau;
  *b = 64.0 * tau * tau * tau * u * u * u;
  *db = 192.0 * tau * tau * u * u * (1.0 - 2.0 * tau);
  *ddb = 384.0 * tau * u * ((1.0 - 2.0 * tau) * (1.0 - 2.0 * tau) - tau * u);
}

/// Milliseconds-rounded duration in ns, so script times are readable in the truth file.
TimeNs duration_ns(double s) { return s_to_ns(std::round(s * 1000.0) / 1000.0); }

struct Tremor {
  Eigen::Vector3d freq_rot_hz, phase_rot, freq_pos_hz, phase_pos;
};

Tremor draw_tremor(std::uint64_t seed) {
  Rng rng(Rng::substream(seed, kSaltTremor));
  Tremor t;
  for (int i = 0; i < 3; ++i) {
    t.freq_rot_hz[i] = rng.uniform(6.0, 11.0);
    t.phase_rot[i] = rng.uniform(0.0, 2.0 * kPi);
    t.freq_pos_hz[i] = rng.uniform(6.0, 11.0);
    t.phase_pos[i] = rng.uniform(0.0, 2.0 * kPi);
  }
  return t;
}

/// Applies R = R_base Exp(eps(t)), p = p_base + d(t): w = Exp(eps)^T w_base + J_r(eps) eps_dot.
void apply_tremor(const TremorOptions& opt, const Eigen::Vector3d& f_rot, const Eigen::Vector3d& ph_rot,
                  const Eigen::Vector3d& f_pos, const Eigen::Vector3d& ph_pos, double t_s, RigState* s) {
  if (!opt.enabled) return;
  Eigen::Vector3d eps, eps_dot, d, d_dot, d_ddot;
  for (int i = 0; i < 3; ++i) {
    const double wr = 2.0 * kPi * f_rot[i];
    eps[i] = opt.rotation_amplitude_rad * std::sin(wr * t_s + ph_rot[i]);
    eps_dot[i] = opt.rotation_amplitude_rad * wr * std::cos(wr * t_s + ph_rot[i]);
    const double wp = 2.0 * kPi * f_pos[i];
    d[i] = opt.translation_amplitude_m * std::sin(wp * t_s + ph_pos[i]);
    d_dot[i] = opt.translation_amplitude_m * wp * std::cos(wp * t_s + ph_pos[i]);
    d_ddot[i] = -opt.translation_amplitude_m * wp * wp * std::sin(wp * t_s + ph_pos[i]);
  }
  const Eigen::Matrix3d E = so3_exp(eps);
  const Eigen::Matrix3d R = s->q_world_body.toRotationMatrix() * E;
  s->q_world_body = Eigen::Quaterniond(R).normalized();
  s->omega_body = E.transpose() * s->omega_body + so3_right_jacobian(eps) * eps_dot;
  s->p_world_body += d;
  s->v_world += d_dot;
  s->a_world += d_ddot;
}

Status check_tremor(const TremorOptions& t) {
  if (!(t.rotation_amplitude_rad >= 0.0 && t.rotation_amplitude_rad <= 0.01) ||
      !(t.translation_amplitude_m >= 0.0 && t.translation_amplitude_m <= 0.001)) {
    return make_error(Errc::kInvalidArgument,
                      "tremor amplitudes must be within [0, 0.01] rad and [0, 0.001] m (a hand tremor)");
  }
  return {};
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// SO(3) helpers

Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  if (theta < 1e-12) return Eigen::Matrix3d::Identity() + skew(phi);
  return Eigen::AngleAxisd(theta, phi / theta).toRotationMatrix();
}

Eigen::Matrix3d so3_right_jacobian(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d K = skew(phi);
  if (theta < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * K + (1.0 / 6.0) * K * K;
  const double t2 = theta * theta;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(theta)) / t2 * K +
         (theta - std::sin(theta)) / (t2 * theta) * K * K;
}

void min_jerk(double tau, double* s, double* ds, double* dds) {
  tau = std::clamp(tau, 0.0, 1.0);
  const double t2 = tau * tau;
  const double t3 = t2 * tau;
  *s = t3 * (10.0 - 15.0 * tau + 6.0 * t2);
  *ds = 30.0 * t2 * (1.0 - 2.0 * tau + t2);
  *dds = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2);
}

// ---------------------------------------------------------------------------------------------
// Options

Status StaticProtocolOptions::validate() const {
  if (poses < 9 || poses > 100) {
    return make_error(Errc::kInvalidArgument,
                      "the static protocol needs 9..100 poses (Tedaldi et al. need at least 9 "
                      "attitudes; 36-50 is recommended), got " +
                          std::to_string(poses));
  }
  if (!(initial_still_s >= 1.0 && initial_still_s <= 3600.0)) {
    return make_error(Errc::kInvalidArgument, "static protocol: the initial still period must be 1..3600 s");
  }
  if (!(hold_min_s > 0.0 && hold_max_s >= hold_min_s && hold_max_s <= 600.0)) {
    return make_error(Errc::kInvalidArgument,
                      "static protocol: hold times must satisfy 0 < min <= max <= 600 s");
  }
  if (!(excitation > 0.05 && excitation <= 10.0)) {
    return make_error(Errc::kInvalidArgument, "static protocol: excitation must be within (0.05, 10]");
  }
  return check_tremor(tremor);
}

Status SixFaceOptions::validate() const {
  if (!(hold_s >= 1.0 && hold_s <= 3600.0) || !(move_s >= 0.5 && move_s <= 60.0)) {
    return make_error(Errc::kInvalidArgument, "six-face script: hold must be 1..3600 s and moves 0.5..60 s");
  }
  for (int f : faces) {
    if (f < 0 || f > 5)
      return make_error(Errc::kInvalidArgument, "six-face script: a face index is not 0..5");
  }
  if (revisits < 0 || revisits > 1000 || !(revisit_hold_s >= 1.0 && revisit_hold_s <= 3600.0)) {
    return make_error(Errc::kInvalidArgument,
                      "six-face script: revisits must be 0..1000 and their holds 1..3600 s");
  }
  return check_tremor(tremor);
}

Status StillOptions::validate() const {
  if (!(duration_s >= 1.0 && duration_s <= 48.0 * 3600.0)) {
    return make_error(Errc::kInvalidArgument, "still script: duration must be 1 s .. 48 h");
  }
  return check_tremor(tremor);
}

Status CheckerboardMotionOptions::validate() const {
  if (!(still_s >= 0.0 && ramp_s >= 0.1) || !(duration_s >= 2.0 * (still_s + ramp_s) + 1.0) ||
      duration_s > 3600.0) {
    return make_error(
        Errc::kInvalidArgument,
        "checkerboard motion: duration must exceed 2 * (still + ramp) + 1 s and be at most 3600 s");
  }
  if (!(mean_accel_mps2 > 0.0 && mean_rate_radps > 0.0 && excitation > 0.0) ||
      mean_accel_mps2 * excitation > 40.0 || mean_rate_radps * excitation > 5.0) {
    return make_error(Errc::kInvalidArgument,
                      "checkerboard motion: mean acceleration and rate targets (times excitation) must be "
                      "positive and at most 40 m/s^2 and 5 rad/s");
  }
  if (!(standoff_m >= 0.2 && standoff_m <= 10.0)) {
    return make_error(Errc::kInvalidArgument, "checkerboard motion: standoff must be 0.2..10 m");
  }
  return check_tremor(tremor);
}

// ---------------------------------------------------------------------------------------------
// PoseScript

PoseScript::PoseScript(std::vector<Piece> pieces, std::vector<Segment> segments, const TremorOptions& tremor,
                       std::uint64_t seed, int poses)
    : pieces_(std::move(pieces)), segments_(std::move(segments)), tremor_(tremor), poses_(poses) {
  const Tremor t = draw_tremor(seed);
  tremor_freq_rot_hz_ = t.freq_rot_hz;
  tremor_phase_rot_ = t.phase_rot;
  tremor_freq_pos_hz_ = t.freq_pos_hz;
  tremor_phase_pos_ = t.phase_pos;
}

RigState PoseScript::at(TimeNs t_ns) const {
  t_ns = std::clamp(t_ns, start_ns(), end_ns());
  auto it = std::upper_bound(pieces_.begin(), pieces_.end(), t_ns,
                             [](TimeNs t, const Piece& p) { return t < p.t0_ns; });
  const Piece& pc = it == pieces_.begin() ? pieces_.front() : *(it - 1);
  const double T = ns_to_s(pc.t1_ns - pc.t0_ns);
  const double tau = T > 0.0 ? ns_to_s(t_ns - pc.t0_ns) / T : 0.0;
  double s = 0, ds = 0, dds = 0, b = 0, db = 0, ddb = 0;
  min_jerk(tau, &s, &ds, &dds);
  bump(std::clamp(tau, 0.0, 1.0), &b, &db, &ddb);
  const double sd = T > 0.0 ? ds / T : 0.0;
  const double sdd = T > 0.0 ? dds / (T * T) : 0.0;

  RigState st;
  // R = R0 Exp(s(tau) theta): a rotation about a body-fixed axis, so w_body = s_dot theta.
  st.q_world_body = Eigen::Quaterniond(pc.q0.toRotationMatrix() * so3_exp(s * pc.rotvec_body)).normalized();
  st.omega_body = sd * pc.rotvec_body;
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  st.p_world_body = pc.p0 + s * pc.dp + pc.lift_m * b * up;
  st.v_world = sd * pc.dp + (T > 0.0 ? pc.lift_m * db / T : 0.0) * up;
  st.a_world = sdd * pc.dp + (T > 0.0 ? pc.lift_m * ddb / (T * T) : 0.0) * up;
  apply_tremor(tremor_, tremor_freq_rot_hz_, tremor_phase_rot_, tremor_freq_pos_hz_, tremor_phase_pos_,
               ns_to_s(t_ns - start_ns()), &st);
  return st;
}

namespace {

/// Appends a hold at (q, p) and a segment of `kind`.
void add_hold(std::vector<PoseScript::Piece>* pieces, std::vector<Segment>* segments, TimeNs* t,
              const Eigen::Quaterniond& q, const Eigen::Vector3d& p, double hold_s, const std::string& kind,
              const std::string& label = {}) {
  PoseScript::Piece pc;
  pc.t0_ns = *t;
  pc.t1_ns = *t + duration_ns(hold_s);
  pc.q0 = q;
  pc.p0 = p;
  pieces->push_back(pc);
  segments->push_back({pc.t0_ns, pc.t1_ns, kind, label});
  *t = pc.t1_ns;
}

/// Appends a minimum-jerk move from (q0, p0) to (q1, p1) along the geodesic.
void add_move(std::vector<PoseScript::Piece>* pieces, std::vector<Segment>* segments, TimeNs* t,
              const Eigen::Quaterniond& q0, const Eigen::Vector3d& p0, const Eigen::Quaterniond& q1,
              const Eigen::Vector3d& p1, double move_s, double lift_m) {
  PoseScript::Piece pc;
  pc.t0_ns = *t;
  pc.t1_ns = *t + duration_ns(move_s);
  pc.q0 = q0;
  const Eigen::AngleAxisd delta(q0.conjugate() * q1);
  pc.rotvec_body = delta.angle() * delta.axis();
  if (pc.rotvec_body.norm() > kPi) {  // take the short way
    pc.rotvec_body = pc.rotvec_body * (1.0 - 2.0 * kPi / pc.rotvec_body.norm());
  }
  pc.p0 = p0;
  pc.dp = p1 - p0;
  pc.lift_m = lift_m;
  pieces->push_back(pc);
  segments->push_back({pc.t0_ns, pc.t1_ns, "move", ""});
  *t = pc.t1_ns;
}

/// Attitude whose body-frame "up" direction is `up_body`, turned by `yaw` about world z.
Eigen::Quaterniond attitude(const Eigen::Vector3d& up_body, double yaw) {
  const Eigen::Quaterniond align = Eigen::Quaterniond::FromTwoVectors(up_body, Eigen::Vector3d::UnitZ());
  return (Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())) * align).normalized();
}

}  // namespace

Result<std::unique_ptr<PoseScript>> make_static_protocol(const StaticProtocolOptions& options,
                                                         std::uint64_t seed) {
  IMUCAL_TRY(options.validate());
  Rng rng(Rng::substream(seed, kSaltMotion));
  const int n = options.poses;

  // Attitudes well spread over the sphere: a Fibonacci lattice of "up" directions in the body
  // frame, turned by a random rotation, visited in greedy nearest-neighbour order starting from
  // the rest attitude (body z up).
  Eigen::Quaterniond spin(rng.normal(), rng.normal(), rng.normal(), rng.normal());
  spin.normalize();
  std::vector<Eigen::Vector3d> dirs;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    dirs.push_back(spin * Eigen::Vector3d(r * std::cos(golden * i), r * std::sin(golden * i), z));
  }
  std::vector<Eigen::Vector3d> order;
  Eigen::Vector3d current = Eigen::Vector3d::UnitZ();
  while (!dirs.empty()) {
    auto best = std::max_element(dirs.begin(), dirs.end(), [&](const auto& a, const auto& b) {
      return a.dot(current) < b.dot(current);
    });
    current = *best;
    order.push_back(current);
    dirs.erase(best);
  }

  std::vector<PoseScript::Piece> pieces;
  std::vector<Segment> segments;
  TimeNs t = 0;
  const Eigen::Vector3d centre(0.0, 0.0, 1.0);
  double yaw = rng.uniform(-kPi, kPi);
  Eigen::Quaterniond q = attitude(Eigen::Vector3d::UnitZ(), yaw);
  Eigen::Vector3d p = centre;
  add_hold(&pieces, &segments, &t, q, p, options.initial_still_s, "still");
  for (const Eigen::Vector3d& up : order) {
    // Every move turns by at least 20 deg about the vertical as well, so consecutive attitudes
    // stay distinct even where the gravity directions are close.
    yaw += rng.signed_magnitude(20.0 * kDeg, 60.0 * kDeg);
    const Eigen::Quaterniond q1 = attitude(up, yaw);
    const Eigen::Vector3d p1 = centre + Eigen::Vector3d(rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15),
                                                        rng.uniform(-0.05, 0.05));
    const double angle = q.angularDistance(q1);
    const double move_s = (1.0 + 1.5 * angle / kPi) / options.excitation;
    add_move(&pieces, &segments, &t, q, p, q1, p1, move_s, 0.05 * options.excitation);
    add_hold(&pieces, &segments, &t, q1, p1, rng.uniform(options.hold_min_s, options.hold_max_s), "hold");
    q = q1;
    p = p1;
  }
  return std::make_unique<PoseScript>(std::move(pieces), std::move(segments), options.tremor, seed, n);
}

const std::vector<std::string>& six_face_names() {
  static const std::vector<std::string> names = {"+z up", "-y up", "-z up", "+y up", "+x up", "-x up"};
  return names;
}

Result<std::unique_ptr<PoseScript>> make_six_face(const SixFaceOptions& options, std::uint64_t seed) {
  IMUCAL_TRY(options.validate());
  const std::vector<Eigen::Vector3d> ups = {Eigen::Vector3d::UnitZ(),  -Eigen::Vector3d::UnitY(),
                                            -Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitY(),
                                            Eigen::Vector3d::UnitX(),  -Eigen::Vector3d::UnitX()};
  std::vector<PoseScript::Piece> pieces;
  std::vector<Segment> segments;
  TimeNs t = 0;
  const Eigen::Vector3d p(0.0, 0.0, 1.0);
  // Faces are reached through 90 deg turns where possible; -z up from -y up is a 90 deg turn
  // about x, and so on, so the fixture looks like a cube turned on a table.
  std::vector<int> faces = options.faces;
  if (faces.empty()) faces = {0, 1, 2, 3, 4, 5};
  Eigen::Quaterniond q = attitude(ups[static_cast<std::size_t>(faces[0])], 0.0);
  const auto& names = six_face_names();
  add_hold(&pieces, &segments, &t, q, p, options.hold_s, "face", names[static_cast<std::size_t>(faces[0])]);
  for (std::size_t i = 1; i < faces.size(); ++i) {
    const Eigen::Quaterniond q1 = attitude(ups[static_cast<std::size_t>(faces[i])], 0.0);
    add_move(&pieces, &segments, &t, q, p, q1, p, options.move_s, 0.02);
    add_hold(&pieces, &segments, &t, q1, p, options.hold_s, "face",
             names[static_cast<std::size_t>(faces[i])]);
    q = q1;
  }
  Rng rng(Rng::substream(seed, kSaltMotion));
  int face = faces.back();
  double yaw = 0.0;
  for (int r = 0; r < options.revisits; ++r) {
    int next = face;
    while (next == face) next = static_cast<int>(rng.uniform(0.0, 6.0)) % 6;
    face = next;
    yaw += rng.signed_magnitude(20.0 * kDeg, 60.0 * kDeg);
    const Eigen::Quaterniond q1 = attitude(ups[static_cast<std::size_t>(face)], yaw);
    add_move(&pieces, &segments, &t, q, p, q1, p, options.move_s, 0.02);
    add_hold(&pieces, &segments, &t, q1, p, options.revisit_hold_s, "hold",
             names[static_cast<std::size_t>(face)]);
    q = q1;
  }
  return std::make_unique<PoseScript>(std::move(pieces), std::move(segments), options.tremor, seed,
                                      static_cast<int>(faces.size()) + options.revisits);
}

Result<std::unique_ptr<PoseScript>> make_still(const StillOptions& options, std::uint64_t seed) {
  IMUCAL_TRY(options.validate());
  std::vector<PoseScript::Piece> pieces;
  std::vector<Segment> segments;
  TimeNs t = 0;
  add_hold(&pieces, &segments, &t, Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.0, 0.0, 1.0),
           options.duration_s, "still");
  return std::make_unique<PoseScript>(std::move(pieces), std::move(segments), options.tremor, seed, 1);
}

// ---------------------------------------------------------------------------------------------
// CheckerboardMotion

Eigen::Quaterniond CheckerboardMotion::q_world_body_nominal() const {
  Eigen::Matrix3d R;  // columns: body x, y, z in world
  R.col(0) = Eigen::Vector3d::UnitX();
  R.col(1) = -Eigen::Vector3d::UnitZ();
  R.col(2) = Eigen::Vector3d::UnitY();
  return Eigen::Quaterniond(R);
}

Eigen::Vector3d CheckerboardMotion::p_world_body_nominal() const {
  return options_.board_centre_world - options_.standoff_m * Eigen::Vector3d::UnitY();
}

Eigen::Isometry3d CheckerboardMotion::T_world_board(const TargetDescription& target) const {
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d::UnitX();
  double w, h;  // extent of the target's points
  if (target.type == TargetDescription::Type::kAprilgrid) {
    // Printed on its z > 0 side (Kalibr's frame, y up the page): board y up, z towards the rig.
    R.col(1) = Eigen::Vector3d::UnitZ();
    R.col(2) = -Eigen::Vector3d::UnitY();
    const double pitch = (1.0 + target.tag_spacing) * target.tag_size_m;
    w = std::max(0, target.tag_cols - 1) * pitch + target.tag_size_m;
    h = std::max(0, target.tag_rows - 1) * pitch + target.tag_size_m;
  } else {
    // Printed on its z < 0 side: board y down, z away from the rig.
    R.col(1) = -Eigen::Vector3d::UnitZ();
    R.col(2) = Eigen::Vector3d::UnitY();
    w = std::max(0, target.cols - 1) * target.col_spacing_m;
    h = std::max(0, target.rows - 1) * target.row_spacing_m;
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = options_.board_centre_world - R * Eigen::Vector3d(0.5 * w, 0.5 * h, 0.0);
  return T;
}

void CheckerboardMotion::evaluate(const std::vector<Harmonic>& hs, double scale, double t_s,
                                  Eigen::Vector3d* x, Eigen::Vector3d* xd, Eigen::Vector3d* xdd) const {
  // Envelope e(t): 0 while still, a minimum-jerk ramp up, 1, a ramp down, 0.
  const double d = options_.duration_s;
  const double a0 = options_.still_s, a1 = a0 + options_.ramp_s;
  const double b1 = d - options_.still_s, b0 = b1 - options_.ramp_s;
  double e = 0, ed = 0, edd = 0;
  if (t_s >= a0 && t_s < a1) {
    double s, ds, dds;
    min_jerk((t_s - a0) / options_.ramp_s, &s, &ds, &dds);
    e = s;
    ed = ds / options_.ramp_s;
    edd = dds / (options_.ramp_s * options_.ramp_s);
  } else if (t_s >= a1 && t_s < b0) {
    e = 1.0;
  } else if (t_s >= b0 && t_s < b1) {
    double s, ds, dds;
    min_jerk((t_s - b0) / options_.ramp_s, &s, &ds, &dds);
    e = 1.0 - s;
    ed = -ds / options_.ramp_s;
    edd = -dds / (options_.ramp_s * options_.ramp_s);
  }
  Eigen::Vector3d h = Eigen::Vector3d::Zero(), hd = h, hdd = h;
  for (const Harmonic& k : hs) {
    for (int i = 0; i < 3; ++i) {
      const double w = 2.0 * kPi * k.freq_hz[i];
      const double sn = std::sin(w * t_s + k.phase[i]), cs = std::cos(w * t_s + k.phase[i]);
      h[i] += k.amplitude[i] * sn;
      hd[i] += k.amplitude[i] * w * cs;
      hdd[i] -= k.amplitude[i] * w * w * sn;
    }
  }
  *x = scale * e * h;
  *xd = scale * (ed * h + e * hd);
  *xdd = scale * (edd * h + 2.0 * ed * hd + e * hdd);
}

RigState CheckerboardMotion::state_at(double t_s) const {
  Eigen::Vector3d dp, dv, da, phi, phid, phidd;
  evaluate(translation_, translation_scale_, t_s, &dp, &dv, &da);
  evaluate(rotation_, rotation_scale_, t_s, &phi, &phid, &phidd);
  RigState st;
  // R = R_nominal Exp(phi(t)): w_body = J_r(phi) phi_dot.
  st.q_world_body = Eigen::Quaterniond(q_world_body_nominal().toRotationMatrix() * so3_exp(phi)).normalized();
  st.omega_body = so3_right_jacobian(phi) * phid;
  st.p_world_body = p_world_body_nominal() + dp;
  st.v_world = dv;
  st.a_world = da;
  apply_tremor(tremor_, tremor_freq_rot_hz_, tremor_phase_rot_, tremor_freq_pos_hz_, tremor_phase_pos_, t_s,
               &st);
  return st;
}

RigState CheckerboardMotion::at(TimeNs t_ns) const {
  return state_at(ns_to_s(std::clamp<TimeNs>(t_ns, 0, end_ns_)));
}

Result<std::unique_ptr<CheckerboardMotion>> CheckerboardMotion::create(
    const CheckerboardMotionOptions& options, std::uint64_t seed) {
  IMUCAL_TRY(options.validate());
  std::unique_ptr<CheckerboardMotion> m(new CheckerboardMotion());
  m->options_ = options;
  m->end_ns_ = duration_ns(options.duration_s);
  m->tremor_ = options.tremor;
  const Tremor tr = draw_tremor(seed);
  m->tremor_freq_rot_hz_ = tr.freq_rot_hz;
  m->tremor_phase_rot_ = tr.phase_rot;
  m->tremor_freq_pos_hz_ = tr.freq_pos_hz;
  m->tremor_phase_pos_ = tr.phase_pos;

  // "Trigonometric functions with different frequencies" (Krebs 5.1.1): three harmonics per
  // axis. Translation mostly along the viewing direction (world y), rotation mostly about the
  // viewing axis (body z), so the board stays in view.
  Rng rng(Rng::substream(seed, kSaltMotion));
  const Eigen::Vector3d trans_weight(0.7, 1.0, 0.7);  // world x, y, z
  const Eigen::Vector3d rot_weight(0.6, 0.6, 1.0);    // body x, y, z
  for (int k = 0; k < 3; ++k) {
    Harmonic ht, hr;
    for (int i = 0; i < 3; ++i) {
      ht.freq_hz[i] = rng.uniform(0.4, 1.2);
      ht.phase[i] = rng.uniform(0.0, 2.0 * kPi);
      ht.amplitude[i] = trans_weight[i] * rng.uniform(0.5, 1.0) / std::pow(2.0 * kPi * ht.freq_hz[i], 2);
      hr.freq_hz[i] = rng.uniform(0.15, 0.5);
      hr.phase[i] = rng.uniform(0.0, 2.0 * kPi);
      hr.amplitude[i] = rot_weight[i] * rng.uniform(0.5, 1.0) / (2.0 * kPi * hr.freq_hz[i]);
    }
    m->translation_.push_back(ht);
    m->rotation_.push_back(hr);
  }

  // Scale to the targets, measured on a 100 Hz grid over the whole script. Translation enters
  // linearly; rotation almost so (through J_r), hence a few fixed-point steps.
  const double target_a = options.mean_accel_mps2 * options.excitation;
  const double target_w = options.mean_rate_radps * options.excitation;
  const int steps = static_cast<int>(options.duration_s * 100.0);
  auto means = [&](double* mean_a, double* mean_w) {
    double sa = 0.0, sw = 0.0;
    for (int k = 0; k <= steps; ++k) {
      const double t = options.duration_s * k / steps;
      Eigen::Vector3d x, xd, xdd, phi, phid, phidd;
      m->evaluate(m->translation_, m->translation_scale_, t, &x, &xd, &xdd);
      m->evaluate(m->rotation_, m->rotation_scale_, t, &phi, &phid, &phidd);
      sa += xdd.norm();
      sw += (so3_right_jacobian(phi) * phid).norm();
    }
    *mean_a = sa / (steps + 1);
    *mean_w = sw / (steps + 1);
  };
  for (int iter = 0; iter < 4; ++iter) {
    double mean_a = 0.0, mean_w = 0.0;
    means(&mean_a, &mean_w);
    if (!(mean_a > 0.0 && mean_w > 0.0)) {
      return make_error(Errc::kInternal, "checkerboard motion: degenerate excitation");
    }
    m->translation_scale_ *= target_a / mean_a;
    m->rotation_scale_ *= target_w / mean_w;
  }

  const TimeNs still_ns = duration_ns(options.still_s);
  if (still_ns > 0) m->segments_.push_back({0, still_ns, "still", ""});
  m->segments_.push_back({still_ns, m->end_ns_ - still_ns, "move", ""});
  if (still_ns > 0) m->segments_.push_back({m->end_ns_ - still_ns, m->end_ns_, "still", ""});
  return m;
}

}  // namespace imucal::sim
