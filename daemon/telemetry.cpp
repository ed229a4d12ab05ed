#include "daemon/telemetry.hpp"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include "control/path.hpp"

namespace contour::daemon {

namespace {
constexpr double kSearchMarginMm = 10.0;  // > following error at max feed on Table 1 (~2.3 mm)
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
    if (++n % 4096 == 0) std::this_thread::yield();
  }
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

RunStats TelemetryWriter::stats(std::uint64_t job) const {
  std::lock_guard lk(mu_);
  if (current_.job == job) return current_;
  if (last_.job == job) return last_;
  return RunStats{job};
}

}  // namespace contour::daemon
