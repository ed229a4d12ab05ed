#pragma once
// Translation of OS errors at the adapter boundary (style.md: errno is translated once, into
// std::error_code plus a message naming the device and the operation).
#include <string>
#include <system_error>

namespace contour::drivers {

struct IoError {
  std::error_code code;
  std::string message;  // "vcan0: bind: No such device"
  [[nodiscard]] explicit operator bool() const { return static_cast<bool>(code); }
};

// Builds an IoError from errno value `err` for `device` and `operation`.
IoError io_error(const std::string& device, const std::string& operation, int err);

}  // namespace contour::drivers
