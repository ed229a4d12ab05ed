#pragma once
// Counts heap allocations made by the current thread while a guard is alive. Global operator new
// is replaced always; malloc/calloc/realloc/aligned_alloc/posix_memalign too when the build has no
// AddressSanitizer (ASan owns malloc), so Eigen's allocations are seen in the plain builds.
#include <cstddef>

namespace contour::test {

struct AllocCounts {
  std::size_t news = 0;
  std::size_t mallocs = 0;
  [[nodiscard]] std::size_t total() const { return news + mallocs; }
};

// True when malloc-family calls are counted in this build (not under ASan).
bool malloc_is_counted();

class AllocGuard {
 public:
  AllocGuard();
  ~AllocGuard();
  AllocGuard(const AllocGuard&) = delete;
  AllocGuard& operator=(const AllocGuard&) = delete;
  [[nodiscard]] AllocCounts counts() const;
};

}  // namespace contour::test
