#pragma once
// `mqtt:` and `mtconnect:` sections: the shop network (issue 22), used by contour-bridge (MQTT
// publisher, MTConnect SHDR adapter; tools/contour-bridge/README.md documents every key, the
// topics and the SHDR items). contourd validates them on load (--check-config too) and otherwise
// ignores them. Absent sections: the bridge has nothing to do there.
//
// Secrets never live in this file: the broker's username/password (and a TLS key's passphrase)
// come from `mqtt.credentials_file`, a file readable by its owner only (0600), which the bridge
// reads at start and never logs. Paths are checked by the bridge when it starts (contourd's
// --check-config may run on another host), values and ranges here.
#include <string>
#include <vector>

#include "config/yaml_reader.hpp"

namespace contour::config {

struct MqttTlsConfig {
  bool enabled = false;    // the `tls:` map is present
  std::string ca_file;     // PEM CA bundle that signed the broker's certificate
  std::string ca_path;     // or a directory of hashed CA certificates
  std::string cert_file;   // client certificate (PEM): certificate authentication
  std::string key_file;    // its private key (PEM; a passphrase goes in the credentials file)
  bool insecure = false;   // do not check the broker's host name against its certificate
  std::string version;     // "" (library default), tlsv1.2 or tlsv1.3
  std::string ciphers;     // OpenSSL cipher list ("" = library default)
};

struct MqttCommandsConfig {
  bool enabled = false;  // commands over MQTT are off unless enabled
  // Socket commands the bridge forwards from `<prefix>/<machine_id>/cmd`. Default hold, resume,
  // stop; enable and run only when listed here (kMqttCommandNames is the closed set).
  std::vector<std::string> allow{"hold", "resume", "stop"};
  double max_per_s = 5.0;  // commands beyond this rate are refused (answer names the limit)
};

// Socket commands that may ever be allowed over MQTT.
inline const std::vector<std::string> kMqttCommandNames{
    "hold", "resume", "stop", "estop", "reset", "enable", "disable", "run", "override"};

struct MqttConfig {
  bool present = false;
  std::string host = "localhost";
  int port = 1883;
  std::string machine_id;             // required: one topic level, [A-Za-z0-9_.-]{1,64}
  std::string topic_prefix = "contourd";
  std::string client_id;              // "" = contour-bridge-<machine_id>
  int keepalive_s = 30;
  double position_rate_hz = 10.0;     // `.../position` samples while the axes move; 0 = off
  double position_deadband_um = 1.0;  // a sample is published when an axis moved more than this
  double state_rate_hz = 10.0;        // how often the daemon's status is read for `.../state`
  int queue_size = 10000;             // messages held while the broker is gone (bounded)
  int max_inflight = 64;              // QoS 1 messages sent and not yet acknowledged
  double reconnect_min_s = 0.5;       // backoff after a lost connection: min, doubling to max
  double reconnect_max_s = 30.0;
  int retain_jobs = 16;               // job summaries re-published (retained) after a reconnect
  double status_interval_s = 10.0;    // the bridge's own counters on `.../bridge`
  std::string credentials_file;       // username/password/key_password; mode 0600 enforced
  MqttTlsConfig tls;
  MqttCommandsConfig commands;
};

struct MtconnectConfig {
  bool present = false;
  std::string bind = "127.0.0.1";  // loopback by default: an agent on this host
  int port = 7878;
  std::string device_name;         // "" = mqtt.machine_id, else "contourd"
  std::string device_uuid;         // "" = contourd-<device name>
  std::string manufacturer;        // Devices.xml <Description> (optional)
  std::string model;
  std::string serial_number;
  int heartbeat_ms = 10000;        // the `* PONG <ms>` an agent is told
  double sample_rate_hz = 10.0;    // positions, feed rate, KPIs
  int max_clients = 8;
  std::string devices_xml;         // "" = none; else the bridge writes Devices.xml there at start
};

MqttConfig parse_mqtt(Section& s);
MtconnectConfig parse_mtconnect(Section& s);

// One topic level: 1..64 of A-Z a-z 0-9 _ . - (no '/', '+', '#', spaces). Exposed for tests.
bool valid_topic_level(const std::string& s);

}  // namespace contour::config
