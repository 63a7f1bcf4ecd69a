// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// imucald's parts: the rig (daemon/imucald/rig.hpp: its hardware on the Boost.Asio event loop,
// or the virtual rig on accelerated time, chosen once at start-up), the session runner (app/session), the
// control socket (daemon/service) and systemd's notifications, on one io_context. docs/service.md.
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/session/session_runner.hpp"
#include "core/rig_config.hpp"
#include "daemon/imucald/rig.hpp"
#include "daemon/imucald/service_options.hpp"
#include "daemon/service/control_server.hpp"
#include "daemon/service/live_view_server.hpp"
#include "daemon/service/notify.hpp"
#include "daemon/service/session_host.hpp"
#include "drivers/camera/camera.hpp"

namespace imucal::imucald {

/// imucald's exit status when its configuration cannot be used (sysexits.h EX_CONFIG): the file is
/// missing, unreadable or invalid. The unit lists it in RestartPreventExitStatus=, so systemd
/// does not restart the service until the file is fixed.
inline constexpr int kExitConfigUnusable = 78;

/// imucald's exit status when a device of its configuration is not on this machine (sysexits.h
/// EX_UNAVAILABLE): `--check` when any configured device node is absent, the service when the
/// IMU's is. The unit lists it in RestartPreventExitStatus= too: a device that is not there does
/// not come back by restarting every two seconds. `--devices-may-appear-later` turns both off
/// (--check reports the nodes and exits 0; the service exits 1, which the unit restarts until
/// its start limit).
inline constexpr int kExitDeviceAbsent = 69;

/// imucald's exit status when its program was replaced on disk (a package upgrade) while it ran
/// (sysexits.h EX_TEMPFAIL): under systemd it exits with it once no session runs, and the unit's
/// Restart=on-failure starts the new version. A session in progress is never cut short by it.
inline constexpr int kExitUpgraded = 75;

/// The file, in the state folder, that holds the live view's token (mode 0640).
inline constexpr const char* kLiveViewTokenFile = "live-view.token";

/// The configured device nodes that are not on this machine, each as "KEY PATH" ("imu.device
/// /dev/spidev0.0"); none for the virtual rig (`sim`). `imu_only`: only those the service opens
/// when it starts (the IMU's bus node and data-ready chip; not a node the kernel's inv-mpu6050
/// driver owns). Otherwise also the V4L2 cameras' nodes and the nvmem or i2c-eeprom storage.
std::vector<std::string> absent_devices(const RigConfig& config, bool sim, bool imu_only);

/// The error for a configuration that cannot be used: what is wrong and the file to edit.
std::string config_unusable_message(const std::string& config_path, const Error& error);

/// imucald --check, a dry run: reads and validates the configuration, prints what the service
/// would use (IMU, cameras, storage, state folder; whether their device nodes exist on this
/// machine) and loads the modules the configuration needs, opening no device. Returns the exit
/// status: 0 usable, kExitConfigUnusable, kExitDeviceAbsent when a configured device node is not
/// on this machine (unless options.devices_may_appear_later), 1 when a module cannot be loaded (a
/// broken installation).
int check_configuration(const ServiceOptions& options);

class Service final : public service::SessionHost {
 public:
  explicit Service(ServiceOptions options);
  ~Service() override;
  /// Loads the configuration, opens the IMU and the socket; errors say what to fix.
  [[nodiscard]] Status init();
  /// After a failed init(): whether it failed on the configuration (exit kExitConfigUnusable).
  [[nodiscard]] bool config_unusable() const { return config_unusable_; }
  /// After a failed init(): whether it failed on an IMU device node that is not on this machine
  /// (exit kExitDeviceAbsent; never with devices_may_appear_later).
  [[nodiscard]] bool device_absent() const { return device_absent_; }
  /// Runs the event loop until SIGTERM/SIGINT (or the session's end with exit_after_session).
  /// Returns the process exit code.
  int run();

  // service::SessionHost
  session_msg::Status status() override;
  std::vector<session_msg::SessionMessage> snapshot() override;
  Status start(const std::vector<std::string>& steps) override;
  Status key(session_msg::OperatorKey key) override;

 private:
  Status open_imu();
  void close_imu();
  /// Streams the cameras while the session's motion step runs, and only then.
  void sync_cameras();
  Status start_cameras();
  void stop_cameras();
  void read_camera(std::size_t index);
  void camera_failed(std::size_t index, const Error& error);
  void on_message(const session_msg::SessionMessage& message);
  /// The live view (config live_view, or --live-view): its token written to the state folder,
  /// then its server, on the socket systemd passed (imucald.socket) or bound here.
  Status open_live_view(std::optional<int> passed_socket);
  /// A camera's frame for the live view, encoded.
  void view_frame(ViewFrame&& frame);
  void write_view_truth(const ViewFrame& frame);
  void on_samples(std::span<const ImuSample> samples);
  void imu_failed(const Error& error);
  app::session::PreflightReport preflight();
  /// Writes, syncs and verifies the record; returns where it went (storage, slot, sequence).
  Result<std::string> write_storage(const CalibrationRecord& record);
  /// storage.program_gyro_offsets: the stored gyro bias into the chip's gyro offset registers
  /// (`from_record`), or the registers back to their power-up zero (before a session records).
  void set_gyro_offsets(bool from_record);
  void arm_watchdog();
  /// Under systemd (NOTIFY_SOCKET set): every few seconds, whether the program was replaced on
  /// disk; if so, exits with kExitUpgraded once no session runs.
  void arm_upgrade_check();
  void shutdown(const std::string& why);

  ServiceOptions options_;
  RigConfig config_;
  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer watchdog_timer_, upgrade_timer_;
  bool upgrade_noted_ = false;
  service::Notifier notifier_;
  std::unique_ptr<service::ControlServer> server_;
  std::unique_ptr<service::LiveViewServer> live_;
  std::string live_token_file_;
  std::unique_ptr<app::session::SessionRunner> runner_;
  ImuStreamInfo stream_info_;
  // The rig: hardware or virtual, chosen in init().
  std::unique_ptr<Rig> rig_;
  // The cameras: built when the motion step starts, closed when it ends.
  struct CameraSlot {
    std::unique_ptr<drivers::camera::Camera> camera;
    std::uint64_t frames = 0, faults = 0;
    session_msg::DeviceState state = session_msg::DeviceState::kClosed;
    std::string error;
  };
  std::vector<CameraSlot> cameras_;
  bool cameras_streaming_ = false;
  std::string gyro_offsets_ = "off";  // what the gyro offset registers hold, for status and preflight
  session_msg::DeviceState imu_state_ = session_msg::DeviceState::kClosed;
  std::string imu_error_;
  std::uint64_t samples_ = 0, imu_faults_ = 0;
  /// A session asked for before the IMU's first samples (--start, or a client right after the
  /// service is ready): it starts with them.
  std::optional<std::vector<std::string>> pending_start_;
  static constexpr std::chrono::seconds kStatusInterval{5};
  std::chrono::steady_clock::time_point last_status_sent_{};
  bool quit_ = false;
  bool config_unusable_ = false;
  bool device_absent_ = false;
  int exit_code_ = 0;
};

}  // namespace imucal::imucald
