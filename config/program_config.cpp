#include "config/program_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
ProgramConfig parse_program(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
