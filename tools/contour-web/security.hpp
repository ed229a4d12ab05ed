#pragma once
// Request checks of contour-web that need no socket: which Host headers and WebSocket Origins are
// accepted, and which request targets map to which page file.
//
// DNS rebinding: a hostile page can make its own name resolve to 127.0.0.1; the browser then
// sends Host: evil.example:8080 and Origin: http://evil.example:8080 — same-origin from its point
// of view. So the Host header itself is checked: loopback names (localhost, 127.x, [::1]), IP
// literals (a user who typed the machine's address) and web.allowed_hosts only. A WebSocket
// upgrade must then carry an Origin equal to http://HOST (the page contour-web served) or one of
// web.allowed_origins (a TLS reverse proxy's https:// name). A request without Origin is not from
// a browser page (scripts, curl) and is let through; tokens still apply to it.
#include <string>
#include <string_view>
#include <vector>

namespace contour::web {

struct OriginPolicy {
  std::vector<std::string> allowed_hosts;    // host names, without port
  std::vector<std::string> allowed_origins;  // scheme://host[:port]
};

// Host header value ("name:port", "[v6]:port", "name") -> host part without port or brackets.
[[nodiscard]] std::string host_part(std::string_view host_header);
[[nodiscard]] bool host_allowed(std::string_view host_header, const OriginPolicy& p);
// origin: the Origin header ("" when absent).
[[nodiscard]] bool origin_allowed(std::string_view origin, std::string_view host_header,
                                  const OriginPolicy& p);

// Request target -> a relative file path under the page directory ("index.html" for "/"), or ""
// when the target is not a page file (other characters, "..", hidden files). Query and fragment
// are ignored.
[[nodiscard]] std::string static_path(std::string_view target);
[[nodiscard]] const char* content_type(std::string_view path);

}  // namespace contour::web
