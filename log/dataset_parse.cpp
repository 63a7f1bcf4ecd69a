// SPDX-License-Identifier: BSD-3-Clause
// Text parsing for dataset imports: exact decimal times, shortest round-trip doubles, "t x y z"
// files, generic CSV, accelerometer/gyroscope pairing (the unit sanity check is in
// dataset_units.cpp).

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <set>
#include <sstream>

#include "core/text_file.hpp"
#include "core/text_format.hpp"
#include "log/dataset_io.hpp"

namespace imucal::log {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

/// Iterates the lines of a text in memory or of a file read in chunks (TextLineReader), counting
/// from 1, without the line ends.
class Lines {
 public:
  explicit Lines(std::string_view text) : text_(text), total_(text.size()) {}
  explicit Lines(TextLineReader& reader) : reader_(&reader), total_(reader.size()) {}
  bool next(std::string_view& line) {
    if (number_ == std::numeric_limits<int>::max()) {
      too_many_ = true;
      return false;
    }
    if (reader_ != nullptr) {
      if (!reader_->next(line)) return false;
    } else {
      if (pos_ >= text_.size()) return false;
      const std::size_t end = text_.find('\n', pos_);
      const std::size_t stop = end == std::string_view::npos ? text_.size() : end;
      line = text_.substr(pos_, stop - pos_);
      pos_ = stop + 1;
    }
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    ++number_;
    return true;
  }
  int number() const { return number_; }
  double offset() const {
    return static_cast<double>(reader_ != nullptr ? reader_->offset() : std::min(pos_, text_.size()));
  }
  double total() const { return static_cast<double>(total_); }
  /// Why next() returned false before the end: a read error, an overlong line, too many lines.
  std::optional<Error> error(const std::string& source) const {
    if (reader_ != nullptr && reader_->error()) return *reader_->error();
    if (too_many_) return make_error(Errc::kCorrupt, source + ": more than 2^31 lines; split the file");
    return std::nullopt;
  }

 private:
  std::string_view text_;
  TextLineReader* reader_ = nullptr;
  std::uint64_t total_ = 0;
  std::size_t pos_ = 0;
  int number_ = 0;
  bool too_many_ = false;
};

/// Calls field(f) for each whitespace-separated field f of `s`, in order.
template <class Field>
void for_each_whitespace_field(std::string_view s, const Field& field) {
  const char* p = s.data();
  const char* const end = p + s.size();
  while (true) {
    while (p != end && (*p == ' ' || *p == '\t')) ++p;
    if (p == end) return;
    const char* q = p;
    while (q != end && *q != ' ' && *q != '\t') ++q;
    field(std::string_view(p, static_cast<std::size_t>(q - p)));
    p = q;
  }
}

void split_whitespace(std::string_view s, std::vector<std::string_view>& out) {
  out.clear();
  for_each_whitespace_field(s, [&out](std::string_view f) { out.push_back(f); });
}

/// The first N whitespace-separated fields of `s` into `out`; returns how many fields `s` has (more
/// than N are counted, not stored).
template <std::size_t N>
std::size_t split_whitespace_first(std::string_view s, std::array<std::string_view, N>& out) {
  std::size_t count = 0;
  for_each_whitespace_field(s, [&](std::string_view f) {
    if (count < N) out[count] = f;
    ++count;
  });
  return count;
}

void split_delimited(std::string_view s, char delimiter, std::vector<std::string_view>& out) {
  if (delimiter == ' ') {
    split_whitespace(s, out);
    return;
  }
  out.clear();
  std::size_t start = 0;
  while (true) {
    const std::size_t end = s.find(delimiter, start);
    out.push_back(
        trim(s.substr(start, end == std::string_view::npos ? std::string_view::npos : end - start)));
    if (end == std::string_view::npos) break;
    start = end + 1;
  }
}

Error at(const std::string& source, int line, const std::string& what) {
  return make_error(Errc::kCorrupt, source + ":" + std::to_string(line) + ": " + what);
}

std::string seconds_text(TimeNs t_ns) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.9f s", ns_to_s(t_ns));
  return buf;
}

/// Strictly increasing time check shared by all parsers.
std::optional<Error> check_increasing(const std::string& source, TimeNs prev_t, int prev_line, TimeNs t,
                                      int line) {
  if (prev_line <= 0 || t > prev_t) return std::nullopt;
  if (t == prev_t) {
    return at(source, line,
              "duplicate timestamp (same as line " + std::to_string(prev_line) +
                  "); timestamps must increase. If the file's times are printed too coarsely for its rate "
                  "(many rows "
                  "share one), rebuild them from the row index and the rate (t = i / rate) before importing");
  }
  return at(source, line,
            "timestamp goes backwards (" + seconds_text(t) + " after " + seconds_text(prev_t) + " on line " +
                std::to_string(prev_line) + "); rows must be in time order");
}

}  // namespace

Result<TimeUnit> parse_time_unit(const std::string& name) {
  if (name == "s") return TimeUnit::kS;
  if (name == "ms") return TimeUnit::kMs;
  if (name == "us") return TimeUnit::kUs;
  if (name == "ns") return TimeUnit::kNs;
  return make_error(Errc::kInvalidArgument, "time unit '" + name + "' is not one of s, ms, us, ns");
}

const char* time_unit_name(TimeUnit unit) {
  switch (unit) {
    case TimeUnit::kS:
      return "s";
    case TimeUnit::kMs:
      return "ms";
    case TimeUnit::kUs:
      return "us";
    case TimeUnit::kNs:
      return "ns";
  }
  return "?";
}

namespace {

/// 'text' followed by `rest`, the text with non-printable bytes shown as \xNN and at most 80
/// characters. Built by appending: "'" + std::string(...) makes GCC 12 at -O3 report a false
/// -Wrestrict inside libstdc++.
std::string quoted(std::string_view text, std::string_view rest) {
  std::string msg(1, '\'');
  msg.append(printable(text)).append(1, '\'').append(rest);
  return msg;
}

constexpr std::uint64_t kPow10[19] = {1ULL,
                                      10ULL,
                                      100ULL,
                                      1000ULL,
                                      10000ULL,
                                      100000ULL,
                                      1000000ULL,
                                      10000000ULL,
                                      100000000ULL,
                                      1000000000ULL,
                                      10000000000ULL,
                                      100000000000ULL,
                                      1000000000000ULL,
                                      10000000000000ULL,
                                      100000000000000ULL,
                                      1000000000000000ULL,
                                      10000000000000000ULL,
                                      100000000000000000ULL,
                                      1000000000000000000ULL};

/// parse_time_ns for the common form, at most 18 significant digits with an optional dot and an
/// exponent of at most 3 digits, in integer arithmetic (the same rounding: half up on the first
/// dropped digit). Empty for anything else, which the general parser handles with its messages.
std::optional<TimeNs> parse_time_ns_fast(std::string_view s, long long unit_exp) {
  std::size_t i = 0;
  bool negative = false;
  if (i < s.size() && (s[i] == '+' || s[i] == '-')) negative = s[i++] == '-';
  std::uint64_t mantissa = 0;
  int significant = 0;
  long long frac_digits = 0;
  bool seen_dot = false, any_digit = false;
  for (; i < s.size(); ++i) {
    const char c = s[i];
    if (c >= '0' && c <= '9') {
      any_digit = true;
      if (seen_dot) ++frac_digits;
      if (mantissa == 0 && c == '0') continue;
      if (++significant > 18) return std::nullopt;
      mantissa = mantissa * 10 + static_cast<std::uint64_t>(c - '0');
    } else if (c == '.' && !seen_dot) {
      seen_dot = true;
    } else {
      break;
    }
  }
  if (!any_digit) return std::nullopt;
  long long exponent = 0;
  if (i < s.size()) {
    if (s[i] != 'e' && s[i] != 'E') return std::nullopt;
    ++i;
    bool exp_negative = false;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) exp_negative = s[i++] == '-';
    if (i == s.size() || s.size() - i > 3) return std::nullopt;
    for (; i < s.size(); ++i) {
      if (s[i] < '0' || s[i] > '9') return std::nullopt;
      exponent = exponent * 10 + (s[i] - '0');
    }
    if (exp_negative) exponent = -exponent;
    if (exponent > 400 || exponent < -400) return std::nullopt;  // refused by the general parser
  }
  if (mantissa == 0) return TimeNs{0};
  const long long exp10 = exponent - frac_digits + unit_exp;
  std::uint64_t value = 0;
  if (exp10 >= 0) {
    if (significant + exp10 > 18) return std::nullopt;
    value = mantissa * kPow10[exp10];
  } else {
    const long long drop = -exp10;
    if (drop > significant) return TimeNs{0};
    value = mantissa / kPow10[drop];
    if ((mantissa / kPow10[drop - 1]) % 10 >= 5) ++value;
  }
  if (value > static_cast<std::uint64_t>(kTimeLimitNs)) return std::nullopt;
  const auto signed_value = static_cast<TimeNs>(value);
  return negative ? -signed_value : signed_value;
}

}  // namespace

Result<TimeNs> parse_time_ns(std::string_view text, TimeUnit unit) {
  const std::string_view s = trim(text);
  const long long unit_exp = unit == TimeUnit::kS    ? 9
                             : unit == TimeUnit::kMs ? 6
                             : unit == TimeUnit::kUs ? 3
                                                     : 0;
  if (auto fast = parse_time_ns_fast(s, unit_exp)) return *fast;
  const auto bad = [&](const std::string& why) {
    return make_error(Errc::kCorrupt, quoted(s, " is not a time value" + why));
  };
  if (s.empty()) return bad(" (empty)");
  std::size_t i = 0;
  bool negative = false;
  if (s[0] == '+' || s[0] == '-') {
    negative = s[0] == '-';
    ++i;
  }
  std::string digits;
  long long frac_digits = 0;
  bool seen_dot = false;
  long long exponent = 0;
  for (; i < s.size(); ++i) {
    const char c = s[i];
    if (c >= '0' && c <= '9') {
      digits.push_back(c);
      if (seen_dot) ++frac_digits;
    } else if (c == '.' && !seen_dot) {
      seen_dot = true;
    } else if ((c == 'e' || c == 'E') && !digits.empty()) {
      std::size_t k = i + 1;
      if (k < s.size() && s[k] == '+') ++k;
      // One sign at most: "1e+-5" is not a number.
      if (k < s.size() && (s[k] == '+' || (s[k] == '-' && k > i + 1))) return bad("");
      auto [ptr, ec] = std::from_chars(s.data() + k, s.data() + s.size(), exponent);
      if (ec != std::errc() || ptr != s.data() + s.size() || std::llabs(exponent) > 400) return bad("");
      break;
    } else {
      return bad("");
    }
  }
  if (digits.empty()) return bad("");
  const long long exp10 = exponent - frac_digits + unit_exp;
  const std::size_t nz = digits.find_first_not_of('0');
  if (nz == std::string::npos) return TimeNs{0};
  digits.erase(0, nz);
  bool round_up = false;
  if (exp10 >= 0) {
    if (static_cast<long long>(digits.size()) + exp10 > 19) return bad(" (too large for int64 nanoseconds)");
    digits.append(static_cast<std::size_t>(exp10), '0');
  } else {
    const long long keep = static_cast<long long>(digits.size()) + exp10;
    if (keep < 0) return TimeNs{0};
    round_up =
        static_cast<std::size_t>(keep) < digits.size() && digits[static_cast<std::size_t>(keep)] >= '5';
    digits.resize(static_cast<std::size_t>(keep));
    if (digits.size() > 19) return bad(" (too large for int64 nanoseconds)");
  }
  std::uint64_t value = 0;
  if (!digits.empty()) {
    auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    if (ec != std::errc()) return bad(" (too large for int64 nanoseconds)");
  }
  if (round_up) ++value;
  if (value > static_cast<std::uint64_t>(kTimeLimitNs)) {
    return bad(" (beyond 146 years from the clock's zero, 2^62 ns: check the time unit)");
  }
  const auto signed_value = static_cast<TimeNs>(value);
  return negative ? -signed_value : signed_value;
}

Result<double> parse_double(std::string_view text) {
  const std::string_view s = trim(text);
  if (auto v = parse_finite_number(s)) return *v;
  // Say which: a number out of range or NaN, or no number at all.
  double any = 0.0;
  const std::string_view body = !s.empty() && s[0] == '+' ? s.substr(1) : s;
  const auto [ptr, ec] = std::from_chars(body.data(), body.data() + body.size(), any);
  const bool number = !body.empty() && ptr == body.data() + body.size() &&
                      (ec == std::errc() || ec == std::errc::result_out_of_range);
  return make_error(Errc::kCorrupt, quoted(s, number ? " is not a finite number" : " is not a number"));
}

std::string format_double(double value) {
  char buf[64];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, value);
  (void)ec;  // 64 bytes always hold the shortest form of a double
  return std::string(buf, ptr);
}

struct TriadRowReader::State {
  State(std::unique_ptr<TextLineReader> reader, std::string source_name, ProgressFn report)
      : file(std::move(reader)), lines(*file), source(std::move(source_name)), progress(std::move(report)) {}
  State(std::string_view text, std::string source_name, ProgressFn report)
      : lines(text), source(std::move(source_name)), progress(std::move(report)) {}

  std::unique_ptr<TextLineReader> file;  // before `lines`, which reads through it
  Lines lines;
  std::string source;
  ProgressFn progress;
  TimeNs prev_t = 0;
  int prev_line = 0;
  std::int64_t rows = 0;
  bool ended = false;
  std::optional<Error> failed;
};

TriadRowReader::TriadRowReader(std::unique_ptr<State> state) : state_(std::move(state)) {}

TriadRowReader::TriadRowReader(std::string_view text, const std::string& source, const ProgressFn& progress)
    : state_(std::make_unique<State>(text, source, progress)) {}

TriadRowReader::~TriadRowReader() = default;

Result<std::unique_ptr<TriadRowReader>> TriadRowReader::open(const std::string& path,
                                                             const ProgressFn& progress) {
  auto reader = TextLineReader::open(path);
  if (!reader.ok()) return reader.error();
  return std::unique_ptr<TriadRowReader>(
      new TriadRowReader(std::make_unique<State>(std::move(*reader), path, progress)));
}

Result<bool> TriadRowReader::next(TriadRow& row) {
  State& s = *state_;
  if (s.failed) return *s.failed;
  if (s.ended) return false;
  const auto fail = [&s](Error e) -> Result<bool> {
    s.failed = e;
    return e;
  };
  static constexpr const char* kNames[] = {"t", "x", "y", "z"};
  std::string_view line;
  while (s.lines.next(line)) {
    if (s.progress && (s.lines.number() & 0xffff) == 0)
      report_progress(s.progress, s.lines.offset(), s.lines.total());
    const std::size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    std::array<std::string_view, 4> fields;
    const std::size_t count = split_whitespace_first(line, fields);
    if (count == 0) continue;
    if (count != 4) {
      std::string msg = "expected 4 whitespace-separated fields (t x y z), found " + std::to_string(count);
      if (count == 1 && line.find(',') != std::string_view::npos) {
        msg += "; for comma-separated files use 'imucal import csv'";
      }
      return fail(at(s.source, s.lines.number(), msg));
    }
    auto t = parse_time_ns(fields[0], TimeUnit::kS);
    if (!t.ok()) return fail(at(s.source, s.lines.number(), "field 1 (t, seconds): " + t.error().message));
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) {
      auto x = parse_double(fields[static_cast<std::size_t>(k + 1)]);
      if (!x.ok()) {
        return fail(at(s.source, s.lines.number(),
                       "field " + std::to_string(k + 2) + " (" + kNames[k + 1] + "): " + x.error().message));
      }
      v[k] = *x;
    }
    if (auto e = check_increasing(s.source, s.prev_t, s.prev_line, *t, s.lines.number())) return fail(*e);
    s.prev_t = *t;
    s.prev_line = s.lines.number();
    ++s.rows;
    row.t_ns = *t;
    row.xyz = v;
    row.line = s.lines.number();
    return true;
  }
  if (auto e = s.lines.error(s.source)) return fail(*e);
  s.ended = true;
  report_progress(s.progress, 1.0, 1.0);
  if (s.rows == 0) {
    return fail(make_error(Errc::kCorrupt, s.source + ": no data rows (expected 't x y z' lines)"));
  }
  return false;
}

Result<bool> TriadSeriesSource::next(TriadRow& row) {
  if (next_ >= series_.t_ns.size()) return false;
  row.t_ns = series_.t_ns[next_];
  row.xyz = series_.xyz[next_];
  row.line = series_.line[next_];
  ++next_;
  return true;
}

namespace {

Result<TriadSeries> collect_rows(TriadRowReader& reader, const std::string& source) {
  TriadSeries series;
  series.source = source;
  TriadRow row;
  while (true) {
    auto more = reader.next(row);
    if (!more.ok()) return more.error();
    if (!*more) break;
    series.t_ns.push_back(row.t_ns);
    series.xyz.push_back(row.xyz);
    series.line.push_back(row.line);
  }
  return series;
}

}  // namespace

Result<TriadSeries> parse_triad_text(std::string_view text, const std::string& source,
                                     const ProgressFn& progress) {
  TriadRowReader reader(text, source, progress);
  return collect_rows(reader, source);
}

void IntervalMedian::add(TimeNs t_ns) {
  if (times_++ > 0) {
    const TimeNs interval = t_ns - last_;
    if (run_length_ > 0 && interval != run_interval_) {
      counts_[run_interval_] += run_length_;
      run_length_ = 0;
    }
    run_interval_ = interval;
    ++run_length_;
  }
  last_ = t_ns;
}

TimeNs IntervalMedian::median() const {
  if (times_ < 2) return 0;
  std::map<TimeNs, std::int64_t> counts = counts_;  // few entries
  if (run_length_ > 0) counts[run_interval_] += run_length_;
  const std::int64_t upper_middle = (times_ - 1) / 2;  // 0-based, of times_ - 1 intervals
  std::int64_t seen = 0;
  for (const auto& [interval, count] : counts) {
    seen += count;
    if (seen > upper_middle) return interval;
  }
  return counts.rbegin()->first;
}

namespace {

Result<TimeNs> period_from(std::int64_t times, const std::function<TimeNs()>& median_of, double rate_hz,
                           const std::string& source, const std::string& time_hint) {
  if (rate_hz > 0.0) {
    if (!(rate_hz <= 100'000.0)) {
      return make_error(Errc::kInvalidArgument,
                        "the given sample rate " + format_double(rate_hz) + " Hz is above 100 kHz")
          .with_remedy("rate_hz");
    }
    return static_cast<TimeNs>(std::llround(1e9 / rate_hz));
  }
  if (times < 2) {
    return make_error(Errc::kInsufficientData,
                      source + ": fewer than 2 samples, cannot estimate the sample rate; give it")
        .with_remedy("rate_hz");
  }
  const TimeNs median = median_of();
  if (median < 10'000 || median > 2 * kNsPerSecond) {
    return make_error(Errc::kCorrupt,
                      source + ": the median interval between samples is " + seconds_text(median) +
                          ", which is implausible for an IMU (0.5 Hz..100 kHz): check " + time_hint);
  }
  return median;
}

}  // namespace

Result<TimeNs> sample_period_ns(const IntervalMedian& intervals, double rate_hz, const std::string& source,
                                const std::string& time_hint) {
  return period_from(
      intervals.times(), [&intervals] { return intervals.median(); }, rate_hz, source, time_hint);
}

Result<TimeNs> sample_period_ns(const std::vector<TimeNs>& t_ns, double rate_hz, const std::string& source,
                                const std::string& time_hint) {
  return period_from(
      static_cast<std::int64_t>(t_ns.size()), [&t_ns] { return median_interval_ns(t_ns); }, rate_hz, source,
      time_hint);
}

namespace {

std::string where(const std::string& source, const TriadRow& row) {
  return source + ":" + std::to_string(row.line) + " (t = " + seconds_text(row.t_ns) + ")";
}

}  // namespace

TriadPairer::TriadPairer(TriadSource& accel, TriadSpan accel_span, TriadSource& gyro, TriadSpan gyro_span,
                         TimeNs period_ns)
    : accel_(accel),
      gyro_(gyro),
      accel_span_(std::move(accel_span)),
      gyro_span_(std::move(gyro_span)),
      half_(period_ns / 2) {}

// Rows further than half a period outside the other file's span are dropped: the first row of
// `source` inside it, or false at the end of the file.
Result<bool> TriadPairer::next_kept(TriadSource& source, const TriadSpan& other, std::int64_t* kept,
                                    TriadRow& row) {
  while (true) {
    auto more = source.next(row);
    if (!more.ok()) return more.error();
    if (!*more) return false;
    if (row.t_ns <= other.first_ns - half_ || row.t_ns >= other.last_ns + half_) continue;
    ++*kept;
    return true;
  }
}

Error TriadPairer::no_overlap() const {
  return make_error(Errc::kInsufficientData,
                    accel_span_.source + " (" + seconds_text(accel_span_.first_ns) + " .. " +
                        seconds_text(accel_span_.last_ns) + ") and " + gyro_span_.source + " (" +
                        seconds_text(gyro_span_.first_ns) + " .. " + seconds_text(gyro_span_.last_ns) +
                        ") do not overlap in time: are they from the same recording?");
}

Result<bool> TriadPairer::next(ImuSample& sample) {
  if (done_) return false;
  if (accel_span_.rows == 0 || gyro_span_.rows == 0) {
    done_ = true;
    return false;
  }
  // Built only for an error: this runs once per sample.
  const auto advice = [this] {
    return "; accelerometer and gyroscope rows must come from the same sampling instants (pairing tolerance "
           "is half the sample period, " +
           seconds_text(half_) +
           "): resample one file, or give the sample rate if the estimated one is wrong";
  };
  TriadRow a;
  auto more = next_kept(accel_, gyro_span_, &accel_kept_, a);
  if (!more.ok()) return more.error();
  if (!gyro_row_ && !gyro_done_) {
    TriadRow g;
    auto gyro_more = next_kept(gyro_, accel_span_, &gyro_kept_, g);
    if (!gyro_more.ok()) return gyro_more.error();
    if (*gyro_more) {
      gyro_row_ = g;
    } else {
      gyro_done_ = true;
    }
  }
  if (!*more) {
    done_ = true;
    if (accel_kept_ == 0 || (gyro_done_ && gyro_kept_ == 0)) return no_overlap();
    if (gyro_row_) {
      return make_error(Errc::kCorrupt,
                        "no accelerometer row pairs with " + where(gyro_span_.source, *gyro_row_) + advice());
    }
    stats_.dropped_accel = static_cast<int>(accel_span_.rows - accel_kept_);
    stats_.dropped_gyro = static_cast<int>(gyro_span_.rows - gyro_kept_);
    return false;
  }
  if (gyro_done_ && gyro_kept_ == 0) return no_overlap();
  const TimeNs t = a.t_ns;
  if (gyro_row_ && gyro_row_->t_ns <= t - half_) {
    return make_error(Errc::kCorrupt, "no accelerometer row pairs with " +
                                          where(gyro_span_.source, *gyro_row_) + "; nearest is " +
                                          where(accel_span_.source, a) + advice());
  }
  if (!gyro_row_ || std::llabs(gyro_row_->t_ns - t) >= half_) {
    const std::string nearest =
        gyro_row_ ? "; nearest gyroscope row is " + where(gyro_span_.source, *gyro_row_) : "";
    return make_error(Errc::kCorrupt,
                      "no gyroscope row pairs with " + where(accel_span_.source, a) + nearest + advice());
  }
  if (gyro_row_->t_ns == t) {
    ++stats_.exact;
  } else {
    ++stats_.nearest;
  }
  sample = ImuSample{};
  sample.t_ns = t;
  sample.accel = a.xyz;
  sample.gyro = gyro_row_->xyz;
  gyro_row_.reset();
  return true;
}

Result<std::vector<ImuSample>> pair_accel_gyro(const TriadSeries& accel, const TriadSeries& gyro,
                                               TimeNs period_ns, PairingStats* stats) {
  const auto span = [](const TriadSeries& s) {
    TriadSpan out;
    out.source = s.source;
    out.rows = static_cast<std::int64_t>(s.t_ns.size());
    if (!s.t_ns.empty()) {
      out.first_ns = s.t_ns.front();
      out.last_ns = s.t_ns.back();
    }
    return out;
  };
  TriadSeriesSource accel_rows(accel), gyro_rows(gyro);
  TriadPairer pairer(accel_rows, span(accel), gyro_rows, span(gyro), period_ns);
  std::vector<ImuSample> samples;
  samples.reserve(accel.t_ns.size());
  ImuSample s;
  while (true) {
    auto more = pairer.next(s);
    if (!more.ok()) return more.error();
    if (!*more) break;
    samples.push_back(s);
  }
  if (stats) *stats = pairer.stats();
  return samples;
}

Result<CsvColumns> parse_csv_columns(const std::string& spec) {
  CsvColumns c;
  const std::pair<const char*, int CsvColumns::*> names[] = {
      {"t", &CsvColumns::t},   {"ax", &CsvColumns::ax}, {"ay", &CsvColumns::ay}, {"az", &CsvColumns::az},
      {"gx", &CsvColumns::gx}, {"gy", &CsvColumns::gy}, {"gz", &CsvColumns::gz}, {"temp", &CsvColumns::temp}};
  const std::string usage =
      " (expected e.g. t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6[,temp=7]; columns count from 0)";
  std::set<int> used;
  std::set<std::string> seen;
  std::vector<std::string_view> items;
  split_delimited(spec, ',', items);
  for (std::string_view item : items) {
    const std::size_t eq = item.find('=');
    if (eq == std::string_view::npos) {
      return make_error(Errc::kInvalidArgument,
                        "column map: '" + printable(item) + "' is not name=index" + usage)
          .with_remedy("columns");
    }
    const std::string name(trim(item.substr(0, eq)));
    const std::string_view index_text = trim(item.substr(eq + 1));
    int index = -1;
    auto [ptr, ec] = std::from_chars(index_text.data(), index_text.data() + index_text.size(), index);
    if (ec != std::errc() || ptr != index_text.data() + index_text.size() || index < 0 || index > 1000) {
      return make_error(Errc::kInvalidArgument, "column map: index '" + printable(index_text) + "' of " +
                                                    name + " is not 0..1000" + usage)
          .with_remedy("columns");
    }
    const auto it =
        std::find_if(std::begin(names), std::end(names), [&](const auto& n) { return name == n.first; });
    if (it == std::end(names)) {
      return make_error(Errc::kInvalidArgument, "column map: unknown name '" + name + "'" + usage)
          .with_remedy("columns");
    }
    if (!seen.insert(name).second) {
      return make_error(Errc::kInvalidArgument, "column map: " + name + " is given twice")
          .with_remedy("columns");
    }
    if (!used.insert(index).second) {
      return make_error(Errc::kInvalidArgument,
                        "column map: column " + std::to_string(index) + " is mapped twice (" + name + ")")
          .with_remedy("columns");
    }
    c.*(it->second) = index;
  }
  for (const auto& [name, member] : names) {
    if (std::string(name) != "temp" && c.*member < 0) {
      return make_error(Errc::kInvalidArgument, std::string("column map: ") + name + " is missing" + usage)
          .with_remedy("columns");
    }
  }
  return c;
}

namespace {

Status csv_rows(Lines& lines, const std::string& source, const CsvFormat& format, const ProgressFn& progress,
                const std::function<Status(const ImuSample&)>& visit) {
  const CsvColumns& c = format.columns;
  const std::pair<const char*, int> mapped[] = {{"t", c.t},   {"ax", c.ax}, {"ay", c.ay}, {"az", c.az},
                                                {"gx", c.gx}, {"gy", c.gy}, {"gz", c.gz}, {"temp", c.temp}};
  int max_column = 0;
  for (const auto& [name, index] : mapped) max_column = std::max(max_column, index);
  std::int64_t rows = 0;
  TimeNs prev_t = 0;
  std::string_view line;
  std::vector<std::string_view> fields;
  int prev_line = 0;
  while (lines.next(line)) {
    if (progress && (lines.number() & 0xffff) == 0) report_progress(progress, lines.offset(), lines.total());
    if (lines.number() <= format.skip_header) continue;
    const std::string_view content = trim(line);
    if (content.empty() || content.front() == '#') continue;
    split_delimited(content, format.delimiter, fields);
    const bool first_row = rows == 0;
    const bool maybe_header = first_row && format.skip_header == 0;
    const std::string header_hint = maybe_header ? " (if this line is a header, skip it)" : "";
    if (static_cast<int>(fields.size()) <= max_column) {
      std::string delim = format.delimiter == ' ' ? "whitespace" : std::string("'") + format.delimiter + "'";
      Error e = at(source, lines.number(),
                   "has " + std::to_string(fields.size()) + " columns separated by " + delim +
                       ", the mapping needs column " + std::to_string(max_column) +
                       " (columns count from 0; check the column map and the delimiter)" + header_hint)
                    .with_remedy("columns")
                    .with_remedy("delimiter");
      return maybe_header ? e.with_remedy("skip_header", "1") : e;
    }
    ImuSample s;
    for (const auto& [name, index] : mapped) {
      if (index < 0) continue;
      const std::string_view field = fields[static_cast<std::size_t>(index)];
      const std::string col = "column " + std::to_string(index) + " (" + name + "): ";
      if (std::string(name) == "t") {
        auto t = parse_time_ns(field, format.time_unit);
        if (!t.ok()) {
          Error e = at(source, lines.number(), col + t.error().message + header_hint);
          return maybe_header ? e.with_remedy("skip_header", "1") : e;
        }
        s.t_ns = *t;
        continue;
      }
      auto v = parse_double(field);
      if (!v.ok()) {
        Error e = at(source, lines.number(), col + v.error().message + header_hint);
        return maybe_header ? e.with_remedy("skip_header", "1") : e;
      }
      const std::string n(name);
      if (n == "ax") s.accel.x() = *v;
      if (n == "ay") s.accel.y() = *v;
      if (n == "az") s.accel.z() = *v;
      if (n == "gx") s.gyro.x() = *v;
      if (n == "gy") s.gyro.y() = *v;
      if (n == "gz") s.gyro.z() = *v;
      if (n == "temp") s.temperature = *v;
    }
    if (auto e = check_increasing(source, prev_t, prev_line, s.t_ns, lines.number())) return *e;
    prev_t = s.t_ns;
    prev_line = lines.number();
    ++rows;
    IMUCAL_TRY(visit(s));
  }
  if (auto e = lines.error(source)) return *e;
  report_progress(progress, 1.0, 1.0);
  if (rows == 0) return make_error(Errc::kCorrupt, source + ": no data rows");
  return {};
}

Result<std::vector<ImuSample>> parse_csv(Lines& lines, const std::string& source, const CsvFormat& format,
                                         const ProgressFn& progress) {
  std::vector<ImuSample> samples;
  IMUCAL_TRY(csv_rows(lines, source, format, progress, [&samples](const ImuSample& s) {
    samples.push_back(s);
    return Status{};
  }));
  return samples;
}

}  // namespace

Result<std::vector<ImuSample>> parse_imu_csv(std::string_view text, const std::string& source,
                                             const CsvFormat& format, const ProgressFn& progress) {
  Lines lines(text);
  return parse_csv(lines, source, format, progress);
}

Status for_each_csv_sample(const std::string& path, const CsvFormat& format,
                           const std::function<Status(const ImuSample&)>& visit, const ProgressFn& progress) {
  auto reader = TextLineReader::open(path);
  if (!reader.ok()) return reader.error();
  Lines lines(**reader);
  return csv_rows(lines, path, format, progress, visit);
}

namespace {

Status euroc_imu_rows(Lines& lines, const std::string& source,
                      const std::function<Status(const ImuSample&)>& visit) {
  TimeNs prev_t = 0;
  std::string_view line;
  std::vector<std::string_view> fields;
  static constexpr const char* kNames[] = {"timestamp [ns]", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z",
                                           "a_RS_S_x",       "a_RS_S_y", "a_RS_S_z"};
  int prev_line = 0;
  while (lines.next(line)) {
    const std::string_view content = trim(line);
    if (content.empty() || content.front() == '#') continue;
    split_delimited(content, ',', fields);
    if (fields.size() != 7) {
      return at(source, lines.number(),
                "expected 7 comma-separated columns (timestamp [ns], w_RS_S_x/y/z [rad s^-1], "
                "a_RS_S_x/y/z [m s^-2]), found " +
                    std::to_string(fields.size()));
    }
    ImuSample s;
    auto [ptr, ec] = std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), s.t_ns);
    if (fields[0].empty() || ec != std::errc() || ptr != fields[0].data() + fields[0].size()) {
      return at(
          source, lines.number(),
          "column 1 (timestamp [ns]): '" + printable(fields[0]) + "' is not an integer nanosecond time");
    }
    if (!time_in_range(s.t_ns)) {
      return at(source, lines.number(),
                "column 1 (timestamp [ns]): '" + printable(fields[0]) +
                    "' is beyond 146 years from the clock's zero (2^62 ns)");
    }
    for (int k = 0; k < 6; ++k) {
      auto v = parse_double(fields[static_cast<std::size_t>(k + 1)]);
      if (!v.ok()) {
        return at(source, lines.number(),
                  "column " + std::to_string(k + 2) + " (" + kNames[k + 1] + "): " + v.error().message);
      }
      if (k < 3) {
        s.gyro[k] = *v;
      } else {
        s.accel[k - 3] = *v;
      }
    }
    if (auto e = check_increasing(source, prev_t, prev_line, s.t_ns, lines.number())) return *e;
    prev_t = s.t_ns;
    prev_line = lines.number();
    IMUCAL_TRY(visit(s));
  }
  if (auto e = lines.error(source)) return *e;
  return {};
}

Result<std::vector<ImuSample>> parse_euroc_imu(Lines& lines, const std::string& source) {
  std::vector<ImuSample> samples;
  IMUCAL_TRY(euroc_imu_rows(lines, source, [&samples](const ImuSample& s) {
    samples.push_back(s);
    return Status{};
  }));
  return samples;
}

}  // namespace

Result<std::vector<ImuSample>> parse_euroc_imu_csv(std::string_view text, const std::string& source) {
  Lines lines(text);
  return parse_euroc_imu(lines, source);
}

Status for_each_euroc_imu_sample(const std::string& path,
                                 const std::function<Status(const ImuSample&)>& visit) {
  auto reader = TextLineReader::open(path);
  if (!reader.ok()) return reader.error();
  Lines lines(**reader);
  return euroc_imu_rows(lines, path, visit);
}

Result<std::vector<EurocImageRow>> parse_euroc_camera_csv(std::string_view text, const std::string& source) {
  std::vector<EurocImageRow> rows;
  Lines lines(text);
  std::string_view line;
  std::vector<std::string_view> fields;
  while (lines.next(line)) {
    const std::string_view content = trim(line);
    if (content.empty() || content.front() == '#') continue;
    split_delimited(content, ',', fields);
    if (fields.size() != 2) {
      return at(source, lines.number(),
                "expected 2 comma-separated columns (timestamp [ns], filename), found " +
                    std::to_string(fields.size()));
    }
    EurocImageRow row;
    row.line = lines.number();
    auto [ptr, ec] = std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), row.t_ns);
    if (fields[0].empty() || ec != std::errc() || ptr != fields[0].data() + fields[0].size()) {
      return at(
          source, lines.number(),
          "column 1 (timestamp [ns]): '" + printable(fields[0]) + "' is not an integer nanosecond time");
    }
    if (!time_in_range(row.t_ns)) {
      return at(source, lines.number(),
                "column 1 (timestamp [ns]): '" + printable(fields[0]) +
                    "' is beyond 146 years from the clock's zero (2^62 ns)");
    }
    row.filename = std::string(fields[1]);
    if (row.filename.empty() || row.filename.find('/') != std::string::npos || row.filename == "." ||
        row.filename == "..") {
      return at(
          source, lines.number(),
          "column 2 (filename): '" + printable(row.filename) + "' must be a plain file name inside data/");
    }
    if (!rows.empty()) {
      if (auto e = check_increasing(source, rows.back().t_ns, rows.back().line, row.t_ns, row.line))
        return *e;
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace imucal::log
