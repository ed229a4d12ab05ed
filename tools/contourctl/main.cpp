// contourctl — command-line client of contourd's command socket (daemon/commands.hpp).
//   contourctl [--socket PATH] [--json] status|load PROGRAM|run [PROGRAM] [--wait]|hold|resume|stop|
//              estop|reset|enable|disable|jog AXIS VEL_MM_MIN DIST_MM|set-position AXIS POS_MM|
//              gains get|gains set k=v...|override PERCENT|record start [PATH]|record stop|shutdown
// `run PROGRAM --wait --json` ends with one JSON object: state, duration_s, max_contour_error_um,
// rms_contour_error_um, faults, overruns (+ job, completed, ...). Exit status: 0 ok, 1 error reply
// or run ended in FAULT/ESTOP/not completed, 2 usage, 3 cannot reach the daemon.
// Socket: --socket, else $CONTOURD_SOCKET, else /run/contourd/contourd.sock when it exists, else
// ${XDG_RUNTIME_DIR:-/tmp}/contourd.sock (config/sim.yaml's default).
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

using nlohmann::json;

struct Unreachable : std::runtime_error {
  using std::runtime_error::runtime_error;
};
struct ErrorReply : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::string default_socket() {
  if (const char* e = std::getenv("CONTOURD_SOCKET"); e != nullptr && *e != '\0') return e;
  struct stat st{};
  if (::stat("/run/contourd/contourd.sock", &st) == 0) return "/run/contourd/contourd.sock";
  const char* x = std::getenv("XDG_RUNTIME_DIR");
  return std::string(x != nullptr && *x != '\0' ? x : "/tmp") + "/contourd.sock";
}

class Client {
 public:
  explicit Client(const std::string& path) : path_(path) {
    fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) throw Unreachable(std::string("socket: ") + std::strerror(errno));
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof(addr.sun_path)) throw Unreachable(path + ": socket path too long");
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
      const int err = errno;
      ::close(fd_);
      fd_ = -1;
      if (err == ENOENT || err == ECONNREFUSED) {
        throw Unreachable(path + ": contourd is not running (" + std::strerror(err) +
                          "); start it or pass --socket PATH");
      }
      if (err == EACCES || err == EPERM) {
        throw Unreachable(path + ": permission denied; the socket is group-writable: add your user "
                                 "to contourd's group");
      }
      throw Unreachable(path + ": " + std::strerror(err));
    }
  }
  ~Client() {
    if (fd_ >= 0) ::close(fd_);
  }
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  json call(json req) {
    req["id"] = ++id_;
    const std::string line = req.dump() + "\n";
    std::size_t off = 0;
    while (off < line.size()) {
      const ssize_t n = ::send(fd_, line.data() + off, line.size() - off, MSG_NOSIGNAL);
      if (n < 0) {
        if (errno == EINTR) continue;
        throw Unreachable(path_ + ": send: " + std::strerror(errno));
      }
      off += static_cast<std::size_t>(n);
    }
    for (;;) {
      const std::size_t nl = buf_.find('\n');
      if (nl != std::string::npos) {
        const std::string l = buf_.substr(0, nl);
        buf_.erase(0, nl + 1);
        json r = json::parse(l, nullptr, false);
        if (r.is_discarded() || !r.is_object()) throw Unreachable("daemon sent a malformed reply");
        if (r.contains("event")) continue;  // subscription traffic
        if (!r.value("ok", false)) throw ErrorReply(r.value("error", std::string("error")));
        return r.value("result", json::object());
      }
      char tmp[4096];
      const ssize_t n = ::recv(fd_, tmp, sizeof(tmp), 0);
      if (n == 0) throw Unreachable(path_ + ": daemon closed the connection");
      if (n < 0) {
        if (errno == EINTR) continue;
        throw Unreachable(path_ + ": recv: " + std::strerror(errno));
      }
      buf_.append(tmp, static_cast<std::size_t>(n));
    }
  }

 private:
  std::string path_;
  int fd_ = -1;
  std::string buf_;
  long id_ = 0;
};

// Inline text when small (the daemon may not see the client's files, e.g. PrivateTmp), else the
// absolute path.
json program_args(const std::string& file) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto size = fs::file_size(file, ec);
  if (ec) throw ErrorReply(file + ": cannot read (" + ec.message() + ")");
  if (size < 32 * 1024) {
    std::ifstream in(file);
    std::stringstream ss;
    ss << in.rdbuf();
    return {{"program", ss.str()}, {"name", file}};
  }
  return {{"path", fs::absolute(file).string()}};
}

void print(const json& j, bool as_json) {
  if (as_json) {
    std::cout << j.dump() << std::endl;
    return;
  }
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) {
      std::cout << it.key() << ": " << (it.value().is_string() ? it.value().get<std::string>() : it.value().dump())
                << '\n';
    }
  } else {
    std::cout << j.dump(2) << '\n';
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"contourctl: client of the contourd command socket"};
  std::string socket_path;
  bool as_json = false;
  app.add_option("--socket", socket_path, "command socket (default: $CONTOURD_SOCKET, "
                                          "/run/contourd/contourd.sock, ${XDG_RUNTIME_DIR:-/tmp}/contourd.sock)");
  app.add_flag("--json", as_json, "print one JSON object");
  app.require_subcommand(1);
  std::string program;
  bool wait = false;
  double timeout_s = 3600.0;
  std::string axis;
  double vel = 0.0, dist = 0.0, pos = 0.0, pct = 100.0;
  std::vector<std::string> gains_args;
  std::vector<std::string> record_args;

  app.add_subcommand("status", "machine state, positions, errors, loop timing");
  auto* load = app.add_subcommand("load", "validate and plan a part program");
  load->add_option("PROGRAM", program, "RS274/NGC file")->required();
  auto* run = app.add_subcommand("run", "run the loaded program (or load PROGRAM first)");
  run->add_option("PROGRAM", program, "RS274/NGC file");
  run->add_flag("--wait", wait, "wait until the program ends and print its figures");
  run->add_option("--timeout", timeout_s, "seconds to wait with --wait");
  for (const char* c : {"hold", "resume", "stop", "estop", "reset", "enable", "disable", "shutdown"}) {
    app.add_subcommand(c, std::string(c));
  }
  auto* jog = app.add_subcommand("jog", "jog an axis by a distance");
  jog->add_option("AXIS", axis)->required();
  jog->add_option("VELOCITY_MM_MIN", vel)->required();
  jog->add_option("DISTANCE_MM", dist)->required();
  auto* setpos = app.add_subcommand("set-position", "set an axis position (sim / absolute encoders)");
  setpos->add_option("AXIS", axis)->required();
  setpos->add_option("POSITION_MM", pos)->required();
  auto* gains = app.add_subcommand("gains", "gains get | gains set k=v ... (kp=0.6 or kp=0.6,0.6,0.6)");
  gains->add_option("ARGS", gains_args)->required();
  auto* ovr = app.add_subcommand("override", "feed override in percent");
  ovr->add_option("PERCENT", pct)->required();
  auto* rec = app.add_subcommand("record", "record start [PATH] | record stop");
  rec->add_option("ARGS", record_args)->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  if (socket_path.empty()) socket_path = default_socket();
  const std::string cmd = app.get_subcommands().front()->get_name();
  try {
    Client c(socket_path);
    json req{{"cmd", cmd}};
    if (cmd == "load") {
      req.update(program_args(program));
    } else if (cmd == "run") {
      if (!program.empty()) req.update(program_args(program));
      const json r = c.call(req);
      if (!wait) {
        print(r, as_json);
        return 0;
      }
      const std::uint64_t job = r.at("job").get<std::uint64_t>();
      const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
      for (;;) {
        const json st = c.call({{"cmd", "status"}});
        const std::string s = st.at("state").get<std::string>();
        const bool ended = st.at("finished_job").get<std::uint64_t>() >= job && s != "RUNNING" && s != "HOLD";
        if (ended || s == "FAULT" || s == "ESTOP" || s == "DISABLED") break;
        if (std::chrono::steady_clock::now() > until) throw ErrorReply("timed out waiting for the program");
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
      const json res = c.call({{"cmd", "result"}, {"job", job}});
      print(res, as_json);
      return res.value("completed", false) ? 0 : 1;
    } else if (cmd == "jog") {
      req["axis"] = axis;
      req["velocity_mm_min"] = vel;
      req["distance_mm"] = dist;
    } else if (cmd == "set-position") {
      req["axis"] = axis;
      req["position_mm"] = pos;
    } else if (cmd == "override") {
      req["percent"] = pct;
    } else if (cmd == "record") {
      if (record_args[0] != "start" && record_args[0] != "stop") {
        std::cerr << "contourctl: record start [PATH] | record stop\n";
        return 2;
      }
      req["action"] = record_args[0];
      if (record_args.size() > 1) req["path"] = std::filesystem::absolute(record_args[1]).string();
    } else if (cmd == "gains") {
      if (gains_args[0] == "set") {
        json set = json::object();
        for (std::size_t i = 1; i < gains_args.size(); ++i) {
          const auto& kv = gains_args[i];
          const auto eq = kv.find('=');
          if (eq == std::string::npos) {
            std::cerr << "contourctl: gains set expects key=value, got '" << kv << "'\n";
            return 2;
          }
          const std::string k = kv.substr(0, eq), v = kv.substr(eq + 1);
          if (v == "true" || v == "false") {
            set[k] = v == "true";
            continue;
          }
          json vals = json::array();
          std::stringstream ss(v);
          std::string item;
          while (std::getline(ss, item, ',')) {
            try {
              std::size_t used = 0;
              vals.push_back(std::stod(item, &used));
              if (used != item.size()) throw std::invalid_argument(item);
            } catch (const std::exception&) {
              std::cerr << "contourctl: gains set: '" << item << "' is not a number (key " << k << ")\n";
              return 2;
            }
          }
          set[k] = vals.size() == 1 ? vals[0] : vals;
        }
        if (set.empty()) {
          std::cerr << "contourctl: gains set needs key=value pairs\n";
          return 2;
        }
        req["set"] = set;
      } else if (gains_args[0] != "get") {
        std::cerr << "contourctl: gains get | gains set k=v ...\n";
        return 2;
      }
    }
    print(c.call(req), as_json);
    return 0;
  } catch (const Unreachable& e) {
    std::cerr << "contourctl: " << e.what() << '\n';
    return 3;
  } catch (const ErrorReply& e) {
    if (as_json) std::cout << json{{"error", e.what()}}.dump() << std::endl;
    std::cerr << "contourctl: " << cmd << ": " << e.what() << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "contourctl: " << e.what() << '\n';
    return 1;
  }
}
