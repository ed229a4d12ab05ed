#pragma once
// Simulated dynamometer: a Modbus TCP server (libmodbus) on its own thread, serving the force of a
// first-order cutting model (seed 001 section 2: P_f = K_f/(tau_f s + 1) from feed, P_s =
// K_s/(tau_s s + 1) from spindle speed, around an operating point) plus tooth-passing harmonics
// (Fig 2.2), white noise and a material step at a path position. Registers follow the same
// RegisterMap the reader uses, encoded with drivers/modbus/register_codec (never libmodbus' float
// setters: swapped words in Debian's 3.1.6).
//
// Thread-safety: setters may be called from any thread; the model is evaluated at each request,
// on the server thread. Fault injection: no reply, delayed reply, exception reply, connection drop
// (set_fault: until changed), and one-shot faults on top of it (inject_*: contour-machine-sim
// --storm), which take precedence while active.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "drivers/modbus/register_map.hpp"

namespace contour::sim {

struct ForceModelParams {
  // Operating point of the linearisation.
  double feed0_mm_min = 300.0;
  double spindle0_rpm = 3000.0;
  double force0_N = 400.0;             // resultant mean force at the operating point
  double k_feed_N_per_mm_min = 1.0;    // K_f
  double tau_feed_s = 0.05;            // tau_f
  double k_spindle_N_per_rpm = -0.05;  // K_s (< 0: force falls as speed rises)
  double tau_spindle_s = 0.2;          // tau_s
  int teeth = 4;
  // Tooth-passing harmonics: amplitude relative to the mean force, harmonic k at k * z * n / 60 Hz.
  std::vector<double> harmonics{0.4, 0.15};
  double noise_std_N = 2.0;
  // Material step: beyond `step_at_mm` of path, the mean force is multiplied by `step_factor`.
  double step_at_mm = 1e300;
  double step_factor = 1.0;
  // Share of the resultant on each channel (Fx, Fy, Fz).
  std::array<double, drivers::modbus::kForceChannels> channel_ratio{1.0, 0.5, 0.3};
  std::uint32_t seed = 1;
};

enum class FaultMode { kNone, kNoReply, kDelay, kException, kDropConnection };

class DynamometerServer {
 public:
  DynamometerServer(drivers::modbus::RegisterMap map, ForceModelParams model, int unit_id = 1);
  ~DynamometerServer();
  DynamometerServer(const DynamometerServer&) = delete;
  DynamometerServer& operator=(const DynamometerServer&) = delete;

  // Listens on host:port (port 0: any free port, see port()). Throws std::runtime_error with the
  // endpoint and errno text if it cannot listen. Restartable after stop() (same port if port 0
  // was given and a port was bound before).
  void start(const std::string& host = "127.0.0.1", int port = 0);
  void stop();
  [[nodiscard]] int port() const noexcept { return port_.load(); }
  [[nodiscard]] bool running() const noexcept { return thread_.joinable(); }

  // Model inputs.
  void set_feed(double feed_mm_min);
  void set_spindle(double spindle_rpm);
  void set_path_position(double path_mm);
  // Fixed forces for decode tests (no dynamics, harmonics or noise); nullopt returns to the model.
  void set_fixed_forces(std::optional<std::array<double, drivers::modbus::kForceChannels>> f_N);
  void set_status_valid(bool valid);

  void set_fault(FaultMode mode, std::chrono::milliseconds delay = std::chrono::milliseconds(0),
                 int exception_code = 4);
  // One-shot faults (any thread). No reply to any request for `d` of wall time from now (the
  // requests are read and dropped); an exception reply (`code`, 4 = server device failure) to
  // each of the next `count` requests; closing the connection that carries the next request,
  // without a reply. A no-reply window defers the other two; a pending disconnect goes before
  // pending exceptions.
  void inject_no_reply(std::chrono::milliseconds d);
  void inject_exceptions(int count, int code = 4);
  void inject_disconnect();
  [[nodiscard]] std::uint64_t requests() const noexcept { return requests_.load(); }
  // Last forces served (N), per channel.
  [[nodiscard]] std::array<double, drivers::modbus::kForceChannels> last_forces() const;
  // Mean (harmonic- and noise-free) resultant force the model would serve now.
  [[nodiscard]] double mean_force_N() const;

 private:
  void run(int listen_fd);
  void update_registers();  // server thread

  drivers::modbus::RegisterMap map_;
  ForceModelParams p_;
  int unit_id_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<int> port_{0};
  std::atomic<std::uint64_t> requests_{0};

  mutable std::mutex mu_;  // guards everything below
  double feed_mm_min_;
  double spindle_rpm_;
  double path_mm_ = 0.0;
  double x_feed_N_ = 0.0;  // first-order states (deviation from force0)
  double x_spindle_N_ = 0.0;
  double phase_rad_ = 0.0;  // tooth-passing phase
  std::chrono::steady_clock::time_point last_eval_{};
  bool evaluated_ = false;
  std::optional<std::array<double, drivers::modbus::kForceChannels>> fixed_;
  bool status_valid_ = true;
  FaultMode fault_ = FaultMode::kNone;
  std::chrono::milliseconds delay_{0};
  int exception_code_ = 4;
  std::chrono::steady_clock::time_point no_reply_until_{};
  int exceptions_left_ = 0;
  int injected_exception_code_ = 4;
  bool disconnect_pending_ = false;
  std::array<double, drivers::modbus::kForceChannels> last_{};
  std::mt19937 rng_;
  std::vector<std::uint16_t> regs_;  // shadow of the served table
};

}  // namespace contour::sim
