#include "drivers/can/socket_can.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>

namespace contour::drivers {

namespace {
[[noreturn]] void fail(const std::string& ifname, const std::string& op, int err) {
  throw SocketCanError(io_error(ifname, op, err));
}
}  // namespace

SocketCan::SocketCan(const std::string& ifname, const std::vector<CanFilter>& filters)
    : ifname_(ifname) {
  if (ifname.empty() || ifname.size() >= IFNAMSIZ) fail(ifname, "interface name", EINVAL);
  fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd_ < 0) fail(ifname, "socket(PF_CAN)", errno);
  try {
    ifreq ifr{};
    std::strncpy(ifr.ifr_name, ifname.c_str(), IFNAMSIZ - 1);
    if (::ioctl(fd_, SIOCGIFINDEX, &ifr) < 0) fail(ifname, "SIOCGIFINDEX", errno);
    const int index = ifr.ifr_ifindex;
    if (::ioctl(fd_, SIOCGIFFLAGS, &ifr) < 0) fail(ifname, "SIOCGIFFLAGS", errno);
    if ((ifr.ifr_flags & IFF_UP) == 0) {
      throw SocketCanError(IoError{std::error_code(ENETDOWN, std::generic_category()),
                                   ifname + ": interface is down (ip link set " + ifname + " up)"});
    }
    if (!filters.empty()) {
      std::vector<can_filter> k(filters.size());
      for (std::size_t i = 0; i < filters.size(); ++i) {
        // Standard data frames only: extended and RTR frames never match these filters.
        k[i].can_id = filters[i].id & CAN_SFF_MASK;
        k[i].can_mask = (filters[i].mask & CAN_SFF_MASK) | CAN_EFF_FLAG | CAN_RTR_FLAG;
      }
      if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, k.data(),
                       static_cast<socklen_t>(k.size() * sizeof(can_filter))) < 0)
        fail(ifname, "CAN_RAW_FILTER", errno);
    }
    can_err_mask_t mask = CAN_ERR_MASK;
    if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof(mask)) < 0)
      fail(ifname, "CAN_RAW_ERR_FILTER", errno);
    int on = 1;
    if (::setsockopt(fd_, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof(on)) < 0)
      fail(ifname, "SO_RXQ_OVFL", errno);
    if (::setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on)) < 0)
      fail(ifname, "SO_TIMESTAMPNS", errno);
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = index;
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) < 0)
      fail(ifname, "bind", errno);
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
}

SocketCan::~SocketCan() {
  if (fd_ >= 0) ::close(fd_);
}

SendResult SocketCan::send(const CanFrame& f) noexcept {
  can_frame k{};
  k.can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0u) | (f.rtr ? CAN_RTR_FLAG : 0u);
  k.can_dlc = f.dlc > 8 ? 8 : f.dlc;
  std::memcpy(k.data, f.data.data(), 8);
  const ssize_t n = ::write(fd_, &k, sizeof(k));
  if (n == static_cast<ssize_t>(sizeof(k))) {
    ++stats_.tx_frames;
    return SendResult::kOk;
  }
  if (n < 0 && (errno == ENOBUFS || errno == EAGAIN)) {
    ++stats_.tx_dropped;
    return SendResult::kDropped;
  }
  ++stats_.tx_errors;
  return SendResult::kError;
}

bool SocketCan::receive(CanFrame& f) noexcept {
  can_frame k{};
  iovec iov{&k, sizeof(k)};
  // Room for SCM_TIMESTAMPNS (timespec) + SO_RXQ_OVFL (u32); fixed-size, no allocation.
  alignas(cmsghdr) char ctrl[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = ctrl;
  msg.msg_controllen = sizeof(ctrl);
  const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
  if (n != static_cast<ssize_t>(sizeof(k))) return false;
  f = CanFrame{};
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET) continue;
    if (c->cmsg_type == SCM_TIMESTAMPNS) {
      timespec ts{};
      std::memcpy(&ts, CMSG_DATA(c), sizeof(ts));
      f.timestamp_ns = static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
    } else if (c->cmsg_type == SO_RXQ_OVFL) {
      std::uint32_t drops = 0;
      std::memcpy(&drops, CMSG_DATA(c), sizeof(drops));
      stats_.rx_overflow = drops;
    }
  }
  f.extended = (k.can_id & CAN_EFF_FLAG) != 0;
  f.rtr = (k.can_id & CAN_RTR_FLAG) != 0;
  f.error = (k.can_id & CAN_ERR_FLAG) != 0;
  f.id = f.error ? (k.can_id & CAN_ERR_MASK) : (k.can_id & (f.extended ? CAN_EFF_MASK : CAN_SFF_MASK));
  f.dlc = k.can_dlc > 8 ? 8 : k.can_dlc;
  std::memcpy(f.data.data(), k.data, 8);
  if (f.error) {
    on_error_frame(f);
  } else {
    ++stats_.rx_frames;
  }
  return true;
}

bool SocketCan::wait_readable(std::int64_t timeout_ns) noexcept {
  if (timeout_ns < 0) timeout_ns = 0;
  pollfd p{fd_, POLLIN, 0};
  timespec ts{static_cast<time_t>(timeout_ns / 1000000000LL),
              static_cast<long>(timeout_ns % 1000000000LL)};
  return ::ppoll(&p, 1, &ts, nullptr) == 1 && (p.revents & POLLIN) != 0;
}

void SocketCan::on_error_frame(const CanFrame& f) noexcept { apply_error_frame(f, state_, stats_); }

void apply_error_frame(const CanFrame& f, BusState& state, CanStats& stats) noexcept {
  ++stats.error_frames;
  if ((f.id & CAN_ERR_BUSOFF) != 0) {
    if (state != BusState::kBusOff) ++stats.bus_off_events;
    state = BusState::kBusOff;
    return;
  }
  if ((f.id & CAN_ERR_RESTARTED) != 0) {
    state = BusState::kErrorActive;
    return;
  }
  if ((f.id & CAN_ERR_CRTL) != 0 && f.dlc >= 2) {
    const std::uint8_t c = f.data[1];
    if ((c & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) != 0) {
      if (state != BusState::kErrorPassive && state != BusState::kBusOff)
        ++stats.error_passive_events;
      if (state != BusState::kBusOff) state = BusState::kErrorPassive;
    } else if ((c & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) != 0) {
      if (state == BusState::kErrorActive) state = BusState::kErrorWarning;
    } else if ((c & CAN_ERR_CRTL_ACTIVE) != 0) {
      state = BusState::kErrorActive;
    }
  }
}

const char* bus_state_name(BusState s) noexcept {
  switch (s) {
    case BusState::kErrorActive: return "error-active";
    case BusState::kErrorWarning: return "error-warning";
    case BusState::kErrorPassive: return "error-passive";
    case BusState::kBusOff: return "bus-off";
  }
  return "?";
}

}  // namespace contour::drivers
