#pragma once
// `web:` section: contour-web (issue 21), the browser HMI — listen address, tokens and roles, rate
// and size limits. contourd validates it on load and otherwise ignores it.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct WebConfig {
  bool present = false;
};

WebConfig parse_web(Section& s);

}  // namespace contour::config
