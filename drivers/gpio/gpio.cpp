#include "drivers/gpio/gpio.hpp"

namespace contour::drivers::gpio {

std::string LineSpec::describe() const {
  std::string where;
  if (offset >= 0)
    where = (chip.empty() ? std::string("?") : chip) + ":" + std::to_string(offset);
  else
    where = "line '" + name + "'" + (chip.empty() ? std::string() : " on " + chip);
  return (role.empty() ? std::string("gpio") : role) + " (" + where + ")";
}

}  // namespace contour::drivers::gpio
