// SPDX-License-Identifier: BSD-3-Clause
// What the live view costs the service's event loop (docs/benchmarks.md, "Live view"): a camera
// frame made into the view's frame and PNG (done on the loop for each frame sent, at most
// live_view.frame_rate_hz a camera, and only while somebody watches), and one frame event with a
// live-figures message fanned out to N watchers over loopback TCP, each also fetching the PNG as
// the page does. The time reported for the fan-out is the loop thread's CPU time
// (CLOCK_THREAD_CPUTIME_ID), not the wall clock: the watchers' threads share the machine.
#include <benchmark/benchmark.h>
#include <time.h>

#include <atomic>
#include <boost/asio/post.hpp>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "app/session/view_coverage.hpp"
#include "daemon/service/live_view_server.hpp"
#include "tests/daemon/service_test_host.hpp"
#include "tests/support/live_view_client.hpp"

namespace imucal {
namespace {

constexpr int kWidth = 752, kHeight = 480;  // the MT9V034's frame, as on the EuRoC rigs

TargetDescription board() {
  TargetDescription t;
  t.type = TargetDescription::Type::kCheckerboard;
  t.cols = 7;
  t.rows = 6;
  t.col_spacing_m = t.row_spacing_m = 0.05;
  return t;
}

/// A checkerboard seen square on, with the sensor noise of a real frame (2 grey levels rms:
/// a noiseless image would compress far better than a camera's), and its 42 inner corners.
struct Frame {
  std::vector<std::uint8_t> grey;
  std::vector<Eigen::Vector2d> px;
  std::vector<int> ids;
};
Frame board_frame() {
  Frame f;
  f.grey.resize(static_cast<std::size_t>(kWidth) * kHeight);
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 2.0);
  const double x0 = 176, y0 = 100, s = 50;  // 8 x 7 squares from (x0, y0)
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      const int cx = static_cast<int>(std::floor((x - x0) / s)),
                cy = static_cast<int>(std::floor((y - y0) / s));
      const bool inside = cx >= 0 && cx < 8 && cy >= 0 && cy < 7;
      const double v = inside ? ((cx + cy) % 2 ? 30.0 : 220.0) : 128.0;
      f.grey[static_cast<std::size_t>(y) * kWidth + x] =
          static_cast<std::uint8_t>(std::clamp(v + noise(rng), 0.0, 255.0));
    }
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 7; ++c) {
      f.px.emplace_back(x0 + (c + 1) * s, y0 + (r + 1) * s);
      f.ids.push_back(r * 7 + c);
    }
  return f;
}

/// The work done on the loop for a frame the view is sent: shrunk to the view's width, its
/// corners moved with it, and encoded as PNG.
void BM_ViewFrameAndPng(benchmark::State& state) {
  const Frame f = board_frame();
  const TargetDescription t = board();
  const int width = static_cast<int>(state.range(0));
  std::size_t png_bytes = 0;
  for (auto _ : state) {
    ViewFrame v = app::session::make_view_frame(f.grey.data(), kWidth, kHeight, width, f.px, f.ids, t);
    auto png = app::session::view_frame_png(v);
    if (!png.ok()) state.SkipWithError(png.error().message.c_str());
    png_bytes = png.ok() ? png->size() : 0;
    benchmark::DoNotOptimize(png_bytes);
  }
  state.counters["png_bytes"] = static_cast<double>(png_bytes);
}
BENCHMARK(BM_ViewFrameAndPng)->Arg(320)->Arg(640)->Unit(benchmark::kMillisecond);

double thread_cpu_s() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// One frame event (with its PNG kept for the fetches) and one live-figures message to N
/// watchers; the time is the loop thread's CPU from the publication until every watcher has the
/// frame (and, with fetches, its PNG served).
void BM_LiveViewFanOut(benchmark::State& state) {
  const int watchers = static_cast<int>(state.range(0));
  const bool fetch = state.range(1) != 0;
  const Frame f = board_frame();
  const ViewFrame view =
      app::session::make_view_frame(f.grey.data(), kWidth, kHeight, 320, f.px, f.ids, board());
  const auto png = app::session::view_frame_png(view);
  if (!png.ok()) return state.SkipWithError(png.error().message.c_str());

  test::TestHost host;
  test::IoThread loop;
  std::unique_ptr<service::LiveViewServer> server;
  service::LiveViewOptions options;
  options.port = 0;
  options.token = "0123456789abcdef0123456789abcdef";
  options.cameras = {"cam0"};
  options.rig = "bench";
  std::string error;
  loop.call([&] {
    auto created = service::LiveViewServer::create(loop.io, options, host);
    if (created.ok())
      server = std::move(*created);
    else
      error = created.error().message;
  });
  if (!server) return state.SkipWithError(error.c_str());
  const int port = loop.call([&] { return static_cast<int>(server->port()); });
  {
    std::vector<std::unique_ptr<test::Watcher>> ws;
    for (int i = 0; i < watchers; ++i) ws.push_back(std::make_unique<test::Watcher>(port, fetch));
    while (loop.call([&] { return server->watchers(); }) < static_cast<std::size_t>(watchers))
      std::this_thread::sleep_for(std::chrono::milliseconds(5));

    session_msg::Live live;
    live.step = session_msg::StepId::kMotion;
    live.lines = {"Move the rig: every axis, the target in view",
                  "cam0 detects the target in 92 % of frames"};
    live.progress = 0.5;
    long sent = 0;
    for (auto _ : state) {
      const double before = loop.call([&] {
        const double t = thread_cpu_s();
        ViewFrame v = view;
        v.t_ns = sent * 250'000'000;
        server->frame(std::move(v), *png);
        server->broadcast(live);
        return t;
      });
      ++sent;
      for (const auto& w : ws)
        while (w->frames() < sent) std::this_thread::sleep_for(std::chrono::microseconds(200));
      // Fetches end when the server closes them, after it sent the PNG: the loop's part is done.
      const double after = loop.call([&] { return thread_cpu_s(); });
      state.SetIterationTime(after - before);
    }
    long refused = 0;
    for (const auto& w : ws) refused += w->refused();
    state.counters["refused"] = static_cast<double>(refused);
  }
  loop.call([&] { server.reset(); });
  loop.stop();
}
BENCHMARK(BM_LiveViewFanOut)
    ->ArgsProduct({{1, 20, 40}, {0, 1}})
    ->ArgNames({"watchers", "fetch"})
    ->UseManualTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace imucal

BENCHMARK_MAIN();
