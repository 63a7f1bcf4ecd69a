// SPDX-License-Identifier: BSD-3-Clause
#include "app/report/static_log.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>

#include "app/initial_guess.hpp"
#include "app/report/builders.hpp"
#include "app/streams.hpp"
#include "calib/quality.hpp"
#include "calib/rk4.hpp"
#include "core/imu_model.hpp"

namespace imucal::app::report {
namespace {

constexpr double kDeg = 180.0 / M_PI;

/// A triad of the result JSON (corrected = misalignment * diag(scale) * (raw - bias)) in
/// Tedaldi's form, which adds its bias.
TedaldiTriad triad_of(const nlohmann::json& j) {
  TedaldiTriad t;
  t.T = mat3(at(j, "misalignment"));
  t.scale = vec3(at(j, "scale"));
  t.bias = -vec3(at(j, "bias"));
  return t;
}

/// The result's static intervals as sample ranges of the stream.
Status locate_poses(const nlohmann::json& result, StaticLogData& d, const std::string& log_path) {
  const auto& s = d.samples;
  auto index_of = [&](TimeNs t) {
    return static_cast<std::size_t>(
        std::lower_bound(s.begin(), s.end(), t, [](const ImuSample& a, TimeNs v) { return a.t_ns < v; }) -
        s.begin());
  };
  for (const auto& iv : at(result, "static_intervals")) {
    const auto t0 = at(iv, "t0_ns").get<TimeNs>();
    const auto t1 = at(iv, "t1_ns").get<TimeNs>();
    StaticLogData::Pose p;
    p.begin = index_of(t0);
    p.end = index_of(t1);
    if (p.end >= s.size() || s[p.begin].t_ns != t0 || s[p.end].t_ns != t1 || p.end < p.begin) {
      return make_error(Errc::kCorrupt, "the result's static intervals are not samples of " + log_path +
                                            ": give the log the result was computed from");
    }
    for (std::size_t i = p.begin; i <= p.end; ++i) p.mean_raw += s[i].accel;
    p.mean_raw /= static_cast<double>(p.end - p.begin + 1);
    d.poses.push_back(p);
  }
  if (d.poses.size() < 2) return make_error(Errc::kCorrupt, "the result has fewer than two static intervals");
  return {};
}

/// The gravity direction at the first and at the last sample of a pose: every calibrated
/// accelerometer sample is carried there by RK4n integration of the corrected gyro before the
/// average, as the calibration does (docs/static-calibration.md, step 6), so that the slow start or
/// end of a move inside an interval biases neither direction.
struct PoseEnds {
  Eigen::Vector3d u_start, u_end;
};
/// The gyro model of a report: the triad and the g-sensitivity in input units, H = A_g^-1 G, so
/// that triad.apply(w_raw - H a) = A_g (w_raw - b_g) - G a (a calibrated, m/s^2).
struct GyroModel {
  TedaldiTriad triad;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
};

/// A raw gyro sample with its g-sensitivity removed, as the calibration integrates it.
Eigen::Vector3d gyro_raw(const ImuSample& s, const TedaldiTriad& accel, const GyroModel& gyro) {
  return s.gyro - gyro.H * accel.apply(s.accel);
}

PoseEnds carried_directions(const StaticLogData& d, const StaticLogData::Pose& p, const TedaldiTriad& accel,
                            const GyroModel& model) {
  const TedaldiTriad& gyro = model.triad;
  const auto& s = d.samples;
  calib::Quat4 q(1, 0, 0, 0);
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d sum = accel.apply(s[p.begin].accel);
  Eigen::Vector3d w_prev = gyro.apply(gyro_raw(s[p.begin], accel, model));
  for (std::size_t j = p.begin + 1; j <= p.end; ++j) {
    const Eigen::Vector3d w = gyro.apply(gyro_raw(s[j], accel, model));
    q = calib::rk4n_step(q, w_prev, w, ns_to_s(s[j].t_ns - s[j - 1].t_ns));
    w_prev = w;
    R = calib::quat_to_matrix(q);
    sum += R * accel.apply(s[j].accel);
  }
  return {sum.normalized(), (R.transpose() * sum).normalized()};
}

/// Per-pose | |a| - g | and per-motion gravity direction errors with one accelerometer and one
/// gyroscope model, through calib/quality.hpp one pose (motion) at a time; `carry` is the gyro
/// model that carries the directions inside the poses.
void pose_errors(StaticLogData& d, const TedaldiTriad& accel, const GyroModel& gyro, const GyroModel& carry,
                 double g, std::vector<double>& magnitude, std::vector<double>& direction) {
  std::vector<PoseEnds> u;
  for (const auto& p : d.poses) {
    magnitude.push_back(calib::gravity_magnitude_error(std::span(&p.mean_raw, 1), accel, g).mean_mps2);
    u.push_back(carried_directions(d, p, accel, carry));
  }
  std::vector<Eigen::Vector3d> w;
  std::vector<double> t;
  for (std::size_t k = 0; k + 1 < d.poses.size(); ++k) {
    w.clear();
    t.clear();
    const std::size_t a = d.poses[k].end, b = d.poses[k + 1].begin;
    for (std::size_t i = a; i <= b; ++i) {
      w.push_back(gyro_raw(d.samples[i], accel, gyro));
      t.push_back(ns_to_s(d.samples[i].t_ns - d.samples[a].t_ns));
    }
    const calib::GravityTransfer tr{u[k].u_end, u[k + 1].u_start, w, t};
    direction.push_back(calib::gravity_direction_error(std::span(&tr, 1), gyro.triad, g).mean_rad);
  }
}

}  // namespace

Result<StaticLogData> static_log_data(const nlohmann::json& result, const std::string& log_path) {
  auto loaded = load_imu_stream(log_path, at(result, "stream").get<std::string>(), DamagePolicy::kAllow);
  if (!loaded.ok()) return loaded.error();
  StaticLogData d;
  d.info = loaded->info;
  d.damage_warning = loaded->damage_warning();
  d.samples = std::move(loaded->samples);
  IMUCAL_TRY(locate_poses(result, d, log_path));
  const double g = number(result, "gravity");
  const TedaldiTriad accel = triad_of(at(result, "accel"));
  GyroModel gyro{triad_of(at(result, "gyro")), Eigen::Matrix3d::Zero()};
  gyro.H = gyro.triad.TK().inverse() * mat3(at(at(result, "gsens"), "G"));
  for (auto& p : d.poses) p.direction = accel.apply(p.mean_raw).normalized();
  pose_errors(d, accel, gyro, gyro, g, d.magnitude_after_mps2, d.direction_after_rad);
  // "Before" as the calibration defines it: the nominal conversions the log gives.
  auto nominal = nominal_guess(d.info, {});
  if (nominal.ok() && nominal->accel) {
    d.before_available = true;
    TedaldiTriad accel0;
    GyroModel gyro0;
    accel0.scale = nominal->accel->scale;
    accel0.bias = -nominal->accel->offset;
    gyro0.triad.scale = nominal->gyro.scale;
    gyro0.triad.bias = -nominal->gyro.offset;
    // The calibration carries the directions with the still start's mean as the bias (the first
    // static interval) and scores the nominal gyro without one.
    GyroModel carry0 = gyro0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    const auto& first = d.poses.front();
    for (std::size_t i = first.begin; i <= first.end; ++i) mean += d.samples[i].gyro;
    carry0.triad.bias = -mean / static_cast<double>(first.end - first.begin + 1);
    pose_errors(d, accel0, gyro0, carry0, g, d.magnitude_before_mps2, d.direction_before_rad);
  }
  return d;
}

namespace {

/// The signal as min/max pairs per bucket: the plot keeps every spike with a bounded size.
std::vector<std::vector<double>> envelope(const StaticLogData& d, bool gyro, std::size_t buckets) {
  const auto& s = d.samples;
  const std::size_t per = std::max<std::size_t>(1, (s.size() + buckets - 1) / buckets);
  auto value = [&](const ImuSample& x) {
    return gyro ? Eigen::Vector3d(d.info.gyro.to_si(x.gyro) * kDeg) : d.info.accel.to_si(x.accel);
  };
  auto time = [&](std::size_t i) { return ns_to_s(s[i].t_ns - s.front().t_ns); };
  std::vector<std::vector<double>> rows;
  for (std::size_t b = 0; b < s.size(); b += per) {
    const std::size_t e = std::min(s.size(), b + per);
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (std::size_t i = b; i < e; ++i) {
      lo = lo.cwiseMin(value(s[i]));
      hi = hi.cwiseMax(value(s[i]));
    }
    rows.push_back({time(b), lo[0], lo[1], lo[2]});
    if (e - b > 1) rows.push_back({time(e - 1), hi[0], hi[1], hi[2]});
  }
  return rows;
}

std::string axis_lines(const std::string& block, const std::string& style) {
  std::string out = "plot ";
  for (int a = 0; a < 3; ++a) {
    out += (a ? ", " : "") + std::string(a ? "''" : block) + " using 1:" + std::to_string(a + 2) + " with " +
           style + " lc rgb '" + kAxisColour[a] + "' title '" + "xyz"[a] + "'";
  }
  return out;
}

}  // namespace

Figure signal_figure(const StaticLogData& d, bool gyro) {
  Figure f;
  f.id = gyro ? "static-gyro-signal" : "static-accel-signal";
  f.title = gyro ? "Gyroscope signal and static intervals" : "Accelerometer signal and static intervals";
  f.caption = std::string(gyro ? "Angular rate (deg/s)" : "Specific force (m/s^2)") +
              " on the log's nominal conversion, per axis; the shaded spans are the " +
              std::to_string(d.poses.size()) +
              " static intervals the calibration used. Long recordings are "
              "drawn as the minimum and maximum of each of 1500 time slices.";
  std::string s = datablock("sig", envelope(d, gyro, 1500));
  const TimeNs t0 = d.samples.front().t_ns;
  int n = 1;
  for (const auto& p : d.poses) {
    s += "set object " + std::to_string(n++) + " rect from first " +
         num(ns_to_s(d.samples[p.begin].t_ns - t0), 10) + ", graph 0 to first " +
         num(ns_to_s(d.samples[p.end].t_ns - t0), 10) +
         ", graph 1 behind fillcolor rgb '#dcefd6' fillstyle solid 1.0 noborder\n";
  }
  s += "set xlabel 'time from the first sample (s)'\nset ylabel " +
       gp_quote(gyro ? "angular rate (deg/s)" : "specific force (m/s^2)") +
       "\nset key outside right top\nset grid\nset xrange [*:*] noextend\n" +
       axis_lines("$sig", "lines lw 1") +
       ", keyentry with boxes fillcolor rgb '#dcefd6' fillstyle solid 1.0 title 'static'\n";
  f.script = s;
  return f;
}

namespace {

Figure before_after(const std::string& id, const std::string& title, const std::vector<double>& before,
                    const std::vector<double>& after, double scale, const std::string& xlabel,
                    const std::string& ylabel) {
  Figure f;
  f.id = id;
  f.title = title;
  std::vector<std::vector<double>> rows;
  for (std::size_t i = 0; i < after.size(); ++i) {
    // Zero cannot be drawn on a log scale.
    auto pos = [&](double v) { return v * scale > 0 ? v * scale : std::numeric_limits<double>::quiet_NaN(); };
    rows.push_back(
        {static_cast<double>(i + 1), before.empty() ? std::nan("") : pos(before[i]), pos(after[i])});
  }
  f.script = datablock("e", rows) + "set logscale y\nset grid\nset key outside right top\nset xlabel " +
             gp_quote(xlabel) + "\nset ylabel " + gp_quote(ylabel) +
             "\nset xrange [0:" + std::to_string(after.size() + 1) + "]\nset format y '10^{%L}'\nplot ";
  if (!before.empty())
    f.script += "$e using 1:2 with linespoints pt 6 lc rgb '#999999' title 'before (nominal)', ";
  f.script += "$e using 1:3 with linespoints pt 7 lc rgb '#0072b2' title 'after calibration'\n";
  return f;
}

}  // namespace

Figure magnitude_figure(const StaticLogData& d) {
  Figure f =
      before_after("static-gravity-magnitude", "Gravity magnitude error per pose", d.magnitude_before_mps2,
                   d.magnitude_after_mps2, 1.0, "static pose", "| |a| - g |  (m/s^2)");
  f.caption =
      "The magnitude of the mean calibrated specific force of each static pose against local gravity "
      "(Tedaldi 2013, 4.1.1, metric 3), before (the log's nominal conversion) and after calibration. "
      "Recomputed from the log with the result's accelerometer model.";
  return f;
}

Figure direction_figure(const StaticLogData& d) {
  Figure f = before_after("static-gravity-direction", "Gyroscope gravity-direction error per motion",
                          d.direction_before_rad, d.direction_after_rad, kDeg,
                          "motion from pose k to pose k+1", "angle (deg)");
  f.caption =
      "The gravity direction of a pose, carried to the next pose by RK4n integration of the corrected "
      "gyroscope, against the direction measured there (Tedaldi 2013, 4.1.1, metric 4); directions are "
      "the pose means of the calibrated accelerometer. Before: nominal conversions, no bias removed.";
  return f;
}

Figure sphere_figure(const StaticLogData& d) {
  Figure f;
  f.id = "static-pose-directions";
  f.title = "Pose directions";
  f.caption =
      "The calibrated gravity direction (unit mean specific force) of each static pose on the unit "
      "sphere, numbered in recording order: poses spread over the sphere make every accelerometer "
      "parameter observable (Tedaldi 2013, 3.5).";
  f.width_px = 760;
  f.height_px = 640;
  std::vector<std::vector<double>> rows;
  for (std::size_t i = 0; i < d.poses.size(); ++i) {
    const auto& u = d.poses[i].direction;
    rows.push_back({u[0], u[1], u[2], static_cast<double>(i + 1)});
  }
  f.script = datablock("dirs", rows) +
             "set parametric\nset urange [0:2*pi]\nset vrange [-pi/2:pi/2]\nset isosamples 25,13\n"
             "set view 60,35,1.2\nset view equal xyz\nset xyplane relative 0\n"
             "set xlabel 'x'\nset ylabel 'y'\nset zlabel 'z'\nset xrange [-1.1:1.1]\nset yrange [-1.1:1.1]\n"
             "set zrange [-1.1:1.1]\nset xtics 1\nset ytics 1\nset ztics 1\nset key top right\n"
             "splot cos(u)*cos(v), sin(u)*cos(v), sin(v) with lines lc rgb '#dddddd' notitle, "
             "$dirs using 1:2:3 with points pt 7 ps 1.3 lc rgb '#d55e00' title 'static poses', "
             "$dirs using 1:2:3:(sprintf('%d', $4)) with labels offset 0.9,0.5 font ',8' notitle\n";
  return f;
}

}  // namespace imucal::app::report
