// A single-precision supernodal LL^T factor, for preconditioning: a copy of CHOLMOD's double
// factor, or factorized here in float from CHOLMOD's symbolic analysis (analyze, factorize).
//
// The SQP solver's conjugate gradients apply a Cholesky factor of an older Hessian hundreds of
// times per run; each application is a forward and a backward triangular solve, which reads the
// whole factor twice and is bound by memory bandwidth (fandisk, 37.8k tets: 9.3M nonzeros, 150 MB
// per double solve). A float copy halves the traffic and doubles the SIMD width; conjugate
// gradients (in double) absorb its rounding like any other difference between the preconditioner
// and the current matrix. The direct solves that must be exact keep CHOLMOD's double factor.
#pragma once
#include <cholmod.h>

#include <array>
#include <vector>

namespace polycube::deform {

class FloatFactor {
 public:
  /// Copies L (supernodal LL^T with int indices). Returns false, and leaves the copy empty, for
  /// any other kind of factor (simplicial, LDL^T, long indices): callers then use CHOLMOD's solve.
  bool assign(const cholmod_factor* L);
  bool empty() const { return n_ == 0; }
  int size() const { return n_; }
  /// Prepares factorize(): the structure of the supernodal symbolic factor L (CHOLMOD's analysis,
  /// int indices) and, per stored entry of the n x n matrix A (upper triangle, CSC: Ap, Ai), its
  /// place in the factor. False, and nothing prepared, if L is not supernodal with int indices.
  bool analyze(const cholmod_factor* L, const int* Ap, const int* Ai);
  /// Numeric factorization of A (the values of the pattern given to analyze, in its order) in
  /// single precision, left-looking over the supernodes as CHOLMOD's (its BLAS calls in float:
  /// about twice the speed of CHOLMOD's double factorization). The result replaces the copy, for
  /// solve() and solve2(). False if a pivot is not positive in float (the copy is empty then).
  /// shift: added to every diagonal entry first (the factor is then a preconditioner of A).
  bool factorize(const double* Ax, double shift = 0);
  bool analyzed() const { return !a_dest_.empty(); }
  /// x = A^-1 b with A = P^T L L^T P, in float. `work` is the caller's scratch (one per thread).
  void solve(const double* b, double* x, std::vector<float>& work) const;
  /// x0 = A^-1 b0 and x1 = A^-1 b1 at once, on two threads when the machine has them: the factor is
  /// read once for both, each thread sweeping its own subtrees of the elimination tree. The
  /// arithmetic does not depend on the thread count.
  void solve2(const double* b0, const double* b1, double* x0, double* x1, std::vector<float>& work) const;
  /// Factors with fewer entries are swept by one thread (torus, 4k tets, 0.3M entries: the threads'
  /// start-up cost more than the sweeps).
  static constexpr size_t kParallelEntries = 1000000;
  /// True when solve2 sweeps on two threads (the factor has kParallelEntries or more).
  bool parallel() const { return x_.size() >= parallel_entries_; }
  /// Tests: sweep on two threads from this many entries on (kParallelEntries by default).
  void set_parallel_entries(size_t n) { parallel_entries_ = n; }

 private:
  int n_ = 0, nsuper_ = 0, max_rows_ = 0;
  std::vector<int> super_, pi_, s_, perm_;
  std::vector<long> off_;    // per supernode, its first value in x_
  std::vector<float> x_;     // per supernode, the rows below its diagonal block, then that block's lower triangle
  std::vector<float> dinv_;  // inverse diagonal of L
  // Two-thread split of the elimination tree (see partition()): per thread, ranges [begin, end) of
  // supernodes (whole subtrees); the top part's ranges; per column, 0 or 1 (a thread's) or 2 (top).
  std::array<std::vector<std::array<int, 2>>, 2> ranges_;
  std::vector<std::array<int, 2>> top_ranges_;
  std::vector<signed char> owner_;
  size_t parallel_entries_ = kParallelEntries;
  // analyze(): per entry of A, its place in x_ (>= 0) or, as -1 - k, on the diagonal of column k;
  // per column, its supernode.
  std::vector<long> a_dest_;
  std::vector<int> col_super_;
  const cholmod_factor* analyzed_for_ = nullptr;  // the factor analyze() read (assign() of it keeps the map)
  void set_structure(const cholmod_factor* L);
  void partition();
};

}  // namespace polycube::deform
