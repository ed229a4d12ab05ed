// `upload`: a part program of any size over the command socket, in chunks that each fit one
// socket line (socket.max_line_bytes). The daemon never needs to see the client's files: under
// systemd (PrivateTmp=yes, ProtectHome=yes) a client's path is not the daemon's.
#include <algorithm>
#include <chrono>
#include <string>

#include "daemon/commands.hpp"
#include "daemon/daemon.hpp"

namespace contour::daemon {

namespace {

using nlohmann::json;

// A connection that stopped sending chunks this long ago no longer holds the upload slot.
constexpr auto kUploadIdle = std::chrono::seconds(30);

}  // namespace

// One upload at a time (one program is loaded at a time anyway): memory stays bounded by
// socket.max_program_bytes whatever the clients do. offset must continue the upload exactly, so a
// lost or repeated chunk is an error, never a silently corrupted program.
json Daemon::cmd_upload(const json& req, const ClientInfo& client) {
  for (auto it = req.begin(); it != req.end(); ++it) {
    const auto& k = it.key();
    if (k != "id" && k != "cmd" && k != "name" && k != "offset" && k != "data" && k != "final") {
      throw CommandError("unknown argument '" + k + "'");
    }
  }
  if (!req.contains("name") || !req["name"].is_string() || req["name"].get<std::string>().empty()) {
    throw CommandError("upload: argument 'name' (the program's name) must be a non-empty string");
  }
  if (!req.contains("offset") || !req["offset"].is_number_unsigned()) {
    throw CommandError("upload: argument 'offset' must be a byte offset (0 starts an upload)");
  }
  if (!req.contains("data") || !req["data"].is_string()) {
    throw CommandError("upload: argument 'data' must be a string (the next chunk of the program)");
  }
  if (req.contains("final") && !req["final"].is_boolean()) {
    throw CommandError("upload: argument 'final' must be true or false");
  }
  const auto name = req["name"].get<std::string>();
  const auto offset = req["offset"].get<std::uint64_t>();
  const auto& data = req["data"].get_ref<const std::string&>();
  const bool final_chunk = req.value("final", false);
  const auto limit = static_cast<std::uint64_t>(cfg_.socket.max_program_bytes);
  const auto now = std::chrono::steady_clock::now();

  if (offset == 0) {
    if (upload_ && upload_->client != client.id && now - upload_->last < kUploadIdle) {
      throw CommandError("upload: another connection (pid " + std::to_string(upload_->pid) +
                         ") is uploading '" + upload_->name + "'; retry when it is done");
    }
    upload_ = Upload{client.id, client.pid, name, {}, now};
  } else if (!upload_ || upload_->client != client.id || upload_->name != name) {
    throw CommandError("upload: no upload of '" + name +
                       "' in progress on this connection (start with offset 0)");
  } else if (offset != upload_->text.size()) {
    const std::size_t have = upload_->text.size();
    upload_.reset();
    throw CommandError("upload: offset " + std::to_string(offset) + " does not continue '" + name +
                       "' (" + std::to_string(have) + " bytes received); upload discarded, start "
                       "again at offset 0");
  }
  if (offset + data.size() > limit) {
    upload_.reset();
    throw CommandError("upload: program '" + name + "' is larger than socket.max_program_bytes = " +
                       std::to_string(limit) + " bytes (config); upload discarded");
  }
  upload_->text += data;
  upload_->last = now;
  if (!final_chunk) return {{"name", name}, {"bytes", upload_->text.size()}, {"complete", false}};
  ProgramText src;
  src.name = name;
  src.text = std::move(upload_->text);
  upload_.reset();
  const std::size_t bytes = src.text.size();
  if (req.contains("start_line")) src.start_line = req.at("start_line").get<long>();
  json r = load_source(src, req.value("preview", false));
  r["bytes"] = bytes;
  return r;
}

}  // namespace contour::daemon
