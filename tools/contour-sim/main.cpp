// contour-sim: offline, deterministic simulation of the control path on the built-in machine.
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "tools/contour-sim/commands.hpp"

namespace {
int usage(FILE* out) {
  std::fputs(
      "usage: contour-sim <command> [options]\n"
      "commands:\n"
      "  blend    FIR interpolation + corner blending of a part program (seed 004)\n"
      "  contour  contour-error model and P / PID / cross-coupled control (seed 000)\n"
      "  force    2-DOF cutting-force / position control (seed 001)\n"
      "  circle   circular test, servo-gain mismatch estimation and compensation (seed 003)\n"
      "  run      a part program through contourd's own loop code, offline (same figures as the daemon)\n"
      "Run 'contour-sim <command> --help' for the options of a command.\n",
      out);
  return 2;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage(stderr);
  const std::string cmd = argv[1];
  if (cmd == "-h" || cmd == "--help") {
    usage(stdout);
    return 0;
  }
  try {
    if (cmd == "blend") return contour::sim::run_blend(argc - 1, argv + 1);
    if (cmd == "contour") return contour::sim::run_contour(argc - 1, argv + 1);
    if (cmd == "force") return contour::sim::run_force(argc - 1, argv + 1);
    if (cmd == "circle") return contour::sim::run_circle(argc - 1, argv + 1);
    if (cmd == "run") return contour::sim::run_run(argc - 1, argv + 1);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contour-sim %s: error: %s\n", cmd.c_str(), e.what());
    return 1;
  }
  std::fprintf(stderr, "contour-sim: unknown command '%s'\n", cmd.c_str());
  return usage(stderr);
}
