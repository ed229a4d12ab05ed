// in_private_tmp (daemon/daemon.hpp): contourd refuses, at start-up, a socket or telemetry
// directory inside systemd's PrivateTmp= /tmp, recognised in /proc/self/mountinfo by the mount
// root systemd uses ("systemd-private-*"). Mountinfo lines below are the shapes seen on Debian 12:
// /tmp on the root file system (root = the bind source path) and /tmp on its own tmpfs.
#include <gtest/gtest.h>

#include <string>

#include "daemon/daemon.hpp"

namespace {

using contour::daemon::in_private_tmp;

const std::string kHost =
    "21 1 8:1 / / rw,relatime shared:1 - ext4 /dev/sda1 rw\n"
    "25 21 0:22 / /run rw,nosuid,nodev shared:5 - tmpfs tmpfs rw,mode=755\n";

// PrivateTmp=yes with /tmp and /var/tmp on the root file system.
const std::string kPrivateOnRootFs =
    kHost +
    "300 21 8:1 /tmp/systemd-private-5e3c1f-contourd.service-AbCdEf/tmp /tmp rw,relatime - ext4 "
    "/dev/sda1 rw\n"
    "301 21 8:1 /var/tmp/systemd-private-5e3c1f-contourd.service-GhIjKl/tmp /var/tmp rw,relatime - "
    "ext4 /dev/sda1 rw\n";

// PrivateTmp=yes with the host's /tmp a tmpfs: the root is relative to that tmpfs.
const std::string kPrivateOnTmpfs =
    kHost + "40 21 0:30 / /tmp rw,nosuid,nodev shared:20 - tmpfs tmpfs rw\n" +
    "310 21 0:30 /systemd-private-5e3c1f-contourd.service-AbCdEf/tmp /tmp rw,nosuid,nodev - tmpfs "
    "tmpfs rw\n";

TEST(PrivateTmp, RecognisesSystemdPrivateTmp) {
  for (const auto* mi : {&kPrivateOnRootFs, &kPrivateOnTmpfs}) {
    EXPECT_TRUE(in_private_tmp("/tmp", *mi));
    EXPECT_TRUE(in_private_tmp("/tmp/run.csv", *mi));
    EXPECT_TRUE(in_private_tmp("/tmp/a/b", *mi));
    EXPECT_FALSE(in_private_tmp("/run/contourd/contourd.sock", *mi));
    EXPECT_FALSE(in_private_tmp("/var/lib/contourd/records", *mi));
    EXPECT_FALSE(in_private_tmp("/tmpx/y", *mi)) << "prefix of a name, not of a path";
  }
  EXPECT_TRUE(in_private_tmp("/var/tmp/r.csv", kPrivateOnRootFs));
}

TEST(PrivateTmp, HostTmpIsNotPrivate) {
  EXPECT_FALSE(in_private_tmp("/tmp/run.csv", kHost));
  EXPECT_FALSE(in_private_tmp("/tmp/run.csv",
                              kHost + "40 21 0:30 / /tmp rw,nosuid,nodev shared:20 - tmpfs tmpfs rw\n"));
  EXPECT_FALSE(in_private_tmp("/tmp/run.csv", ""));
  EXPECT_FALSE(in_private_tmp("/tmp/run.csv", "garbage\n\n1 2\n"));
}

}  // namespace
