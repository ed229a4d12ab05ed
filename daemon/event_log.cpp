#include "daemon/event_log.hpp"

#include <spdlog/async.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

namespace contour::daemon {

namespace {

// "<N>" syslog priority prefix for journald (sd-daemon.h SD_ERR etc.).
class SyslogPrefix final : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&,
              spdlog::memory_buf_t& dest) override {
    int pri = 6;
    switch (msg.level) {
      case spdlog::level::trace:
      case spdlog::level::debug: pri = 7; break;
      case spdlog::level::info: pri = 6; break;
      case spdlog::level::warn: pri = 4; break;
      case spdlog::level::err: pri = 3; break;
      case spdlog::level::critical: pri = 2; break;
      default: pri = 6; break;
    }
    const char buf[3] = {'<', static_cast<char>('0' + pri), '>'};
    dest.append(buf, buf + 3);
  }
  [[nodiscard]] std::unique_ptr<custom_flag_formatter> clone() const override {
    return std::make_unique<SyslogPrefix>();
  }
};

}  // namespace

void setup_logging(const config::LogConfig& cfg) {
  if (spdlog::get("contourd")) return;
  spdlog::init_thread_pool(8192, 1);
  auto sink = std::make_shared<spdlog::sinks::stderr_color_sink_mt>(
      cfg.journald_format ? spdlog::color_mode::never : spdlog::color_mode::automatic);
  auto logger = std::make_shared<spdlog::async_logger>("contourd", sink, spdlog::thread_pool(),
                                                       spdlog::async_overflow_policy::block);
  if (cfg.journald_format) {
    auto f = std::make_unique<spdlog::pattern_formatter>();
    f->add_flag<SyslogPrefix>('*').set_pattern("%*%v");
    logger->set_formatter(std::move(f));
  } else {
    logger->set_pattern("%Y-%m-%d %H:%M:%S.%e %^%l%$ %v");
  }
  logger->set_level(spdlog::level::from_str(cfg.level));
  logger->flush_on(spdlog::level::warn);
  spdlog::set_default_logger(logger);
}

std::string_view to_string(CommandKind k) noexcept {
  switch (k) {
    case CommandKind::kEnable: return "enable";
    case CommandKind::kDisable: return "disable";
    case CommandKind::kRun: return "run";
    case CommandKind::kHold: return "hold";
    case CommandKind::kResume: return "resume";
    case CommandKind::kStop: return "stop";
    case CommandKind::kEstop: return "estop";
    case CommandKind::kReset: return "reset";
    case CommandKind::kJog: return "jog";
    case CommandKind::kAttachJob: return "load";
    case CommandKind::kSetOverride: return "override";
    case CommandKind::kRecordFlag: return "record";
    case CommandKind::kSetPosition: return "set-position";
    case CommandKind::kForce: return "force";
    case CommandKind::kIdentify: return "identify";
    case CommandKind::kJogBrake: return "jog brake (dead-man)";
    case CommandKind::kHome: return "home";
    case CommandKind::kSetOptionalStop: return "optional stop switch";
    case CommandKind::kSetSingleBlock: return "single block switch";
  }
  return "?";
}

// The limit-cycle watchdog's figure (safety.chatter): which one, its value and the level crossed.
static std::string chatter_figure_text(const RtEvent& e) {
  std::ostringstream o;
  if (e.detail == 2) {
    o << "clamped cycles " << e.value << "/s > " << e.limit << "/s (safety.chatter)";
  } else {
    o << "command chatter " << e.value << " mm/s RMS > " << e.limit << " mm/s (safety.chatter)";
  }
  return o.str();
}

std::string describe(const RtEvent& e) {
  std::ostringstream o;
  o << "cycle " << e.cycle << ": ";
  switch (e.kind) {
    case EventKind::kTransition:
      o << "state " << to_string(e.from) << " -> " << to_string(e.to);
      if (e.cause != FaultCause::kNone) o << " (cause " << to_string(e.cause) << ')';
      break;
    case EventKind::kFault:
      o << "FAULT " << to_string(e.cause);
      // For a heartbeat loss or an I/O module the field carries the CANopen node-id, not an axis.
      if (e.axis >= 0)
        o << (e.cause == FaultCause::kHeartbeatLost || e.cause == FaultCause::kIoModule ? " node "
                                                                                        : " axis ")
          << e.axis;
      if (e.cause == FaultCause::kFollowingError || e.cause == FaultCause::kContourError) {
        o << ": " << e.value << " mm > limit " << e.limit << " mm";
      } else if (e.cause == FaultCause::kSoftLimit) {
        o << ": reference " << e.value << " mm beyond limit " << e.limit << " mm";
      } else if (e.cause == FaultCause::kMissedTpdo) {
        o << ": " << e.value << " missed TPDOs in a row"
          << (e.detail == static_cast<std::uint8_t>(MissedPdo::kDigitalInputs)
                  ? " (0x60FD digital inputs; the position still came)"
                  : "");
      } else if (e.cause == FaultCause::kForceStale) {
        o << ": sample age " << e.value << " s > " << e.limit << " s (or invalid)";
      } else if (e.cause == FaultCause::kDriveEmcy ||
                 (e.cause == FaultCause::kDriveFault && e.value != 0.0)) {
        char code[16];
        std::snprintf(code, sizeof code, "0x%04X", static_cast<unsigned>(e.value));
        o << ": EMCY code " << code << " (see the CANopen log line)";
      } else if (e.cause == FaultCause::kIoModule) {
        if (e.detail == static_cast<std::uint8_t>(IoModuleFault::kTpdoMissed)) {
          o << ": " << e.value << " missed TPDOs in a row (CiA 401 inputs)";
        } else if (e.detail == static_cast<std::uint8_t>(IoModuleFault::kEmcy)) {
          char code[16];
          std::snprintf(code, sizeof code, "0x%04X", static_cast<unsigned>(e.value));
          o << ": EMCY code " << code << " (see the CANopen log line)";
        } else {
          o << ": no longer NMT operational";
        }
      } else if (e.cause == FaultCause::kNmtStateChange) {
        o << ": node " << e.value << " is no longer NMT operational";
      } else if (e.cause == FaultCause::kLimitCycle) {
        o << ": " << chatter_figure_text(e);
      }
      break;
    case EventKind::kUnderrun: o << "segment queue underrun: feed hold on the path at "
                                 << e.value << " mm"; break;
    case EventKind::kUnderrunEnd: o << "segment queue refilled: motion continues"; break;
    case EventKind::kProgramDone: o << "program " << e.job << " done"; break;
    case EventKind::kProgramAborted: o << "program " << e.job << " ended early (stop/fault/estop)"; break;
    case EventKind::kGainsSwapped: o << "gains generation " << e.value << " active"; break;
    case EventKind::kCommandRefused:
      o << "command '" << to_string(e.command) << "' refused in state " << to_string(e.from);
      break;
    case EventKind::kForceOn: o << "force control on, reference " << e.value << " N"; break;
    case EventKind::kForceOff: o << "force control off"; break;
    case EventKind::kForceFallback:
      o << "force sample stale/invalid (age " << e.value << " s, limit " << e.limit
        << " s): fallback "
        << control::to_string(static_cast<control::ForceStatus>(e.axis));
      break;
    case EventKind::kForceCeiling:
      o << "force " << e.value << " N >= ceiling " << e.limit << " N: feed hold";
      break;
    case EventKind::kForceRecovered:
      o << "force samples valid again (force control stays off until 'force on')";
      break;
    case EventKind::kLimitsSwapped: o << "safety limits generation " << e.value << " active"; break;
    case EventKind::kSpindleAtSpeed:
      o << "spindle at speed (" << e.limit << " rpm) after " << e.value << " s: feed move starts";
      break;
    case EventKind::kProgramPause:
      o << "program paused (M0/M1/M6): waits for resume";
      break;
    case EventKind::kLimitCycleWarning:
      o << "LIMIT CYCLE WARNING axis " << e.axis << ": " << chatter_figure_text(e);
      break;
    case EventKind::kHomed:
      o << "axis " << e.axis << " homed: latch at " << e.value << " mm (encoder) is now " << e.limit
        << " mm (home_offset_mm)";
      break;
    case EventKind::kHomingFailed:
      o << "HOMING FAILED";
      if (e.axis >= 0) o << " axis " << e.axis;
      o << ": " << homing_failure_text(e.detail);
      if (e.detail == 2) o << " (" << e.value << " mm travelled)";
      if (e.detail == 11) {
        const auto v = static_cast<std::uint32_t>(e.value);
        o << " (object 0x" << std::hex << std::uppercase << (v >> 8) << ":" << (v & 0xFFu) << std::dec
          << std::nouppercase << ")";
      }
      if (e.detail == 10) o << " (statusword 0x" << std::hex << static_cast<std::uint32_t>(e.value) << std::dec << ")";
      break;
    case EventKind::kStandstillTimeout:
      o << "STANDSTILL TIMEOUT: axis " << e.axis << " still ";
      if (std::isnan(e.value)) {
        o << "without fresh feedback";
      } else {
        o << "moving at " << e.value << " mm/s";
      }
      o << " " << e.limit << " s after the stop (safety.standstill_timeout_s): drives quick stop";
      break;
  }
  return o.str();
}

EventLogger::EventLogger(SpscRing<RtEvent>& ring, Observer obs) : ring_(ring), obs_(std::move(obs)) {}

EventLogger::~EventLogger() { stop(); }

void EventLogger::start() {
  running_ = true;
  thread_ = std::thread([this] {
    while (running_.load(std::memory_order_acquire)) {
      drain();
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    drain();
  });
}

void EventLogger::stop() {
  if (running_.exchange(false) && thread_.joinable()) thread_.join();
}

void EventLogger::drain() {
  RtEvent e;
  while (ring_.pop(e)) {
    std::string text = describer_ ? describer_(e) : std::string();
    if (text.empty()) text = describe(e);
    if (e.kind == EventKind::kFault || e.kind == EventKind::kStandstillTimeout) {
      spdlog::error("{}", text);
    } else if (e.kind == EventKind::kCommandRefused || e.kind == EventKind::kUnderrun ||
               e.kind == EventKind::kProgramAborted || e.kind == EventKind::kForceFallback ||
               e.kind == EventKind::kForceCeiling || e.kind == EventKind::kLimitCycleWarning ||
               e.kind == EventKind::kHomingFailed) {
      spdlog::warn("{}", text);
    } else {
      spdlog::info("{}", text);
    }
    if (obs_) obs_(e, text);
  }
}

}  // namespace contour::daemon
