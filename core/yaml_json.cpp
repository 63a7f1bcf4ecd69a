// SPDX-License-Identifier: BSD-3-Clause
#include "core/yaml_json.hpp"

#include <cmath>
#include <cstdint>
#include <string>

#include "core/text_file.hpp"

namespace imucal {

nlohmann::json yaml_to_json(const YAML::Node& n) {
  using nlohmann::json;
  switch (n.Type()) {
    case YAML::NodeType::Sequence: {
      json a = json::array();
      for (const auto& item : n) a.push_back(yaml_to_json(item));
      return a;
    }
    case YAML::NodeType::Map: {
      json o = json::object();
      for (const auto& kv : n) o[kv.first.as<std::string>()] = yaml_to_json(kv.second);
      return o;
    }
    case YAML::NodeType::Scalar: {
      std::int64_t i = 0;
      double d = 0;
      bool b = false;
      if (n.Tag() != "!" && YAML::convert<std::int64_t>::decode(n, i)) return i;
      // A figure that could not be determined (.nan: a sigma) is null, as in result.json: a
      // record then compares equal to itself after a write, which NaN never does.
      if (n.Tag() != "!" && YAML::convert<double>::decode(n, d))
        return std::isnan(d) ? json(nullptr) : json(d);
      if (n.Tag() != "!" && YAML::convert<bool>::decode(n, b)) return b;
      return n.Scalar();
    }
    default:
      return nullptr;
  }
}

Result<YAML::Node> read_yaml_file(const std::string& path) {
  auto text = read_text_file(path, kMaxResultFileBytes);
  if (!text.ok()) return text.error();
  try {
    return YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return make_error(Errc::kCorrupt, path + ": not valid YAML (" + std::string(e.what()) + ")");
  }
}

YAML::Node yaml_matrix_rows(const Eigen::MatrixXd& m) {
  YAML::Node rows(YAML::NodeType::Sequence);
  for (Eigen::Index r = 0; r < m.rows(); ++r) {
    YAML::Node row(YAML::NodeType::Sequence);
    for (Eigen::Index c = 0; c < m.cols(); ++c) row.push_back(m(r, c));
    row.SetStyle(YAML::EmitterStyle::Flow);
    rows.push_back(row);
  }
  return rows;
}

}  // namespace imucal
