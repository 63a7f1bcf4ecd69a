// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/ctl/client.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace imucal::ctl {

using nlohmann::json;

namespace {
std::string text_field(const json& message, const char* key) {
  const auto it = message.find(key);
  return it != message.end() && it->is_string() ? it->get<std::string>() : std::string();
}
}  // namespace

Result<Connection> Connection::open(const std::string& path, ConnectFailure* failure) {
  auto fail = [&](ConnectFailure kind, Errc code, const std::string& message) -> Result<Connection> {
    if (failure != nullptr) {
      *failure = kind;
    }
    return make_error(code, message);
  };
  sockaddr_un addr{};
  if (path.empty() || path.size() >= sizeof(addr.sun_path)) {
    return fail(ConnectFailure::kOther, Errc::kInvalidArgument,
                "the socket path '" + path + "' is empty or too long for a Unix socket");
  }
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return fail(ConnectFailure::kOther, Errc::kIo,
                std::string("cannot create a socket: ") + std::strerror(errno));
  }
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int err = errno;
    ::close(fd);
    if (err == ENOENT || err == ECONNREFUSED) {
      return fail(ConnectFailure::kNoService, Errc::kNotFound,
                  "cannot reach imucald at " + path + " (" + std::strerror(err) +
                      "): is imucald running? systemctl status imucald");
    }
    if (err == EACCES || err == EPERM) {
      return fail(ConnectFailure::kPermission, Errc::kIo,
                  "permission denied on " + path +
                      ": the control socket belongs to group imucal; add yourself with "
                      "'sudo usermod -aG imucal $USER' and log in again");
    }
    return fail(ConnectFailure::kOther, Errc::kIo, "cannot connect to " + path + ": " + std::strerror(err));
  }
  if (failure != nullptr) {
    *failure = ConnectFailure::kNone;
  }
  return Connection(fd);
}

Connection::Connection(Connection&& other) noexcept : fd_(other.fd_), input_(std::move(other.input_)) {
  other.fd_ = -1;
}

Connection& Connection::operator=(Connection&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) {
      ::close(fd_);
    }
    fd_ = other.fd_;
    input_ = std::move(other.input_);
    other.fd_ = -1;
  }
  return *this;
}

Connection::~Connection() {
  if (fd_ >= 0) {
    ::close(fd_);
  }
}

Status Connection::send(const json& request) {
  const std::string line = request.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + '\n';
  std::size_t written = 0;
  while (written < line.size()) {
    // MSG_NOSIGNAL: a service that went away is an error here, not a SIGPIPE.
    const ssize_t n = ::send(fd_, line.data() + written, line.size() - written, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) {
        continue;
      }
      const int err = errno;
      // The service may have refused the connection and closed it (too many clients): its
      // reason is waiting to be read, and says more than "Broken pipe".
      if (auto reason = refusal(); !reason.empty()) return make_error(Errc::kInvalidArgument, reason);
      return make_error(Errc::kIo, std::string("cannot send to imucald: ") + std::strerror(err));
    }
    written += static_cast<std::size_t>(n);
  }
  return {};
}

namespace {

/// A reply whose ok is false.
bool is_refusal(const json& message) {
  const auto ok = message.find("ok");
  return text_field(message, "type") == "reply" && ok != message.end() && ok->is_boolean() &&
         !ok->get<bool>();
}

}  // namespace

std::string Connection::refusal() {
  pollfd pfd{fd_, POLLIN, 0};
  if (::poll(&pfd, 1, 200) > 0) (void)read_some();
  while (auto message = buffered()) {
    if (is_refusal(*message)) {
      return text_field(*message, "error");
    }
  }
  return {};
}

std::optional<json> Connection::buffered() {
  for (std::size_t nl; (nl = input_.find('\n')) != std::string::npos;) {
    json message =
        json::parse(input_.begin(), input_.begin() + static_cast<std::ptrdiff_t>(nl), nullptr, false);
    input_.erase(0, nl + 1);
    if (message.is_object()) {
      return message;
    }
    // A line that is not an object is skipped: the console shows what it understands.
  }
  return std::nullopt;
}

Status Connection::read_some() {
  char buffer[8192];
  for (;;) {
    const ssize_t n = ::recv(fd_, buffer, sizeof(buffer), 0);
    if (n > 0) {
      input_.append(buffer, static_cast<std::size_t>(n));
      return {};
    }
    if (n == 0) {
      return make_error(Errc::kNotFound, "imucald closed the connection");
    }
    if (errno != EINTR) {
      return make_error(Errc::kIo, std::string("cannot read from imucald: ") + std::strerror(errno));
    }
  }
}

Result<json> Connection::receive(std::optional<std::chrono::milliseconds> timeout) {
  for (;;) {
    if (auto message = buffered()) {
      return std::move(*message);
    }
    pollfd pfd{fd_, POLLIN, 0};
    const int ready = ::poll(&pfd, 1, timeout ? static_cast<int>(timeout->count()) : -1);
    if (ready < 0 && errno == EINTR) {
      continue;
    }
    if (ready == 0) {
      return make_error(Errc::kTimeout, "imucald did not answer in time");
    }
    IMUCAL_TRY(read_some());
  }
}

Result<json> Connection::request(const json& request, std::vector<json>* others,
                                 std::chrono::milliseconds timeout) {
  IMUCAL_TRY(send(request));
  const std::string cmd = text_field(request, "cmd");
  for (;;) {
    auto message = receive(timeout);
    if (!message) {
      return message.error();
    }
    // A reply to no command is the service refusing the connection itself (too many clients,
    // nothing received in time): the answer to this request as well.
    const bool refused = is_refusal(*message) && text_field(*message, "cmd").empty();
    if (refused || (text_field(*message, "type") == "reply" && text_field(*message, "cmd") == cmd)) {
      const auto ok = message->find("ok");
      if (ok == message->end() || *ok != true) {
        const std::string error = text_field(*message, "error");
        return make_error(Errc::kInvalidArgument, error.empty() ? "imucald refused " + cmd : error);
      }
      return std::move(*message);
    }
    if (others != nullptr) {
      others->push_back(std::move(*message));
    }
  }
}

}  // namespace imucal::ctl
