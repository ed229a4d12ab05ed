// socket: limits of issue 17 (idle timeout, per-client rate and buffer): defaults, values read,
// out-of-range and unknown keys reported with file:line and key.
#include <gtest/gtest.h>

#include "config/config.hpp"
#include "tests/support/config_errors.hpp"

using contour::config::load_config_string;
using contour::test::any_contains;

TEST(SocketConfig, LimitDefaults) {
  const auto cfg = load_config_string(std::string("socket:\n  path: /tmp/x.sock\n") + contour::test::kMachineYaml);
  EXPECT_DOUBLE_EQ(cfg.socket.idle_timeout_s, 60.0);
  EXPECT_EQ(cfg.socket.max_requests_per_s, 500);
  EXPECT_EQ(cfg.socket.max_buffered_bytes, 4 << 20);
  EXPECT_EQ(cfg.socket.max_clients, 16);
}

TEST(SocketConfig, LimitsAreRead) {
  const auto cfg = load_config_string(
      "socket:\n  idle_timeout_s: 2.5\n  max_requests_per_s: 40\n  max_buffered_bytes: 131072\n"
      "  max_clients: 3\n" + std::string(contour::test::kMachineYaml));
  EXPECT_DOUBLE_EQ(cfg.socket.idle_timeout_s, 2.5);
  EXPECT_EQ(cfg.socket.max_requests_per_s, 40);
  EXPECT_EQ(cfg.socket.max_buffered_bytes, 131072);
  EXPECT_EQ(cfg.socket.max_clients, 3);
}

TEST(SocketConfig, OutOfRangeAndUnknownKeysAreErrorsWithLineAndKey) {
  const auto errs = contour::test::config_errors(
      "socket:\n  idle_timeout_s: 0\n  max_requests_per_s: 0\n  max_buffered_bytes: 100\n"
      "  idle_timeout: 5\n" + std::string(contour::test::kMachineYaml),
      "s.yaml");
  ASSERT_EQ(errs.size(), 4u) << ::testing::PrintToString(errs);
  EXPECT_TRUE(any_contains(errs, "s.yaml:2:")) << errs[0];
  EXPECT_TRUE(any_contains(errs, "socket.idle_timeout_s: value 0 out of range"));
  EXPECT_TRUE(any_contains(errs, "s.yaml:3:"));
  EXPECT_TRUE(any_contains(errs, "socket.max_requests_per_s"));
  EXPECT_TRUE(any_contains(errs, "s.yaml:4:"));
  EXPECT_TRUE(any_contains(errs, "socket.max_buffered_bytes"));
  EXPECT_TRUE(any_contains(errs, "s.yaml:5:3: socket.idle_timeout: unknown key"));
  EXPECT_FALSE(contour::test::config_errors("socket:\n  idle_timeout_s: -1\n").empty());
  EXPECT_FALSE(contour::test::config_errors("socket:\n  max_requests_per_s: 2.5\n").empty());
}
