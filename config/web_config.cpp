#include "config/web_config.hpp"

#include <arpa/inet.h>

#include <cstdlib>

namespace contour::config {

namespace {
constexpr std::size_t kMinTokenChars = 16;

WebRole role_of(const std::string& s) {
  if (s == "operator") return WebRole::kOperator;
  if (s == "viewer") return WebRole::kViewer;
  return WebRole::kNone;
}

std::vector<std::string> string_list(Section& s, const std::string& key) {
  s.accept(key);
  std::vector<std::string> out;
  if (!s.has(key)) return out;
  const YAML::Node n = s.node()[key];
  if (!n.IsSequence()) {
    s.error(key, "expected a list of strings");
    return out;
  }
  for (std::size_t i = 0; i < n.size(); ++i) {
    if (!n[i].IsScalar() || n[i].Scalar().empty()) {
      s.error(key, "item " + std::to_string(i) + " must be a non-empty string");
      continue;
    }
    out.push_back(n[i].Scalar());
  }
  return out;
}
}  // namespace

const char* to_string(WebRole r) noexcept {
  switch (r) {
    case WebRole::kNone: return "none";
    case WebRole::kViewer: return "viewer";
    case WebRole::kOperator: return "operator";
  }
  return "?";
}

std::string parse_listen(const std::string& listen, std::string& host, int& port) {
  std::string h, p;
  if (!listen.empty() && listen.front() == '[') {
    const auto close = listen.find(']');
    if (close == std::string::npos || close + 1 >= listen.size() || listen[close + 1] != ':') {
      return "'" + listen + "' is not [IPV6]:PORT";
    }
    h = listen.substr(1, close - 1);
    p = listen.substr(close + 2);
  } else {
    const auto colon = listen.rfind(':');
    if (colon == std::string::npos || colon == 0) return "'" + listen + "' is not HOST:PORT";
    h = listen.substr(0, colon);
    p = listen.substr(colon + 1);
    if (h.find(':') != std::string::npos) return "'" + listen + "': write an IPv6 address as [ADDR]:PORT";
  }
  if (p.empty() || p.size() > 5 || p.find_first_not_of("0123456789") != std::string::npos) {
    return "'" + listen + "': port must be a number 0..65535";
  }
  const long v = std::strtol(p.c_str(), nullptr, 10);
  if (v > 65535) return "'" + listen + "': port must be a number 0..65535";
  if (h.empty()) return "'" + listen + "': empty host";
  host = h;
  port = static_cast<int>(v);
  return "";
}

bool is_loopback_host(const std::string& host) {
  if (host == "localhost" || host == "::1") return true;
  in_addr a{};
  if (::inet_pton(AF_INET, host.c_str(), &a) == 1) return (ntohl(a.s_addr) >> 24) == 127;
  return false;
}

std::string check_web_security(const WebConfig& c) {
  if (is_loopback_host(c.host)) return "";
  if (c.tokens.empty()) {
    return "listening on " + c.host + " (not a loopback address) needs at least one token "
           "(web.tokens); use 127.0.0.1 and a TLS reverse proxy, or configure tokens";
  }
  if (c.anonymous_role != WebRole::kNone) {
    return "listening on " + c.host + " (not a loopback address): web.anonymous_role must be "
           "none (every client needs a token)";
  }
  return "";
}

WebConfig parse_web(Section& s) {
  WebConfig c;
  c.present = s.present();
  if (!c.present) {
    c.anonymous_role = WebRole::kOperator;
    return c;
  }
  c.listen = s.string("listen", c.listen);
  if (const std::string e = parse_listen(c.listen, c.host, c.port); !e.empty()) s.error("listen", e);
  for (Section& t : s.list("tokens")) {
    WebToken tok;
    tok.name = t.required_string("name");
    tok.role = role_of(t.choice("role", "viewer", {"viewer", "operator"}));
    tok.token = t.string("token", "");
    tok.token_file = t.string("token_file", "");
    if (tok.token.empty() == tok.token_file.empty()) {
      t.error("", "give exactly one of token and token_file");
    } else if (!tok.token.empty() && tok.token.size() < kMinTokenChars) {
      // The value itself is never repeated in a message.
      t.error("token", "too short (at least " + std::to_string(kMinTokenChars) + " characters)");
    }
    for (const auto& other : c.tokens) {
      if (other.name == tok.name) t.error("name", "token name '" + tok.name + "' used twice");
      if (!tok.token.empty() && other.token == tok.token) t.error("token", "same token as '" + other.name + "'");
    }
    c.tokens.push_back(std::move(tok));
  }
  c.anonymous_role_set = s.has("anonymous_role");
  c.anonymous_role = role_of(s.choice("anonymous_role", c.tokens.empty() ? "operator" : "none",
                                      {"none", "viewer", "operator"}));
  c.allowed_origins = string_list(s, "allowed_origins");
  for (const auto& o : c.allowed_origins) {
    if (o.rfind("http://", 0) != 0 && o.rfind("https://", 0) != 0) {
      s.error("allowed_origins", "'" + o + "' must start with http:// or https://");
    } else if (o.back() == '/') {
      s.error("allowed_origins", "'" + o + "': an origin has no path (remove the trailing /)");
    }
  }
  c.allowed_hosts = string_list(s, "allowed_hosts");
  c.status_rate_hz = s.number("status_rate_hz", c.status_rate_hz, 0.5, 100.0);
  c.max_clients = static_cast<int>(s.integer("max_clients", c.max_clients, 1, 256));
  c.max_message_bytes = s.integer("max_message_bytes", c.max_message_bytes, 4096, 16L << 20);
  c.max_requests_per_s = s.number("max_requests_per_s", c.max_requests_per_s, 1.0, 10000.0);
  c.client_queue_bytes = s.integer("client_queue_bytes", c.client_queue_bytes, 64 * 1024, 256L << 20);
  c.jog_deadman_ms = static_cast<int>(s.integer("jog_deadman_ms", c.jog_deadman_ms, 100, 10000));
  c.viewer_may_stop = s.boolean("viewer_may_stop", c.viewer_may_stop);
  c.static_dir = s.string("static_dir", "");
  if (const std::string e = check_web_security(c); !e.empty()) s.error("listen", e);
  return c;
}

}  // namespace contour::config
