// Large arrays backed by transparent huge pages (2 MB) where the kernel offers them.
//
// The SQP solver's big arrays (CHOLMOD's factor, 424 MB on rocker's 132k tets; its float copy,
// 212 MB; the system's values, 21 MB, which the assembly adds into at scattered positions) are
// touched page by page when first written, and on a virtual machine 4 KB page faults cost several
// microseconds each: rocker's first factorization took 4.3 s against 1.8 s for the later ones,
// its float copy 1.2 s against 0.05-0.1 s, and its polycube extraction, which factorizes afresh
// at each coupled Newton step, made 2.1M faults. With the kernel's transparent huge pages in
// "madvise" mode (as on this project's Debian machines) or "always", a region marked
// MADV_HUGEPAGE before it is touched faults in 2 MB pages (the extraction: 0.1M faults, 82-100 s
// -> 68-69 s). Only a hint: without huge pages (another kernel setting, another OS) nothing
// changes, and the contents and arithmetic are the same.
#pragma once
#include <cstddef>
#include <new>
#include <vector>

namespace polycube {

/// Arrays from this many bytes on are marked for huge pages (smaller ones gain nothing).
constexpr std::size_t kHugePageMinBytes = std::size_t(4) << 20;

/// Marks the 2 MB-aligned part of [p, p + bytes) for transparent huge pages (madvise
/// MADV_HUGEPAGE), if bytes >= kHugePageMinBytes and the system has them; no effect otherwise.
/// Call it before the memory is first written.
void advise_huge_pages(void* p, std::size_t bytes);

/// malloc / free with advise_huge_pages on large blocks (aligned to 2 MB when large, so that the
/// whole block can be backed by huge pages).
void* huge_page_malloc(std::size_t bytes);
void huge_page_free(void* p) noexcept;

/// Allocator for std::vector: large buffers marked for huge pages before they are filled.
template <class T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}
  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_array_new_length();
    void* p = huge_page_malloc(n * sizeof(T));
    if (!p) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t) noexcept { huge_page_free(p); }
  template <class U>
  bool operator==(const HugePageAllocator<U>&) const noexcept {
    return true;
  }
  template <class U>
  bool operator!=(const HugePageAllocator<U>&) const noexcept {
    return false;
  }
};

/// A vector whose large buffers are marked for huge pages.
template <class T>
using HugeVector = std::vector<T, HugePageAllocator<T>>;

/// Makes CHOLMOD (through SuiteSparse_config's allocation functions, process-wide) allocate with
/// huge_page_malloc, so that its factors fault in huge pages. Idempotent; call before the first
/// factorization.
void use_huge_pages_in_cholmod();

}  // namespace polycube
