#include "tools/contour-web/daemon_link.hpp"

#include <istream>

namespace contour::web {

using nlohmann::json;

DaemonConnection::DaemonConnection(asio::io_context& io, std::string path, std::string name)
    : io_(io), path_(std::move(path)), name_(std::move(name)), sock_(io) {}

void DaemonConnection::request(json req, Reply cb) {
  const std::uint64_t id = next_id_++;
  req["id"] = id;
  pending_.emplace(id, std::move(cb));
  out_.push_back(req.dump(-1, ' ', false, json::error_handler_t::replace) + "\n");
  if (state_ == State::kIdle) connect();
  else if (state_ == State::kUp) write();
}

void DaemonConnection::connect() {
  state_ = State::kConnecting;
  const std::uint64_t gen = ++generation_;
  sock_ = asio::local::stream_protocol::socket(io_);
  sock_.async_connect(asio::local::stream_protocol::endpoint(path_),
                      [self = shared_from_this(), gen](const boost::system::error_code& ec) {
                        if (gen != self->generation_) return;
                        if (ec) {
                          self->fail("cannot connect to contourd at " + self->path_ + ": " + ec.message());
                          return;
                        }
                        self->state_ = State::kUp;
                        if (self->on_state) self->on_state(true, "");
                        self->read();
                        self->write();
                      });
}

void DaemonConnection::read() {
  const std::uint64_t gen = generation_;
  asio::async_read_until(sock_, in_, '\n',
                         [self = shared_from_this(), gen](const boost::system::error_code& ec, std::size_t n) {
                           if (gen != self->generation_) return;
                           if (ec) {
                             self->fail(ec == asio::error::not_found
                                            ? "line from contourd longer than 64 MiB"
                                            : "contourd closed the connection (" + ec.message() + ")");
                             return;
                           }
                           std::string line(asio::buffers_begin(self->in_.data()),
                                            asio::buffers_begin(self->in_.data()) +
                                                static_cast<std::ptrdiff_t>(n - 1));
                           self->in_.consume(n);
                           json j = json::parse(line, nullptr, false);
                           if (!j.is_discarded() && j.is_object()) {
                             auto id = j.find("id");
                             if (id != j.end() && id->is_number_unsigned() && !j.contains("event")) {
                               auto it = self->pending_.find(id->get<std::uint64_t>());
                               if (it != self->pending_.end()) {
                                 Reply cb = std::move(it->second);
                                 self->pending_.erase(it);
                                 cb(j);
                               }
                             } else if (self->on_line) {
                               self->on_line(j);
                             }
                           }
                           if (gen == self->generation_) self->read();
                         });
}

void DaemonConnection::write() {
  if (writing_ || out_.empty() || state_ != State::kUp) return;
  writing_ = true;
  const std::uint64_t gen = generation_;
  asio::async_write(sock_, asio::buffer(out_.front()),
                    [self = shared_from_this(), gen](const boost::system::error_code& ec, std::size_t) {
                      if (gen != self->generation_) return;
                      self->writing_ = false;
                      if (ec) {
                        self->fail("write to contourd failed: " + ec.message());
                        return;
                      }
                      self->out_.pop_front();
                      self->write();
                    });
}

void DaemonConnection::fail(const std::string& why) {
  ++generation_;
  boost::system::error_code ignored;
  sock_.close(ignored);
  const bool was_up = state_ == State::kUp;
  state_ = State::kIdle;
  writing_ = false;
  out_.clear();
  in_.consume(in_.size());
  auto pending = std::move(pending_);
  pending_.clear();
  for (auto& [id, cb] : pending) {
    cb(json{{"ok", false}, {"unreachable", true}, {"error", "contourd unreachable: " + why}});
  }
  if (on_state && (was_up || !pending.empty() || true)) on_state(false, why);
}

void DaemonConnection::close(const std::string& why) {
  if (state_ == State::kIdle) return;
  fail(why);
}

DaemonLink::DaemonLink(asio::io_context& io, std::string socket_path)
    : io_(io), path_(std::move(socket_path)), retry_(io), keepalive_(io) {
  poll_ = std::make_shared<DaemonConnection>(io_, path_, "poll");
  command_ = std::make_shared<DaemonConnection>(io_, path_, "command");
  safety_ = std::make_shared<DaemonConnection>(io_, path_, "safety");
}

void DaemonLink::start(std::function<void(const json&)> on_line,
                       std::function<void(bool, const std::string&)> on_state) {
  on_line_ = std::move(on_line);
  on_state_ = std::move(on_state);
  open_stream();
  keepalive();
}

void DaemonLink::open_stream() {
  stream_ = std::make_shared<DaemonConnection>(io_, path_, "stream");
  stream_->on_line = [this](const json& j) {
    if (on_line_) on_line_(j);
  };
  stream_->on_state = [this](bool up, const std::string& why) {
    if (up == was_up_) {
      if (!up) {
        retry_.expires_after(std::chrono::seconds(1));
        retry_.async_wait([this](const boost::system::error_code& ec) {
          if (!ec) open_stream();
        });
      }
      return;
    }
    was_up_ = up;
    if (on_state_) on_state_(up, why);
    if (!up) {
      retry_.expires_after(std::chrono::seconds(1));
      retry_.async_wait([this](const boost::system::error_code& ec) {
        if (!ec) open_stream();
      });
    }
  };
  auto log_refusal = [this](const json& rep) {
    if (!rep.value("ok", false) && !rep.value("unreachable", false) && on_line_) {
      on_line_(json{{"event", "web"}, {"text", "subscribe refused by contourd: " + rep.value("error", std::string())}});
    }
  };
  stream_->request({{"cmd", "subscribe"}, {"topic", "events"}}, log_refusal);
  stream_->request({{"cmd", "subscribe"}, {"topic", "telemetry"}}, log_refusal);
}

// contourd drops a connection without a request for socket.idle_timeout_s (60 s by default):
// the command and safety connections ask for the status now and then so that an E-stop never
// waits for a reconnect.
void DaemonLink::keepalive() {
  keepalive_.expires_after(std::chrono::seconds(20));
  keepalive_.async_wait([this](const boost::system::error_code& ec) {
    if (ec) return;
    for (auto* c : {&command_, &safety_}) {
      if ((*c)->up()) (*c)->request({{"cmd", "status"}}, [](const json&) {});
    }
    keepalive();
  });
}

void DaemonLink::request(Channel ch, json req, Reply cb) {
  switch (ch) {
    case Channel::kSafety: safety_->request(std::move(req), std::move(cb)); return;
    case Channel::kPoll: poll_->request(std::move(req), std::move(cb)); return;
    case Channel::kCommand: command_->request(std::move(req), std::move(cb)); return;
  }
}

void DaemonLink::client_request(ClientId client, json req, Reply cb) {
  auto& c = clients_[client];
  if (!c) c = std::make_shared<DaemonConnection>(io_, path_, "client " + std::to_string(client));
  c->request(std::move(req), std::move(cb));
}

void DaemonLink::close_client(ClientId client) {
  auto it = clients_.find(client);
  if (it == clients_.end()) return;
  it->second->close("browser client gone");
  clients_.erase(it);
}

}  // namespace contour::web
