#include "tools/contour-bridge/shdr_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace contour::bridge {

namespace {
constexpr std::size_t kMaxInputLine = 4096;  // agents send `* PING` and little else
}

ShdrServer::ShdrServer(const std::string& bind, int port, int heartbeat_ms,
                       std::size_t max_clients, std::vector<std::string> header_lines)
    : heartbeat_ms_(heartbeat_ms), max_clients_(max_clients), header_(std::move(header_lines)) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* res = nullptr;
  const std::string port_s = std::to_string(port);
  const int gai = ::getaddrinfo(bind.c_str(), port_s.c_str(), &hints, &res);
  if (gai != 0) {
    throw std::runtime_error("mtconnect.bind: " + bind + ": " + ::gai_strerror(gai));
  }
  std::string err;
  for (addrinfo* a = res; a != nullptr; a = a->ai_next) {
    const int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) continue;
    const int one = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (::bind(fd, a->ai_addr, a->ai_addrlen) == 0 && ::listen(fd, 8) == 0) {
      listen_fd_ = fd;
      sockaddr_storage ss{};
      socklen_t len = sizeof ss;
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&ss), &len);
      port_ = ss.ss_family == AF_INET6 ? ntohs(reinterpret_cast<sockaddr_in6*>(&ss)->sin6_port)
                                       : ntohs(reinterpret_cast<sockaddr_in*>(&ss)->sin_port);
      break;
    }
    err = std::strerror(errno);
    ::close(fd);
  }
  ::freeaddrinfo(res);
  if (listen_fd_ < 0) {
    throw std::runtime_error("mtconnect: cannot listen on " + bind + ":" + port_s + " (" + err +
                             ")");
  }
}

ShdrServer::~ShdrServer() {
  for (auto& c : clients_) ::close(c.fd);
  if (listen_fd_ >= 0) ::close(listen_fd_);
}

void ShdrServer::add_poll_fds(std::vector<pollfd>& fds) const {
  fds.push_back(pollfd{listen_fd_, POLLIN, 0});
  for (const auto& c : clients_) {
    fds.push_back(pollfd{c.fd, static_cast<short>(POLLIN | (c.out.empty() ? 0 : POLLOUT)), 0});
  }
}

void ShdrServer::handle(const std::vector<pollfd>& fds,
                        const std::function<std::vector<std::string>()>& snapshot) {
  std::vector<int> drop;
  for (const auto& p : fds) {
    if (p.revents == 0) continue;
    if (p.fd == listen_fd_) continue;
    for (auto& c : clients_) {
      if (c.fd != p.fd) continue;
      bool ok = true;
      if ((p.revents & (POLLIN | POLLHUP | POLLERR)) != 0) ok = read(c);
      if (ok && (p.revents & POLLOUT) != 0) ok = flush(c);
      if (!ok) drop.push_back(c.fd);
    }
  }
  for (int fd : drop) {
    for (auto it = clients_.begin(); it != clients_.end(); ++it) {
      if (it->fd == fd) {
        ::close(fd);
        clients_.erase(it);
        break;
      }
    }
  }
  for (const auto& p : fds) {
    if (p.fd == listen_fd_ && (p.revents & POLLIN) != 0) accept_clients(snapshot);
  }
  stats_.clients = clients_.size();
}

void ShdrServer::accept_clients(const std::function<std::vector<std::string>()>& snapshot) {
  for (;;) {
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;  // EAGAIN or a transient error: poll again
    if (clients_.size() >= max_clients_) {
      ++stats_.refused;
      ::close(fd);
      continue;
    }
    const int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    ++stats_.accepted;
    Client c{fd, {}, {}};
    for (const auto& l : header_) c.out += l + "\n";
    for (const auto& l : snapshot()) c.out += l + "\n";
    clients_.push_back(std::move(c));
    if (!flush(clients_.back())) {
      ::close(fd);
      clients_.pop_back();
    }
  }
}

bool ShdrServer::flush(Client& c) {
  while (!c.out.empty()) {
    const ssize_t n = ::send(c.fd, c.out.data(), c.out.size(), MSG_NOSIGNAL);
    if (n > 0) {
      c.out.erase(0, static_cast<std::size_t>(n));
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
    return false;
  }
  if (c.out.size() > kMaxBacklogBytes) {
    ++stats_.dropped;
    return false;
  }
  return true;
}

bool ShdrServer::read(Client& c) {
  char buf[1024];
  for (;;) {
    const ssize_t n = ::recv(c.fd, buf, sizeof buf, 0);
    if (n > 0) {
      c.in.append(buf, static_cast<std::size_t>(n));
      continue;
    }
    if (n == 0) return false;
    if (errno == EINTR) continue;
    if (errno == EAGAIN || errno == EWOULDBLOCK) break;
    return false;
  }
  std::size_t nl;
  while ((nl = c.in.find('\n')) != std::string::npos) {
    std::string line = c.in.substr(0, nl);
    c.in.erase(0, nl + 1);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.rfind("* PING", 0) == 0) {
      ++stats_.pings;
      c.out += "* PONG " + std::to_string(heartbeat_ms_) + "\n";
    }
    // Anything else from an agent is ignored (the adapter protocol has no other requests).
  }
  if (c.in.size() > kMaxInputLine) return false;  // not an agent
  return flush(c);
}

void ShdrServer::broadcast(const std::vector<std::string>& lines) {
  if (lines.empty() || clients_.empty()) return;
  std::string text;
  for (const auto& l : lines) text += l + "\n";
  std::vector<int> drop;
  for (auto& c : clients_) {
    c.out += text;
    if (!flush(c)) drop.push_back(c.fd);
  }
  for (int fd : drop) {
    for (auto it = clients_.begin(); it != clients_.end(); ++it) {
      if (it->fd == fd) {
        ::close(fd);
        clients_.erase(it);
        break;
      }
    }
  }
  stats_.clients = clients_.size();
}

}  // namespace contour::bridge
