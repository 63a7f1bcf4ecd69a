// SPDX-License-Identifier: BSD-3-Clause
// The self-check's comparison of the parts of a recording (core/split_check.hpp).

#include <gtest/gtest.h>

#include <cmath>

#include "core/split_check.hpp"

namespace imucal {
namespace {

SplitCheckParameter split_parameter(const std::string& name, double a, double b, double sigma) {
  return {name, "mm", {a, b}, {sigma, sigma}};
}

TEST(SplitCheck, PartsWithinTheirSigmasAgree) {
  SplitCheck c;
  c.parts = 2;
  c.part_errors = {"", ""};
  c.parameters = {split_parameter("cam0 translation x", 1.0, 1.5, 0.5),
                  split_parameter("cam0 translation y", 2.0, 1.0, 0.5)};
  judge_split_check(&c);
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kAgree) << c.summary;
  // Differences of 0.5 and 1.0 over a combined sigma of 0.5 sqrt(2).
  EXPECT_NEAR(c.parameters[0].worst_z, 0.5 / (0.5 * std::sqrt(2.0)), 1e-12);
  EXPECT_NEAR(c.worst_z, 1.0 / (0.5 * std::sqrt(2.0)), 1e-12);
  EXPECT_EQ(c.worst, "cam0 translation y");
  // chi-square: per parameter (d/2)^2 / s^2 twice = d^2 / (2 s^2).
  EXPECT_NEAR(c.chi_square, (0.25 + 1.0) / (2 * 0.25), 1e-12);
  EXPECT_EQ(c.dof, 2);
  EXPECT_NEAR(c.p_value, std::exp(-0.5 * c.chi_square), 1e-12);  // chi-square with 2 dof
  EXPECT_DOUBLE_EQ(c.z_limit, 3.0);
  EXPECT_TRUE(c.advice.empty());
  EXPECT_NE(c.summary.find("the two halves agree"), std::string::npos) << c.summary;
}

TEST(SplitCheck, APartBeyondTheLimitDisagreesAndSaysWhatToDo) {
  SplitCheck c;
  c.parts = 2;
  c.part_errors = {"", ""};
  c.parameters = {split_parameter("cam0 translation x", 1.0, 4.0, 0.5),
                  split_parameter("cam0 time offset", 3.0, 3.1, 0.5)};
  judge_split_check(&c);
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kDisagree);
  EXPECT_EQ(c.worst, "cam0 translation x");
  EXPECT_GT(c.worst_z, 4.0);
  EXPECT_FALSE(c.advice.empty());
  int dof = 0;
  EXPECT_NEAR(split_chi_square(c, "cam0 translation", &dof), 9.0 / 0.5, 1e-12);
  EXPECT_EQ(dof, 1);
}

TEST(SplitCheck, NotDeterminedWhenAPartCouldNotBeSolvedOrNothingHasASigma) {
  SplitCheck c;
  c.parts = 2;
  c.part_errors = {"", "too few frames with the target"};
  c.parameters = {{"cam0 translation x", "mm", {1.0, std::nan("")}, {0.5, std::nan("")}}};
  judge_split_check(&c);
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kNotDetermined);
  EXPECT_NE(c.summary.find("too few frames"), std::string::npos) << c.summary;
  EXPECT_TRUE(std::isnan(c.chi_square));
  SplitCheck n;
  n.parts = 2;
  n.part_errors = {"", ""};
  n.parameters = {{"cam0 translation x", "mm", {1.0, 2.0}, {std::nan(""), 0.5}}};
  judge_split_check(&n);
  EXPECT_EQ(n.verdict, SplitCheck::Verdict::kNotDetermined);
}

TEST(SplitCheck, ManyParametersRaiseTheLimitAndThreePartsCompareEveryPair) {
  SplitCheck c;
  c.parts = 3;
  c.part_errors = {"", "", ""};
  for (int i = 0; i < 40; ++i)
    c.parameters.push_back({"p" + std::to_string(i), "", {0.0, 0.1, 0.2}, {1.0, 1.0, 1.0}});
  c.parameters[7].values = {0.0, 0.0, 4.4};  // 3.11 combined sigmas: beyond 3, within the raised limit
  judge_split_check(&c);
  EXPECT_GT(c.z_limit, 3.0);  // Bonferroni over 40 parameters: 3.23
  EXPECT_LT(c.z_limit, 3.3);
  EXPECT_EQ(c.dof, 80);
  EXPECT_EQ(c.worst, "p7");
  EXPECT_NEAR(c.worst_z, 4.4 / std::sqrt(2.0), 1e-12);
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kAgree) << c.summary;
  c.parameters[7].values = {0.0, 0.0, 4.7};  // 3.32: beyond
  judge_split_check(&c);
  EXPECT_EQ(c.verdict, SplitCheck::Verdict::kDisagree) << c.summary;
}

TEST(SplitCheck, TheJsonRoundTripKeepsWhatWasNotDetermined) {
  SplitCheck c;
  c.parts = 2;
  c.spans_s = {{0.0, 10.0}, {10.0, 20.0}};
  c.part_errors = {"", ""};
  c.parameters = {{"cam0 rotation about x", "deg", {0.01, 0.02}, {0.005, std::nan("")}},
                  split_parameter("cam0 translation x", 1.0, 1.5, 0.5)};
  judge_split_check(&c);
  c.scaled = {{"cam0", 1.8}};
  const SplitCheck r = read_split_check(nlohmann::json::parse(split_check_json(c).dump()));
  EXPECT_EQ(r.verdict, c.verdict);
  EXPECT_EQ(r.spans_s, c.spans_s);
  ASSERT_EQ(r.parameters.size(), 2u);
  EXPECT_TRUE(std::isnan(r.parameters[0].sigmas[1]));
  EXPECT_TRUE(std::isnan(r.parameters[0].worst_z));
  EXPECT_DOUBLE_EQ(r.parameters[1].worst_z, c.parameters[1].worst_z);
  EXPECT_DOUBLE_EQ(r.chi_square, c.chi_square);
  EXPECT_EQ(r.summary, c.summary);
  EXPECT_EQ(r.scaled, c.scaled);
}

}  // namespace
}  // namespace imucal
