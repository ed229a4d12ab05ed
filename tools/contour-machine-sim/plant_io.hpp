#pragma once
// The simulated machine's I/O for the soft PLC in HIL (issue 20): a Modbus TCP I/O coupler
// (CouplerServer: coils, discrete inputs, input and holding registers, a communication watchdog,
// fault injection) and the plant behind it (PlantIo: control/plc_sim_plant.hpp, the same model
// the sim bus steps in-process), stepped with the simulated drives' positions.
//
// Register map of the plant coupler (config/plc/hil_machine.yaml binds the same addresses):
//   discrete inputs  0 door_closed       1 air_ok             2 lube_pressure_ok
//                    3 carousel_in_position                   4 drawbar_clamped
//                    5 drawbar_unclamped 6 limit_x_neg  7 limit_x_pos  8 limit_y_neg
//                    9 limit_y_pos      10 limit_z_neg 11 limit_z_pos
//   input register   0 carousel_pocket (1..8 in position, else 0)
//   coils            0 carousel_cw       1 carousel_ccw       2 drawbar_unclamp   3 lube_pump
//                    4 door_lock         5 work_light         8 coolant_mist      9 coolant_flood
//                    (8 and 9 only recorded: the valves of a coupler-wired machine)
// Watchdog: with no request for watchdog_ms (default 500), every coil drops to 0, as a real
// coupler's fieldbus watchdog does; the plant then sees its outputs off.
//
// Thread-safety: the server runs its own thread; every setter/getter takes the server's mutex.
// PlantIo::step() runs on contour-machine-sim's main loop.
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <memory>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "config/config.hpp"
#include "control/plc_sim_plant.hpp"
#include "tools/contour-machine-sim/dynamometer_server.hpp"  // FaultMode

namespace contour::sim {

class CouplerServer {
 public:
  static constexpr int kTableSize = 256;
  explicit CouplerServer(int unit_id = 1, std::chrono::milliseconds watchdog = std::chrono::milliseconds(500));
  ~CouplerServer();
  CouplerServer(const CouplerServer&) = delete;
  CouplerServer& operator=(const CouplerServer&) = delete;

  // Listens on host:port (0: a free port, see port()); throws std::runtime_error naming the
  // endpoint. Restartable after stop() on the same port.
  void start(const std::string& host = "127.0.0.1", int port = 0);
  void stop();
  [[nodiscard]] int port() const noexcept { return port_.load(); }

  // Field side.
  void set_discrete(int address, bool v);
  void set_input_register(int address, std::uint16_t v);
  void set_coil(int address, bool v);  // as another master would (tests)
  void set_holding(int address, std::uint16_t v);
  [[nodiscard]] bool coil(int address) const;
  [[nodiscard]] std::uint16_t holding(int address) const;
  [[nodiscard]] std::uint64_t requests() const noexcept { return requests_.load(); }
  [[nodiscard]] std::uint64_t watchdog_trips() const noexcept { return watchdog_trips_.load(); }

  // Faults: until changed (kNone, kNoReply, kDelay, kException, kDropConnection), or one-shot.
  void set_fault(FaultMode mode, std::chrono::milliseconds delay = std::chrono::milliseconds(0),
                 int exception_code = 4);
  void inject_disconnect();

 private:
  void run(int listen_fd);

  int unit_id_;
  std::chrono::milliseconds watchdog_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<int> port_{0};
  std::atomic<std::uint64_t> requests_{0};
  std::atomic<std::uint64_t> watchdog_trips_{0};
  mutable std::mutex mu_;  // guards the tables and the fault state
  std::array<std::uint8_t, kTableSize> coils_{};
  std::array<std::uint8_t, kTableSize> discrete_{};
  std::array<std::uint16_t, kTableSize> input_regs_{};
  std::array<std::uint16_t, kTableSize> holding_{};
  FaultMode fault_ = FaultMode::kNone;
  std::chrono::milliseconds delay_{0};
  int exception_code_ = 4;
  bool disconnect_pending_ = false;
};

// Plant <-> coupler: each step copies the coils to the plant's outputs, steps the plant, and
// copies its inputs to the discrete inputs and the input register.
class PlantIo {
 public:
  static constexpr int kDiscreteInputs = 12;
  static constexpr std::array<control::plc::PlantPoint, kDiscreteInputs> kDiscreteMap{
      control::plc::PlantPoint::kDoorClosed,         control::plc::PlantPoint::kAirOk,
      control::plc::PlantPoint::kLubePressureOk,     control::plc::PlantPoint::kCarouselInPosition,
      control::plc::PlantPoint::kDrawbarClamped,     control::plc::PlantPoint::kDrawbarUnclamped,
      control::plc::PlantPoint::kLimitXNeg,          control::plc::PlantPoint::kLimitXPos,
      control::plc::PlantPoint::kLimitYNeg,          control::plc::PlantPoint::kLimitYPos,
      control::plc::PlantPoint::kLimitZNeg,          control::plc::PlantPoint::kLimitZPos};
  static constexpr std::array<control::plc::PlantPoint, 6> kCoilMap{
      control::plc::PlantPoint::kCarouselCw,   control::plc::PlantPoint::kCarouselCcw,
      control::plc::PlantPoint::kDrawbarUnclamp, control::plc::PlantPoint::kLubePump,
      control::plc::PlantPoint::kDoorLock,     control::plc::PlantPoint::kWorkLight};

  explicit PlantIo(CouplerServer& server) : server_(server) {}
  control::plc::MachinePlant& plant() noexcept { return plant_; }
  [[nodiscard]] const control::plc::MachinePlant& plant() const noexcept { return plant_; }
  void step(double dt_s, const std::array<double, 3>& axis_mm);

 private:
  CouplerServer& server_;
  control::plc::MachinePlant plant_;
};

// Scheduled plant events for contour-machine-sim (--plant-event KIND@SYNC, repeatable):
//   door_open door_close air_loss air_ok carousel_jam carousel_free drawbar_stuck drawbar_free
//   sensor_dead sensor_ok coupler_no_reply coupler_ok coupler_drop
struct PlantEvent {
  std::string kind;
  long sync = 0;
};
// Parses "KIND@SYNC"; throws std::invalid_argument naming the problem.
PlantEvent parse_plant_event(const std::string& text);
// Applies one event (the coupler ones to `server`).
void apply_plant_event(const PlantEvent& e, control::plc::MachinePlant& plant,
                       control::plc::PlantFaults& faults, CouplerServer& server);

// contour-machine-sim's options for the plant (registered by add_plant_options):
//   --plant-io HOST:PORT        serve the plant coupler there (port 0: any free port)
//   --plant-event KIND@SYNC     schedule a plant event (repeatable)
//   --coupler-watchdog-ms MS    the coupler's communication watchdog (default 500)
//   --plant-stdin               also take plant events from stdin, one KIND per line, applied at
//                               once (a test drives the plant at the moment it chooses: no SYNC
//                               count to guess); each is acknowledged like a scheduled one
struct PlantOptions {
  std::string endpoint;
  std::vector<std::string> events;
  int watchdog_ms = 500;
  bool from_stdin = false;
};
void add_plant_options(CLI::App& app, PlantOptions& o);

// The plant coupler as contour-machine-sim runs it: listens at construction, applies the
// scheduled events at their SYNC counts, steps the plant by the SYNCs elapsed (period from the
// config) with the axes' positions. Overtravel switches sit 2 mm beyond the soft limits.
class PlantRunner {
 public:
  // Throws std::invalid_argument (bad option, event) or std::runtime_error (cannot listen).
  PlantRunner(const PlantOptions& o, const config::Config& cfg);
  void step(long syncs, const std::array<double, 3>& axis_mm);
  // Applies one event KIND now (--plant-stdin) and prints {"plant":KIND,"sync":syncs}; throws
  // std::invalid_argument for an unknown KIND.
  void apply_now(const std::string& kind, long syncs);
  [[nodiscard]] int port() const noexcept { return server_.port(); }
  [[nodiscard]] std::string host() const { return host_; }
  [[nodiscard]] nlohmann::json summary() const;

 private:
  CouplerServer server_;
  PlantIo io_;
  control::plc::PlantFaults faults_{};
  std::vector<PlantEvent> events_;  // sorted by sync
  std::size_t next_event_ = 0;
  std::size_t events_applied_ = 0;
  long last_sync_ = 0;
  double period_s_ = 0.001;
  std::string host_;
};

}  // namespace contour::sim
