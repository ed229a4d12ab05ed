// Placeholder until the blend simulation lands: says so and fails, never pretends.
#include <cstdio>

#include "tools/contour-sim/commands.hpp"

namespace contour::sim {
int run_blend(int /*argc*/, char** /*argv*/) {
  std::fputs("contour-sim blend: not implemented yet\n", stderr);
  std::puts("{\"error\": \"not implemented\"}");
  return 2;
}
}  // namespace contour::sim
