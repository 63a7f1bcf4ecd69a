// SPDX-License-Identifier: BSD-3-Clause
// The camera-IMU self-check (app/camimu_self_check.hpp).

#include "app/camimu_self_check.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <string>

#include "core/threads.hpp"

namespace imucal::app {
namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

/// The small-angle vector of R_part R_ref^-1 (about the reference's output axes), rad.
Eigen::Vector3d rotation_difference(const Eigen::Matrix3d& part, const Eigen::Matrix3d& ref) {
  const Eigen::AngleAxisd aa(part * ref.transpose());
  return aa.angle() * aa.axis();
}

/// The compared parameters of one part's result.
std::vector<SplitCheckRow> rows_of(const CamImuCalibrationResult& r, const CamImuCalibrationResult& full) {
  std::vector<SplitCheckRow> rows;
  const char* xyz[] = {"x", "y", "z"};
  for (std::size_t c = 0; c < r.cameras.size() && c < full.cameras.size(); ++c) {
    const CamImuCameraResult& cr = r.cameras[c];
    const Eigen::Vector3d d = rotation_difference(cr.T_cam_imu.linear(), full.cameras[c].T_cam_imu.linear());
    for (int a = 0; a < 3; ++a)
      rows.push_back({cr.name + " rotation about " + xyz[a], "deg", d(a) * kRadToDeg,
                      cr.rotation_sigma_rad(a) * kRadToDeg});
    for (int a = 0; a < 3; ++a)
      rows.push_back({cr.name + " translation " + std::string(xyz[a]), "mm",
                      cr.T_cam_imu.translation()(a) * 1e3, cr.translation_sigma_m(a) * 1e3});
    rows.push_back(
        {cr.name + " time offset", "ms", cr.timeshift_cam_imu_s * 1e3, cr.timeshift_sigma_s * 1e3});
    if (cr.camera.shutter.kind == Shutter::Kind::kRolling && std::isfinite(cr.line_delay_sigma_s))
      rows.push_back(
          {cr.name + " line delay", "us", cr.camera.shutter.line_delay_s * 1e6, cr.line_delay_sigma_s * 1e6});
  }
  if (r.model == CamImuModelKind::kExtended) {
    // Intrinsics the prior mostly set are the prior in every part: no check of the data.
    const auto dominated = [&](const std::string& name) {
      return std::find(full.prior_dominated.begin(), full.prior_dominated.end(), name) !=
             full.prior_dominated.end();
    };
    const KrebsImuModel& m = r.imu;
    const KrebsImuSigma& s = r.imu_sigma;
    const auto add3 = [&](const std::string& name, const Eigen::Vector3d& v, const Eigen::Vector3d& sig,
                          double k, const char* unit) {
      for (int a = 0; a < 3; ++a)
        if (!dominated(name + " " + xyz[a]))
          rows.push_back({name + " " + xyz[a], unit, v(a) * k, sig(a) * k});
    };
    add3("S_a", m.S_a, s.S_a, 1e3, "1e-3");
    add3("M_a", m.M_a, s.M_a, 1e3, "mrad");
    add3("S_g", m.S_g, s.S_g, 1e3, "1e-3");
    add3("M_g", m.M_g, s.M_g, 1e3, "mrad");
    add3("C_bg", rotation_difference(m.C_bg, full.imu.C_bg), s.C_bg, 1e3, "mrad");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (!dominated("B_g " + std::string(xyz[i]) + xyz[j]))
          rows.push_back({"B_g " + std::string(xyz[i]) + xyz[j], "1e-4 rad/s per m/s^2", m.B_g(i, j) * 1e4,
                          s.B_g(i, j) * 1e4});
  }
  return rows;
}

}  // namespace

SplitCheck camimu_self_check(const std::vector<calib::CamImuSample>& imu,
                             const std::vector<calib::CamImuCameraInput>& cameras,
                             const TargetDescription& target, const calib::CamImuOptions& options,
                             const CamImuCalibrationResult& full, int parts, int threads) {
  SplitCheck check;
  check.parts = std::clamp(parts, 2, 8);
  const auto start = std::chrono::steady_clock::now();
  TimeNs first = 0, last = 0;
  bool any = false;
  for (const auto& cam : cameras)
    for (const auto& o : cam.observations) {
      first = any ? std::min(first, o.t_ns) : o.t_ns;
      last = any ? std::max(last, o.t_ns) : o.t_ns;
      any = true;
    }
  // The full solve's choices, so that the parts differ only by their data.
  calib::CamImuOptions opt = options;
  opt.model = full.model;
  opt.knot_spacing_s = full.quality.knot_spacing_s;
  bool rolling = false, global = false;
  for (const auto& c : full.cameras)
    (c.camera.shutter.kind == Shutter::Kind::kRolling ? rolling : global) = true;
  if (!opt.shutter.line_delay_s)
    opt.shutter.mode = rolling && !global   ? calib::ShutterSolveOptions::Mode::kRolling
                       : global && !rolling ? calib::ShutterSolveOptions::Mode::kGlobal
                                            : opt.shutter.mode;
  opt.covariance = true;
  // Each part starts where the whole ended: the extrinsics and time offsets (not the IMU model,
  // whose starting value is also the intrinsics' prior). The parts' own solution does not
  // depend on it; their solve takes fewer iterations and skips the cross-correlation.
  opt.T_cam_imu_init.clear();
  opt.timeshift_init_s.clear();
  for (const auto& c : full.cameras) {
    opt.T_cam_imu_init.emplace_back(c.T_cam_imu);
    opt.timeshift_init_s.emplace_back(c.timeshift_cam_imu_s);
  }
  // The parts share the held intrinsics, so their error does not separate them: compared
  // without it (the full result's sigmas carry it).
  opt.propagate_intrinsics = false;
  const int workers = threads_or_cores(threads);
  opt.threads = std::max(1, workers / check.parts);

  const auto spans = split_spans(first, last, check.parts, &check.spans_s);
  std::vector<std::vector<calib::CamImuCameraInput>> part_cameras(spans.size());
  std::vector<std::vector<calib::CamImuSample>> part_imu(spans.size());
  // The IMU covers each part's frames with a margin for the time offset and the spline's ends.
  const auto margin = static_cast<TimeNs>((options.max_timeshift_s + 0.5) * 1e9);
  for (std::size_t p = 0; p < spans.size(); ++p) {
    const auto [from, to] = spans[p];
    for (const auto& cam : cameras) {
      calib::CamImuCameraInput in = cam;
      in.observations.clear();
      for (const auto& o : cam.observations)
        if (o.t_ns >= from && o.t_ns < to) in.observations.push_back(o);
      part_cameras[p].push_back(std::move(in));
    }
    for (const auto& s : imu)
      if (s.t_ns >= from - margin && s.t_ns < to + margin) part_imu[p].push_back(s);
  }
  std::vector<std::optional<std::vector<SplitCheckRow>>> rows(spans.size());
  check.part_errors.assign(spans.size(), "");
  run_side_by_side(check.parts, workers, [&](int p) {
    const auto i = static_cast<std::size_t>(p);
    auto r = calib::calibrate_camimu(part_imu[i], part_cameras[i], target, opt);
    if (r.ok())
      rows[i] = rows_of(*r, full);
    else
      check.part_errors[i] = r.error().message;
  });
  fill_split_parameters(&check, rows);
  judge_split_check(&check);
  check.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return check;
}

}  // namespace imucal::app
