// SPDX-License-Identifier: BSD-3-Clause
// Fuzz target: the text formats a user imports (log/dataset_io.hpp): whitespace "t x y z" files,
// generic CSV with a column spec, EuRoC imu0 and cam0 CSVs, and time and number fields. The first
// byte picks the parser, the rest is the file. Any bytes must give rows or an error with a
// message, never a crash, an exception or a sanitizer report; accepted rows must be finite and
// strictly increasing in time where the format promises it.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "log/dataset_io.hpp"

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

template <class R>
void require_message(const R& r) {
  if (!r.ok()) require(!r.error().message.empty());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace imucal;
  using namespace imucal::log;
  if (size == 0) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 6) {
    case 0: {  // an accelerometer or gyroscope text file, then pairing with itself
      auto s = parse_triad_text(text, "fuzz.txt");
      require_message(s);
      if (!s.ok()) break;
      for (std::size_t i = 1; i < s->t_ns.size(); ++i) require(s->t_ns[i] > s->t_ns[i - 1]);
      for (const auto& v : s->xyz) require(v.allFinite());
      auto period = sample_period_ns(s->t_ns, 0.0, "fuzz.txt", "the time unit");
      require_message(period);
      if (period.ok()) require_message(pair_accel_gyro(*s, *s, *period));
      break;
    }
    case 1: {  // a CSV: the first line is the column spec, the rest the file
      const std::size_t eol = text.find('\n');
      const std::string spec(text.substr(0, eol));
      auto columns = parse_csv_columns(spec);
      require_message(columns);
      if (!columns.ok() || eol == std::string_view::npos) break;
      CsvFormat format;
      format.columns = *columns;
      format.delimiter = spec.size() % 2 ? ',' : ' ';
      auto rows = parse_imu_csv(text.substr(eol + 1), "fuzz.csv", format);
      require_message(rows);
      if (rows.ok()) {
        for (std::size_t i = 1; i < rows->size(); ++i) require((*rows)[i].t_ns > (*rows)[i - 1].t_ns);
        require_message(check_units(*rows, ImuUnits::kSi, "fuzz.csv"));
      }
      break;
    }
    case 2: {
      auto rows = parse_euroc_imu_csv(text, "imu0/data.csv");
      require_message(rows);
      if (rows.ok())
        for (const auto& r : *rows) require(std::isfinite(r.accel.x()) && std::isfinite(r.gyro.z()));
      break;
    }
    case 3:
      require_message(parse_euroc_camera_csv(text, "cam0/data.csv"));
      break;
    case 4:
      for (auto unit : {TimeUnit::kS, TimeUnit::kMs, TimeUnit::kUs, TimeUnit::kNs})
        require_message(parse_time_ns(text, unit));
      break;
    default: {
      auto v = parse_double(text);
      require_message(v);
      if (v.ok()) require(std::isfinite(*v));
      break;
    }
  }
  return 0;
}
