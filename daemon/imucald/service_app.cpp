// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/imucald/service_app.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <boost/asio/post.hpp>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <thread>

#include "app/camera_module.hpp"
#include "app/module_loader.hpp"
#include "app/rig/cameras.hpp"
#include "app/rig/rig.hpp"
#include "app/rig/stored_calibration.hpp"
#include "app/session/option_words.hpp"
#include "core/version.hpp"
#include "drivers/camera/aravis/aravis_module.hpp"
#include "drivers/camera/libcamera/libcamera_module.hpp"
#include "drivers/mpu6000/output_settings.hpp"
#include "drivers/storage/storage_device.hpp"
#include "sim/service_rig.hpp"

namespace imucal::imucald {

using nlohmann::json;
using session_msg::DeviceState;

namespace {

std::string storage_name(const StorageConfig& s) {
  return std::string(storage_backend_name(s.backend)) + " " +
         (s.backend == StorageBackend::kI2cEeprom ? s.i2c_device : s.path);
}

/// Whether the service may write the storage, without writing it: an existing device or file is
/// opened for writing (and closed); a file not yet made needs a folder the service may write.
/// Empty when writable, else why not.
std::string storage_unwritable(const StorageConfig& config) {
  if (config.backend == StorageBackend::kFile && !std::filesystem::exists(config.path)) {
    const std::filesystem::path dir = std::filesystem::path(config.path).parent_path();
    if (::access(dir.empty() ? "." : dir.c_str(), W_OK | X_OK) != 0)
      return "cannot create " + config.path + ": " + std::strerror(errno);
    return {};
  }
  auto device = drivers::open_storage_device(config, drivers::StorageAccess::kWrite);
  return device.ok() ? std::string() : device.error().message;
}

/// Why the storage path cannot be what its backend needs (a FIFO, socket or folder; for the file
/// backend anything but a regular file), judged from the file's type without opening it; empty
/// when it can (or is not there yet).
std::string storage_type_problem(const StorageConfig& s) {
  if (s.backend == StorageBackend::kI2cEeprom) return {};
  std::error_code ec;
  const auto status = std::filesystem::status(s.path, ec);
  if (!std::filesystem::exists(status)) return {};
  if (s.backend == StorageBackend::kFile && !std::filesystem::is_regular_file(status)) {
    return "not a regular file (a FIFO, device, socket or folder): storage.backend file needs one; fix "
           "storage.path";
  }
  if (std::filesystem::is_fifo(status) || std::filesystem::is_socket(status) ||
      std::filesystem::is_directory(status)) {
    return "a FIFO, socket or folder, not an nvmem file: fix storage.path";
  }
  return {};
}

/// "present", or why a device node or file is not there on this machine.
std::string presence(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) return "present";
  return "not found on this machine";
}

/// What the state folder allows the user running the check.
std::string state_dir_note(const std::string& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    return "does not exist yet (systemd-tmpfiles --create, or the unit's StateDirectory=, makes it)";
  if (::access(dir.c_str(), W_OK | X_OK) == 0) return "exists, writable by this user";
  return "exists, not writable by this user (the service writes it as user imucal)";
}

/// Each absent device as one line for --check and the service's error.
std::string absent_list(const std::vector<std::string>& absent) {
  std::string out;
  for (const std::string& a : absent) out += (out.empty() ? "" : ", ") + a;
  return out;
}

bool node_absent(const std::string& path) {
  std::error_code ec;
  return !path.empty() && !std::filesystem::exists(path, ec);
}

}  // namespace

std::vector<std::string> absent_devices(const RigConfig& c, bool sim, bool imu_only) {
  std::vector<std::string> absent;
  if (sim || c.imu.bus == ImuBus::kSim) return absent;
  if (app::resolve_imu_driver(c.imu) != ImuDriver::kIio) {
    if (node_absent(c.imu.device)) absent.push_back("imu.device " + c.imu.device);
    if (c.imu.data_ready) {
      const std::string chip = c.imu.data_ready->chip.rfind('/', 0) == 0 ? c.imu.data_ready->chip
                                                                         : "/dev/" + c.imu.data_ready->chip;
      if (node_absent(chip)) absent.push_back("imu.data_ready.chip " + chip);
    }
  }
  if (imu_only) return absent;
  for (std::size_t i = 0; i < c.cameras.size(); ++i) {
    const CameraConfig& cam = c.cameras[i];
    if (cam.backend == CameraBackend::kV4l2 && node_absent(cam.device))
      absent.push_back("cameras[" + std::to_string(i) + "].device " + cam.device);
  }
  const StorageConfig& st = c.storage;
  if (st.backend == StorageBackend::kI2cEeprom && node_absent(st.i2c_device))
    absent.push_back("storage.i2c_device " + st.i2c_device);
  if (st.backend == StorageBackend::kNvmem && node_absent(st.path))
    absent.push_back("storage.path " + st.path);
  return absent;
}

std::string config_unusable_message(const std::string& config_path, const Error& error) {
  return "the rig configuration " + config_path + " cannot be used: " + error.message + "\nEdit " +
         config_path + " (docs/config.md lists every key), check it with 'imucald --config " + config_path +
         " --check', then start the service again (systemctl restart imucald)";
}

int check_configuration(const ServiceOptions& options) {
  auto loaded = load_rig_config(options.config_path);
  if (!loaded.ok()) {
    std::fprintf(stderr, "imucald: %s\n",
                 config_unusable_message(options.config_path, loaded.error()).c_str());
    return kExitConfigUnusable;
  }
  const RigConfig& c = *loaded;
  const bool sim = options.sim || c.imu.bus == ImuBus::kSim;
  std::printf("configuration %s: valid\n", options.config_path.c_str());
  std::printf("  rig       %s\n", c.name.c_str());
  if (sim) {
    std::printf("  imu       the virtual rig (no device)\n");
  } else {
    std::printf("  imu       %s %s, %g Hz (%s)\n", imu_bus_name(c.imu.bus), c.imu.device.c_str(),
                c.imu.rate_hz, presence(c.imu.device).c_str());
    const ImuDriver driver = app::resolve_imu_driver(c.imu);
    std::printf("  driver    %s%s\n", imu_driver_name(c.imu.driver),
                c.imu.driver != ImuDriver::kAuto ? ""
                : driver == ImuDriver::kIio      ? ": the kernel's inv-mpu6050 driver owns the chip (iio)"
                                                 : ": no inv-mpu6050 IIO device on this bus (direct)");
    if (driver == ImuDriver::kIio) {
      std::printf("  ready     the kernel's driver takes the chip's interrupt%s\n",
                  c.imu.data_ready ? " (imu.data_ready is not used)" : "");
    } else if (c.imu.data_ready) {
      const std::string chip = c.imu.data_ready->chip.rfind('/', 0) == 0 ? c.imu.data_ready->chip
                                                                         : "/dev/" + c.imu.data_ready->chip;
      std::printf("  ready     %s line %d (%s)\n", chip.c_str(), c.imu.data_ready->line,
                  presence(chip).c_str());
    } else {
      std::printf("  ready     no data-ready line: the FIFO is polled\n");
    }
  }
  for (const CameraConfig& cam : c.cameras) {
    const bool node = cam.backend == CameraBackend::kV4l2;
    std::printf("  camera    %s: %s %s, %dx%d at %g Hz%s\n", cam.name.c_str(),
                camera_backend_name(cam.backend), cam.device.c_str(), cam.width, cam.height, cam.rate_hz,
                node && !sim ? (" (" + presence(cam.device) + ")").c_str() : "");
  }
  if (c.cameras.empty()) std::printf("  cameras   none (no motion step)\n");
  const StorageConfig& st = c.storage;
  const std::string where = st.backend == StorageBackend::kI2cEeprom ? st.i2c_device : st.path;
  const std::string storage_problem = storage_type_problem(st);
  std::printf("  storage   %s %s, %d bytes at offset %d (%s)\n", storage_backend_name(st.backend),
              where.c_str(), st.size_bytes, st.offset_bytes,
              !storage_problem.empty() ? storage_problem.c_str()
              : st.backend == StorageBackend::kFile && !std::filesystem::exists(where)
                  ? "not written yet"
                  : presence(where).c_str());
  if (!storage_problem.empty()) {
    std::fprintf(stderr, "imucald: %s\n",
                 config_unusable_message(
                     options.config_path,
                     make_error(Errc::kInvalidArgument, "storage.path " + where + " is " + storage_problem))
                     .c_str());
    return kExitConfigUnusable;
  }
  std::printf("  state dir %s: %s\n", options.state_dir.c_str(), state_dir_note(options.state_dir).c_str());

  // The modules a session of this configuration loads. The solver's names are those of
  // calib/solve_module.hpp, which imucald does not include (tests/check_layering.sh).
  struct Needed {
    const char* name;
    const char* entry;
  };
  std::vector<Needed> needed = {{"imucal_solve", "imucal_solve_module"}};
  if (!c.cameras.empty()) needed.push_back({app::kCameraModule, app::kCameraModuleEntry});
  for (const CameraConfig& cam : c.cameras) {
    if (cam.backend == CameraBackend::kAravis && !sim)
      needed.push_back({drivers::camera::kAravisModule, drivers::camera::kAravisModuleEntry});
    if (cam.backend == CameraBackend::kLibcamera && !sim)
      needed.push_back({drivers::camera::kLibcameraModule, drivers::camera::kLibcameraModuleEntry});
  }
  if (sim) needed.push_back({sim::kVirtualRigModule, sim::kVirtualRigModuleEntry});
  std::string names;
  for (const Needed& m : needed) {
    if (names.find(m.name) != std::string::npos) continue;
    auto api = app::load_module_api(m.name, m.entry);
    if (!api.ok()) {
      std::fprintf(stderr, "imucald: %s\n", api.error().message.c_str());
      return 1;
    }
    names += (names.empty() ? "" : ", ") + std::string(m.name);
  }
  std::printf("  modules   %s: loaded\n", names.c_str());
  std::printf("Devices are not opened by --check, only looked for.\n");
  const std::vector<std::string> absent = absent_devices(c, sim, false);
  if (absent.empty()) return 0;
  if (options.devices_may_appear_later) {
    std::printf("Not on this machine yet: %s (--devices-may-appear-later: not an error).\n",
                absent_list(absent).c_str());
    return 0;
  }
  std::fprintf(stderr,
               "imucald: configured devices not on this machine: %s. Fix the paths in %s, or load their "
               "drivers at boot (/etc/modules-load.d; docs/service.md, \"Devices\"); give "
               "--devices-may-appear-later if they are expected later (exit %d)\n",
               absent_list(absent).c_str(), options.config_path.c_str(), kExitDeviceAbsent);
  return kExitDeviceAbsent;
}

Service::Service(ServiceOptions options)
    : options_(std::move(options)),
      signals_(io_, SIGINT, SIGTERM, SIGHUP),
      watchdog_timer_(io_),
      upgrade_timer_(io_) {
  // The calibrations' messages speak the session's words (core/option_words.hpp).
  set_option_vocabulary(&app::session::session_option_words);
}

Service::~Service() {
  runner_.reset();  // joins the worker before the devices go
  if (rig_) close_imu();
}

Status Service::init() {
  auto config = load_rig_config(options_.config_path);
  if (!config.ok()) {
    config_unusable_ = true;
    return make_error(config.error().code, config_unusable_message(options_.config_path, config.error()));
  }
  config_ = *config;
  if (config_.imu.bus == ImuBus::kSim) options_.sim = true;
  if (const auto absent = absent_devices(config_, options_.sim, true);
      !absent.empty() && !options_.devices_may_appear_later) {
    device_absent_ = true;
    return make_error(Errc::kNotFound,
                      "the IMU's device is not on this machine: " + absent_list(absent) + ". Fix " +
                          options_.config_path +
                          " or load the driver at boot (docs/service.md, \"Devices\"), " +
                          "then start the service again (systemctl restart imucald); the service is not "
                          "restarted until then (exit " +
                          std::to_string(kExitDeviceAbsent) + ")");
  }
  RigEvents events;
  events.samples = [this](std::span<const ImuSample> s) { on_samples(s); };
  events.imu_failed = [this](const Error& e) { imu_failed(e); };
  events.camera_readable = [this](std::size_t i) {
    if (cameras_streaming_ && i < cameras_.size()) read_camera(i);
  };
  events.notice = [this](const std::string& text) {
    spdlog::warn("{}", text);
    if (runner_) runner_->note(text);
  };
  events.worker_busy = [this] { return runner_ && runner_->busy(); };
  events.press_key = [this](session_msg::OperatorKey k) {
    if (auto s = runner_->engine().key(k); !s.ok())
      spdlog::warn("scripted operator: key {}: {}", session_msg::key_name(k), s.error().message);
  };
  rig_ = make_rig(config_, options_, io_, std::move(events));
  IMUCAL_TRY(open_imu());

  app::session::RunnerOptions ro;
  ro.state_dir = options_.state_dir;
  ro.post = [this](std::function<void()> f) { boost::asio::post(io_, std::move(f)); };
  ro.broadcast = [this](const session_msg::SessionMessage& m) { on_message(m); };
  ro.preflight = [this] { return preflight(); };
  ro.recover = [this]() -> Status {
    if (imu_state_ == DeviceState::kOpen) return {};
    return open_imu();
  };
  ro.complete_record = [config = config_](CalibrationRecord& record) -> Status {
    // A session without the motion step keeps the cameras the rig's record holds.
    auto stored = app::read_stored_calibration(config);
    if (!stored.ok()) {
      return make_error(stored.error().code,
                        "reading the stored record, to keep its cameras: " + stored.error().message);
    }
    const std::string kept = app::keep_stored_cameras(record, *stored);
    if (!kept.empty()) spdlog::info("{}", kept);
    return {};
  };
  ro.write_storage = [this](const CalibrationRecord& record) { return write_storage(record); };
  ro.warn = [](const std::string& text) { spdlog::warn("{}", text); };
  // The virtual rig's frames come as fast as it computes: they wait for the encoder.
  ro.frames_wait_for_encoder = rig_->simulated();
  ro.metadata = {{"rig_config", rig_config_to_json(config_)},
                 {"source", rig_->simulated() ? "sim" : "hardware"},
                 {"service", json{{"version", kVersion}, {"config", options_.config_path}}.dump(
                                 -1, ' ', false, nlohmann::json::error_handler_t::replace)}};
  ro.view_frame = [this](ViewFrame&& frame) { view_frame(std::move(frame)); };
  ro.view_watched = [this] { return live_ && live_->watchers() > 0; };
  ro.view_rate_hz = config_.live_view.frame_rate_hz;
  ro.view_width = config_.live_view.width;
  runner_ = std::make_unique<app::session::SessionRunner>(config_, stream_info_, ro);

  service::ControlServerOptions so;
  so.path = options_.socket_path;
  so.mode = options_.socket_mode;
  auto server = service::ControlServer::create(io_, so, *this);
  if (!server.ok()) return server.error().context("control socket " + options_.socket_path);
  server_ = std::move(*server);
  if (options_.live_view_port) {
    config_.live_view.enabled = true;
    config_.live_view.port = *options_.live_view_port;
    if (options_.live_view_address) config_.live_view.address = *options_.live_view_address;
  }
  const std::optional<int> passed = service::listening_socket_from_systemd();
  if (config_.live_view.enabled) {
    // The live view is not the calibration: a view that cannot open is said, and the service runs.
    if (auto s = open_live_view(passed); !s.ok()) spdlog::error("{}", s.error().message);
  } else if (passed) {
    spdlog::warn(
        "systemd passed a socket for the live view (imucald.socket), but live_view.enabled is not true in "
        "{}: the live view stays off",
        options_.config_path);
    ::close(*passed);
  }
  return {};
}

Status Service::open_live_view(std::optional<int> passed_socket) {
  auto token = service::make_token();
  if (!token.ok()) return token.error();
  // The token goes where only the service's user and group read it: the same people the
  // control socket lets in.
  std::error_code ec;
  std::filesystem::create_directories(options_.state_dir, ec);
  live_token_file_ = options_.state_dir + "/" + kLiveViewTokenFile;
  const std::string tmp = live_token_file_ + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << *token << "\n";
    out.close();
    if (!out) return make_error(Errc::kIo, "live view: cannot write its token to " + tmp);
  }
  std::filesystem::permissions(tmp,
                               std::filesystem::perms::owner_read | std::filesystem::perms::owner_write |
                                   std::filesystem::perms::group_read,
                               ec);
  if (!ec) std::filesystem::rename(tmp, live_token_file_, ec);
  if (ec) return make_error(Errc::kIo, "live view: its token file " + live_token_file_ + ": " + ec.message());
  service::LiveViewOptions lo;
  lo.address = config_.live_view.address;
  lo.port = static_cast<unsigned short>(config_.live_view.port);
  lo.listen_fd = passed_socket.value_or(-1);
  lo.token = *token;
  lo.version = kVersion;
  lo.rig = config_.name;
  for (const auto& c : config_.cameras) lo.cameras.push_back(c.name);
  lo.log = [](const std::string& text) { spdlog::info("live view: {}", text); };
  auto live = service::LiveViewServer::create(io_, lo, *this);
  if (!live.ok()) {
    if (passed_socket) return live.error();
    return make_error(live.error().code,
                      live.error().message +
                          ". Under its systemd unit imucald has no network of its own: there, enable the "
                          "socket unit instead (systemctl enable --now imucald.socket, then restart imucald; "
                          "docs/service.md, \"Live view\")");
  }
  live_ = std::move(*live);
  spdlog::info("live view on {} (the keys need the token in {})", live_->url(), live_token_file_);
  return {};
}

void Service::view_frame(ViewFrame&& frame) {
  if (!live_) return;
  if (runner_) write_view_truth(frame);
  auto png = app::session::view_frame_png(frame);
  if (!png.ok()) return;  // a frame the view misses; the recording has it
  live_->frame(std::move(frame), std::move(*png));
}

// The virtual rig's truth of each frame the view is sent, beside what was drawn on it: one line
// "camera t_ns x y x y ..." (full-size pixels, by point id, nan where not on the sensor) in the
// session folder's sim-view-truth.txt (docs/service.md, "Live view").
void Service::write_view_truth(const ViewFrame& frame) {
  const auto corners = rig_->truth_corners(frame.camera, frame.t_ns);
  if (!corners) return;
  std::ofstream out(runner_->session_dir() + "/sim-view-truth.txt", std::ios::app);
  out << frame.camera << ' ' << frame.t_ns;
  char xy[64];
  for (const Eigen::Vector2d& p : *corners) {
    std::snprintf(xy, sizeof xy, " %.3f %.3f", p.x(), p.y());
    out << xy;
  }
  out << '\n';
}

Status Service::open_imu() {
  close_imu();
  if (auto s = rig_->open_imu(); !s.ok()) {
    imu_state_ = DeviceState::kFailed;
    imu_error_ = s.error().message;
    return s;
  }
  stream_info_ = rig_->stream_info();
  imu_state_ = DeviceState::kOpen;
  if (!runner_ || !runner_->engine().running()) set_gyro_offsets(true);
  return {};
}

void Service::close_imu() {
  stop_cameras();
  rig_->close_imu();
  if (imu_state_ == DeviceState::kOpen) imu_state_ = DeviceState::kClosed;
}

void Service::on_samples(std::span<const ImuSample> samples) {
  samples_ += samples.size();
  runner_->on_samples(samples);
  sync_cameras();
  // The service's status every few seconds of a session (the engine's comes at step changes):
  // what the session has recorded, seen to grow while it waits at a prompt.
  if (runner_->engine().running()) {
    const auto now = std::chrono::steady_clock::now();
    if (now - last_status_sent_ >= kStatusInterval) {
      last_status_sent_ = now;
      const session_msg::Status now_status = status();
      server_->broadcast(now_status);
      if (live_) live_->broadcast(now_status);
    }
  }
  if (pending_start_ && samples_ > 0) {
    std::vector<std::string> steps = std::move(*pending_start_);
    pending_start_.reset();
    boost::asio::post(io_, [this, steps] {
      if (auto s = start(steps); !s.ok()) {
        spdlog::error("starting the session: {}", s.error().message);
        if (options_.start) {
          exit_code_ = 1;
          shutdown("the session could not start");
        }
      }
    });
  }
}

void Service::imu_failed(const Error& error) {
  if (quit_) return;
  ++imu_faults_;
  imu_state_ = DeviceState::kFailed;
  imu_error_ = error.message;
  spdlog::error("IMU: {}", error.message);
  const bool scripted = rig_->operator_presses_keys();
  close_imu();
  imu_state_ = DeviceState::kFailed;
  runner_->fault("imu", error.message);
  // The virtual rig's clock stopped with its IMU, and the scripted operator with it: it does
  // what it does on any fault (a script cannot plug the IMU back in), at once.
  if (scripted) {
    boost::asio::post(io_, [this] {
      if (auto s = runner_->engine().key(session_msg::OperatorKey::kAbort); !s.ok())
        spdlog::warn("scripted operator: abort: {}", s.error().message);
    });
  }
}

void Service::on_message(const session_msg::SessionMessage& m) {
  using session_msg::Outcome;
  server_->broadcast(m);
  if (live_) live_->broadcast(m);
  rig_->on_message(m);
  if (const auto* prompt = std::get_if<session_msg::Prompt>(&m)) {
    const std::string step = prompt->step ? session_msg::step_name(*prompt->step) : "";
    spdlog::info("[{}] {}", step, prompt->text);
    notifier_.status(step + ": " + prompt->text);
  } else if (const auto* message = std::get_if<session_msg::Message>(&m)) {
    if (message->level == session_msg::MessageLevel::kWarning) {
      spdlog::warn("{}", message->text);
    } else {
      spdlog::info("{}", message->text);
    }
  } else if (const auto* fault = std::get_if<session_msg::Fault>(&m)) {
    spdlog::warn("{}", fault->text);
  } else if (const auto* result = std::get_if<session_msg::ResultSummary>(&m)) {
    // The virtual rig's truth beside the result; the hardware has none.
    if (const std::string table = rig_->truth_report(*result); !table.empty()) {
      const std::string path = runner_->session_dir() + "/sim-truth.txt";
      std::ofstream(path) << "The session's result beside the virtual rig's truth\n" << table;
      spdlog::info("result beside the virtual rig's truth ({}):\n{}", path, table);
    }
  } else if (const auto* done = std::get_if<session_msg::Done>(&m)) {
    const std::string outcome = session_msg::outcome_name(done->outcome);
    spdlog::info("session {}: {}", outcome, done->text);
    set_gyro_offsets(true);  // the record on the storage now, new or not
    notifier_.status("idle: last session " + outcome);
    if (options_.exit_after_session) {
      exit_code_ = done->outcome == Outcome::kWritten || done->outcome == Outcome::kCompleted ? 0 : 1;
      boost::asio::post(io_, [this] { shutdown("the session ended"); });
    }
  }
}

void Service::set_gyro_offsets(bool from_record) {
  if (!config_.storage.program_gyro_offsets || !rig_->imu_open()) return;
  std::array<double, 3> bias{0.0, 0.0, 0.0};
  std::string source = "cleared (power-up zero) while a session records";
  if (from_record) {
    auto stored = app::read_stored_calibration(config_);
    if (!stored.ok() || !stored->record) {
      source = "cleared: no stored calibration";
    } else {
      const ImuRecord& imu = stored->record->imu;
      if (imu.input_units != "raw") {
        source = "cleared: the stored gyro bias is not in counts";
      } else {
        for (int i = 0; i < 3; ++i) bias[i] = imu.model.b_g[i];
        source = "the stored gyro bias (sequence " + std::to_string(stored->sequence) + ")";
      }
    }
  }
  // The stored bias is in output counts of the configured range; the driver converts it into
  // register counts (drivers::mpu6000::gyro_offset_register_for_bias).
  const auto range = drivers::mpu6000::gyro_range_for(config_.imu.gyro_range_dps);
  if (!range.ok()) {
    gyro_offsets_ = "not set: " + range.error().message;
    spdlog::error("gyro offset registers: {}", range.error().message);
    return;
  }
  auto current = rig_->read_offsets();
  if (!current.ok()) {
    gyro_offsets_ = "not set: " + current.error().message;
    spdlog::error("gyro offset registers: {}", current.error().message);
    return;
  }
  drivers::mpu6000::OffsetRegisters regs = *current;  // the accelerometer's factory trims stay
  for (int i = 0; i < 3; ++i) regs.gyro[i] = drivers::mpu6000::gyro_offset_register_for_bias(bias[i], *range);
  if (auto st = rig_->write_offsets(regs); !st.ok()) {
    gyro_offsets_ = "not set: " + st.error().message;
    spdlog::error("gyro offset registers: {}", st.error().message);
    return;
  }
  gyro_offsets_ = "[" + std::to_string(regs.gyro[0]) + " " + std::to_string(regs.gyro[1]) + " " +
                  std::to_string(regs.gyro[2]) + "] from " + source;
  spdlog::info("gyro offset registers: {}", gyro_offsets_);
}

app::session::PreflightReport Service::preflight() {
  app::session::PreflightReport r;
  const bool open = imu_state_ == DeviceState::kOpen;
  const SelfTest test = open ? rig_->self_test() : SelfTest{};
  r.devices.push_back(
      {"imu", open && test.ok(),
       open ? rig_->describe_imu() + ", " + test.text + ", " + std::to_string(samples_) + " samples so far" +
                  (config_.storage.program_gyro_offsets ? ", gyro offset registers " + gyro_offsets_
                                                        : std::string())
            : "not open: " + imu_error_,
       // The chip's self-test compares outputs with and without its test force: motion during
       // it spoils the comparison, the most common cause of a failure on a working chip.
       open && test.outcome == SelfTest::Outcome::kFailed
           ? "the self-test fails when the rig moves during it: hold the rig still on a steady surface"
           : std::string()});
  auto stored = app::read_stored_calibration(config_);
  if (!stored.ok()) {
    r.devices.push_back({"storage", false, storage_name(config_.storage) + ": " + stored.error().message,
                         stored.error().code == Errc::kNewerVersion ? app::kNewerRecordAdvice : ""});
  } else if (const std::string newer = app::newer_slot_on(*stored); !newer.empty()) {
    // Found now, not when the session's write is refused at its end.
    r.devices.push_back(
        {"storage", false, storage_name(config_.storage) + ": " + newer, app::kNewerRecordAdvice});
  } else {
    const std::string unwritable = storage_unwritable(config_.storage);
    r.devices.push_back(
        {"storage",
         unwritable.empty(),
         storage_name(config_.storage) +
             (unwritable.empty() ? ": readable and writable" : ": readable, not writable: " + unwritable),
         {}});
    if (stored->record) {
      r.stored = app::session::PreflightReport::Stored{
          *stored->record,
          "sequence " + std::to_string(stored->sequence) + " in slot " + drivers::slot_name(stored->slot) +
              (stored->record->created_utc.empty() ? "" : ", written " + stored->record->created_utc)};
    }
  }
  // Each camera opened and closed here; the motion step streams it.
  for (std::size_t i = 0; i < config_.cameras.size(); ++i) r.devices.push_back(rig_->check_camera(i));
  return r;
}

Result<std::string> Service::write_storage(const CalibrationRecord& record) {
  auto written = app::write_stored_calibration(config_, record);
  if (!written.ok()) return written.error();
  // Slot and sequence first: on a narrow console a long path is what gets cut.
  const std::string where = "slot " + std::string(drivers::slot_name(written->slot)) + ", sequence " +
                            std::to_string(written->sequence) + ", " + storage_name(config_.storage);
  spdlog::info("calibration written to {}, read back and verified", where);
  return where;
}

void Service::sync_cameras() {
  const bool want = runner_ && runner_->wants_frames();
  if (want && !cameras_streaming_) {
    if (auto s = start_cameras(); !s.ok()) {
      stop_cameras();
      runner_->fault("camera", s.error().message);
    }
  } else if (!want && cameras_streaming_) {
    stop_cameras();
  }
}

Status Service::start_cameras() {
  cameras_.clear();
  cameras_.resize(config_.cameras.size());
  cameras_streaming_ = true;
  for (std::size_t i = 0; i < config_.cameras.size(); ++i) {
    const CameraConfig& cc = config_.cameras[i];
    CameraSlot& slot = cameras_[i];
    auto camera = rig_->open_camera(i);
    if (!camera.ok()) return camera.error();
    slot.camera = std::move(*camera);
    if (auto s = slot.camera->start(); !s.ok()) return s.error().context("camera " + cc.name + ": starting");
    slot.state = DeviceState::kStreaming;
    IMUCAL_TRY(rig_->watch_camera(i, *slot.camera));
  }
  spdlog::info("cameras streaming for the motion step");
  return {};
}

void Service::stop_cameras() {
  if (!cameras_streaming_) return;
  cameras_streaming_ = false;
  rig_->unwatch_cameras();
  for (auto& slot : cameras_) {
    if (slot.camera) (void)slot.camera->stop();
    slot.camera.reset();
    if (slot.state == DeviceState::kStreaming) slot.state = DeviceState::kClosed;
  }
}

void Service::read_camera(std::size_t index) {
  CameraSlot& slot = cameras_[index];
  if (!slot.camera) return;
  for (;;) {
    auto frame = slot.camera->dequeue();
    if (!frame.ok()) {
      camera_failed(index, frame.error());
      return;
    }
    if (!frame->valid()) return;
    ++slot.frames;
    runner_->on_frame(index, *frame, slot.camera->timestamp_meaning());  // releases the buffer
    if (!cameras_streaming_) return;                                     // the step ended on this frame
  }
}

void Service::camera_failed(std::size_t index, const Error& error) {
  const std::string name = config_.cameras.at(index).name;
  spdlog::error("camera {}: {}", name, error.message);
  stop_cameras();
  CameraSlot& slot = cameras_[index];
  ++slot.faults;
  slot.state = DeviceState::kFailed;
  slot.error = error.message;
  runner_->fault(name, error.message);
}

/// Bytes the session folder's logs hold on disk (*.imulog and their SQLite -wal and -shm files).
static std::int64_t recorded_bytes(const std::string& dir) {
  if (dir.empty()) return 0;
  std::int64_t total = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    if (e.path().filename().string().find(".imulog") == std::string::npos) continue;
    std::error_code size_ec;
    const auto size = e.file_size(size_ec);
    if (!size_ec) total += static_cast<std::int64_t>(size);
  }
  return total;
}

session_msg::Status Service::status() {
  session_msg::Status s = runner_->engine().status();
  session_msg::ServiceStatus service;
  service.devices.imu = {imu_state_,
                         rig_->simulated(),
                         static_cast<std::int64_t>(samples_),
                         static_cast<std::int64_t>(imu_faults_),
                         stream_info_.rate_hz,
                         gyro_offsets_,
                         imu_error_};
  service.devices.storage = storage_name(config_.storage);
  for (std::size_t i = 0; i < config_.cameras.size(); ++i) {
    const CameraSlot* slot = i < cameras_.size() ? &cameras_[i] : nullptr;
    service.devices.cameras.push_back({config_.cameras[i].name, slot ? slot->state : DeviceState::kClosed,
                                       slot ? static_cast<std::int64_t>(slot->frames) : 0,
                                       slot ? static_cast<std::int64_t>(slot->faults) : 0,
                                       slot ? slot->error : ""});
  }
  service.session_dir = runner_->session_dir();
  service.version = kVersion;
  service.recorded_bytes = recorded_bytes(service.session_dir);
  if (live_) service.live_view = session_msg::LiveViewAddress{live_->url(), live_token_file_};
  s.service = std::move(service);
  return s;
}

std::vector<session_msg::SessionMessage> Service::snapshot() {
  auto s = runner_->engine().snapshot();
  if (!s.empty()) s[0] = status();
  return s;
}

Status Service::start(const std::vector<std::string>& steps) {
  if (imu_state_ != DeviceState::kOpen) {
    return make_error(Errc::kDevice,
                      "the IMU is not open (" + imu_error_ + "); check it and restart imucald");
  }
  std::vector<std::string> run = steps;
  if (run.empty()) {
    for (auto id : app::session::configured_steps(config_)) run.emplace_back(app::session::step_name(id));
  }
  if (samples_ == 0) {
    // Right after the service is ready the driver may still be bringing the chip up (its resets
    // take 200 ms), and a self-test then cannot run: the session starts with the first samples,
    // so that its preflight finds the chip streaming.
    if (pending_start_) {
      return make_error(Errc::kInvalidArgument,
                        "a session is already starting: it waits for the IMU's first samples");
    }
    // Steps the engine would refuse are refused now, not when the samples come.
    if (auto planned = runner_->engine().plan(run); !planned.ok()) return planned.error();
    pending_start_ = run;
    spdlog::info("the session starts with the IMU's first samples");
    return {};
  }
  rig_->session_starting();
  // The session calibrates the chip as it powers up: no bias removed inside it.
  set_gyro_offsets(false);
  if (auto s = runner_->start(run); !s.ok()) {
    set_gyro_offsets(true);
    return s;
  }
  spdlog::info("session started in {}", runner_->session_dir());
  return {};
}

Status Service::key(session_msg::OperatorKey key) { return runner_->engine().key(key); }

void Service::arm_watchdog() {
  const auto interval = notifier_.watchdog_interval();
  if (!interval) return;
  watchdog_timer_.expires_after(*interval / 2);
  watchdog_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) return;
    notifier_.watchdog();
    arm_watchdog();
  });
}

namespace {

/// Whether this process's program was replaced on disk: an upgrade renames the new file over the
/// old one, and /proc/self/exe then names the old one "... (deleted)".
bool program_replaced() {
  std::array<char, 4096> buf{};
  const ssize_t n = ::readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  return n > 0 && std::string_view(buf.data(), static_cast<std::size_t>(n)).ends_with(" (deleted)");
}

}  // namespace

void Service::arm_upgrade_check() {
  if (std::getenv("NOTIFY_SOCKET") == nullptr) return;
  upgrade_timer_.expires_after(std::chrono::seconds(2));
  upgrade_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec || quit_) return;
    if (!program_replaced()) return arm_upgrade_check();
    if (runner_->engine().running()) {
      if (!upgrade_noted_)
        spdlog::warn(
            "imucald's program was replaced (an upgrade): it restarts into the new version when the "
            "session ends");
      upgrade_noted_ = true;
      return arm_upgrade_check();
    }
    exit_code_ = kExitUpgraded;
    spdlog::warn(
        "its program was replaced (an upgrade) and no session runs: exit {}, which systemd restarts into "
        "the new version",
        kExitUpgraded);
    shutdown("an upgrade");
  });
}

void Service::shutdown(const std::string& why) {
  if (quit_) return;
  spdlog::info("stopping: {}", why);
  notifier_.stopping();
  if (runner_->engine().running()) runner_->engine().terminate("the service is stopping (" + why + ")");
  quit_ = true;
  rig_->stop();
  io_.stop();
}

int Service::run() {
  signals_.async_wait([this](const boost::system::error_code& ec, int sig) {
    if (ec) return;
    shutdown(sig == SIGTERM ? "SIGTERM" : sig == SIGHUP ? "SIGHUP" : "SIGINT");
  });
  arm_watchdog();
  arm_upgrade_check();
  // --start: once samples flow, so that the session starts on the rig's clock like one that
  // imucalctl starts.
  if (options_.start) pending_start_ = *options_.start;
  notifier_.ready();
  notifier_.status("idle");
  spdlog::info("imucald {} ready: rig '{}', socket {}", kVersion, config_.name, options_.socket_path);
  while (!quit_) {
    io_.restart();
    // Returns on shutdown, or on the IMU's error (then imu_failed() has closed it and a redo
    // reopens it).
    rig_->run();
  }
  // Let the worker finish a solve or a write that is under way, then close the log.
  runner_->drain();
  io_.restart();
  io_.poll();
  server_->close();
  if (live_) live_->close();
  return exit_code_;
}

}  // namespace imucal::imucald
