#include "drivers/modbus/modbus_client.hpp"

#include <modbus/modbus.h>

#include <cerrno>
#include <stdexcept>
#include <utility>

namespace contour::drivers::modbus {

ErrorKind classify_errno(int err) noexcept {
  if (err == 0) return ErrorKind::kNone;
  if (err == ETIMEDOUT) return ErrorKind::kTimeout;
  if (err > MODBUS_ENOBASE && err <= EMBXGTAR) return ErrorKind::kException;
  if (err == EMBBADCRC || err == EMBBADDATA || err == EMBBADEXC || err == EMBUNKEXC ||
      err == EMBMDATA || err == EMBBADSLAVE || err == EINVAL)
    return ErrorKind::kProtocol;
  return ErrorKind::kConnection;  // ECONNRESET, EPIPE, ECONNREFUSED, EBADF, EIO, ...
}

const char* exception_text(int code) noexcept {
  switch (code) {
    case 1:
      return "illegal function";
    case 2:
      return "illegal data address";
    case 3:
      return "illegal data value";
    case 4:
      return "slave device or server failure";
    case 5:
      return "acknowledge";
    case 6:
      return "slave device or server busy";
    case 7:
      return "negative acknowledge";
    case 8:
      return "memory parity error";
    case 10:
      return "gateway path unavailable";
    case 11:
      return "gateway target device failed to respond";
    default:
      return "unknown exception";
  }
}

ModbusClient::ModbusClient(TransportSettings s) : s_(std::move(s)) {
  if (s_.transport == Transport::kTcp) {
    endpoint_ = s_.host + ":" + std::to_string(s_.port);
    ctx_ = modbus_new_tcp(s_.host.c_str(), s_.port);
  } else {
    endpoint_ = s_.device;
    ctx_ = modbus_new_rtu(s_.device.c_str(), s_.baud, s_.parity, s_.data_bits, s_.stop_bits);
  }
  if (ctx_ == nullptr)
    throw std::runtime_error("modbus " + endpoint_ +
                             ": cannot create context: " + modbus_strerror(errno));
  if (modbus_set_slave(ctx_, s_.unit_id) != 0) {
    const std::string msg = modbus_strerror(errno);
    modbus_free(ctx_);
    throw std::runtime_error("modbus " + endpoint_ + ": unit id " + std::to_string(s_.unit_id) +
                             ": " + msg);
  }
  const auto us = s_.response_timeout.count();
  modbus_set_response_timeout(ctx_, static_cast<std::uint32_t>(us / 1000000),
                              static_cast<std::uint32_t>(us % 1000000));
}

ModbusClient::~ModbusClient() {
  close();
  modbus_free(ctx_);
}

ModbusError ModbusClient::fail(const char* op, int err) {
  ModbusError e;
  e.kind = classify_errno(err);
  e.code = e.kind == ErrorKind::kException ? err - MODBUS_ENOBASE : err;
  const std::string what =
      e.kind == ErrorKind::kException
          ? std::string("exception ") + std::to_string(e.code) + " (" + exception_text(e.code) + ")"
          : std::string(modbus_strerror(err));
  e.text = endpoint_ + ": " + op + ": " + what;
  return e;
}

ModbusError ModbusClient::connect() {
  if (connected_) return {};
  if (modbus_connect(ctx_) != 0) {
    const int err = errno;
    ModbusError e = fail("connect", err);
    e.kind = ErrorKind::kConnection;
    return e;
  }
  connected_ = true;
  return {};
}

void ModbusClient::close() noexcept {
  if (connected_) modbus_close(ctx_);
  connected_ = false;
}

void ModbusClient::flush() noexcept {
  if (connected_) modbus_flush(ctx_);
}

ModbusError ModbusClient::read_registers(RegisterFunction fn, std::uint16_t start,
                                         std::span<std::uint16_t> out) {
  if (!connected_) return {ErrorKind::kConnection, ENOTCONN, endpoint_ + ": not connected"};
  const int n = static_cast<int>(out.size());
  const int rc = fn == RegisterFunction::kInput
                     ? modbus_read_input_registers(ctx_, start, n, out.data())
                     : modbus_read_registers(ctx_, start, n, out.data());
  if (rc == n) return {};
  const int err = rc < 0 ? errno : EMBMDATA;
  return fail(fn == RegisterFunction::kInput ? "read input registers" : "read holding registers",
              err);
}

ModbusError ModbusClient::write_register(std::uint16_t address, std::uint16_t value) {
  if (!connected_) return {ErrorKind::kConnection, ENOTCONN, endpoint_ + ": not connected"};
  if (modbus_write_register(ctx_, address, value) == 1) return {};
  return fail("write register", errno);
}

ModbusError ModbusClient::write_coil(std::uint16_t address, bool value) {
  if (!connected_) return {ErrorKind::kConnection, ENOTCONN, endpoint_ + ": not connected"};
  if (modbus_write_bit(ctx_, address, value ? 1 : 0) == 1) return {};
  return fail("write coil", errno);
}

}  // namespace contour::drivers::modbus
