// contourd as a systemd service sees the world differently from its clients (issue 17):
// PrivateTmp=yes gives it its own /tmp, RuntimeDirectory= makes the socket directory. These tests
// run the real contourd (config/sim.yaml variants) and contourctl:
//  - a missing socket directory: exit 78 naming it; an uncreatable telemetry directory: `record`
//    refuses naming it;
//  - `record` writes only into telemetry.directory and the reply names the file (a client path
//    elsewhere, e.g. /tmp/x.csv, is refused naming the directory);
//  - programs of any size go by content: a >= 1 MiB program loads and runs (chunked `upload`),
//    one over socket.max_program_bytes is refused naming the limit;
//  - under a real private /tmp (a mount namespace whose /tmp is a bind mount of a
//    "systemd-private-*" directory, as systemd makes it; needs root), a client's 100 KiB program
//    in its /tmp loads, a record is readable at the path in the reply, and a telemetry directory
//    inside the private /tmp is refused at start-up (exit 78);
//  - `contourctl gains save` keeps the config's mode, owner and group.
// Every wait is a bounded poll, never a timing assertion.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"

extern char** environ;

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
using contour::test::DaemonProcess;
using contour::test::slurp;

const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";

struct Proc {
  int rc = -1;
  std::string out, err;
};

pid_t spawn(const std::vector<std::string>& args, const std::string& out, const std::string& err) {
  std::vector<std::string> a = args;
  std::vector<char*> argv;
  for (auto& s : a) argv.push_back(s.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  if (posix_spawn(&pid, a[0].c_str(), &fa, nullptr, argv.data(), environ) != 0) pid = -1;
  posix_spawn_file_actions_destroy(&fa);
  return pid;
}

// Exit code, or -1 if still running after max_polls x 10 ms (then killed).
int wait_exit(pid_t pid, int max_polls) {
  int st = 0;
  for (int i = 0; i < max_polls; ++i) {
    if (::waitpid(pid, &st, WNOHANG) == pid) return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  return -1;
}

class TempDir {
 public:
  explicit TempDir(const std::string& tag, const fs::path& base = fs::temp_directory_path()) {
    static int n = 0;
    path_ = base / ("contourd_svc_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  [[nodiscard]] const fs::path& path() const { return path_; }
  [[nodiscard]] std::string operator/(const std::string& f) const { return (path_ / f).string(); }

 private:
  fs::path path_;
};

Proc run(const std::vector<std::string>& args, const TempDir& dir, int max_polls = 12000) {
  static int n = 0;
  const std::string o = dir / ("out" + std::to_string(n) + ".txt");
  const std::string e = dir / ("err" + std::to_string(n++) + ".txt");
  Proc p;
  const pid_t pid = spawn(args, o, e);
  if (pid < 0) {
    p.err = "cannot spawn " + args[0];
    return p;
  }
  p.rc = wait_exit(pid, max_polls);
  p.out = slurp(o);
  p.err = slurp(e);
  return p;
}

// config/sim.yaml with telemetry.directory and (when > 0) socket.max_program_bytes changed.
std::string write_config(const std::string& file, const std::string& telemetry_dir,
                         long max_program_bytes = 0) {
  std::string y = contour::test::sim_yaml();
  const std::string tel = "telemetry:\n  directory: /tmp\n";
  const auto t = y.find(tel);
  EXPECT_NE(t, std::string::npos) << "config/sim.yaml changed: no '" << tel << "'";
  if (t != std::string::npos) {
    y.replace(t, tel.size(), "telemetry:\n  directory: " + telemetry_dir + "\n");
  }
  if (max_program_bytes > 0) {
    const std::string mode = "  mode: \"0660\"\n";
    const auto m = y.find(mode);
    EXPECT_NE(m, std::string::npos);
    if (m != std::string::npos) {
      y.insert(m + mode.size(), "  max_program_bytes: " + std::to_string(max_program_bytes) + "\n");
    }
  }
  std::ofstream(file) << y;
  return file;
}

// A valid program of at least `bytes`: a 1 mm square traced `loops` times, each move followed by
// comment lines (what a CAM post-processor writes) that pad it to size.
std::string padded_program(std::size_t bytes, int loops = 5) {
  std::string p = "%\n(contourd service test: padded program)\nG21 G90 G17 G94\n";
  const int moves = 4 * loops;
  const std::string pad =
      "(padding: a CAM post-processor's comment about tool, fixture and operation .........)\n";
  const std::size_t per_move = bytes / static_cast<std::size_t>(moves) / pad.size() + 1;
  const char* corners[4] = {"G1 X1 Y0 F3000\n", "G1 X1 Y1\n", "G1 X0 Y1\n", "G1 X0 Y0\n"};
  for (int i = 0; i < moves; ++i) {
    p += corners[i % 4];
    for (std::size_t k = 0; k < per_move; ++k) p += pad;
  }
  p += "M2\n%\n";
  return p;
}

// The last line of a --json output, parsed (null when it is not JSON).
json last_json(const std::string& out) {
  std::stringstream ss(out);
  std::string l, last;
  while (std::getline(ss, l)) {
    if (!l.empty()) last = l;
  }
  return json::parse(last, nullptr, false);
}

DaemonProcess::Options opts(const std::string& config) {
  DaemonProcess::Options o;
  o.config = config;
  return o;
}

bool running_as_root_with_unshare() {
  if (::geteuid() != 0) return false;
  return std::system("unshare -m true >/dev/null 2>&1") == 0;
}

TEST(ServicePaths, MissingSocketDirectoryExits78NamingIt) {
  TempDir d("nosock");
  const std::string missing = d / "no-such-dir";
  const Proc p = run({contour::test::contourd_binary(), "--config", kSrc + "/config/sim.yaml",
                      "--socket", missing + "/c.sock"},
                     d, 3000);
  EXPECT_EQ(p.rc, 78) << p.err;
  EXPECT_NE(p.err.find(missing), std::string::npos) << p.err;
  EXPECT_NE(p.err.find("does not exist"), std::string::npos) << p.err;
}

// Not fatal (config/hil.yaml's default /var/lib/contourd/records is not creatable by a developer
// who is not root): the daemon runs, `record` refuses naming the directory and why.
TEST(ServicePaths, UncreatableTelemetryDirectoryMakesRecordRefuseNamingIt) {
  TempDir d("notel");
  std::ofstream(d / "a-file") << "x";
  const std::string records = d / "a-file/records";
  const std::string cfg = write_config(d / "c.yaml", records);
  DaemonProcess dp("svc_notel", opts(cfg));
  ASSERT_TRUE(dp.connected()) << dp.log();
  EXPECT_NE(dp.log().find("telemetry.directory: cannot create " + records), std::string::npos)
      << dp.log();
  const json r = dp.call({{"cmd", "record"}, {"action", "start"}, {"name", "x.csv"}});
  EXPECT_FALSE(r.value("ok", true)) << r.dump();
  EXPECT_NE(r.value("error", "").find("cannot create " + records), std::string::npos) << r.dump();
}

TEST(ServicePaths, RecordWritesOnlyIntoTheTelemetryDirectory) {
  TempDir d("rec");
  const std::string records = d / "records";  // the daemon creates it
  const std::string cfg = write_config(d / "c.yaml", records);
  DaemonProcess dp("svc_rec", opts(cfg));
  ASSERT_TRUE(dp.connected()) << dp.log();
  // A client path outside the telemetry directory: refused, naming the directory.
  const json bad = dp.call({{"cmd", "record"}, {"action", "start"}, {"path", "/tmp/run.csv"}});
  EXPECT_FALSE(bad.value("ok", true)) << bad.dump();
  EXPECT_NE(bad.value("error", "").find(records), std::string::npos) << bad.dump();
  for (const char* name : {"../x.csv", ".hidden", "a/b.csv", ""}) {
    const json r = dp.call({{"cmd", "record"}, {"action", "start"}, {"name", name}});
    EXPECT_FALSE(r.value("ok", true)) << name << " -> " << r.dump();
  }
  // contourctl: a name goes into the daemon's directory; the reply names the file.
  const Proc s = run({kCtl, "--socket", dp.sock(), "--json", "record", "start", "run1.csv"}, d);
  ASSERT_EQ(s.rc, 0) << s.err;
  const json started = last_json(s.out);
  EXPECT_EQ(started.value("path", ""), records + "/run1.csv") << s.out;
  EXPECT_EQ(started.value("directory", ""), records) << s.out;
  const Proc t = run({kCtl, "--socket", dp.sock(), "--json", "record", "stop"}, d);
  ASSERT_EQ(t.rc, 0) << t.err;
  EXPECT_EQ(last_json(t.out).value("path", ""), records + "/run1.csv") << t.out;
  EXPECT_EQ(slurp(records + "/run1.csv").rfind("cycle,t_s,", 0), 0u);
  // A path inside the directory is accepted as that file.
  const json in = dp.ok({{"cmd", "record"}, {"action", "start"}, {"path", records + "/run2.csv"}});
  EXPECT_EQ(in.value("path", ""), records + "/run2.csv");
  dp.ok({{"cmd", "record"}, {"action", "stop"}});
  EXPECT_TRUE(fs::exists(records + "/run2.csv"));
}

TEST(ServicePrograms, OneMebibyteProgramLoadsAndRunsByContent) {
  TempDir d("big");
  const std::string prog = d / "big.ngc";
  std::ofstream(prog) << padded_program(1 << 20);
  ASSERT_GE(fs::file_size(prog), 1u << 20);
  DaemonProcess dp("svc_big", opts(kSrc + "/config/sim.yaml"));
  ASSERT_TRUE(dp.connected()) << dp.log();
  const Proc r = run({kCtl, "--socket", dp.sock(), "--json", "run", prog, "--wait", "--quiet"}, d);
  ASSERT_EQ(r.rc, 0) << r.out << r.err << dp.log();
  const json res = last_json(r.out);
  EXPECT_TRUE(res.value("completed", false)) << r.out;
  EXPECT_EQ(res.value("state", ""), "READY") << r.out;
}

TEST(ServicePrograms, OverLimitProgramIsRefusedNamingTheLimit) {
  TempDir d("limit");
  const std::string cfg = write_config(d / "c.yaml", d / "records", 65536);
  DaemonProcess dp("svc_limit", opts(cfg));
  ASSERT_TRUE(dp.connected()) << dp.log();
  const std::string prog = d / "big.ngc";
  std::ofstream(prog) << padded_program(200 * 1024);
  const Proc r = run({kCtl, "--socket", dp.sock(), "load", prog}, d);
  EXPECT_EQ(r.rc, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("socket.max_program_bytes = 65536"), std::string::npos) << r.err;
  EXPECT_EQ(dp.state(), "READY");
  // Under the limit the same way works.
  const std::string small = d / "small.ngc";
  std::ofstream(small) << padded_program(60 * 1024, 1);
  const Proc ok = run({kCtl, "--socket", dp.sock(), "--json", "load", small}, d);
  EXPECT_EQ(ok.rc, 0) << ok.err;
  EXPECT_GT(last_json(ok.out).value("bytes", 0), 60 * 1024) << ok.out;
  // The upload protocol: a chunk that does not continue the upload is an error, never a
  // silently corrupted program.
  dp.ok({{"cmd", "upload"}, {"name", "p"}, {"offset", 0}, {"data", "G21\n"}});
  const json gap = dp.call({{"cmd", "upload"}, {"name", "p"}, {"offset", 10}, {"data", "G1 X1\n"}});
  EXPECT_FALSE(gap.value("ok", true)) << gap.dump();
  EXPECT_NE(gap.value("error", "").find("offset 10"), std::string::npos) << gap.dump();
}

// The daemon in a mount namespace whose /tmp is a private bind mount named like systemd's
// PrivateTmp= directory: what the unit does, without systemd.
class PrivateTmpTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!running_as_root_with_unshare()) {
      GTEST_SKIP() << "needs root and unshare(1) (mount namespaces) to make a private /tmp";
    }
  }
  // Starts contourd with /tmp private; returns its pid (spawned through unshare/sh, which exec).
  pid_t start(const TempDir& run_dir, const std::string& cfg, const std::string& sock) {
    priv_ = run_dir / "systemd-private-0123-contourd.service-abc";
    fs::create_directories(priv_ + "/tmp");
    const std::string script = "mount --make-rprivate / && mount --bind " + priv_ + "/tmp /tmp && exec " +
                               contour::test::contourd_binary() + " --config " + cfg + " --socket " + sock;
    log_ = run_dir / "d.log";
    return spawn({"/usr/bin/unshare", "-m", "/bin/sh", "-c", script}, run_dir / "d.out", log_);
  }
  std::string priv_, log_;
};

TEST_F(PrivateTmpTest, ClientTmpProgramLoadsAndRecordIsReadableWhereTheReplySays) {
  // Everything the daemon must see lives outside /tmp (as /etc, /run, /var/lib under the unit).
  TempDir run_dir("ptmp", "/run");
  const std::string records = run_dir / "records";
  const std::string cfg = write_config(run_dir / "c.yaml", records);
  const std::string sock = run_dir / "c.sock";
  const pid_t pid = start(run_dir, cfg, sock);
  ASSERT_GT(pid, 0);
  Proc st;
  for (int i = 0; i < 1000; ++i) {
    st = run({kCtl, "--socket", sock, "--json", "status"}, run_dir);
    if (st.rc == 0 && last_json(st.out).value("state", "") == "READY") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(last_json(st.out).value("state", ""), "READY") << st.err << slurp(log_);
  // The client's program in the client's /tmp (not the daemon's): > 32 KiB.
  TempDir client("client");
  const std::string prog = client / "part.ngc";
  std::ofstream(prog) << padded_program(100 * 1024, 1);
  const Proc rec = run({kCtl, "--socket", sock, "--json", "record", "start", "part.csv"}, client);
  EXPECT_EQ(rec.rc, 0) << rec.err;
  const std::string csv = last_json(rec.out).value("path", "");
  const Proc r = run({kCtl, "--socket", sock, "--json", "run", prog, "--wait", "--quiet"}, client);
  EXPECT_EQ(r.rc, 0) << r.out << r.err << slurp(log_);
  EXPECT_TRUE(last_json(r.out).value("completed", false)) << r.out;
  const Proc stop = run({kCtl, "--socket", sock, "record", "stop"}, client);
  EXPECT_EQ(stop.rc, 0) << stop.err;
  EXPECT_EQ(csv, records + "/part.csv");
  EXPECT_GT(fs::file_size(csv), 1000u) << "the record is not where the reply says";
  // record start into the client's /tmp: refused (it would land in the daemon's private /tmp).
  const Proc tmp = run({kCtl, "--socket", sock, "record", "start", client / "x.csv"}, client);
  EXPECT_EQ(tmp.rc, 1);
  EXPECT_NE(tmp.err.find(records), std::string::npos) << tmp.err;
  EXPECT_TRUE(fs::is_empty(priv_ + "/tmp")) << "something was written into the private /tmp";
  ::kill(pid, SIGTERM);
  EXPECT_EQ(wait_exit(pid, 2000), 0) << slurp(log_);
}

TEST_F(PrivateTmpTest, TelemetryDirectoryInsidePrivateTmpExits78) {
  TempDir run_dir("ptmp78", "/run");
  const std::string cfg = write_config(run_dir / "c.yaml", "/tmp");
  const pid_t pid = start(run_dir, cfg, run_dir / "c.sock");
  ASSERT_GT(pid, 0);
  EXPECT_EQ(wait_exit(pid, 3000), 78) << slurp(log_);
  EXPECT_NE(slurp(log_).find("private /tmp"), std::string::npos) << slurp(log_);
}

TEST(ServiceGainsSave, KeepsModeOwnerAndGroup) {
  TempDir d("gains");
  const std::string cfg = d / "contourd.yaml";
  contour::test::write_sim_yaml(cfg);  // sim.yaml, its PLC program paths absolute
  ASSERT_EQ(::chmod(cfg.c_str(), 0640), 0);
  const bool root = ::geteuid() == 0;
  // As root: root:daemon (gid 1), the case. Otherwise the mode alone.
  if (root) {
    ASSERT_EQ(::chown(cfg.c_str(), 0, 1), 0);
  }
  DaemonProcess dp("svc_gains", opts(cfg));
  ASSERT_TRUE(dp.connected()) << dp.log();
  const Proc p = run({kCtl, "--socket", dp.sock(), "gains", "save", "--file", cfg}, d);
  ASSERT_EQ(p.rc, 0) << p.err;
  for (const std::string& f : {cfg, cfg + ".bak"}) {
    struct stat st {};
    ASSERT_EQ(::stat(f.c_str(), &st), 0) << f;
    EXPECT_EQ(st.st_mode & 07777, 0640u) << f << ": world-readable or mode changed";
    if (root) {
      EXPECT_EQ(st.st_uid, 0u) << f;
      EXPECT_EQ(st.st_gid, 1u) << f;
    }
  }
  // No temporary file left behind.
  for (const auto& e : fs::directory_iterator(d.path())) {
    EXPECT_EQ(e.path().filename().string().find(".contourd.yaml."), std::string::npos) << e.path();
  }
  const Proc chk = run({contour::test::contourd_binary(), "--config", cfg, "--check-config"}, d);
  EXPECT_EQ(chk.rc, 0) << chk.out << chk.err;
}

}  // namespace
