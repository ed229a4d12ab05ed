#pragma once
// contour-bridge's connection to contourd: its Unix command socket, JSON lines (daemon/
// PROTOCOL.md), non-blocking and driven by the bridge's poll loop. Requests carry an "id" the
// daemon echoes; each reply goes to the callback given with its request, in order. Lines with
// "event" are the subscription traffic (`subscribe` topic events) and go to the event callback.
//
// The bridge never talks to contourd any other way: nothing here reaches the RT loop; the daemon
// serves these requests on its socket thread like any contourctl.
#include <sys/types.h>

#include <cstdint>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

namespace contour::bridge {

class DaemonLink {
 public:
  // ok: the reply's "result" (ok == true) or its "error" text as a JSON string (ok == false;
  // also when the connection is lost before the reply).
  using Reply = std::function<void(bool ok, const nlohmann::json& result)>;
  using EventFn = std::function<void(const nlohmann::json& line)>;
  using LostFn = std::function<void(const std::string& why)>;

  DaemonLink(std::string path, EventFn on_event, LostFn on_lost);
  ~DaemonLink();
  DaemonLink(const DaemonLink&) = delete;
  DaemonLink& operator=(const DaemonLink&) = delete;

  // One connect attempt; false with `error()` naming the socket and the reason.
  bool connect();
  [[nodiscard]] bool connected() const { return fd_ >= 0; }
  [[nodiscard]] int fd() const { return fd_; }
  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] const std::string& path() const { return path_; }

  // Queues a request (its "id" is set here). Not connected: the callback runs at once with
  // ok == false.
  void call(nlohmann::json req, Reply cb);
  [[nodiscard]] std::size_t pending() const { return pending_.size(); }

  // poll(2) interest and the handler for its result.
  [[nodiscard]] short poll_events() const;
  void handle(short revents);

  void close(const std::string& why);

 private:
  void flush();
  void read_lines();

  std::string path_;
  EventFn on_event_;
  LostFn on_lost_;
  int fd_ = -1;
  std::string error_;
  std::string in_, out_;
  std::uint64_t next_id_ = 1;
  std::map<std::uint64_t, Reply> pending_;
};

}  // namespace contour::bridge
