// Placeholder until the force simulation lands: says so and fails, never pretends.
#include <cstdio>

#include "tools/contour-sim/commands.hpp"

namespace contour::sim {
int run_force(int /*argc*/, char** /*argv*/) {
  std::fputs("contour-sim force: not implemented yet\n", stderr);
  std::puts("{\"error\": \"not implemented\"}");
  return 2;
}
}  // namespace contour::sim
