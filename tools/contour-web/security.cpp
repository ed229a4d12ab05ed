#include "tools/contour-web/security.hpp"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>

#include "config/web_config.hpp"

namespace contour::web {

namespace {
std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

bool ip_literal(const std::string& h) {
  in_addr a4{};
  in6_addr a6{};
  return ::inet_pton(AF_INET, h.c_str(), &a4) == 1 || ::inet_pton(AF_INET6, h.c_str(), &a6) == 1;
}
}  // namespace

std::string host_part(std::string_view host_header) {
  std::string h = lower(host_header);
  if (!h.empty() && h.front() == '[') {
    const auto close = h.find(']');
    return close == std::string::npos ? std::string() : h.substr(1, close - 1);
  }
  const auto colon = h.find(':');
  if (colon != std::string::npos) h = h.substr(0, colon);
  if (!h.empty() && h.back() == '.') h.pop_back();  // "localhost." is localhost
  return h;
}

bool host_allowed(std::string_view host_header, const OriginPolicy& p) {
  const std::string h = host_part(host_header);
  if (h.empty()) return false;
  if (config::is_loopback_host(h) || ip_literal(h)) return true;
  return std::any_of(p.allowed_hosts.begin(), p.allowed_hosts.end(),
                     [&](const std::string& a) { return lower(a) == h; });
}

bool origin_allowed(std::string_view origin, std::string_view host_header, const OriginPolicy& p) {
  if (origin.empty()) return true;  // not a browser page
  const std::string o = lower(origin);
  if (o == "null") return false;     // sandboxed frames, file:// pages
  for (const auto& a : p.allowed_origins) {
    if (lower(a) == o) return true;
  }
  return host_allowed(host_header, p) && o == "http://" + lower(host_header);
}

std::string static_path(std::string_view target) {
  const auto q = target.find_first_of("?#");
  if (q != std::string_view::npos) target = target.substr(0, q);
  if (target.empty() || target.front() != '/') return "";
  std::string rel(target.substr(1));
  if (rel.empty()) return "index.html";
  if (rel.size() > 200) return "";
  for (char ch : rel) {
    const bool ok = std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '-' ||
                    ch == '_' || ch == '/';
    if (!ok) return "";
  }
  std::size_t pos = 0;
  while (pos <= rel.size()) {
    const auto slash = rel.find('/', pos);
    const std::string seg = rel.substr(pos, slash == std::string::npos ? std::string::npos : slash - pos);
    if (seg.empty() || seg.front() == '.') return "";  // "..", ".hidden", "//"
    if (slash == std::string::npos) break;
    pos = slash + 1;
  }
  return rel;
}

const char* content_type(std::string_view path) {
  auto ends = [&](std::string_view ext) {
    return path.size() >= ext.size() && path.substr(path.size() - ext.size()) == ext;
  };
  if (ends(".html")) return "text/html; charset=utf-8";
  if (ends(".js") || ends(".mjs")) return "text/javascript; charset=utf-8";
  if (ends(".css")) return "text/css; charset=utf-8";
  if (ends(".svg")) return "image/svg+xml";
  if (ends(".png")) return "image/png";
  if (ends(".json")) return "application/json";
  if (ends(".txt") || ends("LICENSE")) return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

}  // namespace contour::web
