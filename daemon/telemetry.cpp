#include "daemon/telemetry.hpp"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string_view>

#include "control/path.hpp"

namespace contour::daemon {

namespace {
constexpr double kSearchMarginMm = 10.0;  // > following error at max feed on Table 1 (~2.3 mm)

void append_number(std::string& out, double v) {
  if (!std::isfinite(v)) {
    out += "null";
    return;
  }
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest round-trip form
  out.append(buf, r.ptr);
}

void append_number(std::string& out, std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

void append_key(std::string& out, std::string_view key) {
  out += ",\"";
  out += key;
  out += "\":";
}

void append_array(std::string& out, std::string_view key, const std::array<double, 3>& v,
                  double scale) {
  append_key(out, key);
  out += '[';
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (i != 0) out += ',';
    append_number(out, v[i] * scale);
  }
  out += ']';
}
// A template so that the requires-expression is checked against the sample type as it is.
template <typename Sample>
void append_lateness(std::string& out, const Sample& s) {
  if constexpr (requires { s.lateness_us; }) {
    append_key(out, "lateness_us");
    append_number(out, static_cast<double>(s.lateness_us));
  }
}
}  // namespace

std::string encode_stream_sample(const StreamSample& ss) {
  const TelemetrySample& s = ss.s;
  std::string out;
  out.reserve(480);
  out += "{\"cycle\":";
  append_number(out, s.cycle);
  append_key(out, "t_s");
  append_number(out, s.t_s);
  append_key(out, "state");
  out += '"';
  out += to_string(s.state);  // fixed upper-case names: nothing to escape
  out += '"';
  append_key(out, "job");
  append_number(out, s.job);
  append_key(out, "line");
  append_number(out, static_cast<double>(s.line));
  append_key(out, "in_program");
  out += s.in_program ? "true" : "false";
  append_key(out, "progress_mm");
  append_number(out, s.progress_mm);
  append_array(out, "ref_mm", s.ref_mm, 1.0);
  append_array(out, "act_mm", s.act_mm, 1.0);
  append_array(out, "cmd_mm_s", s.cmd_mm_s, 1.0);
  append_array(out, "eps_um", s.eps_mm, 1e3);
  append_key(out, "model_error_um");
  append_number(out,
                1e3 * std::sqrt(s.eps_mm[0] * s.eps_mm[0] + s.eps_mm[1] * s.eps_mm[1] +
                                s.eps_mm[2] * s.eps_mm[2]));
  append_key(out, "true_error_um");
  append_number(out, ss.true_contour_error_um);
  append_key(out, "override");
  append_number(out, s.override_applied);
  append_key(out, "force_n");
  append_number(out, s.force_N);
  append_key(out, "force_override");
  append_number(out, s.force_override);
  append_key(out, "spindle_rpm");
  append_number(out, s.spindle_rpm);
  append_key(out, "recording");
  out += s.recording ? "true" : "false";
  // Wake-up lateness per cycle: encoded as soon as the loop's sample carries it (issue 21 asks
  // for it in TelemetrySample; until then the scope takes it from status.timing).
  append_lateness(out, s);
  out += '}';
  return out;
}

std::shared_ptr<const StreamChunk> make_stream_chunk(std::span<const StreamSample> batch,
                                                     std::uint64_t ring_dropped) {
  auto chunk = std::make_shared<StreamChunk>();
  chunk->items.reserve(batch.size());
  for (const StreamSample& s : batch) chunk->items.push_back({s.s.cycle, encode_stream_sample(s)});
  chunk->source_dropped = ring_dropped;
  return chunk;
}

double RunStats::rms_contour_error_um() const {
  return samples > 0 ? std::sqrt(sum_sq_um2 / static_cast<double>(samples)) : 0.0;
}

double RunStats::duration_s(double period_s) const {
  return last_cycle >= first_cycle && job != 0
             ? static_cast<double>(last_cycle - first_cycle + 1) * period_s
             : 0.0;
}

TelemetryWriter::TelemetryWriter(SpscRing<TelemetrySample>& ring, double period_s)
    : ring_(ring), period_s_(period_s) {}

TelemetryWriter::~TelemetryWriter() { stop(); }

void TelemetryWriter::start() {
  running_ = true;
  thread_ = std::thread([this] {
    while (running_.load(std::memory_order_acquire)) {
      drain();
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    drain();
    flush_batch(true);
  });
}

void TelemetryWriter::stop() {
  if (running_.exchange(false) && thread_.joinable()) thread_.join();
  std::lock_guard lk(mu_);
  if (csv_.is_open()) csv_.close();
}

void TelemetryWriter::drain() {
  TelemetrySample s;
  int n = 0;
  while (ring_.pop(s)) {
    consume(s);
    if (batch_full_) flush_batch(false);
    if (++n % 4096 == 0) std::this_thread::yield();
  }
  flush_batch(false);
}

void TelemetryWriter::flush_batch(bool force) {
  BatchStream stream;
  {
    std::lock_guard lk(mu_);
    batch_full_ = false;
    if (batch_.empty() || !batch_stream_) return;
    if (!force && batch_.size() < batch_samples_ &&
        std::chrono::steady_clock::now() - batch_started_ < kMaxBatchAge) {
      return;
    }
    out_batch_.clear();
    out_batch_.swap(batch_);
    stream = batch_stream_;
  }
  stream(std::span<const StreamSample>(out_batch_.data(), out_batch_.size()));
}

void TelemetryWriter::begin_job(std::uint64_t job) {
  std::lock_guard lk(mu_);
  geo_job_ = job;
  geo_.clear();
}

void TelemetryWriter::add_segment(std::uint64_t job, const control::PlannedSegment& s) {
  if (s.kind != control::SegmentKind::kMotion) return;
  std::lock_guard lk(mu_);
  if (job != geo_job_) return;
  geo_.push_back({s.start_mm, s.end_mm, s.path_start_mm, s.path_start_mm + s.length_mm});
}

double TelemetryWriter::true_distance(const Eigen::Vector3d& p, double progress_mm,
                                     const Eigen::Vector3d& ref, bool* beyond_end) {
  while (geo_.size() > 1 && geo_.front().s1 < progress_mm - kSearchMarginMm) geo_.pop_front();
  double best = std::numeric_limits<double>::infinity();
  const Geo* arg = nullptr;
  for (const auto& g : geo_) {
    if (g.s0 > progress_mm + kSearchMarginMm) break;
    const double d = control::distance_point_segment(p, g.a, g.b);
    if (d < best) {
      best = d;
      arg = &g;
    }
  }
  // Past the end point along the last segment, once the reference is on it: along-path overshoot
  // is tracking error, not contour error (as contour-sim contour's beyond_end).
  *beyond_end = false;
  (void)ref;
  if (arg != nullptr && arg == &geo_.back() && progress_mm >= arg->s0) {
    const Eigen::Vector3d ab = arg->b - arg->a;
    const double l2 = ab.squaredNorm();
    if (l2 > 0.0 && (p - arg->a).dot(ab) / l2 > 1.0) *beyond_end = true;
  }
  return best;
}

void TelemetryWriter::consume(const TelemetrySample& s) {
  std::lock_guard lk(mu_);
  const Eigen::Vector3d act(s.act_mm[0], s.act_mm[1], s.act_mm[2]);
  const Eigen::Vector3d ref(s.ref_mm[0], s.ref_mm[1], s.ref_mm[2]);
  const Eigen::Vector3d eps(s.eps_mm[0], s.eps_mm[1], s.eps_mm[2]);
  double true_um = std::numeric_limits<double>::quiet_NaN();
  if (s.in_program && s.job != 0) {
    if (current_.job != s.job) {
      if (current_.job != 0) last_ = current_;
      current_ = RunStats{};
      current_.job = s.job;
      current_.first_cycle = s.cycle;
    }
    bool beyond = false;
    double d = s.job == geo_job_ ? true_distance(act, s.progress_mm, ref, &beyond) : eps.norm();
    if (!std::isfinite(d)) d = eps.norm();
    current_.last_cycle = s.cycle;
    if (beyond) {
      current_.end_overshoot_um = std::max(current_.end_overshoot_um, d * 1e3);
    } else {
      true_um = d * 1e3;
      ++current_.samples;
      current_.max_contour_error_um = std::max(current_.max_contour_error_um, true_um);
      current_.sum_sq_um2 += true_um * true_um;
    }
    current_.max_model_error_um = std::max(current_.max_model_error_um, eps.norm() * 1e3);
    current_.max_following_error_um =
        std::max(current_.max_following_error_um, (ref - act).norm() * 1e3);
  }
  if (csv_.is_open()) {
    csv_ << s.cycle << ',' << s.t_s << ',' << static_cast<int>(s.state) << ',' << s.job << ','
         << s.line << ',' << s.progress_mm;
    for (double v : s.ref_mm) csv_ << ',' << v;
    for (double v : s.act_mm) csv_ << ',' << v;
    for (double v : s.eps_mm) csv_ << ',' << v * 1e3;
    csv_ << ',';
    if (std::isfinite(true_um)) csv_ << true_um;
    for (double v : s.cmd_mm_s) csv_ << ',' << v;
    csv_ << ',' << s.override_applied << ',' << s.force_N << ',' << s.force_override << ','
         << s.spindle_rpm << '\n';
  }
  if (stream_ && stream_every_ > 0 && s.cycle % static_cast<std::uint64_t>(stream_every_) == 0) {
    stream_(s);
  }
  if (batch_stream_) {
    if (batch_.empty()) batch_started_ = std::chrono::steady_clock::now();
    batch_.push_back({s, true_um});
    if (batch_.size() >= batch_samples_) batch_full_ = true;
  }
  written_.fetch_add(1, std::memory_order_relaxed);
  last_cycle_.store(s.cycle, std::memory_order_release);
}

void TelemetryWriter::start_recording(const std::string& path) {
  std::lock_guard lk(mu_);
  if (csv_.is_open()) csv_.close();
  csv_.open(path);
  if (!csv_) throw std::runtime_error(path + ": cannot open for writing");
  csv_.precision(10);
  csv_ << "cycle,t_s,state,job,line,progress_mm,rx_mm,ry_mm,rz_mm,px_mm,py_mm,pz_mm,"
          "eps_x_um,eps_y_um,eps_z_um,true_contour_error_um,vx_mm_s,vy_mm_s,vz_mm_s,override,"
          "force_n,force_override,spindle_rpm\n";
  csv_path_ = path;
}

std::string TelemetryWriter::stop_recording() {
  std::lock_guard lk(mu_);
  if (!csv_.is_open()) return "";
  csv_.close();
  return csv_path_;
}

bool TelemetryWriter::recording() const {
  std::lock_guard lk(mu_);
  return csv_.is_open();
}

void TelemetryWriter::set_stream(Stream s, int every_n) {
  std::lock_guard lk(mu_);
  stream_ = std::move(s);
  stream_every_ = every_n;
}

void TelemetryWriter::set_batch_stream(BatchStream s, std::size_t batch_samples) {
  std::lock_guard lk(mu_);
  batch_stream_ = std::move(s);
  batch_samples_ = std::max<std::size_t>(1, batch_samples);
  batch_.clear();
  batch_.reserve(batch_samples_ * 4);
  out_batch_.reserve(batch_samples_ * 4);
}

RunStats TelemetryWriter::stats(std::uint64_t job) const {
  std::lock_guard lk(mu_);
  if (current_.job == job) return current_;
  if (last_.job == job) return last_;
  return RunStats{job};
}

}  // namespace contour::daemon
