#pragma once
// `web:` section: contour-web (issue 21), the browser HMI — listen address, tokens and roles, rate
// and size limits. contourd validates it on load and otherwise ignores it; contour-web reads it.
//
//   web:
//     listen: 127.0.0.1:8080      # HOST:PORT ([v6]:PORT); port 0 = any free port (tests)
//     anonymous_role: operator    # none | viewer | operator: a client without a token. Default:
//                                 # operator when no tokens are configured, else none. Only
//                                 # `none` is accepted when listen is not a loopback address.
//     tokens:                     # required when listen is not a loopback address
//       - {name: shopfloor, role: operator, token_file: /etc/contourd/web-operator.token}
//       - {name: office, role: viewer, token: "at least 16 characters"}
//     allowed_origins: [https://hmi.example.com]   # besides the page's own http://HOST:PORT
//     allowed_hosts: [hmi.example.com]             # Host headers accepted besides loopback names
//     status_rate_hz: 10          # status subscriptions: changed fields at most this often
//     max_clients: 16             # browser connections (the 17th is refused with 503)
//     max_message_bytes: 262144   # largest WebSocket message accepted (bigger: closed, 1009)
//     max_requests_per_s: 50      # per connection (1 s burst); estop, hold, stop never refused
//     client_queue_bytes: 4194304 # per connection unsent bytes; scope batches beyond: dropped
//     jog_deadman_ms: 500         # a jog stops when its client is silent this long
//     viewer_may_stop: false      # viewers may send estop/hold/stop
//     static_dir: ""              # page files (default: the installed share/contour-web/www)
// Token values are secrets: no error message, log line or status reply contains one.
#include <string>
#include <vector>

#include "config/yaml_reader.hpp"

namespace contour::config {

enum class WebRole { kNone, kViewer, kOperator };
[[nodiscard]] const char* to_string(WebRole r) noexcept;

struct WebToken {
  std::string name;
  WebRole role = WebRole::kViewer;
  std::string token;       // inline value, or
  std::string token_file;  // a file holding it (read by contour-web at start-up)
};

struct WebConfig {
  bool present = false;
  std::string listen = "127.0.0.1:8080";
  std::string host = "127.0.0.1";  // parsed from listen (without IPv6 brackets)
  int port = 8080;
  WebRole anonymous_role = WebRole::kOperator;
  bool anonymous_role_set = false;  // given explicitly in the file
  std::vector<WebToken> tokens;
  std::vector<std::string> allowed_origins;
  std::vector<std::string> allowed_hosts;
  double status_rate_hz = 10.0;
  int max_clients = 16;
  long max_message_bytes = 256 * 1024;
  double max_requests_per_s = 50.0;
  long client_queue_bytes = 4L << 20;
  int jog_deadman_ms = 500;
  bool viewer_may_stop = false;
  std::string static_dir;
};

WebConfig parse_web(Section& s);

// "HOST:PORT" or "[V6]:PORT" -> host (no brackets) and port 0..65535. Returns an error text, or
// "" when valid.
[[nodiscard]] std::string parse_listen(const std::string& listen, std::string& host, int& port);
// 127.0.0.0/8, ::1, localhost.
[[nodiscard]] bool is_loopback_host(const std::string& host);
// The security rules that involve several keys (and the command line's --listen): a non-loopback
// listen needs a token and no anonymous role. Returns an error text or "".
[[nodiscard]] std::string check_web_security(const WebConfig& c);

}  // namespace contour::config
