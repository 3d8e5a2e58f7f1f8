// core/memory.h: huge-page-backed blocks and CHOLMOD's allocation through them.
#include <SuiteSparse_config.h>
#include <cholmod.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <Eigen/Sparse>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "polycube/core/memory.h"
#include "polycube/deform/sparse_system.h"

using namespace polycube;

namespace {
constexpr std::uintptr_t kTwoMB = std::uintptr_t(2) << 20;
bool aligned_2mb(const void* p) { return (reinterpret_cast<std::uintptr_t>(p) & (kTwoMB - 1)) == 0; }
long minor_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}
// The kernel's transparent huge page mode ("always", "madvise" or "never"), "" if unknown.
std::string thp_mode() {
  std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string s;
  std::getline(f, s);
  const auto a = s.find('['), b = s.find(']');
  return a != std::string::npos && b != std::string::npos && b > a ? s.substr(a + 1, b - a - 1) : "";
}
}  // namespace

TEST(Memory, LargeBlocksAreAlignedToHugePagesAndSmallOnesAreNot) {
  void* small = huge_page_malloc(100);
  ASSERT_NE(small, nullptr);
  std::free(small);
  const std::size_t bytes = kHugePageMinBytes + 12345;  // not a multiple of 2 MB
  auto* p = static_cast<unsigned char*>(huge_page_malloc(bytes));
  ASSERT_NE(p, nullptr);
  EXPECT_TRUE(aligned_2mb(p));
  p[0] = 1;
  p[bytes - 1] = 2;  // the whole block is usable
  EXPECT_EQ(p[0] + p[bytes - 1], 3);
  std::free(p);
  advise_huge_pages(nullptr, bytes);  // no effect, no crash
}

// Writing a fresh 64 MB block: with the kernel's transparent huge pages on, far fewer page faults
// than its 16384 pages of 4 KB (34 against 16386 with malloc on the machine this was written on).
TEST(Memory, LargeBlocksFaultInHugePagesWhereTheKernelHasThem) {
  const std::string mode = thp_mode();
  if (mode != "always" && mode != "madvise")
    GTEST_SKIP() << "transparent huge pages are off here (" << (mode.empty() ? "unknown" : mode) << ")";
  const std::size_t n = std::size_t(64) << 20;
  const long before = minor_faults();
  auto* p = static_cast<unsigned char*>(huge_page_malloc(n));
  ASSERT_NE(p, nullptr);
  std::memset(p, 1, n);
  const long faults = minor_faults() - before;
  EXPECT_EQ(p[n - 1], 1);
  std::free(p);
  EXPECT_LT(faults, static_cast<long>(n / 4096 / 4)) << "no huge pages: " << faults << " faults";
}

namespace {
// A 3D grid Laplacian plus identity over m^3 vertices (3 unknowns each), factorized; its factor
// (returned) is kept by `sys`.
const cholmod_factor* factorize_grid(std::unique_ptr<deform::SparseSystem>& sys, int m) {
  const int n = m * m * m;
  std::vector<std::vector<int>> elements;
  auto id = [&](int i, int j, int k) { return (i * m + j) * m + k; };
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j)
      for (int k = 0; k < m; ++k) {
        if (i + 1 < m) elements.push_back({id(i, j, k), id(i + 1, j, k)});
        if (j + 1 < m) elements.push_back({id(i, j, k), id(i, j + 1, k)});
        if (k + 1 < m) elements.push_back({id(i, j, k), id(i, j, k + 1)});
      }
  sys = std::make_unique<deform::SparseSystem>(n, elements);
  sys->set_zero();
  Eigen::MatrixXd edge = Eigen::MatrixXd::Zero(6, 6);
  for (int a = 0; a < 3; ++a) {
    edge(a, a) = edge(3 + a, 3 + a) = 1;
    edge(a, 3 + a) = edge(3 + a, a) = -1;
  }
  for (const auto& e : elements) sys->add(e.data(), 2, edge);
  sys->add_diagonal(1.0);
  if (!sys->factorize()) return nullptr;
  return sys->factor_ptr();
}
}  // namespace

// Inside a CholmodHugePages scope CHOLMOD allocates through huge_page_malloc: a supernodal factor's
// values (a large block) come 2 MB-aligned, and solves are still right; nested scopes (the
// realization's two starts) keep it; after the last one CHOLMOD's own functions are back.
TEST(Memory, CholmodFactorsComeFromHugePagesInsideTheScope) {
  const auto malloc_before = SuiteSparse_config.malloc_func;
  const auto calloc_before = SuiteSparse_config.calloc_func;
  {
    const CholmodHugePages outer;
    EXPECT_EQ(SuiteSparse_config.malloc_func, &huge_page_malloc);
    {
      const CholmodHugePages inner;
      EXPECT_EQ(SuiteSparse_config.malloc_func, &huge_page_malloc);
    }
    EXPECT_EQ(SuiteSparse_config.malloc_func, &huge_page_malloc);
    std::unique_ptr<deform::SparseSystem> sys;
    const cholmod_factor* L = factorize_grid(sys, 20);  // 24k unknowns: a factor of several MB
    ASSERT_NE(L, nullptr);
    ASSERT_TRUE(L->is_super);
    EXPECT_GE(L->xsize * sizeof(double), kHugePageMinBytes);
    EXPECT_TRUE(aligned_2mb(L->x)) << "the factor's values did not come from huge_page_malloc";
    const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(sys->dofs(), -1, 1), x = sys->solve(b);
    EXPECT_LT((sys->multiply(x) - b).norm(), 1e-8 * b.norm());
  }
  EXPECT_EQ(SuiteSparse_config.malloc_func, malloc_before);
  EXPECT_EQ(SuiteSparse_config.calloc_func, calloc_before);
}
