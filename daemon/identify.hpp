#pragma once
// `identify` (issue 16, `contourctl identify AXIS`): commissioning measurement of one feed drive
// through the running loop. The loop plays the excitation on the axis at rest (ServoLoop
// CommandKind::kIdentify: ~0.84 s, +-5 mm/s, at most 0.5 mm from where it stands, net zero), the
// other axes hold; the record is fitted by control::identify_axis (gain K, time constant tau,
// transport delay in whole cycles) and compared with the configuration the controller uses
// (machine.axes[].drive: the drive model of the Smith predictor and the stability check).
// Non-RT (the command thread). Throws CommandError with a clear message when the loop refuses
// (not READY, a program loaded, a jog) or the experiment is aborted, or the axis is too close to
// a soft limit for the excursion.
#include <functional>

#include <nlohmann/json.hpp>

#include "config/config.hpp"
#include "daemon/servo_loop.hpp"

namespace contour::daemon {

// give_way: polled while waiting; true when another client's safety request (stop, E-stop) waits
// (the wait then ends at once and the experiment is left to the loop, which aborts it when the
// state changes). The reply carries the fitted model, the configured one, whether the delay
// matches, and the record (v_cmd_mm_s, position_mm per cycle) for plotting.
nlohmann::json identify_on_loop(ServoLoop& loop, const config::Config& cfg, int axis,
                                const std::function<bool()>& give_way);

}  // namespace contour::daemon
