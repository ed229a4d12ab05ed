#include "tools/contour-bridge/out_queue.hpp"

#include <algorithm>

namespace contour::bridge {

OutQueue::OutQueue(std::size_t capacity) : cap_(std::max<std::size_t>(capacity, 1)) {}

bool OutQueue::drop_oldest(MsgClass cls) {
  const auto it =
      std::find_if(q_.begin(), q_.end(), [cls](const OutMessage& m) { return m.cls == cls; });
  if (it == q_.end()) return false;
  q_.erase(it);
  return true;
}

void OutQueue::push(OutMessage m) {
  ++c_.enqueued;
  if (m.cls == MsgClass::kState || m.cls == MsgClass::kMeta) {
    // Latest value wins: the older snapshot of this topic leaves its slot, the new one goes to
    // the back (after the events that led to it).
    const auto it = std::find_if(q_.begin(), q_.end(), [&](const OutMessage& o) {
      return o.cls == m.cls && o.topic == m.topic;
    });
    if (it != q_.end()) {
      q_.erase(it);
      ++c_.coalesced;
    }
  }
  if (q_.size() >= cap_) {
    if (drop_oldest(MsgClass::kPosition)) {
      ++c_.dropped_positions;
    } else if (m.cls == MsgClass::kPosition) {
      ++c_.dropped_positions;  // nothing older to give way: this sample is the one dropped
      return;
    } else if (drop_oldest(MsgClass::kMeta) || drop_oldest(MsgClass::kState)) {
      ++c_.coalesced;  // re-sent as a fresh snapshot after the reconnect anyway
    } else {
      // Only events and job summaries left: the oldest goes, counted.
      q_.pop_front();
      ++c_.dropped_events;
    }
  }
  q_.push_back(std::move(m));
  c_.high_water = std::max(c_.high_water, q_.size());
}

bool OutQueue::contains_topic(const std::string& topic) const {
  return std::any_of(q_.begin(), q_.end(), [&](const OutMessage& m) { return m.topic == topic; });
}

std::size_t OutQueue::count(MsgClass cls) const {
  return static_cast<std::size_t>(
      std::count_if(q_.begin(), q_.end(), [cls](const OutMessage& m) { return m.cls == cls; }));
}

}  // namespace contour::bridge
