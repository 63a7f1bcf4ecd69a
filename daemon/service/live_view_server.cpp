// SPDX-License-Identifier: BSD-3-Clause
#include "daemon/service/live_view_server.hpp"

#include <sys/socket.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <charconv>
#include <deque>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string_view>

namespace imucal::service {

namespace beast = boost::beast;
namespace http = beast::http;
namespace asio = boost::asio;
using tcp = asio::ip::tcp;
using nlohmann::json;

namespace {

// The page's own content only: inline script and style, images and streams from here.
constexpr const char* kPagePolicy =
    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src 'self'; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// A whole non-negative number, or none.
std::optional<std::uint64_t> whole_number(std::string_view text) {
  if (text.empty() || text.size() > 18) return std::nullopt;
  std::uint64_t v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return v;
}

/// The value of `key` in a query string ("seq=4&x=1"), or none.
std::optional<std::string_view> query_value(std::string_view query, std::string_view key) {
  while (!query.empty()) {
    const auto amp = query.find('&');
    const std::string_view pair = query.substr(0, amp);
    const auto eq = pair.find('=');
    if (eq != std::string_view::npos && pair.substr(0, eq) == key) return pair.substr(eq + 1);
    if (amp == std::string_view::npos) break;
    query.remove_prefix(amp + 1);
  }
  return std::nullopt;
}

std::string event(const char* name, const std::string& data) {
  return std::string("event: ") + name + "\ndata: " + data + "\n\n";
}

json frame_json(const ViewFrame& f, std::uint64_t seq) {
  json corners = json::array();
  for (const auto& c : f.corners) corners.push_back({c.x(), c.y()});
  const auto& cov = f.coverage;
  return {{"camera", f.camera},
          {"name", f.name},
          {"seq", seq},
          {"t", static_cast<double>(f.t_ns) * 1e-9},
          {"width", f.width},
          {"height", f.height},
          {"full_width", f.full_width},
          {"full_height", f.full_height},
          {"seen", f.seen},
          {"corners", corners},
          {"board", {f.board[0], f.board[1]}},
          {"coverage",
           {{"cols", cov.cols},
            {"rows", cov.rows},
            {"cells", cov.cells},
            {"views", cov.views},
            {"bars", {{"x", cov.x}, {"y", cov.y}, {"size", cov.size}, {"skew", cov.skew}}}}}};
}

}  // namespace

bool token_matches(const std::string& token, const std::string& given) {
  if (token.empty()) return false;
  unsigned char diff = token.size() == given.size() ? 0 : 1;
  for (std::size_t i = 0; i < token.size(); ++i)
    diff |= static_cast<unsigned char>(token[i] ^ (i < given.size() ? given[i] : 0));
  return diff == 0;
}

Result<std::string> make_token() {
  std::ifstream in("/dev/urandom", std::ios::binary);
  unsigned char bytes[16];
  if (!in.read(reinterpret_cast<char*>(bytes), sizeof bytes))
    return make_error(Errc::kIo, "the live view's token: /dev/urandom cannot be read");
  std::string out;
  static constexpr char kHex[] = "0123456789abcdef";
  for (unsigned char b : bytes) {
    out += kHex[b >> 4];
    out += kHex[b & 15];
  }
  return out;
}

// ---- a connection ----------------------------------------------------------------------------

class Connection : public std::enable_shared_from_this<Connection> {
 public:
  /// What a connection needs of the options, copied: its handlers may run after the server is gone.
  struct Limits {
    std::size_t max_header_bytes, max_body_bytes, max_queued_bytes;
    std::chrono::milliseconds request_timeout;
  };
  Connection(tcp::socket socket, std::weak_ptr<LiveViewServer::Impl> server, const LiveViewOptions& options)
      : stream_(std::move(socket)),
        server_(std::move(server)),
        options_{options.max_header_bytes, options.max_body_bytes, options.max_queued_bytes,
                 options.request_timeout} {}

  void start() { read(); }
  /// Bytes for the client (a response or events); the connection closes once they are sent
  /// when `then_close`.
  void send(std::string bytes, bool then_close = false);
  bool streaming() const { return streaming_; }
  void become_stream() { streaming_ = true; }
  void close();
  bool closed() const { return closed_; }

 private:
  void read();
  void on_read(beast::error_code ec);
  void write_next();
  void watch_for_close();

  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::weak_ptr<LiveViewServer::Impl> server_;
  const Limits options_;
  std::deque<std::string> out_;
  std::size_t queued_ = 0;
  bool writing_ = false, close_after_ = false, streaming_ = false, closed_ = false;
  char probe_[64];
};

// ---- the server -------------------------------------------------------------------------------

class LiveViewServer::Impl : public std::enable_shared_from_this<Impl> {
 public:
  Impl(asio::io_context& io, LiveViewOptions options, SessionHost& host)
      : io_(io), options_(std::move(options)), host_(host), acceptor_(io) {}

  Status open() {
    beast::error_code ec;
    if (options_.listen_fd >= 0) {
      sockaddr_storage sa{};
      socklen_t len = sizeof sa;
      if (::getsockname(options_.listen_fd, reinterpret_cast<sockaddr*>(&sa), &len) != 0 ||
          (sa.ss_family != AF_INET && sa.ss_family != AF_INET6))
        return make_error(Errc::kInvalidArgument,
                          "live view: the socket systemd passed is not a TCP socket (check imucald.socket's "
                          "ListenStream=)");
      acceptor_.assign(sa.ss_family == AF_INET ? tcp::v4() : tcp::v6(), options_.listen_fd, ec);
      if (ec) return make_error(Errc::kIo, "live view: the socket systemd passed: " + ec.message());
      const tcp::endpoint at = acceptor_.local_endpoint(ec);
      options_.address = at.address().to_string();
      port_ = at.port();
      return {};
    }
    const auto address = asio::ip::make_address(options_.address, ec);
    if (ec)
      return make_error(Errc::kInvalidArgument, "live view: '" + options_.address +
                                                    "' is not an IP address (live_view.address: 127.0.0.1 "
                                                    "for this machine only, 0.0.0.0 for every interface)");
    const tcp::endpoint at(address, options_.port);
    acceptor_.open(at.protocol(), ec);
    if (!ec) acceptor_.set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor_.bind(at, ec);
    if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
    if (ec)
      return make_error(Errc::kIo,
                        "live view: cannot listen on " + options_.address + " port " +
                            std::to_string(options_.port) + ": " + ec.message() +
                            " (another program uses the port? choose another with live_view.port)");
    port_ = acceptor_.local_endpoint().port();
    return {};
  }

  void accept() {
    acceptor_.async_accept([weak = weak_from_this()](beast::error_code ec, tcp::socket socket) {
      auto self = weak.lock();
      if (!self || !self->acceptor_.is_open()) return;
      if (!ec) self->admit(std::move(socket));
      self->accept();
    });
  }

  void admit(tcp::socket socket) {
    prune();
    auto c = std::make_shared<Connection>(std::move(socket), weak_from_this(), options_);
    if (connections_.size() >= options_.max_clients) {
      note("a client was refused: " + std::to_string(connections_.size()) + " connections already");
      c->send(
          plain(http::status::service_unavailable, "The live view has too many clients; try again later.\n"),
          true);
      return;
    }
    connections_.push_back(c);
    c->start();
  }

  void prune() {
    std::erase_if(connections_, [](const std::weak_ptr<Connection>& w) {
      auto c = w.lock();
      return !c || c->closed();
    });
  }

  void note(const std::string& text) const {
    if (options_.log) options_.log(text);
  }

  /// A whole response as bytes.
  template <typename Body>
  static std::string serialize(http::response<Body>& res) {
    res.set(http::field::server, "imucald");
    res.set(http::field::cache_control, "no-store");
    res.set(http::field::connection, "close");
    res.set("X-Content-Type-Options", "nosniff");
    res.keep_alive(false);
    res.prepare_payload();
    std::ostringstream out;
    out << res;
    return out.str();
  }
  static std::string plain(http::status status, const std::string& text) {
    http::response<http::string_body> res{status, 11};
    res.set(http::field::content_type, "text/plain; charset=utf-8");
    res.body() = text;
    return serialize(res);
  }
  static std::string typed(const char* type, std::string body, bool head = false) {
    http::response<http::string_body> res{http::status::ok, 11};
    res.set(http::field::content_type, type);
    res.body() = std::move(body);
    std::string out = serialize(res);
    if (head) out.resize(out.find("\r\n\r\n") + 4);
    return out;
  }

  void handle(const std::shared_ptr<Connection>& c, const http::request<http::string_body>& req) {
    const std::string_view target(req.target().data(), req.target().size());
    const auto q = target.find('?');
    const std::string_view path = target.substr(0, q);
    const std::string_view query = q == std::string_view::npos ? std::string_view() : target.substr(q + 1);
    const bool get = req.method() == http::verb::get, head = req.method() == http::verb::head;
    if (req.method() == http::verb::post && path.starts_with("/key/")) {
      c->send(key(std::string(path.substr(5)), req), true);
      return;
    }
    if (!get && !head) {
      c->send(plain(http::status::method_not_allowed, "Only GET, HEAD and POST /key/<name> are served.\n"),
              true);
      return;
    }
    if (path == "/" || path == "/index.html") {
      std::string out = typed("text/html; charset=utf-8", live_view_page(), head);
      out.insert(out.find("\r\n") + 2, std::string("Content-Security-Policy: ") + kPagePolicy + "\r\n");
      c->send(std::move(out), true);
    } else if (path == "/events" && query_value(query, "snapshot") == std::string_view("1")) {
      // The state now, as events in a response that ends (the page's ?poll=1). A poller watches
      // for a while: frames are made for it.
      last_poll_ = std::chrono::steady_clock::now();
      c->send(typed("text/event-stream", snapshot_events(), head), true);
    } else if (path == "/events" && get) {
      open_stream(c);
    } else if (path.starts_with("/frame/")) {
      c->send(frame_file(path.substr(7), query, head), true);
    } else if (path.starts_with("/report/")) {
      c->send(report(path.substr(8), head), true);
    } else {
      c->send(plain(http::status::not_found,
                    "Not found: the live view serves /, /events, /frame/<camera>.png, "
                    "/report/<n> and /key/<name>.\n"),
              true);
    }
  }

  std::string key(const std::string& name, const http::request<http::string_body>& req) {
    const auto it = req.find("X-Imucal-Token");
    const std::string given = it == req.end() ? std::string() : std::string(it->value());
    if (!token_matches(options_.token, given)) {
      note("a key from the live view was refused: no token or a wrong one");
      return plain(http::status::forbidden,
                   "The keys need the live view's token (X-Imucal-Token): imucalctl status shows the file "
                   "that holds it, readable by the imucal group.\n");
    }
    Status done;
    if (name == "start") {
      done = host_.start({});
    } else {
      auto k = session_msg::parse_key(name);
      if (!k.ok())
        return plain(http::status::bad_request,
                     "'" + name + "' is not a key (start, " + session_msg::key_list() + ")\n");
      done = host_.key(*k);
    }
    if (!done.ok()) return plain(http::status::conflict, done.error().message + "\n");
    http::response<http::empty_body> res{http::status::no_content, 11};
    return serialize(res);
  }

  std::string frame_file(std::string_view name, std::string_view query, bool head) {
    const auto dot = name.find('.');
    const auto camera = whole_number(name.substr(0, dot));
    const std::string_view kind = dot == std::string_view::npos ? std::string_view() : name.substr(dot);
    std::optional<std::uint64_t> seq;
    if (auto s = query_value(query, "seq")) seq = whole_number(*s);
    if (!camera || *camera >= frames_.size() || (kind != ".png" && kind != ".json") ||
        (query_value(query, "seq") && !seq))
      return plain(http::status::not_found, "No such frame.\n");
    const auto& kept = frames_[*camera];
    const Kept* f = nullptr;
    for (const Kept& k : kept)
      if (!seq || k.seq == *seq) f = &k;
    if (!f) return plain(http::status::not_found, "That frame is no longer kept.\n");
    if (kind == ".png") return typed("image/png", std::string(f->png.begin(), f->png.end()), head);
    return typed("application/json", f->json, head);
  }

  std::string report(std::string_view index, bool head) {
    const auto i = whole_number(index);
    if (!done_ || !i || *i >= done_->reports.size())
      return plain(http::status::not_found, "No such report: the reports come at the session's end.\n");
    const std::string& path = done_->reports[*i];
    std::ifstream in(path, std::ios::binary);
    std::string body;
    if (in) {
      in.seekg(0, std::ios::end);
      const auto size = static_cast<std::size_t>(std::max<std::streamoff>(0, in.tellg()));
      if (size > options_.max_report_bytes)
        return plain(http::status::internal_server_error,
                     "The report is too large to serve; it is " + path + "\n");
      in.seekg(0);
      body.resize(size);
      in.read(body.data(), static_cast<std::streamsize>(size));
    }
    if (!in)
      return plain(http::status::internal_server_error, "The report cannot be read; it was " + path + "\n");
    return typed("text/html; charset=utf-8", std::move(body), head);
  }

  /// What brings a new watcher up to date: hello, the host's snapshot, the last live figures,
  /// review, result and end, and each camera's latest frame.
  std::string snapshot_events() {
    json cams = json::array();
    for (std::size_t i = 0; i < options_.cameras.size(); ++i)
      cams.push_back({{"index", i}, {"name", options_.cameras[i]}});
    std::string out = event("hello", json{{"version", options_.version},
                                          {"rig", options_.rig},
                                          {"cameras", cams},
                                          {"keys_need_token", true}}
                                         .dump());
    for (const auto& m : host_.snapshot())
      if (!std::holds_alternative<session_msg::Live>(m)) out += event("msg", session_msg::dump(m));
    if (kept_live_) out += event("msg", *kept_live_);
    for (const auto& m : kept_messages_) out += event("msg", m);
    for (const auto& kept : frames_)
      if (!kept.empty()) out += event("frame", kept.back().json);
    return out;
  }

  void open_stream(const std::shared_ptr<Connection>& c) {
    std::string out =
        "HTTP/1.1 200 OK\r\nServer: imucald\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n"
        "X-Content-Type-Options: nosniff\r\nConnection: keep-alive\r\n\r\n";
    out += "retry: 2000\n\n";
    out += snapshot_events();
    c->become_stream();
    c->send(std::move(out));
  }

  void broadcast(const session_msg::SessionMessage& message) {
    using namespace session_msg;
    if (std::holds_alternative<SessionStart>(message)) {
      kept_live_.reset();
      kept_messages_.clear();
      done_.reset();
      for (auto& kept : frames_) kept.clear();
    }
    const std::string text = dump(message);
    if (std::holds_alternative<Live>(message)) kept_live_ = text;
    if (std::holds_alternative<Review>(message) || std::holds_alternative<ResultSummary>(message))
      kept_messages_.push_back(text);
    if (const auto* d = std::get_if<Done>(&message)) {
      done_ = *d;
      kept_messages_.push_back(text);
    }
    send_all(event("msg", text));
  }

  void frame(ViewFrame f, std::vector<std::uint8_t> png) {
    if (f.camera >= 64) return;
    if (frames_.size() <= f.camera) frames_.resize(f.camera + 1);
    const std::uint64_t seq = ++seq_;
    Kept k{seq, frame_json(f, seq).dump(), std::move(png)};
    auto& kept = frames_[f.camera];
    kept.push_back(std::move(k));
    while (kept.size() > std::max<std::size_t>(1, options_.frames_kept)) kept.pop_front();
    send_all(event("frame", kept.back().json));
  }

  void send_all(const std::string& bytes) {
    prune();
    for (const auto& w : connections_)
      if (auto c = w.lock(); c && c->streaming()) c->send(bytes);
  }

  std::size_t watchers() const {
    std::size_t n = std::chrono::steady_clock::now() - last_poll_ < kPollWatches ? 1 : 0;
    for (const auto& w : connections_)
      if (auto c = w.lock(); c && c->streaming() && !c->closed()) ++n;
    return n;
  }
  std::size_t clients() {
    prune();
    return connections_.size();
  }

  void close() {
    beast::error_code ec;
    acceptor_.close(ec);
    for (const auto& w : connections_)
      if (auto c = w.lock()) c->close();
    connections_.clear();
  }

  asio::io_context& io_;
  LiveViewOptions options_;
  SessionHost& host_;
  tcp::acceptor acceptor_;
  unsigned short port_ = 0;
  std::vector<std::weak_ptr<Connection>> connections_;
  struct Kept {
    std::uint64_t seq = 0;
    std::string json;
    std::vector<std::uint8_t> png;
  };
  std::vector<std::deque<Kept>> frames_;
  std::uint64_t seq_ = 0;
  std::optional<std::string> kept_live_;
  std::vector<std::string> kept_messages_;  // the review, result and end, as they came
  std::optional<session_msg::Done> done_;
  static constexpr std::chrono::seconds kPollWatches{3};  // a snapshot's poller counts as watching this long
  std::chrono::steady_clock::time_point last_poll_{};
};

// ---- the connection's I/O -----------------------------------------------------------------------

void Connection::read() {
  parser_.emplace();
  parser_->header_limit(static_cast<std::uint32_t>(options_.max_header_bytes));
  parser_->body_limit(options_.max_body_bytes);
  stream_.expires_after(options_.request_timeout);
  http::async_read(stream_, buffer_, *parser_,
                   [self = shared_from_this()](beast::error_code ec, std::size_t) { self->on_read(ec); });
}

void Connection::on_read(beast::error_code ec) {
  if (closed_) return;
  auto server = server_.lock();
  if (!server) return close();
  if (ec == http::error::end_of_stream || ec == asio::error::eof || ec == asio::error::connection_reset)
    return close();
  if (ec == beast::error::timeout) {
    server->note("a live view client was dropped: its request was not whole within " +
                 std::to_string(options_.request_timeout.count()) + " ms");
    return close();
  }
  if (ec == http::error::header_limit) {
    return send(LiveViewServer::Impl::plain(http::status::request_header_fields_too_large,
                                            "The request's head is too large.\n"),
                true);
  }
  if (ec == http::error::body_limit) {
    return send(
        LiveViewServer::Impl::plain(http::status::payload_too_large, "The request's body is too large.\n"),
        true);
  }
  if (ec) {
    return send(
        LiveViewServer::Impl::plain(http::status::bad_request, "Not an HTTP request the live view reads.\n"),
        true);
  }
  server->handle(shared_from_this(), parser_->get());
  if (streaming_) watch_for_close();
}

void Connection::watch_for_close() {
  // An event stream sends nothing more; a read that ends tells that the browser went away.
  stream_.expires_never();
  stream_.async_read_some(asio::buffer(probe_),
                          [self = shared_from_this()](beast::error_code ec, std::size_t) {
                            if (ec) return self->close();
                            self->watch_for_close();
                          });
}

void Connection::send(std::string bytes, bool then_close) {
  if (closed_) return;
  if (queued_ + bytes.size() > options_.max_queued_bytes) {
    if (auto server = server_.lock())
      server->note("a live view client was dropped: it does not read what it is sent");
    return close();
  }
  queued_ += bytes.size();
  out_.push_back(std::move(bytes));
  close_after_ = close_after_ || then_close;
  if (!writing_) write_next();
}

void Connection::write_next() {
  if (closed_) return;
  if (out_.empty()) {
    writing_ = false;
    if (close_after_) {
      beast::error_code ec;
      stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
      // The peer's own close (or the timeout) ends the connection; its request is answered.
      stream_.expires_after(options_.request_timeout);
      stream_.async_read_some(asio::buffer(probe_),
                              [self = shared_from_this()](beast::error_code, std::size_t) { self->close(); });
    }
    return;
  }
  writing_ = true;
  if (!streaming_) stream_.expires_after(options_.request_timeout);
  asio::async_write(stream_, asio::buffer(out_.front()),
                    [self = shared_from_this()](beast::error_code ec, std::size_t) {
                      if (ec) return self->close();
                      self->queued_ -= self->out_.front().size();
                      self->out_.pop_front();
                      self->write_next();
                    });
}

void Connection::close() {
  if (closed_) return;
  closed_ = true;
  beast::error_code ec;
  stream_.socket().shutdown(tcp::socket::shutdown_both, ec);
  stream_.close();
}

// ---- the public face ------------------------------------------------------------------------------

Result<std::unique_ptr<LiveViewServer>> LiveViewServer::create(asio::io_context& io, LiveViewOptions options,
                                                               SessionHost& host) {
  auto impl = std::make_shared<Impl>(io, std::move(options), host);
  IMUCAL_TRY(impl->open());
  impl->accept();
  return std::unique_ptr<LiveViewServer>(new LiveViewServer(std::move(impl)));
}

LiveViewServer::LiveViewServer(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
LiveViewServer::~LiveViewServer() { close(); }
void LiveViewServer::broadcast(const session_msg::SessionMessage& message) { impl_->broadcast(message); }
void LiveViewServer::frame(ViewFrame frame, std::vector<std::uint8_t> png) {
  impl_->frame(std::move(frame), std::move(png));
}
std::size_t LiveViewServer::watchers() const { return impl_->watchers(); }
std::size_t LiveViewServer::clients() const { return impl_->clients(); }
unsigned short LiveViewServer::port() const { return impl_->port_; }
std::string LiveViewServer::url() const {
  const bool v6 = impl_->options_.address.find(':') != std::string::npos;
  return "http://" + (v6 ? "[" + impl_->options_.address + "]" : impl_->options_.address) + ":" +
         std::to_string(impl_->port_) + "/";
}
void LiveViewServer::close() { impl_->close(); }

}  // namespace imucal::service
