#pragma once
// The scope channel: contourd's telemetry samples (daemon/telemetry.hpp encode_stream_sample, in
// the command server's batch lines) decoded into columns of named signals, the derived ones
// computed here (outside the RT loop), and serialised per client as one notify_scope message:
//   {"jsonrpc":"2.0","method":"notify_scope","params":{
//      "cycle":[...], "job":[...], "line":[...], "signals":{NAME:[...], ...},
//      "decimation":N, "dropped":D, "daemon_dropped":S, "gaps":G}}
// null where a value is unknown (true error outside a program, lateness before the daemon sends
// it). D = samples this client's queue dropped (slow browser); S = contourd's count for
// contour-web's subscription; G = cycles missing between samples contour-web received.
#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace contour::web {

struct SignalInfo {
  const char* name;
  const char* unit;
  int decimals;  // fixed-point digits on the wire
  const char* meaning;
};

// Every signal a client may ask for (subscribe {topic: "telemetry", signals: [...]}).
[[nodiscard]] const std::vector<SignalInfo>& scope_signals();
[[nodiscard]] int signal_index(const std::string& name);  // -1 if unknown

struct ScopeBlock {
  std::vector<std::uint64_t> cycle;
  std::vector<std::uint64_t> job;
  std::vector<int> line;
  std::vector<std::vector<double>> columns;  // [signal index][sample], NaN unknown
  std::uint64_t daemon_dropped = 0;
  std::uint64_t gaps = 0;
  [[nodiscard]] std::size_t size() const { return cycle.size(); }
};

class ScopeDecoder {
 public:
  // A telemetry line from contourd: a batch {"event":"telemetry","samples":[...],"dropped",
  // "source_dropped"} or (older contourd) one sample {"event":"telemetry","cycle",...,"eps_mm"}.
  // Appends to `out`; malformed samples are skipped and counted.
  void decode(const nlohmann::json& line, ScopeBlock& out);
  [[nodiscard]] std::uint64_t malformed() const { return malformed_; }
  [[nodiscard]] std::uint64_t gaps() const { return gaps_; }

 private:
  void add(const nlohmann::json& s, ScopeBlock& out, double scale_eps_to_um, bool eps_in_mm);
  bool have_prev_ = false;
  std::uint64_t prev_cycle_ = 0;
  double prev_t_s_ = 0.0;
  std::array<double, 3> prev_ref_{};
  std::uint64_t malformed_ = 0;
  std::uint64_t gaps_ = 0;
};

// One client's notify_scope message text (signals by index, every sample whose cycle is a
// multiple of `decimation`). Returns "" when no sample passes. *samples = samples in it.
[[nodiscard]] std::string scope_message(const ScopeBlock& b, const std::vector<int>& signals,
                                        std::uint32_t decimation, std::uint64_t client_dropped,
                                        std::size_t* samples);

}  // namespace contour::web
