#include "polycube/core/memory.h"

#include <SuiteSparse_config.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <mutex>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace polycube {

namespace {
constexpr std::size_t kHugePage = std::size_t(2) << 20;

void* huge_page_calloc(std::size_t n, std::size_t size) {
  if (size != 0 && n > static_cast<std::size_t>(-1) / size) return nullptr;
  const std::size_t bytes = n * size;
  if (bytes < kHugePageMinBytes) return std::calloc(n, size);
  void* p = huge_page_malloc(bytes);
  if (p) std::memset(p, 0, bytes);
  return p;
}

struct CholmodState {
  std::mutex mutex;
  int users = 0;
  void* (*malloc_before)(std::size_t) = nullptr;
  void* (*calloc_before)(std::size_t, std::size_t) = nullptr;
};
CholmodState& cholmod_state() {
  static CholmodState s;
  return s;
}
}  // namespace

void advise_huge_pages(void* p, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (!p || bytes < kHugePageMinBytes) return;
  const auto begin = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t first = (begin + kHugePage - 1) & ~(kHugePage - 1);
  const std::uintptr_t last = (begin + bytes) & ~(kHugePage - 1);
  if (last > first) madvise(reinterpret_cast<void*>(first), last - first, MADV_HUGEPAGE);  // a hint: errors ignored
#else
  (void)p;
  (void)bytes;
#endif
}

void* huge_page_malloc(std::size_t bytes) {
  if (bytes < kHugePageMinBytes) return std::malloc(bytes == 0 ? 1 : bytes);
  const std::size_t rounded = (bytes + kHugePage - 1) & ~(kHugePage - 1);
  void* p = std::aligned_alloc(kHugePage, rounded);
  advise_huge_pages(p, rounded);
  return p;
}

CholmodHugePages::CholmodHugePages() {
  CholmodState& s = cholmod_state();
  const std::lock_guard<std::mutex> lock(s.mutex);
  if (s.users++ == 0) {
    s.malloc_before = SuiteSparse_config.malloc_func;
    s.calloc_before = SuiteSparse_config.calloc_func;
    SuiteSparse_config.malloc_func = huge_page_malloc;
    SuiteSparse_config.calloc_func = huge_page_calloc;
  }
}

CholmodHugePages::~CholmodHugePages() {
  CholmodState& s = cholmod_state();
  const std::lock_guard<std::mutex> lock(s.mutex);
  if (--s.users == 0) {
    SuiteSparse_config.malloc_func = s.malloc_before;
    SuiteSparse_config.calloc_func = s.calloc_before;
  }
}

}  // namespace polycube
