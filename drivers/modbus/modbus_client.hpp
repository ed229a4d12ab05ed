#pragma once
// Thin owner of one libmodbus context (TCP or RTU), used only from non-RT threads. Translates
// libmodbus/errno failures once, into ModbusError (kind + text), per style.md.
// Not thread-safe: one thread per client.
#include <chrono>
#include <cstdint>
#include <span>
#include <string>

#include "drivers/modbus/register_map.hpp"

struct _modbus;  // libmodbus' opaque context (modbus_t)

namespace contour::drivers::modbus {

enum class Transport { kTcp, kRtu };

struct TransportSettings {
  Transport transport = Transport::kTcp;
  std::string host = "127.0.0.1";  // TCP
  int port = 502;
  std::string device = "/dev/ttyUSB0";  // RTU
  int baud = 115200;
  char parity = 'N';  // 'N', 'E', 'O'
  int data_bits = 8;
  int stop_bits = 1;
  int unit_id = 1;
  std::chrono::microseconds response_timeout{20000};
};

enum class ErrorKind {
  kNone,
  kTimeout,     // no (complete) reply within the response timeout
  kException,   // the device replied with a Modbus exception
  kConnection,  // socket/serial failure: close and reconnect
  kProtocol,    // bad CRC, bad data, wrong slave: flush and retry
  kConfig,      // context could not be created (bad device, parameters)
};

struct ModbusError {
  ErrorKind kind = ErrorKind::kNone;
  int code = 0;      // errno value, or the Modbus exception code (1..11) for kException
  std::string text;  // "127.0.0.1:1502: read input registers 0+6: Slave device or server failure"
  [[nodiscard]] explicit operator bool() const { return kind != ErrorKind::kNone; }
};

// Classifies an errno value set by libmodbus (pure; tested).
[[nodiscard]] ErrorKind classify_errno(int err) noexcept;
// Text of a Modbus exception code 1..11 ("illegal data address", ...); "unknown exception" else.
[[nodiscard]] const char* exception_text(int code) noexcept;

class ModbusClient {
 public:
  explicit ModbusClient(TransportSettings s);
  ~ModbusClient();
  ModbusClient(const ModbusClient&) = delete;
  ModbusClient& operator=(const ModbusClient&) = delete;

  ModbusError connect();
  void close() noexcept;
  [[nodiscard]] bool connected() const noexcept { return connected_; }
  // Discards pending input (after a timeout, a late reply must not be taken for the next one).
  void flush() noexcept;

  ModbusError read_registers(RegisterFunction fn, std::uint16_t start,
                             std::span<std::uint16_t> out);
  ModbusError write_register(std::uint16_t address, std::uint16_t value);
  ModbusError write_coil(std::uint16_t address, bool value);

  [[nodiscard]] const std::string& endpoint() const noexcept { return endpoint_; }

 private:
  ModbusError fail(const char* op, int err);
  TransportSettings s_;
  std::string endpoint_;
  _modbus* ctx_ = nullptr;
  bool connected_ = false;
};

}  // namespace contour::drivers::modbus
