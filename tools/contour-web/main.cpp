// contour-web: the browser HMI of contourd (issue 21). A separate, non-real-time process that
// talks to contourd only through its command socket; it can crash or be restarted without
// touching the loop. See tools/contour-web/README.md.
//   contour-web --socket PATH [--listen HOST:PORT] [--config FILE] [--static-dir DIR]
// Exit codes: 0 on SIGTERM/SIGINT, 78 (EX_CONFIG) for configuration errors, 1 otherwise.
#include <CLI/CLI.hpp>
#include <utility>  // before Boost 1.74's asio/awaitable.hpp, which uses std::exchange without it
#include <boost/asio.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "config/yaml_reader.hpp"
#include "tools/contour-web/daemon_link.hpp"
#include "tools/contour-web/http_server.hpp"
#include "tools/contour-web/options.hpp"

namespace {
void log_line(const std::string& s) {
  // systemd's journal timestamps lines; one line per event, never a token.
  std::fprintf(stderr, "contour-web: %s\n", s.c_str());
  std::fflush(stderr);
}

std::string default_static_dir() {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_directory(CONTOUR_WEB_INSTALLED_WWW, ec)) return CONTOUR_WEB_INSTALLED_WWW;
  return CONTOUR_WEB_SOURCE_WWW;  // running from a build tree
}
}  // namespace

int main(int argc, char** argv) {
  using namespace contour::web;
  CLI::App app{"contour-web: browser HMI for contourd (HTTP + JSON-RPC over WebSocket at /ws)"};
  CommandLine cl;
  std::string socket, listen, config, static_dir;
  app.add_option("--socket", socket, "contourd's command socket (default: socket.path of --config, "
                                     "else /run/contourd/contourd.sock)");
  app.add_option("--listen", listen, "HOST:PORT to serve (default web.listen, 127.0.0.1:8080; "
                                     "port 0: any free port)");
  app.add_option("--config", config, "contourd's YAML file (its web: section and socket.path)");
  app.add_option("--static-dir", static_dir, "page files (default: the installed share/contour-web/www)");
  CLI11_PARSE(app, argc, argv);
  if (!socket.empty()) cl.socket = socket;
  if (!listen.empty()) cl.listen = listen;
  if (!config.empty()) cl.config = config;
  if (!static_dir.empty()) cl.static_dir = static_dir;

  Settings settings;
  try {
    settings = resolve_settings(cl, default_static_dir());
  } catch (const contour::config::ConfigError& e) {
    for (const auto& m : e.errors()) log_line("config error: " + m);
    return 78;
  }
  if (!std::filesystem::exists(settings.static_dir + "/index.html")) {
    log_line("config error: no index.html in the page directory " + settings.static_dir);
    return 78;
  }
  try {
    boost::asio::io_context io(1);
    DaemonLink daemon(io, settings.socket_path);
    Hub hub(hub_options(settings), daemon);
    hub.log = log_line;
    ServerOptions so;
    so.host = settings.web.host;
    so.port = static_cast<unsigned short>(settings.web.port);
    so.static_dir = settings.static_dir;
    so.max_message_bytes = static_cast<std::size_t>(settings.web.max_message_bytes);
    so.client_queue_bytes = static_cast<std::size_t>(settings.web.client_queue_bytes);
    so.max_clients = settings.web.max_clients;
    so.origins = origin_policy(settings);
    WebServer server(io, so, hub);
    const unsigned short port = server.start();
    const bool v6 = so.host.find(':') != std::string::npos;
    log_line("serving http://" + (v6 ? "[" + so.host + "]" : so.host) + ":" + std::to_string(port) +
             "/ (WebSocket /ws), page files " + settings.static_dir + ", contourd at " +
             settings.socket_path + ", " + std::to_string(settings.tokens.size()) +
             " token(s), anonymous role " + contour::config::to_string(settings.web.anonymous_role));
    daemon.start([&hub](const nlohmann::json& j) { hub.on_daemon_line(j); },
                 [&hub](bool up, const std::string& why) {
                   hub.log(up ? std::string("connected to contourd") : "contourd: " + why);
                   hub.on_daemon_state(up, why);
                 });
    boost::asio::steady_timer tick(io);
    std::function<void()> arm = [&] {
      tick.expires_after(std::chrono::milliseconds(10));
      tick.async_wait([&](const boost::system::error_code& ec) {
        if (ec) return;
        hub.tick(Clock::now());
        arm();
      });
    };
    arm();
    boost::asio::signal_set signals(io, SIGINT, SIGTERM);
    signals.async_wait([&](const boost::system::error_code&, int sig) {
      log_line(std::string("stopping on ") + (sig == SIGTERM ? "SIGTERM" : "SIGINT"));
      io.stop();
    });
    ::signal(SIGPIPE, SIG_IGN);
    io.run();
  } catch (const std::exception& e) {
    log_line(std::string("error: ") + e.what());
    return 1;
  }
  return 0;
}
