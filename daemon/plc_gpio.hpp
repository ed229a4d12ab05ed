#pragma once
// The soft PLC's GPIO lines (issue 20): a non-RT thread reads the input lines and sets the output
// lines every `period` (libgpiod calls are ioctls: never from the RT thread, as io_channels.hpp
// does for the fixed roles). The RT scan exchanges one bit record each way through lock-free
// triple buffers: read() and write() are noexcept, wait-free and allocation-free.
// Outputs are set only on change; at stop() every output goes to its safe value.
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/gpio/gpio.hpp"
#include "drivers/modbus/triple_buffer.hpp"

namespace contour::daemon {

inline constexpr std::size_t kPlcMaxGpioLines = 64;  // per direction

struct GpioBits {
  std::int64_t t_ns = 0;
  std::uint64_t seq = 0;  // 0: not read yet
  std::array<std::uint8_t, kPlcMaxGpioLines> v{};
};

class PlcGpio {
 public:
  // Requests every line now (throws drivers::gpio::GpioError naming the line, or
  // std::invalid_argument for more than kPlcMaxGpioLines). `safe`: the outputs' values at start
  // and after stop(). Logical values (active_low applied by the backend).
  PlcGpio(drivers::gpio::GpioBackend& backend, const std::vector<drivers::gpio::LineSpec>& inputs,
          const std::vector<drivers::gpio::LineSpec>& outputs, const std::vector<bool>& safe,
          std::chrono::milliseconds period, std::function<void(const std::string&)> log = {});
  ~PlcGpio();
  PlcGpio(const PlcGpio&) = delete;
  PlcGpio& operator=(const PlcGpio&) = delete;

  void start();
  void stop();
  // Applies the latest outputs and reads the inputs once (the thread's body; tests).
  void poll_once();

  // RT side.
  bool read(GpioBits& in) noexcept { return inbox_.read(in); }
  void write(const GpioBits& out) noexcept { outbox_.write(out); }

 private:
  void run();
  std::vector<std::unique_ptr<drivers::gpio::GpioInputLine>> in_;
  std::vector<std::unique_ptr<drivers::gpio::GpioOutputLine>> out_;
  std::vector<bool> safe_;
  std::chrono::milliseconds period_;
  std::function<void(const std::string&)> log_;
  drivers::TripleBuffer<GpioBits> inbox_;
  drivers::TripleBuffer<GpioBits> outbox_;
  bool out_written_ = false;
  std::uint64_t seq_ = 0;
  std::thread thread_;
  std::mutex mu_;  // the lines (thread vs poll_once from tests) and the cv
  std::condition_variable cv_;
  bool stopping_ = false;
};

}  // namespace contour::daemon
