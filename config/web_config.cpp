#include "config/web_config.hpp"

namespace contour::config {

WebConfig parse_web(Section& s) {
  WebConfig c;
  c.present = s.present();
  return c;  // every key is still unknown (reported by the Section)
}

}  // namespace contour::config
