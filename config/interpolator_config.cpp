#include "config/interpolator_config.hpp"

#include <cmath>
#include <stdexcept>

namespace contour::config {

control::BlendMode parse_blend_mode(const std::string& s) {
  if (s == "g61") return control::BlendMode::kExactStop;
  if (s == "g64") return control::BlendMode::kFull;
  if (s == "limited") return control::BlendMode::kLimited;
  throw std::invalid_argument("blend mode must be g61, g64 or limited, got '" + s + "'");
}

int fir_taps(double ms, double period_s) {
  if (ms <= 0.0) return 0;
  return static_cast<int>(std::lround(ms * 1e-3 / period_s)) + 1;
}

InterpolatorConfig parse_interpolator(Section& s) {
  InterpolatorConfig c;
  c.fir_ms = s.number("fir_ms", c.fir_ms, 0.0, 2000.0);
  c.fir2_ms = s.number("fir2_ms", c.fir2_ms, 0.0, 2000.0);
  c.blend = parse_blend_mode(s.choice("blend", "limited", {"g61", "g64", "limited"}));
  c.tolerance_um = s.number("tolerance_um", c.tolerance_um, 0.1, 10000.0);
  c.arc_chord_fraction = s.number("arc_chord_fraction", c.arc_chord_fraction, 0.01, 0.9);
  c.feed_override_max_percent = s.number("feed_override_max_percent", c.feed_override_max_percent, 0.0, 300.0);
  c.rapid_override_max_percent =
      s.number("rapid_override_max_percent", c.rapid_override_max_percent, 1.0, 100.0);
  c.floor_rounding = s.choice("rounding", "ceil", {"ceil", "floor"}) == "floor";
  const std::string m = s.choice("method", "true", {"true", "paper", "exhaustive", "lookahead"});
  c.method = m == "paper"        ? control::BlendMethod::kPaper
             : m == "exhaustive" ? control::BlendMethod::kExhaustive
             : m == "lookahead"  ? control::BlendMethod::kLookahead
                                 : control::BlendMethod::kTrue;
  c.optional_stop = s.boolean("optional_stop", c.optional_stop);
  c.queue_capacity = s.integer("queue_capacity", c.queue_capacity, 16, 1 << 20);
  s.finish();
  return c;
}

}  // namespace contour::config
