// SPDX-License-Identifier: BSD-3-Clause
// The live view's server (daemon/service/live_view_server.hpp) through real TCP connections: the
// page, the event stream with the session's messages and the frames, the frames' PNG by
// sequence, the keys behind the token, and hostile clients (malformed, oversized and slow
// requests, paths outside the page's own, clients that never read, too many clients).

#include <gtest/gtest.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/write.hpp>
#include <chrono>
#include <future>
#include <string>
#include <thread>
#include <vector>

#include "daemon/service/live_view_server.hpp"
#include "tests/daemon/service_test_host.hpp"

namespace imucal {
namespace {

using boost::asio::ip::tcp;
constexpr const char* kToken = "0123456789abcdef0123456789abcdef";

/// A live view server on a thread of its own, on a free loopback port.
class LiveView {
 public:
  explicit LiveView(service::LiveViewOptions options = {}) {
    options.port = 0;
    if (options.token.empty()) options.token = kToken;
    if (options.cameras.empty()) options.cameras = {"cam0"};
    options.rig = "sim";
    loop_.call([&] {
      auto created = service::LiveViewServer::create(loop_.io, options, host);
      if (created.ok()) {
        server_ = std::move(*created);
        port = server_->port();
      } else {
        error = created.error().message;
      }
    });
  }
  ~LiveView() {
    loop_.call([this] { server_.reset(); });
    loop_.stop();
  }
  template <class F>
  auto call(F&& f) {
    return loop_.call(std::forward<F>(f));
  }
  void broadcast(const nlohmann::json& message) {
    auto m = session_msg::decode(message);
    ASSERT_TRUE(m.ok()) << m.error().message;
    call([&] { server_->broadcast(*m); });
  }
  void frame(ViewFrame f, std::vector<std::uint8_t> png) {
    call([&] { server_->frame(std::move(f), std::move(png)); });
  }
  std::size_t watchers() {
    return call([&] { return server_->watchers(); });
  }
  std::size_t clients() {
    return call([&] { return server_->clients(); });
  }

  test::TestHost host;
  std::string error;
  unsigned short port = 0;

 private:
  test::IoThread loop_;
  std::unique_ptr<service::LiveViewServer> server_;
};

/// A client connection with a receive timeout.
struct Client {
  explicit Client(unsigned short port) : socket(io) {
    socket.connect(tcp::endpoint(boost::asio::ip::make_address("127.0.0.1"), port));
    timeval tv{10, 0};
    ::setsockopt(socket.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  void send(const std::string& bytes) { boost::asio::write(socket, boost::asio::buffer(bytes)); }
  /// Everything until the server closes (or the timeout).
  std::string read_all() {
    std::string out;
    char buf[4096];
    for (;;) {
      boost::system::error_code ec;
      const std::size_t n = socket.read_some(boost::asio::buffer(buf), ec);
      out.append(buf, n);
      if (ec) break;
    }
    return out;
  }
  /// Reads until `what` has come (or the timeout, or the end).
  std::string read_until(const std::string& what) {
    char buf[4096];
    while (received.find(what) == std::string::npos) {
      boost::system::error_code ec;
      const std::size_t n = socket.read_some(boost::asio::buffer(buf), ec);
      received.append(buf, n);
      if (ec) break;
    }
    return received;
  }
  boost::asio::io_context io;
  tcp::socket socket;
  std::string received;
};

std::string request(unsigned short port, const std::string& text) {
  Client c(port);
  c.send(text);
  return c.read_all();
}
std::string get(unsigned short port, const std::string& path) {
  return request(port, "GET " + path + " HTTP/1.1\r\nHost: x\r\n\r\n");
}
std::string post_key(unsigned short port, const std::string& name, const std::string& token) {
  std::string head = "POST /key/" + name + " HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n";
  if (!token.empty()) head += "X-Imucal-Token: " + token + "\r\n";
  return request(port, head + "\r\n");
}
std::string status_line(const std::string& response) { return response.substr(0, response.find("\r\n")); }

ViewFrame test_frame(std::size_t camera) {
  ViewFrame f;
  f.camera = camera;
  f.name = "cam" + std::to_string(camera);
  f.t_ns = 1'500'000'000;
  f.width = 4;
  f.height = 3;
  f.full_width = 8;
  f.full_height = 6;
  f.grey.assign(12, 128);
  f.corners = {{1.25, 0.75}, {2.5, 1.5}};
  f.seen = true;
  f.coverage.cols = 2;
  f.coverage.rows = 1;
  f.coverage.cells = {3, 0};
  f.coverage.views = 1;
  f.coverage.x = 0.25;
  return f;
}

TEST(LiveView, ServesItsPageWithAPolicyThatAllowsNothingFromElsewhere) {
  LiveView view;
  ASSERT_TRUE(view.error.empty()) << view.error;
  const std::string r = get(view.port, "/");
  EXPECT_EQ(status_line(r), "HTTP/1.1 200 OK");
  EXPECT_NE(r.find("Content-Type: text/html"), std::string::npos);
  EXPECT_NE(r.find("Content-Security-Policy: default-src 'none'"), std::string::npos);
  EXPECT_NE(r.find("<html"), std::string::npos);
  // One self-contained page: nothing fetched from another origin.
  EXPECT_EQ(r.find("http://"), std::string::npos);
  EXPECT_EQ(r.find("https://"), std::string::npos);
  EXPECT_EQ(r.find("<script src"), std::string::npos);
}

TEST(LiveView, TheStreamBringsANewWatcherUpToDateThenEveryMessageAndFrame) {
  LiveView view;
  ASSERT_TRUE(view.error.empty()) << view.error;
  view.broadcast(
      {{"type", "prompt"}, {"t", 3.0}, {"step", "poses"}, {"text", "Turn the rig"}, {"keys", {"abort"}}});
  view.frame(test_frame(0), {1, 2, 3});
  Client c(view.port);
  c.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  std::string got = c.read_until("event: frame");
  EXPECT_NE(got.find("Content-Type: text/event-stream"), std::string::npos);
  EXPECT_NE(got.find("event: hello\ndata: {"), std::string::npos);
  EXPECT_NE(got.find("\"rig\":\"sim\""), std::string::npos);
  EXPECT_NE(got.find("\"type\":\"status\""), std::string::npos)
      << "the host's snapshot starts with its status";
  ASSERT_TRUE(test::TestService::wait_for([&] { return view.watchers() == 1; }));
  got = c.read_until("\"seq\":1");
  EXPECT_NE(got.find("\"corners\":[[1.25,0.75],[2.5,1.5]]"), std::string::npos) << got;

  view.broadcast({{"type", "message"}, {"t", 4.0}, {"level", "info"}, {"text", "Pose 3 captured"}});
  got = c.read_until("Pose 3 captured");
  EXPECT_NE(got.find("event: msg\ndata: {\"level\":\"info\""), std::string::npos);
  view.frame(test_frame(0), {4, 5, 6});
  got = c.read_until("\"seq\":2");
  EXPECT_NE(got.find("\"seq\":2"), std::string::npos);
  // The watcher leaves: the server sees it go, so that frames stop being made for nobody.
  c.socket.close();
  EXPECT_TRUE(test::TestService::wait_for([&] { return view.watchers() == 0; }));
}

TEST(LiveView, FramesAreServedBySequenceWhileKept) {
  service::LiveViewOptions o;
  o.frames_kept = 2;
  LiveView view(o);
  ASSERT_TRUE(view.error.empty()) << view.error;
  for (std::uint8_t i = 1; i <= 3; ++i) view.frame(test_frame(0), {0x89, 'P', 'N', 'G', i});
  std::string r = get(view.port, "/frame/0.png?seq=3");
  EXPECT_EQ(status_line(r), "HTTP/1.1 200 OK");
  EXPECT_NE(r.find("Content-Type: image/png"), std::string::npos);
  EXPECT_EQ(r.substr(r.size() - 5), std::string("\x89PNG\x03"));
  r = get(view.port, "/frame/0.json?seq=2");
  EXPECT_NE(r.find("\"seq\":2"), std::string::npos);
  EXPECT_EQ(status_line(get(view.port, "/frame/0.png?seq=1")), "HTTP/1.1 404 Not Found") << "no longer kept";
  EXPECT_EQ(status_line(get(view.port, "/frame/0.png")), "HTTP/1.1 200 OK") << "the latest";
  EXPECT_EQ(status_line(get(view.port, "/frame/1.png")), "HTTP/1.1 404 Not Found") << "no such camera";
}

TEST(LiveView, NothingOutsideThePagesOwnIsServed) {
  LiveView view;
  ASSERT_TRUE(view.error.empty()) << view.error;
  for (const char* path :
       {"/../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/etc/passwd", "/frame/../../etc/passwd",
        "/frame/0.png/../../x", "/report/../../etc/passwd", "/report/0", "/report/-1",
        "/frame/0.png?seq=../1", "//etc/passwd", "/index.html/..", "/events/../x"}) {
    const std::string r = get(view.port, path);
    EXPECT_EQ(status_line(r), "HTTP/1.1 404 Not Found") << path;
    EXPECT_EQ(r.find("root:"), std::string::npos) << path;
  }
  EXPECT_EQ(status_line(request(view.port, "DELETE / HTTP/1.1\r\nHost: x\r\n\r\n")),
            "HTTP/1.1 405 Method Not Allowed");
}

TEST(LiveView, KeysNeedTheToken) {
  LiveView view;
  ASSERT_TRUE(view.error.empty()) << view.error;
  EXPECT_EQ(status_line(post_key(view.port, "abort", "")), "HTTP/1.1 403 Forbidden");
  EXPECT_EQ(status_line(post_key(view.port, "accept", "0123456789abcdef0123456789abcdee")),
            "HTTP/1.1 403 Forbidden");
  EXPECT_EQ(status_line(post_key(view.port, "start", std::string(kToken) + "0")), "HTTP/1.1 403 Forbidden");
  EXPECT_TRUE(view.host.keys().empty());
  EXPECT_TRUE(view.host.starts().empty());

  EXPECT_EQ(status_line(post_key(view.port, "abort", kToken)), "HTTP/1.1 204 No Content");
  EXPECT_EQ(status_line(post_key(view.port, "start", kToken)), "HTTP/1.1 204 No Content");
  EXPECT_EQ(view.host.keys(), std::vector<std::string>{"abort"});
  EXPECT_EQ(view.host.starts().size(), 1u);
  // The session's refusal, in its words; a name that is no key.
  const std::string refused = post_key(view.port, "skip", kToken);
  EXPECT_EQ(status_line(refused), "HTTP/1.1 409 Conflict");
  EXPECT_NE(refused.find("cannot be skipped"), std::string::npos);
  EXPECT_EQ(status_line(post_key(view.port, "reboot", kToken)), "HTTP/1.1 400 Bad Request");
  // A GET of a key's path is no key.
  EXPECT_EQ(status_line(get(view.port, "/key/abort")), "HTTP/1.1 404 Not Found");
  EXPECT_EQ(view.host.keys().size(), 2u);  // abort, and skip (refused by the host)
}

TEST(LiveView, AServerWithoutATokenRefusesEveryKey) {
  EXPECT_FALSE(service::token_matches("", ""));
  EXPECT_TRUE(service::token_matches("ab", "ab"));
  EXPECT_FALSE(service::token_matches("ab", "a"));
  auto t1 = service::make_token(), t2 = service::make_token();
  ASSERT_TRUE(t1.ok() && t2.ok());
  EXPECT_EQ(t1->size(), 32u);
  EXPECT_NE(*t1, *t2);
}

TEST(LiveView, HostileRequestsAreAnsweredAndTheServerGoesOn) {
  service::LiveViewOptions o;
  o.request_timeout = std::chrono::milliseconds(500);
  o.max_header_bytes = 2048;
  LiveView view(o);
  ASSERT_TRUE(view.error.empty()) << view.error;
  EXPECT_EQ(status_line(request(view.port, "HELLO\r\n\r\n")), "HTTP/1.1 400 Bad Request");
  EXPECT_EQ(status_line(request(view.port, std::string("GET / HTTP/1.1\r\n\0\x01\x02\r\n\r\n", 23))),
            "HTTP/1.1 400 Bad Request");
  EXPECT_EQ(
      status_line(request(view.port, "GET / HTTP/1.1\r\nX-Big: " + std::string(4096, 'a') + "\r\n\r\n")),
      "HTTP/1.1 431 Request Header Fields Too Large");
  EXPECT_EQ(status_line(request(view.port, "POST /key/abort HTTP/1.1\r\nContent-Length: 100000\r\n\r\n")),
            "HTTP/1.1 413 Payload Too Large");
  // A slow client that never finishes its request: the others are served meanwhile, and it is
  // dropped once its time is up.
  Client slow(view.port);
  slow.send("GET / HTTP/1.1\r\nHo");
  EXPECT_EQ(status_line(get(view.port, "/")), "HTTP/1.1 200 OK");
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(slow.read_all(), "") << "dropped without a reply";
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(9));
  EXPECT_EQ(status_line(get(view.port, "/")), "HTTP/1.1 200 OK");
}

TEST(LiveView, AWatcherThatDoesNotReadIsDroppedAndTooManyClientsAreTurnedAway) {
  service::LiveViewOptions o;
  o.max_queued_bytes = 64 * 1024;
  o.max_clients = 3;
  LiveView view(o);
  ASSERT_TRUE(view.error.empty()) << view.error;
  Client lazy(view.port);
  int buffer = 4096;
  ::setsockopt(lazy.socket.native_handle(), SOL_SOCKET, SO_RCVBUF, &buffer, sizeof buffer);
  lazy.send("GET /events HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_TRUE(test::TestService::wait_for([&] { return view.watchers() == 1; }));
  Client a(view.port), b(view.port);
  ASSERT_TRUE(test::TestService::wait_for([&] { return view.clients() == 3; }));
  EXPECT_EQ(status_line(get(view.port, "/")), "HTTP/1.1 503 Service Unavailable");
  // Frames of 28 kB of JSON each for a watcher that reads nothing: the kernel's buffers fill, then the
  // server's queue, and the watcher is dropped; the server goes on.
  std::vector<std::uint8_t> png(20000, 7);
  for (int i = 0; i < 2000 && view.watchers() > 0; ++i) {
    ViewFrame f = test_frame(0);
    f.corners.assign(2000, Eigen::Vector2d(1.0, 2.0));
    view.frame(f, png);
  }
  EXPECT_EQ(view.watchers(), 0u);
  a.socket.close();
  b.socket.close();
  EXPECT_TRUE(test::TestService::wait_for([&] { return view.clients() < 3; }, std::chrono::seconds(15)));
  EXPECT_EQ(status_line(get(view.port, "/")), "HTTP/1.1 200 OK");
}

TEST(LiveView, ABadAddressOrABusyPortIsRefusedWithWhatToDo) {
  boost::asio::io_context io;
  test::TestHost host;
  service::LiveViewOptions o;
  o.address = "not-an-address";
  auto bad = service::LiveViewServer::create(io, o, host);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("live_view.address"), std::string::npos);
  o.address = "127.0.0.1";
  o.port = 0;
  auto first = service::LiveViewServer::create(io, o, host);
  ASSERT_TRUE(first.ok()) << first.error().message;
  o.port = (*first)->port();
  auto second = service::LiveViewServer::create(io, o, host);
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.error().message.find("live_view.port"), std::string::npos);
  EXPECT_EQ((*first)->url(), "http://127.0.0.1:" + std::to_string(o.port) + "/");
}

}  // namespace
}  // namespace imucal
