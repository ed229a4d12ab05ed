#pragma once
// Drive profiles: what a CiA 402 drive model lacks or limits, so that the master configures it
// without touching what is not there (bus.drives.profile, bus.nodes[].profile,
// bus.spindle.profile; drivers/README.md "Commissioning real drives").
//
//   bus:
//     profile_files: [drives/acme-x1.yaml]   # relative to this config file; each file is a map
//     profiles:                              #   name -> profile, same keys as here
//       acme-x1:
//         description: "ACME X1 servo, EDS rev 1.2"
//         skip_objects: ["0x1006", "0x60C2"]  # optional objects the drive lacks (sub-index:
//                                             #   "0x60C2:01"); only 0x1006 0x1007 0x1008 0x1016
//                                             #   0x605A 0x6085 0x60C2 may be listed
//         rpdos: 1              # RPDOs the drive has (1..4); tpdos likewise
//         tpdos: 1
//         rpdo_max_entries: 2   # objects one RPDO can map (1..8); tpdo_max_entries likewise
//         tpdo_max_entries: 2
//         sdo: expedited_only   # segmented (default) | expedited_only
//         tpdo_sampling: sync   # sync (default: sampled at SYNC, before the drive's step)
//                               #   | after_step (sampled after the step)
//     drives: {profile: acme-x1, ...}
//
// Built in (always available; a file may restate one but not change it): `generic` (a complete CiA 301/402 drive:
// every optional object, 4 PDOs of 8 entries, segmented SDO, sampled at SYNC; the default) and
// `contour-machine-sim` (the simulated drive, the same values). config/drives/*.yaml are the same
// two as files, as templates for new ones.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "config/yaml_reader.hpp"

namespace contour::config {

struct ProfileObject {
  std::uint16_t index = 0;
  int sub = -1;  // -1: every sub-index
  bool operator==(const ProfileObject&) const = default;
};

struct DriveProfile {
  std::string name = "generic";
  std::string description;
  std::vector<ProfileObject> skip_objects;
  int rpdos = 4;
  int tpdos = 4;
  int rpdo_max_entries = 8;
  int tpdo_max_entries = 8;
  std::string sdo = "segmented";     // segmented | expedited_only
  std::string tpdo_sampling = "sync";  // sync | after_step
  // Compares the settings (not the name nor the description).
  [[nodiscard]] bool same_settings(const DriveProfile& o) const;
};

// The objects a profile may skip (the master's optional objects, drivers/canopen/master.hpp).
const std::vector<std::uint16_t>& skippable_objects();

// `generic` and `contour-machine-sim`.
std::map<std::string, DriveProfile> builtin_drive_profiles();

// Parses one profile map (keys above) at `s`; errors go to s.diag() with file:line.
DriveProfile parse_drive_profile(Section& s, const std::string& name);

// Parses a map name -> profile into `out` (a name defined twice, or a built-in name with other
// settings, is an error at its line).
void parse_drive_profiles(Section& s, std::map<std::string, DriveProfile>& out);

// Loads a profile file (a map name -> profile). Throws ConfigError naming that file and line.
std::map<std::string, DriveProfile> load_drive_profile_file(const std::string& path);

}  // namespace contour::config
