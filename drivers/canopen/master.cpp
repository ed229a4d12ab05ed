#include "drivers/canopen/master.hpp"

#include <time.h>

#include <chrono>
#include <cstdio>
#include <thread>

namespace contour::drivers::canopen {

namespace {

std::int64_t mono_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

std::string hex(std::uint32_t v, int width) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%0*X", width, v);
  return b;
}

std::string object_name(std::uint16_t index, std::uint8_t sub) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%04X:%02X", index, sub);
  return b;
}

constexpr std::uint16_t kOptionalObjects[] = {0x1006, 0x1007, 0x1008, 0x1016,
                                              0x605A, 0x6085, 0x60C2};

bool skipped(const NodeSetup& n, std::uint16_t index, std::uint8_t sub) {
  for (const auto& o : n.quirks.skip)
    if (o.matches(index, sub)) return true;
  return false;
}

// The PDO numbers (0: PDO1) of NodeSetup::touch_probe: the TPDO after the digital inputs'; the
// RPDO 0 (0x60B8 appended to RPDO1) when RPDO1 has 2 bytes and an entry to spare on this drive,
// else the one after the digital outputs'. {-1, -1} without the touch probe.
TouchProbePdos touch_probe_layout(const NodeSetup& n) {
  TouchProbePdos p;
  if (!n.touch_probe || n.kind != NodeKind::kDrive) return p;
  p.tpdo = static_cast<std::int8_t>(n.digital_inputs ? 2 : 1);
  const bool fits = n.rpdo.bytes() + 2 <= 8 && n.rpdo.count < PdoMapping::kMaxEntries &&
                    n.rpdo.count < n.quirks.rpdo_max_entries;
  p.rpdo = static_cast<std::int8_t>(fits ? 0 : (n.digital_output_mask != 0 ? 2 : 1));
  return p;
}

std::string entries_text(const PdoMapping& m) {
  std::string s;
  for (std::size_t k = 0; k < m.count; ++k) s += (k ? ", " : "") + hex(m.entries[k].index, 4);
  return s;
}

}  // namespace

std::span<const std::uint16_t> optional_objects() noexcept { return kOptionalObjects; }

std::vector<CanFilter> master_rx_filters(const MasterConfig& cfg) {
  std::vector<CanFilter> f;
  for (const auto& n : cfg.nodes) {
    for (std::uint32_t base : {kCobEmcy, kCobSdoTx, kCobHeartbeat})
      f.push_back({base + n.node_id, 0x7FF});
    if (n.kind == NodeKind::kIoModule) {
      const std::size_t tpdos = io_module_pdos(n.io, false).size();
      for (std::size_t k = 0; k < tpdos && k < 4; ++k)
        f.push_back({kCobTpdo[k] + n.node_id, 0x7FF});
      continue;
    }
    f.push_back({kCobTpdo[0] + n.node_id, 0x7FF});
    if (n.digital_inputs) f.push_back({kCobTpdo[1] + n.node_id, 0x7FF});
    if (const auto p = touch_probe_layout(n); p.tpdo > 0 && p.tpdo < 4)
      f.push_back({kCobTpdo[static_cast<std::size_t>(p.tpdo)] + n.node_id, 0x7FF});
  }
  return f;
}

std::vector<PdoMapping> io_module_pdos(const IoModuleMap& io, bool rx) {
  std::vector<PdoMapping> out;
  auto add = [&](std::uint16_t index, std::uint8_t mask, std::uint8_t bits) {
    for (int k = 0; k < kIoChannels; ++k) {
      if (((mask >> k) & 1u) == 0) continue;
      if (out.empty() || out.back().bytes() + bits / 8u > 8 ||
          out.back().count >= PdoMapping::kMaxEntries)
        out.emplace_back();
      PdoMapping& m = out.back();
      m.entries[m.count++] = PdoEntry{index, static_cast<std::uint8_t>(k + 1), bits};
    }
  };
  if (rx) {
    add(0x6200, io.digital_outputs, 8);
    add(0x6411, io.analog_outputs, 16);
  } else {
    add(0x6000, io.digital_inputs, 8);
    add(0x6401, io.analog_inputs, 16);
  }
  return out;
}

PdoMapping digital_inputs_tpdo() {
  PdoMapping p;
  p.entries[0] = {0x60FD, 0, 32};
  p.count = 1;
  return p;
}

PdoMapping digital_outputs_rpdo() {
  PdoMapping p;
  p.entries[0] = {0x60FE, 1, 32};
  p.count = 1;
  return p;
}

PdoMapping touch_probe_tpdo() {
  PdoMapping p;
  p.entries[0] = {0x60B9, 0, 16};
  p.entries[1] = {0x60BA, 0, 32};
  p.count = 2;
  return p;
}

PdoMapping touch_probe_rpdo() {
  PdoMapping p;
  p.entries[0] = {0x60B8, 0, 16};
  p.count = 1;
  return p;
}

PdoMapping default_rpdo(DriveMode m) {
  PdoMapping p;
  p.entries[0] = {0x6040, 0, 16};
  p.entries[1] = {static_cast<std::uint16_t>(m == DriveMode::kCsp ? 0x607A : 0x60FF), 0, 32};
  p.count = 2;
  return p;
}

PdoMapping default_tpdo() {
  PdoMapping p;
  p.entries[0] = {0x6041, 0, 16};
  p.entries[1] = {0x6064, 0, 32};
  p.count = 2;
  return p;
}

Master::Master(CanBus& bus, MasterConfig cfg, Log log_fn)
    : bus_(bus), cfg_(std::move(cfg)), log_(std::move(log_fn)) {
  index_by_node_.fill(-1);
  if (cfg_.nodes.empty()) throw StartupError("bus: no nodes configured");
  std::vector<CyclicFrame> frames{{0, 1}};  // SYNC
  io_pdos_.resize(cfg_.nodes.size());
  probe_pdos_.resize(cfg_.nodes.size());
  for (std::size_t i = 0; i < cfg_.nodes.size(); ++i) {
    const auto& n = cfg_.nodes[i];
    const std::string who = node_label(n.node_id);
    if (n.node_id < 1 || n.node_id > 127) throw StartupError(who + ": node-id out of 1..127");
    if (index_by_node_[n.node_id] >= 0) throw StartupError(who + ": node-id used twice");
    index_by_node_[n.node_id] = static_cast<std::int16_t>(i);
    if (n.kind == NodeKind::kIoModule) {
      // A CiA 401 module: the PDOs follow from what the PLC uses; each one more frame a cycle.
      const auto tx = io_module_pdos(n.io, false);
      const auto rx = io_module_pdos(n.io, true);
      if (tx.empty() && rx.empty()) throw StartupError(who + ": CiA 401 module maps no object");
      const std::string prof = " (profile '" + n.quirks.profile + "')";
      if (tx.size() > n.quirks.tpdos)
        throw StartupError(who + ": the CiA 401 inputs used need " + std::to_string(tx.size()) +
                           " TPDOs, the module has " + std::to_string(n.quirks.tpdos) + prof);
      if (rx.size() > n.quirks.rpdos)
        throw StartupError(who + ": the CiA 401 outputs used need " + std::to_string(rx.size()) +
                           " RPDOs, the module has " + std::to_string(n.quirks.rpdos) + prof);
      IoPdos& p = io_pdos_[i];
      for (const auto& m : tx) p.tx[p.ntx++] = m;
      for (const auto& m : rx) p.rx[p.nrx++] = m;
      const int every = n.sync_every < 1 ? 1 : n.sync_every;
      for (const auto& m : tx) frames.push_back({static_cast<int>(m.bytes()), every});
      for (const auto& m : rx) frames.push_back({static_cast<int>(m.bytes()), every});
      continue;
    }
    for (const auto* m : {&n.rpdo, &n.tpdo}) {
      const std::string err = m->validate();
      if (!err.empty()) throw StartupError(who + ": PDO mapping: " + err);
    }
    if (n.rpdo.find(0x6040) < 0) throw StartupError(who + ": RPDO must map 0x6040 controlword");
    if (n.tpdo.find(0x6041) < 0) throw StartupError(who + ": TPDO must map 0x6041 statusword");
    const DriveQuirks& q = n.quirks;
    const std::string prof = " (drive profile '" + q.profile + "')";
    if (q.rpdos < 1 || q.rpdos > 4 || q.tpdos < 1 || q.tpdos > 4)
      throw StartupError(who + ": the drive must have 1 to 4 RPDOs and TPDOs" + prof);
    // The master maps everything it needs into RPDO1/TPDO1; a drive whose PDOs take fewer
    // entries cannot be driven with this mapping.
    if (n.rpdo.count > q.rpdo_max_entries)
      throw StartupError(who + ": RPDO1 needs " + std::to_string(n.rpdo.count) + " entries (" +
                         entries_text(n.rpdo) + "), the drive maps at most " +
                         std::to_string(q.rpdo_max_entries) + prof);
    if (n.tpdo.count > q.tpdo_max_entries)
      throw StartupError(who + ": TPDO1 needs " + std::to_string(n.tpdo.count) + " entries (" +
                         entries_text(n.tpdo) + "), the drive maps at most " +
                         std::to_string(q.tpdo_max_entries) + prof);
    for (const auto& o : q.skip) {
      bool ok = false;
      for (std::uint16_t k : kOptionalObjects) ok = ok || k == o.index;
      if (!ok)
        throw StartupError(who + ": object " + hex(o.index, 4) +
                           " is mandatory for this master and cannot be skipped" + prof);
    }
    // The digital I/O has a PDO of its own (TPDO1/RPDO1 keep their mapping: the default ones
    // have no room for 32 more bits in 8 bytes).
    if (n.digital_inputs && q.tpdos < 2)
      throw StartupError(who + ": 0x60FD digital inputs (home switch or plc cia402 input binding) need TPDO2, "
                               "the drive has 1 TPDO" + prof);
    if (n.digital_output_mask != 0 && q.rpdos < 2)
      throw StartupError(who + ": 0x60FE:01 digital outputs (plc cia402 output binding) need "
                               "RPDO2, the drive has 1 RPDO" + prof);
    // The touch probe (home.use_index): its status and position in a TPDO of their own (with
    // 0x60FD they would need 10 bytes); 0x60B8 in RPDO1 when it fits, else an RPDO of its own.
    const TouchProbePdos probe = touch_probe_layout(n);
    if (probe.tpdo > 0 && q.tpdos <= probe.tpdo)
      throw StartupError(who + ": 0x60B9/0x60BA touch probe status and position (home.use_index) need TPDO" +
                         std::to_string(probe.tpdo + 1) + ", the drive has " +
                         std::to_string(q.tpdos) + (q.tpdos == 1 ? " TPDO" : " TPDOs") + prof);
    if (probe.rpdo > 0 && q.rpdos <= probe.rpdo)
      throw StartupError(who + ": 0x60B8 touch probe function (home.use_index) does not fit into RPDO1 (" +
                         entries_text(n.rpdo) + ") and needs RPDO" + std::to_string(probe.rpdo + 1) +
                         ", the drive has " + std::to_string(q.rpdos) +
                         (q.rpdos == 1 ? " RPDO" : " RPDOs") + prof);
    if (probe.rpdo == 0) {
      PdoMapping& m = cfg_.nodes[i].rpdo;  // `n` is this node: it sees the appended entry
      m.entries[m.count++] = touch_probe_rpdo().entries[0];
    }
    probe_pdos_[i] = probe;
    const int every = n.sync_every < 1 ? 1 : n.sync_every;
    frames.push_back({static_cast<int>(n.rpdo.bytes()), every});
    frames.push_back({static_cast<int>(n.tpdo.bytes()), every});
    if (n.digital_inputs) frames.push_back({4, every});
    if (n.digital_output_mask != 0) frames.push_back({4, every});
    if (probe.tpdo > 0) frames.push_back({static_cast<int>(touch_probe_tpdo().bytes()), every});
    if (probe.rpdo > 0) frames.push_back({static_cast<int>(touch_probe_rpdo().bytes()), every});
  }
  load_ = estimate_bus_load(frames, cfg_.bitrate, cfg_.period_us * 1e-6);
  char msg[200];
  std::snprintf(msg, sizeof msg,
                "bus load at %u bit/s, %u us: %.1f %% nominal, %.1f %% worst case (bit stuffing), "
                "busiest cycle %.1f %%, %.3f frames/cycle",
                cfg_.bitrate, cfg_.period_us, 100.0 * load_.nominal, 100.0 * load_.worst_case,
                100.0 * load_.peak_cycle_worst, load_.frames_per_cycle_avg_x1000 / 1000.0);
  log(msg);
  if (load_.worst_case > cfg_.load_ceiling) {
    char e[160];
    std::snprintf(e, sizeof e, "bus load %.1f %% worst case exceeds the ceiling of %.1f %%",
                  100.0 * load_.worst_case, 100.0 * cfg_.load_ceiling);
    throw StartupError(e);
  }
  rt_.resize(cfg_.nodes.size());
  seq_.resize(cfg_.nodes.size());
  unwrap_.resize(cfg_.nodes.size());
  booted_.assign(cfg_.nodes.size(), false);
}

std::string Master::node_label(std::uint8_t node_id) const {
  std::string s = "node " + std::to_string(node_id);
  for (const auto& n : cfg_.nodes)
    if (n.node_id == node_id && !n.name.empty()) s += " (" + n.name + ")";
  return s;
}

int Master::index_of(std::uint8_t node_id) const noexcept {
  return node_id < 128 ? index_by_node_[node_id] : -1;
}

// ------------------------------------------------------------------ SDO
std::vector<std::uint8_t> Master::run_sdo(std::uint8_t node_id, std::uint16_t index,
                                          std::uint8_t sub, bool upload,
                                          std::span<const std::uint8_t> data) {
  const std::string what = node_label(node_id) + ": SDO " + (upload ? "upload " : "download ") +
                           object_name(index, sub);
  SdoTransfer t;
  const int node_index = index_of(node_id);
  const bool expedited_only =
      node_index >= 0 && cfg_.nodes[static_cast<std::size_t>(node_index)].quirks.expedited_only;
  if (expedited_only && !upload && data.size() > 4)
    throw StartupError(what + ": " + std::to_string(data.size()) +
                       " bytes need a segmented transfer, the drive takes expedited SDO only");
  const std::int64_t timeout_ns = static_cast<std::int64_t>(cfg_.sdo_timeout_ms) * 1000000LL;
  for (int attempt = 0; attempt <= cfg_.sdo_retries; ++attempt) {
    CanFrame req = upload ? t.start_upload(node_id, index, sub, expedited_only)
                          : t.start_download(node_id, index, sub, data);
    if (bus_.send(req) != SendResult::kOk) throw StartupError(what + ": send failed");
    std::int64_t deadline = mono_ns() + timeout_ns;
    while (t.status() == SdoTransfer::Status::kWaiting) {
      const std::int64_t left = deadline - mono_ns();
      if (left <= 0) break;
      if (!bus_.wait_readable(left)) continue;
      CanFrame f;
      while (t.status() == SdoTransfer::Status::kWaiting && bus_.receive(f)) {
        if (!f.error && f.id == kCobSdoTx + node_id) {
          auto next = t.on_frame(f);
          if (next) bus_.send(*next);
          deadline = mono_ns() + timeout_ns;  // the timeout is per request/response pair
        } else {
          dispatch(f, false);
        }
      }
    }
    switch (t.status()) {
      case SdoTransfer::Status::kDone: return t.data();
      case SdoTransfer::Status::kAborted: {
        const bool refused_segmented = expedited_only && !t.abort_from_server() &&
                                       t.abort_code() == 0x06010000;
        throw SdoAbortError(what + ": " +
                                (t.abort_from_server() ? "aborted by the drive: "
                                                       : "aborted by the master: ") +
                                sdo_abort_text(t.abort_code()) +
                                (refused_segmented ? " (the drive answered with a segmented "
                                                     "upload; its profile says expedited only)"
                                                   : ""),
                            t.abort_code(), t.abort_from_server());
      }
      default: break;
    }
    bus_.send(t.timeout_abort());
    log(what + ": no response in " + std::to_string(cfg_.sdo_timeout_ms) + " ms (attempt " +
        std::to_string(attempt + 1) + ")");
  }
  throw StartupError(what + ": no response after " + std::to_string(cfg_.sdo_retries + 1) +
                     " attempts of " + std::to_string(cfg_.sdo_timeout_ms) + " ms: " +
                     sdo_abort_text(0x05040000));
}

std::vector<std::uint8_t> Master::sdo_upload(std::uint8_t node_id, std::uint16_t index,
                                             std::uint8_t sub) {
  return run_sdo(node_id, index, sub, true, {});
}
void Master::sdo_download(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                          std::span<const std::uint8_t> data) {
  run_sdo(node_id, index, sub, false, data);
}
void Master::sdo_download_u8(std::uint8_t n, std::uint16_t i, std::uint8_t s, std::uint8_t v) {
  const std::uint8_t b[1] = {v};
  sdo_download(n, i, s, b);
}
void Master::sdo_download_u16(std::uint8_t n, std::uint16_t i, std::uint8_t s, std::uint16_t v) {
  std::uint8_t b[2];
  put_u16(b, v);
  sdo_download(n, i, s, b);
}
void Master::sdo_download_u32(std::uint8_t n, std::uint16_t i, std::uint8_t s, std::uint32_t v) {
  std::uint8_t b[4];
  put_u32(b, v);
  sdo_download(n, i, s, b);
}
std::uint32_t Master::sdo_upload_u32(std::uint8_t n, std::uint16_t i, std::uint8_t s) {
  const auto d = sdo_upload(n, i, s);
  std::uint32_t v = 0;
  for (std::size_t k = 0; k < d.size() && k < 4; ++k) v |= static_cast<std::uint32_t>(d[k]) << (8 * k);
  return v;
}

// ------------------------------------------------------------------ start-up
void Master::wait_boot_ups() {
  const std::int64_t deadline = mono_ns() + static_cast<std::int64_t>(cfg_.boot_timeout_ms) * 1000000LL;
  auto all = [&] {
    for (bool b : booted_)
      if (!b) return false;
    return true;
  };
  while (!all()) {
    const std::int64_t left = deadline - mono_ns();
    if (left <= 0) break;
    if (!bus_.wait_readable(left)) continue;
    CanFrame f;
    while (bus_.receive(f)) dispatch(f, false);
  }
  std::string missing;
  for (std::size_t i = 0; i < booted_.size(); ++i)
    if (!booted_[i]) missing += (missing.empty() ? "" : ", ") + node_label(cfg_.nodes[i].node_id);
  if (!missing.empty())
    throw StartupError("no boot-up within " + std::to_string(cfg_.boot_timeout_ms) +
                       " ms after NMT reset communication from " + missing);
}

void Master::configure_pdo(const NodeSetup& n, bool rx, const PdoMapping& m, std::uint16_t k) {
  const std::uint8_t id = n.node_id;
  const auto comm = static_cast<std::uint16_t>((rx ? 0x1400 : 0x1800) + k);
  const auto map = static_cast<std::uint16_t>((rx ? 0x1600 : 0x1A00) + k);
  const std::uint32_t cob = (rx ? kCobRpdo[k] : kCobTpdo[k]) + id;
  // CiA 301 order: disable, comm parameters, count 0, entries, count, enable.
  sdo_download_u32(id, comm, 1, 0x80000000u | cob);
  sdo_download_u8(id, comm, 2, n.sync_every);
  sdo_download_u8(id, map, 0, 0);
  for (std::size_t e = 0; e < m.count; ++e)
    sdo_download_u32(id, map, static_cast<std::uint8_t>(e + 1), m.entries[e].mapping_word());
  sdo_download_u8(id, map, 0, static_cast<std::uint8_t>(m.count));
  sdo_download_u32(id, comm, 1, cob);
}

void Master::disable_pdos(const NodeSetup& n, bool rx, std::uint16_t from) {
  // The drive's other PDOs off, so that only the configured traffic is on the bus (a drive with
  // one PDO per direction has no 0x1401/0x1801: nothing to switch off).
  const std::uint8_t id = n.node_id;
  const std::uint16_t comm = rx ? 0x1400 : 0x1800;
  const std::uint16_t have = rx ? n.quirks.rpdos : n.quirks.tpdos;
  for (std::uint16_t k = from; k < have && k < 4; ++k)
    sdo_download_u32(id, static_cast<std::uint16_t>(comm + k), 1,
                     0x80000000u | ((rx ? kCobRpdo[k] : kCobTpdo[k]) + id));
}

// The objects of the digital I/O, checked before they are mapped: a drive that lacks them would
// otherwise fail in the middle of the PDO mapping with an abort on 0x1A01 that names neither
// the object nor why it is wanted.
void Master::check_digital_io(const NodeSetup& n) {
  const std::string who = node_label(n.node_id);
  auto need = [&](std::uint16_t index, std::uint8_t sub, const char* what) {
    try {
      sdo_upload(n.node_id, index, sub);
    } catch (const SdoAbortError& e) {
      if (!e.from_server()) throw;
      throw StartupError(who + ": " + object_name(index, sub) + " " + what +
                         ": the drive does not provide it (SDO abort " + hex(e.code(), 8) + " " +
                         sdo_abort_text(e.code()) + ")");
    }
  };
  if (n.digital_inputs) {
    need(0x60FD, 0, "digital inputs, needed by a home switch (home.method switch) or the PLC's cia402 input bindings");
  }
  if (n.digital_output_mask != 0) {
    need(0x60FE, 1, "digital outputs, needed by the PLC's cia402 output bindings");
    std::uint8_t b[4];
    put_u32(b, n.digital_output_mask);
    if (!optional_download(n, 0x60FE, 2, b))
      log(who + ": 0x60FE:02 (output mask) not written: the drive drives 0x60FE:01 as sent");
  }
}

// The touch probe objects, checked before they are mapped (as check_digital_io: a drive without
// them is refused naming the object and why, not by an abort on a mapping object).
void Master::check_touch_probe(const NodeSetup& n) {
  if (!n.touch_probe) return;
  const std::string who = node_label(n.node_id);
  auto need = [&](std::uint16_t index, const char* what) {
    try {
      sdo_upload(n.node_id, index, 0);
    } catch (const SdoAbortError& e) {
      if (!e.from_server()) throw;
      throw StartupError(who + ": " + object_name(index, 0) + " " + what +
                         ", needed by home.use_index (the encoder index latch): the drive does "
                         "not provide it (SDO abort " +
                         hex(e.code(), 8) + " " + sdo_abort_text(e.code()) + ")");
    }
  };
  need(0x60B8, "touch probe function");
  need(0x60B9, "touch probe status");
  need(0x60BA, "touch probe 1 positive edge position");
}

namespace {
bool missing_object_abort(const SdoAbortError& e) {
  return e.from_server() && (e.code() == 0x06020000 || e.code() == 0x06090011);
}
}  // namespace

bool Master::optional_download(const NodeSetup& n, std::uint16_t index, std::uint8_t sub,
                               std::span<const std::uint8_t> data) {
  if (skipped(n, index, sub)) {
    log(node_label(n.node_id) + ": " + object_name(index, sub) + " not written (drive profile '" +
        n.quirks.profile + "' has no such object)");
    return false;
  }
  try {
    sdo_download(n.node_id, index, sub, data);
    return true;
  } catch (const SdoAbortError& e) {
    if (!missing_object_abort(e) || index == 0x1016) throw;
    log(std::string(e.what()) + ": optional object, skipped");
    return false;
  }
}

std::optional<std::vector<std::uint8_t>> Master::optional_upload(const NodeSetup& n,
                                                                 std::uint16_t index,
                                                                 std::uint8_t sub) {
  if (skipped(n, index, sub)) {
    log(node_label(n.node_id) + ": " + object_name(index, sub) + " not read (drive profile '" +
        n.quirks.profile + "' has no such object)");
    return std::nullopt;
  }
  try {
    return sdo_upload(n.node_id, index, sub);
  } catch (const SdoAbortError& e) {
    if (!missing_object_abort(e)) throw;
    log(std::string(e.what()) + ": optional object, skipped");
    return std::nullopt;
  }
}

void Master::configure_io_module(const NodeSetup& n) {
  const std::uint8_t id = n.node_id;
  const std::string who = node_label(id);
  const std::uint32_t device_type = sdo_upload_u32(id, 0x1000, 0);
  if (n.device_type && device_type != *n.device_type)
    throw StartupError(who + ": identity: 0x1000 device type " + hex(device_type, 8) +
                       ", expected " + hex(*n.device_type, 8));
  if ((device_type & 0xFFFF) != 401)
    throw StartupError(who + ": 0x1000 device type " + hex(device_type, 8) +
                       " is not a CiA 401 I/O module (profile " +
                       std::to_string(device_type & 0xFFFF) +
                       "), needed by the PLC's cia401 bindings");
  std::optional<std::vector<std::uint8_t>> name;
  if (!n.quirks.expedited_only) name = optional_upload(n, 0x1008, 0);
  log(who + ": CiA 401 I/O module \"" +
      (name ? std::string(name->begin(), name->end()) : std::string("?")) + "\", type " +
      hex(device_type, 8));
  sdo_download_u16(id, 0x1017, 0, n.heartbeat_ms);
  if (cfg_.master_heartbeat_ms > 0) {
    const std::uint32_t t = std::min<std::uint32_t>(65535u, 3u * cfg_.master_heartbeat_ms);
    std::uint8_t b[4];
    put_u32(b, (static_cast<std::uint32_t>(cfg_.master_node_id) << 16) | t);
    if (!optional_download(n, 0x1016, 1, b))
      log(who +
          ": WARNING: no heartbeat consumer: this module keeps its outputs when the "
          "master dies");
  }
  // Every object the PLC uses, read before it is mapped: a module without it is refused naming
  // the object, not by an abort on 0x1A00 that says neither which nor why.
  const IoPdos& p = io_pdos_[static_cast<std::size_t>(index_of(id))];
  auto need = [&](const PdoEntry& e, bool output) {
    try {
      sdo_upload(id, e.index, e.sub);
    } catch (const SdoAbortError& ex) {
      if (!ex.from_server()) throw;
      throw StartupError(who + ": " + object_name(e.index, e.sub) + " (" +
                         (e.index == 0x6000 || e.index == 0x6200 ? "digital " : "analog ") +
                         (output ? "output" : "input") +
                         ", needed by the PLC's cia401 bindings): the module does not provide it "
                         "(SDO abort " +
                         hex(ex.code(), 8) + " " + sdo_abort_text(ex.code()) + ")");
    }
  };
  for (std::size_t k = 0; k < p.ntx; ++k)
    for (std::size_t e = 0; e < p.tx[k].count; ++e) need(p.tx[k].entries[e], false);
  for (std::size_t k = 0; k < p.nrx; ++k)
    for (std::size_t e = 0; e < p.rx[k].count; ++e) need(p.rx[k].entries[e], true);
  for (std::uint16_t k = 0; k < p.nrx; ++k) configure_pdo(n, true, p.rx[k], k);
  disable_pdos(n, true, p.nrx);
  for (std::uint16_t k = 0; k < p.ntx; ++k) configure_pdo(n, false, p.tx[k], k);
  disable_pdos(n, false, p.ntx);
}

void Master::configure_node(const NodeSetup& n) {
  const std::uint8_t id = n.node_id;
  const std::string who = node_label(id);
  if (n.kind == NodeKind::kIoModule) {
    configure_io_module(n);
    return;
  }
  const std::uint32_t device_type = sdo_upload_u32(id, 0x1000, 0);
  if (n.device_type && device_type != *n.device_type)
    throw StartupError(who + ": identity: 0x1000 device type " + hex(device_type, 8) +
                       ", expected " + hex(*n.device_type, 8));
  if ((device_type & 0xFFFF) != 402)
    throw StartupError(who + ": 0x1000 device type " + hex(device_type, 8) +
                       " is not a CiA 402 drive (profile " + std::to_string(device_type & 0xFFFF) +
                       ")");
  const std::optional<std::uint32_t>* expect[3] = {&n.vendor_id, &n.product_code, &n.revision};
  const char* names[3] = {"vendor-id", "product code", "revision"};
  for (std::uint8_t s = 1; s <= 3; ++s) {
    if (!*expect[s - 1]) continue;
    const std::uint32_t v = sdo_upload_u32(id, 0x1018, s);
    if (v != **expect[s - 1])
      throw StartupError(who + ": identity: 0x1018:0" + std::to_string(s) + " " + names[s - 1] +
                         " " + hex(v, 8) + ", expected " + hex(**expect[s - 1], 8));
  }
  // The device name is a visible-string of any length: a segmented upload, which an
  // expedited-only drive cannot serve. It is only logged.
  std::optional<std::vector<std::uint8_t>> name;
  if (n.quirks.expedited_only)
    log(who + ": 0x1008:00 device name not read (drive profile '" + n.quirks.profile +
        "': expedited SDO only)");
  else
    name = optional_upload(n, 0x1008, 0);
  log(who + ": device \"" + (name ? std::string(name->begin(), name->end()) : std::string("?")) +
      "\", type " + hex(device_type, 8) + ", drive profile '" + n.quirks.profile + "', feedback " +
      (n.quirks.feedback == FeedbackTiming::kAfterStep ? "sampled after the drive's step"
                                                       : "sampled at SYNC"));
  sdo_download_u16(id, 0x1017, 0, n.heartbeat_ms);
  if (cfg_.master_heartbeat_ms > 0) {
    // Consumer time 3x the master's period: a drive stops on its own if the daemon dies.
    const std::uint32_t t = std::min<std::uint32_t>(65535u, 3u * cfg_.master_heartbeat_ms);
    std::uint8_t b[4];
    put_u32(b, (static_cast<std::uint32_t>(cfg_.master_node_id) << 16) | t);
    if (!optional_download(n, 0x1016, 1, b))
      log(who + ": WARNING: no heartbeat consumer: this drive does not stop by itself when the "
                "master dies (the E-stop chain must)");
  }
  {
    std::uint8_t b[4];
    put_u32(b, cfg_.period_us);
    optional_download(n, 0x1006, 0, b);
  }
  if (n.sync_window_us > 0) {
    std::uint8_t b[4];
    put_u32(b, n.sync_window_us);
    optional_download(n, 0x1007, 0, b);
  }
  if (n.mode != DriveMode::kProfileVelocity) {
    // 0x60C2 {value, exponent}: the smallest exponent (finest unit) that fits in a u8.
    std::uint32_t v = cfg_.period_us;
    std::int8_t e = -6;
    while (v > 255 || (v % 10 == 0 && e < -3)) {
      v /= 10;
      ++e;
    }
    const std::uint8_t value[1] = {static_cast<std::uint8_t>(v)};
    const std::uint8_t exponent[1] = {static_cast<std::uint8_t>(e)};
    if (optional_download(n, 0x60C2, 1, value)) optional_download(n, 0x60C2, 2, exponent);
  }
  // Quick stop: without 0x605A/0x6085 the drive uses its built-in reaction and deceleration
  // for the quick-stop controlword; the master sends the same controlword either way.
  {
    std::uint8_t b[2];
    put_u16(b, static_cast<std::uint16_t>(n.quick_stop_option));
    optional_download(n, 0x605A, 0, b);
  }
  {
    std::uint8_t b[4];
    put_u32(b, n.quick_stop_decel);
    optional_download(n, 0x6085, 0, b);
  }
  sdo_download_u8(id, 0x6060, 0, static_cast<std::uint8_t>(n.mode));
  const auto disp = sdo_upload(id, 0x6061, 0);
  if (disp.size() != 1 || static_cast<std::int8_t>(disp[0]) != static_cast<std::int8_t>(n.mode))
    throw StartupError(who + ": mode not confirmed: 0x6061 = " +
                       (disp.empty() ? std::string("?") : std::to_string(static_cast<std::int8_t>(disp[0]))) +
                       " after writing 0x6060 = " + std::to_string(static_cast<int>(n.mode)));
  check_digital_io(n);
  check_touch_probe(n);
  const TouchProbePdos probe = probe_pdos_[static_cast<std::size_t>(index_of(id))];
  configure_pdo(n, true, n.rpdo);  // with 0x60B8 when probe.rpdo == 0
  std::uint16_t rx_used = 1, tx_used = 1;
  if (n.digital_output_mask != 0) {
    configure_pdo(n, true, digital_outputs_rpdo(), 1);
    rx_used = 2;
  }
  if (probe.rpdo > 0) {
    configure_pdo(n, true, touch_probe_rpdo(), static_cast<std::uint16_t>(probe.rpdo));
    rx_used = static_cast<std::uint16_t>(probe.rpdo + 1);
  }
  disable_pdos(n, true, rx_used);
  configure_pdo(n, false, n.tpdo);
  if (n.digital_inputs) {
    configure_pdo(n, false, digital_inputs_tpdo(), 1);
    tx_used = 2;
  }
  if (probe.tpdo > 0) {
    configure_pdo(n, false, touch_probe_tpdo(), static_cast<std::uint16_t>(probe.tpdo));
    tx_used = static_cast<std::uint16_t>(probe.tpdo + 1);
  }
  disable_pdos(n, false, tx_used);
}

void Master::start_up() {
  cycling_ = false;
  booted_.assign(cfg_.nodes.size(), false);
  // Drain what is queued from before (old heartbeats would confuse the boot-up wait).
  CanFrame f;
  while (bus_.receive(f)) {
  }
  bus_.send(nmt_frame(NmtCommand::kResetCommunication, 0));
  wait_boot_ups();
  log("boot-up received from all " + std::to_string(cfg_.nodes.size()) + " nodes");
  for (const auto& n : cfg_.nodes) configure_node(n);
  bus_.send(nmt_frame(NmtCommand::kStart, 0));
  for (std::size_t i = 0; i < rt_.size(); ++i) {
    rt_[i] = NodeRuntime{};
    rt_[i].nmt = NmtState::kUnknown;
    seq_[i] = Cia402Sequencer{};
    unwrap_[i] = PositionUnwrapper{};
  }
  wait_operational();
  log("all nodes configured and started (NMT operational)");
}

void Master::wait_operational() {
  // A node's heartbeat sent in pre-operational just before it handled the NMT start can reach
  // the master after it: taken in the first cycles, it read as "left NMT operational" and
  // faulted the machine at cycle 0..22 under load (HIL flake). So, until each node that
  // produces a heartbeat has reported operational in one (CAN keeps one node's frames in
  // order: what it sent before is then taken in too), the state is not known; at most two of
  // its heartbeat periods + 20 ms. A node that stays silent is assumed operational as before:
  // its next heartbeat in another state faults it in the cycle.
  std::int64_t wait_ns = 0;
  for (const auto& n : cfg_.nodes)
    if (n.heartbeat_ms > 0)
      wait_ns = std::max<std::int64_t>(wait_ns, (2LL * n.heartbeat_ms + 20) * 1000000LL);
  const std::int64_t deadline = mono_ns() + wait_ns;
  auto pending = [&] {
    for (std::size_t i = 0; i < rt_.size(); ++i)
      if (cfg_.nodes[i].heartbeat_ms > 0 && rt_[i].nmt != NmtState::kOperational) return true;
    return false;
  };
  while (pending()) {
    const std::int64_t left = deadline - mono_ns();
    if (left <= 0) break;
    if (!bus_.wait_readable(left)) continue;
    CanFrame f;
    while (bus_.receive(f)) dispatch(f, false);
  }
  for (std::size_t i = 0; i < rt_.size(); ++i) {
    if (rt_[i].nmt == NmtState::kOperational) continue;
    if (cfg_.nodes[i].heartbeat_ms > 0)
      log(node_label(cfg_.nodes[i].node_id) + ": no operational heartbeat within " +
          std::to_string(wait_ns / 1000000) + " ms of NMT start (last: " +
          nmt_state_name(rt_[i].nmt) + "); taken as operational, its next heartbeat decides");
    rt_[i].nmt = NmtState::kOperational;
  }
}

// ------------------------------------------------------------------ frames
void Master::push_event(const MasterEvent& e) noexcept {
  const std::size_t next = (ev_head_ + 1) % events_.size();
  if (next == ev_tail_) return;  // full: the oldest unread stay, this one is dropped
  events_[ev_head_] = e;
  ev_head_ = next;
}

bool Master::pop_event(MasterEvent& e) noexcept {
  if (ev_tail_ == ev_head_) return false;
  e = events_[ev_tail_];
  ev_tail_ = (ev_tail_ + 1) % events_.size();
  return true;
}

void Master::dispatch(const CanFrame& f, bool in_cycle) noexcept {
  if (f.error) {
    MasterEvent e{MasterEvent::Kind::kBusState, 0, static_cast<std::uint16_t>(bus_.bus_state()), 0,
                  counters_.cycles};
    push_event(e);
    return;
  }
  ++counters_.rx_frames;
  if (f.extended || f.rtr) {
    ++counters_.unknown_frames;
    return;
  }
  const std::uint32_t id = f.id;
  if (id >= kCobTpdo[0] && id < kCobRpdo[3] && (id & 0x80u) != 0) {
    // 0x180..0x1FF, 0x280.., 0x380.., 0x480..0x4FF: a TPDO of a CiA 401 module?
    const auto pdo = static_cast<std::uint16_t>((id - kCobTpdo[0]) >> 8);
    const std::uint8_t n = node_of(id, kCobTpdo[pdo]);
    if (const int i = n != 0 ? index_of(n) : -1;
        i >= 0 && cfg_.nodes[static_cast<std::size_t>(i)].kind == NodeKind::kIoModule) {
      dispatch_io_tpdo(static_cast<std::size_t>(i), pdo, f, in_cycle);
      return;
    }
  }
  if (std::uint8_t n = node_of(id, kCobTpdo[0]); n != 0 && index_of(n) >= 0) {
    const auto i = static_cast<std::size_t>(index_of(n));
    const auto& m = cfg_.nodes[i].tpdo;
    PdoValues v{};
    if (!take_pdo(m, f, in_cycle, v)) return;
    auto& r = rt_[i];
    r.statusword = static_cast<std::uint16_t>(v[static_cast<std::size_t>(m.find(0x6041))]);
    const Cia402State s = decode_statusword(r.statusword);
    if ((s == Cia402State::kFault || s == Cia402State::kFaultReactionActive) &&
        (r.faults & static_cast<std::uint8_t>(NodeFault::kDriveFault)) == 0) {
      r.faults |= static_cast<std::uint8_t>(NodeFault::kDriveFault);
      push_event({MasterEvent::Kind::kDriveFault, n, r.statusword, 0, counters_.cycles});
    }
    r.state = s;
    if (int k = m.find(0x6064); k >= 0) {
      r.position_raw = as_i32(v[static_cast<std::size_t>(k)]);
      r.position_counts = unwrap_[i].update(r.position_raw);
    }
    if (int k = m.find(0x606C); k >= 0) r.velocity_counts_s = as_i32(v[static_cast<std::size_t>(k)]);
    r.tpdo_fresh = true;
    ++r.tpdo_received;
    return;
  }
  for (std::size_t k = 1; k < 4; ++k) {
    // The touch probe's TPDO: {0x60B9 status, 0x60BA position}, 6 bytes.
    const std::uint8_t n = node_of(id, kCobTpdo[k]);
    const int i = n != 0 ? index_of(n) : -1;
    if (i < 0 || probe_pdos_[static_cast<std::size_t>(i)].tpdo != static_cast<int>(k)) continue;
    if (f.dlc != 6) {
      ++counters_.malformed_frames;
      return;
    }
    if (!in_cycle) {
      ++counters_.late_or_stray_frames;
      return;
    }
    auto& r = rt_[static_cast<std::size_t>(i)];
    r.touch_probe_status = get_u16(f.data.data());
    r.touch_probe_position_raw = static_cast<std::int32_t>(get_u32(&f.data[2]));
    r.touch_probe_fresh = true;
    return;
  }
  if (std::uint8_t n = node_of(id, kCobTpdo[1]); n != 0 && index_of(n) >= 0 &&
      cfg_.nodes[static_cast<std::size_t>(index_of(n))].digital_inputs) {
    if (f.dlc != 4) {
      ++counters_.malformed_frames;
      return;
    }
    if (!in_cycle) {
      ++counters_.late_or_stray_frames;
      return;
    }
    auto& r = rt_[static_cast<std::size_t>(index_of(n))];
    r.digital_inputs = get_u32(f.data.data());
    r.digital_inputs_fresh = true;
    return;
  }
  if (std::uint8_t n = node_of(id, kCobHeartbeat); n != 0 && index_of(n) >= 0) {
    const auto i = static_cast<std::size_t>(index_of(n));
    const auto st = decode_heartbeat(f);
    if (!st) {
      ++counters_.malformed_frames;
      return;
    }
    auto& r = rt_[i];
    if (*st == NmtState::kBootUp) {
      booted_[i] = true;
      if (cycling_) {
        r.faults |= static_cast<std::uint8_t>(NodeFault::kUnexpectedBootUp);
        r.nmt_lost = true;
        push_event({MasterEvent::Kind::kUnexpectedBootUp, n, 0, 0, counters_.cycles});
      }
    } else if (*st != r.nmt && cycling_) {
      if (*st != NmtState::kOperational) r.nmt_lost = true;
      push_event({MasterEvent::Kind::kNmtStateChange, n, static_cast<std::uint16_t>(*st), 0,
                  counters_.cycles});
    }
    r.nmt = *st;
    r.last_heartbeat_ns = now_ns_;
    r.heartbeat_since_loss = true;
    return;
  }
  if (std::uint8_t n = node_of(id, kCobEmcy); n != 0 && index_of(n) >= 0) {
    const auto e = decode_emcy(f);
    if (!e) {
      ++counters_.malformed_frames;
      return;
    }
    ++counters_.emcy_frames;
    if (e->code != 0) rt_[static_cast<std::size_t>(index_of(n))].emcy_code = e->code;
    push_event({MasterEvent::Kind::kEmcy, n, e->code, e->error_register, counters_.cycles});
    return;
  }
  if (std::uint8_t n = node_of(id, kCobSdoTx); n != 0) {
    if (!sdo_async_response(n, f)) ++counters_.late_or_stray_frames;
    return;
  }
  if (id == kCobSync || id == kCobNmt || id == kCobHeartbeat + cfg_.master_node_id) return;
  ++counters_.unknown_frames;
}

bool Master::take_pdo(const PdoMapping& m, const CanFrame& f, bool in_cycle, PdoValues& v) noexcept {
  if (f.dlc != m.bytes() || !unpack_pdo(m, f, v)) {
    ++counters_.malformed_frames;
    return false;
  }
  if (!in_cycle) {
    ++counters_.late_or_stray_frames;
    return false;
  }
  return true;
}

void Master::dispatch_io_tpdo(std::size_t i, std::uint16_t pdo, const CanFrame& f,
                              bool in_cycle) noexcept {
  const IoPdos& p = io_pdos_[i];
  if (pdo >= p.ntx) {
    ++counters_.unknown_frames;
    return;
  }
  const PdoMapping& m = p.tx[pdo];
  PdoValues v{};
  if (!take_pdo(m, f, in_cycle, v)) return;
  NodeRuntime& r = rt_[i];
  for (std::size_t k = 0; k < m.count; ++k) {
    const PdoEntry& e = m.entries[k];
    const std::size_t ch = static_cast<std::size_t>(e.sub) - 1;  // 1..8 (io_module_pdos)
    if (e.index == 0x6000)
      r.io_digital_in[ch] = static_cast<std::uint8_t>(v[k] & 0xFF);
    else
      r.io_analog_in[ch] = as_i16(v[k]);
  }
  r.io_tpdos_in = static_cast<std::uint8_t>(r.io_tpdos_in | (1u << pdo));
  if (static_cast<unsigned>(r.io_tpdos_in) == (1u << p.ntx) - 1u && !r.tpdo_fresh) {
    r.tpdo_fresh = true;
    ++r.tpdo_received;
  }
}

void Master::send_io_rpdos(std::size_t i, bool& err) noexcept {
  const IoPdos& p = io_pdos_[i];
  const NodeRuntime& r = rt_[i];
  for (std::size_t k = 0; k < p.nrx; ++k) {
    const PdoMapping& m = p.rx[k];
    PdoValues v{};
    for (std::size_t e = 0; e < m.count; ++e) {
      const std::size_t ch = static_cast<std::size_t>(m.entries[e].sub) - 1;
      v[e] = m.entries[e].index == 0x6200 ? r.io_digital_out[ch] : r.io_analog_out[ch];
    }
    CanFrame f;
    f.id = kCobRpdo[k] + cfg_.nodes[i].node_id;
    pack_pdo(m, v, f);
    const SendResult s = bus_.send(f);
    if (s == SendResult::kDropped) ++counters_.tx_dropped;
    if (s == SendResult::kError) err = true;
  }
}

// ------------------------------------------------------------------ RT cycle
CycleStatus Master::begin_cycle(std::int64_t now_ns) noexcept {
  if (!cycling_) {
    cycling_ = true;
    for (auto& r : rt_) r.last_heartbeat_ns = now_ns;
    last_master_hb_ns_ = -1;
    last_master_hb_cycle_ = counters_.cycles;
  }
  now_ns_ = now_ns;
  ++counters_.cycles;
  // Frames queued since the last collect() (late TPDOs, heartbeats, EMCY) are handled first
  // so the SYNC below starts a clean collection window.
  CanFrame f;
  while (bus_.receive(f)) dispatch(f, false);
  for (std::size_t i = 0; i < rt_.size(); ++i) {
    auto& r = rt_[i];
    // A module that maps no input has no TPDO to wait for: fresh by definition (its heartbeat
    // still watches it).
    r.tpdo_fresh = cfg_.nodes[i].kind == NodeKind::kIoModule && io_pdos_[i].ntx == 0;
    r.io_tpdos_in = 0;
    r.digital_inputs_fresh = false;
    r.touch_probe_fresh = false;
  }
  sync_mono_ns_ = mono_ns();
  const SendResult s = bus_.send(sync_frame());
  if (s == SendResult::kDropped) ++counters_.tx_dropped;
  // The producer runs on the wall clock whatever `now_ns` is (see the header: the drives time it
  // with their own clock), and also every master_heartbeat_ms worth of SYNC periods: cycles that
  // catch up after a stall (a burst of SYNCs faster than real time) must not leave a consumer
  // that counts SYNCs (contour-machine-sim in lockstep) 3 x its period without a heartbeat.
  const std::int64_t wall = sync_mono_ns_;
  const std::uint64_t hb_cycles = std::max<std::uint64_t>(
      1, std::uint64_t{cfg_.master_heartbeat_ms} * 1000u / std::max<std::uint32_t>(1, cfg_.period_us));
  if (cfg_.master_heartbeat_ms > 0 && heartbeat_on_ &&
      (last_master_hb_ns_ < 0 ||
       wall - last_master_hb_ns_ >= static_cast<std::int64_t>(cfg_.master_heartbeat_ms) * 1000000LL ||
       counters_.cycles - last_master_hb_cycle_ >= hb_cycles)) {
    last_master_hb_ns_ = wall;
    last_master_hb_cycle_ = counters_.cycles;
    if (bus_.send(heartbeat_frame(cfg_.master_node_id, NmtState::kOperational)) ==
        SendResult::kDropped)
      ++counters_.tx_dropped;
  }
  return s == SendResult::kError ? CycleStatus::kFault : CycleStatus::kOk;
}

CycleStatus Master::collect() noexcept {
  const std::int64_t deadline = sync_mono_ns_ + static_cast<std::int64_t>(cfg_.tpdo_deadline_us) * 1000LL;
  const std::uint64_t cycle = counters_.cycles - 1;  // SYNCs sent before this one
  // A node transmitting every n-th SYNC sends after the n-th, 2n-th, ... SYNC of its count;
  // with both counts starting at NMT start that is cycle % n == n - 1 here.
  auto expected = [&](std::size_t i) {
    const std::uint64_t every = cfg_.nodes[i].sync_every < 1 ? 1u : cfg_.nodes[i].sync_every;
    return every == 1 || cycle % every == every - 1;
  };
  auto all_in = [&] {
    for (std::size_t i = 0; i < rt_.size(); ++i)
      if (expected(i) && (!rt_[i].tpdo_fresh ||
                          (cfg_.nodes[i].digital_inputs && !rt_[i].digital_inputs_fresh) ||
                          (probe_pdos_[i].tpdo > 0 && !rt_[i].touch_probe_fresh)))
        return false;
    return true;
  };
  CanFrame f;
  // Drain before looking at the clock: frames already queued count even when this thread was
  // preempted past the deadline (seen on a loaded 2-core host: 1 cycle in 10k).
  for (;;) {
    while (bus_.receive(f)) dispatch(f, true);
    if (all_in()) break;
    const std::int64_t left = deadline - mono_ns();
    if (left <= 0) break;
    bus_.wait_readable(left);
  }
  bool fault = false;
  for (std::size_t i = 0; i < rt_.size(); ++i) {
    auto& r = rt_[i];
    const auto& n = cfg_.nodes[i];
    if (expected(i)) {
      if (r.tpdo_fresh) {
        r.missed_streak = 0;
      } else {
        ++r.missed_streak;
        ++r.missed_total;
      }
      if (n.digital_inputs && !r.digital_inputs_fresh) ++r.digital_inputs_missed;
      if (probe_pdos_[i].tpdo > 0 && !r.touch_probe_fresh) ++r.touch_probe_missed;
    }
    if (r.missed_streak >= static_cast<std::uint32_t>(cfg_.missed_tpdo_fault) &&
        (r.faults & static_cast<std::uint8_t>(NodeFault::kTpdoMissed)) == 0) {
      r.faults |= static_cast<std::uint8_t>(NodeFault::kTpdoMissed);
      push_event({MasterEvent::Kind::kTpdoMissedFault, n.node_id,
                  static_cast<std::uint16_t>(r.missed_streak), 0, counters_.cycles});
    }
    if (n.heartbeat_timeout_ms > 0 && n.heartbeat_ms > 0 &&
        now_ns_ - r.last_heartbeat_ns > static_cast<std::int64_t>(n.heartbeat_timeout_ms) * 1000000LL &&
        (r.faults & static_cast<std::uint8_t>(NodeFault::kHeartbeatLost)) == 0) {
      r.faults |= static_cast<std::uint8_t>(NodeFault::kHeartbeatLost);
      r.heartbeat_since_loss = false;
      push_event({MasterEvent::Kind::kHeartbeatLost, n.node_id, 0, 0, counters_.cycles});
    }
    if (r.faults != 0) fault = true;
    if (r.sdo.state == AsyncSdo::State::kBusy && --r.sdo.cycles_left <= 0) {
      r.sdo.state = AsyncSdo::State::kTimedOut;
    }
  }
  if (bus_.bus_state() == BusState::kBusOff) fault = true;
  return fault ? CycleStatus::kFault : CycleStatus::kOk;
}

CycleStatus Master::send_rpdos() noexcept {
  const std::uint64_t cycle = counters_.cycles - 1;
  bool err = false;
  for (std::size_t i = 0; i < rt_.size(); ++i) {
    auto& r = rt_[i];
    const auto& n = cfg_.nodes[i];
    if (n.sync_every > 1 && cycle % n.sync_every != 0) continue;
    if (n.kind == NodeKind::kIoModule) {
      send_io_rpdos(i, err);
      continue;
    }
    const bool allow_reset = fault_reset_;
    r.controlword = seq_[i].next(r.state, r.request, allow_reset);
    if (r.state == Cia402State::kOperationEnabled && r.request == DriveRequest::kEnabled)
      r.controlword = static_cast<std::uint16_t>(r.controlword | r.controlword_extra);
    // Before and while enabling the drive must not jump: CSV/PV target 0, CSP target = actual.
    std::int32_t target = r.target;
    if (r.state != Cia402State::kOperationEnabled || r.request != DriveRequest::kEnabled)
      target = n.mode == DriveMode::kCsp ? r.position_raw : 0;
    PdoValues v{};
    for (std::size_t k = 0; k < n.rpdo.count; ++k) {
      const auto idx = n.rpdo.entries[k].index;
      if (idx == 0x6040) v[k] = r.controlword;
      else if (idx == 0x60FF || idx == 0x607A) v[k] = static_cast<std::uint32_t>(target);
      else if (idx == 0x6060)
        v[k] = static_cast<std::uint8_t>(r.rpdo_mode != 0 ? r.rpdo_mode : static_cast<std::int8_t>(n.mode));
      else if (idx == 0x60B8)
        v[k] = r.touch_probe_function;
    }
    CanFrame f;
    f.id = kCobRpdo[0] + n.node_id;
    pack_pdo(n.rpdo, v, f);
    const SendResult s = bus_.send(f);
    if (s == SendResult::kDropped) ++counters_.tx_dropped;
    if (s == SendResult::kError) err = true;
    if (n.digital_output_mask != 0) {
      CanFrame o;
      o.id = kCobRpdo[1] + n.node_id;
      o.dlc = 4;
      put_u32(o.data.data(), r.digital_outputs & n.digital_output_mask);
      const SendResult so = bus_.send(o);
      if (so == SendResult::kDropped) ++counters_.tx_dropped;
      if (so == SendResult::kError) err = true;
    }
    if (const auto k = probe_pdos_[i].rpdo; k > 0) {
      CanFrame o;
      o.id = kCobRpdo[static_cast<std::size_t>(k)] + n.node_id;
      o.dlc = 2;
      put_u16(o.data.data(), r.touch_probe_function);
      const SendResult so = bus_.send(o);
      if (so == SendResult::kDropped) ++counters_.tx_dropped;
      if (so == SendResult::kError) err = true;
    }
  }
  if (fault_reset_) {
    // Operator reset in progress: a drive that has left Fault clears its drive-fault latch (it may
    // have been latched again by the TPDOs that still showed Fault before the reset edge acted).
    bool any = false;
    for (auto& r : rt_) {
      if (r.state == Cia402State::kFault || r.state == Cia402State::kFaultReactionActive) {
        any = true;
      } else {
        r.faults &= static_cast<std::uint8_t>(~static_cast<std::uint8_t>(NodeFault::kDriveFault));
      }
    }
    if (!any) fault_reset_ = false;
  }
  return err ? CycleStatus::kFault : CycleStatus::kOk;
}

// ------------------------------------------------------------------ RT expedited SDO
bool Master::sdo_async_download(std::size_t i, std::uint16_t index, std::uint8_t sub,
                                std::uint32_t value, std::uint8_t bytes) noexcept {
  AsyncSdo& a = rt_[i].sdo;
  if (a.state == AsyncSdo::State::kBusy || bytes < 1 || bytes > 4) return false;
  a = AsyncSdo{};
  a.upload = false;
  a.index = index;
  a.sub = sub;
  a.value = bytes == 4 ? value : value & ((1u << (8u * bytes)) - 1u);
  CanFrame f;
  f.id = kCobSdoRx + cfg_.nodes[i].node_id;
  f.dlc = 8;
  // Expedited download, size indicated: 0x23 | (4 - bytes) << 2.
  f.data[0] = static_cast<std::uint8_t>(0x23u | ((4u - bytes) << 2));
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  put_u32(&f.data[4], a.value);
  if (bus_.send(f) != SendResult::kOk) return false;
  a.state = AsyncSdo::State::kBusy;
  a.cycles_left = std::max(1, static_cast<int>(static_cast<std::int64_t>(cfg_.sdo_timeout_ms) * 1000 /
                                               std::max<std::uint32_t>(1u, cfg_.period_us)));
  return true;
}

bool Master::sdo_async_upload(std::size_t i, std::uint16_t index, std::uint8_t sub) noexcept {
  AsyncSdo& a = rt_[i].sdo;
  if (a.state == AsyncSdo::State::kBusy) return false;
  a = AsyncSdo{};
  a.upload = true;
  a.index = index;
  a.sub = sub;
  CanFrame f;
  f.id = kCobSdoRx + cfg_.nodes[i].node_id;
  f.dlc = 8;
  f.data[0] = 0x40;  // initiate upload
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  if (bus_.send(f) != SendResult::kOk) return false;
  a.state = AsyncSdo::State::kBusy;
  a.cycles_left = std::max(1, static_cast<int>(static_cast<std::int64_t>(cfg_.sdo_timeout_ms) * 1000 /
                                               std::max<std::uint32_t>(1u, cfg_.period_us)));
  return true;
}

// A server response to node n's async transfer (true: consumed).
bool Master::sdo_async_response(std::uint8_t node, const CanFrame& f) noexcept {
  const int k = index_of(node);
  if (k < 0 || f.dlc != 8) return false;
  AsyncSdo& a = rt_[static_cast<std::size_t>(k)].sdo;
  if (a.state != AsyncSdo::State::kBusy) return false;
  if (get_u16(&f.data[1]) != a.index || f.data[3] != a.sub) return false;
  const std::uint8_t cs = f.data[0];
  if (cs == 0x80) {
    a.abort_code = get_u32(&f.data[4]);
    a.state = AsyncSdo::State::kAborted;
  } else if (!a.upload && cs == 0x60) {
    a.state = AsyncSdo::State::kDone;
  } else if (a.upload && (cs & 0xE0u) == 0x40u && (cs & 0x02u) != 0) {
    // Expedited upload: bytes 4..7, of which 4 - n valid when size is indicated.
    std::uint32_t v = get_u32(&f.data[4]);
    if ((cs & 0x01u) != 0) {
      const unsigned n = (cs >> 2) & 0x03u;
      if (n > 0) v &= (1u << (8u * (4u - n))) - 1u;
    }
    a.value = v;
    a.state = AsyncSdo::State::kDone;
  } else {
    // A segmented answer (or a wrong command): this client does expedited transfers only.
    a.abort_code = 0x06010000;
    a.state = AsyncSdo::State::kAborted;
    (void)bus_.send(sdo_abort_frame(node, false, a.index, a.sub, a.abort_code));
  }
  return true;
}

void Master::set_request_all(DriveRequest r) noexcept {
  for (auto& n : rt_) n.request = r;
}

void Master::reset_faults() noexcept {
  fault_reset_ = true;
  constexpr auto kLost = static_cast<std::uint8_t>(NodeFault::kHeartbeatLost);
  for (auto& r : rt_) {
    // A heartbeat loss is acknowledged only when the node has been heard again since: re-arming
    // the timer here let `reset` succeed with the drive still silent (issue 16), and the machine
    // faulted again a consumer timeout later.
    const bool still_lost = (r.faults & kLost) != 0 && !r.heartbeat_since_loss;
    r.faults = still_lost ? kLost : 0;
    r.missed_streak = 0;
    r.emcy_code = 0;
    r.nmt_lost = r.nmt_lost && r.nmt != NmtState::kOperational;
  }
  bus_.clear_bus_state();
}

bool Master::all_enabled() const noexcept {
  for (std::size_t i = 0; i < rt_.size(); ++i)
    if (cfg_.nodes[i].kind == NodeKind::kDrive && rt_[i].state != Cia402State::kOperationEnabled)
      return false;
  return true;
}

bool Master::any_fault() const noexcept {
  for (const auto& r : rt_)
    if (r.faults != 0) return true;
  return bus_.bus_state() == BusState::kBusOff;
}

std::string Master::describe(const MasterEvent& e) const {
  const std::string who = node_label(e.node_id);
  const std::string at = " (cycle " + std::to_string(e.cycle) + ")";
  switch (e.kind) {
    case MasterEvent::Kind::kEmcy:
      return "EMCY " + who + ": " + hex(e.code, 4) + " " + emcy_code_text(e.code) +
             ", error register " + hex(e.error_register, 2) + at;
    case MasterEvent::Kind::kDriveFault:
      return who + ": drive fault, statusword " + hex(e.code, 4) + " (" +
             cia402_state_name(decode_statusword(e.code)) + ")" + at;
    case MasterEvent::Kind::kHeartbeatLost: {
      const int i = index_of(e.node_id);
      return who + ": heartbeat lost (no heartbeat for " +
             std::to_string(i >= 0 ? cfg_.nodes[static_cast<std::size_t>(i)].heartbeat_timeout_ms : 0) +
             " ms)" + at;
    }
    case MasterEvent::Kind::kTpdoMissedFault:
      return who + ": " + std::to_string(e.code) + " TPDOs missed in a row" + at;
    case MasterEvent::Kind::kUnexpectedBootUp: return who + ": unexpected boot-up (drive reset)" + at;
    case MasterEvent::Kind::kNmtStateChange:
      return who + ": NMT state " + nmt_state_name(static_cast<NmtState>(e.code)) + at;
    case MasterEvent::Kind::kBusState:
      return std::string("CAN bus state: ") + bus_state_name(static_cast<BusState>(e.code)) + at;
  }
  return who + ": ?";
}

}  // namespace contour::drivers::canopen
