// SPDX-License-Identifier: BSD-3-Clause
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "log/dataset_io.hpp"
#include "tests/support/test_helpers.hpp"

namespace imucal::log {
namespace {

/// True when `error` names the remedy `option` (with `value`, when given).
using test::has_remedy;

using ::testing::HasSubstr;

TEST(DatasetTime, ParsesDecimalSecondsExactly) {
  EXPECT_EQ(*parse_time_ns("1403636579.763555527", TimeUnit::kS), 1403636579763555527);
  EXPECT_EQ(*parse_time_ns("0.005", TimeUnit::kS), 5'000'000);
  EXPECT_EQ(*parse_time_ns("12", TimeUnit::kS), 12'000'000'000);
  EXPECT_EQ(*parse_time_ns("-1.5", TimeUnit::kS), -1'500'000'000);
  EXPECT_EQ(*parse_time_ns("+.25", TimeUnit::kS), 250'000'000);
  EXPECT_EQ(*parse_time_ns("1.5e-3", TimeUnit::kS), 1'500'000);
  EXPECT_EQ(*parse_time_ns("1E2", TimeUnit::kMs), 100'000'000);
  EXPECT_EQ(*parse_time_ns("2.5", TimeUnit::kUs), 2'500);
  EXPECT_EQ(*parse_time_ns("17", TimeUnit::kNs), 17);
  EXPECT_EQ(*parse_time_ns("0.0000000014", TimeUnit::kS), 1);  // rounds to nearest ns
  EXPECT_EQ(*parse_time_ns("0.0000000015", TimeUnit::kS), 2);
  EXPECT_EQ(*parse_time_ns("000.000", TimeUnit::kS), 0);
}

// The common short form is parsed in integer arithmetic, anything longer by the general parser:
// the same number written with 20 more zeros after its last decimal (which only the general parser
// takes) must give the same time, or the same refusal.
TEST(DatasetTime, TheShortFormAndTheGeneralParserAgree) {
  std::mt19937 rng(11);
  const auto pick = [&](int n) { return static_cast<int>(rng() % static_cast<unsigned>(n)); };
  const auto digits = [&](int n) {
    std::string d;
    for (int k = 0; k < n; ++k) d.push_back(static_cast<char>('0' + pick(pick(3) == 0 ? 2 : 10)));
    return d;
  };
  const TimeUnit units[] = {TimeUnit::kS, TimeUnit::kMs, TimeUnit::kUs, TimeUnit::kNs};
  const char* const signs[] = {"", "+", "-"};
  int accepted = 0;
  for (int k = 0; k < 20000; ++k) {
    const std::string sign = signs[pick(3)];
    std::string whole = digits(pick(13)), frac = digits(pick(13));
    if (whole.empty() && frac.empty()) whole = "7";
    std::string exponent;
    if (pick(2) == 0) exponent = std::string(pick(2) ? "e" : "E") + signs[pick(3)] + digits(1 + pick(3));
    const bool dot = !frac.empty() || pick(2) == 0;
    const std::string text = sign + whole + (dot ? "." : "") + frac + exponent;
    const std::string longer = sign + whole + "." + frac + std::string(20, '0') + exponent;
    const TimeUnit unit = units[pick(4)];
    const auto a = parse_time_ns(text, unit);
    const auto b = parse_time_ns(longer, unit);
    ASSERT_EQ(a.ok(), b.ok()) << text << " / " << longer;
    if (a.ok()) {
      EXPECT_EQ(*a, *b) << text << " / " << longer;
      ++accepted;
    }
  }
  EXPECT_GT(accepted, 10000);  // most of them are times, so the comparison has teeth
}

TEST(DatasetTime, RejectsGarbageAndOverflow) {
  for (const char* bad :
       {"", "abc", "1.2.3", "1e", "--1", "+-1", "1e+-5", "1e++5", "1,5", "nan", "inf", "0x10"}) {
    auto t = parse_time_ns(bad, TimeUnit::kS);
    EXPECT_FALSE(t.ok()) << bad;
  }
  for (const char* bad : {"+-1", "++1", "+", "1e+-5", "inf", "nan", ""}) {
    auto v = parse_double(bad);
    EXPECT_FALSE(v.ok()) << bad;
  }
  EXPECT_EQ(*parse_double("+1.5e-3"), 1.5e-3);
  EXPECT_EQ(*parse_double("-2"), -2.0);
  auto big = parse_time_ns("1e12", TimeUnit::kS);  // 1e21 ns
  ASSERT_FALSE(big.ok());
  EXPECT_THAT(big.error().message, HasSubstr("too large"));
  EXPECT_TRUE(parse_time_unit("us").ok());
  EXPECT_FALSE(parse_time_unit("sec").ok());
}

TEST(DatasetNumbers, ShortestFormatRoundTripsBitForBit) {
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<std::uint64_t> bits;
  int tested = 0;
  while (tested < 20000) {
    const std::uint64_t b = bits(rng);
    double v;
    std::memcpy(&v, &b, sizeof v);
    if (!std::isfinite(v)) continue;
    ++tested;
    auto back = parse_double(format_double(v));
    ASSERT_TRUE(back.ok()) << format_double(v);
    std::uint64_t b2;
    std::memcpy(&b2, &*back, sizeof b2);
    ASSERT_EQ(b, b2) << format_double(v);
  }
  EXPECT_EQ(format_double(0.1), "0.1");
  EXPECT_EQ(format_double(-9.81), "-9.81");
  EXPECT_FALSE(parse_double("1.0x").ok());
  EXPECT_FALSE(parse_double("nan").ok());
  EXPECT_EQ(*parse_double(" +2.5 "), 2.5);
}

TEST(DatasetTriads, ParsesRowsCommentsAndBlankLines) {
  const std::string text =
      "# imu_tk style accelerometer file\n"
      "\n"
      "0.000 1 2 3\n"
      "0.010\t4  5 6   # trailing comment\r\n"
      "0.020 -7e-1 8.5 +9\n";
  auto s = parse_triad_text(text, "acc.txt");
  ASSERT_TRUE(s.ok()) << s.error().message;
  ASSERT_EQ(s->t_ns.size(), 3u);
  EXPECT_EQ(s->t_ns[1], 10'000'000);
  EXPECT_EQ(s->line[1], 4);
  EXPECT_EQ(s->xyz[2], Eigen::Vector3d(-0.7, 8.5, 9));
}

TEST(DatasetTriads, MalformedRowsNameFileLineAndField) {
  struct Case {
    const char* text;
    const char* expected;
  };
  for (const Case& c : {
           Case{"0 1 2 3\n0.01 1 2\n", "acc.txt:2: expected 4 whitespace-separated fields"},
           Case{"0 1 2 3\n\n0.01 1 x 3\n", "acc.txt:3: field 3 (y): 'x' is not a number"},
           Case{"0,1,2,3\n", "use 'imucal import csv'"},
           Case{"zero 1 2 3\n", "acc.txt:1: field 1 (t, seconds)"},
           Case{"0 1 2 3\n0.01 1 2 3\n0.01 1 2 3\n", "acc.txt:3: duplicate timestamp (same as line 2)"},
           Case{"0 1 2 3\n0.01 1 2 3\n0.01 1 2 3\n", "rebuild them from the row index and the rate"},
           Case{"0 1 2 3\n0.02 1 2 3\n0.01 1 2 3\n", "acc.txt:3: timestamp goes backwards"},
       }) {
    auto s = parse_triad_text(c.text, "acc.txt");
    ASSERT_FALSE(s.ok()) << c.text;
    EXPECT_THAT(s.error().message, HasSubstr(c.expected));
  }
  auto empty = parse_triad_text("# nothing\n\n", "acc.txt");
  ASSERT_FALSE(empty.ok());
  EXPECT_THAT(empty.error().message, HasSubstr("no data rows"));
}

TriadSeries series(const std::string& name, std::vector<TimeNs> t) {
  TriadSeries s;
  s.source = name;
  for (std::size_t i = 0; i < t.size(); ++i) {
    s.t_ns.push_back(t[i]);
    s.xyz.emplace_back(static_cast<double>(i), 0, 0);
    s.line.push_back(static_cast<int>(i) + 1);
  }
  return s;
}

TEST(DatasetPairing, ExactNearestAndDroppedEnds) {
  const TimeNs p = 10'000'000;
  auto a = series("a.txt", {0, p, 2 * p, 3 * p});
  auto g = series("g.txt", {p + 1000, 2 * p - 2000, 3 * p, 4 * p});
  PairingStats st;
  auto s = pair_accel_gyro(a, g, p, &st);
  ASSERT_TRUE(s.ok()) << s.error().message;
  ASSERT_EQ(s->size(), 3u);
  EXPECT_EQ((*s)[0].t_ns, p);  // accelerometer time
  EXPECT_EQ((*s)[0].gyro.x(), 0.0);
  EXPECT_EQ((*s)[2].gyro.x(), 2.0);
  EXPECT_EQ(st.exact, 1);
  EXPECT_EQ(st.nearest, 2);
  EXPECT_EQ(st.dropped_accel, 1);
  EXPECT_EQ(st.dropped_gyro, 1);
}

TEST(DatasetPairing, UnpairableRowIsAnError) {
  const TimeNs p = 10'000'000;
  auto a = series("a.txt", {0, p, 2 * p, 3 * p});
  auto g = series("g.txt", {0, p + p / 2 + 1, 2 * p, 3 * p});
  auto s = pair_accel_gyro(a, g, p);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.error().message, HasSubstr("a.txt:2"));
  EXPECT_THAT(s.error().message, HasSubstr("half"));
  auto far = pair_accel_gyro(series("a.txt", {0, p}), series("g.txt", {100 * p, 101 * p}), p);
  ASSERT_FALSE(far.ok());
  EXPECT_THAT(far.error().message, HasSubstr("do not overlap"));
}

TEST(DatasetPairing, PeriodEstimateAndImplausibleRates) {
  auto p =
      sample_period_ns({0, 5'000'000, 10'000'000, 15'000'000, 40'000'000}, 0.0, "a.txt", "the time unit");
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(*p, 5'000'000);
  EXPECT_EQ(*sample_period_ns({0, 1}, 200.0, "a.txt", "x"), 5'000'000);
  auto too_fast = sample_period_ns({0, 5, 10}, 0.0, "a.txt", "the time unit");
  ASSERT_FALSE(too_fast.ok());
  EXPECT_THAT(too_fast.error().message, HasSubstr("check the time unit"));
}

TEST(DatasetCsv, ColumnMapping) {
  auto c = parse_csv_columns("t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6,temp=7");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->temp, 7);
  EXPECT_EQ(c->gz, 6);
  for (const char* bad :
       {"t=0,ax=1,ay=2,az=3,gx=4,gy=5", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=5",
        "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6,wx=7", "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=-1", "t0,ax=1"}) {
    EXPECT_FALSE(parse_csv_columns(bad).ok()) << bad;
  }
}

TEST(DatasetCsv, ParsesMappedColumnsWithUnitsAndHeader) {
  const std::string text =
      "time_ms;gz;gy;gx;az;ay;az_dup;ax;temp\n"
      "1000.5; 0.3;0.2;0.1;9.8;0.0;0;0.01;25.5\n"
      "1005.5; 0.3;0.2;0.1;9.8;0.0;0;0.02;25.6\n";
  CsvFormat f;
  f.columns = *parse_csv_columns("t=0,gz=1,gy=2,gx=3,az=4,ay=5,ax=7,temp=8");
  f.time_unit = TimeUnit::kMs;
  f.delimiter = ';';
  f.skip_header = 1;
  auto s = parse_imu_csv(text, "data.csv", f);
  ASSERT_TRUE(s.ok()) << s.error().message;
  ASSERT_EQ(s->size(), 2u);
  EXPECT_EQ((*s)[0].t_ns, 1'000'500'000);
  EXPECT_EQ((*s)[1].accel, Eigen::Vector3d(0.02, 0.0, 9.8));
  EXPECT_EQ((*s)[1].gyro, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_EQ((*s)[1].temperature, 25.6);

  f.skip_header = 0;
  auto header = parse_imu_csv(text, "data.csv", f);
  ASSERT_FALSE(header.ok());
  EXPECT_THAT(header.error().message, HasSubstr("data.csv:1: column 0 (t)"));
  EXPECT_TRUE(has_remedy(header.error(), "skip_header", "1")) << header.error().message;
  EXPECT_THAT(header.error().message, HasSubstr("if this line is a header"));
}

TEST(DatasetCsv, MalformedRowsNameLineAndColumn) {
  CsvFormat f;
  f.columns = *parse_csv_columns("t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6");
  auto short_row = parse_imu_csv("0,1,2,3,4,5,6\n0.01,1,2,3,4,5\n", "d.csv", f);
  ASSERT_FALSE(short_row.ok());
  EXPECT_THAT(short_row.error().message, HasSubstr("d.csv:2: has 6 columns"));
  auto bad_value = parse_imu_csv("0,1,2,3,4,5,6\n0.01,1,2,3,4,five,6\n", "d.csv", f);
  ASSERT_FALSE(bad_value.ok());
  EXPECT_THAT(bad_value.error().message, HasSubstr("d.csv:2: column 5 (gy): 'five' is not a number"));
  auto dup = parse_imu_csv("0,1,2,3,4,5,6\n0,1,2,3,4,5,6\n", "d.csv", f);
  ASSERT_FALSE(dup.ok());
  EXPECT_THAT(dup.error().message, HasSubstr("d.csv:2: duplicate timestamp"));
  f.delimiter = ' ';
  auto ws = parse_imu_csv("0 1 2 3 4 5 6\n0.01\t1 2 3 4 5 6\n", "d.txt", f);
  ASSERT_TRUE(ws.ok()) << ws.error().message;
  EXPECT_EQ(ws->size(), 2u);
}

std::vector<ImuSample> at_rest(const Eigen::Vector3d& a, bool integral) {
  std::vector<ImuSample> s(100);
  for (std::size_t i = 0; i < s.size(); ++i) {
    s[i].t_ns = static_cast<TimeNs>(i) * 5'000'000;
    s[i].accel = a + Eigen::Vector3d::Constant(integral ? static_cast<double>(i % 3) : 0.001 * (i % 7));
  }
  return s;
}

// The median interval counted one time at a time equals the one of the whole series (the upper
// median for an even count), for regular, jittered and gapped times.
TEST(DatasetPairing, IntervalMedianFedOneTimeAtATimeIsTheSeriesMedian) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 50; ++trial) {
    std::uniform_int_distribution<int> length(0, 400), jitter(-3, 3), gap(0, 30);
    std::vector<TimeNs> t;
    TimeNs now = 1'000;
    for (int i = length(rng); i > 0; --i) {
      now += 100 + jitter(rng) + (gap(rng) == 0 ? 5000 : 0);
      t.push_back(now);
    }
    IntervalMedian m;
    for (const TimeNs x : t) m.add(x);
    EXPECT_EQ(m.times(), static_cast<std::int64_t>(t.size()));
    EXPECT_EQ(m.median(), median_interval_ns(t)) << trial;
    auto from_vector = sample_period_ns(t, 0.0, "a.txt", "the time unit");
    auto from_counts = sample_period_ns(m, 0.0, "a.txt", "the time unit");
    ASSERT_EQ(from_vector.ok(), from_counts.ok()) << trial;
    if (from_vector.ok()) {
      EXPECT_EQ(*from_vector, *from_counts);
    } else {
      EXPECT_EQ(from_vector.error().message, from_counts.error().message);
    }
  }
}

// The unit check fed one sample at a time keeps an evenly spaced subset (every 2^k-th) of
// 20000 to 40000: a long recording of raw counts called SI is still refused, a few odd samples
// do not move its median.
TEST(DatasetUnits, TheStreamedCheckKeepsAnEvenlySpacedSubset) {
  UnitCheck counts, si;
  for (int i = 0; i < 250'000; ++i) {
    counts.add(i % 1000 == 0 ? Eigen::Vector3d(0.1, 0.2, 9.8) : Eigen::Vector3d(10, -20, 16384 + i % 7));
    si.add(i % 1000 == 0 ? Eigen::Vector3d(0, 0, 16384) : Eigen::Vector3d(0.1, 0.2, 9.79 + 1e-6 * (i % 5)));
  }
  EXPECT_TRUE(counts.check(ImuUnits::kRaw, "f").ok());
  auto wrong = counts.check(ImuUnits::kSi, "f");
  ASSERT_FALSE(wrong.ok());
  EXPECT_TRUE(has_remedy(wrong.error(), "units", "raw"));
  EXPECT_TRUE(si.check(ImuUnits::kSi, "f").ok());
  EXPECT_FALSE(si.check(ImuUnits::kRaw, "f").ok());
}

TEST(DatasetUnits, DetectsRawCountsImportedAsSiAndViceVersa) {
  auto raw = at_rest({0, 0, 16384}, true);
  auto si = at_rest({0.1, 0.2, 9.79}, false);
  auto g = at_rest({0.01, 0.02, 0.998}, false);
  EXPECT_TRUE(check_units(raw, ImuUnits::kRaw, "f").ok());
  EXPECT_TRUE(check_units(si, ImuUnits::kSi, "f").ok());
  auto s1 = check_units(raw, ImuUnits::kSi, "f");
  ASSERT_FALSE(s1.ok());
  EXPECT_TRUE(has_remedy(s1.error(), "units", "raw"));
  EXPECT_TRUE(has_remedy(s1.error(), "unit_check", "off"));
  auto s2 = check_units(si, ImuUnits::kRaw, "f");
  ASSERT_FALSE(s2.ok());
  EXPECT_TRUE(has_remedy(s2.error(), "units", "si"));
  auto s3 = check_units(g, ImuUnits::kSi, "f");
  ASSERT_FALSE(s3.ok());
  EXPECT_THAT(s3.error().message, HasSubstr("look like g"));
}

TEST(DatasetEuroc, ParsesImuAndCameraCsv) {
  const std::string imu =
      "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
      "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\r\n"
      "1403636579758555392,-0.099134701513277898,0.14730578886832138,0.02722713633111154,8.1476917083333333,"
      "-0.37592158333333331,-2.4026292499999999\r\n";
  auto s = parse_euroc_imu_csv(imu, "imu0/data.csv");
  ASSERT_TRUE(s.ok()) << s.error().message;
  ASSERT_EQ(s->size(), 1u);
  EXPECT_EQ((*s)[0].t_ns, 1403636579758555392);
  EXPECT_EQ((*s)[0].gyro.x(), -0.099134701513277898);
  EXPECT_EQ((*s)[0].accel.z(), -2.4026292499999999);
  auto bad = parse_euroc_imu_csv("#h\n1,2,3,4,5,6,7\n2.5,2,3,4,5,6,7\n", "imu0/data.csv");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, HasSubstr("imu0/data.csv:3: column 1 (timestamp [ns])"));

  auto cam = parse_euroc_camera_csv("#timestamp [ns],filename\n10,10.png\n20,20.png\n", "cam0/data.csv");
  ASSERT_TRUE(cam.ok()) << cam.error().message;
  ASSERT_EQ(cam->size(), 2u);
  EXPECT_EQ((*cam)[1].filename, "20.png");
  EXPECT_EQ((*cam)[1].line, 3);
  auto evil = parse_euroc_camera_csv("10,../../etc/passwd\n", "cam0/data.csv");
  ASSERT_FALSE(evil.ok());
  EXPECT_THAT(evil.error().message, HasSubstr("plain file name"));
}

}  // namespace
}  // namespace imucal::log
