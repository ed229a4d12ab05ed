#include "daemon/command_server.hpp"
#include "daemon/command_table.hpp"

#include <fcntl.h>
#include <grp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
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

CommandServer::CommandServer(CommandServerOptions opt, Handler handler, NoticeHandler on_notice)
    : opt_(std::move(opt)), handler_(std::move(handler)), on_notice_(std::move(on_notice)) {
  notice_tokens_ = std::max(1.0, opt_.max_notices_per_s);
}

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
  if (::chmod(opt_.path.c_str(), opt_.mode) != 0 || ::listen(listen_fd_, 64) != 0) {
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

const char* to_string(ServerNotice::Kind k) noexcept {
  switch (k) {
    case ServerNotice::Kind::kDroppedIdle: return "dropped_idle";
    case ServerNotice::Kind::kEvicted: return "evicted_idle";
    case ServerNotice::Kind::kRateLimited: return "rate_limited";
    case ServerNotice::Kind::kDroppedBuffer: return "oversize_buffer";
  }
  return "?";
}

std::string CommandServer::describe(const ClientInfo& c) {
  return "client " + std::to_string(c.id) + " (pid " + std::to_string(c.pid) + ", uid " +
         std::to_string(c.uid) + ", fd " + std::to_string(c.fd) + ")";
}

namespace {
std::string seconds_text(double s) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f s", s);
  return b;
}
double seconds_between(std::chrono::steady_clock::time_point a,
                       std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}
}  // namespace

void CommandServer::run() {
  std::vector<pollfd> fds;
  std::vector<std::uint64_t> ids;
  std::vector<char> backlogged;  // client had unprocessed complete lines: served without POLLIN
  const auto idle = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(opt_.idle_timeout_s));
  while (running_) {
    fds.clear();
    ids.clear();
    backlogged.clear();
    fds.push_back({listen_fd_, POLLIN, 0});
    fds.push_back({wake_pipe_[0], POLLIN, 0});
    const Clock::time_point round_start = Clock::now();
    Clock::time_point next_deadline = round_start + std::chrono::milliseconds(500);
    bool any_backlogged = false;
    {
      std::lock_guard lk(mu_);
      for (auto& [id, c] : clients_) {
        // Stop reading a client while it has complete lines waiting (kernel backpressure keeps
        // its input bounded); those lines are served below without waiting for poll.
        if (!c.streams.empty()) pump_streams(c);  // output drained by a reply's flush
        const bool waiting = c.eof || has_complete_line(c);
        short ev = waiting ? 0 : POLLIN;
        if (!c.out.empty()) ev = static_cast<short>(ev | POLLOUT);
        fds.push_back({c.fd, ev, 0});
        ids.push_back(id);
        backlogged.push_back(waiting ? 1 : 0);
        any_backlogged = any_backlogged || waiting;
        c.fresh = false;
        if (c.topics.empty()) next_deadline = std::min(next_deadline, c.last_request + idle);
      }
    }
    int timeout_ms = 0;
    if (!any_backlogged) {
      const auto wait = std::chrono::ceil<std::chrono::milliseconds>(next_deadline - round_start);
      timeout_ms = static_cast<int>(std::clamp<std::int64_t>(wait.count(), 0, 500));
    }
    const int n = ::poll(fds.data(), fds.size(), timeout_ms);
    if (n < 0 && errno != EINTR) break;
    if (fds[1].revents & POLLIN) {
      char buf[64];
      while (::read(wake_pipe_[0], buf, sizeof(buf)) > 0) {
      }
    }
    for (std::size_t i = 0; i < ids.size(); ++i) {
      const pollfd& p = fds[i + 2];
      if (p.revents == 0 && backlogged[i] == 0) continue;
      std::unique_lock lk(mu_);
      auto it = clients_.find(ids[i]);
      if (it == clients_.end()) continue;
      Client& c = it->second;
      bool keep = true;
      lk.unlock();  // the handler runs without the lock held (it may subscribe()/publish())
      if ((p.events & POLLIN) && (p.revents & (POLLIN | POLLHUP | POLLERR))) {
        if (read_client(c) == ReadResult::kClosed) c.eof = true;
      }
      keep = process_input(c);
      lk.lock();
      if (keep && (p.revents & POLLOUT)) {
        keep = flush_client(c);
        if (keep && !c.streams.empty()) {
          pump_streams(c);  // the client read: refill its output from its sample queue
          keep = flush_client(c);
        }
      }
      if (!keep && !c.overflow) close_client(it);
    }
    drop_idle_clients(Clock::now());
    if (fds[0].revents & POLLIN) accept_clients();
    {
      // Clients over the output limit (from a reply above or from publish() on another thread).
      std::lock_guard lk(mu_);
      for (auto it = clients_.begin(); it != clients_.end();) {
        if (!it->second.overflow) {
          ++it;
          continue;
        }
        ++stats_.oversize_buffer;
        ++stats_.dropped_clients;
        notice(ServerNotice::Kind::kDroppedBuffer, it->second.info,
               "socket: dropped " + describe(it->second.info) + ": more than " +
                   std::to_string(opt_.max_backlog_bytes) +
                   " bytes of replies/events unread (socket.max_buffered_bytes)");
        it = close_client(it);
      }
    }
    emit_notices();
  }
}

bool CommandServer::has_complete_line(const Client& c) const {
  return c.in.find('\n') != std::string::npos;
}

// Serves what a client has already sent (several rounds' worth, bounded) before it is closed by
// the server: a queued estop in an evicted or idle-dropped client still runs.
bool CommandServer::serve_pending(Client& c) {
  for (int round = 0; round < 64; ++round) {
    ReadResult r = ReadResult::kDrained;
    if (!c.eof && !has_complete_line(c)) {
      r = read_client(c);
      if (r == ReadResult::kClosed) c.eof = true;
    }
    if (!process_input(c)) return false;
    if (r == ReadResult::kDrained && !has_complete_line(c)) return true;
  }
  return true;
}

void CommandServer::drop_idle_clients(Clock::time_point now) {
  const auto idle = std::chrono::duration<double>(opt_.idle_timeout_s);
  std::vector<std::uint64_t> ids;
  {
    std::lock_guard lk(mu_);
    for (const auto& [id, c] : clients_) {
      if (c.topics.empty() && !c.fresh && now - c.last_request > idle) ids.push_back(id);
    }
  }
  for (const std::uint64_t id : ids) {
    std::unique_lock lk(mu_);
    auto it = clients_.find(id);
    if (it == clients_.end()) continue;
    lk.unlock();
    const bool alive = serve_pending(it->second);
    lk.lock();
    Client& c = it->second;
    if (alive && !c.overflow && now - c.last_request <= idle) continue;  // it just sent one
    if (c.overflow) continue;  // counted as oversize_buffer by the sweep
    if (alive) {
      ++stats_.dropped_idle;
      ++stats_.dropped_clients;
      notice(ServerNotice::Kind::kDroppedIdle, c.info,
             "socket: dropped " + describe(c.info) + ": no complete request for " +
                 seconds_text(seconds_between(c.last_request, Clock::now())) +
                 (c.in.empty()
                      ? std::string()
                      : " (" + std::to_string(c.in.size()) + " bytes of an unfinished line)") +
                 " (socket.idle_timeout_s " + seconds_text(opt_.idle_timeout_s) + ")");
    }
    close_client(it);
  }
}

void CommandServer::accept_clients() {
  for (;;) {
    std::unique_lock lk(mu_);
    bool full = clients_.size() >= opt_.max_clients;
    if (full) {
      // A burst of short-lived clients can fill the table with peers that have already hung up
      // but whose hang-up this thread has not polled yet; reap those before evicting anyone.
      lk.unlock();
      reap_hung_up_clients();
      lk.lock();
      full = clients_.size() >= opt_.max_clients;
    }
    if (full && !has_eviction_candidate()) {
      // Nobody can give way in this round (see evict_longest_idle): the connection waits in the
      // listen backlog for the next round, which follows at once (never refused).
      return;
    }
    lk.unlock();
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) return;
    Client c;
    c.fd = fd;
    c.info.fd = fd;
    ucred cred{};
    socklen_t len = sizeof(cred);
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0) {
      c.info.uid = cred.uid;
      c.info.pid = cred.pid;
    }
    c.connected_at = Clock::now();
    c.last_request = c.connected_at;
    c.tokens = std::max(1.0, opt_.max_requests_per_s);
    c.refill_at = c.connected_at;
    lk.lock();
    c.info.id = next_id_++;
    lk.unlock();
    if (full && !evict_longest_idle(c.info)) {
      // Only if the candidate vanished meanwhile (it cannot: this thread alone erases).
      ::close(fd);
      return;
    }
    lk.lock();
    ++stats_.connections;
    clients_.emplace(c.info.id, std::move(c));
  }
}

// Called with mu_ held.
bool CommandServer::has_eviction_candidate() const {
  bool any_fresh = false;
  for (const auto& [id, c] : clients_) any_fresh = any_fresh || c.fresh;
  for (const auto& [id, c] : clients_) {
    if (!c.fresh && !(any_fresh && (c.requested || !c.topics.empty()))) return true;
  }
  return false;
}

bool CommandServer::evict_longest_idle(const ClientInfo& for_whom) {
  std::unique_lock lk(mu_);
  // Silent clients (never a complete request) before those that made requests, non-subscribers
  // before subscribers, then the oldest last request (connect time for silent ones). While
  // clients accepted in this round are still unpolled (all silent so far), only a silent client
  // gives way: a burst of connections must not sweep out the established clients in one round.
  bool any_fresh = false;
  for (const auto& [id, c] : clients_) any_fresh = any_fresh || c.fresh;
  auto rank = [](const Client& c) { return (c.topics.empty() ? 0 : 2) + (c.requested ? 1 : 0); };
  auto victim = clients_.end();
  for (auto it = clients_.begin(); it != clients_.end(); ++it) {
    const Client& c = it->second;
    if (c.fresh || (any_fresh && (c.requested || !c.topics.empty()))) continue;
    if (victim == clients_.end()) {
      victim = it;
      continue;
    }
    const Client& v = victim->second;
    if (rank(c) != rank(v) ? rank(c) < rank(v) : c.last_request < v.last_request) victim = it;
  }
  if (victim == clients_.end()) return false;
  lk.unlock();
  serve_pending(victim->second);
  lk.lock();
  Client& v = victim->second;
  if (v.overflow) return true;  // the sweep closes and counts it
  ++stats_.evicted_idle;
  ++stats_.dropped_clients;
  const std::string unfinished =
      v.in.empty() ? std::string()
                   : " with " + std::to_string(v.in.size()) + " bytes of an unfinished line";
  notice(ServerNotice::Kind::kEvicted, v.info,
         "socket: table full (" + std::to_string(opt_.max_clients) +
             " clients, socket.max_clients): evicted " + describe(v.info) + ", " +
             (v.requested ? "idle " : "silent since connecting ") +
             seconds_text(seconds_between(v.last_request, Clock::now())) + " ago" + unfinished +
             (v.topics.empty() ? std::string() : " (subscriber)") + ", to admit " +
             describe(for_whom));
  close_client(victim);
  return true;
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
    const bool keep = serve_pending(it->second);  // answers what it sent, then sees the EOF
    lk.lock();
    if (!keep && !it->second.overflow) close_client(it);
  }
}

CommandServer::ReadResult CommandServer::read_client(Client& c) {
  char buf[4096];
  std::size_t got = 0;
  while (got < kReadBudgetBytes) {
    const ssize_t n = ::read(c.fd, buf, sizeof(buf));
    if (n == 0) return ReadResult::kClosed;
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) return ReadResult::kDrained;
      if (errno == EINTR) continue;
      return ReadResult::kClosed;
    }
    c.in.append(buf, static_cast<std::size_t>(n));
    got += static_cast<std::size_t>(n);
  }
  return ReadResult::kMore;
}

bool CommandServer::process_input(Client& c) {
  int handled = 0;
  std::size_t pos = 0;  // consumed prefix of c.in
  while (handled < kLinesPerRound && !c.overflow) {
    const std::size_t nl = c.in.find('\n', pos);
    if (c.discarding) {
      if (nl == std::string::npos) {
        pos = c.in.size();
        break;
      }
      c.discarding = false;
      pos = nl + 1;
      continue;
    }
    const std::size_t len = (nl == std::string::npos ? c.in.size() : nl) - pos;
    if (len > opt_.max_line_bytes) {
      {
        std::lock_guard lk(mu_);
        ++stats_.errors;
      }
      queue(c, error_reply("request line longer than " + std::to_string(opt_.max_line_bytes) +
                           " bytes; discarded"));
      ++handled;
      if (nl == std::string::npos) {
        c.discarding = true;
        pos = c.in.size();
        break;
      }
      pos = nl + 1;
      continue;
    }
    if (nl == std::string::npos) break;
    std::string line = c.in.substr(pos, len);
    pos = nl + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    handle_line(c, line);
    ++handled;
  }
  c.in.erase(0, pos);
  if (c.overflow) return false;
  // After EOF: the complete lines it sent are served (over several rounds), a partial one is not.
  return !(c.eof && !has_complete_line(c));
}

void CommandServer::handle_line(Client& c, const std::string& line) {
  const Clock::time_point now = Clock::now();
  c.last_request = now;
  c.requested = true;
  const double rate = opt_.max_requests_per_s;
  const double burst = std::max(1.0, rate);
  c.tokens = std::min(burst, c.tokens + rate * seconds_between(c.refill_at, now));
  c.refill_at = now;
  const bool limited = c.tokens < 1.0;
  if (!limited) {
    c.tokens -= 1.0;
    c.rate_noticed = false;
  }
  {
    std::lock_guard lk(mu_);
    ++stats_.requests;
  }
  bool refused = false;
  // The handler runs without mu_ held (it may call subscribe()/publish(), which take it).
  RequestOutcome r = handle_request_line(line, [&](const nlohmann::json& req) {
    if (limited && !is_safety_command(req.at("cmd").get<std::string>())) {
      refused = true;
      throw CommandError("rate limited: more than " + std::to_string(static_cast<long>(rate)) +
                         " requests/s from this client (socket.max_requests_per_s); request "
                         "refused (estop, hold and stop are never refused)");
    }
    return handler_(req, c.info);
  });
  {
    std::lock_guard lk(mu_);
    if (r.error) ++stats_.errors;
    if (refused) ++stats_.rate_limited;
  }
  if (refused && !c.rate_noticed) {
    c.rate_noticed = true;  // one notice per burst over the rate
    notice(ServerNotice::Kind::kRateLimited, c.info,
           "socket: rate limited " + describe(c.info) + ": more than " +
               std::to_string(static_cast<long>(rate)) +
               " requests/s (socket.max_requests_per_s); refusing its requests except estop, hold "
               "and stop");
  }
  queue(c, r.reply);
}

void CommandServer::queue(Client& c, const nlohmann::json& j) {
  std::string s = to_line(j);
  std::lock_guard lk(mu_);
  c.out += s;
  flush_client(c);
}

// Called with mu_ held. False only when the peer is gone; a backlog over the limit sets
// `overflow` (the run loop's sweep closes and counts the client).
bool CommandServer::flush_client(Client& c) {
  while (!c.out.empty()) {
    const ssize_t n = ::send(c.fd, c.out.data(), c.out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) break;
      if (errno == EINTR) continue;
      return false;
    }
    c.out.erase(0, static_cast<std::size_t>(n));
  }
  if (c.out.size() > opt_.max_backlog_bytes) c.overflow = true;
  return true;
}

// Server thread only (pending_notices_ and the notice bucket are not shared).
void CommandServer::notice(ServerNotice::Kind k, const ClientInfo& who, std::string text) {
  const Clock::time_point now = Clock::now();
  const double rate = opt_.max_notices_per_s;
  notice_tokens_ = std::min(std::max(1.0, rate),
                            notice_tokens_ + rate * seconds_between(notice_refill_at_, now));
  notice_refill_at_ = now;
  if (notice_tokens_ < 1.0) {
    ++notices_suppressed_since_;
    notices_suppressed_.fetch_add(1, std::memory_order_relaxed);  // callers may hold mu_
    return;
  }
  notice_tokens_ -= 1.0;
  if (notices_suppressed_since_ > 0) {
    text += " (" + std::to_string(notices_suppressed_since_) +
            " earlier notices suppressed; see status.counters.socket)";
    notices_suppressed_since_ = 0;
  }
  pending_notices_.push_back({k, who, std::move(text)});
}

std::map<std::uint64_t, CommandServer::Client>::iterator CommandServer::close_client(
    std::map<std::uint64_t, Client>::iterator it) {
  ::close(it->second.fd);
  pending_disconnects_.push_back(it->second.info);
  return clients_.erase(it);
}

void CommandServer::emit_notices() {
  std::vector<ClientInfo> gone;
  {
    std::lock_guard lk(mu_);
    gone.swap(pending_disconnects_);
  }
  if (on_disconnect_) {
    for (const auto& c : gone) on_disconnect_(c);
  }
  if (pending_notices_.empty()) return;
  std::vector<ServerNotice> v;
  v.swap(pending_notices_);
  if (!on_notice_) return;
  for (const auto& n : v) on_notice_(n);
}

void CommandServer::subscribe(std::uint64_t client, const std::string& topic) {
  subscribe(client, topic, StreamOptions{});
}

void CommandServer::subscribe(std::uint64_t client, const std::string& topic, StreamOptions opt) {
  std::lock_guard lk(mu_);
  auto it = clients_.find(client);
  if (it == clients_.end()) return;
  Client& c = it->second;
  opt.decimation = std::max<std::uint32_t>(1, opt.decimation);
  c.stream_opts[topic] = opt;
  for (auto& q : c.streams) {
    if (q.topic == topic) q.opt = opt;  // re-subscribe: new decimation from the next chunk on
  }
  for (const auto& t : c.topics) {
    if (t == topic) return;
  }
  c.topics.push_back(topic);
}

void CommandServer::unsubscribe(std::uint64_t client, const std::string& topic) {
  std::lock_guard lk(mu_);
  auto it = clients_.find(client);
  if (it == clients_.end()) return;
  Client& c = it->second;
  std::erase(c.topics, topic);
  c.stream_opts.erase(topic);
  std::erase_if(c.streams, [&](const StreamQueue& q) { return q.topic == topic; });
}

// mu_ held.
void CommandServer::enqueue_stream(Client& c, const std::string& topic,
                                   const std::shared_ptr<const StreamChunk>& chunk) {
  StreamQueue* q = nullptr;
  for (auto& s : c.streams) {
    if (s.topic == topic) q = &s;
  }
  if (q == nullptr) {
    StreamQueue nq;
    nq.topic = topic;
    if (auto o = c.stream_opts.find(topic); o != c.stream_opts.end()) nq.opt = o->second;
    c.streams.push_back(std::move(nq));
    q = &c.streams.back();
  }
  q->source_dropped = chunk->source_dropped;
  const std::uint64_t dec = q->opt.decimation;
  for (std::size_t i = 0; i < chunk->items.size(); ++i) {
    if (chunk->items[i].seq % dec != 0) continue;
    q->refs.push_back({chunk, static_cast<std::uint32_t>(i)});
  }
  const std::size_t cap = std::max<std::size_t>(1, opt_.max_stream_samples);
  if (q->refs.size() > cap) {
    const std::size_t over = q->refs.size() - cap;
    q->refs.erase(q->refs.begin(), q->refs.begin() + static_cast<std::ptrdiff_t>(over));
    q->dropped += over;
    stats_.stream_dropped += over;
  }
}

// mu_ held. One batch line per pass, while the client's unsent output is below the low-water mark.
void CommandServer::pump_streams(Client& c) {
  const std::size_t max_batch = std::max<std::size_t>(1, opt_.max_batch_samples);
  for (auto& q : c.streams) {
    while (!q.refs.empty() && c.out.size() < kStreamLowWaterBytes) {
      const std::size_t n = std::min(max_batch, q.refs.size());
      std::string line;
      line.reserve(160 + n * (q.refs.front().chunk->items[q.refs.front().index].json.size() + 1));
      line += "{\"event\":";
      line += nlohmann::json(q.topic).dump();
      line += ",\"count\":" + std::to_string(n);
      line += ",\"decimation\":" + std::to_string(q.opt.decimation);
      line += ",\"dropped\":" + std::to_string(q.dropped);
      line += ",\"source_dropped\":" + std::to_string(q.source_dropped);
      line += ",\"samples\":[";
      for (std::size_t i = 0; i < n; ++i) {
        if (i != 0) line += ',';
        const StreamRef& r = q.refs[i];
        line += r.chunk->items[r.index].json;
      }
      line += "]}\n";
      q.refs.erase(q.refs.begin(), q.refs.begin() + static_cast<std::ptrdiff_t>(n));
      stats_.stream_samples_sent += n;
      c.out += line;
    }
  }
}

void CommandServer::publish_stream(const std::string& topic,
                                   std::shared_ptr<const StreamChunk> chunk) {
  if (!chunk) return;
  bool any = false;
  {
    std::lock_guard lk(mu_);
    stream_topics_.insert(topic);
    if (chunk->items.empty()) return;
    for (auto& [id, c] : clients_) {
      if (c.overflow) continue;
      if (std::find(c.topics.begin(), c.topics.end(), topic) == c.topics.end()) continue;
      enqueue_stream(c, topic, chunk);
      pump_streams(c);  // written by the server thread (POLLOUT), never here
      any = true;
    }
  }
  if (any) {
    const char b = 's';
    [[maybe_unused]] auto n = ::write(wake_pipe_[1], &b, 1);
  }
}

std::uint64_t CommandServer::stream_dropped(std::uint64_t client, const std::string& topic) const {
  std::lock_guard lk(mu_);
  auto it = clients_.find(client);
  if (it == clients_.end()) return 0;
  for (const auto& q : it->second.streams) {
    if (q.topic == topic) return q.dropped;
  }
  return 0;
}

void CommandServer::publish(const std::string& topic, const nlohmann::json& event) {
  bool stream_topic = false;
  {
    std::lock_guard lk(mu_);
    stream_topic = stream_topics_.count(topic) != 0;
  }
  if (stream_topic) {
    // One format per topic: a single event on a stream topic is a one-sample chunk.
    auto chunk = std::make_shared<StreamChunk>();
    nlohmann::json sample = event;
    if (sample.is_object()) sample.erase("event");
    std::uint64_t seq = 0;
    if (auto c = event.find("cycle"); event.is_object() && c != event.end() && c->is_number_unsigned()) {
      seq = c->get<std::uint64_t>();
    }
    std::string text = to_line(sample);
    text.pop_back();  // the newline
    chunk->items.push_back({seq, std::move(text)});
    publish_stream(topic, std::move(chunk));
    return;
  }
  const std::string s = to_line(event);
  bool any = false;
  {
    std::lock_guard lk(mu_);
    for (auto& [id, c] : clients_) {
      if (c.overflow) continue;
      for (const auto& t : c.topics) {
        if (t == topic) {
          c.out += s;
          // A subscriber that does not read is dropped by the server thread's sweep (POLLOUT
          // never fires for it, so the check cannot wait for a flush).
          if (c.out.size() > opt_.max_backlog_bytes) c.overflow = true;
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
  s.notices_suppressed = notices_suppressed_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace contour::daemon
