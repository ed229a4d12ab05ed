#include "drivers/common/io_error.hpp"

#include <cstring>

namespace contour::drivers {

IoError io_error(const std::string& device, const std::string& operation, int err) {
  return IoError{std::error_code(err, std::generic_category()),
                 device + ": " + operation + ": " + std::strerror(err)};
}

}  // namespace contour::drivers
