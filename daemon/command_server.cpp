#include "daemon/command_server.hpp"

#include <fcntl.h>
#include <grp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace contour::daemon {

namespace {
std::string errno_text(const std::string& what) { return what + ": " + std::strerror(errno); }

void set_nonblocking(int fd) {
  const int fl = fcntl(fd, F_GETFL, 0);
  fcntl(fd, F_SETFL, fl | O_NONBLOCK);
}
}  // namespace

CommandServer::CommandServer(CommandServerOptions opt, Handler handler)
    : opt_(std::move(opt)), handler_(std::move(handler)) {}

CommandServer::~CommandServer() { stop(); }

void CommandServer::start() {
  if (running_) return;
  sockaddr_un addr{};
  if (opt_.path.size() >= sizeof(addr.sun_path)) {
    throw std::runtime_error("socket path too long (max " + std::to_string(sizeof(addr.sun_path) - 1) +
                             " bytes): " + opt_.path);
  }
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, opt_.path.c_str(), opt_.path.size() + 1);

  listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw std::runtime_error(errno_text("socket"));
  // A stale socket file from a previous run is removed only if nothing listens on it.
  struct stat st{};
  if (::lstat(opt_.path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode)) {
      ::close(listen_fd_);
      throw std::runtime_error(opt_.path + ": exists and is not a socket");
    }
    const int probe = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const bool alive = ::connect(probe, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0;
    ::close(probe);
    if (alive) {
      ::close(listen_fd_);
      throw std::runtime_error(opt_.path + ": another contourd is already serving this socket");
    }
    ::unlink(opt_.path.c_str());
  }
  const mode_t old_umask = ::umask(0177);
  const int rc = ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
  ::umask(old_umask);
  if (rc < 0) {
    const std::string msg = errno_text(opt_.path + ": bind");
    ::close(listen_fd_);
    throw std::runtime_error(msg);
  }
  if (!opt_.group.empty()) {
    const group* g = ::getgrnam(opt_.group.c_str());
    if (g == nullptr || ::chown(opt_.path.c_str(), static_cast<uid_t>(-1), g->gr_gid) != 0) {
      ::close(listen_fd_);
      ::unlink(opt_.path.c_str());
      throw std::runtime_error(opt_.path + ": cannot give the socket to group '" + opt_.group + "'");
    }
  }
  if (::chmod(opt_.path.c_str(), opt_.mode) != 0 || ::listen(listen_fd_, 16) != 0) {
    const std::string msg = errno_text(opt_.path + ": chmod/listen");
    ::close(listen_fd_);
    ::unlink(opt_.path.c_str());
    throw std::runtime_error(msg);
  }
  set_nonblocking(listen_fd_);
  if (::pipe2(wake_pipe_, O_CLOEXEC | O_NONBLOCK) != 0) {
    ::close(listen_fd_);
    throw std::runtime_error(errno_text("pipe"));
  }
  running_ = true;
  thread_ = std::thread([this] { run(); });
}

void CommandServer::stop() {
  if (!running_.exchange(false)) return;
  const char b = 'x';
  [[maybe_unused]] auto n = ::write(wake_pipe_[1], &b, 1);
  if (thread_.joinable()) thread_.join();
  std::lock_guard lk(mu_);
  for (auto& [id, c] : clients_) ::close(c.fd);
  clients_.clear();
  ::close(listen_fd_);
  ::close(wake_pipe_[0]);
  ::close(wake_pipe_[1]);
  ::unlink(opt_.path.c_str());
}

void CommandServer::run() {
  std::vector<pollfd> fds;
  std::vector<std::uint64_t> ids;
  while (running_) {
    fds.clear();
    ids.clear();
    fds.push_back({listen_fd_, POLLIN, 0});
    fds.push_back({wake_pipe_[0], POLLIN, 0});
    {
      std::lock_guard lk(mu_);
      for (auto& [id, c] : clients_) {
        short ev = POLLIN;
        if (!c.out.empty()) ev = static_cast<short>(ev | POLLOUT);
        fds.push_back({c.fd, ev, 0});
        ids.push_back(id);
      }
    }
    const int n = ::poll(fds.data(), fds.size(), 500);
    if (n < 0 && errno != EINTR) break;
    if (fds[1].revents & POLLIN) {
      char buf[64];
      while (::read(wake_pipe_[0], buf, sizeof(buf)) > 0) {
      }
    }
    if (fds[0].revents & POLLIN) accept_clients();
    for (std::size_t i = 0; i < ids.size(); ++i) {
      const short re = fds[i + 2].revents;
      if (re == 0) continue;
      std::unique_lock lk(mu_);
      auto it = clients_.find(ids[i]);
      if (it == clients_.end()) continue;
      bool keep = true;
      if (re & (POLLIN | POLLHUP | POLLERR)) {
        lk.unlock();
        keep = read_client(it->second);  // handler runs without the lock held
        lk.lock();
      }
      if (keep && (re & POLLOUT)) keep = flush_client(it->second);
      if (!keep) {
        ::close(it->second.fd);
        clients_.erase(it);
      }
    }
  }
}

void CommandServer::accept_clients() {
  for (;;) {
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;
    std::unique_lock lk(mu_);
    if (clients_.size() >= opt_.max_clients) {
      // A burst of short-lived clients can fill the table with peers that have already hung up
      // but whose hang-up this thread has not polled yet; reap those before refusing anyone.
      lk.unlock();
      reap_hung_up_clients();
      lk.lock();
    }
    if (clients_.size() >= opt_.max_clients) {
      const char* msg = "{\"ok\":false,\"error\":\"too many clients\"}\n";
      [[maybe_unused]] auto n = ::send(fd, msg, std::strlen(msg), MSG_NOSIGNAL | MSG_DONTWAIT);
      ::close(fd);
      ++stats_.errors;
      continue;
    }
    Client c;
    c.fd = fd;
    c.info.id = next_id_++;
    ucred cred{};
    socklen_t len = sizeof(cred);
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0) {
      c.info.uid = cred.uid;
      c.info.pid = cred.pid;
    }
    ++stats_.connections;
    clients_.emplace(c.info.id, std::move(c));
  }
}

void CommandServer::reap_hung_up_clients() {
  std::vector<std::uint64_t> ids;
  {
    std::lock_guard lk(mu_);
    for (const auto& [id, c] : clients_) ids.push_back(id);
  }
  for (const std::uint64_t id : ids) {
    std::unique_lock lk(mu_);
    auto it = clients_.find(id);
    if (it == clients_.end()) continue;
    pollfd p{it->second.fd, static_cast<short>(POLLIN | POLLRDHUP), 0};
    if (::poll(&p, 1, 0) != 1 || (p.revents & (POLLHUP | POLLERR | POLLRDHUP)) == 0) continue;
    lk.unlock();
    const bool keep = read_client(it->second);  // answers what it sent, then sees the EOF
    lk.lock();
    if (!keep) {
      ::close(it->second.fd);
      clients_.erase(it);
    }
  }
}

bool CommandServer::read_client(Client& c) {
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(c.fd, buf, sizeof(buf));
    if (n == 0) return false;
    if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
    for (ssize_t i = 0; i < n; ++i) {
      const char ch = buf[i];
      if (ch == '\n') {
        if (c.discarding) {
          c.discarding = false;
        } else {
          std::string line;
          line.swap(c.in);
          if (!line.empty() && line.back() == '\r') line.pop_back();
          if (!line.empty()) handle_line(c, line);
        }
        continue;
      }
      if (c.discarding) continue;
      c.in.push_back(ch);
      if (c.in.size() > opt_.max_line_bytes) {
        c.in.clear();
        c.discarding = true;
        {
          std::lock_guard lk(mu_);
          ++stats_.errors;
        }
        queue(c, error_reply("request line longer than " + std::to_string(opt_.max_line_bytes) +
                             " bytes; discarded"));
      }
    }
  }
}

void CommandServer::handle_line(Client& c, const std::string& line) {
  {
    std::lock_guard lk(mu_);
    ++stats_.requests;
  }
  // The handler runs without mu_ held (it may call subscribe()/publish(), which take it).
  RequestOutcome r = handle_request_line(
      line, [&](const nlohmann::json& req) { return handler_(req, c.info); });
  if (r.error) {
    std::lock_guard lk(mu_);
    ++stats_.errors;
  }
  queue(c, r.reply);
}

void CommandServer::queue(Client& c, const nlohmann::json& j) {
  std::string s = to_line(j);
  std::lock_guard lk(mu_);
  c.out += s;
  flush_client(c);
}

bool CommandServer::flush_client(Client& c) {
  while (!c.out.empty()) {
    const ssize_t n = ::send(c.fd, c.out.data(), c.out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) break;
      return false;
    }
    c.out.erase(0, static_cast<std::size_t>(n));
  }
  if (c.out.size() > opt_.max_backlog_bytes) {
    ++stats_.dropped_clients;
    return false;
  }
  return true;
}

void CommandServer::subscribe(std::uint64_t client, const std::string& topic) {
  std::lock_guard lk(mu_);
  auto it = clients_.find(client);
  if (it == clients_.end()) return;
  for (const auto& t : it->second.topics) {
    if (t == topic) return;
  }
  it->second.topics.push_back(topic);
}

void CommandServer::unsubscribe(std::uint64_t client, const std::string& topic) {
  std::lock_guard lk(mu_);
  auto it = clients_.find(client);
  if (it == clients_.end()) return;
  std::erase(it->second.topics, topic);
}

void CommandServer::publish(const std::string& topic, const nlohmann::json& event) {
  const std::string s = to_line(event);
  bool any = false;
  {
    std::lock_guard lk(mu_);
    for (auto& [id, c] : clients_) {
      for (const auto& t : c.topics) {
        if (t == topic) {
          c.out += s;
          any = true;
          break;
        }
      }
    }
  }
  if (any) {
    const char b = 'p';
    [[maybe_unused]] auto n = ::write(wake_pipe_[1], &b, 1);
  }
}

CommandServerStats CommandServer::stats() const {
  std::lock_guard lk(mu_);
  CommandServerStats s = stats_;
  s.clients = clients_.size();
  return s;
}

}  // namespace contour::daemon
