#pragma once
// A YAML document as JSON: for the readers that take either (a result YAML into the calibration
// record, a thermal YAML into the report).

#include <yaml-cpp/yaml.h>

#include <nlohmann/json.hpp>

namespace imucal {

/// Scalars become integers, then floating point (NaN as null: a figure not determined), then
/// booleans, else strings; a quoted scalar (tag "!") stays a string; YAML null is null.
nlohmann::json yaml_to_json(const YAML::Node& node);

}  // namespace imucal
