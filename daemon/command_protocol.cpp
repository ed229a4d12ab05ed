#include "daemon/command_protocol.hpp"

#include <utility>

namespace contour::daemon {

std::size_t json_nesting_depth(std::string_view text, std::size_t limit) noexcept {
  std::size_t depth = 0;
  std::size_t max_depth = 0;
  bool in_string = false;
  bool escaped = false;
  for (const char ch : text) {
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (ch == '\\') {
        escaped = true;
      } else if (ch == '"') {
        in_string = false;
      }
      continue;
    }
    if (ch == '"') {
      in_string = true;
    } else if (ch == '[' || ch == '{') {
      if (++depth > max_depth) {
        max_depth = depth;
        if (max_depth > limit) break;
      }
    } else if ((ch == ']' || ch == '}') && depth > 0) {
      --depth;
    }
  }
  return max_depth;
}

nlohmann::json error_reply(const std::string& message) {
  return nlohmann::json{{"ok", false}, {"error", message}};
}

RequestOutcome handle_request_line(std::string_view line, const RequestHandler& handler) {
  RequestOutcome out;
  out.reply = nlohmann::json::object();
  auto fail = [&](std::string msg) {
    out.error = true;
    out.reply["ok"] = false;
    out.reply["error"] = std::move(msg);
  };
  // Depth first: a too-deep line is never handed to the (recursive) DOM at all.
  if (json_nesting_depth(line, kMaxRequestDepth) > kMaxRequestDepth) {
    fail("request nested deeper than " + std::to_string(kMaxRequestDepth) + " levels");
    return out;
  }
  const nlohmann::json req = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
  if (req.is_discarded()) {
    fail("malformed JSON");
    return out;
  }
  if (!req.is_object()) {
    fail("request must be a JSON object");
    return out;
  }
  if (const auto id = req.find("id"); id != req.end()) out.reply["id"] = *id;
  const auto cmd = req.find("cmd");
  if (cmd == req.end() || !cmd->is_string()) {
    fail("missing string field 'cmd'");
    return out;
  }
  try {
    nlohmann::json result = handler(req);
    out.reply["ok"] = true;
    out.reply["result"] = std::move(result);
  } catch (const CommandError& e) {
    fail(e.what());
  } catch (const nlohmann::json::exception& e) {
    fail(std::string("bad argument: ") + e.what());
  } catch (const std::bad_alloc&) {
    throw;
  } catch (const std::exception& e) {
    fail(std::string("internal error: ") + e.what());
  }
  return out;
}

std::string to_line(const nlohmann::json& j) {
  std::string s = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  s.push_back('\n');
  return s;
}

}  // namespace contour::daemon
