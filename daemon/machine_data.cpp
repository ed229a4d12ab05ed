#include "daemon/machine_data.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "daemon/daemon.hpp"  // expand_env

namespace contour::daemon {

namespace {

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MachineDataError(path + ": cannot open (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

bool same_tools(const std::vector<control::ToolData>& a, const std::vector<control::ToolData>& b) {
  return control::format_tool_table(a) == control::format_tool_table(b);
}

}  // namespace

void write_file_atomic(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw MachineDataError(tmp + ": cannot create (" + std::strerror(errno) + ")");
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string e = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      throw MachineDataError(tmp + ": write failed (" + e + ")");
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string e = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw MachineDataError(tmp + ": fsync/close failed (" + e + ")");
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string e = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw MachineDataError(path + ": rename failed (" + e + ")");
  }
  const std::string dir = p.has_parent_path() ? p.parent_path().string() : std::string(".");
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);  // the rename itself durable; best effort (some filesystems refuse)
    ::close(dfd);
  }
}

MachineData::MachineData(const config::ProgramConfig& p, std::string var_path, std::string tbl_path)
    : var_path_(std::move(var_path)), tbl_path_(std::move(tbl_path)) {
  for (int s = 1; s <= 6; ++s) {
    const auto& w = p.work_offsets_mm[static_cast<std::size_t>(s - 1)];
    m_.set_work_offset_mm(s, Eigen::Vector3d(w[0], w[1], w[2]));
  }
  m_.set_g28_mm(Eigen::Vector3d(p.g28_mm[0], p.g28_mm[1], p.g28_mm[2]));
  m_.set_g30_mm(Eigen::Vector3d(p.g30_mm[0], p.g30_mm[1], p.g30_mm[2]));
  for (const auto& t : p.tools) {
    control::ToolData d;
    d.number = t.number;
    d.pocket = t.number;
    d.offset[2] = t.length_mm;
    m_.tools.push_back(d);
  }
  try {
    if (!var_path_.empty() && std::filesystem::exists(var_path_)) {
      control::apply_var_file(m_, control::parse_var_file(read_file(var_path_), var_path_));
    }
    if (!tbl_path_.empty()) m_.tools = control::parse_tool_table(read_file(tbl_path_), tbl_path_);
  } catch (const control::MachineFileError& e) {
    throw MachineDataError(e.what());
  }
}

control::MachineContext MachineData::snapshot() const {
  std::lock_guard lk(mu_);
  return m_;
}

Eigen::Vector3d MachineData::tool_offset_mm() const {
  std::lock_guard lk(mu_);
  return tool_offset_mm_;
}

void MachineData::set_tool_offset_mm(const Eigen::Vector3d& v) {
  std::lock_guard lk(mu_);
  tool_offset_mm_ = v;
}

std::uint64_t MachineData::generation() const {
  std::lock_guard lk(mu_);
  return generation_;
}

void MachineData::commit(const control::MachineContext& m) {
  std::lock_guard lk(mu_);
  write_locked(m, !same_tools(m.tools, m_.tools));
  m_ = m;
  ++generation_;
}

void MachineData::commit(const control::MachineContext& m, const Eigen::Vector3d& tool_offset_mm) {
  std::lock_guard lk(mu_);
  write_locked(m, !same_tools(m.tools, m_.tools));
  m_ = m;
  tool_offset_mm_ = tool_offset_mm;
  ++generation_;
}

void MachineData::write_locked(const control::MachineContext& m, bool tools_changed) const {
  if (!var_path_.empty()) write_file_atomic(var_path_, control::format_var_file(m));
  if (tools_changed && !tbl_path_.empty()) write_file_atomic(tbl_path_, control::format_tool_table(m.tools));
}

std::string resolve_config_path(const std::string& config_file, const std::string& p) {
  if (p.empty()) return {};
  std::filesystem::path q(expand_env(p));
  if (q.is_relative()) q = std::filesystem::absolute(config_file).parent_path() / q;
  return q.lexically_normal().string();
}

namespace {
constexpr const char* kSystemNames[10] = {"", "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"};
}

int coord_system_index(const std::string& name) {
  for (int i = 1; i <= 9; ++i) {
    if (name == kSystemNames[i]) return i;
  }
  return 0;
}

const char* coord_system_name(int system) {
  return system >= 1 && system <= 9 ? kSystemNames[system] : "G54";
}

}  // namespace contour::daemon
