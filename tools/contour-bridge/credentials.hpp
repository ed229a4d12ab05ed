#pragma once
// Broker credentials for contour-bridge: `mqtt.credentials_file`, lines `key: value` (username,
// password, key_password; '#' comments). The file must be a regular file that only its owner can
// read or write (mode 0600 or 0400): anything else is refused at start with the file's mode and
// the chmod that fixes it. Values are never logged or put into an error message; errors name the
// file, the line and the key only.
#include <stdexcept>
#include <string>

namespace contour::bridge {

struct Credentials {
  std::string username;
  std::string password;
  std::string key_password;  // passphrase of tls.key_file, if it has one
};

struct CredentialsError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Throws CredentialsError.
Credentials load_credentials(const std::string& path);

}  // namespace contour::bridge
