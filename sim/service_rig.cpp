// SPDX-License-Identifier: BSD-3-Clause
// The service's virtual rig (sim/service_rig.hpp), built into libimucal_virtual_rig.so.

#include "sim/service_rig.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <numbers>
#include <optional>
#include <sstream>

#include "core/camimu_calibration.hpp"
#include "core/text_format.hpp"
#include "sim/camera_scene.hpp"
#include "sim/camimu.hpp"
#include "sim/motion.hpp"
#include "sim/session_operator.hpp"
#include "sim/session_rig.hpp"
#include "sim/truth.hpp"
#include "sim/virtual_cameras.hpp"

namespace imucal::sim {
namespace {

using nlohmann::json;

constexpr TimeNs kTickNs = 20'000'000;  // rig time per tick
constexpr auto kBusyWait = std::chrono::milliseconds(2);

/// One row of the final table: a quantity the session estimated beside the virtual rig's truth.
struct TruthRow {
  std::string name;
  std::string unit;
  double estimate = kNotDetermined;
  double truth = kNotDetermined;
  /// 1-sigma; NaN, 0 or negative: not determined.
  double sigma = kNotDetermined;
  /// The error when it is not estimate - truth (a rotation's error about one axis): the row then
  /// shows no estimate, truth or relative error.
  std::optional<double> error_only;
};

TruthRow compared(std::string name, std::string unit, double estimate, double truth, double sigma) {
  TruthRow r;
  r.name = std::move(name);
  r.unit = std::move(unit);
  r.estimate = estimate;
  r.truth = truth;
  r.sigma = sigma;
  return r;
}

bool determined(double sigma) { return std::isfinite(sigma) && sigma > 0.0; }

std::string number(double v, const char* format) {
  if (!std::isfinite(v)) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

/// The text with every line longer than `width` broken at spaces, the continuation indented by
/// two more spaces than the line (the table's own rows fit; its notes and headings are prose).
std::string wrapped(const std::string& text, std::size_t width = 100) {
  std::istringstream in(text);
  std::string out;
  for (std::string line; std::getline(in, line);) {
    const std::size_t indent =
        line.find_first_not_of(' ') == std::string::npos ? 0 : line.find_first_not_of(' ');
    while (line.size() > width) {
      std::size_t cut = line.rfind(' ', width);
      if (cut == std::string::npos || cut <= indent + 2) break;
      out += line.substr(0, cut) + "\n";
      line = std::string(indent + 2, ' ') + line.substr(cut + 1);
    }
    out += line + "\n";
  }
  return out;
}

/// The table, 100 columns wide, a space before every column (a wide number shifts its row, never
/// joins its neighbour): a figure that has no sigma says "not determined" across the sigma's and
/// the ratio's columns.
std::string table_text(const std::vector<TruthRow>& rows) {
  std::ostringstream out;
  auto line = [&](const std::string& name, const std::string& unit, const std::string& est,
                  const std::string& tru, const std::string& err, const std::string& rel,
                  const std::optional<std::pair<std::string, std::string>>& sigma_ratio) {
    out << "  " << std::left << std::setw(23) << name << ' ' << std::setw(15) << unit << std::right << ' '
        << std::setw(12) << est << ' ' << std::setw(12) << tru << ' ' << std::setw(8) << err << ' '
        << std::setw(8) << rel;
    if (sigma_ratio) {
      out << ' ' << std::setw(8) << sigma_ratio->first << ' ' << std::setw(5) << sigma_ratio->second << '\n';
    } else {
      out << ' ' << std::setw(14) << "not determined" << '\n';
    }
  };
  line("quantity", "unit", "estimate", "truth", "error", "rel.err",
       std::pair<std::string, std::string>("1-sigma", "e/sig"));
  int with_sigma = 0, within[3] = {0, 0, 0};
  double worst = 0.0;
  std::string worst_name;
  for (const TruthRow& r : rows) {
    const double error = r.error_only ? *r.error_only : r.estimate - r.truth;
    const bool sig = determined(r.sigma);
    const double ratio = sig ? error / r.sigma : kNotDetermined;
    if (sig && std::isfinite(ratio)) {
      ++with_sigma;
      for (int k = 0; k < 3; ++k) within[k] += std::abs(ratio) <= k + 1 ? 1 : 0;
      if (std::abs(ratio) > worst) {
        worst = std::abs(ratio);
        worst_name = r.name;
      }
    }
    const bool values = !r.error_only;
    line(r.name, r.unit, values ? number(r.estimate, "%.6g") : "-", values ? number(r.truth, "%.6g") : "-",
         number(error, "%.2g"),
         values && r.truth != 0.0 ? number(error / std::abs(r.truth), "%.1e") : std::string("-"),
         sig ? std::optional(std::pair(number(r.sigma, "%.2g"), number(ratio, "%.1f"))) : std::nullopt);
  }
  out << "  " << rows.size() << " quantities, " << with_sigma
      << " with a sigma: |error/sigma| <= 1: " << within[0] << ", <= 2: " << within[1]
      << ", <= 3: " << within[2];
  if (!worst_name.empty()) out << "; largest " << number(worst, "%.2f") << " (" << worst_name << ")";
  out << "\n";
  return out.str();
}

Eigen::Vector3d vec3(const json& j) {
  auto v = [&](int i) { return j.at(i).is_number() ? j.at(i).get<double>() : kNotDetermined; };
  return Eigen::Vector3d(v(0), v(1), v(2));
}

Eigen::Matrix3d mat3(const json& j) {
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) m.row(r) = vec3(j.at(r)).transpose();
  return m;
}

/// j[a][b]... when every key is there, else null.
json at_path(const json& j, std::initializer_list<const char*> keys) {
  const json* at = &j;
  for (const char* k : keys) {
    if (!at->is_object() || !at->contains(k)) return nullptr;
    at = &(*at)[k];
  }
  return *at;
}

Eigen::Vector3d sigma3(const json& j) {
  return j.is_array() && j.size() == 3 ? vec3(j) : Eigen::Vector3d::Constant(kNotDetermined);
}

Eigen::Matrix3d sigma33(const json& j) {
  return j.is_array() && j.size() == 3 ? mat3(j) : Eigen::Matrix3d::Constant(kNotDetermined);
}

/// The JSON file at `path`; null when it cannot be read.
json read_json(const std::string& path) {
  std::ifstream in(path);
  if (!in) return nullptr;
  return json::parse(in, nullptr, false);
}

/// The result files the session names (the "files" of its result message) by role.
struct ResultFiles {
  json static_result;                        // imu-static.json
  json camimu_result;                        // camimu/result.json
  std::map<std::string, YAML::Node> camera;  // camera-NAME.yaml by camera name
  YAML::Node chain;                          // cameras-chain.yaml (a rig with several cameras)
};

ResultFiles read_result_files(const session_msg::ResultSummary& result) {
  ResultFiles f;
  for (const std::string& entry : result.files) {
    const std::filesystem::path path(entry);
    const std::string file = path.filename().string();
    if (file == "imu-static.json") {
      f.static_result = read_json(path.string());
    } else if (file == "result.json" && path.parent_path().filename() == "camimu") {
      f.camimu_result = read_json(path.string());
    } else if (file == "cameras-chain.yaml") {
      try {
        f.chain = YAML::LoadFile(path.string());
      } catch (const std::exception&) {
      }
    } else if (file.starts_with("camera-") && file.ends_with(".yaml")) {
      try {
        f.camera[file.substr(7, file.size() - 12)] = YAML::LoadFile(path.string());
      } catch (const std::exception&) {
      }
    }
  }
  if (f.static_result.is_discarded()) f.static_result = nullptr;
  if (f.camimu_result.is_discarded()) f.camimu_result = nullptr;
  return f;
}

const char* kAxis[3] = {"x", "y", "z"};

/// The IMU's rows: the static result (the message's canonical model, the sigmas of its file)
/// beside the truth in the frame that result is expressed in.
void imu_rows(const session_msg::ResultSummary::Imu& imu, const json& static_result,
              const CanonicalImuModel& truth, bool counts, double accel_si_per_unit, double gyro_si_per_unit,
              std::vector<TruthRow>& rows) {
  const Eigen::Matrix3d &A_a = imu.A_a, &A_g = imu.A_g, &G = imu.G;
  const Eigen::Vector3d &b_a = imu.b_a, &b_g = imu.b_g;
  const std::string scale_unit_a = counts ? "(m/s^2)/count" : "1",
                    scale_unit_g = counts ? "(rad/s)/count" : "1";
  constexpr double kDeg = 180.0 / std::numbers::pi;
  struct Triad {
    const char* name;
    const Eigen::Matrix3d& A;
    const Eigen::Matrix3d& A_true;
    const Eigen::Vector3d& b;
    const Eigen::Vector3d& b_true;
    const char* key;
    std::string scale_unit;
    const char* bias_unit;
    double bias_to_unit;  // stream units -> the bias's unit in the table
    bool full_misalignment;
  };
  const Triad triads[2] = {
      {"accel", A_a, truth.A_a, b_a, truth.b_a, "accel", scale_unit_a, "m/s^2", accel_si_per_unit, false},
      {"gyro", A_g, truth.A_g, b_g, truth.b_g, "gyro", scale_unit_g, "deg/s", gyro_si_per_unit * kDeg, true}};
  for (const Triad& t : triads) {
    // corrected = misalignment * diag(scale) * (raw - bias): the scales are the diagonal of A,
    // the misalignments A's columns divided by them.
    const Eigen::Vector3d s_sigma = sigma3(at_path(static_result, {t.key, "sigma", "scale"}));
    const Eigen::Matrix3d m_sigma = sigma33(at_path(static_result, {t.key, "sigma", "misalignment"}));
    const Eigen::Vector3d b_sigma = sigma3(at_path(static_result, {t.key, "sigma", "bias"}));
    for (int i = 0; i < 3; ++i)
      rows.push_back(compared(std::string(t.name) + " scale " + kAxis[i], t.scale_unit, t.A(i, i),
                              t.A_true(i, i), s_sigma(i)));
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        // The accelerometer's frame has its misalignment upper-triangular (docs/static-calibration.md).
        if (i == j || (!t.full_misalignment && i > j)) continue;
        rows.push_back(compared(std::string(t.name) + " misalignment " + kAxis[i] + kAxis[j], "1",
                                t.A(i, j) / t.A(j, j), t.A_true(i, j) / t.A_true(j, j), m_sigma(i, j)));
      }
    for (int i = 0; i < 3; ++i)
      rows.push_back(compared(std::string(t.name) + " bias " + kAxis[i], t.bias_unit, t.b(i) * t.bias_to_unit,
                              t.b_true(i) * t.bias_to_unit, b_sigma(i) * t.bias_to_unit));
  }
  // The g-sensitivity, when the static method estimated it.
  const json mode = at_path(static_result, {"gsens", "mode"});
  const bool gsens = mode.is_string() ? mode.get<std::string>() == "estimate" : !G.isZero(0.0);
  if (!gsens) return;
  const Eigen::Matrix3d G_sigma = sigma33(at_path(static_result, {"gsens", "G_sigma"}));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      rows.push_back(compared(std::string("gyro g-sensitivity G_") + kAxis[i] + kAxis[j], "(rad/s)/(m/s^2)",
                              G(i, j), truth.G(i, j), G_sigma(i, j)));
}

/// The rows of camera n >= 1 of the chain (cameras-chain.yaml) against camera n - 1: the
/// baseline, the relative rotation's error about camera n's axes and the time offset against cam0,
/// with the chain's sigmas.
void pair_rows(const YAML::Node& cam, const std::string& name, const VirtualCameraTruth& truth,
               const VirtualCameraTruth& before, const VirtualCameraTruth& cam0,
               std::vector<TruthRow>& rows) {
  const YAML::Node own = cam["imucal"];
  const auto get = [&](const YAML::Node& n) {
    return n && n.IsScalar() && n.Scalar() != "~" && n.Scalar() != "null" ? n.as<double>() : kNotDetermined;
  };
  const auto item = [&](const char* key, int i) {
    const YAML::Node n = own ? own[key] : YAML::Node();
    return n && n.IsSequence() && n.size() > static_cast<std::size_t>(i) ? get(n[i]) : kNotDetermined;
  };
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 4; ++r)
    for (int k = 0; k < 4; ++k) T(r, k) = cam["T_cn_cnm1"][r][k].as<double>();
  const Eigen::Isometry3d T_true = truth.T_cam_imu * before.T_cam_imu.inverse();
  rows.push_back(compared(name + " baseline", "mm", 1e3 * T.topRightCorner<3, 1>().norm(),
                          1e3 * T_true.translation().norm(),
                          1e3 * get(own ? own["baseline_sigma_m"] : YAML::Node())));
  const Eigen::AngleAxisd e_aa(Eigen::Matrix3d(T.topLeftCorner<3, 3>() * T_true.linear().transpose()));
  const Eigen::Vector3d e = e_aa.angle() * e_aa.axis();
  constexpr double kDeg = 180.0 / std::numbers::pi;
  for (int i = 0; i < 3; ++i) {
    TruthRow r = compared(name + " rel. rotation " + kAxis[i], "deg", kNotDetermined, kNotDetermined,
                          kDeg * item("T_cn_cnm1_rotation_sigma_rad", i));
    r.error_only = e(i) * kDeg;
    rows.push_back(r);
  }
  rows.push_back(compared(name + " offset to cam0", "ms",
                          1e3 * get(own ? own["timeshift_cam_cam0"] : YAML::Node()),
                          1e3 * (truth.timeshift_cam_imu_s - cam0.timeshift_cam_imu_s),
                          1e3 * get(own ? own["timeshift_cam_cam0_sigma"] : YAML::Node())));
}

/// The rows of one camera: intrinsics (camera-NAME.yaml), rotation, translation and time offset
/// (the result message, the sigmas of camimu/result.json), beside the virtual camera's truth.
void camera_rows(const session_msg::ResultSummary::Camera& c, const ResultFiles& files,
                 const CameraModel& truth_camera, const Eigen::Isometry3d& T_true, double timeshift_true_s,
                 std::vector<TruthRow>& rows, std::ostringstream& notes) {
  const std::string name = c.name.empty() ? "cam" : c.name;
  json sig;
  if (files.camimu_result.is_object() && files.camimu_result.contains("cameras"))
    for (const auto& rc : files.camimu_result["cameras"])
      if (rc.value("name", "") == name) sig = rc;
  if (auto it = files.camera.find(name); it != files.camera.end()) {
    try {
      const YAML::Node cam = it->second[name] ? it->second[name] : it->second.begin()->second;
      auto list = [&](const YAML::Node& n, int i) {
        return n && n.IsSequence() && n.size() > static_cast<std::size_t>(i) ? n[i].as<double>()
                                                                             : kNotDetermined;
      };
      const YAML::Node own = cam["imucal"];
      auto own_list = [&](const char* key, int i) { return own ? list(own[key], i) : kNotDetermined; };
      const char* kIntrinsics[4] = {"fx", "fy", "cx", "cy"};
      // Kalibr's intrinsics hold the projection's parameters (omni, eucm, ds) before fu fv pu pv.
      const auto projection =
          parse_projection_name(cam["camera_model"] ? cam["camera_model"].as<std::string>() : "pinhole");
      const int extra = projection ? projection_param_count(*projection) : 0;
      for (int i = 0; i < 4; ++i)
        rows.push_back(compared(name + " " + kIntrinsics[i], "px", list(cam["intrinsics"], extra + i),
                                truth_camera.intrinsics[i], own_list("intrinsics_sigma", extra + i)));
      const std::string model = cam["distortion_model"] ? cam["distortion_model"].as<std::string>() : "";
      if (model == "radtan" && truth_camera.distortion_model == DistortionModel::kRadtan) {
        const char* kCoeffs[4] = {"k1", "k2", "p1", "p2"};
        for (int i = 0; i < 4; ++i)
          rows.push_back(compared(name + " distortion " + kCoeffs[i], "1", list(cam["distortion_coeffs"], i),
                                  truth_camera.distortion_coeffs[i], own_list("distortion_coeffs_sigma", i)));
      } else {
        notes << "  " << name << ": distortion model " << model
              << " estimated; the virtual camera's is radtan: not compared\n";
      }
    } catch (const std::exception& e) {
      notes << "  " << name << ": intrinsics not read (" << e.what() << ")\n";
    }
  } else {
    notes << "  " << name << ": no intrinsics file in the result\n";
  }
  const Eigen::Quaterniond q(c.q_cam_imu_wxyz[0], c.q_cam_imu_wxyz[1], c.q_cam_imu_wxyz[2],
                             c.q_cam_imu_wxyz[3]);
  const Eigen::Quaterniond q_true(T_true.rotation());
  // The error as a rotation about the camera's axes, R_est = Exp(e) R_true, the axes of the
  // rotation sigmas (calib/camimu_calibration.cpp).
  const Eigen::AngleAxisd e_aa(q.normalized() * q_true.conjugate());
  const Eigen::Vector3d e = e_aa.angle() * e_aa.axis();
  constexpr double kDeg = 180.0 / std::numbers::pi;
  const Eigen::Vector3d r_sigma = sigma3(sig.is_object() ? sig.value("rotation_sigma_rad", json()) : json());
  for (int i = 0; i < 3; ++i) {
    TruthRow r = compared(name + " rotation about " + kAxis[i], "deg", kNotDetermined, kNotDetermined,
                          r_sigma(i) * kDeg);
    r.error_only = e(i) * kDeg;
    rows.push_back(r);
  }
  const Eigen::Vector3d& t = c.t_cam_imu_m;
  const Eigen::Vector3d t_sigma = sigma3(sig.is_object() ? sig.value("translation_sigma_m", json()) : json());
  for (int i = 0; i < 3; ++i)
    rows.push_back(compared(name + " translation " + kAxis[i], "mm", t(i) * 1e3,
                            T_true.translation()(i) * 1e3, t_sigma(i) * 1e3));
  const json shift_sigma = sig.is_object() ? sig.value("timeshift_sigma_s", json()) : json();
  rows.push_back(compared(name + " time offset", "ms", c.timeshift_cam_imu_s * 1e3, timeshift_true_s * 1e3,
                          shift_sigma.is_number() ? shift_sigma.get<double>() * 1e3 : kNotDetermined));
  notes.setf(std::ios::fixed);
  notes.precision(4);
  notes << "  " << name << " rotation R_cam_imu: estimated q_wxyz (" << q.w() << ", " << q.x() << ", "
        << q.y() << ", " << q.z() << "), true (" << q_true.w() << ", " << q_true.x() << ", " << q_true.y()
        << ", " << q_true.z() << "), " << q.angularDistance(q_true) * kDeg << " deg apart; reprojection RMS "
        << c.reprojection_rms_px << " px\n";
  notes.unsetf(std::ios::fixed);
}

class VirtualServiceRig final : public ServiceRig {
 public:
  static Result<std::unique_ptr<ServiceRig>> create(const ServiceRigOptions& options) {
    std::unique_ptr<VirtualServiceRig> r(new VirtualServiceRig(options));
    SessionRigOptions so;
    so.settings = options.settings;
    so.mounting = options.mounting;
    so.seed = options.seed;
    if (options.cold_start_c) {
      ImuModelParams p = ImuModelParams::draw(options.seed);
      p.temp_start_c = *options.cold_start_c;
      p.temp_final_c = 45.0;
      p.temp_time_constant_s = 300.0;
      p.draw_temperature_coefficients(options.seed, 2);
      so.params = p;
    }
    auto rig = SessionRig::create(so);
    if (!rig.ok()) return rig.error();
    r->rig_ = std::move(*rig);
    IMUCAL_TRY(r->prepare_cameras());
    if (!options.operator_mode.empty()) {
      ScriptedOperatorOptions oo;
      oo.seed = options.seed;
      oo.press_keys = options.operator_mode == "full";
      oo.wave = r->motion_;
      if (r->motion_) oo.wave_T_op_motion = follow_transform(*r->motion_);
      r->operator_ = std::make_unique<ScriptedOperator>(r->rig_->trajectory(), oo, options.press_key);
    }
    r->wall_start_ = std::chrono::steady_clock::now();
    r->rig_start_ns_ = r->rig_->now_ns();
    return std::unique_ptr<ServiceRig>(std::move(r));
  }

  const ImuStreamInfo& stream_info() const override { return rig_->stream_info(); }
  drivers::mpu6000::Mpu6000& driver() override { return rig_->rig().driver(); }
  TimeNs now_ns() override { return rig_->now_ns(); }
  void stall(TimeNs duration_ns) override { rig_->rig().stall_until(rig_->now_ns() + duration_ns); }

  Result<ServiceRigTick> tick(bool worker_busy,
                              const std::function<void(std::span<const ImuSample>)>& deliver) override {
    const double scale = options_.time_scale;
    if (scale != 1.0 && worker_busy) {
      paused_ = true;
      return ServiceRigTick{false, std::chrono::steady_clock::now() + kBusyWait, {}};
    }
    if (paused_) {
      // Wall time spent waiting does not count as rig time.
      paused_ = false;
      if (scale > 0.0) wall_start_ = std::chrono::steady_clock::now() - wall_offset(scale);
      pace_wall_start_.reset();
    }
    if (unplug_imu_at_ns_ >= 0 && rig_->now_ns() >= unplug_imu_at_ns_) {
      unplug_imu_at_ns_ = -1;
      rig_->rig().emulator().fail_next_transfers(1 << 30);  // every transfer from now on
    }
    batch_.clear();
    IMUCAL_TRY(rig_->advance(kTickNs, batch_));
    deliver(batch_);
    if (operator_) operator_->on_time(rig_->now_ns());
    ServiceRigTick t{true, std::nullopt, {}};
    // Rig time runs `scale` times as fast as wall time.
    if (scale > 0.0) {
      t.next = wall_start_ + wall_offset(scale);
      t.pace_notice = check_pace(scale);
    }
    return t;
  }

  void unplug_imu_after(double after_s) override {
    unplug_imu_at_ns_ = rig_->now_ns() + static_cast<TimeNs>(after_s * 1e9);
  }

  void on_message(const session_msg::SessionMessage& message) override {
    if (const auto* prompt = std::get_if<session_msg::Prompt>(&message); prompt && prompt->step)
      mark_bias_window(*prompt->step);
    if (operator_) operator_->on_message(message, rig_->now_ns());
  }

  bool operator_presses_keys() const override { return options_.operator_mode == "full"; }
  bool cameras_ready() const override { return renderers_.size() == options_.cameras.size(); }

  Result<std::unique_ptr<drivers::camera::Camera>> open_camera(std::size_t index,
                                                               std::uint32_t disconnect_after) override {
    if (index >= renderers_.size())
      return make_error(Errc::kInvalidArgument, "the virtual rig has no camera " + std::to_string(index));
    const CameraConfig& cc = options_.cameras[index];
    VirtualCameraTiming timing;
    timing.first_frame_ns = rig_->now_ns() + static_cast<TimeNs>(1e9 / cc.rate_hz);
    timing.clock = [this] { return rig_->now_ns(); };
    timing.disconnect_after = disconnect_after;
    auto camera = make_virtual_camera(cc, renderers_[index], timing);
    if (!camera.ok()) return camera.error();
    return std::unique_ptr<drivers::camera::Camera>(std::move(*camera));
  }

  std::optional<std::vector<Eigen::Vector2d>> truth_corners(std::size_t index, TimeNs t_ns) const override {
    if (index >= sources_.size()) return std::nullopt;
    return sources_[index]->corners_at(t_ns);
  }

  std::string truth_report(const session_msg::ResultSummary& result) const override {
    if (!result.imu) return {};
    const ResultFiles files = read_result_files(result);
    const bool counts = rig_->stream_info().units == ImuUnits::kRaw;
    const ImuModelParams& p = rig_->params();
    // The static method finds one bias per triad; the simulated one wanders (random walk), so its
    // truth is the bias in effect averaged over the samples of the still and pose steps.
    ImuModelParams at_session = p;
    // A result corrected to a thermal model's reference temperature: the truth is the bias there,
    // the simulator's temperature parts over the window replaced by its part at T_ref.
    std::optional<double> reference_c;
    if (result.thermal && result.thermal->determined) reference_c = result.thermal->reference_c;
    const std::string window = realised_biases(at_session.accel_bias, at_session.gyro_bias, reference_c);
    const double accel_si = counts ? p.accel_mps2_per_count() : 1.0,
                 gyro_si = counts ? p.gyro_radps_per_count() : 1.0;
    std::vector<TruthRow> rows;
    std::ostringstream notes;
    imu_rows(*result.imu, files.static_result, canonical_in_tedaldi_frame(at_session, counts), counts,
             accel_si, gyro_si, rows);
    if (result.cameras) {
      for (const auto& c : *result.cameras) {
        const std::string& name = c.name;
        auto cc = std::find_if(options_.cameras.begin(), options_.cameras.end(),
                               [&](const CameraConfig& k) { return k.name == name; });
        if (cc == options_.cameras.end()) {
          notes << "  " << name << ": no such virtual camera, not compared\n";
          continue;
        }
        const VirtualCameraTruth truth =
            virtual_camera_truth(*cc, static_cast<std::size_t>(cc - options_.cameras.begin()));
        camera_rows(c, files, truth.camera, truth.T_cam_imu, truth.timeshift_cam_imu_s, rows, notes);
      }
    }
    // The chain's pairs: camN against camN-1 in the configuration's order.
    for (std::size_t n = 1; files.chain && files.chain.IsMap() && n < options_.cameras.size(); ++n) {
      const YAML::Node cam = files.chain["cam" + std::to_string(n)];
      if (!cam || !cam["T_cn_cnm1"]) continue;
      try {
        pair_rows(cam, options_.cameras[n].name, virtual_camera_truth(options_.cameras[n], n),
                  virtual_camera_truth(options_.cameras[n - 1], n - 1),
                  virtual_camera_truth(options_.cameras[0], 0), rows);
      } catch (const std::exception& e) {
        notes << "  " << options_.cameras[n].name << ": the camera chain not read (" << e.what() << ")\n";
      }
    }
    std::ostringstream head;
    head << "  Every estimated quantity: estimate, truth, error = estimate - truth, relative error = error / "
            "|truth|, the result's 1-sigma and error / sigma (e/sig).\n"
         << "  IMU: the static result (the record's IMU), in the frame it reports in (z along the "
            "accelerometer's "
            "z axis)";
    if (counts) {
      head.setf(std::ios::scientific);
      head.precision(4);
      head << "; scales per count of the raw stream, biases at the nominal sensitivity (1 count = "
           << accel_si << " m/s^2, " << gyro_si * 180.0 / std::numbers::pi << " deg/s)";
      head.unsetf(std::ios::scientific);
    }
    head << "; true biases: " << window << ".\n"
         << "  Cameras: intrinsics (camera-NAME.yaml), then the camera-IMU calibration (t_imu = t_cam + time "
            "offset; "
            "the rotation's error about the camera's axes, R_est = Exp(e) R_true); with several cameras the "
            "camera chain's baseline, relative rotation (about the camera's axes) and time offset of each "
            "camera against the one before.\n";
    return wrapped(head.str() + table_text(rows) + notes.str());
  }

 private:
  explicit VirtualServiceRig(ServiceRigOptions options) : options_(std::move(options)) {}

  /// The window of the biases' truth: from the (last) start of the still step to the first step
  /// after the poses.
  void mark_bias_window(session_msg::StepId step) {
    if (bias_end_) return;
    if (step == session_msg::StepId::kStill) {
      bias_begin_ = rig_->sensor_stats();
    } else if (bias_begin_ && step != session_msg::StepId::kPoses) {
      bias_end_ = rig_->sensor_stats();
    }
  }

  /// The mean biases in effect over the window (or over every sample so far, when the session
  /// had no still step); what they are averaged over. With `reference_c` (a result corrected to a
  /// thermal model's reference temperature) their mean temperature parts are replaced by the
  /// parts at that temperature.
  std::string realised_biases(Eigen::Vector3d& accel, Eigen::Vector3d& gyro,
                              std::optional<double> reference_c) const {
    const TrajectorySensorStats end = bias_end_ ? *bias_end_ : rig_->sensor_stats();
    const TrajectorySensorStats begin = bias_begin_ ? *bias_begin_ : TrajectorySensorStats{};
    const std::int64_t n = end.samples - begin.samples;
    if (n <= 0) return "the turn-on biases (no samples)";
    const double k = 1.0 / static_cast<double>(n);
    accel = (end.sum_accel_bias - begin.sum_accel_bias) * k;
    gyro = (end.sum_gyro_bias - begin.sum_gyro_bias) * k;
    std::string what = bias_begin_ ? "their mean over the still and pose steps (they wander)"
                                   : "their mean over the session (they wander)";
    if (reference_c) {
      const ImuModelParams& p = rig_->params();
      accel += p.accel_bias_temp(*reference_c) - (end.sum_accel_bias_temp - begin.sum_accel_bias_temp) * k;
      gyro += p.gyro_bias_temp(*reference_c) - (end.sum_gyro_bias_temp - begin.sum_gyro_bias_temp) * k;
      what += ", their temperature parts replaced by those at the thermal model's reference " +
              fixed(*reference_c, 2) + " deg C";
    }
    return what;
  }

  /// The pace reached over the last window against the one asked: a notice when it falls below
  /// 80 % of it (once), and when it is back above 95 %.
  std::string check_pace(double scale) {
    const auto now = std::chrono::steady_clock::now();
    if (!pace_wall_start_) {
      pace_wall_start_ = now;
      pace_rig_start_ns_ = rig_->now_ns();
      return {};
    }
    const double wall_s = std::chrono::duration<double>(now - *pace_wall_start_).count();
    if (wall_s < options_.pace_window_s) return {};
    const double pace = static_cast<double>(rig_->now_ns() - pace_rig_start_ns_) * 1e-9 / wall_s;
    pace_wall_start_ = now;
    pace_rig_start_ns_ = rig_->now_ns();
    if (!pace_slow_ && pace < 0.8 * scale) {
      pace_slow_ = true;
      return "The virtual rig runs at " + format_number("%.2g", pace) + "x real time, slower than the " +
             format_number("%g", scale) +
             "x asked (--time-scale): this machine is too busy to keep up. The session's results "
             "do not change, it only takes longer";
    }
    if (pace_slow_ && pace >= 0.95 * scale) {
      pace_slow_ = false;
      return "The virtual rig is back at the " + format_number("%g", scale) + "x asked";
    }
    return {};
  }

  std::chrono::nanoseconds wall_offset(double scale) const {
    const double rig_s = static_cast<double>(rig_->now_ns() - rig_start_ns_) * 1e-9;
    return std::chrono::nanoseconds(static_cast<std::int64_t>(rig_s / scale * 1e9));
  }

  /// One renderer per camera, the board where the operator's motion puts it.
  Status prepare_cameras() {
    if (options_.cameras.empty()) return {};
    if (!options_.target)
      return make_error(Errc::kInvalidArgument,
                        "the virtual rig's cameras need the target (target: in the configuration)");
    // The operator's motion in front of the board: long enough to cover the step from the first
    // move on, then at rest.
    CheckerboardMotionOptions mo = CamImuSimOptions::default_motion();
    mo.duration_s = options_.motion_s + 8.0;
    auto motion = CheckerboardMotion::create(mo, options_.seed);
    if (!motion.ok()) return motion.error().context("the virtual rig's motion");
    motion_ = std::move(*motion);
    const Eigen::Isometry3d T_op = follow_transform(*motion_);
    // The trajectory belongs to the rig, which outlives its cameras' sources here.
    for (std::size_t i = 0; i < options_.cameras.size(); ++i) {
      const SimCameraScene scene =
          virtual_camera_scene(options_.cameras[i], *options_.target, options_.seed, i);
      auto source =
          SceneFrameSource::create(scene, rig_->trajectory(), T_op * motion_->T_world_board(scene.target));
      if (!source.ok()) return source.error().context("camera " + options_.cameras[i].name);
      sources_.push_back(std::move(*source));
      renderers_.push_back(SceneFrameSource::as_renderer(sources_.back()));
    }
    return {};
  }

  ServiceRigOptions options_;
  std::unique_ptr<SessionRig> rig_;
  std::unique_ptr<ScriptedOperator> operator_;
  std::shared_ptr<const CheckerboardMotion> motion_;
  std::vector<std::shared_ptr<SceneFrameSource>> sources_;  // one per camera, behind renderers_
  std::vector<drivers::camera::fake::FrameRenderer> renderers_;
  std::vector<ImuSample> batch_;
  std::chrono::steady_clock::time_point wall_start_;
  TimeNs rig_start_ns_ = 0;
  TimeNs unplug_imu_at_ns_ = -1;
  bool paused_ = false;
  std::optional<std::chrono::steady_clock::time_point> pace_wall_start_;  // the pace window's start
  TimeNs pace_rig_start_ns_ = 0;
  bool pace_slow_ = false;  // the last pace notice said "slower"
  std::optional<TrajectorySensorStats> bias_begin_, bias_end_;
};

}  // namespace

Result<std::unique_ptr<ServiceRig>> make_service_rig(const ServiceRigOptions& options) {
  return VirtualServiceRig::create(options);
}

}  // namespace imucal::sim
