#pragma once
// Devices.xml for an MTConnect agent (MTConnectDevices 2.0), generated from the machine config
// and the SHDR item table (shdr.hpp): one Device with its Controller/Path, one Linear component
// per axis and the spindle, every DataItem named by the SHDR key the adapter sends. contourd's
// KPIs are DataItems of types `x:...` in the extension namespace kExtensionUrn.
#include <string>
#include <vector>

namespace contour::bridge {

struct DeviceInfo {
  std::string name;  // Device name (mtconnect.device_name)
  std::string uuid;
  std::string manufacturer, model, serial_number;
  std::vector<std::string> axes;
  bool has_spindle = false;
};

std::string devices_xml(const DeviceInfo& d);

}  // namespace contour::bridge
