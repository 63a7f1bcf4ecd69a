// SPDX-License-Identifier: BSD-3-Clause
// The session's recording steps, sample by sample: warm-up, thermal recording, still start,
// static poses, six-face holds, checkerboard motion; and the review's gates.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

#include "app/rig/stored_calibration.hpp"
#include "app/session/review_lines.hpp"
#include "app/session/session_engine.hpp"
#include "app/session/session_window.hpp"
#include "core/text_format.hpp"

namespace imucal::app::session {

using nlohmann::json;
using session_msg::MessageLevel;
using K = session_msg::OperatorKey;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr TimeNs kLiveIntervalNs = 250'000'000;  // live figures 4 times a second of sample time

double seconds(TimeNs ns) { return static_cast<double>(ns) * 1e-9; }

/// The six faces of the six-face holds and the coverage display: the IMU axis that points up.
const Eigen::Vector3d kFaces[6] = {Eigen::Vector3d::UnitX(), -Eigen::Vector3d::UnitX(),
                                   Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitY(),
                                   Eigen::Vector3d::UnitZ(), -Eigen::Vector3d::UnitZ()};
const char* kFaceNames[6] = {"+X", "-X", "+Y", "-Y", "+Z", "-Z"};

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) / kDeg;
}

}  // namespace

ImuSample SessionEngine::to_si(const ImuSample& raw) const {
  if (info_.units == ImuUnits::kSi) return raw;
  ImuSample s = raw;
  s.accel = info_.accel.to_si(raw.accel);
  s.gyro = info_.gyro.to_si(raw.gyro);
  s.temperature = info_.temperature_scale * raw.temperature + info_.temperature_offset;
  return s;
}

bool SessionEngine::live_due() {
  if (now_ns_ - last_live_ns_ < kLiveIntervalNs) return false;
  last_live_ns_ = now_ns_;
  return true;
}

void SessionEngine::on_sample(const ImuSample& sample) {
  now_ns_ = sample.t_ns;
  if (!sampled_ && running()) {
    // The first prompt (the preflight's) was stamped before the session's first sample, with
    // whatever time the engine had: the wait counts from this sample, live and in replay.
    sampled_ = true;
    if (operator_since_ns_ >= 0) operator_since_ns_ = now_ns_;
  }
  if (operator_wait_over()) {
    end_operator_wait();
    return;
  }
  if (state_ != SessionState::kRunning || progress_.current >= progress_.steps.size()) return;
  const StepId id = progress_.steps[progress_.current].id;
  const ImuSample si = to_si(sample);
  window_->add(si.accel, si.gyro);
  if (recording_ && id >= StepId::kStill && id <= StepId::kMotion) samples_->push_back(sample);
  if (progress_.failed || id > StepId::kMotion) return;
  // Still: the accelerometer and gyro barely vary over the window, and once the gyro bias is
  // known the gyro mean (bias removed) is small: a slow steady turn varies little but is no pose.
  const double gyro_limit = config_.session.still_gyro_dps * kDeg;
  bool still = window_->full() && window_->accel_std() < config_.session.still_accel_mps2 &&
               window_->gyro_std() < 0.5 * gyro_limit;
  if (still && still_.bias_known) still = (window_->gyro_mean() - still_.gyro_bias).norm() < gyro_limit;
  switch (id) {
    case StepId::kWarmup:
      if (thermal_planned()) record_thermal(si, still);
      sample_warmup(si);
      break;
    case StepId::kThermal:
      record_thermal(si, still);
      sample_thermal(si);
      break;
    case StepId::kStill:
      sample_still(si, still);
      break;
    case StepId::kPoses:
      sample_poses(si, still);
      break;
    case StepId::kGsens:
      sample_gsens(si, still);
      break;
    case StepId::kMotion:
      sample_motion(si);
      break;
    default:
      break;
  }
}

void SessionEngine::on_frame(std::size_t camera, TimeNs t_ns, bool target_seen) {
  if (state_ != SessionState::kRunning || progress_.current >= progress_.steps.size() ||
      progress_.steps[progress_.current].id != StepId::kMotion)
    return;
  ++motion_.frames;
  if (target_seen) {
    ++motion_.frames_seen;
    motion_.last_seen_ns = t_ns;
  }
  if (camera >= motion_.camera_frames.size()) return;
  ++motion_.camera_frames[camera];
  if (!target_seen) return;
  ++motion_.camera_seen[camera];
  motion_.camera_last_seen_ns[camera] = t_ns;
  // An instant every camera saw the target: each one's last detection within half a frame
  // interval (of the slowest camera) of this one, counted once.
  if (motion_.camera_frames.size() < 2) return;
  double rate = 0.0;
  for (const CameraConfig& c : config_.cameras) rate = rate == 0.0 ? c.rate_hz : std::min(rate, c.rate_hz);
  const TimeNs half = rate > 0.0 ? static_cast<TimeNs>(0.5e9 / rate) : 25'000'000;
  if (motion_.last_shared_ns >= 0 && std::abs(t_ns - motion_.last_shared_ns) < half) return;
  for (TimeNs seen : motion_.camera_last_seen_ns)
    if (seen < 0 || std::abs(t_ns - seen) >= half) return;
  ++motion_.frames_shared;
  motion_.last_shared_ns = t_ns;
}

std::optional<SessionEngine::TemperatureTrend> SessionEngine::temperature_trend(
    const ImuSample& si, const std::string& no_temperature) {
  if (!std::isfinite(si.temperature)) {
    message(MessageLevel::kWarning, no_temperature);
    return std::nullopt;
  }
  if (warmup_.temps.empty() || si.t_ns - warmup_.last_temp_ns >= 500'000'000) {
    warmup_.temps.emplace_back(seconds(si.t_ns), si.temperature);
    warmup_.last_temp_ns = si.t_ns;
    // Keep the shortest tail that still spans the window.
    while (warmup_.temps.size() > 2 &&
           warmup_.temps.back().first - warmup_.temps[1].first >= config_.session.warmup_window_s)
      warmup_.temps.pop_front();
  }
  TemperatureTrend trend;
  // Rate: least-squares slope over the window, deg C per minute.
  if (warmup_.temps.size() >= 3) {
    double mt = 0, mc = 0;
    for (const auto& [t, c] : warmup_.temps) mt += t, mc += c;
    mt /= static_cast<double>(warmup_.temps.size());
    mc /= static_cast<double>(warmup_.temps.size());
    double num = 0, den = 0;
    for (const auto& [t, c] : warmup_.temps) num += (t - mt) * (c - mc), den += (t - mt) * (t - mt);
    trend.rate_c_per_min = den > 0 ? 60.0 * num / den : 0.0;
  }
  trend.window_s = warmup_.temps.back().first - warmup_.temps.front().first;
  trend.elapsed_s = seconds(si.t_ns - progress_.start_ns);
  // The window starts with the step (warmup_.temps is cleared there): a full one is as old as the step.
  trend.settled = trend.window_s >= config_.session.warmup_window_s &&
                  std::abs(trend.rate_c_per_min) < config_.session.warmup_rate_c_per_min;
  return trend;
}

void SessionEngine::sample_warmup(const ImuSample& si) {
  const auto trend = temperature_trend(si, "The IMU reports no temperature: warm-up skipped");
  if (!trend) {
    advance();
    return;
  }
  const double rate = trend->rate_c_per_min, elapsed = trend->elapsed_s;
  if (live_due()) {
    live({"Temperature " + fixed(si.temperature, 2) + " C, changing " + fixed(rate, 2) +
              " C/min (warm below " + fixed(config_.session.warmup_rate_c_per_min, 2) + ")",
          "Elapsed " + fixed(elapsed, 0) + " s of at most " + fixed(config_.session.warmup_timeout_s, 0) +
              " s"},
         std::min(1.0, trend->window_s / config_.session.warmup_window_s),
         session_msg::WarmupFigures{si.temperature, rate});
  }
  if (trend->settled) {
    message(MessageLevel::kInfo,
            "Warm: " + fixed(si.temperature, 2) + " C, changing " + fixed(rate, 2) + " C/min");
    advance();
  } else if (elapsed > config_.session.warmup_timeout_s) {
    fault("imu", "the temperature did not settle within " + fixed(config_.session.warmup_timeout_s, 0) +
                     " s (still " + fixed(rate, 2) + " C/min)");
  }
}

bool SessionEngine::thermal_planned() const {
  return std::any_of(progress_.steps.begin(), progress_.steps.end(),
                     [](const Step& s) { return s.id == StepId::kThermal; });
}

void SessionEngine::record_thermal(const ImuSample& si, bool still) {
  if (!still) {
    // The model needs one attitude throughout (gravity's projection is in the accelerometer's
    // bias): a recording the rig moved in starts again.
    if (!thermal_.means.empty())
      message(MessageLevel::kWarning,
              "Motion during the thermal recording: it starts again from here; keep the rig still");
    thermal_ = {};
    return;
  }
  if (!std::isfinite(si.temperature) || (si.flags & (kImuFlagAccelSaturated | kImuFlagGyroSaturated)) != 0)
    return;
  ThermalState::Mean& m = thermal_.sum;
  if (m.count > 0 && si.t_ns - m.first_ns >= 100'000'000) {
    const double n = static_cast<double>(m.count);
    ImuSample mean;
    mean.t_ns = m.first_ns + (m.last_ns - m.first_ns) / 2;
    mean.accel = m.accel / n;
    mean.gyro = m.gyro / n;
    mean.temperature = m.temperature / n;
    thermal_.means.push_back(mean);
    m = {};
  }
  if (m.count == 0) m.first_ns = si.t_ns;
  m.last_ns = si.t_ns;
  m.accel += si.accel;
  m.gyro += si.gyro;
  m.temperature += si.temperature;
  ++m.count;
}

namespace {

/// The lowest and highest temperature of the thermal recording's means ({0, 0} without any).
std::pair<double, double> temperature_range(const std::vector<ImuSample>& means) {
  if (means.empty()) return {0.0, 0.0};
  const auto [lo, hi] = std::minmax_element(
      means.begin(), means.end(),
      [](const ImuSample& a, const ImuSample& b) { return a.temperature < b.temperature; });
  return {lo->temperature, hi->temperature};
}

/// Least-squares slopes of gyro and accelerometer against temperature over the recording so
/// far (the live figure: the model is fitted with the final solve). NaN below 0.2 deg C of span.
std::pair<Eigen::Vector3d, Eigen::Vector3d> thermal_slopes(const std::vector<ImuSample>& means) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::pair<Eigen::Vector3d, Eigen::Vector3d> out{Eigen::Vector3d::Constant(nan),
                                                  Eigen::Vector3d::Constant(nan)};
  const auto [lo, hi] = temperature_range(means);
  if (means.size() < 10 || hi - lo < 0.2) return out;
  double mt = 0.0;
  Eigen::Vector3d mg = Eigen::Vector3d::Zero(), ma = Eigen::Vector3d::Zero();
  for (const auto& s : means) mt += s.temperature, mg += s.gyro, ma += s.accel;
  const double n = static_cast<double>(means.size());
  mt /= n, mg /= n, ma /= n;
  double den = 0.0;
  Eigen::Vector3d ng = Eigen::Vector3d::Zero(), na = Eigen::Vector3d::Zero();
  for (const auto& s : means) {
    const double dt = s.temperature - mt;
    den += dt * dt, ng += dt * (s.gyro - mg), na += dt * (s.accel - ma);
  }
  return {ng / den, na / den};
}

}  // namespace

void SessionEngine::sample_thermal(const ImuSample& si) {
  const auto trend = temperature_trend(si, "The IMU reports no temperature: no thermal model");
  if (!trend) {
    thermal_.means.clear();
    advance();
    return;
  }
  const double rate = trend->rate_c_per_min, elapsed = trend->elapsed_s;
  if (live_due()) {
    auto [lo, hi] = temperature_range(thermal_.means);
    if (thermal_.means.empty()) lo = hi = si.temperature;
    const auto [gyro_slope, accel_slope] = thermal_slopes(thermal_.means);
    live({"Temperature " + fixed(si.temperature, 2) + " C, changing " + fixed(rate, 2) +
              " C/min (the recording ends below " + fixed(config_.session.warmup_rate_c_per_min, 2) + ")",
          "Recorded " + fixed(lo, 2) + " .. " + fixed(hi, 2) + " C: a span of " + fixed(hi - lo, 2) +
              " C (at least " + fixed(config_.session.thermal_min_span_c, 1) + " C for a model)",
          "Gyro bias change so far: " + figures(gyro_slope, 1.0 / kDeg, 4) + " (deg/s)/C",
          "Accel change so far: " + figures(accel_slope, 1e3 / kStandardGravity, 3) + " mg/C",
          "Elapsed " + fixed(elapsed, 0) + " s of at most " + fixed(config_.session.thermal_timeout_s, 0) +
              " s; c ends the recording"},
         std::min(1.0, (hi - lo) / config_.session.thermal_min_span_c),
         session_msg::ThermalFigures{si.temperature, rate, {lo, hi}, gyro_slope / kDeg, accel_slope});
  }
  if (trend->settled) {
    end_thermal("the temperature settled at " + fixed(si.temperature, 2) + " C");
  } else if (elapsed > config_.session.thermal_timeout_s) {
    end_thermal("session.thermal_timeout_s (" + fixed(config_.session.thermal_timeout_s, 0) + " s) reached");
  }
}

void SessionEngine::end_thermal(const std::string& why) {
  const auto [lo, hi] = temperature_range(thermal_.means);
  const double minutes =
      thermal_.means.empty() ? 0.0 : seconds(thermal_.means.back().t_ns - thermal_.means.front().t_ns) / 60.0;
  if (hi - lo < config_.session.thermal_min_span_c) {
    message(MessageLevel::kWarning,
            "Thermal recording " + why + ": the die moved " + fixed(hi - lo, 2) +
                " C, less than session.thermal_min_span_c (" + fixed(config_.session.thermal_min_span_c, 1) +
                " C): no thermal model. Start from a cold rig, or warm it (a heater), for a model");
    thermal_.means.clear();
  } else {
    message(MessageLevel::kInfo, "Thermal recording " + why + ": " + fixed(lo, 2) + " .. " + fixed(hi, 2) +
                                     " C over " + fixed(minutes, 1) +
                                     " min; the model is fitted with the final solve");
  }
  advance();
}

void SessionEngine::sample_still(const ImuSample& si, bool still) {
  if (!still) {
    if (still_.since_ns >= 0 || samples_->size() > window_->size) {
      if (still_.since_ns >= 0)
        message(MessageLevel::kWarning, "Motion detected: keep the rig still; the countdown restarts");
      still_.since_ns = -1;
      samples_->clear();  // the still period the calibration uses must be still from its start
    }
    return;
  }
  if (still_.since_ns < 0) {
    still_.since_ns = si.t_ns;
    still_.gyro_sum.setZero();
    still_.count = 0;
  }
  still_.gyro_sum += si.gyro;
  ++still_.count;
  const double held = seconds(si.t_ns - still_.since_ns);
  if (live_due()) {
    live({"Still: " + fixed(held, 1) + " of " + fixed(config_.session.still_s, 0) + " s"},
         std::min(1.0, held / config_.session.still_s));
  }
  if (held >= config_.session.still_s) {
    still_.gyro_bias = still_.gyro_sum / static_cast<double>(still_.count);
    still_.bias_known = true;
    message(MessageLevel::kInfo,
            "Still start done: gyro bias " + fixed(still_.gyro_bias.norm() / kDeg, 3) + " deg/s");
    advance();
  }
}

void SessionEngine::poses_prompt() {
  std::string text = "Turn the rig to a new orientation and hold it still (" +
                     fixed(config_.session.hold_s, 1) + " s); " + std::to_string(config_.session.poses) +
                     " poses, all directions";
  for (int f = 0; f < 6; ++f) {
    const bool near = std::any_of(pose_.ups.begin(), pose_.ups.end(),
                                  [&](const Eigen::Vector3d& p) { return angle_deg(p, kFaces[f]) < 50.0; });
    if (!near) {
      text += ". Next: " + guide_.instruction(kFaces[f]);
      prompt(text, {K::kContinue, K::kRedo, K::kAbort}, guide_.drawing(kFaces[f]), &kFaces[f]);
      return;
    }
  }
  if (!pose_.ups.empty()) text += ". Every side has been up: now tilt between them";
  prompt(text, {K::kContinue, K::kRedo, K::kAbort});
}

void SessionEngine::face_prompt() {
  prompt("Six-face holds, " + std::to_string(pose_.face + 1) +
             " of 6: " + guide_.instruction(kFaces[pose_.face]) + ", and hold it still",
         {K::kRedo, K::kSkip, K::kAbort}, guide_.drawing(kFaces[pose_.face]), &kFaces[pose_.face]);
}

std::string SessionEngine::missing_words() const {
  std::string words;
  for (int f = 0; f < 6; ++f) {
    const bool near = std::any_of(pose_.ups.begin(), pose_.ups.end(),
                                  [&](const Eigen::Vector3d& p) { return angle_deg(p, kFaces[f]) < 50.0; });
    if (!near) words += (words.empty() ? "" : ", ") + guide_.up_name(kFaces[f]);
  }
  return words;
}

std::vector<std::string> SessionEngine::coverage() const {
  std::vector<std::string> missing;
  for (int f = 0; f < 6; ++f) {
    const bool near = std::any_of(pose_.ups.begin(), pose_.ups.end(),
                                  [&](const Eigen::Vector3d& p) { return angle_deg(p, kFaces[f]) < 50.0; });
    if (!near) missing.push_back(kFaceNames[f]);
  }
  return missing;
}

void SessionEngine::capture_pose() {
  const Eigen::Vector3d up = window_->accel_mean().normalized();
  for (std::size_t i = 0; i < pose_.ups.size(); ++i) {
    const double a = angle_deg(up, pose_.ups[i]);
    if (a < config_.session.pose_min_angle_deg) {
      message(MessageLevel::kWarning,
              "Too close to pose " + std::to_string(i + 1) + " (" + fixed(a, 0) +
                  " deg apart): turn at least " + fixed(config_.session.pose_min_angle_deg, 0) +
                  " deg further",
              session_msg::MessageCause::kPoseRefused);
      pose_.need_motion = true;
      return;
    }
  }
  pose_.ups.push_back(up);
  pose_.need_motion = true;
  emit(session_msg::PoseCaptured{std::nullopt, pose_.ups.size(), up});
  std::string text = "Pose " + std::to_string(pose_.ups.size()) + " captured";
  const std::string missing = missing_words();
  if (!missing.empty()) text += "; not yet up: " + missing;
  message(MessageLevel::kInfo, text);
  poses_prompt();  // the next direction to cover
  // The quick solve waits for the rig to move on: the static detector needs the end of the hold
  // (its variance window reaches past it) to count it as an attitude.
  pose_.quick_pending = true;
}

void SessionEngine::sample_poses(const ImuSample& si, bool still) {
  if (still) pose_.last_still_ns = si.t_ns;
  if (!still) {
    still_.since_ns = -1;
    pose_.need_motion = false;
    if (pose_.quick_pending && seconds(si.t_ns - pose_.last_still_ns) >= 0.5) {
      pose_.quick_pending = false;
      request_quick_solve();
    }
  } else if (!pose_.need_motion) {
    if (still_.since_ns < 0) still_.since_ns = si.t_ns;
    if (seconds(si.t_ns - still_.since_ns) >= config_.session.hold_s) capture_pose();
  }
  const int target = config_.session.poses;
  double scale_sigma = NAN;
  if (pose_.quick) {
    scale_sigma = std::max(
        pose_.quick->accel_sigma.scale.cwiseQuotient(pose_.quick->model.accel.scale.cwiseAbs()).maxCoeff(),
        pose_.quick->gyro_sigma.scale.cwiseQuotient(pose_.quick->model.gyro.scale.cwiseAbs()).maxCoeff());
  }
  if (live_due()) {
    const double held = still_.since_ns < 0 || pose_.need_motion ? 0.0 : seconds(si.t_ns - still_.since_ns);
    const std::string missing = missing_words();
    live({std::string(pose_.need_motion ? "Captured: turn to a new orientation"
                                        : (still ? "Still: " + fixed(held, 1) + " of " +
                                                       fixed(config_.session.hold_s, 1) + " s"
                                                 : "Moving")),
          "Poses: " + std::to_string(pose_.ups.size()) + " of " + std::to_string(target) +
              (missing.empty() ? "; every side has been up" : "; not yet up: " + missing),
          std::isnan(scale_sigma) ? std::string("Scale sigma: after 9 poses")
                                  : "Scale sigma: " + fixed(scale_sigma * 1e3, 2) + "e-3 (target " +
                                        fixed(config_.session.pose_sigma_target * 1e3, 2) + "e-3)"},
         std::min(1.0, static_cast<double>(pose_.ups.size()) / target),
         session_msg::PoseFigures{pose_.ups.size(), still, coverage(), scale_sigma,
                                  static_cast<std::size_t>(std::max(config_.session.poses_min, 0))});
  }
  // Done: enough poses and the last quick solve, over all of them, meets the sigma target.
  if (static_cast<int>(pose_.ups.size()) >= target && pose_.quick && pose_.quick_poses == pose_.ups.size() &&
      scale_sigma <= config_.session.pose_sigma_target) {
    message(MessageLevel::kInfo,
            std::to_string(pose_.ups.size()) + " poses, scale sigma " + fixed(scale_sigma * 1e3, 2) + "e-3");
    advance();
  }
}

void SessionEngine::sample_gsens(const ImuSample& si, bool still) {
  if (pose_.face >= 6) return;
  if (!still) {
    still_.since_ns = -1;
    pose_.need_motion = false;
    return;
  }
  if (pose_.need_motion) return;
  const Eigen::Vector3d up = window_->accel_mean().normalized();
  const double off = angle_deg(up, kFaces[pose_.face]);
  if (off > 15.0) {
    if (still_.since_ns < 0 || seconds(si.t_ns - still_.since_ns) > 1.0) {
      int nearest = 0;
      for (int f = 1; f < 6; ++f)
        if (angle_deg(up, kFaces[f]) < angle_deg(up, kFaces[nearest])) nearest = f;
      message(MessageLevel::kWarning,
              "This is " + guide_.up_name(kFaces[nearest]) + " (" + fixed(off, 0) + " deg off); " +
                  guide_.instruction(kFaces[pose_.face]),
              session_msg::MessageCause::kWrongFace);
      pose_.need_motion = true;
    }
    return;
  }
  if (still_.since_ns < 0) still_.since_ns = si.t_ns;
  const double held = seconds(si.t_ns - still_.since_ns);
  if (live_due())
    live({"Holding " + guide_.up_name(kFaces[pose_.face]) + ": " + fixed(held, 1) + " of " +
              fixed(config_.session.gsens_hold_s, 0) + " s",
          "Faces done: " + std::to_string(pose_.face) + " of 6"},
         (pose_.face + std::min(1.0, held / config_.session.gsens_hold_s)) / 6.0);
  if (held < config_.session.gsens_hold_s) return;
  emit(session_msg::FaceHeld{std::nullopt, kFaceNames[pose_.face], up});
  ++pose_.face;
  pose_.need_motion = true;
  still_.since_ns = -1;
  if (pose_.face >= 6) {
    message(MessageLevel::kInfo, "All six faces held");
    advance();
    return;
  }
  face_prompt();
}

void SessionEngine::sample_motion(const ImuSample& si) {
  const Eigen::Vector3d w = si.gyro - still_.gyro_bias;
  motion_.gyro_sq += w.cwiseProduct(w);
  motion_.accel_sum += si.accel;
  motion_.accel_sq += si.accel.cwiseProduct(si.accel);
  ++motion_.count;
  const double accel_fs = info_.accel_full_scale_g * kStandardGravity;
  const double gyro_fs = info_.gyro_full_scale_dps * kDeg;
  if ((accel_fs > 0 && si.accel.cwiseAbs().maxCoeff() > 0.98 * accel_fs) ||
      (gyro_fs > 0 && si.gyro.cwiseAbs().maxCoeff() > 0.98 * gyro_fs)) {
    if (motion_.saturated++ % 200 == 0)
      message(MessageLevel::kWarning, "Too fast: the IMU saturates; move more gently");
  }
  const double elapsed = seconds(si.t_ns - progress_.start_ns);
  if (live_due()) {
    const double n = static_cast<double>(motion_.count);
    const Eigen::Vector3d gyro_rms = (motion_.gyro_sq / n).cwiseSqrt();
    const Eigen::Vector3d accel_std =
        (motion_.accel_sq / n - (motion_.accel_sum / n).cwiseProduct(motion_.accel_sum / n))
            .cwiseMax(0)
            .cwiseSqrt();
    std::vector<std::string> lines = {
        "Rotation RMS deg/s  x " + fixed(gyro_rms.x() / kDeg, 0) + "  y " + fixed(gyro_rms.y() / kDeg, 0) +
            "  z " + fixed(gyro_rms.z() / kDeg, 0),
        "Acceleration std m/s^2  x " + fixed(accel_std.x(), 1) + "  y " + fixed(accel_std.y(), 1) + "  z " +
            fixed(accel_std.z(), 1),
        "Target seen in " + std::to_string(motion_.frames_seen) + " of " + std::to_string(motion_.frames) +
            " frames",
        "Time left " + fixed(std::max(0.0, config_.session.motion_s - elapsed), 0) + " s"};
    // Several cameras: each one's detection rate and the instants all of them saw the target
    // (what the camera chain is solved from).
    if (motion_.camera_frames.size() >= 2) {
      std::string rates = "Target seen:";
      long fewest = -1;
      for (std::size_t c = 0; c < motion_.camera_frames.size(); ++c) {
        const long n = motion_.camera_frames[c];
        rates +=
            " " + config_.cameras[c].name + " " +
            (n > 0 ? fixed(100.0 * static_cast<double>(motion_.camera_seen[c]) / static_cast<double>(n), 0) +
                         " %"
                   : std::string("no frame"));
        fewest = fewest < 0 ? n : std::min(fewest, n);
      }
      const double shared =
          fewest > 0 ? 100.0 * static_cast<double>(motion_.frames_shared) / static_cast<double>(fewest) : 0.0;
      rates += "; all cameras at once " + fixed(shared, 0) + " %";
      lines.insert(lines.begin() + 3, rates);
      if (elapsed > 10.0 && shared < 50.0) lines.push_back("Keep the target where every camera sees it");
    }
    for (int a = 0; a < 3; ++a) {
      if (elapsed > 10.0 && gyro_rms[a] < 20.0 * kDeg)
        lines.push_back(std::string("Rotate more about ") + "xyz"[a]);
    }
    if (motion_.frames > 0 && motion_.last_seen_ns >= 0 && si.t_ns - motion_.last_seen_ns > 1'000'000'000)
      lines.push_back("Target lost: bring it back into view");
    live(lines, std::min(1.0, elapsed / config_.session.motion_s),
         session_msg::MotionFigures{gyro_rms / kDeg,
                                    motion_.frames,
                                    motion_.frames_seen,
                                    {motion_.camera_frames.begin(), motion_.camera_frames.end()},
                                    {motion_.camera_seen.begin(), motion_.camera_seen.end()},
                                    motion_.frames_shared,
                                    {}});  // the coverage: the runner adds it (it has the corners)
  }
  if (elapsed >= config_.session.motion_s) advance();
}

void SessionEngine::evaluate_gates() {
  solve_.gates.clear();
  const auto& s = config_.session;
  if (solve_.final->imu) {
    const auto& r = *solve_.final->imu;
    const double scale_sigma =
        std::max(r.accel_sigma.scale.cwiseQuotient(r.model.accel.scale.cwiseAbs()).maxCoeff(),
                 r.gyro_sigma.scale.cwiseQuotient(r.model.gyro.scale.cwiseAbs()).maxCoeff());
    solve_.gates.push_back({"gravity residual RMS (m/s^2)", r.quality.accel_after.mean_mps2,
                            s.gate_gravity_rms_mps2,
                            r.quality.accel_after.mean_mps2 <= s.gate_gravity_rms_mps2, 4});
    // Shown in units of 1e-3 (the figures are a few 1e-4), judged on the figure itself.
    solve_.gates.push_back({"largest scale sigma (relative, e-3)", scale_sigma * 1e3,
                            s.gate_scale_sigma * 1e3,
                            std::isfinite(scale_sigma) && scale_sigma <= s.gate_scale_sigma, 2});
    solve_.gates.push_back(
        {"distinct attitudes", static_cast<double>(r.distinct_attitudes), 9.0, r.distinct_attitudes >= 9, 0});
  }
  if (solve_.final->camimu) {
    const auto& res = solve_.final->camimu->result;
    const auto fixed = [&](const char* name) {
      return std::find(res.fixed.begin(), res.fixed.end(), name) != res.fixed.end();
    };
    for (const auto& cam : res.cameras) {
      solve_.gates.push_back({cam.name + " reprojection RMS (px)", cam.reprojection_rms_px,
                              s.gate_reprojection_px, cam.reprojection_rms_px <= s.gate_reprojection_px, 3});
      // Every estimated extrinsic and time offset carries a sigma before it goes to storage.
      int missing = 0;
      if (!fixed("T_cam_imu"))
        missing += static_cast<int>((!cam.rotation_sigma_rad.array().isFinite()).count() +
                                    (!cam.translation_sigma_m.array().isFinite()).count());
      if (!fixed("timeshift")) missing += std::isfinite(cam.timeshift_sigma_s) ? 0 : 1;
      solve_.gates.push_back(
          {cam.name + " extrinsics without a sigma", static_cast<double>(missing), 0.0, missing == 0, 0});
    }
    // The halves of the recording, calibrated apart, agree within their sigmas (a self-check that
    // could not be made does not pass: its sigmas are then unchecked).
    const SplitCheck& sc = res.self_check;
    if (sc.verdict != SplitCheck::Verdict::kNotRun)
      solve_.gates.push_back({"self-check: largest difference of the parts (sigmas)", sc.worst_z, sc.z_limit,
                              sc.verdict == SplitCheck::Verdict::kAgree, 1});
  }
  solve_.gates_pass =
      std::all_of(solve_.gates.begin(), solve_.gates.end(), [](const Gate& g) { return g.pass; });
}

std::vector<CameraRecord> SessionEngine::review_cameras() const {
  if (solve_.final->record) return solve_.final->record->cameras;
  // A solve without a record (none is written): the cameras as the record would hold them.
  if (!solve_.final->camimu) return {};
  return calibration_record_from_camimu(*solve_.final->camimu, "").cameras;
}

std::vector<std::string> SessionEngine::difference_to_stored(
    std::optional<session_msg::Review::Difference>* diff) const {
  if (!stored_) {
    if (!solve_.final->imu) return {};
    return {stored_unreadable_.empty()
                ? "Stored calibration: none; this is the first"
                : "Stored calibration: present but not comparable (" + stored_unreadable_ + ")"};
  }
  std::vector<std::string> lines = imu_difference_to_stored(diff);
  if (solve_.final->record && solve_.final->record->thermal) {
    for (auto& line : thermal_change_lines(*solve_.final->record->thermal, stored_->record.thermal, info_))
      lines.push_back(std::move(line));
  }
  if (solve_.final->camimu) {
    for (const CameraRecord& cam : review_cameras()) {
      const auto& stored = stored_->record.cameras;
      const auto old = std::find_if(stored.begin(), stored.end(),
                                    [&](const CameraRecord& c) { return c.name == cam.name; });
      lines.push_back(old == stored.end() ? "  " + cam.name + ": not in the stored calibration (new)"
                                          : camera_change_line(cam, *old));
    }
  }
  if (lines.empty()) return lines;
  lines.insert(lines.begin(), "Change to the stored calibration (" + stored_->summary + "):");
  return lines;
}

std::vector<std::string> SessionEngine::imu_difference_to_stored(
    std::optional<session_msg::Review::Difference>* diff) const {
  if (!solve_.final->imu) return {};
  const ImuRecord& imu = stored_->record.imu;
  const std::string units = info_.units == ImuUnits::kRaw ? "raw" : "si";
  if (imu.input_units != units)
    return {"  IMU: the stored one is for " + imu.input_units + " input, not comparable"};
  const auto& c = solve_.final->imu->canonical;
  const CanonicalImuModel& old = imu.model;
  *diff = session_msg::Review::Difference{
      c.b_a - old.b_a, c.b_g - old.b_g,
      Eigen::Vector3d(c.A_a.diagonal().cwiseQuotient(old.A_a.diagonal()).array() - 1.0),
      Eigen::Vector3d(c.A_g.diagonal().cwiseQuotient(old.A_g.diagonal()).array() - 1.0)};
  return imu_change_lines(c, old, info_.units == ImuUnits::kRaw);
}

void SessionEngine::review() {
  state_ = SessionState::kReview;
  session_msg::Review review_message;
  for (const auto& g : solve_.gates)
    review_message.gates.push_back({g.name, g.value, g.limit, g.pass, g.digits});
  std::vector<std::string> lines;
  if (solve_.final->imu) lines = imu_review_lines(*solve_.final->imu, info_);
  if (solve_.final->thermal) {
    for (auto& line : thermal_review_lines(*solve_.final->thermal)) lines.push_back(std::move(line));
    if (solve_.final->thermal->determined && solve_.final->imu) {
      lines.push_back("The biases above are those at " + fixed(solve_.final->thermal->reference_c, 2) +
                      " C: the samples were corrected to the thermal model's reference temperature");
      for (const auto& w : solve_.final->imu->warnings)
        if (w.starts_with("thermal: ")) lines.push_back("  " + w.substr(9));
    }
  }
  if (solve_.final->camimu) {
    const auto& solved = solve_.final->camimu->result.cameras;
    for (const CameraRecord& cam : review_cameras()) {
      const auto it = std::find_if(solved.begin(), solved.end(),
                                   [&](const CamImuCameraResult& c) { return c.name == cam.name; });
      for (auto& line :
           camera_review_lines(cam, it == solved.end() ? kNotDetermined : it->reprojection_rms_px))
        lines.push_back(std::move(line));
    }
    const SplitCheck& chain = solve_.final->chain_self_check;
    if (chain.verdict != SplitCheck::Verdict::kNotRun) {
      lines.push_back("Camera chain self-check: " + chain.summary);
      for (const auto& [who, k] : chain.scaled)
        lines.push_back("  " + who + "'s sigmas scaled by " + fixed(k, 2) +
                        " (its parts spread that much more)");
    }
    const SplitCheck& sc = solve_.final->camimu->result.self_check;
    if (sc.verdict != SplitCheck::Verdict::kNotRun) lines.push_back("Self-check: " + sc.summary);
    if (!sc.advice.empty()) lines.push_back("  " + sc.advice);
  } else if (solve_.final->record) {
    // Cameras the record will keep from the stored one (app::keep_stored_cameras): said, so
    // that the operator accepts knowing what is written.
    for (const std::string& note : solve_.final->record->notes)
      if (note.starts_with("cameras kept")) lines.push_back("Cameras: " + note);
  }
  // A stored thermal model the record does not carry on (app::keep_stored_cameras): said too.
  if (solve_.final->record) {
    for (const std::string& note : solve_.final->record->notes)
      if (note.starts_with("the stored thermal model")) lines.push_back("Thermal: " + note);
  }
  for (auto& line : difference_to_stored(&review_message.difference_to_stored))
    lines.push_back(std::move(line));
  review_message.pass = solve_.gates_pass;
  review_message.lines = std::move(lines);
  review_message.files = solve_.final->result_files;
  emit(std::move(review_message));
  if (solve_.gates_pass && config_.session.auto_write) {
    message(MessageLevel::kInfo, "Every gate passed; writing (session.auto_write)");
    state_ = SessionState::kRunning;
    advance();
    return;
  }
  prompt(solve_.gates_pass ? "Every gate passed. Press y to accept and write, n to reject"
                           : "A gate failed. Press y to write anyway, n to reject",
         {K::kAccept, K::kReject, K::kAbort});
}

}  // namespace imucal::app::session
