// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// Figures drawn by gnuplot (Debian package gnuplot-nox), run as a child process: a figure is a
// gnuplot script with its data inline (datablocks), rendered to SVG for the HTML report or to
// PNG (pngcairo) for --png-dir. docs/report.md says why a plotting program and not plots drawn
// by hand.

#include <string>
#include <vector>

#include "core/result.hpp"

namespace imucal::app::report {

/// One figure: `script` holds the datablocks and the plot commands; the terminal and the output
/// are set by render_figure, so the same script gives the SVG and the PNG.
struct Figure {
  std::string id;       // file name stem and HTML id, [a-z0-9_-]
  std::string title;    // shown above the figure
  std::string caption;  // shown below it (plain text)
  std::string script;
  int width_px = 960;
  int height_px = 420;
};

enum class FigureFormat { kSvg, kPng };

/// A gnuplot datablock `$name << EOD ... EOD` of rows of numbers (full precision).
std::string datablock(const std::string& name, const std::vector<std::vector<double>>& rows);

/// Quotes `text` for a gnuplot single-quoted string (titles, labels).
std::string gp_quote(const std::string& text);

/// Runs `gnuplot` (found on PATH) on the figure and returns the rendered file's bytes.
/// Errc::kUnsupported naming the Debian package when gnuplot is not installed; Errc::kInternal
/// with gnuplot's stderr when it fails or writes nothing; Errc::kIo when the temporary folder
/// cannot be used.
[[nodiscard]] Result<std::string> render_figure(const Figure& figure, FigureFormat format,
                                                const std::string& work_dir);

/// Checks that gnuplot can be started (`gnuplot --version`), before any work is done.
[[nodiscard]] Status check_gnuplot(const std::string& work_dir);

}  // namespace imucal::app::report
