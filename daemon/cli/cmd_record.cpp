// imucal record: acquire the rig's MPU-6000 into a session log, on hardware (spidev / i2c-dev,
// data-ready through libgpiod) or, with --sim, through the same driver and acquisition code
// against the register-level emulator (docs/acquisition.md).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>
#include <string>

#include "acquisition/mounting.hpp"
#include "acquisition/recorder.hpp"
#include "core/rig_config.hpp"
#include "daemon/cli/command.hpp"
#include "drivers/bus/i2cdev_bus.hpp"
#include "drivers/bus/spidev_bus.hpp"
#include "drivers/gpio/gpiod_line.hpp"
#include "drivers/mpu6000/mpu6000.hpp"
#include "drivers/sim/imu_model.hpp"
#include "drivers/sim/motion.hpp"
#include "drivers/sim/mpu6000_emulator.hpp"
#include "drivers/sim/sim_data_ready.hpp"

namespace imucal::cli {
namespace {

namespace mpu = drivers::mpu6000;

struct RecordArgs {
  std::string config_path;
  std::string out_path;
  double duration_s = 10.0;
  bool sim = false;
  bool force = false;
  bool json = false;
  std::uint64_t seed = 1;
  double sim_clock_ppm = -15'000.0;
  double sim_jitter_us = 30.0;
};

template <class T>
T take(Result<T> r, const std::string& what) {
  if (!r.ok()) fail(r.error(), what);
  return std::move(r).value();
}

/// Like take(), but any failure to open or probe hardware ends with the device exit code (a
/// missing node is a device problem here, not a missing input file).
template <class T>
T take_device(Result<T> r, const std::string& what) {
  if (!r.ok()) throw CliExit{kExitDevice, what + ": " + r.error().message};
  return std::move(r).value();
}

/// Driver settings from the rig configuration (already validated by the loader).
mpu::Settings settings_from(const ImuConfig& imu) {
  mpu::Settings s;
  s.bus = imu.bus == ImuBus::kI2c ? mpu::BusKind::kI2c : mpu::BusKind::kSpi;
  switch (imu.accel_range_g) {
    case 2:
      s.accel_range = mpu::AccelRange::k2g;
      break;
    case 4:
      s.accel_range = mpu::AccelRange::k4g;
      break;
    case 8:
      s.accel_range = mpu::AccelRange::k8g;
      break;
    default:
      s.accel_range = mpu::AccelRange::k16g;
      break;
  }
  switch (imu.gyro_range_dps) {
    case 250:
      s.gyro_range = mpu::GyroRange::k250dps;
      break;
    case 500:
      s.gyro_range = mpu::GyroRange::k500dps;
      break;
    case 1000:
      s.gyro_range = mpu::GyroRange::k1000dps;
      break;
    default:
      s.gyro_range = mpu::GyroRange::k2000dps;
      break;
  }
  s.dlpf_cfg = 1;
  for (std::uint8_t i = 0; i < 7; ++i) {
    if (kMpu6000DlpfHz[i] == imu.dlpf_hz) s.dlpf_cfg = i;
  }
  const double base_hz = s.gyro_rate_hz();
  s.smplrt_div = static_cast<std::uint8_t>(std::clamp(std::lround(base_hz / imu.rate_hz) - 1, 0L, 255L));
  // Read about every millisecond, or every sample at lower rates, with room for one late read.
  const double period_ns = 1e9 / s.sample_rate_hz();
  const double per_read = std::max(1.0, std::round(s.sample_rate_hz() / 1000.0));
  s.read_interval_ns = static_cast<TimeNs>(2.0 * per_read * period_ns);
  s.config_speed_hz = static_cast<std::uint32_t>(imu.spi_config_speed_hz);
  s.fifo_speed_hz = static_cast<std::uint32_t>(imu.spi_data_speed_hz);
  return s;
}

/// Mean of max(0, N(mean, sigma)): the simulated line clips its latency at zero, which moves
/// the mean edge latency above the nominal one.
TimeNs clipped_latency_mean_ns(TimeNs mean_ns, TimeNs sigma_ns) {
  if (sigma_ns <= 0) return std::max<TimeNs>(0, mean_ns);
  const double m = static_cast<double>(mean_ns), s = static_cast<double>(sigma_ns), a = m / s;
  const double cdf = 0.5 * std::erfc(-a / std::sqrt(2.0));
  const double pdf = std::exp(-0.5 * a * a) / std::sqrt(2.0 * std::numbers::pi);
  return static_cast<TimeNs>(std::llround(m * cdf + s * pdf));
}

/// The emulator's clock, seen by the acquisition loop.
class SimClock final : public acq::AcquisitionClock {
 public:
  explicit SimClock(sim::Mpu6000Emulator& emu) : emu_(emu) {}
  TimeNs now_ns() override { return emu_.now_ns(); }
  void sleep_until(TimeNs t_ns) override {
    if (t_ns > emu_.now_ns()) emu_.advance_to(t_ns);
  }

 private:
  sim::Mpu6000Emulator& emu_;
};

void print_summary(const RecordArgs& a, const acq::RecordSummary& s, const std::string& extra_json) {
  if (a.json) {
    nlohmann::json j;
    j["log"] = a.out_path;
    j["samples"] = s.samples;
    j["duration_s"] = s.duration_s;
    j["rate_hz"] = s.rate_hz;
    j["period_error_ppm"] = s.period_error_ppm;
    j["gaps"] = s.timing.gaps;
    j["samples_lost"] = s.timing.samples_lost;
    j["edges_rejected"] = s.timing.edges_rejected;
    j["log_dropped"] = s.stream.log_dropped;
    if (!extra_json.empty()) j["sim"] = nlohmann::json::parse(extra_json);
    std::cout << j.dump(2) << "\n";
    return;
  }
  std::printf(
      "recorded %llu samples over %.3f s (%.3f Hz measured; chip rate %+.0f ppm from nominal) to %s\n",
      static_cast<unsigned long long>(s.samples), s.duration_s, s.rate_hz, s.period_error_ppm,
      a.out_path.c_str());
  std::printf("timing: %llu edges rejected, %llu gaps, %llu samples lost; log: %llu dropped\n",
              static_cast<unsigned long long>(s.timing.edges_rejected),
              static_cast<unsigned long long>(s.timing.gaps),
              static_cast<unsigned long long>(s.timing.samples_lost),
              static_cast<unsigned long long>(s.stream.log_dropped));
}

void run_record(const RecordArgs& a) {
  if (!(a.duration_s > 0.0) || !std::isfinite(a.duration_s)) {
    throw CliExit{kExitUsage, "--duration must be a positive number of seconds"};
  }
  const RigConfig config = take(load_rig_config(a.config_path), "reading the rig configuration");
  const bool sim = a.sim || config.imu.bus == ImuBus::kSim;
  const acq::MountingMap mounting =
      take(acq::MountingMap::from_rotation(config.imu.R_rig_imu), "imu mounting in " + a.config_path);
  const mpu::Settings settings = settings_from(config.imu);
  std::string why;
  if (!settings.validate(&why)) throw CliExit{kExitUsage, "imu settings in " + a.config_path + ": " + why};

  acq::RecordOptions ro;
  ro.log_path = a.out_path;
  ro.overwrite = a.force;
  ro.duration_s = a.duration_s;
  ro.metadata.emplace_back("rig_config", rig_config_to_json(config));
  ro.metadata.emplace_back("source", sim ? "sim" : "hardware");
  Progress progress("recording", a.duration_s);
  ro.progress = [&](double f) { progress.update(f * a.duration_s); };

  acq::AcquisitionOptions ao;
  if (sim) {
    // The virtual rig at rest (gravity, sensor noise, warm-up), read through the emulated chip.
    sim::StillOptions still;
    still.duration_s = a.duration_s + 30.0;
    auto trajectory = take(sim::make_still(still, a.seed), "simulated rig");
    sim::ImuModelParams params = sim::ImuModelParams::draw(a.seed);
    auto simulator = std::make_shared<sim::ImuSimulator>(params, a.seed);
    sim::EmulatorOptions eo;
    eo.bus = settings.bus;
    eo.timing = settings.bus == mpu::BusKind::kSpi ? sim::BusTiming::spi() : sim::BusTiming::i2c();
    eo.clock_ppm = a.sim_clock_ppm;
    eo.start_ns = 100 * kNsPerSecond;
    eo.record_truth = false;
    const TimeNs t0 = eo.start_ns;
    TimeNs last_t = t0;
    const sim::Trajectory* traj = trajectory.get();
    sim::SensorSource source = [&, traj, simulator](TimeNs t_ns) {
      const TimeNs t = std::max(t_ns, last_t);
      const double dt = ns_to_s(t - last_t);
      last_t = t;
      const TimeNs rel = std::clamp<TimeNs>(t - t0, traj->start_ns(), traj->end_ns());
      const auto d = simulator->sample_si(rel, traj->at(rel), dt);
      sim::SensorReading r;
      r.specific_force = d.accel_si;
      r.angular_rate = d.gyro_si;
      r.temperature_c = d.temperature_c;
      return r;
    };
    sim::Mpu6000Emulator emu(source, eo);
    sim::DataReadyTiming dt;
    dt.sigma_ns = static_cast<TimeNs>(a.sim_jitter_us * 1e3);
    dt.seed = a.seed;
    sim::SimDataReadyLine line(emu, dt);
    emu.connect(line);
    mpu::Mpu6000 driver(emu, settings);
    if (auto s = driver.probe(); !s.ok()) fail(s.error(), "simulated MPU-6000");
    SimClock clock(emu);
    ao.timestamps.edge_latency_ns = clipped_latency_mean_ns(dt.latency_ns, dt.sigma_ns);
    ao.timestamps.edge_jitter_ns = std::max<TimeNs>(1, dt.sigma_ns);
    acq::ImuAcquisition acquisition(driver, &line, clock, mounting, ao);
    ro.stream_info = mpu::make_stream_info(settings, "sim");
    ro.stream_info.name = "imu0";
    nlohmann::json sim_meta = {{"seed", a.seed},
                               {"clock_ppm", a.sim_clock_ppm},
                               {"edge_latency_ns", dt.latency_ns},
                               {"edge_jitter_ns", dt.sigma_ns},
                               {"script", "still"}};
    ro.metadata.emplace_back("sim", sim_meta.dump());
    const auto summary = take(acq::record_imu_session(acquisition, driver, ro), "recording");
    progress.finish();
    print_summary(a, summary, sim_meta.dump());
    return;
  }

  // Hardware.
  std::unique_ptr<drivers::RegisterBus> bus;
  if (config.imu.bus == ImuBus::kSpi) {
    drivers::SpidevOptions so;
    so.config_speed_hz = static_cast<std::uint32_t>(config.imu.spi_config_speed_hz);
    so.max_speed_hz = static_cast<std::uint32_t>(config.imu.spi_data_speed_hz);
    bus = take_device(drivers::SpidevBus::open(config.imu.device, so), "opening the IMU bus");
  } else {
    drivers::I2cDevOptions io;
    io.address = static_cast<std::uint8_t>(config.imu.i2c_address);
    bus = take_device(drivers::I2cDevBus::open(config.imu.device, io), "opening the IMU bus");
  }
  std::unique_ptr<drivers::DataReadyLine> line;
  if (config.imu.data_ready) {
    drivers::GpiodLineOptions lo;
    lo.chip = config.imu.data_ready->chip;
    lo.line = std::to_string(config.imu.data_ready->line);
    line = take_device(drivers::GpiodDataReadyLine::open(lo), "opening the data-ready line");
  }
  mpu::Mpu6000 driver(*bus, settings);
  if (auto s = driver.probe(); !s.ok()) {
    throw CliExit{kExitDevice, "MPU-6000 on " + bus->name() + ": " + s.error().message};
  }
  acq::MonotonicClock clock;
  acq::ImuAcquisition acquisition(driver, line.get(), clock, mounting, ao);
  ro.stream_info = mpu::make_stream_info(settings, "mpu6000@" + bus->name());
  ro.stream_info.name = "imu0";
  const auto summary = take(acq::record_imu_session(acquisition, driver, ro), "recording");
  progress.finish();
  print_summary(a, summary, "");
}

const CommandRegistrar kRegistrar(20, [](CLI::App& root) {
  auto args = std::make_shared<RecordArgs>();
  auto* cmd = root.add_subcommand(
      "record",
      "Record the rig's IMU into a session log: timestamps reconstructed per sample from the data-ready "
      "interrupt, gaps flagged. --sim records the virtual rig through the same driver code.");
  cmd->add_option("--config", args->config_path, "Rig configuration (YAML, docs/config.md)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", args->out_path, "Session log to write (.imulog)")->required();
  cmd->add_option("--duration", args->duration_s, "Seconds of samples to record (default 10)");
  cmd->add_flag("--sim", args->sim,
                "Record the simulated rig (MPU-6000 register emulator, data-ready jitter) instead of "
                "hardware; simulated time runs as fast as the host allows");
  cmd->add_option("--seed", args->seed, "Simulation: random seed (default 1)");
  cmd->add_option("--sim-clock-ppm", args->sim_clock_ppm,
                  "Simulation: the chip oscillator's error in ppm (default -15000, a 1.5 % slow chip)")
      ->check(CLI::Range(-80'000.0, 80'000.0));
  cmd->add_option("--sim-jitter-us", args->sim_jitter_us,
                  "Simulation: standard deviation of the data-ready edge latency, us (default 30)")
      ->check(CLI::Range(0.0, 1000.0));
  cmd->add_flag("--force", args->force, "Replace the log if it exists");
  cmd->add_flag("--json", args->json, "Print the summary as JSON");
  cmd->callback([args] { run_record(*args); });
});

}  // namespace
}  // namespace imucal::cli
