#include "tools/contour-web/options.hpp"

#include <sys/stat.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "config/config.hpp"

namespace contour::web {

std::string expand_env(const std::string& s) {
  std::string out;
  std::size_t i = 0;
  while (i < s.size()) {
    if (s[i] == '$' && i + 1 < s.size() && s[i + 1] == '{') {
      const std::size_t end = s.find('}', i);
      if (end == std::string::npos) break;
      std::string expr = s.substr(i + 2, end - i - 2);
      std::string def;
      if (const std::size_t dash = expr.find(":-"); dash != std::string::npos) {
        def = expr.substr(dash + 2);
        expr = expr.substr(0, dash);
      }
      const char* v = std::getenv(expr.c_str());
      out += (v != nullptr && *v != '\0') ? std::string(v) : def;
      i = end + 1;
    } else {
      out += s[i++];
    }
  }
  if (i < s.size()) out += s.substr(i);
  return out;
}

namespace {
std::string read_token_file(const std::string& path, const std::string& name) {
  std::ifstream in(path);
  if (!in) {
    throw config::ConfigError({path + ": cannot read the token file of web token '" + name + "'"});
  }
  std::stringstream ss;
  ss << in.rdbuf();
  std::string t = ss.str();
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r' || t.back() == ' ')) t.pop_back();
  if (t.size() < 16) {
    throw config::ConfigError({path + ": the token of web token '" + name +
                               "' is too short (at least 16 characters)"});
  }
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && (st.st_mode & S_IROTH) != 0) {
    throw config::ConfigError({path + ": token file is readable by every user (chmod o-r)"});
  }
  return t;
}
}  // namespace

Settings resolve_settings(const CommandLine& cl, const std::string& default_static_dir) {
  Settings s;
  std::string socket_from_config;
  if (cl.config) {
    const config::Config cfg = config::load_config_file(*cl.config);  // throws ConfigError
    s.web = cfg.web;
    socket_from_config = cfg.socket.path;
  }
  if (cl.listen) {
    s.web.listen = *cl.listen;
    if (const std::string e = config::parse_listen(*cl.listen, s.web.host, s.web.port); !e.empty()) {
      throw config::ConfigError({"--listen: " + e});
    }
  }
  if (const std::string e = config::check_web_security(s.web); !e.empty()) {
    throw config::ConfigError({(cl.listen ? "--listen: " : "web.listen: ") + e});
  }
  if (cl.socket) {
    s.socket_path = *cl.socket;
  } else if (!socket_from_config.empty()) {
    s.socket_path = expand_env(socket_from_config);
  } else {
    s.socket_path = "/run/contourd/contourd.sock";
  }
  s.static_dir = cl.static_dir ? *cl.static_dir
                               : (!s.web.static_dir.empty() ? s.web.static_dir : default_static_dir);
  for (const auto& t : s.web.tokens) {
    ResolvedToken r;
    r.name = t.name;
    r.role = t.role;
    r.value = t.token.empty() ? read_token_file(t.token_file, t.name) : t.token;
    s.tokens.push_back(std::move(r));
  }
  return s;
}

HubOptions hub_options(const Settings& s) {
  HubOptions h;
  h.status_rate_hz = s.web.status_rate_hz;
  h.max_requests_per_s = s.web.max_requests_per_s;
  h.jog_deadman_ms = s.web.jog_deadman_ms;
  h.viewer_may_stop = s.web.viewer_may_stop;
  h.anonymous_role = s.web.anonymous_role;
  h.tokens = s.tokens;
  h.max_message_bytes = static_cast<std::size_t>(s.web.max_message_bytes);
  h.client_queue_bytes = static_cast<std::size_t>(s.web.client_queue_bytes);
  h.max_clients = s.web.max_clients;
  return h;
}

OriginPolicy origin_policy(const Settings& s) {
  return OriginPolicy{s.web.allowed_hosts, s.web.allowed_origins};
}

}  // namespace contour::web
