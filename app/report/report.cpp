// SPDX-License-Identifier: BSD-3-Clause
#include "app/report/report.hpp"

#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/report/builders.hpp"
#include "app/report/gnuplot.hpp"
#include "app/report/html.hpp"
#include "app/results/output.hpp"
#include "app/results/thermal_results.hpp"
#include "core/text_file.hpp"
#include "core/yaml_json.hpp"

namespace imucal::app::report {
namespace {

namespace fs = std::filesystem;

/// A private temporary folder for gnuplot's scripts and outputs, removed with its contents.
class WorkDir {
 public:
  static Result<WorkDir> create() {
    std::string tmpl = (fs::temp_directory_path() / "imucal-report-XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      return make_error(Errc::kIo,
                        "could not create a temporary folder under " + fs::temp_directory_path().string());
    return WorkDir(tmpl);
  }
  WorkDir(WorkDir&& o) noexcept : path_(std::move(o.path_)) { o.path_.clear(); }
  WorkDir& operator=(WorkDir&&) = delete;
  ~WorkDir() {
    std::error_code ec;
    if (!path_.empty()) fs::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  explicit WorkDir(std::string path) : path_(std::move(path)) {}
  std::string path_;
};

/// The result file: `path` itself, or result.json inside a folder (the camera-IMU output).
Result<std::string> result_file(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    const std::string inside = (fs::path(path) / "result.json").string();
    if (!fs::exists(inside, ec))
      return make_error(Errc::kNotFound, path + " is a folder without result.json: give a result JSON file");
    return inside;
  }
  if (!fs::exists(path, ec)) return make_error(Errc::kNotFound, path + " does not exist");
  return path;
}

Result<nlohmann::json> read_result(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error();
  try {
    return nlohmann::json::parse(*text);
  } catch (const nlohmann::json::exception&) {
  }
  // The thermal model is a YAML file (calibrate thermal -o).
  try {
    const YAML::Node y = YAML::Load(*text);
    if (y.IsMap() && y["format"] && y["format"].as<std::string>("") == kThermalFormat) return yaml_to_json(y);
    // The camera YAML (calibrate camera -o): its cameras and figures, not its views.
    if (y.IsMap() && y["cam0"]) {
      if (!y["cam0"].IsMap() || !y["cam0"]["imucal"])
        return make_error(Errc::kCorrupt,
                          path +
                              " is a camchain without imucal's figures (cam0.imucal: sigmas, residuals, "
                              "coverage), as Kalibr writes it: give the YAML or the --json of imucal "
                              "calibrate camera");
      return camera_chain_from_yaml(y);
    }
  } catch (const YAML::Exception&) {
  }
  return make_error(
      Errc::kCorrupt,
      path +
          " is not JSON: give the JSON of a result (calibrate static --json, allan --json, "
          "calibrate camera --json, calibrate camimu's folder), a camera YAML (calibrate camera -o) "
          "or a thermal model (calibrate thermal -o)");
}

Result<Document> build_document(ReportKind kind, const nlohmann::json& result, BuildContext& ctx) {
  // The builders read the JSON through at()/number(), which throw JsonError for a key that is
  // missing; nlohmann throws for a value of the wrong type. Both mean a damaged result file.
  try {
    switch (kind) {
      case ReportKind::kStatic:
        return static_document(result, ctx);
      case ReportKind::kAllan:
        return allan_document(result, ctx);
      case ReportKind::kCamera:
        return camera_document(result, ctx);
      case ReportKind::kCameraChain:
        return camera_chain_document(result, ctx);
      case ReportKind::kCamImu:
        return camimu_document(result, ctx);
      case ReportKind::kThermal:
        return thermal_document(result, ctx);
    }
  } catch (const JsonError& e) {
    return make_error(Errc::kCorrupt, ctx.result_path + ": " + e.message);
  } catch (const nlohmann::json::exception& e) {
    return make_error(Errc::kCorrupt, ctx.result_path + ": a value has the wrong type (" + e.what() + ")");
  }
  return make_error(Errc::kInternal, "unknown report kind");
}

/// Outputs are checked before any work: never the inputs, never an existing file without
/// overwrite; the PNG folder is created.
Status check_outputs(const ReportOptions& o, const std::string& result_path) {
  OutputPolicy policy{o.overwrite, {result_path}};
  if (!o.log_path.empty()) policy.inputs.push_back(o.log_path);
  IMUCAL_TRY(check_output(o.html_path, policy));
  if (o.png_dir.empty()) return {};
  std::error_code ec;
  fs::create_directories(o.png_dir, ec);
  if (ec || !fs::is_directory(o.png_dir, ec))
    return make_error(Errc::kIo, "could not create the folder " + o.png_dir + " for the PNG figures");
  return {};
}

/// The last line of gnuplot's message that says something, shortened.
std::string last_line_of(const std::string& text) {
  std::string last;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = std::min(text.find('\n', start), text.size());
    std::string line = text.substr(start, end - start);
    while (!line.empty() && (line.back() == ' ' || line.back() == '\r')) line.pop_back();
    // gnuplot names its script and line ("/tmp/.../x.svg.gp" line 13: ...): only the message counts.
    if (const std::size_t at = line.find(".gp\" line "); at != std::string::npos) {
      const std::size_t colon = line.find(": ", at);
      if (colon != std::string::npos) line = line.substr(colon + 2);
    }
    if (line.find_first_not_of(" ^") != std::string::npos) last = line;
    start = end + 1;
  }
  return last.size() > 200 ? last.substr(0, 200) + "..." : last;
}

/// Whether gnuplot's complaint is about the data (nothing plottable: empty series, values such
/// as 1e308) rather than about gnuplot itself (a broken installation, a terminal missing).
bool about_the_data(const std::string& message) {
  for (const char* what : {"range is invalid", "no valid points", "all points", "undefined value"})
    if (message.find(what) != std::string::npos) return true;
  return false;
}

/// Draws every figure as SVG for the page and, with a PNG folder, as PNG files.
Result<std::vector<std::string>> draw(const Document& doc, const ReportOptions& o, const std::string& work,
                                      ReportSummary& summary) {
  std::vector<std::string> html;
  const OutputPolicy policy{o.overwrite, {}};
  for (const auto& section : doc.sections) {
    for (const auto& fig : section.figures) {
      auto svg = render_figure(fig, FigureFormat::kSvg, work);
      if (!svg.ok() && svg.error().code == Errc::kInternal && about_the_data(svg.error().message)) {
        // gnuplot ran but drew nothing: the result's data for this figure (empty arrays, values
        // such as 1e308) are not plottable. The figure gives way to a note; the rest stands.
        const std::string why = last_line_of(svg.error().message);
        summary.warnings.push_back("figure '" + fig.title +
                                   "' not drawn: the result holds nothing gnuplot could plot for it (" + why +
                                   ")");
        html.push_back(missing_figure_html(fig, why));
        continue;
      }
      if (!svg.ok()) return svg.error();
      ++summary.figures;
      html.push_back(figure_html(fig, *svg));
      if (o.png_dir.empty()) continue;
      auto png = render_figure(fig, FigureFormat::kPng, work);
      if (!png.ok()) return png.error();
      const std::string path = (fs::path(o.png_dir) / (fig.id + ".png")).string();
      IMUCAL_TRY(write_text_file(path, *png, policy));
      summary.png_files.push_back(path);
    }
  }
  return html;
}

}  // namespace

const char* report_kind_name(ReportKind kind) {
  switch (kind) {
    case ReportKind::kStatic:
      return "static calibration";
    case ReportKind::kAllan:
      return "Allan deviation";
    case ReportKind::kCamImu:
      return "camera-IMU calibration";
    case ReportKind::kCamera:
      return "camera calibration";
    case ReportKind::kCameraChain:
      return "camera chain calibration";
    case ReportKind::kThermal:
      return "thermal calibration";
  }
  return "unknown";
}

Result<ReportKind> detect_report_kind(const nlohmann::json& r, const std::string& origin) {
  if (r.is_object()) {
    if (r.contains("static_intervals") && r.contains("accel") && r.contains("gyro"))
      return ReportKind::kStatic;
    if (r.contains("accelerometer") && r.contains("gyroscope") && r.contains("kalibr"))
      return ReportKind::kAllan;
    if (r.contains("cameras") && r.contains("imu") && r.contains("biases")) return ReportKind::kCamImu;
    if (r.contains("intrinsics") && r.contains("views") && r.contains("coverage_grid"))
      return ReportKind::kCamera;
    if (r.value("format", nlohmann::json()) == kThermalFormat) return ReportKind::kThermal;
    if (r.contains("cameras") && r["cameras"].is_array() && !r["cameras"].empty() &&
        r["cameras"][0].is_object() && r["cameras"][0].contains("intrinsics"))
      return ReportKind::kCameraChain;
  }
  return make_error(Errc::kCorrupt,
                    origin +
                        " is no result imucal writes: give the JSON of calibrate static "
                        "--json, allan --json, calibrate camera --json, the YAML of calibrate "
                        "camera -o, or the output folder of calibrate camimu");
}

Result<ReportSummary> write_report(const ReportOptions& o) {
  auto path = result_file(o.result_path);
  if (!path.ok()) return path.error();
  IMUCAL_TRY(check_outputs(o, *path));
  auto result = read_result(*path);
  if (!result.ok()) return result.error();
  auto kind = detect_report_kind(*result, *path);
  if (!kind.ok()) return kind.error();
  auto work = WorkDir::create();
  if (!work.ok()) return work.error();
  // gnuplot is checked before the log is read: a missing package is the first thing to fix.
  IMUCAL_TRY(check_gnuplot(work->path()));

  ReportSummary summary;
  summary.kind = *kind;
  BuildContext ctx{*path, o.log_path, {}, o.log_in_progress, o.log_name};
  auto doc = build_document(*kind, *result, ctx);
  if (!doc.ok()) return doc.error();
  auto figures = draw(*doc, o, work->path(), summary);
  if (!figures.ok()) return figures.error();
  summary.notes = std::move(ctx.notes);
  IMUCAL_TRY(write_text_file(o.html_path, page_html(*doc, *figures, o.generator), {o.overwrite, {}}));
  return summary;
}

}  // namespace imucal::app::report
