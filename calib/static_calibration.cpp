// SPDX-License-Identifier: BSD-3-Clause
#include "calib/static_calibration.hpp"

#include <ceres/ceres.h>
#include <time.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <limits>
#include <memory>
#include <string>

#include "calib/allan.hpp"
#include "calib/ellipsoid.hpp"
#include "calib/gravity.hpp"
#include "calib/gsens_calibration.hpp"
#include "calib/rk4.hpp"
#include "calib/static_detector.hpp"
#include "calib/static_faces.hpp"
#include "calib/static_gyro.hpp"
#include "calib/static_gyro_fit.hpp"
#include "calib/static_steps.hpp"
#include "core/option_words.hpp"
#include "core/threads.hpp"

namespace imucal::calib {
namespace {

/// CPU time of the calling thread: the timings mean the same on a loaded machine as on an idle one.
struct Clock {
  using time_point = double;
  static double now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
};

double seconds_since(Clock::time_point t0) { return Clock::now() - t0; }

// ---- accelerometer (eqs. 3.1-3.4) ---------------------------------------------------------

/// Residual of eq. 3.4 for one static mean: g^2 - |T_a K_a (a + b_a)|^2, parameters in the order
/// of eq. 3.2: [alpha_yz, alpha_zy, alpha_zx, s_x, s_y, s_z, b_x, b_y, b_z], each divided by a
/// fixed unit c_i so that all columns of the Jacobian have similar size (raw counts would
/// otherwise make the bias columns 1e7 times smaller than the scale columns, and the covariance
/// would lose them).
struct AccelMagnitudeCost {
  Eigen::Vector3d a;
  double g2;
  Vec9 c;

  template <class T>
  bool operator()(const T* pn, T* r) const {
    T p[9];
    for (int i = 0; i < 9; ++i) p[i] = pn[i] * c[i];
    const T x = p[3] * (a[0] + p[6]);
    const T y = p[4] * (a[1] + p[7]);
    const T z = p[5] * (a[2] + p[8]);
    const T ox = x - p[0] * y + p[1] * z;
    const T oy = y - p[2] * z;
    r[0] = T(g2) - (ox * ox + oy * oy + z * z);
    return true;
  }
  static ceres::CostFunction* Create(const Eigen::Vector3d& a, double g, const Vec9& c) {
    return new ceres::AutoDiffCostFunction<AccelMagnitudeCost, 1, 9>(new AccelMagnitudeCost{a, g * g, c});
  }
};

struct AccelSolve {
  Vec9 p;
  double cost = 0.0;
  double rms = 0.0;
  int iterations = 0;
  bool ok = false;
};

/// Magnitude form (eq. 3.4) from `init`; with fix_misalignment the three angles stay as given
/// (the scale-bias form: 6 parameters).
AccelSolve solve_accel(std::span<const Eigen::Vector3d> means, double g, const TedaldiTriad& init,
                       Eigen::MatrixXd* covariance, bool fix_misalignment = false) {
  AccelSolve out;
  Vec9 c;
  for (int i = 0; i < 3; ++i) {
    const double s = std::max(std::abs(init.scale[i]), 1e-12);
    c[i] = 1.0;
    c[3 + i] = s;
    c[6 + i] = g / s;
  }
  Vec9 pn = accel_params(init).cwiseQuotient(c);
  ceres::Problem problem;
  for (const auto& m : means)
    problem.AddResidualBlock(AccelMagnitudeCost::Create(m, g, c), nullptr, pn.data());
  if (fix_misalignment) problem.SetManifold(pn.data(), new ceres::SubsetManifold(9, {0, 1, 2}));
  const double fitted = fix_misalignment ? 6.0 : 9.0;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options(200), &problem, &summary);
  out.p = pn.cwiseProduct(c);
  out.ok = summary.IsSolutionUsable() && out.p.allFinite();
  out.cost = summary.final_cost;
  out.iterations = static_cast<int>(summary.iterations.size());
  const double n = static_cast<double>(means.size());
  out.rms = std::sqrt(2.0 * out.cost / n);
  if (covariance && out.ok) {
    // Covariance of the fitted columns, (J^T J)^+ from the Jacobian at the solution with the
    // truncation of ceres::Covariance's DENSE_SVD (normal_pseudo_inverse); a problem without the
    // manifold gives every column, and the held angles' rows stay zero. (ceres::Covariance itself
    // is not used: with a manifold its tangent-space path frees memory it did not allocate in the
    // sanitized build.)
    ceres::Problem plain;
    for (const auto& m : means)
      plain.AddResidualBlock(AccelMagnitudeCost::Create(m, g, c), nullptr, pn.data());
    ceres::Problem::EvaluateOptions eo;
    eo.num_threads = 1;
    ceres::CRSMatrix crs;
    if (!plain.Evaluate(eo, nullptr, nullptr, nullptr, &crs) || crs.num_cols != 9) {
      out.ok = false;
      return out;
    }
    const int first = fix_misalignment ? 3 : 0;
    Eigen::MatrixXd Jf = Eigen::MatrixXd::Zero(crs.num_rows, 9 - first);
    for (int r = 0; r < crs.num_rows; ++r) {
      for (int idx = crs.rows[r]; idx < crs.rows[r + 1]; ++idx) {
        if (crs.cols[idx] >= first) Jf(r, crs.cols[idx] - first) = crs.values[idx];
      }
    }
    Eigen::Matrix<double, 9, 9> cn = Eigen::Matrix<double, 9, 9>::Zero();
    cn.bottomRightCorner(9 - first, 9 - first) = normal_pseudo_inverse(Jf);
    // With no degrees of freedom left the residual variance, and so every sigma, is unknown.
    const double scale =
        n > fitted ? 2.0 * out.cost / (n - fitted) : std::numeric_limits<double>::quiet_NaN();
    *covariance = c.asDiagonal() * cn * c.asDiagonal() * scale;
  }
  return out;
}

// ---- helpers ---------------------------------------------------------------------------------

int count_distinct(std::span<const Eigen::Vector3d> directions, double min_angle_rad) {
  std::vector<Eigen::Vector3d> reps;
  const double cos_min = std::cos(min_angle_rad);
  for (const auto& d : directions) {
    bool found = false;
    for (const auto& r : reps) {
      if (r.dot(d) > cos_min) {
        found = true;
        break;
      }
    }
    if (!found) reps.push_back(d);
  }
  return static_cast<int>(reps.size());
}

TriadSigma accel_sigma(const Eigen::MatrixXd& cov) {
  TriadSigma s;
  const Eigen::VectorXd d = sigmas_of(cov);
  s.T(0, 1) = d[0];
  s.T(0, 2) = d[1];
  s.T(1, 2) = d[2];
  s.scale = d.segment<3>(3);
  s.bias = d.segment<3>(6);
  return s;
}

}  // namespace

namespace {

// ---- threshold search (Algorithm 1) ----------------------------------------------------------

/// Prefix sums over the whole recording, so that the mean of any interval costs O(1) for every
/// multiplier tried: accelerometer values about the first one (no precision lost on raw counts
/// with large offsets) and gyro rates about the still-period bias (for the rotation check).
struct PrefixSums {
  std::vector<Eigen::Vector3d> accel, gyro;
  Eigen::Vector3d accel_center = Eigen::Vector3d::Zero();
};

PrefixSums prefix_sums(const ScannedRecording& scan, const Eigen::Vector3d& gyro_bias_raw) {
  const std::size_t n = scan.accel.size();
  PrefixSums p;
  p.accel.resize(n + 1);
  p.gyro.resize(n + 1);
  p.accel[0].setZero();
  p.gyro[0].setZero();
  p.accel_center = scan.accel[0];
  for (std::size_t i = 0; i < n; ++i) {
    p.accel[i + 1] = p.accel[i] + (scan.accel[i] - p.accel_center);
    p.gyro[i + 1] = p.gyro[i] + (scan.gyro[i] - gyro_bias_raw);
  }
  return p;
}

/// The static poses found with one threshold multiplier and the accelerometer fitted to them.
struct Candidate {
  int multiplier = 0;
  std::vector<StaticInterval> intervals;
  std::vector<Eigen::Vector3d> means;       // accelerometer, input units
  std::vector<Eigen::Vector3d> gyro_means;  // gyroscope, input units
  AccelSolve solve;
  GyroStaticFit gyro;  // with the still start as its first pose
  int distinct = 0;
  std::vector<int> faces;           // the face each pose lies on (-1: none)
  int rotated = 0;                  // intervals dropped for rotation inside them
  double worst_rotation_deg = 0.0;  // of the dropped ones
};

using AccelModel = StaticCalibrationOptions::AccelModel;

/// The static means' directions: through the nominal conversion, else about the centre of the
/// means' bounding box.
std::vector<Eigen::Vector3d> attitude_directions(const std::vector<Eigen::Vector3d>& means,
                                                 const StaticCalibrationOptions& opt) {
  std::vector<Eigen::Vector3d> dirs;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& m : means) {
    lo = lo.cwiseMin(m);
    hi = hi.cwiseMax(m);
  }
  for (const auto& m : means) {
    const Eigen::Vector3d d =
        opt.accel_init ? opt.accel_init->to_si(m) : Eigen::Vector3d(m - 0.5 * (lo + hi));
    dirs.push_back(d.normalized());
  }
  return dirs;
}

/// Sets the candidate's distinct attitudes and faces; true when there are enough for `model`.
bool enough_attitudes(Candidate* c, AccelModel model, const StaticCalibrationOptions& opt) {
  const auto dirs = attitude_directions(c->means, opt);
  c->distinct = count_distinct(dirs, opt.distinct_attitude_deg * M_PI / 180.0);
  c->faces = assign_faces(dirs, opt.face_max_angle_deg * M_PI / 180.0);
  switch (model) {
    case AccelModel::kFaces:
      return missing_faces_in_words(face_counts(c->faces)).empty();
    case AccelModel::kScaleBias:
      return c->distinct >= opt.min_attitudes_scale_bias;
    default:
      return c->distinct >= opt.min_attitudes;
  }
}

/// Known-orientation form: the scales and biases are fitted again to the gravity magnitude (with
/// the faces' misalignment held) when the poses leave that fit at least 3 degrees of freedom; with
/// one pose per face the faces' fit is the whole result.
bool magnitude_after_faces(std::size_t poses) { return poses >= 9; }

/// Accelerometer fit (no covariance) of `model`. The magnitude forms start from the nominal
/// guess, or from the ellipsoid fit when there is no guess or it fits poorly; the known-orientation
/// form is linear. The rms is always that of eq. 3.4, so that multipliers compare alike.
AccelSolve first_accel_solve(const Candidate& c, AccelModel model, const StaticCalibrationOptions& opt) {
  const auto& means = c.means;
  if (model == AccelModel::kFaces) {
    // The faces give the misalignment, which the magnitude cannot see with so few attitudes; the
    // scales and biases come from the magnitude, which does not depend on how flat the faces lay.
    const KnownOrientationFit fit = fit_known_orientation(means, c.faces, opt.gravity_mps2);
    if (!fit.ok) return {};
    if (magnitude_after_faces(means.size()))
      return solve_accel(means, opt.gravity_mps2, fit.triad, nullptr, true);
    AccelSolve solve;  // one pose per face: the faces alone
    solve.p = accel_params(fit.triad);
    double ss = 0.0;
    for (const auto& m : means) {
      const double r = opt.gravity_mps2 * opt.gravity_mps2 - fit.triad.apply(m).squaredNorm();
      ss += r * r;
    }
    solve.cost = 0.5 * ss;
    solve.rms = std::sqrt(ss / static_cast<double>(means.size()));
    solve.ok = std::isfinite(solve.rms);
    return solve;
  }
  const bool fix = model == AccelModel::kScaleBias;
  const auto level = [fix](TedaldiTriad t) {
    if (fix) t.T.setIdentity();
    return t;
  };
  AccelSolve solve;
  std::optional<TedaldiTriad> init;
  if (opt.accel_init) init = triad_from_conversion(*opt.accel_init);
  if (init) solve = solve_accel(means, opt.gravity_mps2, level(*init), nullptr, fix);
  if (!init || !solve.ok || solve.rms > 0.02 * opt.gravity_mps2 * opt.gravity_mps2) {
    auto ell = fit_ellipsoid(means, opt.gravity_mps2);
    if (ell.ok()) {
      AccelSolve s2 = solve_accel(means, opt.gravity_mps2, level(*ell), nullptr, fix);
      if (s2.ok && (!solve.ok || s2.rms < solve.rms)) solve = s2;
    }
  }
  return solve;
}

/// Everything the threshold search reads.
struct SearchInput {
  const ScannedRecording& scan;
  const StaticDetection& detection;
  const StillStart& still;
  const PrefixSums& sums;
  std::size_t min_samples = 0;
  double max_rot_rad = 0.0;
  Eigen::Vector3d gyro_scale0 = Eigen::Vector3d::Ones();
  Eigen::Matrix3d H_fixed = Eigen::Matrix3d::Zero();  // input units per m/s^2, when G is given
  AccelModel model = AccelModel::kFull;
};

/// The g-sensitivity treatment used with `poses` static poses: an estimate needs enough of them.
GSensitivityMode effective_gsens(const StaticCalibrationOptions& opt, const Candidate& c) {
  const std::size_t poses = c.means.size();
  // Poses on all six faces determine G with few of them (the six-face experiment of Krebs
  // 5.2.3): each axis is seen at +g and -g.
  const bool six_faces = missing_faces_in_words(face_counts(c.faces)).empty();
  if (opt.gsens == GSensitivityMode::kEstimate && poses < static_cast<std::size_t>(opt.min_poses_for_gsens) &&
      !six_faces) {
    return GSensitivityMode::kOff;
  }
  return opt.gsens;
}

/// The still start's and a candidate's pose means, the accelerometer's calibrated with `accel`.
PoseMeans pose_means(const Candidate& c, const StillStart& still, const TedaldiTriad& accel,
                     const ScannedRecording& scan) {
  PoseMeans m;
  m.gyro.push_back(still.gyro_bias_raw);
  m.accel_si.push_back(accel.apply(still.accel_mean_raw));
  m.t_s.push_back(0.5 * (scan.t_s.front() + scan.t_s[still.samples - 1]));
  for (std::size_t k = 0; k < c.means.size(); ++k) {
    m.gyro.push_back(c.gyro_means[k]);
    m.accel_si.push_back(accel.apply(c.means[k]));
    m.t_s.push_back(0.5 * (scan.t_s[c.intervals[k].begin] + scan.t_s[c.intervals[k].end - 1]));
  }
  return m;
}

/// The gyro's static model fitted to a candidate's poses (through its accelerometer solve).
void fit_candidate_gyro(Candidate* c, const SearchInput& in, const StaticCalibrationOptions& opt) {
  c->gyro = fit_gyro_static(pose_means(*c, in.still, accel_triad(c->solve.p), in.scan), in.still,
                            effective_gsens(opt, *c), in.H_fixed);
}

/// The static intervals at threshold (k varsigma_init)^2 with their means and attitude count, the
/// accelerometer fitted to them when there are enough attitudes, and the gyro's static model.
/// Intervals whose gyro shows rotation beyond what the bias and the g-sensitivity explain are
/// dropped, and the fits repeated without them.
Candidate evaluate_multiplier(int k, const SearchInput& in, const StaticCalibrationOptions& opt) {
  Candidate c;
  c.multiplier = k;
  const double threshold = static_cast<double>(k) * static_cast<double>(k) * in.still.sigma_init_sq;
  const auto raw_intervals = detect_static_intervals(in.detection.sigma_sq, threshold, in.scan.accel_ok,
                                                     in.scan.break_before, in.min_samples);
  for (const auto& iv : raw_intervals) {
    const double m = static_cast<double>(iv.size());
    c.intervals.push_back(iv);
    c.means.push_back((in.sums.accel[iv.end] - in.sums.accel[iv.begin]) / m + in.sums.accel_center);
    c.gyro_means.push_back((in.sums.gyro[iv.end] - in.sums.gyro[iv.begin]) / m + in.still.gyro_bias_raw);
  }
  if (!enough_attitudes(&c, in.model, opt)) return c;
  c.solve = first_accel_solve(c, in.model, opt);
  if (!c.solve.ok) return c;
  fit_candidate_gyro(&c, in, opt);
  // Drop the interval whose gyro shows the most rotation beyond the static model, one at a time
  // with a refit after each: a pose turned about gravity (which the accelerometer cannot see)
  // pulls the fit towards itself, and dropping everything above the limit after one fit would
  // throw out good poses with it.
  bool dropped = false;
  for (;;) {
    std::size_t worst = 0;
    double worst_rot = 0.0;
    for (std::size_t j = 0; j < c.intervals.size(); ++j) {
      const double duration = static_cast<double>(c.intervals[j].size()) * in.scan.period_s;
      const double rot = in.gyro_scale0.cwiseProduct(c.gyro.residual[j + 1]).norm() * duration;
      if (rot > worst_rot) {
        worst_rot = rot;
        worst = j;
      }
    }
    if (worst_rot <= in.max_rot_rad) break;
    ++c.rotated;
    c.worst_rotation_deg = std::max(c.worst_rotation_deg, worst_rot * 180.0 / M_PI);
    const auto at = static_cast<std::ptrdiff_t>(worst);
    c.intervals.erase(c.intervals.begin() + at);
    c.means.erase(c.means.begin() + at);
    c.gyro_means.erase(c.gyro_means.begin() + at);
    dropped = true;
    if (!enough_attitudes(&c, in.model, opt)) {
      c.solve.ok = false;  // too few attitudes left for this model
      return c;
    }
    fit_candidate_gyro(&c, in, opt);  // with the accelerometer of all the poses: close enough here
  }
  if (dropped) {
    c.solve = first_accel_solve(c, in.model, opt);
    if (c.solve.ok) fit_candidate_gyro(&c, in, opt);
  }
  return c;
}

/// The candidates of every multiplier that have enough attitudes for in.model, and the most
/// attitudes and faces any multiplier found (for the refusal).
struct SearchPass {
  std::vector<Candidate> valid;
  int best_distinct = 0;
  std::size_t best_intervals = 0;
  std::array<int, kFaceCount> best_faces{};
};

SearchPass search_pass(const SearchInput& in, const StaticCalibrationOptions& opt) {
  SearchPass pass;
  int best_covered = -1;
  for (int k = opt.multiplier_min; k <= opt.multiplier_max; ++k) {
    Candidate c = evaluate_multiplier(k, in, opt);
    if (c.distinct > pass.best_distinct) {
      pass.best_distinct = c.distinct;
      pass.best_intervals = c.intervals.size();
    }
    const auto counts = face_counts(c.faces);
    const int covered =
        static_cast<int>(std::count_if(counts.begin(), counts.end(), [](int n) { return n > 0; }));
    if (covered > best_covered) {
      best_covered = covered;
      pass.best_faces = counts;
    }
    if (c.solve.ok) pass.valid.push_back(std::move(c));
  }
  return pass;
}

/// The models tried, in order: auto falls back from the full model to the known-orientation form
/// (six faces) and then to scales and biases alone.
std::vector<AccelModel> models_to_try(AccelModel m) {
  if (m == AccelModel::kAuto) return {AccelModel::kFull, AccelModel::kFaces, AccelModel::kScaleBias};
  return {m};
}

std::string refusal(const SearchPass& pass, const StaticCalibrationOptions& opt) {
  const std::string missing = missing_faces_in_words(pass.best_faces);
  std::string msg = "found at most " + std::to_string(pass.best_distinct) + " distinct static attitudes (" +
                    std::to_string(pass.best_intervals) + " static intervals of at least " +
                    format_number("%.1f", opt.min_interval_s) + " s) with any threshold multiplier in [" +
                    std::to_string(opt.multiplier_min) + ", " + std::to_string(opt.multiplier_max) + "]; ";
  switch (opt.accel_model) {
    case AccelModel::kFull:
      msg += "the full accelerometer model needs " + std::to_string(opt.min_attitudes);
      break;
    case AccelModel::kFaces:
      msg += "the known-orientation form needs a pose on each of the six faces";
      break;
    case AccelModel::kScaleBias:
      msg += "scales and biases alone need " + std::to_string(opt.min_attitudes_scale_bias);
      break;
    case AccelModel::kAuto:
      msg += "the full accelerometer model needs " + std::to_string(opt.min_attitudes) +
             ", scales and biases alone " + std::to_string(opt.min_attitudes_scale_bias) +
             " or a pose on each of the six faces";
      break;
  }
  if (std::all_of(pass.best_faces.begin(), pass.best_faces.end(), [](int n) { return n == 0; })) {
    msg += ". None of the poses lies within " + format_number("%.0f", opt.face_max_angle_deg) +
           " deg of a face (gravity along one axis), so the six-face form cannot be used either";
  } else if (!missing.empty()) {
    msg += ". No pose was held with " + missing + ": hold the rig that way too";
  }
  msg += ". " + std::to_string(pass.best_distinct) +
         " attitudes would determine at most the three biases with the scales taken as nominal, which is no "
         "calibration. Record again: after the still start, hold the rig still for 1-4 s on each of its six "
         "faces, better in 36-50 different attitudes (" +
         std::to_string(opt.recommended_attitudes) + " or more distinct), turning it between holds";
  return msg;
}

/// Algorithm 1: the multiplier whose static poses give the lowest accelerometer residual, for
/// the first model that some multiplier has enough attitudes for.
Result<Candidate> search_threshold(const ScannedRecording& scan, const StaticDetection& detection,
                                   const StillStart& still, const StaticCalibrationOptions& opt,
                                   std::vector<ThresholdCandidate>* scored, AccelModel* model,
                                   std::vector<std::string>* warnings) {
  const PrefixSums sums = prefix_sums(scan, still.gyro_bias_raw);
  SearchInput in{scan, detection, still, sums};
  in.gyro_scale0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  // A given G (rad/s per m/s^2) in input units through the nominal gyro scale.
  in.H_fixed = in.gyro_scale0.cwiseInverse().asDiagonal() * opt.gsens_fixed;
  in.min_samples =
      std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(opt.min_interval_s * scan.rate_hz)));
  in.max_rot_rad = opt.max_rotation_in_static_deg * M_PI / 180.0;
  SearchPass pass;
  for (AccelModel m : models_to_try(opt.accel_model)) {
    in.model = m;
    pass = search_pass(in, opt);
    if (!pass.valid.empty()) {
      *model = m;
      break;
    }
  }
  std::vector<Candidate>& valid = pass.valid;
  // Score: the accelerometer residual (eq. 3.4, Algorithm 1) and the gyro's residual about its
  // static model (motion let into the intervals shows there first), each relative to its best
  // over the multipliers, summed. A threshold whose intervals had to be dropped for rotation
  // loses to any that did not.
  double min_a = std::numeric_limits<double>::infinity(), min_g = min_a;
  for (const auto& c : valid) {
    min_a = std::min(min_a, c.solve.rms);
    min_g = std::min(min_g, c.gyro.rms);
  }
  const auto key = [&](const Candidate& c) {
    const double score = c.solve.rms / std::max(min_a, 1e-300) + c.gyro.rms / std::max(min_g, 1e-300);
    return std::make_pair(c.rotated > 0, score);
  };
  std::optional<Candidate> best;
  for (auto& c : valid) {
    scored->push_back({c.multiplier, static_cast<int>(c.intervals.size()), c.distinct, c.rotated, c.solve.rms,
                       c.gyro.rms, key(c).second});
    if (!best || key(c) < key(*best)) best = std::move(c);
  }
  if (!best) return make_error(Errc::kInsufficientData, refusal(pass, opt));
  if (*model == AccelModel::kFull && best->distinct < opt.recommended_attitudes) {
    warnings->push_back("only " + std::to_string(best->distinct) + " distinct attitudes were found (" +
                        std::to_string(opt.recommended_attitudes) +
                        " or more recommended, 36-50 ideal): the result is less certain, see the sigmas");
  }
  if (best->rotated > 0) {
    warnings->push_back(
        std::to_string(best->rotated) +
        " static interval(s) were dropped because the rig turned inside them: " + "the gyro shows up to " +
        format_number("%.1f", best->worst_rotation_deg) + " deg beyond its bias" +
        (opt.gsens == GSensitivityMode::kOff ? "" : " and g-sensitivity") + " (more than " +
        format_number("%.1f", opt.max_rotation_in_static_deg) + " deg): hold the poses steadier");
  }
  return std::move(*best);
}

// ---- accelerometer: final solve with covariance ----------------------------------------------

/// Held misalignment angles (at zero in the scale-bias form, at the faces' values in the
/// known-orientation form) are really uncertain by `priors`; the scales and biases they move (to
/// second order on faces, to first order on tilted poses) are widened by the shift a held angle
/// moved by +-prior gives, and the held angles carry the prior's variance so that the gyro's
/// covariance (which takes the accelerometer's) includes it.
void widen_for_held_misalignment(const Candidate& best, const StaticCalibrationOptions& opt, const Vec9& p,
                                 const Eigen::Vector3d& priors, Eigen::MatrixXd* cov) {
  for (int j = 0; j < 3; ++j) {
    const double prior = priors[j];
    Vec9 shift[2];
    for (int side = 0; side < 2; ++side) {
      Vec9 q = p;
      q[j] += side == 0 ? prior : -prior;
      const AccelSolve s = solve_accel(best.means, opt.gravity_mps2, accel_triad(q), nullptr, true);
      shift[side] = s.ok ? Vec9(s.p - q) : Vec9::Zero();
      shift[side][j] = 0.0;
    }
    const Vec9 linear = 0.5 * (shift[0] - shift[1]);
    *cov += 0.5 * (shift[0] * shift[0].transpose() + shift[1] * shift[1].transpose());
    // The held angle and what it moves, correlated through the linear part.
    for (int i = 0; i < 9; ++i) {
      (*cov)(i, j) += linear[i] * prior;
      (*cov)(j, i) += linear[i] * prior;
    }
    (*cov)(j, j) = prior * prior;
  }
}

/// The accelerometer's part of the static result.
struct AccelPiece {
  TedaldiTriad triad;
  Eigen::MatrixXd covariance;
  TriadSigma sigma;
  FitDof dof;
  StaticAccelModel model = StaticAccelModel::kFull;
  std::string reason;              // why that model
  std::vector<std::string> fixed;  // parameters held instead of fitted
  double faces_direction_rms_rad = 0.0;
  double faces_rotation_rad = 0.0;
  int poses_off_faces = 0;
  double residual_rms = 0.0;
  int iterations = 0;
  std::vector<StaticIntervalInfo> intervals;
  std::vector<std::string> warnings;
};

Result<AccelPiece> solve_accelerometer(const Candidate& best, AccelModel model,
                                       std::span<const ImuSample> samples,
                                       const StaticCalibrationOptions& opt) {
  AccelPiece a;
  AccelSolve final;
  if (model == AccelModel::kFaces) {
    const KnownOrientationFit fit = fit_known_orientation(best.means, best.faces, opt.gravity_mps2);
    if (!fit.ok)
      return make_error(Errc::kSolverFailed, "the known-orientation accelerometer fit failed: " + fit.error);
    if (magnitude_after_faces(best.means.size())) {
      // Misalignment from the faces, scales and biases from the magnitude with it held.
      final = solve_accel(best.means, opt.gravity_mps2, fit.triad, &a.covariance, true);
      if (!final.ok) return make_error(Errc::kSolverFailed, "the accelerometer's scale and bias fit failed");
      const Eigen::Vector3d angle_sigma = fit.covariance.diagonal().head<3>().cwiseMax(0.0).cwiseSqrt();
      widen_for_held_misalignment(best, opt, final.p, angle_sigma, &a.covariance);
      a.covariance.topLeftCorner<3, 3>() = fit.covariance.topLeftCorner<3, 3>();
      a.dof = {static_cast<int>(best.means.size()), 6};
    } else {
      final = first_accel_solve(best, model, opt);
      a.covariance = fit.covariance;
      a.dof = {fit.residuals, fit.parameters};
    }
    a.faces_direction_rms_rad = fit.direction_rms_rad;
    a.faces_rotation_rad = fit.q_angle_rad;
    a.poses_off_faces = static_cast<int>(std::count(best.faces.begin(), best.faces.end(), -1));
    a.model = StaticAccelModel::kFaces;
    a.reason =
        std::to_string(best.distinct) + " distinct attitudes, fewer than the " +
        std::to_string(opt.min_attitudes) +
        " the magnitude form needs, on all six faces: the misalignment from the poses taken as lying flat on "
        "their faces with gravity along their axes (the form PX4 and ArduPilot use), scales and biases " +
        (magnitude_after_faces(best.means.size()) ? std::string("from the gravity magnitude")
                                                  : std::string("from the faces too (fewer than 9 poses)"));
    if (opt.accel_model == AccelModel::kFaces)
      a.reason = "chosen with " + option_words(CalibOption::kAccelModel, "faces");
    if (a.poses_off_faces > 0) {
      a.warnings.push_back(
          std::to_string(a.poses_off_faces) + " static pose(s) lie on no face (more than " +
          format_number("%.0f", opt.face_max_angle_deg) +
          " deg from every axis): left out of the accelerometer fit, used for the gyroscope");
    }
    if (fit.direction_rms_rad > 1.0 * M_PI / 180.0) {
      a.warnings.push_back("the poses lie " + format_number("%.2f", fit.direction_rms_rad * 180.0 / M_PI) +
                           " deg RMS from their faces' axes: they were not flat on level faces, and the "
                           "misalignment is only as good as that (the scale-bias model, " +
                           option_words(CalibOption::kAccelModel, "scale-bias") +
                           ", fits scales and biases without assuming the faces)");
    }
  } else {
    const bool fix = model == AccelModel::kScaleBias;
    final = solve_accel(best.means, opt.gravity_mps2, accel_triad(best.solve.p), &a.covariance, fix);
    if (!final.ok) {
      return make_error(Errc::kSolverFailed,
                        "the accelerometer covariance could not be computed: the static attitudes do not "
                        "constrain all " +
                            std::string(fix ? "6" : "9") +
                            " parameters; record poses covering more directions");
    }
    a.dof = {static_cast<int>(best.means.size()), fix ? 6 : 9};
    if (fix) {
      widen_for_held_misalignment(best, opt, final.p, Eigen::Vector3d::Constant(opt.misalignment_prior_rad),
                                  &a.covariance);
      a.model = StaticAccelModel::kScaleBias;
      a.fixed = {"misalignment alpha_yz", "misalignment alpha_zy", "misalignment alpha_zx"};
      a.reason = opt.accel_model == AccelModel::kScaleBias
                     ? "chosen with " + option_words(CalibOption::kAccelModel, "scale-bias")
                     : std::to_string(best.distinct) + " distinct attitudes, fewer than the " +
                           std::to_string(opt.min_attitudes) +
                           " the full model needs, not on all six faces (missing: " +
                           missing_faces_in_words(face_counts(best.faces)) +
                           "): scales and biases from the gravity magnitude, misalignment held at zero";
      a.warnings.push_back("the accelerometer misalignment was not determined (held at zero; " + a.reason +
                           "); the scale and bias sigmas include a misalignment of " +
                           format_number("%.3f", opt.misalignment_prior_rad) + " rad");
    } else {
      a.model = StaticAccelModel::kFull;
      a.reason = std::to_string(best.distinct) + " distinct attitudes (" + std::to_string(opt.min_attitudes) +
                 " needed): Tedaldi's magnitude form";
    }
  }
  a.triad = accel_triad(final.p);
  if (!a.dof.determined()) {
    a.warnings.push_back("the accelerometer fit is exact: " + std::to_string(a.dof.residuals) +
                         " residuals for its " + std::to_string(a.dof.parameters) +
                         " parameters leave nothing to check it against, and its sigmas are undetermined. "
                         "Record more poses (36-50)");
  }
  a.residual_rms = final.rms;
  a.iterations = best.solve.iterations + final.iterations;
  a.sigma = accel_sigma(a.covariance);
  if (model == AccelModel::kScaleBias) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    a.sigma.T(0, 1) = a.sigma.T(0, 2) = a.sigma.T(1, 2) = nan;
  }
  for (std::size_t k = 0; k < best.intervals.size(); ++k) {
    const auto& iv = best.intervals[k];
    a.intervals.push_back({samples[iv.begin].t_ns, samples[iv.end - 1].t_ns, iv.size(), best.means[k]});
  }
  return a;
}

// ---- g-sensitivity ---------------------------------------------------------------------------

/// Few poses on all six faces: the fit over the poses has too few degrees of freedom for its
/// residual covariance to mean much, so G and the bias come from the six-face experiment
/// (calib/gsens_calibration.hpp: generalised least squares weighted by the holds' white noise and
/// bias walk) through the final accelerometer; the pose fit stays when that cannot be had (holds
/// shorter than its minimum), with a warning.
void six_face_gsens(std::span<const ImuSample> samples, const StaticCalibrationOptions& opt,
                    const Eigen::Vector3d& s0, const TedaldiTriad& accel, std::vector<std::string>* warnings,
                    GyroStaticFit* f) {
  GSensitivityOptions g;
  g.gravity_mps2 = opt.gravity_mps2;
  TedaldiImuModel model;  // the accelerometer's canonical form: the gyro is not solved yet
  model.accel = accel;
  const CanonicalImuModel c = canonical_from_tedaldi(model);
  g.A_a = c.A_a;
  g.b_a = c.b_a;
  g.A_g = s0.asDiagonal();
  g.window_s = opt.window_s;
  g.max_face_angle_deg = std::max(opt.face_max_angle_deg, 30.0);
  const Result<GSensitivityResult> r = calibrate_gsens(samples, g);
  if (!r.ok()) {
    warnings->push_back("the g-sensitivity comes from the " + std::to_string(f->dof.residuals) +
                        " pose means with " + std::to_string(f->dof.dof()) +
                        " degrees of freedom per axis, too few for trustworthy sigmas; the six-face "
                        "experiment could not be used: " +
                        r.error().message);
    return;
  }
  const Eigen::Vector3d inv = s0.cwiseInverse();
  f->H = inv.asDiagonal() * r->G;
  f->bias = r->b_g;
  f->drift.setZero();
  f->drift_offset.setZero();
  for (int i = 0; i < 3; ++i) {
    f->H_sigma.row(i) = r->G_sigma.row(i) * inv[i];
    f->bias_sigma[i] = r->b_g_sigma[i];
  }
  f->dof = {r->dof.residuals / 3, r->dof.parameters / 3};
  for (const auto& w : r->warnings) warnings->push_back("g-sensitivity (six-face holds): " + w);
}

/// The gyro's static model with the final accelerometer calibration. When G is neglected for
/// being indistinguishable from zero, two: the bias and its drift fitted to the poses, and the
/// still start's mean (Tedaldi's); the caller keeps the one whose gyro carries gravity better.
struct GsensPiece {
  GSensitivityMode mode = GSensitivityMode::kOff;
  double wald = std::numeric_limits<double>::quiet_NaN();
  FitDof dof;
  std::vector<GyroStaticFit> fits;  // one, or two when G is neglected (see above)
  std::vector<std::string> warnings;
};

GsensPiece final_gyro_static_fits(const Candidate& best, const ScannedRecording& scan,
                                  std::span<const ImuSample> samples, const StillStart& still,
                                  const StaticCalibrationOptions& opt, const TedaldiTriad& accel) {
  GsensPiece p;
  p.mode = effective_gsens(opt, best);
  if (p.mode != opt.gsens) {
    p.warnings.push_back(
        "the gyro g-sensitivity was not estimated: " + std::to_string(best.means.size()) +
        " static poses are too few to fit it (" + std::to_string(opt.min_poses_for_gsens) +
        " needed, or a pose on each of the six faces); it is neglected (Tedaldi's model), which "
        "costs gyro accuracy on MEMS gyros. Record more poses, or give a known G");
  }
  // A given G in input units through the nominal gyro scale (the solved scale differs from it by
  // far less than G's own uncertainty).
  const Eigen::Vector3d s0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  const Eigen::Matrix3d H_fixed = s0.cwiseInverse().asDiagonal() * opt.gsens_fixed;
  GyroStaticFit f = fit_gyro_static(pose_means(best, still, accel, scan), still, p.mode, H_fixed);
  if (p.mode == GSensitivityMode::kEstimate &&
      best.means.size() < static_cast<std::size_t>(opt.min_poses_for_gsens)) {
    six_face_gsens(samples, opt, s0, accel, &p.warnings, &f);
  }
  if (p.mode == GSensitivityMode::kEstimate) {
    // Is G distinguishable from zero at all? The Wald statistic of its nine entries (their
    // correlations neglected) against the chi-square 95 % point; below it, estimating G only
    // adds its noise to every gyro sample (on the real recordings of docs/static-calibration.md
    // whose G this test rejects, neglecting it carried gravity better on every one).
    double w = 0.0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) w += (f.H(i, j) / f.H_sigma(i, j)) * (f.H(i, j) / f.H_sigma(i, j));
    p.wald = w;
    if (std::isfinite(w) && w < kGsensWaldLimit) {
      // Not a warning: there is nothing to do about it. The summary and the JSON say so.
      p.mode = GSensitivityMode::kOff;
      const PoseMeans m = pose_means(best, still, accel, scan);
      p.fits = {fit_gyro_static(m, still, GSensitivityMode::kEstimate, H_fixed, false),
                fit_gyro_static(m, still, GSensitivityMode::kOff, H_fixed)};
      p.dof = p.fits[0].dof;
      return p;
    }
  }
  p.dof = f.dof;
  p.fits = {f};
  return p;
}

/// The recording with every gyro sample's g-sensitivity removed (w_raw - H a(t), a(t) the
/// calibrated accelerometer sample), so that the transfers integrate rates that carry only the
/// bias besides the rotation.
ScannedRecording without_gsens(const ScannedRecording& scan, const GyroStaticFit& f,
                               const TedaldiTriad& accel) {
  ScannedRecording out = scan;
  if (f.H.isZero(0.0) && f.drift.isZero(0.0)) return out;
  for (std::size_t i = 0; i < out.gyro.size(); ++i) {
    out.gyro[i] -= f.H * accel.apply(scan.accel[i]) + f.drift_at(scan.t_s[i]);
  }
  return out;
}

/// The g-sensitivity's part of the result: canonical G = A_g H (minus the Earth's vertical rate
/// when the latitude is known) and its sigma; none when it is neglected.
struct GsensOutcome {
  std::optional<Eigen::Matrix3d> G;
  Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
  double earth_rate_removed = 0.0;
  double residual_rms = 0.0;
};

GsensOutcome gsens_outcome(const GyroStaticFit& f, GSensitivityMode mode, const TedaldiTriad& gyro,
                           const StaticCalibrationOptions& opt) {
  GsensOutcome out;
  out.residual_rms = f.rms;
  const Eigen::Matrix3d A = gyro.TK();
  if (mode == GSensitivityMode::kFixed) {
    out.G = opt.gsens_fixed;
    out.residual_rms = (opt.gyro_init ? opt.gyro_init->scale.mean() : 1.0) * f.rms;
    return out;
  }
  if (mode == GSensitivityMode::kOff) return out;
  Eigen::Matrix3d G = A * f.H;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double var = 0.0;
      for (int k = 0; k < 3; ++k) var += A(i, k) * A(i, k) * f.H_sigma(k, j) * f.H_sigma(k, j);
      out.sigma(i, j) = std::sqrt(var);
    }
  }
  if (opt.latitude_deg) {
    out.earth_rate_removed = earth_rate_gsens(*opt.latitude_deg, opt.gravity_mps2);
    G -= out.earth_rate_removed * Eigen::Matrix3d::Identity();
  }
  out.G = G;
  const Eigen::Vector3d s0 = opt.gyro_init ? opt.gyro_init->scale : Eigen::Vector3d::Ones();
  out.residual_rms = s0.mean() * f.rms;
  return out;
}

}  // namespace

/// The gyro solve kept (of one per static model) with the transfers it used.
struct GyroChoice {
  GyroPiece gyro;
  std::vector<Transfer> transfers;
  std::vector<std::string> transfer_warnings;
  std::size_t fit = 0;  // of GsensPiece::fits
};

/// The result, assembled once from the steps' pieces (warnings in the order the steps ran).
void put_pieces(const AccelPiece& a, const GsensPiece& gsens, const GyroChoice& chosen,
                StaticCalibrationResult* out) {
  StaticCalibrationResult& res = *out;
  res.model.accel = a.triad;
  res.accel_covariance = a.covariance;
  res.accel_sigma = a.sigma;
  res.accel_dof = a.dof;
  res.accel_model = a.model;
  res.accel_model_reason = a.reason;
  res.accel_fixed = a.fixed;
  res.faces_direction_rms_rad = a.faces_direction_rms_rad;
  res.faces_rotation_rad = a.faces_rotation_rad;
  res.poses_off_faces = a.poses_off_faces;
  res.accel_residual_rms = a.residual_rms;
  res.accel_iterations = a.iterations;
  res.intervals = a.intervals;
  res.gsens_mode = gsens.mode;
  res.gsens_wald = gsens.wald;
  res.gsens_dof = gsens.dof;
  const GyroPiece& g = chosen.gyro;
  res.gyro_bias_from_poses = gsens.fits.size() == 2 && chosen.fit == 0;
  res.gyro_transfers = static_cast<int>(chosen.transfers.size());
  res.model.gyro = g.triad;
  res.gyro_covariance = g.covariance;
  res.gyro_sigma = g.sigma;
  res.gyro_dof = g.dof;
  res.gyro_fixed = g.fixed;
  res.gyro_residual_rms = g.residual_rms;
  res.gyro_iterations = g.iterations;
  const std::vector<std::string>* const steps_said[] = {&a.warnings, &gsens.warnings,
                                                        &chosen.transfer_warnings, &g.warnings};
  for (const std::vector<std::string>* said : steps_said)
    res.warnings.insert(res.warnings.end(), said->begin(), said->end());
}

Result<StaticCalibrationResult> calibrate_static(std::span<const ImuSample> samples,
                                                 const StaticCalibrationOptions& given) {
  IMUCAL_TRY(given.validate());
  StaticCalibrationOptions opt = given;  // its nominal accelerometer conversion may be set aside
  StaticCalibrationResult res;
  res.gravity_mps2 = opt.gravity_mps2;
  if (samples.size() < 1000) {
    return make_error(Errc::kInsufficientData,
                      "the recording has " + std::to_string(samples.size()) +
                          " samples: a static calibration needs a still start (about 50 s) and 36-50 "
                          "held poses; record again");
  }
  Result<ScannedRecording> scan = scan_recording(samples, &res.warnings);
  if (!scan.ok()) return scan.error();

  auto t0 = Clock::now();
  const StaticDetection detection = detect_variance(*scan, opt.window_s);
  Result<StillStart> still = find_still_start(samples, *scan, detection, opt, &res.warnings);
  if (!still.ok()) return still.error();
  set_aside_an_implausible_accel_conversion(*still, &opt, &res.warnings);
  res.init_still_s = still->length_s;
  res.init_still_from_allan = still->from_allan;
  res.sigma_init_sq = still->sigma_init_sq;
  res.timings.detector_s = seconds_since(t0);

  t0 = Clock::now();
  AccelModel model = AccelModel::kFull;
  Result<Candidate> best =
      search_threshold(*scan, detection, *still, opt, &res.threshold_candidates, &model, &res.warnings);
  res.timings.threshold_search_s = seconds_since(t0);
  if (!best.ok()) return best.error();
  res.threshold_multiplier = best->multiplier;
  res.threshold = static_cast<double>(best->multiplier) * best->multiplier * res.sigma_init_sq;
  res.distinct_attitudes = best->distinct;

  t0 = Clock::now();
  Result<AccelPiece> accel = solve_accelerometer(*best, model, samples, opt);
  if (!accel.ok()) return accel.error();
  res.timings.accel_s = seconds_since(t0);

  t0 = Clock::now();
  const GsensPiece gsens = final_gyro_static_fits(*best, *scan, samples, *still, opt, accel->triad);
  // One gyro solve per static model; with two (G neglected: the bias from the poses or from the
  // still start), the one with the smaller residual of eq. 3.8 is kept, warnings and all.
  std::optional<GyroChoice> chosen;
  for (std::size_t k = 0; k < gsens.fits.size(); ++k) {
    const ScannedRecording corrected = without_gsens(*scan, gsens.fits[k], accel->triad);
    std::vector<std::string> transfer_warnings;
    Result<std::vector<Transfer>> transfers =
        collect_transfers(best->intervals, corrected, samples, opt, &transfer_warnings);
    if (!transfers.ok()) return transfers.error();
    const GyroSolveInput gyro_input{best->intervals, best->means, gsens.fits[k].bias,
                                    gsens.fits[k].bias_sigma};
    Result<GyroPiece> gyro = solve_gyroscope(
        &*transfers, gyro_input, AccelForGyro{accel->triad, accel->covariance}, corrected, samples, opt);
    if (!gyro.ok()) return gyro.error();
    if (!chosen || gyro->residual_rms < chosen->gyro.residual_rms) {
      chosen = GyroChoice{std::move(*gyro), std::move(*transfers), std::move(transfer_warnings), k};
    }
  }
  res.timings.gyro_s = seconds_since(t0);

  put_pieces(*accel, gsens, *chosen, &res);
  res.quality = quality_figures(chosen->transfers, best->intervals, best->means, *scan, samples, *still, opt,
                                res.model);
  res.canonical = canonical_from_tedaldi(res.model);
  const GsensOutcome G = gsens_outcome(gsens.fits[chosen->fit], res.gsens_mode, res.model.gyro, opt);
  if (G.G) res.canonical.G = *G.G;
  res.gsens_sigma = G.sigma;
  res.earth_rate_removed = G.earth_rate_removed;
  res.gsens_residual_rms = G.residual_rms;
  return res;
}

}  // namespace imucal::calib
