#pragma once
// contourctl's connection to contourd's command socket (JSON lines, daemon/command_server.hpp):
// one request {"id", "cmd", ...} per line, replies {"id", "ok", "result"|"error"}; lines carrying
// "event" are subscription traffic and skipped.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

namespace contour::ctl {

// Exit codes (documented in `contourctl --help`).
inline constexpr int kExitOk = 0;
inline constexpr int kExitError = 1;        // error reply, run not completed, plot/analysis failed
inline constexpr int kExitUsage = 2;        // bad command line
inline constexpr int kExitUnreachable = 3;  // daemon not running / socket missing or refused
inline constexpr int kExitPermission = 4;   // socket exists but this user may not connect
inline constexpr int kExitInterrupted = 130;  // Ctrl-C during run --wait (daemon asked to hold)

struct Unreachable : std::runtime_error {
  explicit Unreachable(const std::string& m, int code = kExitUnreachable)
      : std::runtime_error(m), exit_code(code) {}
  int exit_code;
};
struct ErrorReply : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// --socket, else $CONTOURD_SOCKET, else /run/contourd/contourd.sock when it exists, else
// ${XDG_RUNTIME_DIR:-/tmp}/contourd.sock (config/sim.yaml's default).
std::string default_socket();

// A status reply says program `job` is over: it finished and the machine is neither RUNNING nor
// HOLD, or the machine stopped (FAULT, ESTOP, DISABLED).
bool job_ended(const nlohmann::json& status, std::uint64_t job);

class Client {
 public:
  // Connects; throws Unreachable naming the path and what to do.
  explicit Client(const std::string& path);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Sends one request and returns its "result"; throws ErrorReply on {"ok": false}.
  nlohmann::json call(nlohmann::json req);
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  std::string path_;
  int fd_ = -1;
  std::string buf_;
  long id_ = 0;
};

}  // namespace contour::ctl
