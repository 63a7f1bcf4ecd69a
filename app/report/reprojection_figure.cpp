// SPDX-License-Identifier: BSD-3-Clause
// The reprojection-error figure shared by the camera and the camera-IMU reports.
#include <algorithm>
#include <cmath>

#include "app/report/builders.hpp"
#include "app/report/gnuplot.hpp"

namespace imucal::app::report {

Figure reprojection_figure(const std::string& id, const std::vector<ResidualSeries>& series,
                           const std::string& what) {
  Figure f;
  f.id = id;
  f.title = "Reprojection errors";
  f.height_px = 460;
  std::string s, scatter, hist, circles;
  std::vector<double> lengths;
  double extent = 0.0;
  for (std::size_t i = 0; i < series.size(); ++i) {
    const ResidualSeries& r = series[i];
    if (r.px.size() < 2) continue;
    std::vector<std::vector<double>> rows;
    for (std::size_t k = 0; k + 1 < r.px.size(); k += 2) {
      rows.push_back({r.px[k], r.px[k + 1], std::hypot(r.px[k], r.px[k + 1])});
      lengths.push_back(rows.back()[2]);
    }
    const std::string n = std::to_string(i);
    s += datablock("e" + n, rows);
    scatter += std::string(scatter.empty() ? "plot " : ", ") + "$e" + n +
               " using 1:2 with points pt 7 ps 0.25 lc rgb '" + r.colour + "' title " + gp_quote(r.name);
    hist += std::string(hist.empty() ? "plot " : ", ") + "$e" + n +
            " using (bin($3)):(1) smooth frequency with boxes lc rgb '" + r.colour + "' title " +
            gp_quote(r.name);
    if (r.loss_px > 0) {
      circles += "set object circle at 0,0 size " + num(r.loss_px, 8) + " fs empty border lc rgb '" +
                 r.colour + "' dashtype 2\n";
      extent = std::max(extent, r.loss_px);
    }
  }
  if (lengths.empty()) return {};
  // The axes cover the bulk (the 99.5th percentile, or the loss's scale if larger) so that a few
  // far outliers do not squeeze it into a dot; the caption counts what lies beyond.
  std::sort(lengths.begin(), lengths.end());
  extent = std::max(extent,
                    lengths[std::min(lengths.size() - 1, static_cast<std::size_t>(0.995 * lengths.size()))]);
  extent = std::max(extent * 1.25, 1e-3);
  const auto beyond =
      static_cast<std::size_t>(lengths.end() - std::upper_bound(lengths.begin(), lengths.end(), extent));
  const double width = extent / 40.0;
  f.caption =
      "Projected minus detected corner position (px): left, each corner, with the robust loss's scale "
      "dashed where there is one; right, the histogram of their lengths. " +
      what + " " + std::to_string(beyond) + " lie beyond the axes (" + num(extent, 3) + " px).";
  const std::string range = "[" + num(-extent, 8) + ":" + num(extent, 8) + "]";
  f.script = s + "bin(x) = " + num(width, 8) + " * (floor(x / " + num(width, 8) + ") + 0.5)\n" +
             "set multiplot layout 1,2\nset grid\nset key top right\nset size ratio -1\nset xrange " + range +
             "\nset yrange " + range + "\nset xlabel 'dx (px)'\nset ylabel 'dy (px)'\n" + circles + scatter +
             "\nunset object\nset size noratio\nset style fill solid 0.5 noborder\nset boxwidth " +
             num(width, 8) +
             "\nset xlabel '|e| (px)'\nset ylabel 'corners'\nset xrange [0:" + num(extent, 8) +
             "]\nset yrange [0:*]\n" + hist + "\nunset multiplot\n";
  return f;
}

}  // namespace imucal::app::report
