#pragma once
// Shared gnuplot helpers for the command-line tools (contourctl; contour-sim may adopt them).
// Header-only. Non-RT tool code: allocates, throws std::runtime_error with the output path on
// failure. gnuplot comes from Debian (`gnuplot-nox`, tools/deps.sh); PNGs are written with the
// pngcairo terminal, which needs no display.
#include <stdio.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

namespace contour::tools::gnuplot {

// A string literal for a gnuplot script: single-quoted, embedded quotes doubled (gnuplot's rule).
inline std::string quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'')
      out += "''";
    else
      out += c;
  }
  return out + "'";
}

// A double-quoted gnuplot string: backslash sequences such as \n (line break) are interpreted;
// embedded double quotes escaped. For titles built by the tools, not for file names.
inline std::string dquote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"')
      out += "\\\"";
    else
      out += c;
  }
  return out + "\"";
}

// Text for an enhanced-mode label: gnuplot's markup characters escaped, so file names such as
// "table2_coupled" are not typeset as subscripts. For single-quoted strings (quote()).
inline std::string enhanced_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '_' || c == '^' || c == '{' || c == '}' || c == '@' || c == '&' || c == '~')
      out += '\\';
    out += c;
  }
  return out;
}

// Terminal and style preamble: white background, readable fonts, grid, legend box.
inline std::string png_preamble(const std::string& png, int width_px = 1200, int height_px = 800) {
  return "set terminal pngcairo size " + std::to_string(width_px) + "," +
         std::to_string(height_px) +
         " enhanced font 'DejaVu Sans,12' background rgb 'white'\n"
         "set output " +
         quote(png) +
         "\n"
         "set grid lc rgb '#d0d0d0'\n"
         "set key box opaque top right\n"
         "set datafile separator whitespace\n";
}

// Runs gnuplot on the script; gnuplot's stderr is passed through. Throws when gnuplot cannot be
// started, exits non-zero, or leaves no output file.
inline void run(const std::string& script, const std::string& png) {
  std::error_code ec;
  std::filesystem::remove(png, ec);
  FILE* gp = ::popen("gnuplot", "w");
  if (gp == nullptr) {
    throw std::runtime_error("cannot start gnuplot (install gnuplot-nox: tools/deps.sh)");
  }
  std::fputs(script.c_str(), gp);
  const int rc = ::pclose(gp);
  if (rc != 0) {
    const int code = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
    throw std::runtime_error(png + ": gnuplot failed (exit " + std::to_string(code) +
                             (code == 127 ? ", gnuplot not installed: tools/deps.sh" : "") + ")");
  }
  if (!std::filesystem::exists(png, ec) || std::filesystem::file_size(png, ec) == 0) {
    throw std::runtime_error(png + ": gnuplot wrote no image");
  }
}

// Data file next to the PNG, removed on destruction (the plot data stay out of the user's way).
class TempData {
 public:
  explicit TempData(const std::string& png, const std::string& tag = "")
      : path_(png + tag + ".dat"), out_(path_) {
    if (!out_) throw std::runtime_error(path_ + ": cannot write plot data");
    out_.precision(9);
  }
  ~TempData() {
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }
  TempData(const TempData&) = delete;
  TempData& operator=(const TempData&) = delete;
  std::ofstream& out() { return out_; }
  void close() { out_.close(); }
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::ofstream out_;
};

}  // namespace contour::tools::gnuplot
