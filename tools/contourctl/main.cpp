// contourctl — command-line client of contourd's command socket (daemon/commands.hpp), plus the
// bench tools built on it: progress while running, a live status line, telemetry plots (gnuplot),
// live gain tuning saved back to the YAML config, and seed 003's circle test on the machine.
// `contourctl --help` documents every subcommand, the exit codes and the gains-save choice.
// `run PROGRAM --wait --json` ends with one JSON object on stdout: state, duration_s,
// max_contour_error_um, rms_contour_error_um, faults, overruns (+ job, completed, ...); progress
// goes to stderr, so scripts keep reading the last stdout line (tools/demo.sh).
#include <signal.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "control/gcode.hpp"
#include "daemon/command_table.hpp"
#include "tools/contourctl/circle.hpp"
#include "tools/contourctl/client.hpp"
#include "tools/contourctl/gains.hpp"
#include "tools/contourctl/plot.hpp"

namespace {

using nlohmann::json;
using namespace contour::ctl;
namespace fs = std::filesystem;

volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_sigint(int) { g_interrupted = 1; }

// SIGINT without SA_RESTART: the status poll's sleep and recv return early.
void install_sigint() {
  struct sigaction sa {};
  sa.sa_handler = on_sigint;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;
  ::sigaction(SIGINT, &sa, nullptr);
}

std::string slurp(const std::string& file) {
  std::ifstream in(file);
  if (!in) throw ErrorReply(file + ": cannot read");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Programs always go by content, never by path: the daemon may not see the client's files
// (systemd's PrivateTmp= and ProtectHome= give it its own /tmp and no /home). One `load {program}`
// line when it fits a socket line (socket.max_line_bytes, 64 KiB by default, with room for the
// request's other keys), else `upload` chunks of at most that size each; the daemon's
// socket.max_program_bytes bounds the total.
constexpr std::size_t kMaxRequestBytes = 60 * 1024;
constexpr std::size_t kChunkBytes = 32 * 1024;

std::string dump_utf8(const json& j, const std::string& file) {
  try {
    return j.dump();
  } catch (const json::type_error&) {
    throw ErrorReply(file + ": not UTF-8 text; part programs are sent as text");
  }
}

// {program, name} for a load/run request when the text fits one line; empty otherwise.
json inline_program_args(const std::string& file, const std::string& text) {
  json a{{"program", text}, {"name", file}};
  if (dump_utf8(a, file).size() <= kMaxRequestBytes) return a;
  return json();
}

// Uploads and loads (the final chunk loads): the load reply (+ bytes).
json upload_program(Client& c, const std::string& file, const std::string& text, bool preview = false,
                    long start_line = 0) {
  std::size_t off = 0;
  for (;;) {
    std::size_t n = std::min(kChunkBytes, text.size() - off);
    json req;
    for (;;) {
      // Never split a UTF-8 sequence: each chunk must be a valid JSON string on its own.
      while (n > 1 && off + n < text.size() &&
             (static_cast<unsigned char>(text[off + n]) & 0xC0) == 0x80) {
        --n;
      }
      req = {{"cmd", "upload"}, {"name", file}, {"offset", off}, {"data", text.substr(off, n)},
             {"final", off + n == text.size()}};
      if (preview && off + n == text.size()) req["preview"] = true;
      if (start_line > 0 && off + n == text.size()) req["start_line"] = start_line;
      // Escaping grows control characters up to 6x: halve until the line fits.
      if (n <= 64 || dump_utf8(req, file).size() <= kMaxRequestBytes) break;
      n /= 2;
    }
    const json r = c.call(req);
    off += n;
    if (off == text.size()) return r;
  }
}

json load_program(Client& c, const std::string& file, bool preview = false, long start_line = 0) {
  const std::string text = slurp(file);
  const json a = inline_program_args(file, text);
  if (!a.is_null()) {
    json req{{"cmd", "load"}};
    req.update(a);
    if (preview) req["preview"] = true;
    if (start_line > 0) req["start_line"] = start_line;
    return c.call(req);
  }
  return upload_program(c, file, text, preview, start_line);
}

// `load --preview`: what was loaded, the program's extents, time, blocks and tools.
std::string format_preview(const json& r) {
  std::ostringstream o;
  char b[256];
  std::snprintf(b, sizeof b, "loaded job %llu: %s, %ld lines, %ld motion blocks, %.3f mm\n",
                static_cast<unsigned long long>(r.value("job", 0ULL)), r.value("name", std::string()).c_str(),
                r.value("lines", 0L), r.value("motion_blocks", 0L), r.value("length_mm", 0.0));
  o << b;
  const double t = r.value("estimated_time_s", 0.0);
  std::string tools;
  for (const auto& n : r.value("tools", json::array())) tools += " T" + std::to_string(n.get<int>());
  std::snprintf(b, sizeof b, "preview: %ld blocks, estimated time %d min %04.1f s (100 %% override, holds not counted), tools:%s\n",
                r.value("blocks", 0L), static_cast<int>(t / 60.0), std::fmod(t, 60.0),
                tools.empty() ? " none" : tools.c_str());
  o << b;
  const json ex = r.value("extents", json::object());
  const json mach = ex.value("machine", json::object()), work = ex.value("work", json::object());
  for (auto it = mach.begin(); it != mach.end(); ++it) {
    const json w = work.value(it.key(), json());
    if (!it.value().is_array() || !w.is_array()) {
      o << "  " << it.key() << "  no motion\n";
      continue;
    }
    std::snprintf(b, sizeof b, "  %s  machine [%9.3f, %9.3f] mm   work [%9.3f, %9.3f] mm\n", it.key().c_str(),
                  it.value()[0].get<double>(), it.value()[1].get<double>(), w[0].get<double>(),
                  w[1].get<double>());
    o << b;
  }
  return o.str();
}

// Source lines of the program's motion blocks, for "block n/N" (the daemon's status reports the
// current source line, not a block index). Parsed with the default program setup: offsets and
// tools do not change which lines move. Empty when the file does not parse here.
std::vector<int> motion_lines(const std::string& file) {
  std::vector<int> lines;
  try {
    contour::control::GcodeParser p(contour::control::ProgramSetup{}, file);
    std::ifstream in(file);
    std::string l;
    std::vector<contour::control::Block> blocks;
    while (std::getline(in, l) && !p.ended()) p.parse_line(l, blocks);
    p.finish(blocks);
    for (const auto& b : blocks) {
      if (b.kind == contour::control::BlockKind::kMotion) lines.push_back(b.line);
    }
  } catch (const std::exception&) {
    lines.clear();
  }
  return lines;
}

std::string clock_str(double s) {
  if (!std::isfinite(s) || s < 0.0) return "--:--";
  char b[32];
  const long m = static_cast<long>(s) / 60;
  std::snprintf(b, sizeof b, "%ld:%04.1f", m, s - 60.0 * static_cast<double>(m));
  return b;
}

int terminal_columns() {
  winsize w{};
  if (::ioctl(STDERR_FILENO, TIOCGWINSZ, &w) == 0 && w.ws_col > 20) return w.ws_col;
  return 100;
}

void print(const json& j, bool as_json) {
  if (as_json) {
    std::cout << j.dump() << std::endl;
    return;
  }
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) {
      std::cout << it.key() << ": "
                << (it.value().is_string() ? it.value().get<std::string>() : it.value().dump())
                << '\n';
    }
  } else {
    std::cout << j.dump(2) << '\n';
  }
}

// The one-line answer of a command that changes the machine (issue 15): what was asked and
// the state it left, from the daemon's reply (the reply itself is unchanged; --json prints it
// whole). Empty when the reply lacks what the line needs: the caller then prints the reply.
std::string confirmation(const std::string& cmd, const json& r) {
  if (!r.is_object()) return {};
  char b[160];
  if (cmd == "jog" && r.contains("axis") && r.contains("target_mm")) {
    std::snprintf(b, sizeof b, "jog: %s to %.3f mm", r["axis"].get<std::string>().c_str(),
                  r["target_mm"].get<double>());
    return b;
  }
  if (cmd == "set-position" && r.contains("axis") && r.contains("position_mm")) {
    std::snprintf(b, sizeof b, "set-position: %s at %.3f mm",
                  r["axis"].get<std::string>().c_str(), r["position_mm"].get<double>());
    return b;
  }
  if (cmd == "switches" && r.contains("block_delete")) {
    std::snprintf(b, sizeof b, "switches: block delete %s, optional stop %s, single block %s",
                  r.value("block_delete", false) ? "on" : "off", r.value("optional_stop", false) ? "on" : "off",
                  r.value("single_block", false) ? "on" : "off");
    return b;
  }
  if (cmd == "override" && r.contains("feed_override_percent")) {
    std::snprintf(b, sizeof b, "override: feed %g %%, rapid %g %%, spindle %g %%",
                  r["feed_override_percent"].get<double>(), r.value("rapid_override_percent", 100.0),
                  r.value("spindle_override_percent", 100.0));
    return b;
  }
  if (cmd == "force" && r.contains("enabled")) {
    std::snprintf(b, sizeof b, "force: %s, reference %.1f N, %s",
                  r["enabled"].get<bool>() ? "on" : "off", r.value("reference_n", 0.0),
                  r.value("status", std::string("?")).c_str());
    return b;
  }
  if (cmd == "shutdown" && r.value("shutting_down", false))
    return "shutdown: contourd is stopping";
  if (r.contains("state") && r["state"].is_string()) {
    // hold, resume, stop, estop, reset, enable, disable: the status after the command.
    std::string line = cmd + ": state " + r["state"].get<std::string>();
    const std::string cause = r.value("cause", std::string("none"));
    if (cause != "none") line += " (cause " + cause + ")";
    return line;
  }
  return {};
}

void print_confirmation(const std::string& cmd, const json& r, bool as_json) {
  const std::string line = as_json ? std::string() : confirmation(cmd, r);
  if (line.empty())
    print(r, as_json);
  else
    std::cout << line << '\n';
}

void print_run_summary(const json& r) {
  const bool done = r.value("completed", false);
  std::printf("run: job %llu %s (state %s) in %.3f s\n",
              static_cast<unsigned long long>(r.value("job", 0ULL)),
              done ? "completed" : "NOT completed", r.value("state", std::string("?")).c_str(),
              r.value("duration_s", 0.0));
  std::printf(
      "contour error: max %.1f um, RMS %.1f um (distance to the planned path); max following error "
      "%.1f um\n",
      r.value("max_contour_error_um", 0.0), r.value("rms_contour_error_um", 0.0),
      r.value("max_following_error_um", 0.0));
  std::printf("overruns: %llu   telemetry dropped: %llu   faults: %s\n",
              static_cast<unsigned long long>(r.value("overruns", 0ULL)),
              static_cast<unsigned long long>(r.value("telemetry_dropped", 0ULL)),
              r.contains("faults") && !r["faults"].empty() ? r["faults"].dump().c_str() : "none");
  // Issue 16: RMS / max of the cycle-to-cycle change of each axis' velocity command.
  const json& rms = r.contains("command_chatter_rms_mm_s") ? r["command_chatter_rms_mm_s"] : json();
  const json& mx = r.contains("command_chatter_max_mm_s") ? r["command_chatter_max_mm_s"] : json();
  if (rms.is_array() && mx.is_array() && rms.size() == mx.size()) {
    std::string line = "command chatter (RMS / max of the cycle-to-cycle change, mm/s):";
    static const char* kNames[] = {"X", "Y", "Z"};
    for (std::size_t i = 0; i < rms.size() && i < 3; ++i) {
      char b[96];
      std::snprintf(b, sizeof b, " %s %.2f / %.1f", kNames[i], rms[i].get<double>(), mx[i].get<double>());
      line += b;
    }
    std::printf("%s\n", line.c_str());
  }
}

struct RunOptions {
  std::string program;
  bool wait = false;
  double timeout_s = 3600.0;
  bool quiet = false;
  double progress_interval_s = 1.0;  // non-TTY progress lines
  long from_line = 0;                // run from line (0: from the beginning)
};

// `home AXIS | --all`: starts homing, prints each axis' phase as it changes, and waits until the
// loop's homing ends. Exit 0 when the requested axes are homed, 1 when homing failed or was
// aborted (the reason from status.homing.failure).
int cmd_home(Client& c, const std::string& axis, bool all, bool as_json) {
  if (all == !axis.empty()) {
    std::cerr << "contourctl: home AXIS, or home --all\n";
    return kExitUsage;
  }
  json req{{"cmd", "home"}};
  if (!all) req["axis"] = axis;
  const json r = c.call(req);
  const json axes = r.value("homing", json::array());
  if (!as_json) {
    std::printf("homing %s\n", axes.dump().c_str());
    std::fflush(stdout);
  }
  json last_phase;
  json st;
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    st = c.call({{"cmd", "status"}});
    const json& h = st["homing"];
    if (!as_json && h["phase"] != last_phase) {
      std::string line;
      for (const auto& n : axes) {
        const std::string name = n.get<std::string>();
        line += (line.empty() ? "" : ", ") + name + " " + h["phase"].value(name, std::string("?"));
      }
      std::printf("  %s\n", line.c_str());
      std::fflush(stdout);
      last_phase = h["phase"];
    }
    if (!h.value("active", false)) break;
  }
  bool ok = true;
  for (const auto& n : axes) ok = ok && st["homed"].value(n.get<std::string>(), false);
  if (as_json) {
    std::cout << json{{"homing", axes}, {"homed", st["homed"]}, {"failure", st["homing"]["failure"]},
                      {"act_mm", st["act_mm"]}}.dump() << std::endl;
  } else if (ok) {
    std::printf("homed %s; reference at %s mm (machine coordinates)\n", axes.dump().c_str(),
                st["ref_mm"].dump().c_str());
  } else {
    const json& f = st["homing"]["failure"];
    std::printf("homing failed: %s\n", f.is_string() ? f.get<std::string>().c_str() : "not homed");
  }
  return ok ? kExitOk : kExitError;
}

int cmd_run(Client& c, const RunOptions& o, bool as_json) {
  json req{{"cmd", "run"}};
  std::vector<int> lines;
  double total_mm = 0.0;
  std::size_t n_blocks = 0;
  if (!o.program.empty()) {
    if (o.wait) {
      // Load first (same as run with a program: the daemon's run loads it the same way): the load
      // reply carries the program length and motion-block count the progress display needs.
      const json lr = load_program(c, o.program, false, o.from_line);
      total_mm = lr.value("length_mm", 0.0);
      n_blocks = lr.value("motion_blocks", std::size_t{0});
      lines = motion_lines(o.program);
    } else {
      const json a = inline_program_args(o.program, slurp(o.program));
      if (a.is_null() || o.from_line > 0) {
        load_program(c, o.program, false, o.from_line);  // then `run` runs the loaded program
      } else {
        req.update(a);
      }
    }
  }
  // Install before the run starts: a Ctrl-C from here on holds instead of killing us mid-reply.
  if (o.wait) install_sigint();
  const json r = c.call(req);
  if (!o.wait) {
    print(r, as_json);
    return kExitOk;
  }
  const std::uint64_t job = r.at("job").get<std::uint64_t>();
  const bool tty = ::isatty(STDERR_FILENO) != 0;
  const bool show = !o.quiet;
  const auto t0 = std::chrono::steady_clock::now();
  const auto until = t0 + std::chrono::duration<double>(o.timeout_s);
  auto last_line = t0 - std::chrono::hours(1);
  double max_eps_um = 0.0;
  if (n_blocks == 0) n_blocks = lines.size();
  bool interrupted = false;
  int paused_line = -1;  // the programmed pause already announced
  for (;;) {
    if (g_interrupted != 0) {
      interrupted = true;
      break;
    }
    const json st = c.call({{"cmd", "status"}});
    if (job_ended(st, job)) break;
    const std::string s = st.at("state").get<std::string>();
    // A programmed pause (M0/M1, M6 tool change) is part of the program: say what it waits for
    // and keep waiting; `contourctl resume` continues it.
    if (st.contains("hold") && st["hold"].is_object()) {
      const int pl = st["hold"].value("line", 0);
      if (pl != paused_line && show) {
        paused_line = pl;
        std::string what = st["hold"].value("message", std::string());
        if (what.empty()) what = "program stop (M0/M1)";
        std::fprintf(stderr, "%srun: paused at line %d: %s (contourctl resume continues)\n",
                     tty ? "\r\033[K" : "", pl, what.c_str());
      }
    } else {
      paused_line = -1;
    }
    if (std::chrono::steady_clock::now() > until)
      throw ErrorReply("timed out waiting for the program");
    max_eps_um = std::max(max_eps_um, st.value("contour_error_um", 0.0));
    // The daemon's running figure for this job (true contour error to the planned path, from
    // every telemetry sample), not just the polled samples.
    if (st.contains("program") && st["program"].value("job", std::uint64_t{0}) == job) {
      max_eps_um = std::max(max_eps_um, st["program"].value("max_contour_error_um", 0.0));
    }
    const double prog = st.value("progress_mm", 0.0);
    // Block index from the current source line (status has no block index): motion blocks of the
    // file parsed here whose line is at or before it.
    const int line = st.value("line", 0);
    std::size_t block = 0;
    while (block < lines.size() && lines[block] <= line) ++block;
    block = std::min(block, n_blocks);
    // Fraction done: by path length when known, else by motion blocks.
    double frac = -1.0;
    if (total_mm > 0.0)
      frac = std::clamp(prog / total_mm, 0.0, 1.0);
    else if (n_blocks > 0)
      frac = static_cast<double>(block == 0 ? 0 : block - 1) / static_cast<double>(n_blocks);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double remaining = frac > 0.01 ? elapsed * (1.0 - frac) / frac : -1.0;
    if (show) {
      char info[200];
      std::snprintf(
          info, sizeof info, "%5.1f%%  block %zu/%s  %s elapsed  %s left  max |eps| %.1f um  %s",
          frac >= 0.0 ? 100.0 * frac : 0.0, block,
          n_blocks > 0 ? std::to_string(n_blocks).c_str() : "?", clock_str(elapsed).c_str(),
          clock_str(remaining).c_str(), max_eps_um, s.c_str());
      if (tty) {
        const int width =
            std::clamp(terminal_columns() - static_cast<int>(std::strlen(info)) - 4, 10, 40);
        const int fill = frac >= 0.0 ? static_cast<int>(std::lround(frac * width)) : 0;
        std::fprintf(stderr, "\r[%s%s] %s\033[K",
                     std::string(static_cast<std::size_t>(fill), '#').c_str(),
                     std::string(static_cast<std::size_t>(width - fill), '-').c_str(), info);
        std::fflush(stderr);
      } else if (std::chrono::steady_clock::now() - last_line >=
                 std::chrono::duration<double>(o.progress_interval_s)) {
        last_line = std::chrono::steady_clock::now();
        std::fprintf(stderr, "run: %s\n", info);
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(tty ? 100 : 50));
  }
  if (show && tty) std::fprintf(stderr, "\r\033[K");
  if (interrupted) {
    std::string what;
    try {
      c.call({{"cmd", "hold"}});
      what =
          "Ctrl-C: asked contourd to hold (feed hold, decelerating on the path). "
          "`contourctl resume` continues, `contourctl stop` ends the program.";
    } catch (const ErrorReply& e) {
      what = std::string("Ctrl-C: hold refused by contourd: ") + e.what();
    }
    std::cerr << "contourctl: " << what << '\n';
    const json res = c.call({{"cmd", "result"}, {"job", job}});
    if (as_json)
      print(res, true);
    else
      print_run_summary(res);
    return kExitInterrupted;
  }
  const json res = c.call({{"cmd", "result"}, {"job", job}});
  if (as_json)
    print(res, true);
  else
    print_run_summary(res);
  return res.value("completed", false) ? kExitOk : kExitError;
}

std::string watch_line(const json& st) {
  std::ostringstream o;
  char b[96];
  o << st.value("state", std::string("?"));
  if (st.value("jogging", false)) o << "(jog)";
  const char* names[] = {"X", "Y", "Z"};
  std::size_t i = 0;
  for (const auto& v : st.value("act_mm", json::array())) {
    std::snprintf(b, sizeof b, "  %s %9.3f", i < 3 ? names[i] : "?", v.get<double>());
    o << b;
    ++i;
  }
  std::snprintf(b, sizeof b, " mm  |eps| %7.1f um", st.value("contour_error_um", 0.0));
  o << b;
  for (const char* k : {"force_N", "force_n"}) {
    if (st.contains(k) && st[k].is_number()) {
      std::snprintf(b, sizeof b, "  F %7.1f N", st[k].get<double>());
      o << b;
    }
  }
  const json tm = st.value("timing", json::object());
  // "overruns" (missed deadlines) spelled out: "ovr" read as override.
  std::snprintf(b, sizeof b,
                "  late p99 %5.0f us  overruns %llu  feed %3.0f%%  rapid %3.0f%%  spindle %3.0f%%  line %d",
                tm.value("lateness_p99_us", 0.0),
                static_cast<unsigned long long>(tm.value("overruns", 0ULL)),
                100.0 * st.value("feed_override", 1.0), 100.0 * st.value("rapid_override", 1.0),
                100.0 * st.value("spindle_override", 1.0), st.value("line", 0));
  o << b;
  return o.str();
}

// Calls show() every interval_s seconds until Ctrl-C, or `count` times when count > 0
// (`watch`, `io --watch`).
template <class F>
void repeat_every(double interval_s, long count, F&& show) {
  install_sigint();
  for (long k = 0; count <= 0 || k < count; ++k) {
    if (g_interrupted != 0) break;
    show();
    if (count > 0 && k + 1 >= count) break;
    std::this_thread::sleep_for(std::chrono::duration<double>(interval_s));
  }
}

int cmd_watch(Client& c, double interval_s, long count, bool as_json) {
  const bool tty = ::isatty(STDOUT_FILENO) != 0 && !as_json;
  repeat_every(interval_s, count, [&] {
    const json st = c.call({{"cmd", "status"}});
    if (as_json) {
      std::cout << st.dump() << std::endl;
    } else if (tty) {
      std::cout << '\r' << watch_line(st) << "\033[K" << std::flush;
    } else {
      std::cout << watch_line(st) << std::endl;
    }
  });
  if (tty) std::cout << std::endl;
  return kExitOk;
}

// The `io` reply as a table; `cycle`: a "cycle N" line first (io --watch).
void print_io_table(const json& r, bool cycle) {
  if (cycle) std::printf("cycle %llu\n", static_cast<unsigned long long>(r.value("cycle", 0ULL)));
  std::printf("%-24s %-5s %-10s %-10s %s\n", "NAME", "TYPE", "DIRECTION", "VALUE", "SOURCE");
  for (const auto& sg : r.value("signals", json::array())) {
    std::string v = sg.contains("value") ? sg["value"].dump() : "?";
    if (sg.value("forced", false)) v += " (forced)";
    std::printf("%-24s %-5s %-10s %-10s %s\n", sg.value("name", std::string()).c_str(),
                sg.value("type", std::string()).c_str(), sg.value("direction", std::string()).c_str(),
                v.c_str(), sg.value("source", std::string()).c_str());
  }
  std::fflush(stdout);
}

constexpr const char* kFooter = R"(
Socket: --socket PATH, else $CONTOURD_SOCKET, else /run/contourd/contourd.sock when it exists, else
  ${XDG_RUNTIME_DIR:-/tmp}/contourd.sock (config/sim.yaml's default).

Exit status:
  0    success
  1    error reply from contourd, run not completed (FAULT/ESTOP/stopped), plot or analysis failed
  2    bad command line
  3    contourd not reachable: no socket at the path (not running), connection refused (stale
       socket), or the daemon closed the connection
  4    permission denied on the socket (join the socket's group; socket.mode in the config)
  130  run --wait interrupted by Ctrl-C: contourd was asked to hold the program

Progress (run --wait) and circle-test progress go to stderr: a bar on a terminal, a plain line
every --progress-interval seconds otherwise; --json prints only the final JSON object on stdout.

Gains keys (gains set): axis.<x|y|z|index>.<kp|ki_per_s|kd_s|ff>=V, coupling.<cp|ci_per_s|cd_s>=V,
  coupling=true|false, or the daemon's own keys for all axes: kp=0.6 | kp=0.6,0.6,0.6, cp=15 ...
  The daemon refuses gain changes while RUNNING (hold first) and unstable gains.

gains save: rewrites the gain VALUES under `control:` in the YAML config file in place
  (--file, default $CONTOURD_CONFIG or /etc/contourd/contourd.yaml; --output writes elsewhere),
  keeping comments, key order and layout; the previous file is kept as FILE.bak. Both are written
  atomically (temporary file in the same directory, fsync, rename) with the config's owner, group
  and mode kept (a root:contourd 0640 config stays so); refused when they cannot be kept. Chosen over a
  separate overrides file because the config loader has no include key: one file stays the
  single source of truth, and `contourd --check-config FILE` validates it. The edited text is
  validated and read back with contourd's own loader before anything is written. Mapping:
  kp -> control.kp (law p) or control.pid.* (law pid); coupling on/off -> controller: ccc | p;
  cp/ci_per_s/cd_s -> control.coupling.*; ff -> control.feed_forward (must be equal on all axes).
  Axes measured by `identify` since contourd started: their measured gain, time constant and
  delay become machine.axes[].sim (the model of the Smith predictor and the stability check,
  applied at the next start) and are recorded in machine.axes[].identified, which contourd checks
  at start-up (a configured delay that contradicts it is a warning naming the axis);
  --no-identified leaves the drive models alone.

Plots (gnuplot, PNG; plot CSV... --plot F.png --kind K, or record stop --plot F.png):
  error   contour error vs time (several CSVs overlay, --label per CSV)
  path    XY path: reference vs actual with the contour error magnified xN (--magnify N, auto)
  path3d  the same in 3-D
  force   force vs reference (when the CSV has force columns) and feed override vs time
  timing  servo loop timing from the daemon's status (no CSV)
)";

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"contourctl: client of the contourd command socket"};
  // The daemon's command table (daemon/command_table.hpp) names and describes the socket
  // commands: the same summaries as daemon/PROTOCOL.md.
  app.footer(std::string("\nSocket commands (contourd's command table, daemon/PROTOCOL.md; contourctl\n"
                         "subcommands of the same name send them):\n") +
             contour::daemon::command_summary_text() + kFooter);
  auto summary = [](const char* name, const char* fallback) {
    const contour::daemon::CommandSpec* c = contour::daemon::find_command(name);
    return c != nullptr ? std::string(c->summary) : std::string(fallback);
  };
  std::string socket_path;
  bool as_json = false;
  // Global options go before or after the subcommand (`contourctl --json status` ==
  // `contourctl status --json`): an option a subcommand does not know falls through to the app.
  // Subcommands inherit this setting when they are created, so it comes first.
  app.fallthrough();
  app.add_option("--socket", socket_path,
                 "command socket (see below; before or after the command)");
  app.add_flag("--json", as_json,
               "print JSON (one object per line) instead of text (before or after the command)");
  app.require_subcommand(1);
  RunOptions ro;
  std::string program;
  std::string axis;
  double vel = 0.0, dist = 0.0, pos = 0.0;
  std::optional<double> pct_feed, pct_rapid, pct_spindle;
  std::string jog_dir;
  std::string home_axis;
  bool home_all = false;
  std::vector<std::string> gains_args, record_args, force_args, csvs, labels;
  bool gains_no_identified = false;
  std::string gains_file, gains_output, plot_png, plot_kind = "error", plot_title, plot_program;
  double magnify = 0.0, watch_interval = 0.5;
  long watch_count = 0;
  CircleTestOptions co;
  bool both = false, ccw_flag = false, cw_flag = false;

  app.add_subcommand("status", summary("status", "machine state"));
  std::string sw_block_delete, sw_optional_stop, sw_single_block;
  auto* sw = app.add_subcommand(
      "switches", summary("switches", "block delete, optional stop and single block switches") +
                      " (switches [--block-delete on|off] [--optional-stop on|off] [--single-block on|off])");
  sw->add_option("--block-delete", sw_block_delete, "on: lines starting with '/' are skipped")
      ->check(CLI::IsMember({"on", "off"}));
  sw->add_option("--optional-stop", sw_optional_stop, "on: M1 holds")->check(CLI::IsMember({"on", "off"}));
  sw->add_option("--single-block", sw_single_block, "on: the program stops before each new line (resume runs it)")
      ->check(CLI::IsMember({"on", "off"}));
  auto* load = app.add_subcommand("load", summary("load", "validate and plan a part program"));
  load->add_option("PROGRAM", program, "RS274/NGC file")->required();
  bool load_preview = false;
  std::string preview_png;
  load->add_flag("--preview", load_preview,
                 "also plan the whole program: extents (machine and work), estimated time, blocks, tools");
  load->add_option("--plot", preview_png, "with --preview: plot the toolpath to this PNG");
  auto* run = app.add_subcommand("run", "run the loaded program (or load PROGRAM first)");
  run->add_option("PROGRAM", ro.program, "RS274/NGC file");
  run->add_option("--from-line", ro.from_line,
                  "run from line N: the lines before it set the modal state only; the run starts "
                  "with a safe approach (up to the clearance, across, down at feed)")
      ->check(CLI::Range(1L, 100000000L));
  run->add_flag("--wait", ro.wait,
                "show progress until the program ends, then its figures; Ctrl-C holds");
  run->add_option("--timeout", ro.timeout_s, "seconds to wait with --wait");
  run->add_flag("--quiet", ro.quiet, "no progress output");
  run->add_option("--progress-interval", ro.progress_interval_s,
                  "seconds between progress lines when not a TTY");
  for (const char* c :
       {"hold", "resume", "stop", "estop", "reset", "enable", "disable", "shutdown"}) {
    app.add_subcommand(c, summary(c, c));
  }
  auto* jog = app.add_subcommand(
      "jog", "jog AXIS VELOCITY_MM_MIN DISTANCE_MM, or jog AXIS VELOCITY_MM_MIN --continuous +|-: "
             "moves while this command runs (Ctrl-C, `contourctl stop`, or the soft limit ends it)");
  jog->add_option("AXIS", axis)->required();
  jog->add_option("VELOCITY_MM_MIN", vel)->required();
  jog->add_option("DISTANCE_MM", dist);
  jog->add_option("--continuous", jog_dir,
                  "+ or -: jog until Ctrl-C / stop / the soft limit; the daemon brakes the axis when "
                  "this client goes away (dead-man)")
      ->check(CLI::IsMember({"+", "-"}));
  auto* home = app.add_subcommand(
      "home", summary("home", "home AXIS, or home --all: switch search, latch, move to the home "
                              "position, in home.sequence order; prints the progress and waits "
                              "until homed (stop aborts)"));
  home->add_option("AXIS", home_axis);
  home->add_flag("--all", home_all, "every axis with a homing method");
  auto* setpos =
      app.add_subcommand("set-position", "set an axis position (sim / absolute encoders)");
  setpos->add_option("AXIS", axis)->required();
  setpos->add_option("POSITION_MM", pos)->required();
  auto* gains =
      app.add_subcommand("gains", "gains get | gains set KEY=V ... | gains save [--file CONFIG]");
  gains->add_option("ARGS", gains_args)->required();
  gains->add_option("--file", gains_file, "gains save: config file to update");
  gains->add_option("--output", gains_output, "gains save: write the edited config here instead");
  gains->add_flag("--no-identified", gains_no_identified,
                  "gains save: leave the drive models (machine.axes[].sim) as they are, even for "
                  "axes measured by identify");
  auto* ovr = app.add_subcommand(
      "override", summary("override", "feed, rapid and spindle override in percent") +
                      " (override [FEED%] [--rapid %] [--spindle %])");
  ovr->add_option("PERCENT", pct_feed, "feed override");
  ovr->add_option("--rapid", pct_rapid, "rapid override (G0), up to interpolator.rapid_override_max_percent");
  ovr->add_option("--spindle", pct_spindle, "spindle override, spindle.override_min/max_percent");
  auto* rec =
      app.add_subcommand("record",
                         "record start [NAME] | record stop [--plot F.png --kind K]: the daemon "
                         "writes NAME into its telemetry directory and replies with the path");
  rec->add_option("ARGS", record_args)->required();
  rec->add_option("--plot", plot_png, "record stop: plot the recorded CSV to this PNG");
  rec->add_option("--kind", plot_kind, "error | path | path3d | force | timing");
  rec->add_option("--magnify", magnify, "path plots: error magnification (default automatic)");
  rec->add_option("--title", plot_title, "extra title line");
  rec->add_option("--program", plot_program,
                  "path plots: also draw this part program (programmed path)");
  auto* plot = app.add_subcommand("plot", "plot telemetry CSV(s) to a PNG");
  plot->add_option("CSV", csvs,
                   "telemetry CSV file(s) written by `record` (none for --kind timing)");
  plot->add_option("--plot,-o", plot_png, "output PNG")->required();
  plot->add_option("--kind", plot_kind, "error | path | path3d | force | timing");
  plot->add_option("--label", labels, "legend label per CSV (repeat)");
  plot->add_option("--magnify", magnify, "path plots: error magnification (default automatic)");
  plot->add_option("--title", plot_title, "extra title line");
  plot->add_option("--program", plot_program,
                   "path plots: also draw this part program (programmed path)");
  auto* watch = app.add_subcommand("watch", "refreshing status line (Ctrl-C ends)");
  watch->add_option("--interval", watch_interval, "seconds between updates")
      ->check(CLI::Range(0.01, 3600.0));
  watch->add_option("--count", watch_count, "stop after N updates (0: until Ctrl-C)");
  auto* force = app.add_subcommand("force", "force on [NEWTON] | force off | force ref NEWTON | force status");
  force->add_option("ARGS", force_args)->required();
  // Soft PLC (issue 20).
  std::vector<std::string> io_args, plc_args;
  auto* io = app.add_subcommand("io", "soft PLC I/O image | io force NAME VALUE | io unforce NAME|all");
  io->add_option("ARGS", io_args);
  bool io_watch = false;
  io->add_flag("--watch", io_watch, "redraw the image every --interval seconds (Ctrl-C ends)");
  io->add_option("--interval", watch_interval, "--watch: seconds between updates")->check(CLI::Range(0.01, 3600.0));
  io->add_option("--count", watch_count, "--watch: stop after N updates (0: until Ctrl-C)");
  // Offsets, tools, touch-off, MDI (issue 18).
  std::vector<std::string> offsets_args, tools_args;
  std::string touch_axis, touch_offset, mdi_text;
  double touch_value = 0.0;
  auto* offsets = app.add_subcommand(
      "offsets", "offsets | offsets set G54..G59.3|G92|G28|G30 X=V [Y=V] [Z=V] (mm)");
  offsets->add_option("ARGS", offsets_args);
  auto* tools = app.add_subcommand(
      "tools", "tools | tools set N [length=MM] [diameter=MM] [pocket=P] [comment=TEXT] | tools remove N");
  tools->add_option("ARGS", tools_args);
  auto* touch = app.add_subcommand(
      "touch-off", "touch-off AXIS VALUE [--offset G54]: the axis' position reads VALUE there");
  touch->add_option("AXIS", touch_axis)->required();
  touch->add_option("VALUE", touch_value)->required();
  touch->add_option("--offset", touch_offset, "G54..G59.3 (default: the active system)");
  std::string ident_axis;
  auto* ident = app.add_subcommand(
      "identify", "identify AXIS [--plot F.png]: measure the axis' drive (gain, time constant, "
                  "delay) with a small move at rest (READY)");
  ident->add_option("AXIS", ident_axis)->required();
  ident->add_option("--plot", plot_png, "plot the experiment (position and velocity target) to this PNG");
  auto* mdi = app.add_subcommand("mdi", "mdi \"G0 X10 Y5\": run G-code line(s) now (READY)");
  mdi->add_option("TEXT", mdi_text)->required();
  auto* plc = app.add_subcommand("plc", "plc status: PLC programs' scan times, couplers, handshakes, faults");
  plc->add_option("ARGS", plc_args)->required();
  auto* circle = app.add_subcommand(
      "circle-test", "seed 003 circle test: per-axis gain and time constant, matched gains");
  circle->add_option("--radius", co.radius_mm, "circle radius (mm)");
  circle->add_option("--feed", co.feed_mm_min, "feed (mm/min)");
  circle->add_flag("--cw", cw_flag, "clockwise (default)");
  circle->add_flag("--ccw", ccw_flag, "counter-clockwise");
  circle->add_flag("--both", both, "CW then CCW; estimates averaged");
  circle->add_option("--turns", co.turns, "revolutions per run (first skipped, >= 2)");
  circle->add_flag("--apply", co.apply, "set the proposed matched gains (gains set)");
  circle->add_option("--plot", co.plot_png,
                     "polar plot of the radial deviation (with --apply: before/after)");
  circle->add_flag("--keep-csv", co.keep_csv,
                   "keep the recorded CSVs (in the daemon's telemetry directory; paths in the report)");
  circle->add_option("--delay-cycles", co.delay_cycles,
                     "bus transport delay in cycles (default 1, as config/sim.yaml)");
  bool no_comp = false;
  circle->add_flag("--no-delay-compensation", no_comp,
                   "the daemon's config has control.delay_compensation: false");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? kExitOk : kExitUsage;
  }
  if (socket_path.empty()) socket_path = default_socket();
  const std::string cmd = app.get_subcommands().front()->get_name();
  co.cw = cw_flag || both || !ccw_flag;
  co.ccw = ccw_flag || both;
  co.delay_compensation = !no_comp;
  PlotOptions po;
  po.labels = labels;
  po.magnify = magnify;
  po.title = plot_title;
  po.program = plot_program;
  try {
    // Commands that may run without a daemon.
    if (cmd == "plot") {
      const PlotKind kind = parse_plot_kind(plot_kind);
      std::string desc;
      if (kind == PlotKind::kTiming) {
        Client c(socket_path);
        desc = plot_timing(c.call({{"cmd", "status"}}), plot_png, po);
      } else {
        if (csvs.empty()) {
          std::cerr << "contourctl: plot --kind " << plot_kind << " needs at least one CSV\n";
          return kExitUsage;
        }
        std::vector<TelemetryCsv> runs;
        for (const auto& f : csvs) runs.push_back(read_telemetry_csv(f));
        desc = plot_csv(kind, runs, plot_png, po);
      }
      if (as_json)
        std::cout << json{{"plot", plot_png}, {"what", desc}}.dump() << std::endl;
      else
        std::cout << "plot: " << plot_png << " (" << desc << ")\n";
      return kExitOk;
    }
    if (cmd == "gains" && !gains_args.empty() && gains_args[0] == "save") {
      std::string file = gains_file;
      if (file.empty()) {
        const char* e = std::getenv("CONTOURD_CONFIG");
        file = e != nullptr && *e != '\0' ? e : "/etc/contourd/contourd.yaml";
      }
      Client c(socket_path);
      json g = c.call({{"cmd", "gains"}});
      if (gains_no_identified) g.erase("identified");
      const std::string edited = config_with_gains(slurp(file), file, g);
      const std::string out = gains_output.empty() ? file : gains_output;
      // Atomic, and owner, group and mode kept (the backup's too): a config readable only by the
      // daemon's group stays so.
      try {
        if (gains_output.empty()) write_file_like(file + ".bak", slurp(file), file);
        write_file_like(out, edited, fs::exists(out) ? out : file);
      } catch (const std::runtime_error& e) {
        throw ErrorReply(e.what());
      }
      if (as_json)
        std::cout << json{{"saved", out}, {"gains", g}}.dump() << std::endl;
      else
        std::cout
            << "gains saved to " << out
            << (gains_output.empty() ? " (previous: " + file + ".bak)" : "")
            << "; `contourd --check-config " << out
            << "` validates it; SIGHUP makes contourd reload it when it is its --config file\n";
      if (!as_json && g.contains("identified")) {
        for (const auto& [ax_name, m] : g["identified"].items()) {
          char b[96];
          std::snprintf(b, sizeof b, "gain_per_s %.10g, tau_ms %.10g, delay_cycles %d",
                        m["gain_per_s"].get<double>(), m["tau_ms"].get<double>(),
                        m["delay_cycles"].get<int>());
          std::cout << "axis " << ax_name << ": measured drive model stored (machine.axes[].sim and "
                    << ".identified): " << b
                    << "; a drive model needs a restart of contourd to take effect\n";
        }
      }
      return kExitOk;
    }
    Client c(socket_path);
    json req{{"cmd", cmd}};
    if (cmd == "run") return cmd_run(c, ro, as_json);
    if (cmd == "watch") return cmd_watch(c, watch_interval, watch_count, as_json);
    if (cmd == "circle-test") {
      const json r = run_circle_test(c, co);
      if (as_json)
        std::cout << r.dump() << std::endl;
      else
        std::cout << format_circle_report(r);
      return kExitOk;
    }
    if (cmd == "load") {
      if (!preview_png.empty() && !load_preview) {
        std::cerr << "contourctl load: --plot needs --preview\n";
        return 2;
      }
      const json r = load_program(c, program, load_preview);
      if (load_preview && !as_json) {
        std::cout << format_preview(r);
      } else {
        print(r, as_json);
      }
      if (!preview_png.empty()) {
        PlotOptions o;
        std::cout << "plot: " << plot_preview(r, preview_png, o) << " -> " << preview_png << '\n';
      }
      return kExitOk;
    } else if (cmd == "jog") {
      req["axis"] = axis;
      req["velocity_mm_min"] = vel;
      if (!jog_dir.empty()) {
        // Continuous: this connection is the dead-man. It renews the jog with a status request
        // every 100 ms and ends when the jog does; Ctrl-C closes it and the daemon brakes.
        req["continuous"] = jog_dir;
        const json r = c.call(req);
        if (as_json) print(r, true);
        else std::printf("jog: %s %s continuously (Ctrl-C stops it)\n", r.value("axis", axis).c_str(), jog_dir.c_str());
        std::fflush(stdout);
        for (int n = 0;; ++n) {
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
          const json st = c.call({{"cmd", "status"}});
          if (!as_json && n % 5 == 0 && st.contains("act_mm")) {
            std::printf("  position %s mm\n", st["act_mm"].dump().c_str());
            std::fflush(stdout);
          }
          if (!st.value("jogging", false)) break;
        }
        if (!as_json) std::printf("jog ended\n");
        return kExitOk;
      }
      if (!jog->count("DISTANCE_MM")) {
        std::cerr << "contourctl: jog AXIS VELOCITY_MM_MIN DISTANCE_MM, or --continuous +|-\n";
        return kExitUsage;
      }
      req["distance_mm"] = dist;
    } else if (cmd == "home") {
      return cmd_home(c, home_axis, home_all, as_json);
    } else if (cmd == "set-position") {
      req["axis"] = axis;
      req["position_mm"] = pos;
    } else if (cmd == "switches") {
      if (!sw_block_delete.empty()) req["block_delete"] = sw_block_delete == "on";
      if (!sw_optional_stop.empty()) req["optional_stop"] = sw_optional_stop == "on";
      if (!sw_single_block.empty()) req["single_block"] = sw_single_block == "on";
    } else if (cmd == "override") {
      if (!pct_feed && !pct_rapid && !pct_spindle) {
        std::cerr << "contourctl override: give FEED%, --rapid % or --spindle %\n";
        return 2;
      }
      if (pct_feed) req["percent"] = *pct_feed;
      if (pct_rapid) req["rapid_percent"] = *pct_rapid;
      if (pct_spindle) req["spindle_percent"] = *pct_spindle;
    } else if (cmd == "force") {
      // force on [N] | force off | force ref N | force status (query): the daemon's `force`
      // command takes action "on"/"off" and/or reference_N.
      const std::string& a = force_args[0];
      if (a == "on" || a == "off") {
        req["action"] = a;
      } else if (a != "ref" && a != "status") {
        std::cerr << "contourctl: force on [NEWTON] | force off | force ref NEWTON | force status\n";
        return kExitUsage;
      }
      if (force_args.size() > 1) {
        char* end = nullptr;
        const double n = std::strtod(force_args[1].c_str(), &end);
        if (end == force_args[1].c_str() || *end != '\0' || !std::isfinite(n)) {
          std::cerr << "contourctl: force: '" << force_args[1] << "' is not a force in newtons\n";
          return kExitUsage;
        }
        req["reference_N"] = n;
      } else if (a == "ref") {
        std::cerr << "contourctl: force ref NEWTON\n";
        return kExitUsage;
      }
    } else if (cmd == "io") {
      const std::size_t n = io_args.size();
      if (n == 0) {
        // One image, or with --watch one per --interval: a terminal redraws in place, a pipe
        // gets each image after a "cycle N" line (--json: one object per line).
        const bool tty = io_watch && ::isatty(STDOUT_FILENO) != 0 && !as_json;
        auto show = [&] {
          const json r = c.call(req);
          if (as_json) {
            print(r, true);
            return;
          }
          if (tty) std::printf("\033[H\033[2J");
          print_io_table(r, io_watch);
        };
        if (io_watch) {
          repeat_every(watch_interval, watch_count, show);
        } else {
          show();
        }
        return kExitOk;
      }
      if (io_args[0] == "force" && n == 3) {
        req["action"] = "force";
        req["name"] = io_args[1];
        req["value"] = io_args[2];
      } else if (io_args[0] == "unforce" && n == 2) {
        req["action"] = "unforce";
        req["name"] = io_args[1];
      } else {
        std::cerr << "contourctl: io | io force NAME VALUE | io unforce NAME|all\n";
        return kExitUsage;
      }
      const json r = c.call(req);
      if (as_json)
        print(r, true);
      else
        std::cout << "io: " << r.value("name", std::string()) << " "
                  << (r.value("forced", false) ? "forced to " + r["value"].dump() : "unforced") << '\n';
      return kExitOk;
    } else if (cmd == "offsets" || cmd == "tools") {
      const auto& a = cmd == "offsets" ? offsets_args : tools_args;
      const std::string usage =
          cmd == "offsets" ? "contourctl: offsets | offsets set G54..G59.3|G92|G28|G30 X=V [Y=V] [Z=V]\n"
                           : "contourctl: tools | tools set N [length=MM] [diameter=MM] [pocket=P] "
                             "[comment=TEXT] | tools remove N\n";
      auto number_of = [](const std::string& v) {
        std::size_t used = 0;
        const double d = std::stod(v, &used);
        if (used != v.size()) throw std::invalid_argument(v);
        return d;
      };
      try {
        if (!a.empty()) {
          if (a[0] != "set" && !(cmd == "tools" && a[0] == "remove")) throw std::invalid_argument(a[0]);
          if (a.size() < 2) throw std::invalid_argument("missing argument");
          if (cmd == "offsets") {
            req["set"] = a[1];
          } else {
            req[a[0]] = number_of(a[1]);
          }
          for (std::size_t i = 2; i < a.size(); ++i) {
            const auto eq = a[i].find('=');
            if (eq == std::string::npos || a[0] == "remove") throw std::invalid_argument(a[i]);
            std::string k = a[i].substr(0, eq);
            const std::string v = a[i].substr(eq + 1);
            if (cmd == "offsets") {
              for (auto& ch : k) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
              req[k] = number_of(v);
            } else if (k == "comment") {
              req[k] = v;
            } else if (k == "length" || k == "diameter") {
              req[k + "_mm"] = number_of(v);
            } else {
              req[k] = number_of(v);
            }
          }
        }
      } catch (const std::exception&) {
        std::cerr << usage;
        return kExitUsage;
      }
      const json r = c.call(req);
      if (as_json) {
        print(r, true);
      } else if (cmd == "offsets") {
        const json& o = r["offsets"];
        std::cout << "active: " << o.value("active", std::string()) << '\n';
        for (const char* k : {"G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3", "G92", "G28", "G30"})
          std::cout << k << ": " << o[k].dump() << '\n';
        std::cout << "G92 applied: " << (o.value("G92_applied", false) ? "yes" : "no") << '\n';
      } else {
        std::cout << "tool in spindle: " << r.value("tool", 0) << '\n';
        for (const auto& t : r["tools"]) {
          std::printf("T%-3d P%-3d length %.4f mm  diameter %.4f mm  %s\n", t["number"].get<int>(),
                      t["pocket"].get<int>(), t["length_mm"].get<double>(),
                      t["diameter_mm"].get<double>(), t["comment"].get<std::string>().c_str());
        }
      }
      return kExitOk;
    } else if (cmd == "touch-off") {
      req["axis"] = touch_axis;
      req["value"] = touch_value;
      if (!touch_offset.empty()) req["offset"] = touch_offset;
      const json r = c.call(req);
      if (as_json)
        print(r, true);
      else
        std::cout << "touch-off: " << r["axis"].get<std::string>() << " reads " << r["value"].get<double>()
                  << " mm in " << r["offset"].get<std::string>() << '\n';
      return kExitOk;
    } else if (cmd == "identify") {
      req["axis"] = ident_axis;
      json r = c.call(req);
      if (!plot_png.empty()) {
        PlotOptions ipo;
        ipo.title = plot_title;
        std::cerr << "plot: " << plot_identify(r, plot_png, ipo) << " -> " << plot_png << '\n';
      }
      if (as_json) {
        print(r, true);
      } else {
        std::printf("%s: K %.3f 1/s (velocity gain %.4f), tau %.3f ms, delay %d cycles (confidence %.2f); "
                    "configured K %.3f, tau %.3f ms, delay %d: %s\n",
                    r["axis"].get<std::string>().c_str(), r["gain_per_s"].get<double>(),
                    r["velocity_gain"].get<double>(), r["tau_ms"].get<double>(),
                    r["delay_cycles"].get<int>(), r["delay_confidence"].get<double>(),
                    r["configured"]["gain_per_s"].get<double>(), r["configured"]["tau_ms"].get<double>(),
                    r["configured"]["delay_cycles"].get<int>(), r["verdict"].get<std::string>().c_str());
      }
      return kExitOk;
    } else if (cmd == "mdi") {
      req["text"] = mdi_text;
      print(c.call(req), as_json);
      return kExitOk;
    } else if (cmd == "plc") {
      if (plc_args.size() != 1 || plc_args[0] != "status") {
        std::cerr << "contourctl: plc status\n";
        return kExitUsage;
      }
      print(c.call({{"cmd", "plc_status"}}), as_json);
      return kExitOk;
    } else if (cmd == "record") {
      if (record_args[0] != "start" && record_args[0] != "stop") {
        std::cerr << "contourctl: record start [NAME] | record stop [--plot F.png]\n";
        return kExitUsage;
      }
      req["action"] = record_args[0];
      // A bare NAME is a file in the daemon's telemetry directory; a PATH must be inside it (the
      // daemon refuses any other, naming the directory). The reply names the file either way.
      if (record_args.size() > 1) {
        const std::string& a = record_args[1];
        if (a.find('/') == std::string::npos)
          req["name"] = a;
        else
          req["path"] = fs::absolute(a).string();
      }
      const json r = c.call(req);
      if (record_args[0] == "stop" && !plot_png.empty()) {
        const PlotKind kind = parse_plot_kind(plot_kind);
        const std::string csv = r.value("path", std::string());
        std::string desc;
        if (kind == PlotKind::kTiming) {
          desc = plot_timing(c.call({{"cmd", "status"}}), plot_png, po);
        } else {
          if (csv.empty())
            throw ErrorReply("record stop: no recording was active, nothing to plot");
          desc = plot_csv(kind, {read_telemetry_csv(csv)}, plot_png, po);
        }
        json out = r;
        out["plot"] = plot_png;
        if (as_json)
          print(out, true);
        else
          std::cout << "recording stopped: " << csv << "\nplot: " << plot_png << " (" << desc
                    << ")\n";
        return kExitOk;
      }
      print(r, as_json);
      return kExitOk;
    } else if (cmd == "gains") {
      if (gains_args[0] == "set") {
        const json cur = c.call({{"cmd", "gains"}});
        try {
          req["set"] = gains_set_request({gains_args.begin() + 1, gains_args.end()}, cur);
        } catch (const std::invalid_argument& e) {
          std::cerr << "contourctl: " << e.what() << '\n';
          return kExitUsage;
        }
      } else if (gains_args[0] != "get") {
        std::cerr << "contourctl: gains get | gains set KEY=V ... | gains save [--file CONFIG]\n";
        return kExitUsage;
      }
      const json g = c.call(req);
      if (as_json)
        print(g, true);
      else
        std::cout << format_gains(g);
      return kExitOk;
    }
    const json r = c.call(req);
    // `force status` is a query: printed whole, like status.
    if (cmd == "status" || cmd == "load" || (cmd == "force" && force_args[0] == "status"))
      print(r, as_json);
    else
      print_confirmation(cmd, r, as_json);
    return kExitOk;
  } catch (const Unreachable& e) {
    std::cerr << "contourctl: " << e.what() << '\n';
    return e.exit_code;
  } catch (const ErrorReply& e) {
    if (as_json) std::cout << json{{"error", e.what()}}.dump() << std::endl;
    std::cerr << "contourctl: " << cmd << ": " << e.what() << '\n';
    return kExitError;
  } catch (const std::invalid_argument& e) {
    std::cerr << "contourctl: " << cmd << ": " << e.what() << '\n';
    return kExitUsage;
  } catch (const std::exception& e) {
    std::cerr << "contourctl: " << cmd << ": " << e.what() << '\n';
    return kExitError;
  }
}
