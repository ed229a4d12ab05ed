#pragma once
// `mqtt:` and `mtconnect:` sections: the shop network (issue 22), used by contour-bridge (MQTT
// publisher, MTConnect SHDR adapter). contourd validates them on load (--check-config too) and
// otherwise ignores them. Absent sections: the bridge has nothing to do there.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct MqttConfig {
  bool present = false;
};

struct MtconnectConfig {
  bool present = false;
};

MqttConfig parse_mqtt(Section& s);
MtconnectConfig parse_mtconnect(Section& s);

}  // namespace contour::config
