#pragma once
// A temporary directory of this test process's own. ctest runs each discovered test in its own
// process, two at a time (-j2): tests that write fixed file names ("drive_io.st") straight into
// ::testing::TempDir() overwrite each other's files mid-read (seen in CI: "PROGRAM expected, found
// the end of the file"). Everything a test writes goes under process_temp_dir() instead.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace contour::test {

// <TempDir>/contour_test_<pid>/ with a trailing slash, created on first use.
inline const std::string& process_temp_dir() {
  static const std::string dir = [] {
    const std::filesystem::path p =
        std::filesystem::path(::testing::TempDir()) / ("contour_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(p);
    return p.string() + "/";
  }();
  return dir;
}

}  // namespace contour::test
