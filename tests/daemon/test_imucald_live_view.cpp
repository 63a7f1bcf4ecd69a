// SPDX-License-Identifier: BSD-3-Clause
// imucald's live view during virtual-rig sessions: the page in headless Chromium at the poses
// step and the motion step (the prompt is the session's, the image changes, the coverage grows,
// the corners drawn are where the frame's detection put them and where the virtual camera's
// truth has them), the keys refused without the
// token, twenty watchers during a 1 kHz + 30 fps recording, and a page left open while the service
// restarts. Skips, saying so, without chromium.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <fstream>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "log/session_log.hpp"
#include "tests/support/headless_browser.hpp"
#include "tests/support/imucald_process.hpp"
#include "tests/support/live_view_client.hpp"
#include "tests/support/test_support.hpp"

namespace imucal {
namespace {

namespace fs = std::filesystem;

using test::free_loopback_port;
using test::http_exchange;
using test::loopback;

using test::Watcher;

/// The page's DOM after Chromium ran it for a few seconds of its virtual time, in its ?poll=1
/// mode (a stream that never ends would hold virtual time still). A caller that needs later
/// state asks again.
std::string page_dom(const std::string& url, const std::string& dir, const std::string& name) {
  const std::string cmd =
      "chromium --headless --no-sandbox --disable-gpu --virtual-time-budget=4000 --user-data-dir=" + dir +
      "/profile-" + name + " --dump-dom '" + url + "?poll=1' > " + dir + "/" + name + ".html 2>/dev/null";
  if (std::system(cmd.c_str()) != 0) return "";
  return test::read_file(dir + "/" + name + ".html");
}

/// An attribute of the first element that has it.
std::string first_attribute(const std::string& dom, const std::string& attribute) {
  const std::regex attr(" " + attribute + "=\"([^\"]*)\"");
  std::smatch v;
  return std::regex_search(dom, v, attr) ? v.str(1) : "";
}

std::string element_text(const std::string& dom, const std::string& id) {
  const std::regex el("id=\"" + id + "\"[^>]*>([^<]*)<");
  std::smatch m;
  return std::regex_search(dom, m, el) ? m.str(1) : "";
}

std::string unescape_html(std::string s) {
  for (const auto& [from, to] : std::vector<std::pair<std::string, std::string>>{
           {"&amp;", "&"}, {"&lt;", "<"}, {"&gt;", ">"}, {"&quot;", "\""}, {"&#39;", "'"}, {"&nbsp;", " "}}) {
    for (auto p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size()))
      s.replace(p, from.size(), to);
  }
  return s;
}

long cells_total(const std::string& cells) {
  long total = 0;
  std::stringstream ss(cells);
  for (std::string n; std::getline(ss, n, ',');)
    if (!n.empty()) total += std::stol(n);
  return total;
}

TEST(ImucaldLiveView, ABrowserSeesThePromptsAndWhatTheCameraSees) {
  if (!test::on_path("chromium"))
    GTEST_SKIP() << "chromium is not installed (scripts/install-deps.sh --test)";
  const std::string dir = test::scratch_dir();
  const int port = free_loopback_port();
  ASSERT_GT(port, 0);
  const std::string config =
      test::write_config(dir,
                         "session:\n  steps: [preflight, still, poses, motion]\n  poses: 9\n  poses_min: 9\n"
                         "  motion_s: 40\nlive_view:\n  enabled: true\n  port: " +
                             std::to_string(port) + "\n",
                         "    width: 640\n    height: 480\n    rate_hz: 10\n");
  test::Daemon daemon(
      dir, {"--sim-operator", "full", "--time-scale", "2", "--start", "default", "--exit-after-session"},
      config);
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/";

  // The poses step: the page says so and shows a prompt of the session's.
  std::string poses_prompt;
  ASSERT_TRUE(test::wait_for(
      [&] {
        const std::string dom = page_dom(url, dir, "poses");
        if (first_attribute(dom, "data-step") != "poses") return false;
        poses_prompt = unescape_html(element_text(dom, "prompt"));
        return !poses_prompt.empty() && poses_prompt.find("Waiting") == std::string::npos;
      },
      120))
      << test::read_file(dir + "/imucald.log");
  // The keys without the token are refused, and change nothing.
  const std::string refused =
      http_exchange(port, "POST /key/abort HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n\r\n");
  EXPECT_EQ(refused.substr(0, 12), "HTTP/1.1 403") << refused;
  EXPECT_EQ(::access((dir + "/state/live-view.token").c_str(), R_OK), 0) << "the token file";

  // The motion step: two looks 3 s apart; the image and the coverage move on.
  std::string a, b;
  ASSERT_TRUE(test::wait_for(
      [&] {
        a = page_dom(url, dir, "motion-a");
        return first_attribute(a, "data-step") == "motion" && !first_attribute(a, "data-frame-seq").empty() &&
               cells_total(first_attribute(a, "data-cells")) > 0;
      },
      120))
      << test::read_file(dir + "/imucald.log");
  // A later look (each look is a fresh page: the stream's snapshot brings the latest frame and
  // figures; a look taken before they came in is taken again).
  const long seq_a = std::stol(first_attribute(a, "data-frame-seq"));
  const long cells_a = cells_total(first_attribute(a, "data-cells"));
  long seq_b = -1, cells_b = -1;
  std::this_thread::sleep_for(std::chrono::seconds(2));
  EXPECT_TRUE(test::wait_for(
      [&] {
        b = page_dom(url, dir, "motion-b");
        const std::string seq = first_attribute(b, "data-frame-seq");
        if (first_attribute(b, "data-step") != "motion" || seq.empty()) return false;
        seq_b = std::stol(seq);
        cells_b = cells_total(first_attribute(b, "data-cells"));
        return seq_b > seq_a && cells_b > cells_a;
      },
      60))
      << "the frames move on (" << seq_a << " then " << seq_b << ") and the coverage grows (" << cells_a
      << " corners then " << cells_b << ")";

  // Frames with the target, each drawn alone at 1:1 (the page's ?camera view, in Chromium's
  // virtual time since it opens no stream): the image changes from one to the next, and the
  // corners drawn are the frame's detection, moved into the shrunk image.
  // The latest frame in which the target was seen, once `wanted` holds for it.
  const auto latest_seen_frame = [&](const std::function<bool(const nlohmann::json&)>& wanted) {
    nlohmann::json f;
    (void)test::wait_for(
        [&] {
          const std::string r = http_exchange(port, "GET /frame/0.json HTTP/1.1\r\nHost: x\r\n\r\n");
          const auto body = r.find("\r\n\r\n");
          if (body == std::string::npos) return false;
          f = nlohmann::json::parse(r.substr(body + 4), nullptr, false);
          return f.is_object() && f.value("seen", false) && f.contains("corners") && wanted(f);
        },
        120);
    return f;
  };
  const auto shot_of = [&](long seq) {
    const std::string file = dir + "/shot-" + std::to_string(seq) + ".png";
    (void)std::system(
        ("chromium --headless --no-sandbox --disable-gpu --hide-scrollbars --force-device-scale-factor=1 "
         "--virtual-time-budget=3000 --window-size=400,300 --user-data-dir=" +
         dir + "/profile-shot --screenshot=" + file + " '" + url + "?camera=0&seq=" + std::to_string(seq) +
         "' > /dev/null 2>&1")
            .c_str());
    return cv::imread(file, cv::IMREAD_COLOR);
  };
  Watcher watching(port, false);  // frames are made while someone watches
  const nlohmann::json first = latest_seen_frame([](const nlohmann::json&) { return true; });
  ASSERT_TRUE(first.is_object() && first.contains("seq"));
  // Its screenshot at once: the server keeps a camera's last 16 frames only.
  const cv::Mat before = shot_of(first["seq"].get<long>());
  // A later frame where the target has moved (by a pixel on average): the operator holds still
  // at times, and on a loaded machine, with the rig at 0.02x, frames 0.5 s of rig time apart
  // were alike to the last grey level.
  const auto moved = [&](const nlohmann::json& f) {
    if (f.value("seq", 0L) <= first["seq"].get<long>() || f["corners"].size() != first["corners"].size())
      return false;
    double sum = 0.0;
    for (std::size_t i = 0; i < f["corners"].size(); ++i)
      sum += std::hypot(f["corners"][i][0].get<double>() - first["corners"][i][0].get<double>(),
                        f["corners"][i][1].get<double>() - first["corners"][i][1].get<double>());
    return sum > static_cast<double>(f["corners"].size());
  };
  const nlohmann::json frame = latest_seen_frame(moved);
  ASSERT_TRUE(frame.is_object() && moved(frame)) << "no frame where the target moved";
  const cv::Mat shot = shot_of(frame["seq"].get<long>());
  ASSERT_FALSE(before.empty());
  ASSERT_FALSE(shot.empty());
  const int w = frame["width"].get<int>(), h = frame["height"].get<int>();
  ASSERT_TRUE(w <= shot.cols && h <= shot.rows);
  double change = 0.0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      change += std::abs(int(shot.at<cv::Vec3b>(v, u)[1]) - int(before.at<cv::Vec3b>(v, u)[1]));
  EXPECT_GT(change / (w * h), 2.0) << "the image changes (mean grey-level difference)";
  // The distance from (x, y) to the centre of the magenta cross drawn within 6 px of it; -1: none.
  const auto drawn_off = [&](double x, double y) {
    double sx = 0, sy = 0;
    int n = 0;
    for (int v = static_cast<int>(y) - 6; v <= static_cast<int>(y) + 6; ++v)
      for (int u = static_cast<int>(x) - 6; u <= static_cast<int>(x) + 6; ++u) {
        if (u < 0 || v < 0 || u >= shot.cols || v >= shot.rows || std::hypot(u - x, v - y) > 6) continue;
        const cv::Vec3b p = shot.at<cv::Vec3b>(v, u);
        if (p[2] > 200 && p[0] > 200 && p[1] < 90) sx += u, sy += v, ++n;
      }
    return n == 0 ? -1.0 : std::hypot(sx / n - x, sy / n - y);
  };
  int found = 0;
  double worst = 0.0;
  for (const auto& c : frame["corners"]) {
    const double off = drawn_off(c[0].get<double>(), c[1].get<double>());
    if (off < 0) continue;
    ++found;
    worst = std::max(worst, off);
  }
  EXPECT_EQ(found, static_cast<int>(frame["corners"].size()));
  EXPECT_LT(worst, 1.5);

  // The same crosses against the virtual camera's truth of that frame (sim-view-truth.txt: what
  // the renderer projected, not what the detector found), moved into the shrunk image.
  const std::string session = fs::path(test::session_log(dir)).parent_path().string();
  const double t_frame = frame["t"].get<double>();
  const double shrink = frame["full_width"].get<double>() / w;
  std::vector<double> truth;
  std::stringstream truth_lines(test::read_file(session + "/sim-view-truth.txt"));
  for (std::string line; std::getline(truth_lines, line);) {
    std::stringstream fields(line);
    long camera = -1;
    long long t_ns = 0;
    fields >> camera >> t_ns;
    if (camera != 0 || std::abs(static_cast<double>(t_ns) * 1e-9 - t_frame) > 1e-6) continue;
    truth.clear();
    for (std::string v; fields >> v;) truth.push_back(std::strtod(v.c_str(), nullptr));
  }
  ASSERT_EQ(truth.size(), 2 * frame["corners"].size()) << "the frame's truth in " << session;
  int truth_found = 0, truth_visible = 0;
  double truth_worst = 0.0;
  for (std::size_t i = 0; i + 1 < truth.size(); i += 2) {
    if (!std::isfinite(truth[i]) || !std::isfinite(truth[i + 1])) continue;
    ++truth_visible;
    const double off = drawn_off((truth[i] + 0.5) / shrink - 0.5, (truth[i + 1] + 0.5) / shrink - 0.5);
    if (off < 0) continue;
    ++truth_found;
    truth_worst = std::max(truth_worst, off);
  }
  EXPECT_EQ(truth_visible, static_cast<int>(frame["corners"].size()));
  EXPECT_EQ(truth_found, truth_visible);
  EXPECT_LT(truth_worst, 1.5) << "the drawn corners against the virtual camera's truth (view pixels)";

  // No solve step: the session ends "recorded", which --exit-after-session reports as 1.
  EXPECT_EQ(daemon.wait(), 1) << test::read_file(dir + "/imucald.log");
  // The prompt the page showed is one the session gave in its poses step.
  const std::string events = test::all_events(test::session_log(dir));
  bool said = false;
  std::stringstream lines(events);
  for (std::string line; std::getline(lines, line);) {
    const auto m = nlohmann::json::parse(line, nullptr, false);
    if (m.is_object() && m.value("type", "") == "prompt" && m.value("step", "") == "poses" &&
        m.value("text", "") == poses_prompt)
      said = true;
  }
  EXPECT_TRUE(said) << "the page's prompt: " << poses_prompt;
}

TEST(ImucaldLiveView, TwentyWatchersDuringA1kHzAnd30FpsRecordingLoseNoSampleOrFrame) {
  const std::string dir = test::scratch_dir();
  const int port = free_loopback_port();
  ASSERT_GT(port, 0);
  std::string config = test::write_config(dir,
                                          "session:\n  steps: [preflight, still, motion]\n  still_s: 3\n  "
                                          "motion_s: 10\nlive_view:\n  enabled: true\n"
                                          "  port: " +
                                              std::to_string(port) + "\n  frame_rate_hz: 30\n",
                                          "    width: 320\n    height: 240\n    rate_hz: 30\n");
  {
    std::string text = test::read_file(config);
    text = std::regex_replace(text, std::regex("rate_hz: 200"), "rate_hz: 1000");
    std::ofstream(config) << text;
  }
  test::Daemon daemon(
      dir, {"--sim-operator", "full", "--time-scale", "1", "--start", "default", "--exit-after-session"},
      config);
  // Twenty watchers, each as a browser: the event stream, and each frame's PNG as it is announced.
  std::vector<std::unique_ptr<Watcher>> watchers;
  ASSERT_TRUE(test::wait_for([&] { return !http_exchange(port, "HEAD / HTTP/1.1\r\n\r\n").empty(); }, 60));
  for (int w = 0; w < 20; ++w) {
    watchers.push_back(std::make_unique<Watcher>(port, true));
  }
  // A session without a solve ends "recorded", which --exit-after-session reports as 1.
  const int rc = daemon.wait();
  long pngs = 0, fewest_frames = -1;
  for (auto& w : watchers) {
    pngs += w->stop();
    fewest_frames = fewest_frames < 0 ? w->frames() : std::min(fewest_frames, w->frames());
  }
  EXPECT_EQ(rc, 1) << test::read_file(dir + "/imucald.log");
  EXPECT_TRUE(test::has(test::all_events(test::session_log(dir)), "\"outcome\":\"recorded\""));
  // Every watcher kept its stream (none fell so far behind that the service dropped it) and
  // they fetched images all along.
  EXPECT_GT(fewest_frames, 100) << "frames announced to the watcher that saw the fewest";
  EXPECT_GT(pngs, 100) << "the watchers' images";

  // The recording, counted as the recorder counts it: every sample of the 10 s at 1 kHz and
  // every frame at 30 Hz, none dropped for want of a buffer.
  const std::string session = fs::path(test::session_log(dir)).parent_path().string();
  auto motion = log::SessionLogReader::open(session + "/motion.imulog");
  ASSERT_TRUE(motion.ok()) << motion.error().message;
  auto imu = (*motion)->find_imu_stream();
  auto cam = (*motion)->find_camera_stream("cam0");
  ASSERT_TRUE(imu.ok() && cam.ok());
  auto samples = (*motion)->read_imu(*imu);
  auto frames = (*motion)->frame_times(*cam);
  ASSERT_TRUE(samples.ok() && frames.ok());
  // The chip's own clock sets the rate (the emulator's oscillator is off by up to a few percent,
  // as a real one): the interval is the median, and the count the span over it.
  ASSERT_GT(samples->size(), 9000u);
  ASSERT_GT(frames->size(), 250u);
  const auto median_interval = [](std::vector<TimeNs> t) {
    std::vector<TimeNs> d;
    for (std::size_t i = 1; i < t.size(); ++i) d.push_back(t[i] - t[i - 1]);
    std::nth_element(d.begin(), d.begin() + static_cast<long>(d.size() / 2), d.end());
    return d[d.size() / 2];
  };
  std::vector<TimeNs> sample_times;
  for (const auto& s : *samples) sample_times.push_back(s.t_ns);
  for (const auto& [what, times] : {std::pair<std::string, std::vector<TimeNs>>{"IMU sample", sample_times},
                                    std::pair<std::string, std::vector<TimeNs>>{"frame", *frames}}) {
    const TimeNs dt = median_interval(times);
    TimeNs worst = 0;
    for (std::size_t i = 1; i < times.size(); ++i) worst = std::max(worst, times[i] - times[i - 1]);
    EXPECT_LT(worst, dt * 3 / 2) << "a " << what << " missing in the motion log";
    const double expected = static_cast<double>(times.back() - times.front()) / static_cast<double>(dt) + 1.0;
    EXPECT_NEAR(static_cast<double>(times.size()), expected, 0.002 * expected + 2.0) << what << "s";
  }
  EXPECT_FALSE(test::has(test::read_file(dir + "/imucald.log"), "dropped"));
}

}  // namespace
}  // namespace imucal

namespace imucal {
namespace {

/// A rig configuration whose rig is called `name`, with the live view on `port`.
std::string named_rig_config(const std::string& dir, const std::string& name, int port) {
  const std::string path =
      test::write_config(dir, "live_view:\n  enabled: true\n  port: " + std::to_string(port) + "\n");
  const std::string text =
      std::regex_replace(test::read_file(path), std::regex("\nname: sim\n"), "\nname: " + name + "\n");
  std::ofstream(path) << text;
  return path;
}

/// The page left open in a browser (its event stream, as a phone shows it) while the service stops
/// and another starts on the same port: it says the connection is lost and keeps what it showed,
/// then comes back by itself with the new service's state.
TEST(ImucaldLiveView, APageLeftOpenReconnectsWhenTheServiceRestarts) {
  if (!test::on_path("chromium"))
    GTEST_SKIP() << "chromium is not installed (scripts/install-deps.sh --test)";
  const std::string dir = test::scratch_dir();
  const int port = free_loopback_port();
  ASSERT_GT(port, 0);
  fs::create_directories(dir + "/a");
  fs::create_directories(dir + "/b");
  auto first = std::make_unique<test::Daemon>(dir + "/a", std::vector<std::string>{},
                                              named_rig_config(dir + "/a", "bench-rig-a", port));
  ASSERT_TRUE(test::wait_for([&] { return first->ready(); }, 60)) << test::read_file(dir + "/a/imucald.log");

  test::HeadlessBrowser browser(dir + "/profile", dir + "/chromium.log");
  ASSERT_TRUE(browser.open("http://127.0.0.1:" + std::to_string(port) + "/")) << browser.error();
  // What the operator sees: the connection's state, the rig's name, the lost-connection banner.
  const std::string look =
      "[document.body.dataset.conn, document.getElementById('h-rig').textContent,"
      " getComputedStyle(document.getElementById('lost')).display !== 'none'].join('|')";
  std::string seen;
  EXPECT_TRUE(test::wait_for([&] { return (seen = browser.text(look)) == "live|rig bench-rig-a|false"; }, 30))
      << seen << " " << browser.error();

  ::kill(first->pid(), SIGTERM);
  EXPECT_EQ(first->wait_for_exit(30), 0)
      << "the service stops with a page open: " << test::read_file(dir + "/a/imucald.log");
  first.reset();
  EXPECT_TRUE(test::wait_for([&] { return (seen = browser.text(look)) == "lost|rig bench-rig-a|true"; }, 30))
      << seen << " " << browser.error();
  EXPECT_TRUE(test::has(browser.text("document.getElementById('lost').textContent"),
                        "What is shown is the last the rig sent"));

  // Gone for a while (longer than one retry), then another service on the same port.
  std::this_thread::sleep_for(std::chrono::seconds(4));
  EXPECT_EQ(browser.text("document.body.dataset.conn"), "lost");
  test::Daemon second(dir + "/b", {}, named_rig_config(dir + "/b", "bench-rig-b", port));
  ASSERT_TRUE(test::wait_for([&] { return second.ready(); }, 60)) << test::read_file(dir + "/b/imucald.log");
  EXPECT_TRUE(test::wait_for([&] { return (seen = browser.text(look)) == "live|rig bench-rig-b|false"; }, 30))
      << "the page comes back by itself: " << seen << " " << browser.error();
  EXPECT_EQ(browser.text("document.getElementById('h-state').textContent"), "idle");
  ::kill(second.pid(), SIGTERM);
  EXPECT_EQ(second.wait_for_exit(30), 0) << test::read_file(dir + "/b/imucald.log");
}

/// imucald under systemd-socket-activate, as imucald.socket starts it: the socket is passed.
TEST(ImucaldLiveView, TheSocketSystemdPassesIsServedAndAViewThatCannotOpenLeavesTheServiceRunning) {
  if (std::system("command -v systemd-socket-activate > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "systemd-socket-activate is not installed (package systemd)";
  const std::string dir = test::scratch_dir();
  const int port = free_loopback_port();
  ASSERT_GT(port, 0);
  // The configuration names another port: the passed socket is the one served.
  const int other = free_loopback_port();
  const std::string config =
      test::write_config(dir, "live_view:\n  enabled: true\n  port: " + std::to_string(other) + "\n");
  const std::string socket = test::short_socket_path();
  const pid_t pid = ::fork();
  if (pid == 0) {
    (void)!std::freopen((dir + "/imucald.log").c_str(), "w", stderr);
    (void)!std::freopen("/dev/null", "w", stdout);
    const std::string listen = "127.0.0.1:" + std::to_string(port);
    ::execlp("systemd-socket-activate", "systemd-socket-activate", "-l", listen.c_str(), IMUCALD_PATH,
             "--config", config.c_str(), "--socket", socket.c_str(), "--state-dir", (dir + "/state").c_str(),
             "--sim", static_cast<char*>(nullptr));
    std::_Exit(127);
  }
  std::string page;
  EXPECT_TRUE(test::wait_for(
      [&] {
        page = http_exchange(port, "GET / HTTP/1.1\r\nHost: x\r\n\r\n");
        return page.rfind("HTTP/1.1 200", 0) == 0;
      },
      60))
      << test::read_file(dir + "/imucald.log");
  EXPECT_TRUE(test::has(page, "<html"));
  EXPECT_EQ(http_exchange(other, "GET / HTTP/1.1\r\nHost: x\r\n\r\n"), "")
      << "the configured port is not bound";
  EXPECT_TRUE(test::has(test::read_file(dir + "/imucald.log"),
                        "live view on http://127.0.0.1:" + std::to_string(port)));
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << test::read_file(dir + "/imucald.log");

  // The port taken: said in the journal, and the service runs on (its socket answers).
  const std::string dir2 = test::scratch_dir();
  const int taken_fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a = loopback(0);
  socklen_t len = sizeof a;
  ASSERT_EQ(::bind(taken_fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ASSERT_EQ(::listen(taken_fd, 1), 0);
  ASSERT_EQ(::getsockname(taken_fd, reinterpret_cast<sockaddr*>(&a), &len), 0);
  const std::string config2 = test::write_config(
      dir2, "live_view:\n  enabled: true\n  port: " + std::to_string(ntohs(a.sin_port)) + "\n");
  test::Daemon daemon(dir2, {}, config2);
  EXPECT_TRUE(test::wait_for([&] { return daemon.ready(); }, 60)) << test::read_file(dir2 + "/imucald.log");
  EXPECT_TRUE(test::wait_for(
      [&] { return test::has(test::read_file(dir2 + "/imucald.log"), "live view: cannot listen"); }, 10))
      << test::read_file(dir2 + "/imucald.log");
  ::kill(daemon.pid(), SIGTERM);
  EXPECT_EQ(daemon.wait(), 0) << test::read_file(dir2 + "/imucald.log");
  ::close(taken_fd);
}

}  // namespace
}  // namespace imucal
