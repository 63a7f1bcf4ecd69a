// SPDX-License-Identifier: BSD-3-Clause
#include "app/calibration_check.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <tuple>

#include "calib/rk4.hpp"
#include "calib/static_detector.hpp"
#include "calib/static_scan.hpp"
#include "core/text_file.hpp"
#include "core/text_format.hpp"

namespace imucal::app {
namespace {

std::string seconds_text(double s) {
  std::ostringstream os;
  os.precision(3);
  os << s;
  return os.str();
}

/// Accumulates mean, RMS and max.
class FigureSum {
 public:
  void add(double v) {
    ++n_;
    sum_ += v;
    sum_sq_ += v * v;
    max_ = std::max(max_, v);
  }
  CheckFigures figures() const {
    CheckFigures f;
    f.count = n_;
    if (n_ == 0) return f;
    f.mean = sum_ / n_;
    f.rms = std::sqrt(sum_sq_ / n_);
    f.max = max_;
    return f;
  }

 private:
  int n_ = 0;
  double sum_ = 0.0, sum_sq_ = 0.0, max_ = 0.0;
};

std::string file_name(const std::string& path) { return std::filesystem::path(path).filename().string(); }

// ---- imucal YAML ----------------------------------------------------------------------------

Result<Eigen::Matrix3d> yaml_matrix(const YAML::Node& section, const char* key, const std::string& origin) {
  const YAML::Node m = section[key];
  const std::string what = origin + ": canonical." + key;
  if (!m) return make_error(Errc::kCorrupt, what + " is missing");
  if (!m.IsSequence() || m.size() != 3)
    return make_error(Errc::kCorrupt, what + " must be 3 rows of 3 numbers");
  Eigen::Matrix3d out;
  for (std::size_t r = 0; r < 3; ++r) {
    if (!m[r].IsSequence() || m[r].size() != 3)
      return make_error(Errc::kCorrupt,
                        what + " must be 3 rows of 3 numbers (row " + std::to_string(r + 1) + " is not)");
    for (std::size_t c = 0; c < 3; ++c) {
      try {
        out(static_cast<int>(r), static_cast<int>(c)) = m[r][c].as<double>();
      } catch (const YAML::Exception&) {
        return make_error(Errc::kCorrupt, what + " row " + std::to_string(r + 1) + " holds '" +
                                              m[r][c].Scalar() + "', not a number");
      }
    }
  }
  if (!out.allFinite()) return make_error(Errc::kCorrupt, what + " holds a value that is not finite");
  return out;
}

Result<Eigen::Vector3d> yaml_vector(const YAML::Node& section, const char* key, const std::string& origin) {
  const YAML::Node v = section[key];
  const std::string what = origin + ": canonical." + key;
  if (!v) return make_error(Errc::kCorrupt, what + " is missing");
  if (!v.IsSequence() || v.size() != 3) return make_error(Errc::kCorrupt, what + " must be 3 numbers");
  Eigen::Vector3d out;
  for (std::size_t i = 0; i < 3; ++i) {
    try {
      out[static_cast<int>(i)] = v[i].as<double>();
    } catch (const YAML::Exception&) {
      return make_error(Errc::kCorrupt, what + " holds '" + v[i].Scalar() + "', not a number");
    }
  }
  if (!out.allFinite()) return make_error(Errc::kCorrupt, what + " holds a value that is not finite");
  return out;
}

/// The factors and sigmas of `accel:` and `gyro:` (calibrate static's result), or nothing when any
/// is missing or malformed: they only widen a held calibration's sigmas, never refuse the file.
std::optional<NamedCalibration::Spread> read_spread(const YAML::Node& root) {
  const auto matrix = [](const YAML::Node& m, Eigen::Matrix3d* out) {
    if (!m || !m.IsSequence() || m.size() != 3) return false;
    for (std::size_t r = 0; r < 3; ++r) {
      if (!m[r].IsSequence() || m[r].size() != 3) return false;
      for (std::size_t c = 0; c < 3; ++c)
        (*out)(static_cast<int>(r), static_cast<int>(c)) = m[r][c].as<double>();
    }
    return true;
  };
  const auto vector = [](const YAML::Node& v, Eigen::Vector3d* out) {
    if (!v || !v.IsSequence() || v.size() != 3) return false;
    for (std::size_t i = 0; i < 3; ++i) (*out)(static_cast<int>(i)) = v[i].as<double>();
    return true;
  };
  NamedCalibration::Spread s;
  try {
    for (auto [key, triad, sigma] :
         {std::tuple{"accel", &s.accel, &s.accel_sigma}, std::tuple{"gyro", &s.gyro, &s.gyro_sigma}}) {
      const YAML::Node t = root[key];
      if (!t || !t.IsMap() || !t["sigma"]) return std::nullopt;
      if (!matrix(t["misalignment"], &triad->T) || !vector(t["scale"], &triad->scale) ||
          !matrix(t["sigma"]["misalignment"], &sigma->T) || !vector(t["sigma"]["scale"], &sigma->scale))
        return std::nullopt;
    }
  } catch (const YAML::Exception&) {
    return std::nullopt;
  }
  return s;
}

}  // namespace

Status CheckSetOptions::validate() const {
  if (!(window_s >= 0.05 && window_s <= 10.0))
    return make_error(Errc::kInvalidArgument, "the detector window must be 0.05-10 s");
  if (!(multiplier >= 1.5 && multiplier <= 100.0))
    return make_error(Errc::kInvalidArgument, "the threshold multiplier must be 1.5-100")
        .with_remedy("multiplier");
  if (!(min_interval_s >= 0.05 && min_interval_s <= 60.0))
    return make_error(Errc::kInvalidArgument, "the shortest static interval must be 0.05-60 s")
        .with_remedy("min_interval_s");
  if (!(floor_percentile > 0.0 && floor_percentile < 1.0))
    return make_error(Errc::kInvalidArgument, "the floor percentile must lie between 0 and 1");
  return {};
}

namespace {

/// The motions from the last sample of one interval to the first of the next that can be
/// integrated (no break, no invalid sample), into `set`.
Status add_transfers(std::span<const ImuSample> samples, const std::vector<bool>& break_before,
                     const std::vector<bool>& usable, CheckSet* set_out) {
  CheckSet& set = *set_out;
  auto t_ns = [&samples](std::size_t i) { return samples[i].t_ns; };
  for (std::size_t k = 0; k + 1 < set.intervals.size(); ++k) {
    ++set.motions;
    const std::size_t a = set.intervals[k].end - 1;
    const std::size_t b = set.intervals[k + 1].begin;
    bool gap = false, saturated = false;
    for (std::size_t i = a; i <= b; ++i) {
      gap = gap || (i > a && break_before[i]);
      saturated = saturated || !usable[i];
    }
    if (gap || saturated) {
      set.motions_with_gap += gap ? 1 : 0;
      set.motions_with_saturation += saturated ? 1 : 0;
      continue;
    }
    CheckTransfer tr;
    tr.from = k;
    for (std::size_t i = a; i <= b; ++i) {
      tr.t_s.push_back(ns_to_s(t_ns(i) - t_ns(a)));
      tr.accel_raw.push_back(samples[i].accel);
      tr.gyro_raw.push_back(samples[i].gyro);
    }
    set.transfers.push_back(std::move(tr));
  }
  if (set.transfers.empty()) {
    return make_error(Errc::kInsufficientData,
                      "none of the " + std::to_string(set.motions) +
                          " motions between static intervals can be integrated (" +
                          std::to_string(set.motions_with_gap) + " contain a gap or a device reset, " +
                          std::to_string(set.motions_with_saturation) +
                          " saturated samples): record again without gaps, turning the rig more gently");
  }
  return {};
}

}  // namespace

Result<CheckSet> build_check_set(std::span<const ImuSample> samples, const CheckSetOptions& opt) {
  IMUCAL_TRY(opt.validate());
  const std::size_t n = samples.size();
  CheckSet set;
  set.options = opt;
  set.samples = n;
  if (n < 10) {
    return make_error(Errc::kInsufficientData, "the recording has " + std::to_string(n) +
                                                   " samples: record static poses (hold each for at least " +
                                                   seconds_text(opt.min_interval_s) + " s)");
  }
  // The time base, breaks and invalid samples as the static calibration scans them.
  std::vector<std::string> scan_notes;  // the counts below say the same
  auto scan = calib::scan_recording(samples, &scan_notes);
  if (!scan.ok()) return scan.error();
  set.t_first_ns = samples.front().t_ns;
  set.rate_hz = scan->rate_hz;
  set.gaps = scan->gaps;
  set.accel_saturated = scan->accel_saturated;
  set.gyro_saturated = scan->gyro_saturated;
  const std::vector<bool>& break_before = scan->break_before;
  std::vector<bool> usable(n);
  for (std::size_t i = 0; i < n; ++i) usable[i] = scan->accel_ok[i] && scan->gyro_ok[i];
  const std::vector<bool>& accel_ok = scan->accel_ok;
  const std::vector<Eigen::Vector3d>& accel = scan->accel;  // invalid samples repeat the previous
  auto t_ns = [&samples](std::size_t i) { return samples[i].t_ns; };

  const std::size_t window =
      std::max<std::size_t>(3, static_cast<std::size_t>(std::lround(opt.window_s * set.rate_hz)));
  const std::vector<double> sigma_sq = calib::variance_magnitude_sq(accel, window);
  std::vector<double> quiet;
  quiet.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (accel_ok[i]) quiet.push_back(sigma_sq[i]);
  }
  set.floor_sq = std::max(calib::percentile(quiet, opt.floor_percentile), 1e-300);
  set.threshold = opt.multiplier * std::sqrt(set.floor_sq);
  const std::size_t min_samples =
      std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(opt.min_interval_s * set.rate_hz)));
  const auto found = calib::detect_static_intervals(sigma_sq, set.threshold * set.threshold, usable,
                                                    break_before, min_samples);
  for (const auto& iv : found) {
    CheckInterval c;
    c.begin = iv.begin;
    c.end = iv.end;
    c.t0_ns = t_ns(iv.begin);
    c.t1_ns = t_ns(iv.end - 1);
    for (std::size_t i = iv.begin; i < iv.end; ++i) {
      c.accel_mean_raw += samples[i].accel;
      c.t_s.push_back(ns_to_s(t_ns(i) - t_ns(iv.begin)));
      c.accel_raw.push_back(samples[i].accel);
      c.gyro_raw.push_back(samples[i].gyro);
    }
    c.accel_mean_raw /= static_cast<double>(iv.size());
    set.intervals.push_back(c);
  }
  if (set.intervals.size() < 2) {
    return make_error(Errc::kInsufficientData,
                      "found " + std::to_string(set.intervals.size()) + " static interval(s) of at least " +
                          seconds_text(opt.min_interval_s) + " s (varsigma below " +
                          seconds_text(opt.multiplier) +
                          " times the quiet floor); the check needs a recording of static poses: hold the "
                          "rig still in several attitudes, turning it between holds")
        .with_remedy("multiplier")
        .with_remedy("min_interval_s");
  }

  IMUCAL_TRY(add_transfers(samples, break_before, usable, &set));
  return set;
}

CheckFiguresPair check_calibration(const CheckSet& set, const CanonicalImuModel& model, double gravity) {
  CheckFiguresPair out;
  FigureSum magnitude, direction;
  // Gravity direction at the first and at the last sample of every interval.
  std::vector<Eigen::Vector3d> u_start(set.intervals.size()), u_end(set.intervals.size());
  for (std::size_t k = 0; k < set.intervals.size(); ++k) {
    const CheckInterval& iv = set.intervals[k];
    const double err = std::abs(model.correct_accel(iv.accel_mean_raw).norm() - gravity);
    magnitude.add(err);
    out.magnitude_per_interval_mps2.push_back(err);
    if (iv.accel_raw.empty()) continue;
    // R rotates the body frame at sample j into the frame at the first sample.
    calib::Quat4 q(1, 0, 0, 0);
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    Eigen::Vector3d a = model.correct_accel(iv.accel_raw[0]);
    Eigen::Vector3d sum = a;
    Eigen::Vector3d w_prev = model.correct_gyro(iv.gyro_raw[0], a);
    for (std::size_t j = 1; j < iv.accel_raw.size(); ++j) {
      a = model.correct_accel(iv.accel_raw[j]);
      const Eigen::Vector3d w = model.correct_gyro(iv.gyro_raw[j], a);
      q = calib::rk4n_step(q, w_prev, w, iv.t_s[j] - iv.t_s[j - 1]);
      w_prev = w;
      R = calib::quat_to_matrix(q);
      sum += R * a;
    }
    u_start[k] = sum.normalized();
    u_end[k] = (R.transpose() * sum).normalized();
  }
  std::vector<Eigen::Vector3d> w;
  for (const auto& tr : set.transfers) {
    w.resize(tr.gyro_raw.size());
    for (std::size_t i = 0; i < w.size(); ++i) {
      w[i] = model.correct_gyro(tr.gyro_raw[i], model.correct_accel(tr.accel_raw[i]));
    }
    // q rotates body vectors at the end of the motion into the body frame at its start, so a
    // direction fixed in the world, u0 at the start, is seen as R^T u0 at the end (as eq. 3.8).
    const Eigen::Matrix3d R = calib::quat_to_matrix(calib::integrate_rk4n(w, tr.t_s));
    const Eigen::Vector3d u_pred = R.transpose() * u_end[tr.from];
    const Eigen::Vector3d& u1 = u_start[tr.from + 1];
    const double angle = std::atan2(u_pred.cross(u1).norm(), u_pred.dot(u1));
    direction.add(angle);
    out.direction_per_transfer_rad.push_back(angle);
  }
  out.gravity_magnitude_mps2 = magnitude.figures();
  out.gravity_direction_rad = direction.figures();
  return out;
}

// ---- reading calibrations ---------------------------------------------------------------------

std::vector<NamedCalibration> gyro_with_first_accelerometer(
    const std::vector<NamedCalibration>& calibrations) {
  std::vector<NamedCalibration> out;
  for (std::size_t i = 1; i < calibrations.size(); ++i) {
    NamedCalibration c = calibrations[i];
    c.name = "[gyro] " + calibrations[i].name;
    c.model.A_a = calibrations[0].model.A_a;
    c.model.b_a = calibrations[0].model.b_a;
    c.accelerometer_of = calibrations[0].name;
    out.push_back(std::move(c));
  }
  return out;
}

Result<NamedCalibration> parse_imucal_calibration(const std::string& yaml_text, const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, origin + ": not valid YAML (" + e.msg + ", line " +
                                          std::to_string(e.mark.line + 1) + ")");
  }
  if (!root.IsMap() || !root["canonical"] || !root["canonical"].IsMap()) {
    return make_error(Errc::kCorrupt,
                      origin +
                          ": no 'canonical:' section with A_a, b_a, A_g, b_g, G (expected the "
                          "result YAML of imucal calibrate static -o)");
  }
  const YAML::Node c = root["canonical"];
  NamedCalibration out;
  out.name = file_name(origin);
  out.format = "imucal";
  out.path = origin;
  auto A_a = yaml_matrix(c, "A_a", origin);
  if (!A_a.ok()) return A_a.error();
  auto b_a = yaml_vector(c, "b_a", origin);
  if (!b_a.ok()) return b_a.error();
  auto A_g = yaml_matrix(c, "A_g", origin);
  if (!A_g.ok()) return A_g.error();
  auto b_g = yaml_vector(c, "b_g", origin);
  if (!b_g.ok()) return b_g.error();
  auto G = yaml_matrix(c, "G", origin);
  if (!G.ok()) return G.error();
  out.model.A_a = *A_a;
  out.model.b_a = *b_a;
  out.model.A_g = *A_g;
  out.model.b_g = *b_g;
  out.model.G = *G;
  out.spread = read_spread(root);
  if (const YAML::Node units = root["input_units"]) {
    const std::string s = units.IsScalar() ? units.Scalar() : std::string();
    if (s == imu_units_name(ImuUnits::kSi)) {
      out.input_units = ImuUnits::kSi;
    } else if (s == imu_units_name(ImuUnits::kRaw)) {
      out.input_units = ImuUnits::kRaw;
    } else {
      return make_error(Errc::kCorrupt, origin + ": input_units is '" + s + "', expected si or raw");
    }
  }
  return out;
}

Result<NamedCalibration> read_imucal_calibration(const std::string& path) {
  auto text = read_text_file(path);
  if (!text.ok()) return text.error();
  return parse_imucal_calibration(*text, path);
}

Result<ImuTkTriad> parse_imu_tk_triad(const std::string& text, const std::string& origin) {
  std::istringstream in(text);
  std::vector<double> v;
  std::string token;
  while (in >> token) {
    const std::optional<double> x = parse_finite_number(token);
    if (!x) {
      return make_error(Errc::kCorrupt,
                        origin + ": '" + token + "' (value " + std::to_string(v.size() + 1) +
                            ") is not a finite number; an imu_tk calib file holds 21 numbers: "
                            "the 3x3 misalignment T, the 3x3 scale K and the bias B");
    }
    v.push_back(*x);
  }
  if (v.size() != 21) {
    return make_error(Errc::kCorrupt, origin + ": " + std::to_string(v.size()) +
                                          " numbers found, 21 expected (imu_tk calib file: the 3x3 "
                                          "misalignment T, the 3x3 scale K, the 3-vector bias B)");
  }
  const Eigen::Matrix3d T = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
  const Eigen::Matrix3d K = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data() + 9);
  ImuTkTriad out;
  out.A = T * K;
  out.b = Eigen::Vector3d(v[18], v[19], v[20]);
  if (!(std::abs(out.A.determinant()) > 0.0)) {
    return make_error(Errc::kCorrupt,
                      origin + ": T K is singular (a zero scale or a degenerate misalignment)");
  }
  return out;
}

Result<NamedCalibration> read_imu_tk_calibration(const std::string& accel_path,
                                                 const std::string& gyro_path) {
  auto acc_text = read_text_file(accel_path);
  if (!acc_text.ok()) return acc_text.error();
  auto gyro_text = read_text_file(gyro_path);
  if (!gyro_text.ok()) return gyro_text.error();
  auto acc = parse_imu_tk_triad(*acc_text, accel_path);
  if (!acc.ok()) return acc.error();
  auto gyro = parse_imu_tk_triad(*gyro_text, gyro_path);
  if (!gyro.ok()) return gyro.error();
  NamedCalibration out;
  out.name = file_name(accel_path) + " + " + file_name(gyro_path);
  out.format = "imu_tk";
  out.path = accel_path + "," + gyro_path;
  out.model.A_a = acc->A;
  out.model.b_a = acc->b;
  out.model.A_g = gyro->A;
  out.model.b_g = gyro->b;
  out.model.G.setZero();
  return out;
}

// ---- report --------------------------------------------------------------------------------

RmsDifference paired_rms_difference(std::span<const double> a, std::span<const double> b) {
  RmsDifference r;
  const std::size_t n = std::min(a.size(), b.size());
  r.count = static_cast<int>(n);
  if (n == 0) {
    r.sigma = std::numeric_limits<double>::quiet_NaN();
    return r;
  }
  double sum_a = 0.0, sum_b = 0.0;
  std::vector<double> d(n);
  for (std::size_t i = 0; i < n; ++i) {
    sum_a += a[i] * a[i];
    sum_b += b[i] * b[i];
    d[i] = b[i] * b[i] - a[i] * a[i];
  }
  const double rms_a = std::sqrt(sum_a / static_cast<double>(n));
  const double rms_b = std::sqrt(sum_b / static_cast<double>(n));
  r.reference = rms_a;
  r.difference = rms_b - rms_a;
  if (n < 2) {
    r.sigma = std::numeric_limits<double>::quiet_NaN();
    return r;
  }
  const double mean_d = (sum_b - sum_a) / static_cast<double>(n);
  double ss = 0.0;
  for (const double x : d) ss += (x - mean_d) * (x - mean_d);
  const double se_mean_d = std::sqrt(ss / static_cast<double>(n - 1)) / std::sqrt(static_cast<double>(n));
  r.sigma = rms_a + rms_b > 0.0 ? se_mean_d / (rms_a + rms_b) : 0.0;
  return r;
}

CheckComparison compare_checks(const CheckFiguresPair& a, const CheckFiguresPair& b) {
  return {paired_rms_difference(a.magnitude_per_interval_mps2, b.magnitude_per_interval_mps2),
          paired_rms_difference(a.direction_per_transfer_rad, b.direction_per_transfer_rad)};
}

std::string calibration_check_json(const std::string& log_path, const ImuStreamInfo& info,
                                   const CheckSet& set, double gravity, const std::string& gravity_source,
                                   const std::vector<NamedCalibration>& calibrations,
                                   const std::vector<CheckFiguresPair>& figures) {
  using nlohmann::json;
  auto rel_s = [&set](TimeNs t) { return ns_to_s(t - set.t_first_ns); };
  auto fig = [](const CheckFigures& f) {
    return json{{"count", f.count}, {"mean", f.mean}, {"rms", f.rms}, {"max", f.max}};
  };
  json j;
  j["log"] = log_path;
  j["stream"] = info.name;
  j["input_units"] = imu_units_name(info.units);
  j["gravity"] = gravity;
  j["gravity_source"] = gravity_source;
  json s;
  s["rule"] = {{"window_s", set.options.window_s},
               {"multiplier", set.options.multiplier},
               {"min_interval_s", set.options.min_interval_s},
               {"floor_percentile", set.options.floor_percentile}};
  s["samples"] = set.samples;
  s["rate_hz"] = set.rate_hz;
  s["floor_varsigma_sq"] = set.floor_sq;
  s["threshold_varsigma"] = set.threshold;
  s["gaps"] = set.gaps;
  s["accel_saturated"] = set.accel_saturated;
  s["gyro_saturated"] = set.gyro_saturated;
  s["motions"] = set.motions;
  s["motions_with_gap"] = set.motions_with_gap;
  s["motions_with_saturation"] = set.motions_with_saturation;
  json intervals = json::array();
  for (const auto& iv : set.intervals) {
    intervals.push_back(
        {{"t0_s", rel_s(iv.t0_ns)},
         {"t1_s", rel_s(iv.t1_ns)},
         {"t0_ns", iv.t0_ns},
         {"t1_ns", iv.t1_ns},
         {"samples", iv.size()},
         {"accel_mean_raw", {iv.accel_mean_raw[0], iv.accel_mean_raw[1], iv.accel_mean_raw[2]}}});
  }
  s["static_intervals"] = intervals;
  json transfers = json::array();
  for (const auto& tr : set.transfers) {
    transfers.push_back({{"from", tr.from},
                         {"to", tr.from + 1},
                         {"t0_s", rel_s(set.intervals[tr.from].t1_ns)},
                         {"t1_s", rel_s(set.intervals[tr.from + 1].t0_ns)},
                         {"samples", tr.t_s.size()}});
  }
  s["transfers"] = transfers;
  j["check_set"] = s;
  json cals = json::array();
  for (std::size_t i = 0; i < calibrations.size() && i < figures.size(); ++i) {
    const auto& c = calibrations[i];
    cals.push_back({{"name", c.name},
                    {"format", c.format},
                    {"path", c.path},
                    {"gravity_magnitude_mps2", fig(figures[i].gravity_magnitude_mps2)},
                    {"gravity_direction_rad", fig(figures[i].gravity_direction_rad)},
                    {"magnitude_per_interval_mps2", figures[i].magnitude_per_interval_mps2},
                    {"direction_per_transfer_rad", figures[i].direction_per_transfer_rad}});
    if (!c.accelerometer_of.empty()) cals.back()["accelerometer_of"] = c.accelerometer_of;
    if (i > 0) {
      // Against the first calibration, paired over the same intervals and transfers.
      const CheckComparison c = compare_checks(figures[0], figures[i]);
      const auto diff = [](const RmsDifference& r) {
        return json{{"count", r.count}, {"rms_difference", r.difference}, {"sigma", r.sigma}};
      };
      cals.back()["against_first"] = {{"gravity_magnitude_mps2", diff(c.gravity_magnitude_mps2)},
                                      {"gravity_direction_rad", diff(c.gravity_direction_rad)}};
    }
  }
  j["calibrations"] = cals;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

}  // namespace imucal::app
