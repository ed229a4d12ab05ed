// HIL: the master brings up contour-machine-sim (config/hil.yaml: X, Y, Z on nodes 1..3, the
// spindle on node 4) over vcan0, and a second raw socket checks the traffic with a decoder
// written here from CiA 301/402 (byte order, command specifiers, COB-IDs), not the master's codec.
#include <cstdio>
#include <map>
#include <tuple>

#include "tests/hil/canopen_hil_support.hpp"

namespace {

using contour::test::Observed;

std::uint32_t le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}
std::uint16_t le16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | p[1] << 8); }

struct SdoWrite {
  std::uint16_t index;
  std::uint8_t sub;
  std::uint32_t value;
  int size;
};

// Expedited downloads to `node`, decoded by hand: ccs 1, e = 1, s = 1, n in bits 3..2.
std::vector<SdoWrite> sdo_writes(const std::vector<Observed>& fr, int node) {
  std::vector<SdoWrite> w;
  for (const auto& f : fr) {
    if (f.id != static_cast<canid_t>(0x600 + node) || f.dlc != 8) continue;
    const std::uint8_t cs = f.data[0];
    if ((cs & 0xE3) != 0x23) continue;
    const int size = 4 - ((cs >> 2) & 3);
    std::uint32_t v = 0;
    for (int i = 0; i < size; ++i) v |= static_cast<std::uint32_t>(f.data[4 + i]) << (8 * i);
    w.push_back({le16(&f.data[1]), f.data[3], v, size});
  }
  return w;
}

std::vector<std::tuple<int, int, std::uint32_t>> pdo_sequence(const std::vector<SdoWrite>& w,
                                                              std::uint16_t comm, std::uint16_t map) {
  std::vector<std::tuple<int, int, std::uint32_t>> s;
  for (const auto& x : w)
    if (x.index == comm || x.index == map) s.emplace_back(x.index, x.sub, x.value);
  return s;
}

}  // namespace

TEST(CanopenBringUp, ThreeAxesAndSpindleReachOperationEnabledWithConfiguredPdos) {
  contour::test::Observer obs;
  ASSERT_TRUE(obs.ok()) << "vcan0 missing: run under tools/with-vcan";
  contour::test::MachineSim sim;
  ASSERT_TRUE(sim.ready()) << sim.stop();
  const auto cfg = contour::test::hil_config();
  contour::test::Rig rig(contour::test::hil_master_config(cfg));
  ASSERT_NO_THROW(rig.master->start_up()) << "log:\n" << ::testing::PrintToString(rig.log);
  const int cycles_to_enable = rig.enable_all();
  ASSERT_GT(cycles_to_enable, 0) << ::testing::PrintToString(rig.events());
  auto& m = *rig.master;
  ASSERT_EQ(m.size(), 4u);
  const std::int32_t targets[4] = {1000, -2000, 0, 3000};
  for (std::size_t i = 0; i < 4; ++i) m.set_target(i, targets[i]);
  constexpr int kRun = 200;
  for (int k = 0; k < kRun; ++k) ASSERT_EQ(rig.step(), contour::drivers::canopen::CycleStatus::kOk);
  std::printf("[figure] bring-up: %d lockstep cycles from the first SYNC to Operation enabled on "
              "all 4 nodes\n", cycles_to_enable);
  std::printf("[figure] bus load estimate (hil.yaml): %.1f %% nominal, %.1f %% worst case, "
              "busiest cycle %.1f %%\n", 100 * m.bus_load().nominal, 100 * m.bus_load().worst_case,
              100 * m.bus_load().peak_cycle_worst);
  for (const auto& l : rig.log) std::printf("[master] %s\n", l.c_str());
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(m.node(i).missed_total, 0u) << i;

  const auto fr = obs.take();
  // NMT: reset communication to all, later start all.
  std::size_t nmt_reset = fr.size(), nmt_start = fr.size();
  for (std::size_t k = 0; k < fr.size(); ++k) {
    if (fr[k].id == 0 && fr[k].dlc == 2 && fr[k].data[0] == 0x82 && fr[k].data[1] == 0 &&
        nmt_reset == fr.size())
      nmt_reset = k;
    if (fr[k].id == 0 && fr[k].dlc == 2 && fr[k].data[0] == 0x01 && fr[k].data[1] == 0) nmt_start = k;
  }
  ASSERT_LT(nmt_reset, fr.size());
  ASSERT_LT(nmt_start, fr.size());
  ASSERT_LT(nmt_reset, nmt_start);
  for (int n = 1; n <= 4; ++n) {
    bool boot = false, abort = false, operational_hb = false;
    for (std::size_t k = nmt_reset; k < fr.size(); ++k) {
      const auto& f = fr[k];
      if (f.id == static_cast<canid_t>(0x700 + n) && f.dlc == 1 && f.data[0] == 0x00 && k < nmt_start) boot = true;
      if (f.id == static_cast<canid_t>(0x700 + n) && f.dlc == 1 && f.data[0] == 0x05 && k > nmt_start)
        operational_hb = true;
      if (f.id == static_cast<canid_t>(0x580 + n) && f.data[0] == 0x80) abort = true;
    }
    EXPECT_TRUE(boot) << "no boot-up 0x" << std::hex << 0x700 + n;
    EXPECT_FALSE(abort) << "SDO abort from node " << n;
    EXPECT_TRUE(operational_hb) << "no operational heartbeat from node " << n;
    // Every SDO request got exactly one response (segment requests included).
    int req = 0, resp = 0;
    for (const auto& f : fr) {
      if (f.id == static_cast<canid_t>(0x600 + n)) ++req;
      if (f.id == static_cast<canid_t>(0x580 + n)) ++resp;
    }
    EXPECT_EQ(req, resp) << "node " << n;

    const auto w = sdo_writes(fr, n);
    const bool spindle = n == 4;
    const std::uint32_t type = spindle ? 10 : 1;
    using T = std::vector<std::tuple<int, int, std::uint32_t>>;
    const T rpdo = {{0x1400, 1, 0x80000200u + n}, {0x1400, 2, type}, {0x1600, 0, 0},
                    {0x1600, 1, 0x60400010}, {0x1600, 2, 0x60FF0020}, {0x1600, 0, 2},
                    {0x1400, 1, 0x200u + n}};
    const T tpdo = {{0x1800, 1, 0x80000180u + n}, {0x1800, 2, type}, {0x1A00, 0, 0},
                    {0x1A00, 1, 0x60410010}, {0x1A00, 2, spindle ? 0x606C0020u : 0x60640020u},
                    {0x1A00, 0, 2}, {0x1800, 1, 0x180u + n}};
    EXPECT_EQ(pdo_sequence(w, 0x1400, 0x1600), rpdo) << "node " << n;
    EXPECT_EQ(pdo_sequence(w, 0x1800, 0x1A00), tpdo) << "node " << n;
    std::map<std::pair<int, int>, SdoWrite> last;
    for (const auto& x : w) last[std::make_pair(int{x.index}, int{x.sub})] = x;
    auto at = [&](int i, int sub) { return last[std::make_pair(i, sub)]; };
    ASSERT_TRUE(last.count(std::make_pair(0x6060, 0)));
    EXPECT_EQ(at(0x6060, 0).size, 1);  // cs 0x2F
    EXPECT_EQ(at(0x6060, 0).value, 9u);  // CSV
    EXPECT_EQ(at(0x1017, 0).size, 2);  // cs 0x2B
    EXPECT_EQ(at(0x1017, 0).value, 50u);
    EXPECT_EQ(at(0x1016, 1).value, (0x7Fu << 16) | 300u);
    EXPECT_EQ(at(0x60C2, 1).value, 1u);
    EXPECT_EQ(at(0x60C2, 2).value, 0xFDu);  // -3: 1 ms
    EXPECT_EQ(at(0x605A, 0).value, 2u);
    for (std::uint16_t k = 1; k < 4; ++k) {  // PDOs 2..4 disabled
      EXPECT_EQ(at(0x1400 + k, 1).value & 0x80000000u, 0x80000000u);
      EXPECT_EQ(at(0x1800 + k, 1).value & 0x80000000u, 0x80000000u);
    }
  }
  // Steady state: the last 100 SYNC periods.
  std::vector<std::size_t> syncs;
  for (std::size_t k = nmt_start; k < fr.size(); ++k)
    if (fr[k].id == 0x080) {
      EXPECT_EQ(fr[k].dlc, 0);
      syncs.push_back(k);
    }
  ASSERT_GE(syncs.size(), 150u);
  int frames = 0, periods = 0;
  for (std::size_t s = syncs.size() - 101; s + 1 < syncs.size(); ++s, ++periods) {
    std::map<canid_t, int> count;
    for (std::size_t k = syncs[s]; k < syncs[s + 1]; ++k) {
      const auto& f = fr[k];
      ++count[f.id];
      ++frames;
      for (int n = 1; n <= 4; ++n) {
        if (f.id == static_cast<canid_t>(0x200 + n)) {  // RPDO1: controlword, target velocity
          ASSERT_EQ(f.dlc, 6);
          EXPECT_EQ(le16(f.data), 0x000F);
          EXPECT_EQ(static_cast<std::int32_t>(le32(f.data + 2)), targets[n - 1]);
        }
        if (f.id == static_cast<canid_t>(0x180 + n)) {  // TPDO1: statusword, position/velocity
          ASSERT_EQ(f.dlc, 6);
          EXPECT_EQ(le16(f.data) & 0x6F, 0x27) << "not operation enabled";
          EXPECT_EQ(le16(f.data) & 0x1000, 0x1000) << "bit 12: drive follows the command";
        }
      }
    }
    for (int n = 1; n <= 3; ++n) {
      EXPECT_EQ(count[static_cast<canid_t>(0x180 + n)], 1);
      EXPECT_EQ(count[static_cast<canid_t>(0x200 + n)], 1);
    }
    EXPECT_LE(count[0x184], 1);
    EXPECT_LE(count[0x204], 1);
  }
  // Position bytes of the last TPDO of each axis equal what the master decoded.
  for (int n = 1; n <= 3; ++n) {
    for (std::size_t k = fr.size(); k-- > 0;) {
      if (fr[k].id == static_cast<canid_t>(0x180 + n)) {
        EXPECT_EQ(static_cast<std::int32_t>(le32(fr[k].data + 2)), m.node(static_cast<std::size_t>(n - 1)).position_raw);
        break;
      }
    }
  }
  // Spindle: one RPDO and one TPDO per 10 SYNCs.
  int sp_rx = 0, sp_tx = 0;
  for (std::size_t k = syncs[syncs.size() - 101]; k < syncs.back(); ++k) {
    if (fr[k].id == 0x204) ++sp_rx;
    if (fr[k].id == 0x184) ++sp_tx;
  }
  EXPECT_EQ(sp_rx, 10);
  EXPECT_EQ(sp_tx, 10);
  std::printf("[figure] frames per SYNC period (observer, last 100 periods): %.2f\n",
              static_cast<double>(frames) / periods);
  // The axes moved as commanded: X at +1000 counts/s for kRun ms, Y at -2000.
  EXPECT_GT(m.node(0).position_counts, 0);
  EXPECT_LT(m.node(1).position_counts, 0);
  EXPECT_GT(m.node(3).velocity_counts_s, 0);  // spindle spinning up
  const std::string out = sim.stop();
  EXPECT_NE(out.find("\"rx_frames\""), std::string::npos) << out;
}

TEST(CanopenBringUp, SdoAbortAtStartupNamesNodeObjectAndAbortText) {
  contour::test::MachineSim sim({"--sdo-abort", "2:0x6060:0"});
  ASSERT_TRUE(sim.ready()) << sim.stop();
  const auto cfg = contour::test::hil_config();
  contour::test::Rig rig(contour::test::hil_master_config(cfg));
  try {
    rig.master->start_up();
    FAIL() << "start-up succeeded despite the abort";
  } catch (const contour::drivers::canopen::StartupError& e) {
    const std::string msg = e.what();
    std::printf("[start-up error] %s\n", msg.c_str());
    EXPECT_NE(msg.find("node 2 (Y)"), std::string::npos) << msg;
    EXPECT_NE(msg.find("0x6060:00"), std::string::npos) << msg;
    EXPECT_NE(msg.find("0x06090030"), std::string::npos) << msg;
    EXPECT_NE(msg.find("invalid value for parameter"), std::string::npos) << msg;
  }
}

TEST(CanopenBringUp, MissingNodeGivesBootUpTimeoutNamingIt) {
  // No simulator: nobody answers the NMT reset.
  auto cfg = contour::test::hil_config();
  auto mc = contour::test::hil_master_config(cfg);
  mc.boot_timeout_ms = 1000;
  contour::test::Rig rig(mc);
  try {
    rig.master->start_up();
    FAIL() << "start-up succeeded without drives";
  } catch (const contour::drivers::canopen::StartupError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("no boot-up within 1000 ms"), std::string::npos) << msg;
    EXPECT_NE(msg.find("node 4 (spindle)"), std::string::npos) << msg;
  }
}

TEST(CanopenBringUp, MissingInterfaceIsAClearError) {
  try {
    contour::drivers::SocketCan bus("vcan_nope");
    FAIL();
  } catch (const contour::drivers::SocketCanError& e) {
    EXPECT_NE(std::string(e.what()).find("vcan_nope"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("No such device"), std::string::npos) << e.what();
  }
}
