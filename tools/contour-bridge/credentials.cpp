#include "tools/contour-bridge/credentials.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

namespace contour::bridge {

namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return {};
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

std::string mode_text(mode_t m) {
  char b[8];
  std::snprintf(b, sizeof b, "%04o", static_cast<unsigned>(m & 07777));
  return b;
}

}  // namespace

Credentials load_credentials(const std::string& path) {
  // Open first, then check the opened file (no window between the check and the read).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) {
    throw CredentialsError("mqtt.credentials_file: " + path + ": cannot open (" +
                           std::strerror(errno) + ")");
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw CredentialsError("mqtt.credentials_file: " + path + ": not a regular file");
  }
  if ((st.st_mode & 077) != 0) {
    ::close(fd);
    throw CredentialsError("mqtt.credentials_file: " + path + " has mode " +
                           mode_text(st.st_mode) +
                           ": it holds the broker password and must be readable by its owner "
                           "only (chmod 600 " + path + ")");
  }
  std::string text;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n > 0) {
      text.append(buf, static_cast<std::size_t>(n));
      if (text.size() > 64 * 1024) {
        ::close(fd);
        throw CredentialsError("mqtt.credentials_file: " + path + ": larger than 64 KiB");
      }
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int e = errno;
      ::close(fd);
      throw CredentialsError("mqtt.credentials_file: " + path + ": read: " + std::strerror(e));
    }
    break;
  }
  ::close(fd);
  Credentials c;
  bool have_user = false;
  bool have_pass = false;
  std::size_t pos = 0;
  int line_no = 0;
  while (pos <= text.size()) {
    const std::size_t nl = text.find('\n', pos);
    const std::string raw = text.substr(pos, nl == std::string::npos ? std::string::npos : nl - pos);
    pos = nl == std::string::npos ? text.size() + 1 : nl + 1;
    ++line_no;
    const std::string line = trim(raw);
    if (line.empty() || line[0] == '#') continue;
    const std::size_t colon = line.find(':');
    const std::string where = "mqtt.credentials_file: " + path + ":" + std::to_string(line_no);
    if (colon == std::string::npos) {
      throw CredentialsError(where + ": expected 'key: value' (keys: username, password, "
                                     "key_password)");
    }
    const std::string key = trim(line.substr(0, colon));
    const std::string value = trim(line.substr(colon + 1));
    if (key == "username") {
      c.username = value;
      have_user = true;
    } else if (key == "password") {
      c.password = value;
      have_pass = true;
    } else if (key == "key_password") {
      c.key_password = value;
    } else {
      throw CredentialsError(where + ": unknown key '" + key +
                             "' (keys: username, password, key_password)");
    }
  }
  if (have_pass && !have_user) {
    throw CredentialsError("mqtt.credentials_file: " + path + ": password without username");
  }
  if (have_user && c.username.empty()) {
    throw CredentialsError("mqtt.credentials_file: " + path + ": username is empty");
  }
  return c;
}

}  // namespace contour::bridge
