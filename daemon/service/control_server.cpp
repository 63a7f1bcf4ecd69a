// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/service/control_server.hpp"

#include <grp.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <array>
#include <boost/asio/local/stream_protocol.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <deque>
#include <set>

#include "daemon/service/protocol.hpp"

namespace imucal::service {
namespace {

namespace asio = boost::asio;
using Protocol = asio::local::stream_protocol;
using nlohmann::json;
using Line = std::shared_ptr<const std::string>;

Error io_error(const std::string& what, int err) {
  return make_error(Errc::kIo, what + ": " + std::strerror(err));
}

// A socket file left by a service that died is replaced; one that somebody still listens on is
// refused, and so is anything that is not a socket (a typo must not delete a user's file).
Status clear_stale_socket(const std::string& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    return errno == ENOENT ? Status{} : io_error("cannot inspect " + path, errno);
  }
  if (!S_ISSOCK(st.st_mode)) {
    return make_error(Errc::kAlreadyExists,
                      path + " exists and is not a socket; remove it or choose another socket path");
  }
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return io_error("cannot create a socket", errno);
  }
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  const int rc = ::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr));
  const int err = errno;
  ::close(fd);
  if (rc == 0) {
    return make_error(Errc::kAlreadyExists, "another process listens on " + path +
                                                " (is imucald already running? systemctl status imucald)");
  }
  if (err != ECONNREFUSED) {
    return io_error("cannot probe the existing socket " + path, err);
  }
  if (::unlink(path.c_str()) != 0 && errno != ENOENT) {
    return io_error("cannot remove the stale socket " + path, errno);
  }
  return {};
}

Status apply_owner_and_mode(const ControlServerOptions& options) {
  if (!options.group.empty()) {
    std::array<char, 4096> buffer{};
    group entry{};
    group* found = nullptr;
    const int rc = ::getgrnam_r(options.group.c_str(), &entry, buffer.data(), buffer.size(), &found);
    if (rc != 0 || found == nullptr) {
      return make_error(Errc::kNotFound, "group '" + options.group +
                                             "' for the control socket does not exist; create it "
                                             "(systemd-sysusers) or configure another group");
    }
    if (::chown(options.path.c_str(), static_cast<uid_t>(-1), found->gr_gid) != 0) {
      return io_error("cannot give " + options.path + " to group " + options.group, errno);
    }
  }
  if (::chmod(options.path.c_str(), options.mode) != 0) {
    return io_error("cannot set the mode of " + options.path, errno);
  }
  return {};
}

}  // namespace

class Client;

class ControlServer::Impl : public std::enable_shared_from_this<ControlServer::Impl> {
 public:
  Impl(asio::io_context& io, ControlServerOptions options, SessionHost& host)
      : options_(std::move(options)), host_(host), acceptor_(io) {}

  Status listen();
  void accept();
  void on_line(Client& client, std::string_view line);
  // Closes a connection; `why` (empty for an orderly close) goes to the log.
  void drop(Client& client, const std::string& why);
  void broadcast(const json& message);
  void close();
  std::size_t clients() const { return clients_.size(); }
  const ControlServerOptions& options() const { return options_; }

 private:
  void hello(Client& client, const Request& request);
  Status control(Client& client, const Request& request);
  // Connections not being closed.
  std::size_t active() const;
  // Closes the longest silent connection that is not the controller and has been silent for
  // evict_idle_after (subscribers first), to make room; false when there is none.
  bool evict_idlest();
  // Whether the controller may be taken from its holder by `client`: it is silent for long.
  bool controller_idle(const Client& client) const;
  // Makes an idle controller (controller_idle) an observer, telling it who took the role.
  void take_idle_controller(const Client& client, const std::string& by);
  void log(const std::string& text) const {
    if (options_.log) {
      options_.log(text);
    }
  }

  ControlServerOptions options_;
  SessionHost& host_;
  Protocol::acceptor acceptor_;
  std::set<std::shared_ptr<Client>> clients_;
  Client* controller_ = nullptr;
  dev_t socket_dev_ = 0;
  ino_t socket_ino_ = 0;
  bool closed_ = false;
};

// One connection: reads request lines, writes queued lines, one write at a time.
class Client : public std::enable_shared_from_this<Client> {
 public:
  Client(Protocol::socket socket, std::weak_ptr<ControlServer::Impl> server)
      : socket_(std::move(socket)),
        server_(std::move(server)),
        linger_(socket_.get_executor()),
        silent_(socket_.get_executor()) {}

  /// Starts reading, and closes the connection if it sends nothing within `timeout`.
  void start(std::chrono::milliseconds timeout) {
    silent_.expires_after(timeout);
    silent_.async_wait([self = shared_from_this(), timeout](const boost::system::error_code& ec) {
      auto server = self->server_.lock();
      if (ec || !server || self->closed() || self->heard_) return;
      char text[160];
      std::snprintf(text, sizeof text,
                    "nothing received within %g s of connecting; the connection is closed (send a request, "
                    "or hello)",
                    static_cast<double>(timeout.count()) / 1000.0);
      const Status error = make_error(Errc::kTimeout, text);
      self->send(std::make_shared<const std::string>(to_line(make_reply("", error))));
      self->close_after_sending(*server);
    });
    read();
  }

  void read() {
    socket_.async_read_some(asio::buffer(buffer_),
                            [self = shared_from_this()](auto ec, std::size_t n) { self->on_read(ec, n); });
  }

  void send(const Line& line) {
    auto server = server_.lock();
    if (closed_ || !server) {
      return;
    }
    if (queued_bytes_ + line->size() > server->options().max_queued_bytes) {
      server->drop(*this, "its unread output passed " + std::to_string(server->options().max_queued_bytes) +
                              " bytes (the client does not read)");
      return;
    }
    queue_.push_back(line);
    queued_bytes_ += line->size();
    if (!writing_) {
      write_next();
    }
  }

  /// Sends what is queued, then closes (used after a fatal protocol error and at end of input).
  void close_after_sending(ControlServer::Impl& server) {
    closing_ = true;
    if (queue_.empty()) {
      server.drop(*this, "");
      return;
    }
    linger_.expires_after(server.options().close_timeout);
    linger_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
      auto server = self->server_.lock();
      if (!ec && server && !self->closed_) {
        server->drop(*self, "it did not read its last replies");
      }
    });
  }

  void shut() {
    closed_ = true;
    linger_.cancel();
    silent_.cancel();
    boost::system::error_code ignored;
    socket_.shutdown(Protocol::socket::shutdown_both, ignored);
    socket_.close(ignored);
  }

  bool closed() const { return closed_ || closing_; }

  std::string name;
  std::optional<Role> role;
  bool subscribed = false;
  bool reserved = false;  // admitted to the place kept for the operator's console
  std::chrono::steady_clock::time_point last_heard = std::chrono::steady_clock::now();

 private:
  void on_read(const boost::system::error_code& ec, std::size_t n) {
    auto server = server_.lock();
    if (!server || closed_) {
      return;
    }
    if (ec) {
      // End of input: answer what was asked, then close. Anything else is a broken peer.
      if (ec == asio::error::eof) {
        close_after_sending(*server);
      } else {
        server->drop(*this, ec.message());
      }
      return;
    }
    pending_.append(buffer_.data(), n);
    if (!split_lines(*server)) {
      return;
    }
    read();
  }

  // Hands complete lines to the server; false when the connection is closing.
  bool split_lines(ControlServer::Impl& server) {
    const std::size_t max_line = server.options().max_line_bytes;
    std::size_t start = 0;
    for (std::size_t nl; (nl = pending_.find('\n', start)) != std::string::npos; start = nl + 1) {
      std::string_view line(pending_.data() + start, nl - start);
      if (line.size() > max_line) {
        break;  // reported below with the partial-line check
      }
      if (!line.empty() && line.back() == '\r') {
        line.remove_suffix(1);
      }
      if (!line.empty()) {
        heard_ = true;
        last_heard = std::chrono::steady_clock::now();
        silent_.cancel();
        server.on_line(*this, line);
      }
      if (closed()) {
        return false;
      }
    }
    pending_.erase(0, start);
    const auto nl = pending_.find('\n');
    if ((nl == std::string::npos ? pending_.size() : nl) > max_line) {
      const Status error =
          make_error(Errc::kInvalidArgument, "request line longer than " + std::to_string(max_line) +
                                                 " bytes; the connection is closed");
      send(std::make_shared<const std::string>(to_line(make_reply("", error))));
      pending_.clear();
      close_after_sending(server);
      return false;
    }
    return true;
  }

  void write_next() {
    writing_ = true;
    asio::async_write(socket_, asio::buffer(*queue_.front()),
                      [self = shared_from_this()](auto ec, std::size_t) { self->on_written(ec); });
  }

  void on_written(const boost::system::error_code& ec) {
    writing_ = false;
    auto server = server_.lock();
    if (closed_ || !server) {
      return;
    }
    if (ec) {
      server->drop(*this, ec.message());
      return;
    }
    queued_bytes_ -= queue_.front()->size();
    queue_.pop_front();
    if (!queue_.empty()) {
      write_next();
    } else if (closing_) {
      server->drop(*this, "");
    }
  }

  Protocol::socket socket_;
  std::weak_ptr<ControlServer::Impl> server_;
  asio::steady_timer linger_;
  asio::steady_timer silent_;
  bool heard_ = false;  // a line arrived
  std::array<char, 4096> buffer_{};
  std::string pending_;
  std::deque<Line> queue_;
  std::size_t queued_bytes_ = 0;
  bool writing_ = false;
  bool closing_ = false;
  bool closed_ = false;
};

Status ControlServer::Impl::listen() {
  IMUCAL_TRY(clear_stale_socket(options_.path));
  boost::system::error_code ec;
  const Protocol::endpoint endpoint(options_.path);
  if (acceptor_.open(endpoint.protocol(), ec); ec) {
    return make_error(Errc::kIo, "cannot create the control socket: " + ec.message());
  }
  if (acceptor_.bind(endpoint, ec); ec) {
    return make_error(Errc::kIo, "cannot bind the control socket " + options_.path + ": " + ec.message() +
                                     " (does its folder exist and is it writable?)");
  }
  struct stat st {};
  if (::stat(options_.path.c_str(), &st) == 0) {
    socket_dev_ = st.st_dev;
    socket_ino_ = st.st_ino;
  }
  IMUCAL_TRY(apply_owner_and_mode(options_));
  if (acceptor_.listen(asio::socket_base::max_listen_connections, ec); ec) {
    return make_error(Errc::kIo, "cannot listen on " + options_.path + ": " + ec.message());
  }
  return {};
}

void ControlServer::Impl::accept() {
  acceptor_.async_accept([weak = weak_from_this()](const boost::system::error_code& ec,
                                                   Protocol::socket socket) {
    auto self = weak.lock();
    if (!self || self->closed_) {
      return;
    }
    if (!ec) {
      auto client = std::make_shared<Client>(std::move(socket), weak);
      // Every place taken: the longest silent connection that does not control gives its place.
      if (self->active() >= self->options_.max_clients + 1) self->evict_idlest();
      const std::size_t before = self->active();
      self->clients_.insert(client);
      // One place beyond max_clients is the operator's (see hello() and on_line()).
      client->reserved = before >= self->options_.max_clients;
      if (before > self->options_.max_clients) {
        // Refused with a reason rather than left unanswered in the backlog.
        const Status refused =
            make_error(Errc::kUnsupported, "too many clients (" + std::to_string(self->options_.max_clients) +
                                               "); close another imucalctl and retry");
        client->send(std::make_shared<const std::string>(to_line(make_reply("", refused))));
        client->close_after_sending(*self);
      } else {
        client->start(self->options_.silent_timeout);
      }
    } else {
      self->log("control socket: accept failed: " + ec.message());
    }
    self->accept();
  });
}

void ControlServer::Impl::on_line(Client& client, std::string_view line) {
  auto request = parse_request(line);
  if (!request) {
    client.send(std::make_shared<const std::string>(to_line(make_reply(command_of(line), request.error()))));
    return;
  }
  const std::string cmd = command_name(request->command);
  auto reply = [&](const Status& status) {
    client.send(std::make_shared<const std::string>(to_line(make_reply(cmd, status))));
  };
  switch (request->command) {
    case Command::kHello:
      hello(client, *request);
      return;
    case Command::kStatus:
      reply({});
      client.send(std::make_shared<const std::string>(to_line(session_msg::encode(host_.status()))));
      // The operator's place answers one status query; then it is free again.
      if (client.reserved && &client != controller_) client.close_after_sending(*this);
      return;
    case Command::kSubscribe:
      if (client.reserved && &client != controller_) {
        reply(make_error(Errc::kUnsupported,
                         "too many clients (" + std::to_string(options_.max_clients) +
                             "): the last place is kept for the operator's console, which says hello as "
                             "controller before it subscribes; close another observer and retry"));
        client.close_after_sending(*this);
        return;
      }
      reply({});
      client.subscribed = true;
      for (const auto& message : host_.snapshot()) {
        client.send(std::make_shared<const std::string>(to_line(session_msg::encode(message))));
      }
      return;
    default:
      reply(control(client, *request));
  }
}

std::size_t ControlServer::Impl::active() const {
  std::size_t n = 0;
  for (const auto& c : clients_) n += c->closed() ? 0 : 1;
  return n;
}

bool ControlServer::Impl::evict_idlest() {
  const auto now = std::chrono::steady_clock::now();
  Client* victim = nullptr;
  for (const auto& c : clients_) {
    if (c->closed() || c.get() == controller_ || now - c->last_heard < options_.evict_idle_after) continue;
    // Subscribers first, then the longest silent.
    if (!victim || (c->subscribed && !victim->subscribed) ||
        (c->subscribed == victim->subscribed && c->last_heard < victim->last_heard)) {
      victim = c.get();
    }
  }
  if (!victim) return false;
  const auto silent_s = std::chrono::duration_cast<std::chrono::seconds>(now - victim->last_heard).count();
  const Status why = make_error(Errc::kUnsupported,
                                "every place of the control socket was taken and this "
                                "connection had sent nothing for " +
                                    std::to_string(silent_s) + " s: it is closed to make room for a new one");
  victim->send(std::make_shared<const std::string>(to_line(make_reply("", why))));
  log("control socket: closing " + (victim->name.empty() ? std::string("a client") : victim->name) +
      ", silent for " + std::to_string(silent_s) + " s, to make room for a new connection");
  victim->close_after_sending(*this);
  return true;
}

bool ControlServer::Impl::controller_idle(const Client& client) const {
  return controller_ != nullptr && controller_ != &client &&
         std::chrono::steady_clock::now() - controller_->last_heard >= options_.controller_idle_after;
}

void ControlServer::Impl::take_idle_controller(const Client& client, const std::string& by) {
  if (!controller_idle(client)) return;
  // A controller silent for long gives the role up to the one asking: it stays, as an observer.
  Client* idle = controller_;
  const auto silent_s =
      std::chrono::duration_cast<std::chrono::seconds>(std::chrono::steady_clock::now() - idle->last_heard)
          .count();
  idle->role = Role::kObserver;
  controller_ = nullptr;
  const std::string who = by.empty() ? "another client" : by;
  const Status taken = make_error(
      Errc::kAlreadyExists, "this connection had sent nothing for " + std::to_string(silent_s) +
                                " s and lost the controller role to " + who + "; it is an observer now");
  idle->send(std::make_shared<const std::string>(to_line(make_reply("hello", taken))));
  log("control socket: the controller role passed from " + idle->name + " (silent for " +
      std::to_string(silent_s) + " s) to " + who);
}

void ControlServer::Impl::hello(Client& client, const Request& request) {
  Status status;
  if (request.role == Role::kController) take_idle_controller(client, request.client);
  if (request.role == Role::kController && controller_ != nullptr && controller_ != &client) {
    status =
        make_error(Errc::kAlreadyExists, "another controller is attached (" + controller_->name +
                                             "); attach as an observer, or detach the other console first");
  } else if (request.role == Role::kObserver && client.reserved) {
    // The place beyond max_clients is kept for the operator's console.
    status = make_error(Errc::kUnsupported, "too many clients (" + std::to_string(options_.max_clients) +
                                                "): the last place is kept for the operator's console; "
                                                "close another observer and retry");
    client.send(std::make_shared<const std::string>(to_line(make_reply("hello", status))));
    client.close_after_sending(*this);
    return;
  } else {
    client.name = request.client.empty() ? "unnamed client" : request.client;
    client.role = request.role;
    if (request.role == Role::kController) {
      controller_ = &client;
    } else if (controller_ == &client) {
      controller_ = nullptr;
    }
  }
  client.send(std::make_shared<const std::string>(to_line(make_reply("hello", status))));
}

// Control commands need the controller role; a client that never said hello takes it
// implicitly when it is free, so one-shot clients (imucalctl abort, socat) need no handshake.
Status ControlServer::Impl::control(Client& client, const Request& request) {
  if (client.role == Role::kObserver) {
    return make_error(
        Errc::kInvalidArgument,
        "this connection is an observer; say {\"cmd\":\"hello\",\"role\":\"controller\"} first");
  }
  take_idle_controller(client, client.name);
  if (controller_ != nullptr && controller_ != &client) {
    return make_error(Errc::kAlreadyExists,
                      "another controller is attached (" + controller_->name +
                          "); only one console may control the session: use that console (c starts a "
                          "session there, R restarts one), or detach it first");
  }
  if (!client.role) {
    client.role = Role::kController;
    client.name = "unnamed client";
  }
  controller_ = &client;
  if (request.command == Command::kStart) {
    return host_.start(request.steps);
  }
  return host_.key(request.key);
}

void ControlServer::Impl::drop(Client& client, const std::string& why) {
  if (controller_ == &client) {
    controller_ = nullptr;
  }
  client.shut();
  if (!why.empty()) {
    log("control socket: closed the connection of " + (client.name.empty() ? "a client" : client.name) +
        ": " + why);
  }
  for (auto it = clients_.begin(); it != clients_.end(); ++it) {
    if (it->get() == &client) {
      clients_.erase(it);
      break;
    }
  }
}

void ControlServer::Impl::broadcast(const json& message) {
  const auto line = std::make_shared<const std::string>(to_line(message));
  // A send can drop its client, which erases it from clients_: iterate over a copy.
  const std::vector<std::shared_ptr<Client>> targets(clients_.begin(), clients_.end());
  for (const auto& client : targets) {
    if (client->subscribed && !client->closed()) {
      client->send(line);
    }
  }
}

void ControlServer::Impl::close() {
  if (closed_) {
    return;
  }
  closed_ = true;
  boost::system::error_code ignored;
  acceptor_.close(ignored);
  for (const auto& client : std::vector<std::shared_ptr<Client>>(clients_.begin(), clients_.end())) {
    client->shut();
  }
  clients_.clear();
  controller_ = nullptr;
  // Remove the file only while it is still ours: a newer service may have replaced it.
  struct stat st {};
  if (::lstat(options_.path.c_str(), &st) == 0 && st.st_dev == socket_dev_ && st.st_ino == socket_ino_) {
    ::unlink(options_.path.c_str());
  }
}

Status ControlServerOptions::validate() const {
  if (path.empty()) {
    return make_error(Errc::kInvalidArgument,
                      "the control socket path is empty; give one, e.g. /run/imucal/imucald.sock");
  }
  if (path.size() >= sizeof(sockaddr_un::sun_path)) {
    return make_error(Errc::kInvalidArgument,
                      "the control socket path " + path + " is longer than " +
                          std::to_string(sizeof(sockaddr_un::sun_path) - 1) +
                          " bytes, the limit of a Unix socket address; use a shorter one");
  }
  if (mode > 07777) {
    return make_error(Errc::kInvalidArgument,
                      "the control socket mode must be an octal permission, e.g. 0660");
  }
  if (max_clients == 0) {
    return make_error(Errc::kInvalidArgument, "max_clients must be at least 1");
  }
  if (max_line_bytes == 0 || max_queued_bytes < max_line_bytes) {
    return make_error(Errc::kInvalidArgument,
                      "max_line_bytes must be positive and max_queued_bytes at least max_line_bytes");
  }
  return {};
}

Result<std::unique_ptr<ControlServer>> ControlServer::create(asio::io_context& io,
                                                             const ControlServerOptions& options,
                                                             SessionHost& host) {
  IMUCAL_TRY(options.validate());
  auto impl = std::make_shared<Impl>(io, options, host);
  if (auto status = impl->listen(); !status) {
    impl->close();
    return status.error();
  }
  impl->accept();
  return std::unique_ptr<ControlServer>(new ControlServer(std::move(impl)));
}

ControlServer::ControlServer(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
ControlServer::~ControlServer() { impl_->close(); }
void ControlServer::broadcast(const json& message) { impl_->broadcast(message); }

void ControlServer::broadcast(const session_msg::SessionMessage& message) {
  impl_->broadcast(session_msg::encode(message));
}
std::size_t ControlServer::clients() const { return impl_->clients(); }
void ControlServer::close() { impl_->close(); }

}  // namespace imucal::service
