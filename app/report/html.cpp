// SPDX-License-Identifier: BSD-3-Clause
#include "app/report/html.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace imucal::app::report {

std::string escape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string base64(const std::string& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = static_cast<unsigned char>(bytes[i]) << 16 |
                       static_cast<unsigned char>(bytes[i + 1]) << 8 |
                       static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[v >> 18 & 63];
    out += kAlphabet[v >> 12 & 63];
    out += kAlphabet[v >> 6 & 63];
    out += kAlphabet[v & 63];
  }
  if (i < bytes.size()) {
    unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += kAlphabet[v >> 18 & 63];
    out += kAlphabet[v >> 12 & 63];
    out += i + 1 < bytes.size() ? kAlphabet[v >> 6 & 63] : '=';
    out += '=';
  }
  return out;
}

std::string num(double value, int digits) {
  if (std::isnan(value)) return "undetermined";
  if (std::isinf(value)) return "-";
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, value);
  return buf;
}

std::string with_sigma(double value, double sigma, bool fixed) {
  if (fixed) return num(value) + " (fixed)";
  if (!(sigma > 0.0)) return with_sigma(value, std::nan(""));
  return with_sigma(value, sigma);
}

std::string with_sigma(double value, double sigma) {
  if (!std::isfinite(value)) return num(value);
  if (std::isnan(sigma)) return num(value) + " (&sigma; not determined)";
  if (sigma <= 0.0) return num(value) + " (fixed)";
  char buf[96];
  const int e = static_cast<int>(std::floor(std::log10(sigma)));
  const double magnitude = std::max(std::abs(value), sigma);
  if (magnitude < 1e-3 || magnitude >= 1e7) {
    // Small or large figures share one power of ten: (1.23 ± 0.11)e-05.
    const int p = static_cast<int>(std::floor(std::log10(magnitude)));
    const double scale = std::pow(10.0, -p);
    const int decimals = std::max(0, p - e + 1);
    std::snprintf(buf, sizeof buf, "(%.*f &plusmn; %.*f)e%+03d", decimals, value * scale, decimals,
                  sigma * scale, p);
    return buf;
  }
  const int decimals = std::clamp(1 - e, 0, 12);
  std::snprintf(buf, sizeof buf, "%.*f &plusmn; %.*f", decimals, value, decimals, sigma);
  return buf;
}

std::string Table::to_html() const {
  std::string out = "<table>\n<thead><tr>";
  for (const auto& h : header) out += "<th>" + h + "</th>";
  out += "</tr></thead>\n<tbody>\n";
  for (const auto& row : rows) {
    out += "<tr>";
    for (const auto& cell : row) out += "<td>" + cell + "</td>";
    out += "</tr>\n";
  }
  return out + "</tbody>\n</table>\n";
}

int Document::figure_count() const {
  int n = 0;
  for (const auto& s : sections) n += static_cast<int>(s.figures.size());
  return n;
}

std::string figure_html(const Figure& figure, const std::string& svg) {
  return "<figure class=\"plot\" id=\"fig-" + escape(figure.id) + "\" data-plot=\"" + escape(figure.id) +
         "\">\n<h3>" + escape(figure.title) + "</h3>\n<img alt=\"" + escape(figure.title) + "\" width=\"" +
         std::to_string(figure.width_px) + "\" height=\"" + std::to_string(figure.height_px) +
         "\" onload=\"plotLoaded(this)\" src=\"data:image/svg+xml;base64," + base64(svg) +
         "\">\n<figcaption>" + escape(figure.caption) + "</figcaption>\n</figure>\n";
}

std::string missing_figure_html(const Figure& figure, const std::string& why) {
  return "<figure class=\"plot missing\" id=\"fig-" + escape(figure.id) + "\">\n<h3>" + escape(figure.title) +
         "</h3>\n<p class=\"note\">Not drawn: the result holds nothing gnuplot could plot for this figure "
         "(its values are missing or out of range). gnuplot said: " +
         escape(why) + "</p>\n</figure>\n";
}

namespace {

constexpr const char* kStyle = R"(
body { font-family: sans-serif; margin: 2em auto; max-width: 1000px; color: #222; line-height: 1.4; }
h1 { margin-bottom: 0.2em; } .subtitle { color: #555; margin-top: 0; }
h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td { font-variant-numeric: tabular-nums; }
.warnings { background: #fff4e5; border: 1px solid #f0b070; padding: 0.5em 1em; }
.note { color: #555; font-size: 0.92em; }
figure.plot { margin: 1.5em 0; } figure.plot h3 { margin: 0 0 0.3em 0; font-size: 1.05em; }
figure.plot img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { color: #444; font-size: 0.9em; }
footer { margin-top: 3em; color: #777; font-size: 0.85em; }
)";

// Marks each figure once its image has decoded, and the page with the count, so that a
// headless browser can tell that every figure rendered.
constexpr const char* kScript = R"(
function plotLoaded(img) {
  if (img.naturalWidth > 0) img.parentElement.dataset.rendered = '1';
  document.body.dataset.plotsRendered = document.querySelectorAll('figure.plot[data-rendered]').length;
}
)";

}  // namespace

std::string page_html(const Document& doc, const std::vector<std::string>& figures_html,
                      const std::string& generator) {
  // Figures that could not be drawn hold a note and no image: the page waits for the others.
  const auto drawn = std::count_if(figures_html.begin(), figures_html.end(), [](const std::string& f) {
    return f.find("plot missing") == std::string::npos;
  });
  std::string out = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" +
                    escape(doc.title) + "</title>\n<style>" + kStyle + "</style>\n<script>" + kScript +
                    "</script>\n</head>\n<body data-plots=\"" + std::to_string(drawn) +
                    "\" data-plots-rendered=\"0\">\n<h1>" + escape(doc.title) +
                    "</h1>\n<p class=\"subtitle\">" + escape(doc.subtitle) + "</p>\n";
  if (!doc.warnings.empty()) {
    out += "<div class=\"warnings\"><strong>Warnings</strong><ul>\n";
    for (const auto& w : doc.warnings) out += "<li>" + escape(w) + "</li>\n";
    out += "</ul></div>\n";
  }
  std::size_t next = 0;
  for (const auto& s : doc.sections) {
    out += "<section>\n<h2>" + escape(s.title) + "</h2>\n" + s.html;
    for (std::size_t i = 0; i < s.figures.size() && next < figures_html.size(); ++i)
      out += figures_html[next++];
    out += "</section>\n";
  }
  return out + "<footer>" + escape(generator) + "</footer>\n</body>\n</html>\n";
}

}  // namespace imucal::app::report
