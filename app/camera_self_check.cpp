// SPDX-License-Identifier: BSD-3-Clause
// The camera calibration's self-check (app/camera_self_check.hpp).

#include "app/camera_self_check.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include "core/threads.hpp"

namespace imucal::app {
namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
constexpr const char* kCameraSuspects =
    "the lens model (one that fits the whole image: a wide lens needs pinhole-equi, beyond 180 degrees "
    "ds-none or "
    "eucm-none; --model auto chooses by the evidence), the target's size and "
    "flatness, views that cover the whole image in every part";

void intrinsic_rows(const std::string& cam, const calib::CameraIntrinsicsResult& r, double line_delay_sigma_s,
                    std::vector<SplitCheckRow>* rows) {
  const char* focal[] = {"fu", "fv", "pu", "pv"};
  const auto projection = projection_param_names(r.camera.projection);
  const auto coeff = distortion_coeff_names(r.camera.distortion_model);
  for (int i = 0; i < 4; ++i)
    rows->push_back({cam + " " + focal[i], "px", r.camera.intrinsics(i), r.intrinsics_sigma(i)});
  for (std::size_t i = 0; i < projection.size(); ++i) {
    const auto e = static_cast<Eigen::Index>(i);
    rows->push_back({cam + " " + projection[i], "", r.camera.projection_params(e), r.projection_sigma(e)});
  }
  for (std::size_t i = 0; i < coeff.size(); ++i) {
    const auto e = static_cast<Eigen::Index>(i);
    rows->push_back({cam + " " + coeff[i], "", r.camera.distortion_coeffs(e), r.distortion_sigma(e)});
  }
  if (r.camera.shutter.rolling() && std::isfinite(line_delay_sigma_s))
    rows->push_back(
        {cam + " line delay", "us", r.camera.shutter.line_delay_s * 1e6, line_delay_sigma_s * 1e6});
}

/// The chain's parameters of one part; rotations as the small-angle difference to the whole's.
std::vector<SplitCheckRow> chain_rows(const calib::CameraChainResult& r,
                                      const calib::CameraChainResult& full) {
  std::vector<SplitCheckRow> rows;
  const char* xyz[] = {"x", "y", "z"};
  for (std::size_t c = 0; c < r.cameras.size() && c < full.cameras.size(); ++c) {
    const auto& cr = r.cameras[c];
    const std::string cam = "cam" + std::to_string(c);
    intrinsic_rows(cam, cr.intrinsics, cr.line_delay_sigma_s, &rows);
    if (c == 0) continue;
    const Eigen::AngleAxisd d(cr.T_cn_cnm1.linear() * full.cameras[c].T_cn_cnm1.linear().transpose());
    const Eigen::Vector3d dv = d.angle() * d.axis();
    for (int a = 0; a < 3; ++a)
      rows.push_back({cam + " rotation to cam" + std::to_string(c - 1) + " about " + xyz[a], "deg",
                      dv(a) * kRadToDeg, cr.T_cn_cnm1_rotation_sigma_rad(a) * kRadToDeg});
    for (int a = 0; a < 3; ++a)
      rows.push_back({cam + " translation to cam" + std::to_string(c - 1) + " " + xyz[a], "mm",
                      cr.T_cn_cnm1.translation()(a) * 1e3, cr.T_cn_cnm1_translation_sigma_m(a) * 1e3});
    if (cr.timeshift_estimated)
      rows.push_back({cam + " time offset", "ms", cr.timeshift_cam0_s * 1e3, cr.timeshift_sigma_s * 1e3});
  }
  return rows;
}

std::pair<TimeNs, TimeNs> time_range(const std::vector<calib::TargetObservation>& views) {
  TimeNs first = views.empty() ? 0 : views.front().t_ns, last = first;
  for (const auto& v : views) {
    first = std::min(first, v.t_ns);
    last = std::max(last, v.t_ns);
  }
  return {first, last};
}

std::vector<calib::TargetObservation> views_in(const std::vector<calib::TargetObservation>& views,
                                               std::pair<TimeNs, TimeNs> span) {
  std::vector<calib::TargetObservation> out;
  for (const auto& v : views)
    if (v.t_ns >= span.first && v.t_ns < span.second) out.push_back(v);
  return out;
}

}  // namespace

double split_scale(SplitCheck* check, const std::string& prefix, const std::string& who,
                   std::vector<std::string>* notes) {
  if (check->verdict != SplitCheck::Verdict::kAgree && check->verdict != SplitCheck::Verdict::kDisagree)
    return 1.0;
  int dof = 0;
  const double chi = split_chi_square(*check, prefix, &dof);
  if (dof == 0 || !(chi_square_probability(chi, dof) < 0.05)) return 1.0;
  const double k = std::sqrt(chi / dof);
  check->scaled.emplace_back(who, k);
  char text[300];
  std::snprintf(
      text, sizeof text,
      "%s's sigmas are scaled by %.2f: the parts of the recording spread that much more than their own "
      "sigmas allow (chi-square %.1f for %d degrees of freedom)",
      who.c_str(), k, chi, dof);
  notes->emplace_back(text);
  return k;
}

SplitCheck camera_self_check(const TargetDescription& target,
                             const std::vector<calib::TargetObservation>& views,
                             const calib::CameraIntrinsicsOptions& options,
                             const calib::CameraIntrinsicsResult& full, const std::string& name, int parts,
                             int threads) {
  SplitCheck check;
  check.parts = std::clamp(parts, 2, 8);
  const auto start = std::chrono::steady_clock::now();
  const auto [first, last] = time_range(views);
  const auto spans = split_spans(first, last, check.parts, &check.spans_s);
  const int workers = threads_or_cores(threads);
  std::vector<std::optional<std::vector<SplitCheckRow>>> rows(spans.size());
  check.part_errors.assign(spans.size(), "");
  run_side_by_side(check.parts, workers, [&](int p) {
    const auto i = static_cast<std::size_t>(p);
    const auto part = views_in(views, spans[i]);
    if (full.camera.shutter.rolling()) {
      // As the whole was solved: on the trajectory, the line delay free.
      calib::CameraChainOptions o;
      o.intrinsics = options;
      o.threads = std::max(1, workers / check.parts);
      o.shutter.mode = calib::ShutterSolveOptions::Mode::kRolling;
      calib::CameraChainInput in{name, options.model, part, full.camera.shutter};
      auto r = calib::calibrate_camera_chain(target, std::span(&in, 1), o, {});
      if (!r.ok()) {
        check.part_errors[i] = r.error().message;
        return;
      }
      rows[i].emplace();
      intrinsic_rows(name, r->cameras.front().intrinsics, r->cameras.front().line_delay_sigma_s, &*rows[i]);
      return;
    }
    auto r = calib::calibrate_camera_intrinsics(target, part, options, {});
    if (!r.ok()) {
      check.part_errors[i] = r.error().message;
      return;
    }
    rows[i].emplace();
    intrinsic_rows(name, *r, std::nan(""), &*rows[i]);
  });
  fill_split_parameters(&check, rows);
  check.suspects = kCameraSuspects;
  judge_split_check(&check);
  check.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return check;
}

SplitCheck chain_self_check(const TargetDescription& target,
                            const std::vector<calib::CameraChainInput>& cameras,
                            const calib::CameraChainOptions& options, const calib::CameraChainResult& full,
                            int parts, int threads) {
  SplitCheck check;
  check.parts = std::clamp(parts, 2, 8);
  const auto start = std::chrono::steady_clock::now();
  const auto [first, last] = time_range(cameras.front().observations);
  const auto spans = split_spans(first, last, check.parts, &check.spans_s);
  const int workers = threads_or_cores(threads);
  // The whole solve's shutters, so that the parts differ only by their data.
  calib::CameraChainOptions o = options;
  o.threads = std::max(1, workers / check.parts);
  bool rolling = false, global = false;
  for (const auto& c : full.cameras) (c.intrinsics.camera.shutter.rolling() ? rolling : global) = true;
  if (!o.shutter.line_delay_s && o.estimate_time_offsets)
    o.shutter.mode = rolling && !global   ? calib::ShutterSolveOptions::Mode::kRolling
                     : global && !rolling ? calib::ShutterSolveOptions::Mode::kGlobal
                                          : o.shutter.mode;
  std::vector<std::optional<std::vector<SplitCheckRow>>> rows(spans.size());
  check.part_errors.assign(spans.size(), "");
  run_side_by_side(check.parts, workers, [&](int p) {
    const auto i = static_cast<std::size_t>(p);
    std::vector<calib::CameraChainInput> part = cameras;
    for (std::size_t c = 0; c < part.size(); ++c) {
      part[c].observations = views_in(cameras[c].observations, spans[i]);
      part[c].shutter = full.cameras[c].intrinsics.camera.shutter;
    }
    auto r = calib::calibrate_camera_chain(target, part, o, {});
    if (r.ok())
      rows[i] = chain_rows(*r, full);
    else
      check.part_errors[i] = r.error().message;
  });
  fill_split_parameters(&check, rows);
  check.suspects = kCameraSuspects;
  judge_split_check(&check);
  check.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return check;
}

std::vector<std::string> scale_camera_by_self_check(calib::CameraIntrinsicsResult* camera,
                                                    double* line_delay_sigma_s, const std::string& name,
                                                    SplitCheck* check) {
  std::vector<std::string> notes;
  const double k = split_scale(check, name + " ", name, &notes);
  camera->intrinsics_sigma *= k;
  camera->projection_sigma *= k;
  camera->distortion_sigma *= k;
  camera->covariance *= k * k;
  *line_delay_sigma_s *= k;
  return notes;
}

std::vector<std::string> scale_chain_by_self_check(calib::CameraChainResult* chain, SplitCheck* check) {
  std::vector<std::string> notes;
  for (std::size_t c = 0; c < chain->cameras.size(); ++c) {
    auto& cr = chain->cameras[c];
    const std::string cam = "cam" + std::to_string(c);
    const double k = split_scale(check, cam + " ", cam, &notes);
    cr.intrinsics.intrinsics_sigma *= k;
    cr.intrinsics.projection_sigma *= k;
    cr.intrinsics.distortion_sigma *= k;
    cr.intrinsics.covariance *= k * k;
    cr.line_delay_sigma_s *= k;
    cr.timeshift_sigma_s *= k;
    cr.T_cam_cam0_covariance *= k * k;
    cr.T_cn_cnm1_covariance *= k * k;
    cr.T_cn_cnm1_rotation_sigma_rad *= k;
    cr.T_cn_cnm1_translation_sigma_m *= k;
    cr.baseline_sigma_m *= k;
  }
  return notes;
}

}  // namespace imucal::app
