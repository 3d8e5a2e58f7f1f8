// core/memory.h: huge-page-backed buffers and CHOLMOD's allocation through them.
#include <SuiteSparse_config.h>
#include <cholmod.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <Eigen/Sparse>
#include <cstdint>
#include <fstream>
#include <numeric>
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
  huge_page_free(small);
  const std::size_t bytes = kHugePageMinBytes + 12345;  // not a multiple of 2 MB
  auto* p = static_cast<unsigned char*>(huge_page_malloc(bytes));
  ASSERT_NE(p, nullptr);
  EXPECT_TRUE(aligned_2mb(p));
  p[0] = 1;
  p[bytes - 1] = 2;  // the whole block is usable
  EXPECT_EQ(p[0] + p[bytes - 1], 3);
  huge_page_free(p);
  advise_huge_pages(nullptr, bytes);  // no effect, no crash
}

TEST(Memory, HugeVectorKeepsItsValues) {
  HugeVector<double> v(std::size_t(1) << 20);  // 8 MB: a huge-page block
  EXPECT_TRUE(aligned_2mb(v.data()));
  std::iota(v.begin(), v.end(), 0.0);
  HugeVector<double> w = v;
  w.push_back(-1);  // grows into a new block, values copied
  EXPECT_EQ(w.size(), v.size() + 1);
  EXPECT_TRUE(std::equal(v.begin(), v.end(), w.begin()));
  EXPECT_EQ(w.back(), -1);
  HugeVector<float> small(10, 2.5f);
  EXPECT_EQ(std::accumulate(small.begin(), small.end(), 0.0f), 25.0f);
}

// Touching a 64 MB huge-page vector: with the kernel's transparent huge pages on, far fewer page
// faults than its 16384 pages of 4 KB (rocker's extraction: 2.1M faults -> 0.1M, 82-100 s -> 68-69 s).
TEST(Memory, HugeVectorFaultsInHugePagesWhereTheKernelHasThem) {
  const std::string mode = thp_mode();
  if (mode != "always" && mode != "madvise")
    GTEST_SKIP() << "transparent huge pages are off here (" << (mode.empty() ? "unknown" : mode) << ")";
  const std::size_t n = std::size_t(64) << 20;
  const long before = minor_faults();
  HugeVector<unsigned char> v(n, 1);  // value-initialized: every page written
  const long faults = minor_faults() - before;
  EXPECT_EQ(v[n - 1], 1);
  EXPECT_LT(faults, static_cast<long>(n / 4096 / 4)) << "no huge pages: " << faults << " faults";
  RecordProperty("faults", static_cast<int>(faults));
}

// CHOLMOD allocates through huge_page_malloc once the SQP system is built: its supernodal factor's
// values (a large block) come 2 MB-aligned, and solves are still right.
TEST(Memory, CholmodFactorsComeFromHugePages) {
  // A 3D grid Laplacian plus identity, 20^3 vertices (24k unknowns): a factor of several MB.
  const int m = 20, n = m * m * m;
  std::vector<std::vector<int>> elements;
  auto id = [&](int i, int j, int k) { return (i * m + j) * m + k; };
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j)
      for (int k = 0; k < m; ++k) {
        if (i + 1 < m) elements.push_back({id(i, j, k), id(i + 1, j, k)});
        if (j + 1 < m) elements.push_back({id(i, j, k), id(i, j + 1, k)});
        if (k + 1 < m) elements.push_back({id(i, j, k), id(i, j, k + 1)});
      }
  deform::SparseSystem sys(n, elements);
  EXPECT_EQ(SuiteSparse_config.malloc_func, &huge_page_malloc);
  sys.set_zero();
  Eigen::MatrixXd edge(6, 6);
  edge.setZero();
  for (int a = 0; a < 3; ++a) {
    edge(a, a) = edge(3 + a, 3 + a) = 1;
    edge(a, 3 + a) = edge(3 + a, a) = -1;
  }
  for (const auto& e : elements) sys.add(e.data(), 2, edge);
  sys.add_diagonal(1.0);
  ASSERT_TRUE(sys.factorize());
  const cholmod_factor* L = sys.factor_ptr();
  ASSERT_NE(L, nullptr);
  ASSERT_TRUE(L->is_super);
  EXPECT_GE(L->xsize * sizeof(double), kHugePageMinBytes);
  EXPECT_TRUE(aligned_2mb(L->x)) << "the factor's values did not come from huge_page_malloc";
  Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(3 * n, -1, 1), x = sys.solve(b);
  EXPECT_LT((sys.multiply(x) - b).norm(), 1e-8 * b.norm());
}
