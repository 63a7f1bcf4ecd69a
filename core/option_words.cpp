// SPDX-License-Identifier: BSD-3-Clause
#include "core/option_words.hpp"

#include <atomic>

namespace imucal {

namespace {

std::atomic<OptionVocabulary> g_vocabulary{nullptr};

std::string with_value(std::string_view quantity, std::string_view value) {
  return std::string(quantity) + ": " + std::string(value.empty() ? "given" : value);
}

}  // namespace

std::string plain_option_words(CalibOption option, std::string_view value) {
  switch (option) {
    case CalibOption::kShutter:
      return with_value("shutter", value);
    case CalibOption::kLineDelay:
      return with_value("line delay", value);
    case CalibOption::kReadout:
      return with_value("readout", value);
    case CalibOption::kHoldTimeOffsets:
      return with_value("time offsets", value.empty() ? "held" : value);
    case CalibOption::kCamImuModel:
      return with_value("model", value);
    case CalibOption::kImuIntrinsics:
      return with_value("IMU intrinsics", value);
    case CalibOption::kGsens:
      return with_value("g-sensitivity", value);
    case CalibOption::kFix:
      return with_value("held intrinsics", value);
    case CalibOption::kKeepNoise:
      return with_value("noise figures", value.empty() ? "kept" : value);
    case CalibOption::kAccelModel:
      return with_value("accelerometer model", value);
    case CalibOption::kImportOffsets:
      return with_value("zero counts at import", value);
    case CalibOption::kImportScales:
      return with_value("scales at import", value);
  }
  return std::string(value);
}

OptionVocabulary set_option_vocabulary(OptionVocabulary vocabulary) {
  return g_vocabulary.exchange(vocabulary);
}

OptionVocabulary option_vocabulary() { return g_vocabulary.load(); }

std::string option_words(CalibOption option, std::string_view value) {
  const OptionVocabulary v = g_vocabulary.load();
  return v ? v(option, value) : plain_option_words(option, value);
}

}  // namespace imucal
