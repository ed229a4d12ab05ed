#include "config/shopnet_config.hpp"

namespace contour::config {

MqttConfig parse_mqtt(Section& s) {
  MqttConfig c;
  c.present = s.present();
  return c;  // every key is still unknown (reported by the Section)
}

MtconnectConfig parse_mtconnect(Section& s) {
  MtconnectConfig c;
  c.present = s.present();
  return c;
}

}  // namespace contour::config
