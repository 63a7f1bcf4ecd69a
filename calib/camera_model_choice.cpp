// SPDX-License-Identifier: BSD-3-Clause
#include "calib/camera_model_choice.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "calib/camera_blocks.hpp"
#include "core/text_format.hpp"

namespace imucal::calib {
namespace {

/// A candidate must explain at least this share of the views the best one explains.
constexpr double kMinViewShare = 0.95;
/// A corner is left out of the comparison when even the model that fits it best leaves a
/// residual beyond this many robust sigmas (a bad detection, not a model's misfit).
constexpr double kOutlierSigmas = 5.0;

double median_of(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// The residual (px) of target point p seen at px under a solved camera and view pose; NaN where
/// the point is outside the model's domain.
Eigen::Vector2d residual_under(const CameraIntrinsicsResult& r, const CameraViewReport& v,
                               const Eigen::Vector3d& p, const Eigen::Vector2d& px) {
  const auto proj = r.camera.project(v.q_cam_target * p + v.t_cam_target);
  if (!proj.in_front) return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
  return proj.px - px;
}

/// The residuals of every candidate in `solved` on the views all of them use: [candidate][corner].
std::vector<std::vector<Eigen::Vector2d>> common_residuals(
    const TargetDescription& target, std::span<const TargetObservation> observations,
    const std::vector<const CameraIntrinsicsResult*>& solved, int* views) {
  const std::vector<Eigen::Vector3d> points = target.points();
  std::vector<std::vector<Eigen::Vector2d>> out(solved.size());
  *views = 0;
  std::size_t index = 0;  // into the results' views: one per non-empty observation
  for (const TargetObservation& o : observations) {
    if (o.empty()) continue;
    const std::size_t v = index++;
    const bool common = std::all_of(solved.begin(), solved.end(), [&](const CameraIntrinsicsResult* r) {
      return v < r->views.size() && r->views[v].used;
    });
    if (!common) continue;
    ++*views;
    for (std::size_t i = 0; i < o.ids.size(); ++i) {
      const Eigen::Vector3d& p = points[static_cast<std::size_t>(o.ids[i])];
      for (std::size_t m = 0; m < solved.size(); ++m)
        out[m].push_back(residual_under(*solved[m], solved[m]->views[v], p, o.px[i]));
    }
  }
  return out;
}

/// Which corners enter the comparison: finite under every candidate and not beyond
/// kOutlierSigmas robust sigmas under the candidate that fits them best.
std::vector<char> comparable_corners(const std::vector<std::vector<Eigen::Vector2d>>& res) {
  const std::size_t n = res.empty() ? 0 : res.front().size();
  std::vector<double> best(n, std::numeric_limits<double>::infinity());
  std::vector<char> keep(n, 1);
  for (std::size_t i = 0; i < n; ++i) {
    for (const auto& m : res) {
      if (!m[i].allFinite()) keep[i] = 0;
      best[i] = std::min(best[i], m[i].cwiseAbs().maxCoeff());
    }
  }
  std::vector<double> finite;
  for (std::size_t i = 0; i < n; ++i)
    if (keep[i]) finite.push_back(best[i]);
  const double limit = std::max(kOutlierSigmas * 1.4826 * median_of(finite), 0.5);
  for (std::size_t i = 0; i < n; ++i)
    if (!(best[i] <= limit)) keep[i] = 0;
  return keep;
}

std::string reason_for(const CameraModelChoice& c) {
  const CameraModelFit* chosen = nullptr;
  const CameraModelFit* next = nullptr;
  for (const auto& f : c.fits) {
    if (!f.compared) continue;
    if (f.model == c.chosen) {
      chosen = &f;
    } else if (!next || f.delta_bic < next->delta_bic) {
      next = &f;
    }
  }
  std::string out = camera_model_name(c.chosen) + ": ";
  if (next) {
    out += "BIC lower by " + format_number("%.1f", next->delta_bic) + " than " +
           camera_model_name(next->model) + ", the next best (RMS " +
           format_number("%.3f", std::sqrt(chosen->rss_px2 / c.common_corners)) + " vs " +
           format_number("%.3f", std::sqrt(next->rss_px2 / c.common_corners)) + " px";
  } else {
    out += "the only model compared (RMS " +
           format_number("%.3f", std::sqrt(chosen->rss_px2 / c.common_corners)) + " px";
  }
  out += " over " + std::to_string(c.common_corners) + " corners of " + std::to_string(c.common_views) +
         " views every compared model explains)";
  for (const auto& f : c.fits)
    if (!f.compared) out += "; " + camera_model_name(f.model) + " left out: " + f.why_not;
  return out;
}

}  // namespace

Result<ChosenCamera> choose_camera_model(const TargetDescription& target,
                                         std::span<const TargetObservation> observations,
                                         const CameraIntrinsicsOptions& options,
                                         const std::vector<CameraModelKind>& candidates) {
  if (candidates.empty()) return make_error(Errc::kInvalidArgument, "no camera model to choose from");
  std::vector<Result<CameraIntrinsicsResult>> results;
  CameraModelChoice choice;
  int most_views = 0;
  for (const CameraModelKind& model : candidates) {
    CameraIntrinsicsOptions o = options;
    o.model = model;
    results.push_back(calibrate_camera_intrinsics(target, observations, o, {}));
    CameraModelFit fit;
    fit.model = model;
    if (results.back().ok()) {
      fit.views_used = results.back()->views_used;
      fit.rms_px = results.back()->rms_px;
      most_views = std::max(most_views, fit.views_used);
    } else {
      fit.why_not = "no solution (" + results.back().error().message + ")";
    }
    choice.fits.push_back(fit);
  }
  if (most_views == 0) return results.front().error();
  std::vector<const CameraIntrinsicsResult*> solved;
  std::vector<std::size_t> which;
  for (std::size_t m = 0; m < candidates.size(); ++m) {
    CameraModelFit& fit = choice.fits[m];
    if (!results[m].ok()) continue;
    if (fit.views_used < kMinViewShare * most_views) {
      fit.why_not = "explains " + std::to_string(fit.views_used) + " of the " + std::to_string(most_views) +
                    " views another model explains";
      continue;
    }
    fit.compared = true;
    solved.push_back(&*results[m]);
    which.push_back(m);
  }
  const auto res = common_residuals(target, observations, solved, &choice.common_views);
  const std::vector<char> keep = comparable_corners(res);
  choice.common_corners = static_cast<int>(std::count(keep.begin(), keep.end(), 1));
  if (choice.common_corners == 0) {
    return make_error(Errc::kInsufficientData, "the camera models share no views to compare them on");
  }
  const double n = 2.0 * choice.common_corners;
  double best = std::numeric_limits<double>::infinity();
  std::size_t chosen = which.front();
  for (std::size_t j = 0; j < solved.size(); ++j) {
    CameraModelFit& fit = choice.fits[which[j]];
    fit.rss_px2 = 0.0;
    for (std::size_t i = 0; i < keep.size(); ++i)
      if (keep[i]) fit.rss_px2 += res[j][i].squaredNorm();
    fit.params = free_camera_params(fit.model) + 6 * choice.common_views;
    fit.bic = n * std::log(fit.rss_px2 / n) + fit.params * std::log(n);
    if (fit.bic < best) {
      best = fit.bic;
      chosen = which[j];
    }
  }
  for (auto& fit : choice.fits)
    if (fit.compared) fit.delta_bic = fit.bic - best;
  choice.chosen = candidates[chosen];
  choice.reason = reason_for(choice);
  return ChosenCamera{std::move(*results[chosen]), std::move(choice)};
}

}  // namespace imucal::calib
