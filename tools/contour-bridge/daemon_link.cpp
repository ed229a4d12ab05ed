#include "tools/contour-bridge/daemon_link.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace contour::bridge {

using nlohmann::json;

namespace {
// A reply or event line longer than this is a broken peer (status is a few KiB).
constexpr std::size_t kMaxLineBytes = 16u << 20;
}  // namespace

DaemonLink::DaemonLink(std::string path, EventFn on_event, LostFn on_lost)
    : path_(std::move(path)), on_event_(std::move(on_event)), on_lost_(std::move(on_lost)) {}

DaemonLink::~DaemonLink() {
  if (fd_ >= 0) ::close(fd_);
}

bool DaemonLink::connect() {
  if (fd_ >= 0) return true;
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    error_ = std::string("socket: ") + std::strerror(errno);
    return false;
  }
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  if (path_.size() >= sizeof(a.sun_path)) {
    ::close(fd);
    error_ = path_ + ": socket path too long";
    return false;
  }
  std::memcpy(a.sun_path, path_.c_str(), path_.size() + 1);
  // A Unix socket connect completes at once (or fails): blocking is fine here.
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
    const int e = errno;
    ::close(fd);
    error_ = path_ + ": " + std::strerror(e) +
             (e == ENOENT || e == ECONNREFUSED ? " (contourd not running?)"
              : e == EACCES                     ? " (add the bridge's user to the socket's group)"
                                                : "");
    return false;
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);
  fd_ = fd;
  error_.clear();
  in_.clear();
  out_.clear();
  return true;
}

void DaemonLink::call(json req, Reply cb) {
  if (fd_ < 0) {
    if (cb) cb(false, json("contourd is not connected (" + path_ + ")"));
    return;
  }
  const std::uint64_t id = next_id_++;
  req["id"] = id;
  out_ += req.dump();
  out_ += '\n';
  pending_[id] = std::move(cb);
  flush();
}

short DaemonLink::poll_events() const {
  if (fd_ < 0) return 0;
  return static_cast<short>(POLLIN | (out_.empty() ? 0 : POLLOUT));
}

void DaemonLink::flush() {
  while (fd_ >= 0 && !out_.empty()) {
    const ssize_t n = ::send(fd_, out_.data(), out_.size(), MSG_NOSIGNAL);
    if (n > 0) {
      out_.erase(0, static_cast<std::size_t>(n));
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return;
    close(std::string("send: ") + std::strerror(errno));
    return;
  }
}

void DaemonLink::handle(short revents) {
  if (fd_ < 0) return;
  if ((revents & POLLOUT) != 0) flush();
  if (fd_ >= 0 && (revents & (POLLIN | POLLHUP | POLLERR)) != 0) read_lines();
}

void DaemonLink::read_lines() {
  char buf[65536];
  for (;;) {
    const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
    if (n > 0) {
      in_.append(buf, static_cast<std::size_t>(n));
      if (in_.size() > kMaxLineBytes && in_.find('\n') == std::string::npos) {
        close("contourd sent a line longer than 16 MiB");
        return;
      }
      continue;
    }
    if (n == 0) {
      close("contourd closed the connection");
      return;
    }
    if (errno == EINTR) continue;
    if (errno == EAGAIN || errno == EWOULDBLOCK) break;
    close(std::string("recv: ") + std::strerror(errno));
    return;
  }
  std::size_t start = 0;
  for (;;) {
    const std::size_t nl = in_.find('\n', start);
    if (nl == std::string::npos) break;
    const std::string_view line(in_.data() + start, nl - start);
    start = nl + 1;
    json j = json::parse(line, nullptr, false);
    if (j.is_discarded() || !j.is_object()) {
      close("contourd sent a line that is not a JSON object");
      return;
    }
    if (j.contains("event")) {
      if (on_event_) on_event_(j);
    } else if (j.contains("id") && j["id"].is_number_unsigned()) {
      auto it = pending_.find(j["id"].get<std::uint64_t>());
      if (it != pending_.end()) {
        Reply cb = std::move(it->second);
        pending_.erase(it);
        const bool ok = j.value("ok", false);
        if (cb) cb(ok, ok ? j.value("result", json::object()) : json(j.value("error", std::string("error"))));
      }
    }
    if (fd_ < 0) return;  // a callback closed the link
  }
  in_.erase(0, start);
}

void DaemonLink::close(const std::string& why) {
  if (fd_ < 0) return;
  ::close(fd_);
  fd_ = -1;
  error_ = why;
  in_.clear();
  out_.clear();
  auto pending = std::move(pending_);
  pending_.clear();
  for (auto& [id, cb] : pending) {
    if (cb) cb(false, json("connection to contourd lost: " + why));
  }
  if (on_lost_) on_lost_(why);
}

}  // namespace contour::bridge
