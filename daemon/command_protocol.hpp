#pragma once
// The pure part of the command socket protocol (command_server.hpp): one request line in, one
// reply object out; no socket, no thread, no clock. CommandServer feeds it every complete line;
// tests/fuzz/command_fuzz.cpp feeds it arbitrary bytes.
//
// Request:  {"id": <any>, "cmd": "<name>", ...args}
// Reply:    {"id": <echoed>, "ok": true, "result": <handler's value>}
//           {"id": <echoed>, "ok": false, "error": "<text>"}     ("id" only when the request had
//           one)
//
// Rejected before the handler runs (error replies, texts are part of the contract):
//   "malformed JSON", "request nested deeper than 64 levels", "request must be a JSON object",
//   "missing string field 'cmd'".
// The nesting limit exists because nlohmann::json copies and dumps values recursively: a 64 KiB
// line of '[' would otherwise recurse ~32k frames deep on the server thread when the id is echoed.
//
// Handler exceptions become error replies: CommandError -> its text; nlohmann::json::exception
// -> "bad argument: ..."; any other std::exception -> "internal error: ...". Never throws itself
// (except std::bad_alloc).
#include <cstddef>
#include <functional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>

namespace contour::daemon {

inline constexpr std::size_t kMaxRequestDepth = 64;

// Thrown by a handler for an error reply ({"ok": false, "error": what()}).
class CommandError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct RequestOutcome {
  nlohmann::json reply;  // always an object with a boolean "ok"
  bool error = false;    // reply["ok"] == false (counted in CommandServerStats::errors)
};

using RequestHandler = std::function<nlohmann::json(const nlohmann::json& request)>;

// Maximum nesting depth of arrays/objects in `text`, scanning brackets outside strings (the text
// need not be valid JSON; stops counting at limit + 1).
[[nodiscard]] std::size_t json_nesting_depth(std::string_view text, std::size_t limit) noexcept;

// Parses one request line (without its newline) and, when it is a well-formed request, calls
// `handler` with the request object.
[[nodiscard]] RequestOutcome handle_request_line(std::string_view line,
                                                 const RequestHandler& handler);

// An error reply without a request ("request line longer than N bytes; discarded").
[[nodiscard]] nlohmann::json error_reply(const std::string& message);

// Serialises a reply (or event) as one protocol line: compact JSON, invalid UTF-8 replaced by
// U+FFFD, terminated by exactly one '\n' (JSON escapes every control character inside strings, so
// the line contains no other newline).
[[nodiscard]] std::string to_line(const nlohmann::json& j);

}  // namespace contour::daemon
