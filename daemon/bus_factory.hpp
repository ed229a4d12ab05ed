#pragma once
// Chooses the daemon's AxisBus from `bus.type`: "sim" -> SimBus (in-process lockstep plant),
// "socketcan" -> the CANopen master over SocketCAN. Non-RT, called once at start-up.
// Throws std::runtime_error with a message naming the interface/node on failure.
#include <functional>
#include <memory>
#include <string>

#include "config/config.hpp"
#include "daemon/axis_bus.hpp"

namespace contour::daemon {

using BusLog = std::function<void(const std::string&)>;

std::unique_ptr<AxisBus> make_axis_bus(const config::Config& cfg, BusLog log = {});

}  // namespace contour::daemon
