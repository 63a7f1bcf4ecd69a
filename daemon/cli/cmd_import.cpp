// SPDX-License-Identifier: BSD-3-Clause
// imucal import euroc|bag|rosbag2|ascii|csv: dataset formats into a session log (docs/datasets.md).

#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>

#include "app/results/output_checks.hpp"
#include "daemon/cli/command.hpp"
#include "log/dataset_io.hpp"

namespace imucal::cli {
namespace {

struct CommonOptions {
  std::string out_path;
  bool force = false;
};

struct RawOptions {
  std::string units;
  double rate_hz = 0.0;
  std::string accel_scale, accel_offset, gyro_scale, gyro_offset;
  bool no_unit_check = false;
};

void add_common(CLI::App* cmd, CommonOptions& o) {
  cmd->add_option("-o,--output", o.out_path, "Session log to write (.imulog)")->required()->check(kNonEmpty);
  cmd->add_flag("--force", o.force, "Replace the output if it exists");
}

void add_raw(CLI::App* cmd, RawOptions& o) {
  cmd->add_option("--units", o.units, "Units of the values: raw (device counts) or si (m/s^2, rad/s)")
      ->required()
      ->check(CLI::IsMember({"raw", "si"}));
  cmd->add_option("--rate", o.rate_hz, "Nominal sample rate in Hz (default: estimated from the timestamps)")
      ->check(kPositive);
  cmd->add_option("--accel-scale", o.accel_scale,
                  "Raw only: m/s^2 per count, S or Sx,Sy,Sz (default 9.80665/16384, MPU-6000 at +-2 g)")
      ->check(kNonEmpty);
  cmd->add_option("--accel-offset", o.accel_offset, "Raw only: counts at zero, O or Ox,Oy,Oz (default 0)")
      ->check(kNonEmpty);
  cmd->add_option("--gyro-scale", o.gyro_scale,
                  "Raw only: rad/s per count, S or Sx,Sy,Sz (default pi/180/131, MPU-6000 at +-250 deg/s)")
      ->check(kNonEmpty);
  cmd->add_option("--gyro-offset", o.gyro_offset, "Raw only: counts at zero rate, O or Ox,Oy,Oz (default 0)")
      ->check(kNonEmpty);
  cmd->add_flag("--no-unit-check", o.no_unit_check,
                "Skip the check that the values look like the units given with --units");
}

void apply_raw(const RawOptions& o, ImuUnits& units, AxisConversion& accel, AxisConversion& gyro) {
  units = o.units == "raw" ? ImuUnits::kRaw : ImuUnits::kSi;
  const bool any =
      !o.accel_scale.empty() || !o.accel_offset.empty() || !o.gyro_scale.empty() || !o.gyro_offset.empty();
  if (units == ImuUnits::kSi && any) {
    throw CliExit{kExitUsage,
                  "--accel-scale/--accel-offset/--gyro-scale/--gyro-offset apply to --units raw only"};
  }
  if (!o.accel_scale.empty()) accel.scale = parse_triple(o.accel_scale, "--accel-scale");
  if (!o.accel_offset.empty()) accel.offset = parse_triple(o.accel_offset, "--accel-offset");
  if (!o.gyro_scale.empty()) gyro.scale = parse_triple(o.gyro_scale, "--gyro-scale");
  if (!o.gyro_offset.empty()) gyro.offset = parse_triple(o.gyro_offset, "--gyro-offset");
  if ((accel.scale.array() == 0).any() || (gyro.scale.array() == 0).any()) {
    throw CliExit{kExitUsage, "a scale of 0 would erase the signal; give the unit per count"};
  }
}

/// Runs an import with a progress display and prints its summary. The log is never one of the
/// dataset's files (`inputs`) or inside its folder (`input_folder`), whatever --force says.
template <class F>
void run_import(const std::string& out_path, bool force, const std::vector<std::string>& inputs,
                const std::string& input_folder, F&& do_import) {
  if (auto s = app::check_not_input(out_path, inputs, {input_folder}); !s.ok()) fail(s.error());
  Progress progress("importing", 1.0);
  log::OutputOptions options;
  options.force = force;
  options.progress = [&progress](double fraction) { progress.update(fraction); };
  Result<log::ImportSummary> summary = do_import(options);
  progress.finish();
  if (!summary.ok()) fail(summary.error(), "import failed");
  const auto& s = *summary;
  std::ostringstream msg;
  msg.precision(6);
  msg << "imported " << s.imu_samples << " IMU samples";
  if (s.imu_streams > 1) msg << " in " << s.imu_streams << " streams";
  if (s.imu_samples > 0) {
    msg << " (" << s.rate_hz << " Hz, " << ns_to_s(s.t_last_ns - s.t_first_ns) << " s)";
  }
  if (s.camera_streams > 0) msg << " and " << s.frames << " frames from " << s.camera_streams << " cameras";
  msg << " into " << out_path;
  std::cout << msg.str() << "\n";
  for (const auto& note : s.notes) std::cout << "note: " << note << "\n";
}

/// `import bag` and `import rosbag2`: one importer, which reads both kinds.
void add_bag_import(CLI::App* import_cmd, const char* name, const char* arg, const char* description) {
  auto common = std::make_shared<CommonOptions>();
  auto in = std::make_shared<log::BagImport>();
  CLI::App* cmd = import_cmd->add_subcommand(name, description);
  cmd->add_option(arg, in->path,
                  std::string(name) == "bag" ? "The bag file" : "The rosbag2 folder or storage file")
      ->required();
  cmd->add_option("--topics", in->topics,
                  "Topics to import, as Kalibr names them (/cam0/image_raw /imu0); Imu topics become imu0, "
                  "imu1, ... and image topics cam0, cam1, ... in this order (default: every Imu, Image and "
                  "CompressedImage topic, by name)")
      ->expected(1, -1);
  cmd->add_flag("--bag-time", in->receive_time,
                "Stamp messages with the time the bag received them instead of their header.stamp");
  cmd->add_flag("--allow-damaged", in->allow_damaged,
                "Import the whole chunks of a bag that is cut short or damaged");
  add_common(cmd, *common);
  cmd->callback([common, in] {
    std::error_code ec;
    const bool folder = std::filesystem::is_directory(in->path, ec);
    run_import(common->out_path, common->force, folder ? std::vector<std::string>{} : std::vector{in->path},
               folder ? in->path : "",
               [&](const log::OutputOptions& o) { return log::import_bag(*in, common->out_path, o); });
  });
}

void setup(CLI::App& root) {
  CLI::App* import_cmd =
      root.add_subcommand("import",
                          "Import a dataset (EuRoC, ROS 1 and ROS 2 bags, ASCII accel/gyro files, CSV) "
                          "into a session log");
  import_cmd->require_subcommand(1);

  {
    auto common = std::make_shared<CommonOptions>();
    auto dir = std::make_shared<std::string>();
    CLI::App* cmd =
        import_cmd->add_subcommand("euroc", "EuRoC/ASL folder (DIR or DIR/mav0) with imuN/ and camN/");
    cmd->add_option("DIR", *dir, "Dataset folder")->required();
    add_common(cmd, *common);
    cmd->callback([common, dir] {
      run_import(common->out_path, common->force, {}, *dir,
                 [&](const log::OutputOptions& o) { return log::import_euroc(*dir, common->out_path, o); });
    });
  }
  add_bag_import(import_cmd, "bag", "BAG",
                 "ROS 1 bag (format 2.0; plain, bz2 or lz4 chunks), or a ROS 2 bag: sensor_msgs/Imu, Image, "
                 "CompressedImage");
  add_bag_import(import_cmd, "rosbag2", "DIR",
                 "ROS 2 bag: a rosbag2 folder (metadata.yaml; sqlite3 .db3 or mcap storage) or one .db3 or "
                 ".mcap file: sensor_msgs/msg/Imu, Image, CompressedImage");
  {
    auto common = std::make_shared<CommonOptions>();
    auto raw = std::make_shared<RawOptions>();
    auto in = std::make_shared<log::AsciiImport>();
    CLI::App* cmd = import_cmd->add_subcommand(
        "ascii", "Accelerometer and gyroscope text files with 't x y z' rows, t in seconds (imu_tk format)");
    cmd->add_option("--accel", in->accel_path, "Accelerometer file")->required();
    cmd->add_option("--gyro", in->gyro_path, "Gyroscope file")->required();
    add_raw(cmd, *raw);
    add_common(cmd, *common);
    cmd->callback([common, raw, in] {
      apply_raw(*raw, in->units, in->accel, in->gyro);
      in->rate_hz = raw->rate_hz;
      in->unit_check = !raw->no_unit_check;
      run_import(common->out_path, common->force, {in->accel_path, in->gyro_path}, "",
                 [&](const log::OutputOptions& o) { return log::import_ascii(*in, common->out_path, o); });
    });
  }
  {
    auto common = std::make_shared<CommonOptions>();
    auto raw = std::make_shared<RawOptions>();
    auto in = std::make_shared<log::CsvImport>();
    auto columns = std::make_shared<std::string>();
    auto time_unit = std::make_shared<std::string>("s");
    auto delimiter = std::make_shared<std::string>(",");
    auto temp_scale = std::make_shared<double>(0.0);
    auto temp_offset = std::make_shared<double>(0.0);
    CLI::App* cmd = import_cmd->add_subcommand("csv", "Generic CSV with a column mapping");
    cmd->add_option("FILE", in->path, "CSV file")->required();
    cmd->add_option("--columns", *columns,
                    "Column of each quantity, counting from 0: t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6[,temp=7]")
        ->required()
        ->check(kNonEmpty);
    cmd->add_option("--time-unit", *time_unit, "Unit of the time column: s, ms, us or ns (default s)")
        ->check(CLI::IsMember({"s", "ms", "us", "ns"}));
    cmd->add_option("--delimiter", *delimiter,
                    "Field separator: one character, or 'tab', or 'space' (any run of blanks); default ','")
        ->check(kNonEmpty);
    cmd->add_option("--skip-header", in->format.skip_header, "Lines to skip at the top (default 0)")
        ->check(kNonNegative);
    auto* ts =
        cmd->add_option("--temp-scale", *temp_scale,
                        "Temperature: deg C = scale * value + offset (default 1, or 1/340 for raw, the "
                        "MPU-6000's)")
            ->check(kFinite);
    auto* to = cmd->add_option("--temp-offset", *temp_offset,
                               "Temperature offset in deg C (default 0, or 36.53 for raw, the MPU-6000's)")
                   ->check(kFinite);
    add_raw(cmd, *raw);
    add_common(cmd, *common);
    cmd->callback([=] {
      auto cols = log::parse_csv_columns(*columns);
      if (!cols.ok()) fail(cols.error());  // kInvalidArgument: a usage error, with the --columns hint
      in->format.columns = *cols;
      in->format.time_unit = *log::parse_time_unit(*time_unit);
      if (*delimiter == "tab" || *delimiter == "\\t" || *delimiter == "\t") {
        in->format.delimiter = '\t';
      } else if (*delimiter == "space" || *delimiter == " ") {
        in->format.delimiter = ' ';
      } else if (delimiter->size() == 1) {
        in->format.delimiter = (*delimiter)[0];
      } else {
        throw CliExit{kExitUsage, "--delimiter: '" + *delimiter + "' is not one character, 'tab' or 'space'"};
      }
      apply_raw(*raw, in->units, in->accel, in->gyro);
      in->rate_hz = raw->rate_hz;
      in->unit_check = !raw->no_unit_check;
      const bool raw_units = in->units == ImuUnits::kRaw;
      in->temperature_scale = ts->count() ? *temp_scale : (raw_units ? 1.0 / 340.0 : 1.0);
      in->temperature_offset = to->count() ? *temp_offset : (raw_units ? 36.53 : 0.0);
      run_import(common->out_path, common->force, {in->path}, "",
                 [&](const log::OutputOptions& o) { return log::import_csv(*in, common->out_path, o); });
    });
  }
}

const CommandRegistrar registrar(40, setup);

}  // namespace
}  // namespace imucal::cli
