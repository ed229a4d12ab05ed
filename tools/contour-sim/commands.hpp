#pragma once
// contour-sim subcommands. Each lives in its own cmd_<name>.cpp and parses its own arguments
// (argv[0] is the subcommand name). Contract (architecture.md): the last line printed on stdout
// is one JSON object; exit 0 on success, 1 when the run fails its own checks, 2 on usage errors.
namespace contour::sim {
int run_blend(int argc, char** argv);
int run_contour(int argc, char** argv);
int run_force(int argc, char** argv);
int run_circle(int argc, char** argv);
int run_run(int argc, char** argv);
}  // namespace contour::sim
