#pragma once
// contour-web's settings: the command line over the `web:` section of contourd's YAML file.
//   contour-web --socket PATH [--listen HOST:PORT] [--config FILE] [--static-dir DIR]
// --config FILE is contourd's configuration (validated whole, like contourd does; only `web:` and
// `socket.path` are used). Token files are read here. Errors throw config::ConfigError (exit 78).
#include <optional>
#include <string>

#include "config/web_config.hpp"
#include "tools/contour-web/hub.hpp"
#include "tools/contour-web/security.hpp"

namespace contour::web {

struct CommandLine {
  std::optional<std::string> socket;
  std::optional<std::string> listen;
  std::optional<std::string> config;
  std::optional<std::string> static_dir;
};

struct Settings {
  config::WebConfig web;
  std::string socket_path;
  std::string static_dir;
  std::vector<ResolvedToken> tokens;
};

// "${VAR:-default}" and "${VAR}" as contourd expands socket.path.
[[nodiscard]] std::string expand_env(const std::string& s);
Settings resolve_settings(const CommandLine& cl, const std::string& default_static_dir);
[[nodiscard]] HubOptions hub_options(const Settings& s);
[[nodiscard]] OriginPolicy origin_policy(const Settings& s);

}  // namespace contour::web
