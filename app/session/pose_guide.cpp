// SPDX-License-Identifier: BSD-3-Clause
#include "app/session/pose_guide.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>

#include "acquisition/mounting.hpp"

namespace imucal::app::session {
namespace {

std::string upper(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::toupper(c); });
  return text;
}

std::string axis_name(const Eigen::Vector3d& axis) {
  Eigen::Index i = 0;
  axis.cwiseAbs().maxCoeff(&i);
  return std::string(axis[i] < 0 ? "-" : "+") + static_cast<char>('X' + i);
}

// `text` centred in `width` columns (cut when longer).
std::string centred(const std::string& text, std::size_t width) {
  if (text.size() >= width) return text.substr(0, width);
  const std::size_t left = (width - text.size()) / 2;
  return std::string(left, ' ') + text + std::string(width - text.size() - left, ' ');
}

}  // namespace

PoseGuide::PoseGuide(const RigConfig& config) {
  if (!config.sides) return;
  RigSides s = *config.sides;
  auto mounting = acq::MountingMap::from_rotation(config.imu.R_rig_imu);
  if (mounting.ok() && !mounting->exact_on_raw()) {
    // Samples stay in the IMU frame: v_imu = R_rig_imu^T v_rig.
    const Eigen::Matrix3d Rt = config.imu.R_rig_imu.transpose();
    s.front = Rt * s.front;
    s.left = Rt * s.left;
    s.top = Rt * s.top;
  }
  sides_ = s;
}

std::optional<std::string> PoseGuide::side(const Eigen::Vector3d& axis) const {
  if (!sides_) return std::nullopt;
  const std::pair<const Eigen::Vector3d*, const char*> named[] = {
      {&sides_->front, "front"}, {&sides_->left, "left"}, {&sides_->top, "top"}};
  const char* opposite[] = {"back", "right", "bottom"};
  for (int i = 0; i < 3; ++i) {
    const double c = named[i].first->dot(axis.normalized());
    if (c > 0.99) return std::string(named[i].second);
    if (c < -0.99) return std::string(opposite[i]);
  }
  return std::nullopt;  // a mounting that is not a signed permutation: the axes are between sides
}

std::string PoseGuide::label(const Eigen::Vector3d& axis) const {
  if (auto s = side(axis)) return upper(*s);
  return axis_name(axis);
}

std::string PoseGuide::up_name(const Eigen::Vector3d& up) const {
  if (auto s = side(up)) return *s + " side up";
  return axis_name(up) + " up";
}

std::string PoseGuide::instruction(const Eigen::Vector3d& up) const {
  const auto u = side(up);
  const auto d = side(-up);
  if (!u || !d) return "Turn the rig so that the IMU's " + axis_name(up) + " axis points up";
  if (*u == "top") return "Stand the rig upright (top side up)";
  if (*u == "bottom") return "Turn the rig upside down (bottom side up)";
  return "Put the rig on its " + *d + " side, " + *u + " side up";
}

std::vector<std::string> PoseGuide::drawing(const Eigen::Vector3d& up) const {
  const Eigen::Vector3d u = up.normalized();
  // The side toward the operator: the front (or top) when it is not the one up; without names
  // the IMU's +X (or +Z).
  std::vector<Eigen::Vector3d> toward = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ()};
  if (sides_) toward = {sides_->front, sides_->top};
  Eigen::Vector3d t = std::abs(toward[0].dot(u)) < 0.5 ? toward[0] : toward[1];
  // Seen by the operator (x right, y up, z toward them, right-handed): right = up x toward.
  const Eigen::Vector3d r = u.cross(t);
  const std::string top = centred(label(u), 11);
  const std::string front = centred(label(t), 11);
  return {
      "       ___________",     "      /" + top + "/|",
      "     /___________/ |",   "     |           | |  right: " + label(r),
      "     |" + front + "| |", "     | (to you)  | /",
      "     |___________|/",    "   ===================  table",
  };
}

}  // namespace imucal::app::session
