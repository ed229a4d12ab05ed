// contour-bridge's MTConnect SHDR adapter with the real daemon (issue 22): an agent-like client
// connects, gets `* shdrVersion` and the snapshot of every item, `* PING` is answered `* PONG`,
// the stream during a Table 2 run parses as SHDR (every line `timestamp|key|value...`,
// conditions with six fields), alarms come and go as conditions, and Devices.xml names every key.
// No broker needed: the section `mqtt:` is absent.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>

#include <map>
#include <regex>
#include <set>

#include "tests/bridge/bridge_support.hpp"
#include "tools/contour-bridge/shdr.hpp"

namespace {

using namespace contour::test::bridge;
using contour::test::DaemonProcess;
using nlohmann::json;
using std::chrono::seconds;

class ShdrClient {
 public:
  explicit ShdrClient(int port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  ~ShdrClient() { ::close(fd_); }
  [[nodiscard]] bool connected() const { return connected_; }
  void send(const std::string& s) { ::send(fd_, s.data(), s.size(), MSG_NOSIGNAL); }
  // Reads lines until pred(all lines so far) holds or `bound` passes.
  bool read_until(const std::function<bool(const std::vector<std::string>&)>& pred,
                  std::chrono::milliseconds bound) {
    const auto until = std::chrono::steady_clock::now() + bound;
    while (!pred(lines_)) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      if (left.count() <= 0) return false;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(std::min<long>(left.count(), 200))) <= 0) continue;
      char buf[8192];
      const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) return false;
      buf_.append(buf, static_cast<std::size_t>(n));
      std::size_t nl;
      while ((nl = buf_.find('\n')) != std::string::npos) {
        lines_.push_back(buf_.substr(0, nl));
        buf_.erase(0, nl + 1);
      }
    }
    return true;
  }
  // A line containing `needle` among those from index `from` on (default: lines not read yet).
  bool read_line_with(const std::string& needle, std::chrono::milliseconds bound,
                      std::size_t from = std::string::npos) {
    if (from == std::string::npos) from = lines_.size();
    return read_until(
        [&](const std::vector<std::string>& v) {
          for (std::size_t i = from; i < v.size(); ++i) {
            if (v[i].find(needle) != std::string::npos) return true;
          }
          return false;
        },
        bound);
  }
  [[nodiscard]] const std::vector<std::string>& lines() const { return lines_; }

 private:
  int fd_ = -1;
  bool connected_ = false;
  std::string buf_;
  std::vector<std::string> lines_;
};

std::vector<std::string> fields(const std::string& line) {
  std::vector<std::string> f;
  std::size_t start = 0;
  for (;;) {
    const std::size_t bar = line.find('|', start);
    f.push_back(line.substr(start, bar == std::string::npos ? bar : bar - start));
    if (bar == std::string::npos) return f;
    start = bar + 1;
  }
}

// Parses the stream as an agent would: `* ` protocol lines, data lines of key/value pairs for
// known keys, condition lines with exactly six fields after the time stamp. Returns every
// (key, value) in order; conditions as key -> "LEVEL|code|severity|qualifier|message".
std::vector<std::pair<std::string, std::string>> parse_shdr(
    const std::vector<std::string>& lines, const std::vector<contour::bridge::ItemDef>& items) {
  static const std::regex ts(R"(^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$)");
  std::set<std::string> conditions, data;
  for (const auto& it : items) {
    (it.category == contour::bridge::ItemCategory::kCondition ? conditions : data).insert(it.key);
  }
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& l : lines) {
    if (l.rfind("* ", 0) == 0) {
      EXPECT_TRUE(l == "* shdrVersion: 2" || l.rfind("* PONG ", 0) == 0 ||
                  l.rfind("* manufacturer: ", 0) == 0 || l.rfind("* serialNumber: ", 0) == 0)
          << l;
      continue;
    }
    const auto f = fields(l);
    EXPECT_GE(f.size(), 3u) << l;
    if (f.size() < 3) continue;
    EXPECT_TRUE(std::regex_match(f[0], ts)) << "bad time stamp: " << l;
    if (conditions.count(f[1]) != 0) {
      EXPECT_EQ(f.size(), 7u) << "a condition has six fields after the time stamp: " << l;
      EXPECT_TRUE(f[2] == "NORMAL" || f[2] == "WARNING" || f[2] == "FAULT" || f[2] == "UNAVAILABLE")
          << l;
      out.emplace_back(f[1], l.substr(f[0].size() + f[1].size() + 2));
      continue;
    }
    EXPECT_EQ(f.size() % 2, 1u) << "key|value pairs: " << l;
    for (std::size_t i = 1; i + 1 < f.size(); i += 2) {
      EXPECT_EQ(data.count(f[i]), 1u) << "unknown key '" << f[i] << "': " << l;
      EXPECT_FALSE(f[i + 1].empty() && f[i] != "program") << "empty value for " << f[i] << ": " << l;
      out.emplace_back(f[i], f[i + 1]);
    }
  }
  return out;
}

bool is_number(const std::string& s) {
  char* end = nullptr;
  std::strtod(s.c_str(), &end);
  return !s.empty() && end == s.c_str() + s.size();
}

TEST(BridgeShdr, SnapshotHeartbeatValidStreamConditionsAndDevicesXml) {
  TempDir dir("shdr");
  const int port = free_port();
  const std::string devices = dir / "Devices.xml";
  const std::string cfg = write_file(
      dir / "m.yaml", sim_config("mtconnect:\n  port: " + std::to_string(port) +
                                 "\n  heartbeat_ms: 2000\n  device_name: mill1\n  manufacturer: "
                                 "ACME\n  devices_xml: " + devices + "\n"));
  DaemonProcess d("bridge_shdr", daemon_options(cfg));
  ASSERT_TRUE(d.connected()) << d.log();
  Child bridge({bin("tools/contour-bridge/contour-bridge"), "--config", cfg, "--socket", d.sock()},
               dir / "bridge.out", dir / "bridge.log");
  ASSERT_TRUE(wait_until([&] { return port_open(port) || !bridge.running(); }, seconds(30)))
      << bridge.err();
  ASSERT_TRUE(bridge.running()) << bridge.err();
  const auto items = contour::bridge::shdr_items({"X", "Y", "Z"}, true);

  ShdrClient agent(port);
  ASSERT_TRUE(agent.connected());
  // Header, then the snapshot of every item; the daemon is reachable: AVAILABLE.
  ASSERT_TRUE(agent.read_line_with("|system|", seconds(20))) << bridge.err();
  ASSERT_FALSE(agent.lines().empty());
  EXPECT_EQ(agent.lines()[0], "* shdrVersion: 2");
  EXPECT_EQ(agent.lines()[1], "* manufacturer: ACME");
  {
    std::set<std::string> keys;
    for (const auto& [k, v] : parse_shdr(agent.lines(), items)) keys.insert(k);
    for (const auto& it : items) EXPECT_EQ(keys.count(it.key), 1u) << it.key << " not in snapshot";
  }
  ASSERT_TRUE(agent.read_line_with("|avail|AVAILABLE", seconds(20), 0));
  // Heartbeat.
  const std::size_t ping_from = agent.lines().size();
  agent.send("* PING\n");
  ASSERT_TRUE(agent.read_line_with("* PONG 2000", seconds(20), ping_from));

  // A run: the stream follows it and parses as SHDR throughout.
  const std::size_t run_from = agent.lines().size();
  const json ctl = contourctl_run_wait(d.sock(), std::string(CONTOUR_SOURCE_DIR) + "/config/programs/table2.ngc",
                                       dir.path().string(), "shdr");
  ASSERT_TRUE(ctl.value("completed", false)) << ctl.dump();
  ASSERT_TRUE(agent.read_line_with("|job|" + std::to_string(ctl["job"].get<int>()), seconds(30),
                                   run_from))
      << bridge.err();
  const std::size_t ping2_from = agent.lines().size();
  agent.send("* PING\n");
  ASSERT_TRUE(agent.read_line_with("* PONG 2000", seconds(20), ping2_from));
  const std::vector<std::string> during(agent.lines().begin() + static_cast<long>(run_from),
                                        agent.lines().end());
  const auto kv = parse_shdr(during, items);
  std::vector<std::string> exec;
  std::set<long> lines_seen;
  std::map<std::string, std::string> last;
  for (const auto& [k, v] : kv) {
    last[k] = v;
    if (k == "exec" && (exec.empty() || exec.back() != v)) exec.push_back(v);
    if (k == "line") lines_seen.insert(std::stol(v));
    if (k == "Xact" || k == "Ycmd" || k == "path_feedrate" || k == "ce") {
      EXPECT_TRUE(is_number(v)) << k << "=" << v;
    }
    if (k == "path_pos") {
      std::istringstream in(v);
      double a = 0, b = 0, c = 0;
      EXPECT_TRUE(static_cast<bool>(in >> a >> b >> c)) << v;
    }
  }
  ASSERT_GE(exec.size(), 2u);
  EXPECT_NE(std::find(exec.begin(), exec.end(), "ACTIVE"), exec.end());
  EXPECT_EQ(exec.back(), "READY");
  EXPECT_GE(lines_seen.size(), 5u) << "the line number followed the program";
  char ce[32];
  std::snprintf(ce, sizeof ce, "%.6f", ctl["max_contour_error_um"].get<double>() / 1000.0);
  EXPECT_EQ(last["job_ce_max"], ce);
  EXPECT_EQ(last["job_completed"], "true");
  EXPECT_EQ(last["mode"], "AUTOMATIC");

  // An alarm: E-stop from the socket, a FAULT condition and the E-stop item; reset clears them.
  const std::size_t estop_from = agent.lines().size();
  d.ok({{"cmd", "estop"}});
  ASSERT_TRUE(agent.read_line_with("|system|FAULT|e_stop_command|estop|", seconds(20)))
      << bridge.err();
  d.ok({{"cmd", "reset"}});
  ASSERT_TRUE(agent.read_line_with("|system|NORMAL||||", seconds(20), estop_from));
  const std::vector<std::string> alarm(agent.lines().begin() + static_cast<long>(estop_from),
                                       agent.lines().end());
  std::vector<std::string> estop_values;
  for (const auto& [k, v] : parse_shdr(alarm, items)) {
    if (k == "estop") estop_values.push_back(v);
  }
  EXPECT_NE(std::find(estop_values.begin(), estop_values.end(), "TRIGGERED"), estop_values.end());
  EXPECT_TRUE(agent.read_line_with("|estop|ARMED", seconds(20), estop_from));

  // A second agent gets its own snapshot.
  ShdrClient second(port);
  ASSERT_TRUE(second.read_line_with("|system|", seconds(20)));
  EXPECT_EQ(second.lines()[0], "* shdrVersion: 2");

  // The contourd daemon goes away: everything becomes UNAVAILABLE, the adapter stays up.
  const std::size_t gone_from = agent.lines().size();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0);
  ASSERT_TRUE(agent.read_line_with("|avail|UNAVAILABLE", seconds(20), gone_from));
  ASSERT_TRUE(agent.read_line_with("|system|UNAVAILABLE||||", seconds(20), gone_from));
  EXPECT_TRUE(bridge.running());

  // Devices.xml written at start, naming every key once; well-formed.
  const std::string xml = slurp(devices);
  ASSERT_FALSE(xml.empty()) << bridge.err();
  for (const auto& it : items) {
    EXPECT_NE(xml.find("name=\"" + it.key + "\""), std::string::npos) << it.key;
  }
  EXPECT_NE(xml.find("<Device id=\"mill1\" name=\"mill1\" uuid=\"contourd-mill1\">"),
            std::string::npos);
  if (std::system("command -v xmllint >/dev/null 2>&1") == 0) {
    EXPECT_EQ(std::system(("xmllint --noout " + devices).c_str()), 0);
  } else {
    std::printf("note: xmllint not installed; Devices.xml well-formedness checked by the unit test\n");
  }
  // The one-shot form writes the same device model.
  Child once({bin("tools/contour-bridge/contour-bridge"), "--config", cfg, "--devices-xml",
              dir / "once.xml"},
             dir / "once.out", dir / "once.err");
  EXPECT_EQ(once.wait(seconds(30)), 0) << once.err();
  const std::string again = slurp(dir / "once.xml");
  EXPECT_EQ(again.substr(again.find("<Devices>")), xml.substr(xml.find("<Devices>")));
}

}  // namespace
