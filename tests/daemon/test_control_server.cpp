// SPDX-License-Identifier: BSD-3-Clause
// The control socket against a test host: roles, broadcasts, hostile input, slow peers, the
// socket file's mode and life cycle; and the request parser.
#include <grp.h>
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>

#include "daemon/ctl/client.hpp"
#include "daemon/service/protocol.hpp"
#include "tests/daemon/service_test_host.hpp"
#include "tests/support/test_support.hpp"

namespace imucal::service {
namespace {

using ctl::Connection;
using nlohmann::json;
using test::TestService;

ControlServerOptions options_in(const test::SocketDir& dir) {
  ControlServerOptions options;
  options.path = dir.socket();
  return options;
}

Connection connect(const std::string& path) {
  auto connection = Connection::open(path);
  EXPECT_TRUE(connection.ok()) << (connection.ok() ? "" : connection.error().message);
  return std::move(*connection);
}

json receive(Connection& connection) {
  auto message = connection.receive(std::chrono::seconds(10));
  EXPECT_TRUE(message.ok()) << (message.ok() ? "" : message.error().message);
  return message.ok() ? *message : json();
}

// A reply for `cmd`, skipping other messages.
json reply_to(Connection& connection, const std::string& cmd) {
  for (int i = 0; i < 100; ++i) {
    json message = receive(connection);
    if (message.is_null() || (message["type"] == "reply" && message["cmd"] == cmd)) {
      return message;
    }
  }
  return {};
}

int raw_connect(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strcpy(addr.sun_path, path.c_str());
  EXPECT_EQ(::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0) << std::strerror(errno);
  return fd;
}

TEST(ControlRequest, ParsesEveryCommand) {
  auto hello = parse_request(R"({"cmd":"hello","client":"x","role":"controller"})");
  ASSERT_TRUE(hello.ok());
  EXPECT_EQ(hello->command, Command::kHello);
  EXPECT_EQ(hello->role, Role::kController);
  EXPECT_EQ(hello->client, "x");
  auto start = parse_request(R"({"cmd":"start","steps":["poses","solve"]})");
  ASSERT_TRUE(start.ok());
  EXPECT_EQ(start->steps, (std::vector<std::string>{"poses", "solve"}));
  auto key = parse_request(R"({"cmd":"key","key":"redo","future_field":1})");
  ASSERT_TRUE(key.ok());
  EXPECT_EQ(key->key, session_msg::OperatorKey::kRedo);
  EXPECT_EQ(parse_request(R"({"cmd":"abort"})")->key, session_msg::OperatorKey::kAbort);
  EXPECT_EQ(parse_request(R"({"cmd":"accept"})")->key, session_msg::OperatorKey::kAccept);
  EXPECT_TRUE(is_control(Command::kStart));
  EXPECT_FALSE(is_control(Command::kSubscribe));
}

// Clients build their requests with to_json (imucalctl does): every one parses back to itself,
// so the client and the service cannot drift apart in the protocol's words.
TEST(ControlRequest, EveryRequestAClientBuildsParsesBackToItself) {
  std::vector<Request> requests{hello_request("imucalctl", Role::kController),
                                hello_request("observer-x", Role::kObserver),
                                plain_request(Command::kStatus),
                                plain_request(Command::kSubscribe),
                                start_request({}),
                                start_request({"poses", "solve"}),
                                plain_request(Command::kAbort),
                                plain_request(Command::kAccept)};
  for (session_msg::OperatorKey key : session_msg::all_keys()) requests.push_back(key_request(key));
  for (const Request& sent : requests) {
    const std::string line = to_line(to_json(sent));
    auto got = parse_request(std::string_view(line).substr(0, line.size() - 1));
    ASSERT_TRUE(got.ok()) << line << ": " << got.error().message;
    EXPECT_EQ(got->command, sent.command) << line;
    EXPECT_EQ(got->client, sent.client) << line;
    EXPECT_EQ(got->role, sent.role) << line;
    EXPECT_EQ(got->steps, sent.steps) << line;
    EXPECT_EQ(got->key, sent.key) << line;
  }
}

TEST(ControlRequest, RefusesMalformedRequestsWithAReason) {
  for (const char* line :
       {"", "not json", "[1,2]", "42", R"({"cmd":5})", R"({"cmd":"nope"})", R"({"cmd":"key"})",
        R"({"cmd":"key","key":"explode"})", R"({"cmd":"start","steps":"poses"})",
        R"({"cmd":"start","steps":[1]})", R"({"cmd":"hello","role":"admin"})", "{\"cmd\":\"status\"",
        "{\"cmd\":\"st\xff\"}"}) {
    auto request = parse_request(line);
    ASSERT_FALSE(request.ok()) << line;
    EXPECT_EQ(request.error().code, Errc::kInvalidArgument);
    EXPECT_FALSE(request.error().message.empty());
  }
  EXPECT_EQ(command_of(R"({"cmd":"nope"})"), "nope");
  EXPECT_EQ(command_of("garbage"), "");
}

TEST(ControlServer, EveryObserverGetsTheSnapshotAndEachBroadcast) {
  const test::SocketDir dir;
  const auto options = options_in(dir);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  std::vector<Connection> observers;
  for (int i = 0; i < 4; ++i) {
    observers.push_back(connect(options.path));
    ASSERT_TRUE(observers.back().send({{"cmd", "subscribe"}}).ok());
    EXPECT_EQ(reply_to(observers.back(), "subscribe")["ok"], true);
    EXPECT_EQ(receive(observers.back())["type"], "status");  // the snapshot
  }
  const json prompt{{"type", "prompt"}, {"step", "poses"}, {"text", "Hold still"}, {"keys", {"continue"}}};
  service.broadcast(prompt);
  service.broadcast({{"type", "message"}, {"level", "info"}, {"text", "two"}});
  for (auto& observer : observers) {
    EXPECT_EQ(receive(observer), prompt);
    EXPECT_EQ(receive(observer)["text"], "two");
  }
  EXPECT_EQ(service.clients(), 4u);
}

TEST(ControlServer, StatusIsAReplyThenTheStatusEvenAfterTheClientStopsWriting) {
  const test::SocketDir dir;
  const auto options = options_in(dir);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  Connection client = connect(options.path);
  ASSERT_TRUE(client.send({{"cmd", "status"}}).ok());
  ::shutdown(client.fd(), SHUT_WR);  // like `echo '{"cmd":"status"}' | socat - UNIX:...`
  EXPECT_EQ(receive(client), (json{{"type", "reply"}, {"cmd", "status"}, {"ok", true}}));
  EXPECT_EQ(receive(client), session_msg::encode(service.host.status()));
  auto end = client.receive(std::chrono::seconds(10));
  ASSERT_FALSE(end.ok());
  EXPECT_EQ(end.error().code, Errc::kNotFound);  // the server closed after answering
}

TEST(ControlServer, OneControllerAtATimeAndTheRoleIsReleasedOnClose) {
  const test::SocketDir dir;
  const auto options = options_in(dir);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  const json hello{{"cmd", "hello"}, {"client", "console-a"}, {"role", "controller"}};
  auto first = std::make_unique<Connection>(connect(options.path));
  ASSERT_TRUE(first->request(hello).ok());
  Connection second = connect(options.path);
  auto refused = second.request({{"cmd", "hello"}, {"client", "console-b"}, {"role", "controller"}});
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("another controller is attached (console-a)"), std::string::npos);
  // Without hello a control command is refused too while console-a controls.
  Connection third = connect(options.path);
  EXPECT_FALSE(third.request({{"cmd", "abort"}}).ok());
  EXPECT_TRUE(service.host.keys().empty());

  first.reset();
  EXPECT_TRUE(TestService::wait_for([&] { return service.clients() == 2; }));
  EXPECT_TRUE(second.request({{"cmd", "hello"}, {"role", "controller"}}).ok());
  EXPECT_TRUE(second.request({{"cmd", "key"}, {"key", "continue"}}).ok());
  EXPECT_EQ(service.host.keys(), std::vector<std::string>{"continue"});
}

TEST(ControlServer, ObserversCannotControlAndControlReachesTheHost) {
  const test::SocketDir dir;
  const auto options = options_in(dir);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  Connection observer = connect(options.path);
  ASSERT_TRUE(observer.request({{"cmd", "hello"}, {"role", "observer"}}).ok());
  for (const json& request : {json{{"cmd", "key"}, {"key", "continue"}}, json{{"cmd", "start"}},
                              json{{"cmd", "abort"}}, json{{"cmd", "accept"}}}) {
    auto refused = observer.request(request);
    ASSERT_FALSE(refused.ok()) << request;
    EXPECT_NE(refused.error().message.find("observer"), std::string::npos);
  }
  EXPECT_TRUE(service.host.keys().empty());
  EXPECT_TRUE(service.host.starts().empty());

  // A client without hello takes the free controller role with its first control command.
  Connection controller = connect(options.path);
  EXPECT_TRUE(controller.request({{"cmd", "start"}, {"steps", {"poses", "solve"}}}).ok());
  EXPECT_TRUE(controller.request({{"cmd", "abort"}}).ok());
  EXPECT_TRUE(controller.request({{"cmd", "accept"}}).ok());
  auto refused = controller.request({{"cmd", "key"}, {"key", "skip"}});  // the host refuses skip
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().message, "the step 'preflight' cannot be skipped");
  EXPECT_EQ(service.host.starts(), (std::vector<std::vector<std::string>>{{"poses", "solve"}}));
  EXPECT_EQ(service.host.keys(), (std::vector<std::string>{"abort", "accept", "skip"}));
}

TEST(ControlServer, MalformedLinesGetAnErrorAndTheConnectionStays) {
  const test::SocketDir dir;
  const auto options = options_in(dir);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  const int fd = raw_connect(options.path);
  const std::string lines =
      "not "
      "json\n[1,2]\n{\"cmd\":5}\n{\"cmd\":\"nope\"}\n{\"cmd\":\"key\",\"key\":7}\n\n\r\n{\"cmd\":\"st\xc3\"}"
      "\n";
  ASSERT_EQ(::write(fd, lines.data(), lines.size()), static_cast<ssize_t>(lines.size()));
  Connection client = connect(options.path);  // a second, well-behaved client
  std::string received;
  int replies = 0;
  char buffer[4096];
  while (replies < 6) {
    const ssize_t n = ::read(fd, buffer, sizeof(buffer));
    ASSERT_GT(n, 0);
    received.append(buffer, static_cast<std::size_t>(n));
    replies = static_cast<int>(std::count(received.begin(), received.end(), '\n'));
  }
  std::istringstream in(received);
  std::string line;
  std::vector<std::string> cmds;
  while (std::getline(in, line)) {
    const json reply = json::parse(line);
    EXPECT_EQ(reply["ok"], false) << line;
    EXPECT_TRUE(reply["error"].is_string());
    cmds.push_back(reply["cmd"]);
  }
  EXPECT_EQ(cmds, (std::vector<std::string>{"", "", "", "nope", "key", ""}));
  // Still connected and served.
  const std::string status = "{\"cmd\":\"status\"}\n";
  ASSERT_EQ(::write(fd, status.data(), status.size()), static_cast<ssize_t>(status.size()));
  const ssize_t n = ::read(fd, buffer, sizeof(buffer));
  ASSERT_GT(n, 0);
  EXPECT_NE(std::string(buffer, static_cast<std::size_t>(n)).find("\"ok\":true"), std::string::npos);
  EXPECT_TRUE(client.request({{"cmd", "status"}}).ok());
  ::close(fd);
}

TEST(ControlServer, ALineLongerThanTheLimitClosesItsConnection) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.max_line_bytes = 1024;
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  Connection other = connect(options.path);
  ASSERT_TRUE(other.request({{"cmd", "subscribe"}}).ok());
  Connection client = connect(options.path);
  // No newline at all: the server must not wait for one forever.
  ASSERT_TRUE(client.send(json{{"cmd", "status"}, {"pad", std::string(4000, 'x')}}).ok());
  const json reply = receive(client);
  EXPECT_EQ(reply["ok"], false);
  EXPECT_NE(reply["error"].get<std::string>().find("longer than 1024 bytes"), std::string::npos);
  auto end = client.receive(std::chrono::seconds(10));
  ASSERT_FALSE(end.ok());
  EXPECT_EQ(end.error().code, Errc::kNotFound);
  EXPECT_TRUE(other.request({{"cmd", "status"}}).ok());
}

TEST(ControlServer, APeerThatNeverReadsIsDroppedAndOthersKeepUp) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.max_queued_bytes = 64 * 1024;
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  const int stuck = raw_connect(options.path);
  const std::string subscribe = "{\"cmd\":\"subscribe\"}\n";
  ASSERT_EQ(::write(stuck, subscribe.data(), subscribe.size()), static_cast<ssize_t>(subscribe.size()));
  Connection reader = connect(options.path);
  ASSERT_TRUE(reader.request({{"cmd", "subscribe"}}).ok());
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 2; }));

  constexpr int kMessages = 400;  // 400 x 4 KiB: far more than the socket buffer and the queue
  std::atomic<int> received{0};
  std::thread drain([&] {
    while (received < kMessages) {
      auto message = reader.receive(std::chrono::seconds(20));
      if (!message.ok()) {
        return;
      }
      if ((*message)["type"] == "live") {
        ++received;
      }
    }
  });
  for (int i = 0; i < kMessages; ++i) {
    // The good reader stays within a few messages (well inside its queue limit): a reader that
    // keeps up is never dropped, however slow the machine.
    if (!TestService::wait_for([&] { return i - received < 8; })) {
      break;  // reported by the count below
    }
    service.broadcast({{"type", "live"}, {"lines", {std::string(4096, 'a' + i % 26)}}});
  }
  drain.join();
  EXPECT_EQ(received, kMessages);
  EXPECT_TRUE(TestService::wait_for([&] { return service.clients() == 1; }));
  EXPECT_TRUE(reader.request({{"cmd", "status"}}).ok()) << "the reader that kept up is still served";
  ::close(stuck);
}

TEST(ControlServer, AClosingPeerThatNeverReadsIsDroppedAfterTheTimeout) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.max_line_bytes = 1024;
  options.close_timeout = std::chrono::milliseconds(200);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  const int stuck = raw_connect(options.path);
  const std::string subscribe = "{\"cmd\":\"subscribe\"}\n";
  ASSERT_EQ(::write(stuck, subscribe.data(), subscribe.size()), static_cast<ssize_t>(subscribe.size()));
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 1; }));
  // 1 MiB for it: more than the socket buffer holds, less than its queue limit.
  for (int i = 0; i < 256; ++i) {
    service.broadcast({{"type", "live"}, {"lines", {std::string(4096, 'x')}}});
  }
  EXPECT_EQ(service.clients(), 1u);
  const std::string too_long(2000, 'y');  // closes the connection, after its unread output
  ASSERT_EQ(::write(stuck, too_long.data(), too_long.size()), static_cast<ssize_t>(too_long.size()));
  EXPECT_TRUE(TestService::wait_for([&] { return service.clients() == 0; }));
  ::close(stuck);
}

// Beyond max_clients one place is kept for the operator's console: observers are refused it,
// a controller gets it, and a connection beyond that is told why before it is closed.
TEST(ControlServer, ClientsBeyondTheLimitAreToldWhyAndTheOperatorStillGetsIn) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.max_clients = 2;
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  const json observe{{"cmd", "hello"}, {"client", "watcher"}, {"role", "observer"}};
  Connection first = connect(options.path);
  Connection second = connect(options.path);
  ASSERT_TRUE(first.request(observe).ok());
  ASSERT_TRUE(second.request(observe).ok());
  Connection third = connect(options.path);
  auto third_hello = third.request(observe);
  ASSERT_FALSE(third_hello.ok());
  EXPECT_NE(third_hello.error().message.find("the last place is kept for the operator's console"),
            std::string::npos)
      << third_hello.error().message;
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 2; }));
  Connection console = connect(options.path);
  EXPECT_TRUE(console.request({{"cmd", "hello"}, {"client", "console"}, {"role", "controller"}}).ok());
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 3; }));
  Connection fourth = connect(options.path);
  const json refused = receive(fourth);
  EXPECT_EQ(refused["ok"], false);
  EXPECT_NE(refused["error"].get<std::string>().find("too many clients (2)"), std::string::npos) << refused;
  EXPECT_EQ(fourth.receive(std::chrono::seconds(10)).error().code, Errc::kNotFound);
  // A request on a refused connection gets the refusal as its answer, in words.
  Connection fifth = connect(options.path);
  auto status = fifth.request({{"cmd", "status"}});
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("too many clients (2)"), std::string::npos) << status.error().message;
  EXPECT_TRUE(first.request({{"cmd", "status"}}).ok());
}

// Before: 33 connections that sent one subscribe or status and stayed open took every place, the
// reserved one included, and `imucalctl status`, `start` and `attach` were refused for good (40
// here, at the default limit of 32).
TEST(ControlServer, FortyHostileClientsCannotLockTheOperatorOut) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.evict_idle_after = std::chrono::milliseconds(200);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  std::vector<Connection> hostile;
  for (int i = 0; i < 40; ++i) {
    hostile.push_back(connect(options.path));
    (void)hostile.back().send(i % 2 == 0 ? json{{"cmd", "subscribe"}} : json{{"cmd", "status"}});
  }
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() <= options.max_clients + 1; }));
  // Past the idle time, the operator's status query and console get in, every time.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  for (int round = 0; round < 3; ++round) {
    Connection status = connect(options.path);
    auto asked = status.request({{"cmd", "status"}});
    ASSERT_TRUE(asked.ok()) << asked.error().message;
  }
  Connection console = connect(options.path);
  auto hello = console.request({{"cmd", "hello"}, {"client", "console"}, {"role", "controller"}});
  ASSERT_TRUE(hello.ok()) << hello.error().message;
  auto subscribed = console.request({{"cmd", "subscribe"}});
  ASSERT_TRUE(subscribed.ok()) << subscribed.error().message;
  // The console holds the reserved place now: a status query gets the place of the longest
  // silent subscriber.
  Connection late = connect(options.path);
  auto asked = late.request({{"cmd", "status"}});
  ASSERT_TRUE(asked.ok()) << asked.error().message;
  EXPECT_LE(service.clients(), options.max_clients + 1);
}

// In the place kept for the operator, a connection may ask for the status once (then it is
// closed) but not subscribe without the controller role.
TEST(ControlServer, TheReservedPlaceAnswersOnceAndDoesNotObserve) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.max_clients = 2;
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  Connection first = connect(options.path);
  Connection second = connect(options.path);
  ASSERT_TRUE(first.request({{"cmd", "subscribe"}}).ok());
  ASSERT_TRUE(second.request({{"cmd", "subscribe"}}).ok());
  Connection third = connect(options.path);
  auto subscribe = third.request({{"cmd", "subscribe"}});
  ASSERT_FALSE(subscribe.ok());
  EXPECT_NE(subscribe.error().message.find("the last place is kept for the operator's console"),
            std::string::npos)
      << subscribe.error().message;
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 2; }));
  Connection asks = connect(options.path);
  ASSERT_TRUE(asks.request({{"cmd", "status"}}).ok());
  ASSERT_TRUE(TestService::wait_for([&] { return service.clients() == 2; })) << "the place is free again";
}

// Before: a client that took the controller role and went silent held it for good.
TEST(ControlServer, AnIdleControllerGivesTheRoleToTheNextThatAsks) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.controller_idle_after = std::chrono::seconds(2);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  Connection idle = connect(options.path);
  ASSERT_TRUE(idle.request({{"cmd", "hello"}, {"client", "idler"}, {"role", "controller"}}).ok());
  Connection console = connect(options.path);
  auto early = console.request({{"cmd", "hello"}, {"client", "console"}, {"role", "controller"}});
  ASSERT_FALSE(early.ok()) << "a controller that spoke just now keeps the role";
  std::this_thread::sleep_for(std::chrono::milliseconds(2200));
  auto late = console.request({{"cmd", "hello"}, {"client", "console"}, {"role", "controller"}});
  ASSERT_TRUE(late.ok()) << late.error().message;
  const json told = reply_to(idle, "hello");
  EXPECT_EQ(told["ok"], false);
  EXPECT_NE(told["error"].get<std::string>().find("lost the controller role to console"), std::string::npos)
      << told;
  auto refused = idle.request({{"cmd", "abort"}});
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("observer"), std::string::npos) << refused.error().message;
}

// A connection that says nothing is closed after silent_timeout, with a reply saying so, so
// that idle connections cannot fill the places; one that spoke stays.
TEST(ControlServer, ASilentConnectionIsClosedAndTakesNoPlace) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.silent_timeout = std::chrono::milliseconds(300);
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  Connection talker = connect(options.path);
  ASSERT_TRUE(talker.request({{"cmd", "status"}}).ok());
  Connection silent = connect(options.path);
  const json closed = receive(silent);
  EXPECT_EQ(closed["ok"], false);
  EXPECT_NE(closed["error"].get<std::string>().find("nothing received within 0.3 s of connecting"),
            std::string::npos)
      << closed;
  EXPECT_EQ(silent.receive(std::chrono::seconds(10)).error().code, Errc::kNotFound);
  EXPECT_TRUE(TestService::wait_for([&] { return service.clients() == 1; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  EXPECT_EQ(service.clients(), 1u);
  EXPECT_TRUE(talker.request({{"cmd", "status"}}).ok());
}

TEST(ControlServer, SocketHasTheModeAndGroupAsked) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  const group* own = ::getgrgid(::getgid());
  ASSERT_NE(own, nullptr);
  options.group = own->gr_name;
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  struct stat st {};
  ASSERT_EQ(::stat(options.path.c_str(), &st), 0);
  EXPECT_TRUE(S_ISSOCK(st.st_mode));
  EXPECT_EQ(st.st_mode & 07777, 0660u);
  EXPECT_EQ(st.st_gid, ::getgid());
  service.close();
  EXPECT_NE(::access(options.path.c_str(), F_OK), 0) << "close() removes the socket file";
}

TEST(ControlServer, UnknownGroupIsAnErrorThatSaysWhatToDo) {
  const test::SocketDir dir;
  auto options = options_in(dir);
  options.group = "no-such-group-imucal-test";
  TestService service(options);
  ASSERT_FALSE(service.ok());
  EXPECT_NE(service.error.find("does not exist"), std::string::npos) << service.error;
}

TEST(ControlServer, AStaleSocketIsReplacedALiveOneAndOtherFilesAreRefused) {
  const test::SocketDir dir;
  const auto options = options_in(dir);
  {
    // A socket file left behind by a process that died: bound, never unlinked.
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strcpy(addr.sun_path, options.path.c_str());
    ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0);
    ::close(fd);
  }
  TestService service(options);
  ASSERT_TRUE(service.ok()) << service.error;
  EXPECT_TRUE(connect(options.path).request({{"cmd", "status"}}).ok());

  TestService second(options);
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.error.find("another process listens"), std::string::npos) << second.error;
  EXPECT_TRUE(connect(options.path).request({{"cmd", "status"}}).ok()) << "the first server still serves";

  const test::SocketDir other_dir;
  auto file_options = options_in(other_dir);
  std::ofstream(file_options.path) << "precious";
  TestService third(file_options);
  ASSERT_FALSE(third.ok());
  EXPECT_NE(third.error.find("is not a socket"), std::string::npos) << third.error;
  EXPECT_EQ(test::read_file(file_options.path), "precious");
}

TEST(ControlServer, OptionsAreValidated) {
  ControlServerOptions options;
  EXPECT_FALSE(options.validate().ok());
  options.path = "/tmp/" + std::string(200, 'x');
  EXPECT_FALSE(options.validate().ok());
  options.path = "/tmp/x.sock";
  EXPECT_TRUE(options.validate().ok());
  options.max_queued_bytes = 10;
  EXPECT_FALSE(options.validate().ok());
  options = ControlServerOptions{};
  options.path = "/tmp/x.sock";
  options.max_clients = 0;
  EXPECT_FALSE(options.validate().ok());
}

// Before: any name was taken, escape sequences and all, and shown on other clients' terminals.
TEST(ControlRequest, AClientNameIsPrintableAndBounded) {
  constexpr std::size_t kMaxName = 64;
  for (const std::string& bad :
       {std::string(R"({"cmd":"hello","client":"\u001b]0;pwned\u0007","role":"controller"})"),
        std::string(R"({"cmd":"hello","client":"a\u009b2Jb"})"),
        std::string(R"({"cmd":"hello","client":"a\nb"})"),
        R"({"cmd":"hello","client":")" + std::string(kMaxName + 1, 'x') + "\"}"}) {
    auto r = parse_request(bad);
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.error().message.find("printable text (no control characters) of at most 64 bytes"),
              std::string::npos)
        << r.error().message;
  }
  auto longest = parse_request(R"({"cmd":"hello","client":")" + std::string(kMaxName, 'x') + "\"}");
  ASSERT_TRUE(longest.ok());
  EXPECT_EQ(longest->client.size(), kMaxName);
  EXPECT_TRUE(parse_request(R"({"cmd":"hello","client":"imucalctl on Zoë's laptop"})").ok());
}

}  // namespace
}  // namespace imucal::service
