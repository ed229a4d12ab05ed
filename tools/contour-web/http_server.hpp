#pragma once
// contour-web's HTTP + WebSocket server (Boost.Beast over Boost.Asio, one io_context thread):
// the page's static files at /, the JSON-RPC WebSocket at /ws (hub.hpp). Every request's Host
// header is checked, every WebSocket upgrade's Origin (security.hpp); a full client table answers
// 503. Per connection: WebSocket messages up to web.max_message_bytes (larger: closed with 1009),
// an outgoing SendQueue of web.client_queue_bytes, pings every 10 s of silence and a close after
// 20 s more (a vanished browser is noticed even without a TCP reset).
#include <utility>  // before Boost 1.74's asio/awaitable.hpp, which uses std::exchange without it
#include <boost/asio.hpp>
#include <memory>
#include <string>

#include "tools/contour-web/hub.hpp"
#include "tools/contour-web/security.hpp"

namespace contour::web {

struct ServerOptions {
  std::string host = "127.0.0.1";
  unsigned short port = 8080;
  std::string static_dir;
  std::size_t max_message_bytes = 256 * 1024;
  std::size_t client_queue_bytes = 4u << 20;
  int max_clients = 16;
  OriginPolicy origins;
};

class WebServer {
 public:
  WebServer(boost::asio::io_context& io, ServerOptions opt, Hub& hub);
  ~WebServer();
  // Binds and listens (throws std::runtime_error naming the address); returns the bound port.
  unsigned short start();
  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace contour::web
