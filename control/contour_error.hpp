#pragma once
// Real-time 3-D contour-error model (seed 000, Jee & Koo 2003, §2.1, eqs 1-8) and two baselines.
//
// Inputs per cycle: the interpolator's reference points R(k) (push_reference, mm, machine frame)
// and the (measured or delay-predicted) tool position P (update, mm). Output: the contour-error
// vector eps = K - P (eq 7, mm), K the model's estimate of the nearest path point, plus the unit
// path tangent at K (used by the coupling controller to drop along-path integral, see
// servo_controller.hpp).
//
// Three-point-circle model (ModelKind::kCircle):
//   window W = {R(c-1), R(c), R(c+1)}; c = k-d is the window centre.
//   plane through W (eq 1) -> circle centre C, radius rho (eq 2); H = projection of P on the plane
//   (eq 3); K = the intersection of line H-C with the circle nearer to P (eqs 4-6).
//   Collinear branch: when R(c) is closer than kCollinearSagitta_mm to the chord R(c-1)R(c+1), K is
//   the foot of the perpendicular from P on that line.
// Window rule (eq 8): advance while |P - R(c+1)| < |P - R(c)|. WindowRule::kMultiStep repeats the
//   test within a cycle until it fails (interpretation.md: taken literally, one step per cycle,
//   the window falls ~10 points behind during start-up and never catches up; the model error
//   grows ~1000x). The multi-step rule then also looks ahead over the lag region (centre+1 .. newest)
//   for a nearer point: eq 8 stops at the first local minimum of |P - R|, which at a
//   sharp G01 corner or a reversal is not the nearest point ahead (found by the random-polyline
//   property test). The window never moves backwards. WindowRule::kLiteral (one eq-8 step per
//   cycle, no look-ahead) is kept only to demonstrate the paper's literal rule.
// Start-up: with one stored point K = R(0); with two, the collinear branch on R(0)R(1).
// Tool ahead of the newest reference: the window stays on the newest three points (K lies on the
//   circle/line extension). End of path: the interpolator stops pushing new points (or pushes the
//   same point: coincident points closer than kMinSpacing_mm to the newest are dropped), the
//   window stays on the last three points and eps is the distance to the extension of the last arc,
//   i.e. along-path overshoot is tracking error, not contour error.
// Degenerate cases never give NaN: coincident points are never stored, collinear points use the
//   line branch, P on the circle's axis gives K = R(c), a fully degenerate window gives K = R(c).
//
// Baselines (for comparison only):
//   kNearestPoint: K = the stored reference point nearest to P (searched over the whole ring).
//   kLinear: Koren-type linear model: eps = e - (e.t)t, e = R(k) - P, t = unit direction of the
//            newest reference step R(k) - R(k-1) (the variable-gain CCC's sin/cos form in 3-D).
//
// Storage: a ring of `window_capacity` points allocated in configure(); when it is full the oldest
// point is dropped, and if the window would lose its first point it is forced forward and
// Status::kLagOverflow is reported (size the capacity above the largest expected lag in points:
// following error / (feed*T) + 3).
//
// RT: push_reference() and update() are noexcept, allocation-free; update() is O(lag points) for
// kCircle (look-ahead), O(1) for kLinear and O(capacity) for kNearestPoint.
// Budget: < 1 us per update (measured 0.14 us with a 30-point lag on eq 11 at 4 m/min, 0.04 us for
// the ring + window bookkeeping alone; tools/bench/bench_control.cpp, shared 2-core VM).
#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace contour::control {

using Vec3 = Eigen::Vector3d;

enum class ModelKind { kCircle, kNearestPoint, kLinear };
enum class WindowRule { kMultiStep, kLiteral };

struct ContourErrorParams {
  ModelKind kind = ModelKind::kCircle;
  WindowRule rule = WindowRule::kMultiStep;
  int window_capacity = 256;  // stored reference points (>= 4)
};

enum class ContourStatus : std::uint8_t {
  kOk = 0,
  kNoReference,   // nothing pushed yet: eps = 0
  kLagOverflow,   // the ring overwrote the window: capacity too small for the lag
};

enum class ContourBranch : std::uint8_t { kPoint, kLine, kCircle };

struct ContourErrorResult {
  Vec3 eps = Vec3::Zero();      // contour-error vector K - P, mm (eq 7)
  Vec3 k_point = Vec3::Zero();  // K, mm
  Vec3 tangent = Vec3::Zero();  // unit path tangent at K (zero when unknown)
  double radius_mm = 0.0;       // circle radius (0 for line/point branches)
  Vec3 centre = Vec3::Zero();   // circle branch: centre C and unit plane normal (eqs 1-2)
  Vec3 plane_normal = Vec3::Zero();
  int lag_points = 0;           // d: newest index - window centre
  ContourBranch branch = ContourBranch::kPoint;
  ContourStatus status = ContourStatus::kNoReference;
};

// The contour-error vector of another point q on the SAME local path geometry as `g` (its
// circle, line or point; eqs 3-7 without a window update). Used by the coupling derivative to
// difference two positions on one geometry, so that a window advance or a branch change (a new
// circle) is not differentiated as if the tool had moved. eps_on(g, P) == g.eps for the P that
// produced g. Pure, noexcept, never NaN for finite q (a point on the circle's axis gives K = K(g)).
Vec3 eps_on(const ContourErrorResult& g, const Vec3& q) noexcept;

class ContourErrorModel {
 public:
  static constexpr double kMinSpacing_mm = 1e-9;       // closer points are treated as coincident
  static constexpr double kCollinearSagitta_mm = 1e-9;  // below: the line branch

  ContourErrorModel() { configure(ContourErrorParams{}); }
  explicit ContourErrorModel(const ContourErrorParams& p) { configure(p); }

  // Setup: allocates the ring; throws std::invalid_argument if window_capacity < 4.
  void configure(const ContourErrorParams& p);
  // Empties the window (new path).
  void reset() noexcept;

  // Appends R(k). Points within kMinSpacing_mm of the newest are ignored (standstill).
  void push_reference(const Vec3& r_mm) noexcept;
  // Advances the window with P (eq 8) and computes eps (eqs 1-7).
  ContourErrorResult update(const Vec3& p_mm) noexcept;

  [[nodiscard]] const ContourErrorParams& params() const noexcept { return p_; }
  [[nodiscard]] std::int64_t stored_points() const noexcept { return newest_ - oldest_ + 1; }

 private:
  // The ring's storage is the next power of two >= window_capacity, so an absolute index maps
  // to its slot with a mask (a 64-bit division per access cost more than the model's arithmetic);
  // how many points are kept is still window_capacity.
  [[nodiscard]] const Vec3& at(std::int64_t i) const noexcept {
    return ring_[static_cast<std::size_t>(i) & mask_];
  }
  ContourErrorResult circle_model(const Vec3& p) noexcept;
  ContourErrorResult nearest_model(const Vec3& p) const noexcept;
  ContourErrorResult linear_model(const Vec3& p) const noexcept;

  ContourErrorParams p_{};
  std::vector<Vec3> ring_;
  std::size_t mask_ = 0;  // ring_.size() - 1 (a power of two)
  std::int64_t oldest_ = 0;
  std::int64_t newest_ = -1;  // absolute index of the newest point; -1 = empty
  std::int64_t centre_ = 0;   // absolute index of R(c)
  bool overflow_ = false;
};

// Geometry kernel shared by the model and the tests: K on the circle (or line) through a, b, c
// nearest to p. Pure, noexcept, never NaN.
struct ThreePointFoot {
  Vec3 k = Vec3::Zero();
  Vec3 tangent = Vec3::Zero();  // unit, oriented a -> c
  double radius_mm = 0.0;
  Vec3 centre = Vec3::Zero();        // circle branch only
  Vec3 plane_normal = Vec3::Zero();  // circle branch only (unit)
  ContourBranch branch = ContourBranch::kPoint;
};
ThreePointFoot three_point_foot(const Vec3& a, const Vec3& b, const Vec3& c,
                                const Vec3& p) noexcept;

}  // namespace contour::control
