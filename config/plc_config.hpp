#pragma once
// `plc:` section: the soft PLC (issue 20) — the I/O image's signals and their sources/sinks, the
// Structured Text programs and their scan periods, forcing rules. Absent section: no PLC.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct PlcConfig {
  bool present = false;  // the section was given
};

PlcConfig parse_plc(Section& s);

}  // namespace contour::config
