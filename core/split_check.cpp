// SPDX-License-Identifier: BSD-3-Clause
#include "core/split_check.hpp"

#include <algorithm>
#include <boost/math/special_functions/erf.hpp>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <cstdio>

namespace imucal {

const char* split_check_verdict_name(SplitCheck::Verdict v) {
  switch (v) {
    case SplitCheck::Verdict::kNotDetermined:
      return "not determined";
    case SplitCheck::Verdict::kAgree:
      return "agree";
    case SplitCheck::Verdict::kDisagree:
      return "disagree";
    default:
      return "not run";
  }
}

std::vector<std::pair<TimeNs, TimeNs>> split_spans(TimeNs first, TimeNs last, int parts,
                                                   std::vector<std::pair<double, double>>* spans_s) {
  std::vector<std::pair<TimeNs, TimeNs>> spans;
  const double span = static_cast<double>(last - first);
  for (int p = 0; p < parts; ++p) {
    const auto from = first + static_cast<TimeNs>(span * p / parts);
    const auto to = p + 1 == parts ? last + 1 : first + static_cast<TimeNs>(span * (p + 1) / parts);
    spans.emplace_back(from, to);
    if (spans_s != nullptr)
      spans_s->emplace_back(static_cast<double>(from - first) * 1e-9, static_cast<double>(to - first) * 1e-9);
  }
  return spans;
}

void fill_split_parameters(SplitCheck* check,
                           const std::vector<std::optional<std::vector<SplitCheckRow>>>& parts) {
  const std::vector<SplitCheckRow>* layout = nullptr;
  for (const auto& part : parts)
    if (part && (layout == nullptr || part->size() > layout->size())) layout = &*part;
  if (layout == nullptr) return;
  for (const SplitCheckRow& row : *layout) {
    SplitCheckParameter par{row.name, row.unit, {}, {}};
    for (const auto& part : parts) {
      const SplitCheckRow* hit = nullptr;
      if (part)
        for (const auto& r : *part)
          if (r.name == row.name) hit = &r;
      par.values.push_back(hit != nullptr ? hit->value : std::nan(""));
      par.sigmas.push_back(hit != nullptr ? hit->sigma : std::nan(""));
    }
    check->parameters.push_back(std::move(par));
  }
}

namespace {

std::string parts_name(int parts) {
  return parts == 2 ? "the two halves" : "the " + std::to_string(parts) + " parts";
}

/// The two-sided standard normal quantile: z with P(|Z| > z) = a.
double two_sided_z(double a) { return std::sqrt(2.0) * boost::math::erfc_inv(a); }

}  // namespace

namespace {

/// The chi-square contribution of one parameter against its parts' weighted mean; false with
/// fewer than two parts that have a value and a sigma.
bool parameter_chi_square(const SplitCheckParameter& p, double* chi, int* dof) {
  double sw = 0.0, swx = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < p.values.size() && i < p.sigmas.size(); ++i) {
    if (!(std::isfinite(p.values[i]) && std::isfinite(p.sigmas[i]) && p.sigmas[i] > 0.0)) continue;
    sw += 1.0 / (p.sigmas[i] * p.sigmas[i]);
    swx += p.values[i] / (p.sigmas[i] * p.sigmas[i]);
    ++n;
  }
  if (n < 2) return false;
  const double mean = swx / sw;
  for (std::size_t i = 0; i < p.values.size() && i < p.sigmas.size(); ++i) {
    if (!(std::isfinite(p.values[i]) && std::isfinite(p.sigmas[i]) && p.sigmas[i] > 0.0)) continue;
    *chi += (p.values[i] - mean) * (p.values[i] - mean) / (p.sigmas[i] * p.sigmas[i]);
  }
  *dof += n - 1;
  return true;
}

}  // namespace

double split_chi_square(const SplitCheck& check, const std::string& prefix, int* dof) {
  double chi = 0.0;
  *dof = 0;
  for (const auto& p : check.parameters)
    if (p.name.rfind(prefix, 0) == 0) parameter_chi_square(p, &chi, dof);
  return *dof > 0 ? chi : std::nan("");
}

double chi_square_probability(double chi_square, int dof) {
  if (dof <= 0 || !(chi_square >= 0.0)) return std::nan("");
  return boost::math::gamma_q(0.5 * dof, 0.5 * chi_square);
}

void judge_split_check(SplitCheck* check) {
  check->chi_square = std::nan("");
  check->p_value = std::nan("");
  check->worst_z = std::nan("");
  check->worst.clear();
  check->dof = 0;
  check->summary.clear();
  check->advice.clear();
  const int solved = static_cast<int>(std::count_if(check->part_errors.begin(), check->part_errors.end(),
                                                    [](const std::string& e) { return e.empty(); }));
  double chi = 0.0;
  int compared = 0;
  for (SplitCheckParameter& p : check->parameters) {
    p.worst_z = std::nan("");
    std::vector<std::pair<double, double>> xs;  // value, sigma of the parts that have both
    for (std::size_t i = 0; i < p.values.size() && i < p.sigmas.size(); ++i)
      if (std::isfinite(p.values[i]) && std::isfinite(p.sigmas[i]) && p.sigmas[i] > 0.0)
        xs.emplace_back(p.values[i], p.sigmas[i]);
    if (!parameter_chi_square(p, &chi, &check->dof)) continue;
    ++compared;
    for (std::size_t i = 0; i < xs.size(); ++i)
      for (std::size_t j = i + 1; j < xs.size(); ++j) {
        const double z = std::abs(xs[i].first - xs[j].first) / std::hypot(xs[i].second, xs[j].second);
        if (!(z <= p.worst_z)) p.worst_z = z;
      }
    if (!(p.worst_z <= check->worst_z)) {
      check->worst_z = p.worst_z;
      check->worst = p.name;
    }
  }
  const std::string who = parts_name(check->parts);
  if (solved < 2 || compared == 0) {
    check->verdict = SplitCheck::Verdict::kNotDetermined;
    std::string why =
        solved < 2 ? "fewer than two parts could be calibrated" : "no parameter had a sigma in two parts";
    for (std::size_t i = 0; i < check->part_errors.size(); ++i)
      if (!check->part_errors[i].empty())
        why += "; part " + std::to_string(i + 1) + ": " + check->part_errors[i];
    check->summary = "self-check not determined: " + why;
    check->advice =
        "record longer (each part must be calibrated on its own: about 20 s of varied motion per part), or "
        "run "
        "with fewer parts";
    return;
  }
  check->chi_square = chi;
  check->p_value = chi_square_probability(chi, check->dof);
  // Per-pair differences over every parameter: a 5 % family-wise rate, never below 3 sigmas.
  check->z_limit = std::max(3.0, two_sided_z(0.05 / compared));
  const bool agree = check->worst_z <= check->z_limit && check->p_value >= 1e-3;
  check->verdict = agree ? SplitCheck::Verdict::kAgree : SplitCheck::Verdict::kDisagree;
  char text[600];
  std::snprintf(
      text, sizeof text,
      "%s %s: the largest difference is %.1f combined sigmas (%s; limit %.1f), chi-square %.1f for %d "
      "degrees of freedom (p = %.2g)",
      who.c_str(), agree ? "agree within their sigmas" : "disagree beyond their sigmas", check->worst_z,
      check->worst.c_str(), check->z_limit, chi, check->dof, check->p_value);
  check->summary = text;
  if (!agree) {
    std::snprintf(
        text, sizeof text,
        "the parts of this recording give results that differ more than their sigmas allow (about %.1f "
        "times, from the chi-square): read the sigmas as lower bounds, and check what the model leaves "
        "out: %s; then record again",
        std::sqrt(chi / std::max(check->dof, 1)),
        check->suspects.empty() ? "the camera's intrinsics (a lens model that fits the whole image), the IMU "
                                  "noise figures, motion that excites every axis in every part"
                                : check->suspects.c_str());
    check->advice = text;
  }
}

namespace {

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }
double number_of(const nlohmann::json& j) { return j.is_null() ? std::nan("") : j.get<double>(); }
nlohmann::json numbers(const std::vector<double>& v) {
  nlohmann::json a = nlohmann::json::array();
  for (double x : v) a.push_back(number(x));
  return a;
}
std::vector<double> numbers_of(const nlohmann::json& j) {
  std::vector<double> v;
  for (const auto& x : j) v.push_back(number_of(x));
  return v;
}

}  // namespace

nlohmann::json split_check_json(const SplitCheck& c) {
  nlohmann::json params = nlohmann::json::array();
  for (const auto& p : c.parameters)
    params.push_back({{"name", p.name},
                      {"unit", p.unit},
                      {"values", numbers(p.values)},
                      {"sigmas", numbers(p.sigmas)},
                      {"worst_z", number(p.worst_z)}});
  nlohmann::json spans = nlohmann::json::array();
  for (auto [a, b] : c.spans_s) spans.push_back({a, b});
  nlohmann::json scaled = nlohmann::json::object();
  for (const auto& [name, factor] : c.scaled) scaled[name] = factor;
  return {{"verdict", split_check_verdict_name(c.verdict)},
          {"parts", c.parts},
          {"spans_s", spans},
          {"part_errors", c.part_errors},
          {"chi_square", number(c.chi_square)},
          {"dof", c.dof},
          {"p_value", number(c.p_value)},
          {"worst_z", number(c.worst_z)},
          {"worst", c.worst},
          {"z_limit", c.z_limit},
          {"summary", c.summary},
          {"advice", c.advice},
          {"suspects", c.suspects},
          {"wall_s", c.wall_s},
          {"sigmas_scaled", scaled},
          {"parameters", params}};
}

SplitCheck read_split_check(const nlohmann::json& j) {
  SplitCheck c;
  const std::string v = j.at("verdict").get<std::string>();
  for (auto k : {SplitCheck::Verdict::kNotRun, SplitCheck::Verdict::kNotDetermined,
                 SplitCheck::Verdict::kAgree, SplitCheck::Verdict::kDisagree})
    if (v == split_check_verdict_name(k)) c.verdict = k;
  c.parts = j.at("parts").get<int>();
  for (const auto& s : j.at("spans_s")) c.spans_s.emplace_back(s.at(0).get<double>(), s.at(1).get<double>());
  c.part_errors = j.at("part_errors").get<std::vector<std::string>>();
  c.chi_square = number_of(j.at("chi_square"));
  c.dof = j.at("dof").get<int>();
  c.p_value = number_of(j.at("p_value"));
  c.worst_z = number_of(j.at("worst_z"));
  c.worst = j.at("worst").get<std::string>();
  c.z_limit = j.at("z_limit").get<double>();
  c.summary = j.at("summary").get<std::string>();
  c.advice = j.at("advice").get<std::string>();
  c.suspects = j.value("suspects", std::string());
  c.wall_s = j.value("wall_s", 0.0);
  if (j.contains("sigmas_scaled"))
    for (const auto& [name, factor] : j["sigmas_scaled"].items())
      c.scaled.emplace_back(name, factor.get<double>());
  for (const auto& p : j.at("parameters")) {
    SplitCheckParameter q;
    q.name = p.at("name").get<std::string>();
    q.unit = p.at("unit").get<std::string>();
    q.values = numbers_of(p.at("values"));
    q.sigmas = numbers_of(p.at("sigmas"));
    q.worst_z = number_of(p.at("worst_z"));
    c.parameters.push_back(std::move(q));
  }
  return c;
}

}  // namespace imucal
