// Large blocks backed by transparent huge pages (2 MB) where the kernel offers them, for CHOLMOD's
// factors in the polycube realization and the deformation's factor.
//
// The realization factorizes afresh at each coupled Newton step (CHOLMOD allocates a new factor,
// tens to hundreds of MB, and frees it after), and every 4 KB page of a fresh block faults when
// first written: rocker's extraction (132k tets, from its saved deformation) made 2.1M page faults
// and spent 37-43 s in the kernel on this virtual machine. With the kernel's transparent huge pages
// in "madvise" mode (as on this project's Debian machines) or "always", a block marked
// MADV_HUGEPAGE before it is touched faults in 2 MB pages: 0.1M faults, 22-27 s in the kernel,
// the extraction 82-100 s -> 68-85 s (interleaved runs), the same polycube to the bit. Only a hint: without huge pages
// (another kernel setting, another OS) nothing changes, and the contents and arithmetic are the
// same.
//
// The deformation's SQP solver, which keeps one factor for the whole run, takes huge pages for
// that factor's values and its float copy only (SparseSystem::analyze; fifty-fifth session: rocker's
// page faults 404k -> 227k, fandisk's first factorization 0.45-0.56 -> 0.20-0.21 s). With all of
// CHOLMOD's blocks in huge pages there, rocker's page faults fell 404k -> 68k but its assembly and
// line search measured 1-5 s slower in five of five pairs of runs (the cause not found).
#pragma once
#include <cstddef>

namespace polycube {

/// Blocks from this many bytes on are marked for huge pages (smaller ones gain nothing).
constexpr std::size_t kHugePageMinBytes = std::size_t(4) << 20;

/// Marks the 2 MB-aligned part of [p, p + bytes) for transparent huge pages (madvise
/// MADV_HUGEPAGE), if bytes >= kHugePageMinBytes and the system has them; no effect otherwise.
/// Call it before the memory is first written.
void advise_huge_pages(void* p, std::size_t bytes);

/// malloc with advise_huge_pages on large blocks, which are aligned to 2 MB so that the whole block
/// can be backed by huge pages. Free the result with std::free.
void* huge_page_malloc(std::size_t bytes);

/// While an instance exists (in any thread), CHOLMOD allocates its large blocks with
/// huge_page_malloc (through SuiteSparse_config's allocation functions, which are process-wide);
/// the functions before the first instance come back when the last one ends. Blocks allocated
/// either way may be freed either way (both go to std::free).
class CholmodHugePages {
 public:
  CholmodHugePages();
  ~CholmodHugePages();
  CholmodHugePages(const CholmodHugePages&) = delete;
  CholmodHugePages& operator=(const CholmodHugePages&) = delete;
};

}  // namespace polycube
