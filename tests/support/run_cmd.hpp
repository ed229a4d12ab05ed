#pragma once
// The exit status and combined output (stdout + stderr) of a shell command, for tests that run the
// built tools (contourctl, contourd --check-config, ...). -1 when it could not be started or did
// not exit normally.
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace contour::test {

inline int run_cmd(const std::string& cmd, std::string* out) {
  FILE* f = ::popen((cmd + " 2>&1").c_str(), "r");
  if (f == nullptr) return -1;
  char buf[512];
  while (std::fgets(buf, sizeof buf, f) != nullptr) *out += buf;
  const int st = ::pclose(f);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

}  // namespace contour::test
