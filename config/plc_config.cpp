#include "config/plc_config.hpp"

namespace contour::config {

PlcConfig parse_plc(Section& s) {
  PlcConfig c;
  c.present = s.present();
  return c;  // every key is still unknown (reported by the Section)
}

}  // namespace contour::config
