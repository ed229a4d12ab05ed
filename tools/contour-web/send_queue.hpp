#pragma once
// A browser connection's outgoing queue: bounded in bytes. Scope batches (samples > 0) are
// droppable: when the queue is over its limit, the oldest droppable messages that are not being
// written go first and their samples are counted. Replies, status and events are never dropped;
// if they alone exceed twice the limit, the client is too slow to serve and overflow() says so
// (the session closes it). Single-threaded (the io_context thread).
#include <cstdint>
#include <deque>
#include <memory>
#include <string>

namespace contour::web {

class SendQueue {
 public:
  struct Item {
    std::shared_ptr<const std::string> text;
    std::size_t samples = 0;
  };
  explicit SendQueue(std::size_t limit_bytes) : limit_(limit_bytes) {}

  void push(std::shared_ptr<const std::string> text, std::size_t samples) {
    bytes_ += text->size();
    items_.push_back({std::move(text), samples});
    if (bytes_ <= limit_) return;
    // Oldest droppable first; items_[0] may be on the wire (writing_).
    for (std::size_t i = writing_ ? 1 : 0; i < items_.size() && bytes_ > limit_;) {
      if (items_[i].samples == 0) {
        ++i;
        continue;
      }
      bytes_ -= items_[i].text->size();
      dropped_samples_ += items_[i].samples;
      ++dropped_messages_;
      items_.erase(items_.begin() + static_cast<std::ptrdiff_t>(i));
    }
  }
  [[nodiscard]] bool empty() const { return items_.empty(); }
  [[nodiscard]] const Item& front() const { return items_.front(); }
  // The front item goes on the wire / has been written.
  void begin_write() { writing_ = true; }
  void end_write() {
    writing_ = false;
    bytes_ -= items_.front().text->size();
    items_.pop_front();
  }
  [[nodiscard]] bool writing() const { return writing_; }
  [[nodiscard]] bool overflow() const { return bytes_ > 2 * limit_; }
  [[nodiscard]] std::size_t bytes() const { return bytes_; }
  [[nodiscard]] std::uint64_t dropped_samples() const { return dropped_samples_; }
  [[nodiscard]] std::uint64_t dropped_messages() const { return dropped_messages_; }

 private:
  std::size_t limit_;
  std::size_t bytes_ = 0;
  bool writing_ = false;
  std::deque<Item> items_;
  std::uint64_t dropped_samples_ = 0;
  std::uint64_t dropped_messages_ = 0;
};

}  // namespace contour::web
