// HIL smoke test of the vcan harness: raw SocketCAN on vcan0, two sockets, local loopback.
// Runs under tools/with-vcan (natively or through User-Mode Linux). Deliberately independent of
// drivers/can: it proves the harness, not our wrapper.
#include <gtest/gtest.h>
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
#include <string>

namespace {

struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

// Returns the socket or -errno.
int open_can(const char* ifname) {
  int s = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (s < 0) return -errno;
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, ifname, IFNAMSIZ - 1);
  if (::ioctl(s, SIOCGIFINDEX, &ifr) < 0) {
    const int e = errno;
    ::close(s);
    return -e;
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) < 0) {
    const int e = errno;
    ::close(s);
    return -e;
  }
  return s;
}

bool recv_frame(int fd, can_frame& f, int timeout_ms) {
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) != 1) return false;
  return ::read(fd, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f));
}

}  // namespace

TEST(VcanSmoke, TwoSocketsSeeEachOthersFrames) {
  Fd tx{open_can("vcan0")};
  Fd rx{open_can("vcan0")};
  ASSERT_GE(tx.fd, 0) << "vcan0: " << std::strerror(-tx.fd) << " (run under tools/with-vcan)";
  ASSERT_GE(rx.fd, 0) << std::strerror(-rx.fd);

  for (int i = 0; i < 100; ++i) {
    can_frame out{};
    out.can_id = static_cast<canid_t>(0x180 + (i % 127) + 1);
    out.can_dlc = static_cast<__u8>(i % 9);
    for (int b = 0; b < out.can_dlc; ++b) out.data[b] = static_cast<__u8>(i * 7 + b);
    ASSERT_EQ(::write(tx.fd, &out, sizeof(out)), static_cast<ssize_t>(sizeof(out)));
    can_frame in{};
    ASSERT_TRUE(recv_frame(rx.fd, in, 1000)) << "frame " << i << " not received";
    EXPECT_EQ(in.can_id, out.can_id);
    ASSERT_EQ(in.can_dlc, out.can_dlc);
    EXPECT_EQ(std::memcmp(in.data, out.data, out.can_dlc), 0);
  }
}

TEST(VcanSmoke, KernelFilterDropsOtherIds) {
  Fd tx{open_can("vcan0")};
  Fd rx{open_can("vcan0")};
  ASSERT_GE(tx.fd, 0);
  ASSERT_GE(rx.fd, 0);
  can_filter flt{0x181, CAN_SFF_MASK};
  ASSERT_EQ(::setsockopt(rx.fd, SOL_CAN_RAW, CAN_RAW_FILTER, &flt, sizeof(flt)), 0);
  can_frame a{};
  a.can_id = 0x182;
  a.can_dlc = 1;
  can_frame b{};
  b.can_id = 0x181;
  b.can_dlc = 2;
  b.data[0] = 0xAB;
  b.data[1] = 0xCD;
  ASSERT_EQ(::write(tx.fd, &a, sizeof(a)), static_cast<ssize_t>(sizeof(a)));
  ASSERT_EQ(::write(tx.fd, &b, sizeof(b)), static_cast<ssize_t>(sizeof(b)));
  can_frame in{};
  ASSERT_TRUE(recv_frame(rx.fd, in, 1000));
  EXPECT_EQ(in.can_id, 0x181u);
  EXPECT_EQ(in.data[1], 0xCD);
  EXPECT_FALSE(recv_frame(rx.fd, in, 50)) << "filtered frame leaked through";
}

TEST(VcanSmoke, ErrorFramesCanBeEnabled) {
  Fd s{open_can("vcan0")};
  ASSERT_GE(s.fd, 0);
  can_err_mask_t mask = CAN_ERR_MASK;
  EXPECT_EQ(::setsockopt(s.fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof(mask)), 0)
      << std::strerror(errno);
}

TEST(VcanSmoke, MissingInterfaceGivesClearError) {
  const int r = open_can("vcan_nope");
  ASSERT_LT(r, 0);
  EXPECT_EQ(-r, ENODEV) << "got " << std::strerror(-r);
}

TEST(VcanSmoke, SecondInterfaceIsIsolated) {
  Fd a{open_can("vcan0")};
  Fd b{open_can("vcan1")};
  ASSERT_GE(a.fd, 0);
  ASSERT_GE(b.fd, 0) << "vcan1 missing: run with tools/with-vcan --ifaces vcan0,vcan1";
  can_frame f{};
  f.can_id = 0x700;
  f.can_dlc = 1;
  ASSERT_EQ(::write(a.fd, &f, sizeof(f)), static_cast<ssize_t>(sizeof(f)));
  can_frame in{};
  EXPECT_FALSE(recv_frame(b.fd, in, 50)) << "frame crossed from vcan0 to vcan1";
}
