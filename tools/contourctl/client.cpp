#include "tools/contourctl/client.hpp"

#include <grp.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace contour::ctl {

using nlohmann::json;

std::string default_socket() {
  if (const char* e = std::getenv("CONTOURD_SOCKET"); e != nullptr && *e != '\0') return e;
  struct stat st {};
  if (::stat("/run/contourd/contourd.sock", &st) == 0) return "/run/contourd/contourd.sock";
  const char* x = std::getenv("XDG_RUNTIME_DIR");
  return std::string(x != nullptr && *x != '\0' ? x : "/tmp") + "/contourd.sock";
}

namespace {

std::string group_of(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};
  if (const group* g = ::getgrgid(st.st_gid); g != nullptr) return g->gr_name;
  return std::to_string(st.st_gid);
}

}  // namespace

Client::Client(const std::string& path) : path_(path) {
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw Unreachable(std::string("socket: ") + std::strerror(errno));
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.size() >= sizeof(addr.sun_path)) {
    ::close(fd_);
    fd_ = -1;
    throw Unreachable(path + ": socket path too long (max " +
                      std::to_string(sizeof(addr.sun_path) - 1) + " bytes)");
  }
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) return;
  const int err = errno;
  ::close(fd_);
  fd_ = -1;
  if (err == ENOENT) {
    throw Unreachable(path +
                      ": no such socket: contourd is not running (or listens elsewhere). "
                      "Start it (`systemctl start contourd`, or `contourd --config FILE`) "
                      "or pass --socket PATH / set CONTOURD_SOCKET.");
  }
  if (err == ECONNREFUSED) {
    throw Unreachable(path +
                      ": connection refused: the socket file exists but no contourd "
                      "listens on it (stale socket of a daemon that died?). Start contourd, "
                      "or pass --socket PATH.");
  }
  if (err == EACCES || err == EPERM) {
    const std::string grp = group_of(path);
    throw Unreachable(path + ": permission denied. The socket is writable by its group" +
                          (grp.empty() ? std::string() : " '" + grp + "'") +
                          " only (socket.mode in the config): add your user to that group "
                          "(`sudo usermod -aG " +
                          (grp.empty() ? std::string("GROUP") : grp) +
                          " $USER`, then log in again) or run as the daemon's user.",
                      kExitPermission);
  }
  throw Unreachable(path + ": " + std::strerror(err));
}

Client::~Client() {
  if (fd_ >= 0) ::close(fd_);
}

json Client::call(json req) {
  req["id"] = ++id_;
  const std::string line = req.dump() + "\n";
  std::size_t off = 0;
  while (off < line.size()) {
    const ssize_t n = ::send(fd_, line.data() + off, line.size() - off, MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Unreachable(path_ + ": send: " + std::strerror(errno) + " (did contourd exit?)");
    }
    off += static_cast<std::size_t>(n);
  }
  for (;;) {
    const std::size_t nl = buf_.find('\n');
    if (nl != std::string::npos) {
      const std::string l = buf_.substr(0, nl);
      buf_.erase(0, nl + 1);
      json r = json::parse(l, nullptr, false);
      if (r.is_discarded() || !r.is_object())
        throw Unreachable(path_ + ": daemon sent a malformed reply");
      if (r.contains("event")) continue;  // subscription traffic
      if (!r.value("ok", false)) throw ErrorReply(r.value("error", std::string("error")));
      return r.value("result", json::object());
    }
    char tmp[4096];
    const ssize_t n = ::recv(fd_, tmp, sizeof(tmp), 0);
    if (n == 0) throw Unreachable(path_ + ": contourd closed the connection (did it exit?)");
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Unreachable(path_ + ": recv: " + std::strerror(errno));
    }
    buf_.append(tmp, static_cast<std::size_t>(n));
  }
}

bool job_ended(const nlohmann::json& status, std::uint64_t job) {
  const std::string s = status.at("state").get<std::string>();
  const bool finished =
      status.at("finished_job").get<std::uint64_t>() >= job && s != "RUNNING" && s != "HOLD";
  return finished || s == "FAULT" || s == "ESTOP" || s == "DISABLED";
}

}  // namespace contour::ctl
