#pragma once
// Small CAN bus interface so the CANopen master runs on SocketCAN or on a scripted fake (tests).
//
// Frames are classic CAN (11-bit or 29-bit ids, 0..8 data bytes). All calls are noexcept and
// non-blocking except wait_readable(), which blocks at most `timeout_ns`. RT-safe: no allocation.
#include <array>
#include <cstdint>

namespace contour::drivers {

struct CanFrame {
  std::uint32_t id = 0;  // 11-bit (or 29-bit when extended) identifier, flags stripped
  std::uint8_t dlc = 0;  // 0..8
  bool extended = false;
  bool rtr = false;
  bool error = false;  // an error frame (id holds the CAN_ERR_* class bits)
  std::array<std::uint8_t, 8> data{};
  std::int64_t timestamp_ns = 0;  // kernel receive time (CLOCK_REALTIME), 0 when unknown
};

enum class SendResult { kOk, kDropped /* ENOBUFS/EAGAIN: counted, never blocks */, kError };

// Controller state as seen through error frames (bus-off / error-passive are latched until
// clear_bus_state()).
enum class BusState { kErrorActive, kErrorWarning, kErrorPassive, kBusOff };

// "bus-off", "error-passive", ... (defined in socket_can.cpp)
const char* bus_state_name(BusState s) noexcept;

// Kernel receive filter for 11-bit data frames: passes when (id & mask) == (filter.id & mask);
// extended (29-bit) and RTR frames never pass a filter.
struct CanFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = 0x7FF;
};

struct CanStats {
  std::uint64_t tx_frames = 0;
  std::uint64_t tx_dropped = 0;   // ENOBUFS / EAGAIN on send
  std::uint64_t tx_errors = 0;    // any other send error
  std::uint64_t rx_frames = 0;
  std::uint64_t rx_overflow = 0;  // kernel socket-queue drops (SO_RXQ_OVFL, cumulative)
  std::uint64_t error_frames = 0;
  std::uint64_t bus_off_events = 0;
  std::uint64_t error_passive_events = 0;
};

class CanBus {
 public:
  virtual ~CanBus() = default;
  virtual SendResult send(const CanFrame& f) noexcept = 0;
  // Returns true and fills `f` when a frame was waiting; false when none (never blocks).
  virtual bool receive(CanFrame& f) noexcept = 0;
  // Blocks until a frame is readable or timeout_ns elapsed; returns true when readable.
  virtual bool wait_readable(std::int64_t timeout_ns) noexcept = 0;
  [[nodiscard]] virtual CanStats stats() const noexcept = 0;
  [[nodiscard]] virtual BusState bus_state() const noexcept = 0;
  virtual void clear_bus_state() noexcept = 0;
};

}  // namespace contour::drivers
