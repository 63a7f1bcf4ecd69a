// The service's virtual rig (sim/service_rig.hpp), built into libimucal_virtual_rig.so.

#include "sim/service_rig.hpp"

#include <numbers>
#include <sstream>

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

/// The result beside the truth (the correction that inverts the error model, in the frame the
/// static method reports in), one block per quantity.
std::string imu_truth_comparison(const json& imu, const CanonicalImuModel& truth, bool counts) {
  auto vec = [](const json& j) {
    return Eigen::Vector3d(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
  };
  auto mat = [&](const json& j) {
    Eigen::Matrix3d m;
    for (int r = 0; r < 3; ++r) m.row(r) = vec(j[r]).transpose();
    return m;
  };
  std::ostringstream out;
  out.setf(std::ios::scientific);
  out.precision(5);
  auto row = [&](const std::string& name, const Eigen::Vector3d& est, const Eigen::Vector3d& tru) {
    out << "  " << name << "\n    estimated " << est.transpose() << "\n    true      " << tru.transpose()
        << "\n    error     " << (est - tru).transpose() << "\n";
  };
  const char* unit = counts ? " (counts)" : "";
  row(std::string("accel scale diag(A_a)"), mat(imu["A_a"]).diagonal(), truth.A_a.diagonal());
  row(std::string("accel bias b_a") + unit, vec(imu["b_a"]), truth.b_a);
  row(std::string("gyro scale diag(A_g)"), mat(imu["A_g"]).diagonal(), truth.A_g.diagonal());
  row(std::string("gyro bias b_g") + unit, vec(imu["b_g"]), truth.b_g);
  const Eigen::Matrix3d dA_a = mat(imu["A_a"]) - truth.A_a, dA_g = mat(imu["A_g"]) - truth.A_g;
  const Eigen::Matrix3d dG = mat(imu["G"]) - truth.G;
  out << "  largest error: A_a " << dA_a.cwiseAbs().maxCoeff() << ", A_g " << dA_g.cwiseAbs().maxCoeff()
      << ", G " << dG.cwiseAbs().maxCoeff() << " (rad/s per m/s^2; true G max "
      << truth.G.cwiseAbs().maxCoeff() << ")\n";
  return out.str();
}

/// The camera-IMU results beside the virtual cameras' truth (every virtual camera is mounted at
/// CamImuSimOptions::default_T_cam_imu and stamps with no offset).
std::string camera_truth_comparison(const json& cameras) {
  const Eigen::Isometry3d T = CamImuSimOptions::default_T_cam_imu();
  const Eigen::Quaterniond q_true(T.rotation());
  std::ostringstream out;
  out.setf(std::ios::fixed);
  for (const auto& c : cameras) {
    const auto& t = c.at("t_cam_imu_m");
    const auto& qj = c.at("q_cam_imu_wxyz");
    const Eigen::Vector3d est(t[0].get<double>(), t[1].get<double>(), t[2].get<double>());
    const Eigen::Quaterniond q(qj[0].get<double>(), qj[1].get<double>(), qj[2].get<double>(),
                               qj[3].get<double>());
    out.precision(2);
    out << "  " << c.value("name", "cam") << " t_cam_imu (mm)\n    estimated " << (est * 1e3).transpose()
        << "\n    true      " << (T.translation() * 1e3).transpose() << "\n    error     "
        << ((est - T.translation()) * 1e3).transpose() << "\n";
    out.precision(4);
    out << "  " << c.value("name", "cam") << " rotation error "
        << q.angularDistance(q_true) * 180.0 / std::numbers::pi << " deg, time offset "
        << c.value("timeshift_cam_imu_s", 0.0) * 1e3 << " ms (true 0), reprojection RMS "
        << c.value("reprojection_rms_px", 0.0) << " px\n";
  }
  return out.str();
}

class VirtualServiceRig final : public ServiceRig {
 public:
  static Result<std::unique_ptr<ServiceRig>> create(const ServiceRigOptions& options) {
    std::unique_ptr<VirtualServiceRig> r(new VirtualServiceRig(options));
    SessionRigOptions so;
    so.settings = options.settings;
    so.mounting = options.mounting;
    so.seed = options.seed;
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
      return ServiceRigTick{false, std::chrono::steady_clock::now() + kBusyWait};
    }
    if (paused_) {
      // Wall time spent waiting does not count as rig time.
      paused_ = false;
      if (scale > 0.0) wall_start_ = std::chrono::steady_clock::now() - wall_offset(scale);
    }
    if (unplug_imu_at_ns_ >= 0 && rig_->now_ns() >= unplug_imu_at_ns_) {
      unplug_imu_at_ns_ = -1;
      rig_->rig().emulator().fail_next_transfers(1 << 30);  // every transfer from now on
    }
    batch_.clear();
    IMUCAL_TRY(rig_->advance(kTickNs, batch_));
    deliver(batch_);
    if (operator_) operator_->on_time(rig_->now_ns());
    ServiceRigTick t{true, std::nullopt};
    // Rig time runs `scale` times as fast as wall time.
    if (scale > 0.0) t.next = wall_start_ + wall_offset(scale);
    return t;
  }

  void unplug_imu_after(double after_s) override {
    unplug_imu_at_ns_ = rig_->now_ns() + static_cast<TimeNs>(after_s * 1e9);
  }

  void on_message(const json& message) override {
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

  std::string truth_report(const json& result) const override {
    if (!result.contains("imu")) return {};
    const bool counts = rig_->stream_info().units == ImuUnits::kRaw;
    std::string text =
        imu_truth_comparison(result["imu"], canonical_in_tedaldi_frame(rig_->params(), counts), counts);
    if (result.contains("cameras")) text += camera_truth_comparison(result["cameras"]);
    return text;
  }

 private:
  explicit VirtualServiceRig(ServiceRigOptions options) : options_(std::move(options)) {}

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
    // The trajectory belongs to the rig, which outlives its cameras' renderers here.
    std::shared_ptr<const Trajectory> trajectory(&rig_->trajectory(), [](const Trajectory*) {});
    for (std::size_t i = 0; i < options_.cameras.size(); ++i) {
      const SimCameraScene scene =
          virtual_camera_scene(options_.cameras[i], *options_.target, options_.seed, i);
      auto renderer = make_scene_renderer(scene, trajectory, T_op * motion_->T_world_board(scene.target));
      if (!renderer.ok()) return renderer.error().context("camera " + options_.cameras[i].name);
      renderers_.push_back(std::move(*renderer));
    }
    return {};
  }

  ServiceRigOptions options_;
  std::unique_ptr<SessionRig> rig_;
  std::unique_ptr<ScriptedOperator> operator_;
  std::shared_ptr<const CheckerboardMotion> motion_;
  std::vector<drivers::camera::fake::FrameRenderer> renderers_;
  std::vector<ImuSample> batch_;
  std::chrono::steady_clock::time_point wall_start_;
  TimeNs rig_start_ns_ = 0;
  TimeNs unplug_imu_at_ns_ = -1;
  bool paused_ = false;
};

}  // namespace

Result<std::unique_ptr<ServiceRig>> make_service_rig(const ServiceRigOptions& options) {
  return VirtualServiceRig::create(options);
}

}  // namespace imucal::sim
