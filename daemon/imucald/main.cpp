// SPDX-License-Identifier: BSD-3-Clause
// imucald: the on-rig calibration service (docs/service.md). Idle until a session is started
// (imucalctl start, or --start); a session runs the guided protocol of app/session.

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <sstream>

#include "core/threads.hpp"
#include "core/version.hpp"
#include "daemon/common/number_check.hpp"
#include "daemon/imucald/service_app.hpp"

/// --socket-mode into the options; false (said on stderr) when it is not a socket mode. Octal
/// digits only, permission bits only (no setuid, setgid or sticky bit), and read and write for
/// the owner: a socket its owner cannot use is a service nobody can reach.
static bool parse_socket_mode(const std::string& mode, imucal::imucald::ServiceOptions& o) {
  const bool octal =
      !mode.empty() && mode.size() <= 4 && mode.find_first_not_of("01234567") == std::string::npos;
  const unsigned value = octal ? static_cast<unsigned>(std::stoul(mode, nullptr, 8)) : 0u;
  if (!octal || value > 0777u || (value & 0600u) != 0600u) {
    std::fprintf(stderr,
                 "imucald: --socket-mode '%s' is not a socket mode: give octal permission bits like 0660 "
                 "(at most 0777, with read and write for the owner)\n",
                 mode.c_str());
    return false;
  }
  o.socket_mode = value;
  return true;
}

/// --live-view [ADDRESS:]PORT into the options; false (said on stderr) when it is not that.
static bool parse_live_view(const std::string& live_view, imucal::imucald::ServiceOptions& o) {
  const auto colon = live_view.rfind(':');
  const std::string port = colon == std::string::npos ? live_view : live_view.substr(colon + 1);
  const bool digits =
      !port.empty() && port.size() <= 5 && port.find_first_not_of("0123456789") == std::string::npos;
  const int value = digits ? std::stoi(port) : 0;
  if (value < 1 || value > 65535) {
    std::fprintf(stderr,
                 "imucald: --live-view '%s' is not [ADDRESS:]PORT: give a port 1..65535, as 8421 or "
                 "127.0.0.1:8421\n",
                 live_view.c_str());
    return false;
  }
  o.live_view_port = value;
  if (colon != std::string::npos) {
    std::string address = live_view.substr(0, colon);
    if (address.size() >= 2 && address.front() == '[' && address.back() == ']')
      address = address.substr(1, address.size() - 2);
    o.live_view_address = address;
  }
  return true;
}

int main(int argc, char** argv) {
  using imucal::imucald::Service;
  using imucal::imucald::ServiceOptions;
  imucal::limit_openmp_teams();  // before the solver modules load
  // The journal adds the time; a level prefix is enough.
  spdlog::set_default_logger(spdlog::stderr_color_mt("imucald"));
  spdlog::set_pattern("%^%l%$: %v");
  spdlog::set_level(spdlog::level::info);

  ServiceOptions o;
  CLI::App app{
      "imucald: the on-rig calibration service. It opens the rig's IMU and storage, listens on a Unix "
      "socket\n"
      "and runs guided calibration sessions that imucalctl starts and drives (docs/service.md)."};
  app.set_version_flag("--version", std::string("imucald ") + imucal::kVersion);
  app.add_option("--config", o.config_path, "The rig configuration")->capture_default_str();
  app.add_option("--socket", o.socket_path, "The control socket (JSON lines)")->capture_default_str();
  std::string mode = "0660";
  app.add_option("--socket-mode", mode, "Permissions of the control socket (octal)")->capture_default_str();
  app.add_option("--state-dir", o.state_dir, "Session folders go to STATE_DIR/sessions/")
      ->capture_default_str();
  app.add_flag("--sim", o.sim, "Use the virtual rig (also when the configuration says imu.bus: sim)");
  app.add_option("--time-scale", o.time_scale,
                 "Virtual rig: rig seconds per wall-clock second (0: as fast as it computes); when the "
                 "machine cannot keep up, the session and the journal say so")
      ->capture_default_str()
      ->check(imucal::cli::finite_number(imucal::cli::NumberSign::kNonNegative));
  app.add_option("--sim-operator", o.sim_operator,
                 "Virtual rig: 'motion' moves the rig as the prompts ask, 'full' also presses the keys "
                 "(a scripted operator); default: nobody moves it")
      ->check(CLI::IsMember({"motion", "full"}));
  app.add_option("--seed", o.seed, "Virtual rig: seed of its IMU errors and of the operator")
      ->capture_default_str();
  app.add_option(
         "--sim-unplug-camera", o.sim_unplug_camera_after,
         "Virtual rig: its cameras vanish (a yanked cable) after this many frames of the first motion "
         "step; for trying the fault path")
      ->check(imucal::cli::finite_number(imucal::cli::NumberSign::kPositive));
  app.add_option("--sim-unplug-imu", o.sim_unplug_imu_after_s,
                 "Virtual rig: its IMU stops answering (a yanked cable) this many seconds of rig time after "
                 "a session "
                 "starts; for trying the fault path")
      ->check(imucal::cli::finite_number(imucal::cli::NumberSign::kPositive));
  app.add_option(
         "--sim-cold-start", o.sim_cold_start_c,
         "Virtual rig: its die starts at this temperature, deg C, and warms towards 45 (time constant "
         "300 s), the biases moving with it: for trying the session's thermal step")
      ->check(CLI::Range(-40.0, 44.0));
  std::string start;
  auto* start_opt = app.add_option("--start", start,
                                   "Start a session at launch: 'default' for the configured steps, or a "
                                   "comma-separated list of steps");
  app.add_flag("--exit-after-session", o.exit_after_session,
               "Stop when the session ends (exit 0 when it wrote or completed, 1 otherwise)");
  bool check = false;
  app.add_flag("--check", check,
               "Read and validate the configuration, print what the service would use and load the "
               "modules it needs, opening no device; exit 0 when usable, 78 when the configuration is "
               "unusable, 69 when a configured device node is not on this machine, 1 when a module "
               "cannot be loaded");
  app.add_flag("--devices-may-appear-later", o.devices_may_appear_later,
               "A configured device node that is not there is no error: --check exits 0, and the service "
               "exits 1 (restarted by the unit) instead of 69 (not restarted) when the IMU's is missing");
  std::string live_view;
  app.add_option("--live-view", live_view,
                 "Serve the live view at [ADDRESS:]PORT (address 127.0.0.1 unless given), whatever the "
                 "configuration's live_view says: a web browser there shows each camera's frames, the "
                 "target found in them and the session's prompts (docs/service.md, \"Live view\")");
  bool quiet = false;
  app.add_flag("-q,--quiet", quiet, "Log warnings and errors only");
  app.footer(
      "Examples:\n"
      "  imucald --check                              # validate /etc/imucal/rig.yaml, exit 0/78/69\n"
      "  sudo systemctl enable --now imucald          # as the packaged service\n"
      "  imucald --sim --config /usr/share/imucal/examples/rig.yaml --socket /tmp/imucal-try/s.sock \\\n"
      "          --state-dir /tmp/imucal-try/state    # the virtual rig, for trying imucalctl attach");
  CLI11_PARSE(app, argc, argv);
  if (quiet) spdlog::set_level(spdlog::level::warn);
  if (!parse_socket_mode(mode, o)) return 2;
  if (!live_view.empty() && !parse_live_view(live_view, o)) return 2;
  if (check) return imucal::imucald::check_configuration(o);
  if (start_opt->count() > 0) {
    std::vector<std::string> steps;
    if (start != "default") {
      std::stringstream ss(start);
      for (std::string s; std::getline(ss, s, ',');)
        if (!s.empty()) steps.push_back(s);
    }
    o.start = steps;
  }

  Service service(o);
  if (auto s = service.init(); !s.ok()) {
    spdlog::error("{}", s.error().message);
    if (service.config_unusable()) return imucal::imucald::kExitConfigUnusable;
    if (service.device_absent()) return imucal::imucald::kExitDeviceAbsent;
    return s.error().code == imucal::Errc::kInvalidArgument ? 2 : 1;
  }
  return service.run();
}
