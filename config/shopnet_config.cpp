#include "config/shopnet_config.hpp"

#include <algorithm>
#include <cctype>
#include <set>

namespace contour::config {

bool valid_topic_level(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_' || c == '.' || c == '-';
  });
}

namespace {

// A topic prefix: one or more valid levels joined by '/'.
bool valid_prefix(const std::string& p) {
  if (p.empty() || p.size() > 128) return false;
  std::size_t start = 0;
  for (;;) {
    const std::size_t slash = p.find('/', start);
    const std::string level = p.substr(start, slash == std::string::npos ? slash : slash - start);
    if (!valid_topic_level(level)) return false;
    if (slash == std::string::npos) return true;
    start = slash + 1;
  }
}

// Host names and addresses: no spaces or control characters.
bool valid_host(const std::string& h) {
  if (h.empty() || h.size() > 253) return false;
  return std::all_of(h.begin(), h.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '.' || c == '-' || c == ':' ||
           c == '_';
  });
}

// Strings in Devices.xml attributes and SHDR `* key: value` lines: printable, no markup.
bool plain_text(const std::string& s) {
  return s.size() <= 128 && std::all_of(s.begin(), s.end(), [](char c) {
           const auto u = static_cast<unsigned char>(c);
           return u >= 0x20 && u != 0x7f && c != '<' && c != '>' && c != '&' && c != '"' &&
                  c != '|';
         });
}

void parse_tls(Section& t, MqttTlsConfig& c) {
  c.enabled = t.present();
  c.ca_file = t.string("ca_file", "");
  c.ca_path = t.string("ca_path", "");
  c.cert_file = t.string("cert_file", "");
  c.key_file = t.string("key_file", "");
  c.insecure = t.boolean("insecure", false);
  c.version = t.choice("version", "", {"", "tlsv1.2", "tlsv1.3"});
  c.ciphers = t.string("ciphers", "");
  if (!c.enabled) return;
  if (c.ca_file.empty() && c.ca_path.empty()) {
    t.error("ca_file", "TLS needs ca_file or ca_path (the CA that signed the broker's certificate)");
  }
  if (c.cert_file.empty() != c.key_file.empty()) {
    t.error(c.cert_file.empty() ? "key_file" : "cert_file",
            "client certificates need both cert_file and key_file");
  }
}

void parse_commands(Section& s, MqttCommandsConfig& c) {
  c.enabled = s.boolean("enabled", false);
  c.max_per_s = s.number("max_per_s", 5.0, 0.1, 1000.0);
  s.accept("allow");
  if (!s.has("allow")) return;
  const YAML::Node n = s.node()["allow"];
  const std::string path = s.path() + ".allow";
  if (!n.IsSequence()) {
    s.diag().error(n, path, "expected a list of command names");
    return;
  }
  std::vector<std::string> out;
  std::set<std::string> seen;
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string item_path = path + "[" + std::to_string(i) + "]";
    if (!n[i].IsScalar()) {
      s.diag().error(n[i], item_path, "expected a command name");
      continue;
    }
    const std::string name = n[i].Scalar();
    if (std::find(kMqttCommandNames.begin(), kMqttCommandNames.end(), name) ==
        kMqttCommandNames.end()) {
      std::string list;
      for (const auto& k : kMqttCommandNames) list += (list.empty() ? "" : ", ") + k;
      s.diag().error(n[i], item_path,
                     "'" + name + "' cannot be allowed over MQTT (one of: " + list + ")");
      continue;
    }
    if (!seen.insert(name).second) {
      s.diag().error(n[i], item_path, "'" + name + "' is listed twice");
      continue;
    }
    out.push_back(name);
  }
  c.allow = out;
}

}  // namespace

MqttConfig parse_mqtt(Section& s) {
  MqttConfig c;
  c.present = s.present();
  if (!c.present) return c;
  c.host = s.string("host", c.host);
  if (!valid_host(c.host)) s.error("host", "'" + c.host + "' is not a host name or address");
  {
    Section t = s.child("tls");
    parse_tls(t, c.tls);
  }
  c.port = static_cast<int>(s.integer("port", c.tls.enabled ? 8883 : 1883, 1, 65535));
  c.machine_id = s.required_string("machine_id");
  if (s.has("machine_id") && !valid_topic_level(c.machine_id)) {
    s.error("machine_id", "'" + c.machine_id +
                              "' must be 1..64 characters of A-Z a-z 0-9 _ . - (one MQTT topic "
                              "level: no '/', '+', '#' or spaces)");
  }
  c.topic_prefix = s.string("topic_prefix", c.topic_prefix);
  if (!valid_prefix(c.topic_prefix)) {
    s.error("topic_prefix", "'" + c.topic_prefix +
                                "' must be topic levels of A-Z a-z 0-9 _ . - joined by '/' (no "
                                "wildcards, no leading or trailing '/')");
  }
  c.client_id = s.string("client_id", "");
  if (!c.client_id.empty() && !valid_topic_level(c.client_id)) {
    s.error("client_id", "must be 1..64 characters of A-Z a-z 0-9 _ . -");
  }
  if (c.client_id.empty()) c.client_id = "contour-bridge-" + c.machine_id;
  c.keepalive_s = static_cast<int>(s.integer("keepalive_s", c.keepalive_s, 5, 3600));
  c.position_rate_hz = s.number("position_rate_hz", c.position_rate_hz, 0.0, 50.0);
  c.position_deadband_um = s.number("position_deadband_um", c.position_deadband_um, 0.0, 1e4);
  c.state_rate_hz = s.number("state_rate_hz", c.state_rate_hz, 0.5, 50.0);
  c.queue_size = static_cast<int>(s.integer("queue_size", c.queue_size, 16, 1000000));
  c.max_inflight = static_cast<int>(s.integer("max_inflight", c.max_inflight, 1, 65535));
  c.reconnect_min_s = s.number("reconnect_min_s", c.reconnect_min_s, 0.05, 60.0);
  c.reconnect_max_s = s.number("reconnect_max_s", c.reconnect_max_s, 0.05, 3600.0);
  if (c.reconnect_max_s < c.reconnect_min_s) {
    s.error("reconnect_max_s", "must be at least reconnect_min_s");
  }
  c.retain_jobs = static_cast<int>(s.integer("retain_jobs", c.retain_jobs, 0, 1000));
  c.status_interval_s = s.number("status_interval_s", c.status_interval_s, 0.5, 3600.0);
  c.credentials_file = s.string("credentials_file", "");
  {
    Section cmd = s.child("commands");
    parse_commands(cmd, c.commands);
  }
  return c;
}

MtconnectConfig parse_mtconnect(Section& s) {
  MtconnectConfig c;
  c.present = s.present();
  if (!c.present) return c;
  c.bind = s.string("bind", c.bind);
  if (!valid_host(c.bind)) s.error("bind", "'" + c.bind + "' is not an address");
  c.port = static_cast<int>(s.integer("port", c.port, 1, 65535));
  c.device_name = s.string("device_name", "");
  if (!c.device_name.empty() && !valid_topic_level(c.device_name)) {
    s.error("device_name", "must be 1..64 characters of A-Z a-z 0-9 _ . -");
  }
  c.device_uuid = s.string("device_uuid", "");
  if (!c.device_uuid.empty() && !valid_topic_level(c.device_uuid)) {
    s.error("device_uuid", "must be 1..64 characters of A-Z a-z 0-9 _ . -");
  }
  for (auto [key, field] : {std::pair{"manufacturer", &c.manufacturer},
                            std::pair{"model", &c.model},
                            std::pair{"serial_number", &c.serial_number}}) {
    *field = s.string(key, "");
    if (!plain_text(*field)) {
      s.error(key, "must be at most 128 printable characters without < > & \" |");
    }
  }
  c.heartbeat_ms = static_cast<int>(s.integer("heartbeat_ms", c.heartbeat_ms, 100, 600000));
  c.sample_rate_hz = s.number("sample_rate_hz", c.sample_rate_hz, 0.5, 50.0);
  c.max_clients = static_cast<int>(s.integer("max_clients", c.max_clients, 1, 64));
  c.devices_xml = s.string("devices_xml", "");
  return c;
}

}  // namespace contour::config
