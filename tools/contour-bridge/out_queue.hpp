#pragma once
// The bridge's outgoing MQTT queue: bounded (mqtt.queue_size messages), FIFO, with the drop
// policy of README "Broker gone":
//   - a `state` or `bridge` message replaces the queued one of its topic (latest value wins:
//     both are retained snapshots), so they never take more than one slot each;
//   - when the queue is full, the OLDEST POSITION sample goes first; a new position sample is
//     dropped when no older one is left to drop;
//   - events and job summaries are kept; only when the queue holds nothing else are they dropped,
//     oldest first, and counted (`dropped_events`): an outage that outlasts queue_size events.
// Single-threaded (the bridge's event loop); no locking.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <string>

namespace contour::bridge {

enum class MsgClass { kPosition, kState, kEvent, kJob, kMeta };

struct OutMessage {
  std::string topic;
  std::string payload;
  int qos = 0;
  bool retain = false;
  MsgClass cls = MsgClass::kEvent;
};

struct QueueCounters {
  std::uint64_t enqueued = 0;
  std::uint64_t coalesced = 0;          // state/bridge snapshots replaced by a newer one
  std::uint64_t dropped_positions = 0;  // position samples dropped (queue full)
  std::uint64_t dropped_events = 0;     // events and job summaries dropped (queue full of them)
  std::size_t high_water = 0;           // largest depth seen
};

class OutQueue {
 public:
  explicit OutQueue(std::size_t capacity);

  void push(OutMessage m);
  [[nodiscard]] bool empty() const { return q_.empty(); }
  [[nodiscard]] std::size_t size() const { return q_.size(); }
  [[nodiscard]] std::size_t capacity() const { return cap_; }
  [[nodiscard]] const OutMessage& front() const { return q_.front(); }
  void pop_front() { q_.pop_front(); }
  [[nodiscard]] bool contains_topic(const std::string& topic) const;
  [[nodiscard]] const QueueCounters& counters() const { return c_; }
  [[nodiscard]] std::size_t count(MsgClass cls) const;

 private:
  bool drop_oldest(MsgClass cls);

  std::size_t cap_;
  std::deque<OutMessage> q_;
  QueueCounters c_;
};

}  // namespace contour::bridge
