#include "drivers/canopen/probe.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <span>
#include <thread>

namespace contour::drivers::canopen {

namespace {

using Clock = std::chrono::steady_clock;

std::string object_label(std::uint16_t index, std::uint8_t sub) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%04X:%02X", index, sub);
  return b;
}

class Prober {
 public:
  Prober(CanBus& bus, const CanProbeSettings& s) : bus_(bus), s_(s) {}

  // Receives everything waiting until `until`, recording heartbeats/boot-ups and SDO answers.
  void pump_until(Clock::time_point until) {
    for (;;) {
      CanFrame f;
      while (bus_.receive(f)) note(f);
      const auto left = until - Clock::now();
      if (left <= Clock::duration::zero()) return;
      bus_.wait_readable(std::chrono::duration_cast<std::chrono::nanoseconds>(left).count());
    }
  }

  // Sends, waiting briefly when the socket queue is full (a probe may wait; it must not drop).
  bool send(const CanFrame& f) {
    for (int i = 0; i < 200; ++i) {
      const SendResult r = bus_.send(f);
      if (r == SendResult::kOk) return true;
      if (r == SendResult::kError) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return false;
  }

  // One SDO transfer (expedited or segmented). Returns the data, or nullopt with `error` set.
  std::optional<std::vector<std::uint8_t>> sdo(std::uint8_t node, std::uint16_t index,
                                               std::uint8_t sub, bool upload,
                                               std::span<const std::uint8_t> data,
                                               std::string& error) {
    const std::string what = object_label(index, sub);
    SdoTransfer t;
    const CanFrame req =
        upload ? t.start_upload(node, index, sub) : t.start_download(node, index, sub, data);
    if (!send(req)) {
      error = what + ": send failed (bus " + bus_state_name(bus_.bus_state()) + ")";
      return std::nullopt;
    }
    auto deadline = Clock::now() + s_.sdo_timeout;
    while (t.status() == SdoTransfer::Status::kWaiting) {
      const auto left = deadline - Clock::now();
      if (left <= Clock::duration::zero()) break;
      if (!bus_.wait_readable(std::chrono::duration_cast<std::chrono::nanoseconds>(left).count()))
        continue;
      CanFrame f;
      while (t.status() == SdoTransfer::Status::kWaiting && bus_.receive(f)) {
        note(f);
        if (!f.error && !f.rtr && !f.extended && f.id == kCobSdoTx + node) {
          if (auto next = t.on_frame(f)) send(*next);
          deadline = Clock::now() + s_.sdo_timeout;  // per request/response pair
        }
      }
    }
    switch (t.status()) {
      case SdoTransfer::Status::kDone:
        return t.data();
      case SdoTransfer::Status::kAborted:
        error = what + ": " +
                (t.abort_from_server() ? "aborted by the drive: " : "aborted by the probe: ") +
                sdo_abort_text(t.abort_code());
        return std::nullopt;
      default:
        break;
    }
    send(t.timeout_abort());
    error = what + ": no response in " + std::to_string(s_.sdo_timeout.count()) + " ms";
    return std::nullopt;
  }

  std::optional<std::uint32_t> upload_u32(CanProbeResult& r, std::uint16_t index,
                                          std::uint8_t sub) {
    std::string err;
    const auto d = sdo(r.node_id, index, sub, true, {}, err);
    if (!d) {
      r.errors.push_back(err);
      return std::nullopt;
    }
    r.found = true;
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < d->size() && k < 4; ++k)
      v |= static_cast<std::uint32_t>((*d)[k]) << (8 * k);
    return v;
  }

  bool download_u16(CanProbeResult& r, std::uint16_t index, std::uint8_t sub, std::uint16_t v) {
    std::uint8_t b[2];
    put_u16(b, v);
    std::string err;
    if (sdo(r.node_id, index, sub, false, b, err)) return true;
    r.errors.push_back(err);
    return false;
  }

  // Scan: one expedited upload of 0x1000:00 per candidate, in batches, answers collected
  // together (127 serial timeouts would take ~40 s; batches of 8 take ~1 s).
  void scan(const std::vector<std::uint8_t>& candidates) {
    constexpr std::size_t kBatch = 8;
    for (std::size_t i = 0; i < candidates.size(); i += kBatch) {
      const std::size_t end = std::min(candidates.size(), i + kBatch);
      std::array<SdoTransfer, kBatch> t{};
      for (std::size_t k = i; k < end; ++k) send(t[k - i].start_upload(candidates[k], 0x1000, 0));
      pump_until(Clock::now() + s_.scan_timeout);
      // A node that answered with a segmented initiate waits for a segment request: abort it.
      for (std::size_t k = i; k < end; ++k)
        if (sdo_seen_[candidates[k]] && (last_sdo_cs_[candidates[k]] & 0xE3) == 0x41)
          send(sdo_abort_frame(candidates[k], false, 0x1000, 0, 0x08000000));
    }
  }

  [[nodiscard]] bool heard(std::uint8_t n) const { return nmt_[n].has_value(); }
  [[nodiscard]] bool sdo_seen(std::uint8_t n) const { return sdo_seen_[n]; }
  [[nodiscard]] std::optional<NmtState> nmt(std::uint8_t n) const { return nmt_[n]; }
  [[nodiscard]] const std::string& nmt_source(std::uint8_t n) const { return nmt_source_[n]; }

 private:
  void note(const CanFrame& f) {
    if (f.error || f.rtr || f.extended) return;
    if (const std::uint8_t n = node_of(f.id, kCobHeartbeat); n != 0) {
      if (const auto st = decode_heartbeat(f)) {
        // A boot-up message means the node has just entered pre-operational (CiA 301 7.3.2.2).
        nmt_[n] = *st == NmtState::kBootUp ? NmtState::kPreOperational : *st;
        nmt_source_[n] = *st == NmtState::kBootUp ? "boot-up" : "heartbeat";
      }
    } else if (const std::uint8_t m = node_of(f.id, kCobSdoTx); m != 0) {
      sdo_seen_[m] = true;
      last_sdo_cs_[m] = f.dlc > 0 ? f.data[0] : 0;
    }
  }

  CanBus& bus_;
  const CanProbeSettings& s_;
  std::array<std::optional<NmtState>, 128> nmt_{};
  std::array<std::string, 128> nmt_source_{};
  std::array<bool, 128> sdo_seen_{};
  std::array<std::uint8_t, 128> last_sdo_cs_{};
};

}  // namespace

std::vector<CanProbeResult> probe_canopen(CanBus& bus, const CanProbeSettings& s) {
  Prober p(bus, s);
  p.pump_until(Clock::now() + s.listen);

  std::vector<CanProbeResult> out;
  std::array<bool, 128> listed{};
  for (const auto& n : s.nodes) {
    if (n.node_id < 1 || n.node_id > 127 || listed[n.node_id]) continue;
    listed[n.node_id] = true;
    CanProbeResult r;
    r.node_id = n.node_id;
    r.name = n.name;
    r.configured = true;
    out.push_back(std::move(r));
  }
  if (s.scan) {
    std::vector<std::uint8_t> candidates;
    for (std::uint8_t id = 1; id <= 127; ++id)
      if (!listed[id]) candidates.push_back(id);
    p.scan(candidates);
    for (std::uint8_t id : candidates) {
      if (!p.sdo_seen(id) && !p.heard(id)) continue;
      CanProbeResult r;
      r.node_id = id;
      out.push_back(std::move(r));
    }
  }

  for (auto& r : out) {
    r.found = p.heard(r.node_id) || p.sdo_seen(r.node_id);
    r.device_type = p.upload_u32(r, 0x1000, 0);
    // 0x1000 is mandatory: a node that does not give it (missing, or NMT stopped and so without
    // SDO server) would only time out on every further object.
    if (!r.device_type) {
      if (p.heard(r.node_id)) {
        r.found = true;
        r.nmt = p.nmt(r.node_id);
        r.nmt_source = p.nmt_source(r.node_id);
      }
      continue;
    }
    r.vendor_id = p.upload_u32(r, 0x1018, 1);
    r.product_code = p.upload_u32(r, 0x1018, 2);
    r.revision = p.upload_u32(r, 0x1018, 3);
    r.serial = p.upload_u32(r, 0x1018, 4);
    // Device profile number in the low 16 bits of 0x1000: 402 = drives and motion control.
    if (r.device_type && (*r.device_type & 0xFFFFu) == 402u) {
      if (const auto sw = p.upload_u32(r, 0x6041, 0))
        r.statusword = static_cast<std::uint16_t>(*sw);
      if (const auto md = p.upload_u32(r, 0x6061, 0))
        r.mode_display = static_cast<std::int8_t>(static_cast<std::uint8_t>(*md & 0xFFu));
    }
    bool temporary = false;
    if (!p.heard(r.node_id)) {
      // No heartbeat so far: find out whether the node produces one at all.
      const auto hb_ms = p.upload_u32(r, 0x1017, 0);
      if (hb_ms && *hb_ms != 0) {
        p.pump_until(Clock::now() + std::chrono::milliseconds(2 * *hb_ms + 100));
      } else if (hb_ms && s.temporary_heartbeat) {
        if (p.download_u16(r, 0x1017, 0, s.temporary_heartbeat_ms)) {
          temporary = true;
          const auto until =
              Clock::now() + std::chrono::milliseconds(3 * s.temporary_heartbeat_ms + 200);
          while (!p.heard(r.node_id) && Clock::now() < until)
            p.pump_until(std::min(until, Clock::now() + std::chrono::milliseconds(20)));
          if (!p.download_u16(r, 0x1017, 0, static_cast<std::uint16_t>(*hb_ms)))
            r.errors.push_back("heartbeat producer 0x1017 could not be restored to " +
                               std::to_string(*hb_ms) + " ms");
        }
      }
    }
    if (p.heard(r.node_id)) {
      r.found = true;
      r.nmt = p.nmt(r.node_id);
      r.nmt_source = p.nmt_source(r.node_id);
      if (temporary)
        r.nmt_source += " (producer 0x1017 set to " + std::to_string(s.temporary_heartbeat_ms) +
                        " ms for the probe, then restored)";
    }
  }
  return out;
}

}  // namespace contour::drivers::canopen
