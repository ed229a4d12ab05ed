#pragma once
// JSON of the soft PLC for the socket commands (issue 20): `io` (the image with values, sources
// and forced flags), `plc_status` (per-program scan times min/median/max and overruns, couplers,
// handshakes, latched faults). Field names are the contract contourctl and the gateways read;
// daemon/PLC.md documents them. Non-RT.
#include <nlohmann/json.hpp>

#include "daemon/plc_engine.hpp"

namespace contour::daemon {

// A value as JSON: BOOL -> true/false, INT/DINT -> integer, REAL/LREAL -> number, TIME -> ms.
nlohmann::json plc_value_json(control::plc::Type t, control::plc::Cell v);
// {"cycle", "forcing_allowed", "signals": [{"name","type","direction","source","value",
//  "forced","forceable","description"}]}
nlohmann::json plc_io_json(const PlcSnapshot& s);
// {"cycle", "scan_us": {...}, "programs": [{"name","file","period_cycles","state","error",
//  "runs","overruns","scan_us": {"last","min","median","max"},"instructions": {"last","max",
//  "worst_case"}}], "devices": [...], "mcode": {...}, "tool_change": {...}, "faults": [...]}
nlohmann::json plc_status_json(const PlcSnapshot& s);

}  // namespace contour::daemon
