#pragma once
// SocketCAN raw socket (CAN_RAW) behind CanBus.
//
// open(): setup-time, throws SocketCanError (an IoError message naming interface and operation)
// when the interface is missing ("vcan9: SIOCGIFINDEX: No such device"), down ("vcan0: interface
// is down"), or a socket option fails. The socket is non-blocking; kernel receive filters are
// installed from `filters` (empty = receive everything); error frames are enabled for every class
// (CAN_RAW_ERR_FILTER = CAN_ERR_MASK); SO_RXQ_OVFL reports kernel queue drops; SO_TIMESTAMPNS
// stamps each frame. Own frames are not received (CAN_RAW_RECV_OWN_MSGS off, the default).
//
// send/receive/wait_readable are noexcept and allocation-free (RT-safe): ENOBUFS/EAGAIN on send
// is a counted drop (SendResult::kDropped), never a block. Error frames update bus_state()
// (bus-off, error-passive, warning) and are returned to the caller with CanFrame::error set.
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "drivers/can/can_bus.hpp"
#include "drivers/common/io_error.hpp"

namespace contour::drivers {

class SocketCanError : public std::runtime_error {
 public:
  explicit SocketCanError(IoError e) : std::runtime_error(e.message), error_(std::move(e)) {}
  [[nodiscard]] const IoError& error() const { return error_; }

 private:
  IoError error_;
};

class SocketCan final : public CanBus {
 public:
  // Throws SocketCanError.
  explicit SocketCan(const std::string& ifname, const std::vector<CanFilter>& filters = {});
  ~SocketCan() override;
  SocketCan(const SocketCan&) = delete;
  SocketCan& operator=(const SocketCan&) = delete;

  SendResult send(const CanFrame& f) noexcept override;
  bool receive(CanFrame& f) noexcept override;
  bool wait_readable(std::int64_t timeout_ns) noexcept override;
  [[nodiscard]] CanStats stats() const noexcept override { return stats_; }
  [[nodiscard]] BusState bus_state() const noexcept override { return state_; }
  void clear_bus_state() noexcept override { state_ = BusState::kErrorActive; }

  [[nodiscard]] int fd() const noexcept { return fd_; }
  [[nodiscard]] const std::string& ifname() const noexcept { return ifname_; }

 private:
  void on_error_frame(const CanFrame& f) noexcept;

  std::string ifname_;
  int fd_ = -1;
  CanStats stats_{};
  BusState state_ = BusState::kErrorActive;
};

// Pure: updates `state`/`stats` from one error frame (CAN_ERR_BUSOFF, CAN_ERR_CRTL data[1]).
void apply_error_frame(const CanFrame& f, BusState& state, CanStats& stats) noexcept;

}  // namespace contour::drivers
