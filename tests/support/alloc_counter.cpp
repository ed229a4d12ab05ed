#include "tests/support/alloc_counter.hpp"

#include <cstdlib>
#include <new>

#if defined(__SANITIZE_ADDRESS__)
#define CONTOUR_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define CONTOUR_ASAN 1
#endif
#endif

namespace {
thread_local bool t_counting = false;
thread_local std::size_t t_news = 0;
thread_local std::size_t t_mallocs = 0;
}  // namespace

namespace contour::test {

#ifdef CONTOUR_ASAN
bool malloc_is_counted() { return false; }
#else
bool malloc_is_counted() { return true; }
#endif

AllocGuard::AllocGuard() {
  t_news = 0;
  t_mallocs = 0;
  t_counting = true;
}
AllocGuard::~AllocGuard() { t_counting = false; }
AllocCounts AllocGuard::counts() const { return {t_news, t_mallocs}; }

}  // namespace contour::test

#ifndef CONTOUR_ASAN
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);

void* malloc(std::size_t n) {
  if (t_counting) ++t_mallocs;
  return __libc_malloc(n);
}
void* calloc(std::size_t a, std::size_t b) {
  if (t_counting) ++t_mallocs;
  return __libc_calloc(a, b);
}
void* realloc(void* p, std::size_t n) {
  if (t_counting) ++t_mallocs;
  return __libc_realloc(p, n);
}
void* aligned_alloc(std::size_t al, std::size_t n) {
  if (t_counting) ++t_mallocs;
  return __libc_memalign(al, n);
}
int posix_memalign(void** out, std::size_t al, std::size_t n) {
  if (t_counting) ++t_mallocs;
  void* p = __libc_memalign(al, n);
  if (p == nullptr) return 12;  // ENOMEM
  *out = p;
  return 0;
}
void free(void* p) { __libc_free(p); }
}
#endif

namespace {
void* counted_new(std::size_t n) {
  if (t_counting) ++t_news;
  void* p = std::malloc(n == 0 ? 1 : n);
  if (p == nullptr) throw std::bad_alloc();
  return p;
}
void* counted_new_aligned(std::size_t n, std::align_val_t al) {
  if (t_counting) ++t_news;
  void* p = std::aligned_alloc(static_cast<std::size_t>(al),
                               (n + static_cast<std::size_t>(al) - 1) &
                                   ~(static_cast<std::size_t>(al) - 1));
  if (p == nullptr) throw std::bad_alloc();
  return p;
}
}  // namespace

void* operator new(std::size_t n) { return counted_new(n); }
void* operator new[](std::size_t n) { return counted_new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t n, std::align_val_t al) { return counted_new_aligned(n, al); }
void* operator new[](std::size_t n, std::align_val_t al) { return counted_new_aligned(n, al); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
