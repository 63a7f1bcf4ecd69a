// SPDX-License-Identifier: BSD-3-Clause
#pragma once
// The self-check of a calibration without ground truth: the recording is cut into consecutive
// parts (halves by default), each part is calibrated apart, and the parts' estimates are
// compared against their own sigmas. Parts that disagree by more than their sigmas allow mean
// that the sigmas (or the model) do not hold for this recording. The comparison lives here, with
// no solver, so that results, reports and the service read the same record;
// app/camimu_self_check.hpp runs the parts. Method: docs/camimu-calibration.md, "Uncertainty and quality".

#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/time.hpp"

namespace imucal {

/// One compared parameter: its value and sigma in every part (in `unit`, as displayed; a value is
/// NaN where its part could not be solved, a sigma NaN where it was not determined).
struct SplitCheckParameter {
  std::string name;  // "cam0 translation y", "S_a x", ...
  std::string unit;  // "mm", "deg", "ms", "us", ""
  std::vector<double> values;
  std::vector<double> sigmas;
  /// The largest difference of two parts in their combined sigmas, |x_i - x_j| / sqrt(s_i^2 + s_j^2)
  /// (NaN: fewer than two parts with a value and a sigma).
  double worst_z = std::numeric_limits<double>::quiet_NaN();
};

struct SplitCheck {
  enum class Verdict { kNotRun, kNotDetermined, kAgree, kDisagree };
  Verdict verdict = Verdict::kNotRun;
  int parts = 0;                                   // asked for (0: not run)
  std::vector<std::pair<double, double>> spans_s;  // each part's span, s from the first frame
  std::vector<std::string> part_errors;            // per part: empty when it was solved
  std::vector<SplitCheckParameter> parameters;
  /// sum over parameters and parts of ((x_i - weighted mean) / s_i)^2, its degrees of freedom
  /// (sum of parts - 1 per parameter) and its upper-tail probability. Correlations between
  /// parameters are left out, so the probability is approximate (docs/camimu-calibration.md).
  double chi_square = std::numeric_limits<double>::quiet_NaN();
  int dof = 0;
  double p_value = std::numeric_limits<double>::quiet_NaN();
  /// The largest worst_z and its parameter; the threshold it was held against.
  double worst_z = std::numeric_limits<double>::quiet_NaN();
  std::string worst;
  double z_limit = 3.0;
  /// One line for screens ("the two halves agree within their sigmas: ..."), and what to do
  /// when they do not (empty when they agree).
  std::string summary;
  std::string advice;
  /// What the advice names to check when the parts disagree (set before judge_split_check;
  /// empty: the camera-IMU solve's inputs).
  std::string suspects;
  double wall_s = 0.0;  // of the parts' solves
  /// The factors the whole recording's sigmas were scaled by where the parts disagreed (a
  /// camera's name, or a group of parameters, and sqrt(chi-square / dof) of its parameters).
  std::vector<std::pair<std::string, double>> scaled;
};

/// The chi-square of the parameters whose names start with `prefix` (as judge_split_check sums
/// them) and its degrees of freedom; NaN and 0 with none compared.
double split_chi_square(const SplitCheck& check, const std::string& prefix, int* dof);
/// The upper-tail probability of a chi-square with `dof` degrees of freedom.
double chi_square_probability(double chi_square, int dof);

const char* split_check_verdict_name(SplitCheck::Verdict v);

/// `parts` consecutive spans of equal duration covering [first, last] (the last one ends after
/// `last`), and their times in s from `first` for SplitCheck::spans_s.
std::vector<std::pair<TimeNs, TimeNs>> split_spans(TimeNs first, TimeNs last, int parts,
                                                   std::vector<std::pair<double, double>>* spans_s);

/// One part's value of one parameter, as a solver's result gives it.
struct SplitCheckRow {
  std::string name, unit;
  double value = 0.0, sigma = 0.0;
};
/// The parameters of `check` from every part's rows (empty optional: the part was not solved):
/// the parameters of the part that has the most, each with every part's value and sigma (NaN
/// where a part does not have it).
void fill_split_parameters(
    SplitCheck* check,
    const std::vector<std::optional<std::vector<SplitCheckRow>>>& parts);  // "not run", "not determined", ...

/// The comparison (chi-square, worst differences, verdict, summary and advice) of the parameters
/// and part_errors already filled in `check`. The parts agree when the largest difference is
/// within z_limit = max(3, the Bonferroni bound of a 5 % family-wise rate over the parameters)
/// and the chi-square's probability is at least 0.001. Not determined with fewer than two parts
/// solved or no parameter with sigmas.
void judge_split_check(SplitCheck* check);

/// result.json's "self_check" object (null numbers where not determined) and back; read throws
/// nlohmann::json's exceptions on a malformed object.
nlohmann::json split_check_json(const SplitCheck& check);
SplitCheck read_split_check(const nlohmann::json& j);

}  // namespace imucal
