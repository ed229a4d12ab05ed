#include "tools/contour-web/http_server.hpp"

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <deque>
#include <stdexcept>

#include "tools/contour-web/send_queue.hpp"

namespace contour::web {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace asio = boost::asio;
using tcp = asio::ip::tcp;

namespace {
constexpr const char* kServer = "contour-web";
// No inline script, no third-party origin: the page's own files and its WebSocket only.
constexpr const char* kCsp =
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' "
    "data: blob:; connect-src 'self' ws: wss:; frame-ancestors 'none'; base-uri 'none'; "
    "form-action 'none'";
constexpr std::size_t kHttpBodyLimit = 16 * 1024;  // GET only: no bodies expected
}  // namespace

struct WebServer::Impl : std::enable_shared_from_this<WebServer::Impl> {
  asio::io_context& io;
  ServerOptions opt;
  Hub& hub;
  tcp::acceptor acceptor;
  int ws_clients = 0;

  Impl(asio::io_context& i, ServerOptions o, Hub& h) : io(i), opt(std::move(o)), hub(h), acceptor(i) {}
  void accept();
};

namespace {

template <class Body>
void security_headers(http::response<Body>& res) {
  res.set(http::field::server, kServer);
  res.set(http::field::cache_control, "no-cache");
  res.set("X-Content-Type-Options", "nosniff");
  res.set("X-Frame-Options", "DENY");
  res.set("Referrer-Policy", "no-referrer");
  res.set("Content-Security-Policy", kCsp);
}

class WsSession : public ClientPort, public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(tcp::socket&& s, std::shared_ptr<WebServer::Impl> srv)
      : ws_(std::move(s)), srv_(std::move(srv)), queue_(srv_->opt.client_queue_bytes) {}
  ~WsSession() override = default;

  void run(http::request<http::string_body> req, std::string remote) {
    remote_ = std::move(remote);
    ++srv_->ws_clients;
    counted_ = true;
    websocket::stream_base::timeout t{};
    t.handshake_timeout = std::chrono::seconds(10);
    t.idle_timeout = std::chrono::seconds(20);
    t.keep_alive_pings = true;
    ws_.set_option(t);
    ws_.read_message_max(srv_->opt.max_message_bytes);
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, kServer); }));
    ws_.async_accept(req, [self = shared_from_this()](beast::error_code ec) {
      if (ec) {
        self->finish();
        return;
      }
      self->id_ = self->srv_->hub.connect(self, self->remote_, Clock::now());
      self->connected_ = true;
      self->read();
    });
  }

  void send(std::shared_ptr<const std::string> text, std::size_t samples) override {
    if (closing_) return;
    queue_.push(std::move(text), samples);
    if (queue_.overflow()) {
      close("too slow: more than " + std::to_string(2 * srv_->opt.client_queue_bytes) +
            " bytes of replies and events unread");
      return;
    }
    write();
  }

  void close(const std::string& reason) override {
    if (closing_) return;
    closing_ = true;
    websocket::close_reason cr(websocket::close_code::policy_error);
    cr.reason = reason.substr(0, 120);
    ws_.async_close(cr, [self = shared_from_this()](beast::error_code) { self->finish(); });
  }

  [[nodiscard]] std::uint64_t dropped_samples() const override { return queue_.dropped_samples(); }

 private:
  void read() {
    ws_.async_read(buf_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) {
        if (ec == websocket::error::message_too_big) {
          // Beast has already failed the connection with 1009 (message too big).
        }
        self->finish();
        return;
      }
      const std::string text = beast::buffers_to_string(self->buf_.data());
      self->buf_.consume(self->buf_.size());
      if (!self->ws_.got_text()) {
        self->close("binary messages are not accepted");
        return;
      }
      self->srv_->hub.on_message(self->id_, text, Clock::now());
      if (!self->closing_) self->read();
    });
  }

  void write() {
    if (queue_.writing() || queue_.empty() || closing_) return;
    queue_.begin_write();
    ws_.text(true);
    ws_.async_write(asio::buffer(*queue_.front().text),
                    [self = shared_from_this()](beast::error_code ec, std::size_t) {
                      self->queue_.end_write();
                      if (ec) {
                        self->finish();
                        return;
                      }
                      self->write();
                    });
  }

  void finish() {
    if (finished_) return;
    finished_ = true;
    closing_ = true;
    if (counted_) --srv_->ws_clients;
    if (connected_) srv_->hub.disconnect(id_, Clock::now());  // drops the hub's reference
    beast::error_code ignored;
    beast::get_lowest_layer(ws_).socket().close(ignored);
  }

  websocket::stream<beast::tcp_stream> ws_;
  std::shared_ptr<WebServer::Impl> srv_;
  SendQueue queue_;
  beast::flat_buffer buf_;
  ClientId id_ = 0;
  std::string remote_;
  bool connected_ = false;
  bool counted_ = false;
  bool closing_ = false;
  bool finished_ = false;
};

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& s, std::shared_ptr<WebServer::Impl> srv)
      : stream_(std::move(s)), srv_(std::move(srv)) {
    beast::error_code ec;
    const auto ep = stream_.socket().remote_endpoint(ec);
    remote_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
  }

  void run() { read(); }

 private:
  void read() {
    parser_.emplace();
    parser_->body_limit(kHttpBodyLimit);
    parser_->header_limit(16 * 1024);
    stream_.expires_after(std::chrono::seconds(30));
    http::async_read(stream_, buf_, *parser_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) {
        beast::error_code ignored;
        self->stream_.socket().shutdown(tcp::socket::shutdown_both, ignored);
        return;
      }
      self->handle(self->parser_->release());
    });
  }

  template <class Body>
  void reply(http::response<Body>&& res) {
    auto sp = std::make_shared<http::response<Body>>(std::move(res));
    http::async_write(stream_, *sp, [self = shared_from_this(), sp](beast::error_code ec, std::size_t) {
      if (ec || sp->need_eof()) {
        beast::error_code ignored;
        self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
        return;
      }
      self->read();
    });
  }

  void text_reply(http::status st, unsigned version, bool keep_alive, const std::string& body) {
    http::response<http::string_body> res{st, version};
    security_headers(res);
    res.set(http::field::content_type, "text/plain; charset=utf-8");
    res.keep_alive(keep_alive);
    res.body() = body + "\n";
    res.prepare_payload();
    reply(std::move(res));
  }

  void handle(http::request<http::string_body> req) {
    const std::string host(req[http::field::host]);
    if (!host_allowed(host, srv_->opt.origins)) {
      // DNS rebinding or a misconfigured proxy: name the header, never serve.
      text_reply(http::status::misdirected_request, req.version(), false,
                 "Host '" + host + "' is not accepted (web.allowed_hosts)");
      return;
    }
    const std::string target(req.target());
    if (websocket::is_upgrade(req)) {
      const std::string path = target.substr(0, target.find('?'));
      if (path != "/ws") {
        text_reply(http::status::not_found, req.version(), false, "WebSocket is at /ws");
        return;
      }
      const std::string origin(req[http::field::origin]);
      if (!origin_allowed(origin, host, srv_->opt.origins)) {
        srv_->hub.log("refused a WebSocket from " + remote_ + ": Origin '" + origin +
                      "' is not this page's (web.allowed_origins)");
        text_reply(http::status::forbidden, req.version(), false,
                   "cross-origin WebSocket refused: Origin '" + origin + "'");
        return;
      }
      if (srv_->ws_clients >= srv_->opt.max_clients) {
        text_reply(http::status::service_unavailable, req.version(), false,
                   "too many clients (web.max_clients " + std::to_string(srv_->opt.max_clients) + ")");
        return;
      }
      stream_.expires_never();
      std::make_shared<WsSession>(stream_.release_socket(), srv_)->run(std::move(req), remote_);
      return;
    }
    if (req.method() != http::verb::get && req.method() != http::verb::head) {
      text_reply(http::status::method_not_allowed, req.version(), req.keep_alive(),
                 "only GET and HEAD (the API is the WebSocket at /ws)");
      return;
    }
    const std::string rel = static_path(target);
    if (rel.empty()) {
      text_reply(http::status::not_found, req.version(), req.keep_alive(), "not found");
      return;
    }
    const std::string file = srv_->opt.static_dir + "/" + rel;
    http::file_body::value_type body;
    beast::error_code ec;
    body.open(file.c_str(), beast::file_mode::scan, ec);
    if (ec) {
      text_reply(http::status::not_found, req.version(), req.keep_alive(), "not found");
      return;
    }
    const auto size = body.size();
    if (req.method() == http::verb::head) {
      http::response<http::empty_body> res{http::status::ok, req.version()};
      security_headers(res);
      res.set(http::field::content_type, content_type(rel));
      res.content_length(size);
      res.keep_alive(req.keep_alive());
      reply(std::move(res));
      return;
    }
    http::response<http::file_body> res{std::piecewise_construct, std::make_tuple(std::move(body)),
                                        std::make_tuple(http::status::ok, req.version())};
    security_headers(res);
    res.set(http::field::content_type, content_type(rel));
    res.content_length(size);
    res.keep_alive(req.keep_alive());
    reply(std::move(res));
  }

  beast::tcp_stream stream_;
  std::shared_ptr<WebServer::Impl> srv_;
  beast::flat_buffer buf_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::string remote_;
};

}  // namespace

void WebServer::Impl::accept() {
  acceptor.async_accept([self = shared_from_this()](beast::error_code ec, tcp::socket s) {
    if (!ec) std::make_shared<HttpSession>(std::move(s), self)->run();
    if (self->acceptor.is_open()) self->accept();
  });
}

WebServer::WebServer(asio::io_context& io, ServerOptions opt, Hub& hub)
    : impl_(std::make_shared<Impl>(io, std::move(opt), hub)) {}

WebServer::~WebServer() {
  beast::error_code ignored;
  impl_->acceptor.close(ignored);
}

unsigned short WebServer::start() {
  beast::error_code ec;
  const auto addr = asio::ip::make_address(impl_->opt.host == "localhost" ? "127.0.0.1" : impl_->opt.host, ec);
  if (ec) throw std::runtime_error("web.listen: '" + impl_->opt.host + "' is not an IP address");
  const tcp::endpoint ep(addr, impl_->opt.port);
  auto& a = impl_->acceptor;
  a.open(ep.protocol(), ec);
  if (!ec) a.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) a.bind(ep, ec);
  if (!ec) a.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    throw std::runtime_error("cannot listen on " + impl_->opt.host + ":" +
                             std::to_string(impl_->opt.port) + ": " + ec.message());
  }
  impl_->accept();
  return a.local_endpoint().port();
}

}  // namespace contour::web
