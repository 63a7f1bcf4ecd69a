// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The HTML side of a report: escaping, number formatting, tables, and the page that embeds the
// figures as base64 data URIs (no network, no external file).

#include <string>
#include <vector>

#include "app/report/gnuplot.hpp"

namespace imucal::app::report {

/// Escapes &, <, >, " and ' for HTML text and attribute values.
std::string escape(const std::string& text);

/// RFC 4648 base64 of `bytes`.
std::string base64(const std::string& bytes);

/// `value` with `digits` significant digits; "undetermined" for NaN, "-" for infinities.
std::string num(double value, int digits = 6);
/// "value ± sigma" with the sigma's two leading digits deciding the precision.
std::string with_sigma(double value, double sigma);
/// The same for a parameter that is estimated unless `fixed`: a sigma of zero or NaN of an
/// estimated parameter reads "sigma not determined", never "(fixed)".
std::string with_sigma(double value, double sigma, bool fixed);

/// A table: a header row and body rows of cell HTML (already escaped).
struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  std::string to_html() const;
};

/// A part of the report: a heading, HTML before the figures (tables, notes), the figures.
struct Section {
  std::string title;
  std::string html;
  std::vector<Figure> figures;
};

/// What a report holds before its figures are drawn.
struct Document {
  std::string title;
  std::string subtitle;               // what the report is of (plain text)
  std::vector<std::string> warnings;  // shown at the top (plain text)
  std::vector<Section> sections;

  int figure_count() const;
};

/// A figure as HTML: title, the image (an SVG as a data URI) and caption. When the image has
/// loaded, the page marks the figure with data-rendered="1" (checked by the browser test).
std::string figure_html(const Figure& figure, const std::string& svg);

/// A figure's place in the page when gnuplot could not draw it (`why`: gnuplot's message).
std::string missing_figure_html(const Figure& figure, const std::string& why);

/// The whole page: inline CSS, the warnings, the sections with the figures' HTML in order.
std::string page_html(const Document& doc, const std::vector<std::string>& figures_html,
                      const std::string& generator);

}  // namespace imucal::app::report
