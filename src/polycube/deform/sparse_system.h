// The sparse symmetric system of the SQP step: a fixed pattern (tet mesh adjacency plus the
// vertices of adjacent boundary-triangle pairs), assembled in place from element Hessians, and
// factorized with CHOLMOD (supernodal or simplicial, chosen by CHOLMOD from the fill-in), the
// symbolic analysis done once per pattern.
#pragma once
#include <Eigen/CholmodSupport>
#include <Eigen/Sparse>
#include <array>
#include <memory>
#include <vector>

#include "polycube/deform/energies.h"
#include "polycube/deform/float_factor.h"

namespace polycube::deform {

/// Eigen's CHOLMOD wrapper with its factor exposed, for solves from several threads.
class CholmodLLT : public Eigen::CholmodDecomposition<Eigen::SparseMatrix<double>, Eigen::Upper> {
 public:
  cholmod_factor* factor() const { return m_cholmodFactor; }
};

class SparseSystem : public HessianSink {
 public:
  /// Solves may run concurrently in this many slots (threads), one slot per thread.
  static constexpr int kSlots = 2;
  /// Pattern over `nvertices` vertices (3 DOF each) from element vertex lists.
  SparseSystem(int nvertices, const std::vector<std::vector<int>>& elements);
  ~SparseSystem() override;
  SparseSystem(const SparseSystem&) = delete;
  SparseSystem& operator=(const SparseSystem&) = delete;

  void set_zero() { std::fill(values_.begin(), values_.end(), 0.0); }
  /// Current values (upper triangle, CSC order); copy/restore for a constant part.
  std::vector<double>& values() { return values_; }
  void add(const int* v, int nv, const Eigen::Ref<const Eigen::MatrixXd>& H) override;
  void add_outer(const int* v, int nv, double c, const double* u) override;
  /// A sink with this system's pattern that adds into `values` (sized like values()) instead, so
  /// that two threads can assemble terms side by side and the caller sums the arrays after.
  class Buffer : public HessianSink {
   public:
    Buffer(const SparseSystem& sys, std::vector<double>& values) : sys_(sys), values_(values) {}
    void add(const int* v, int nv, const Eigen::Ref<const Eigen::MatrixXd>& H) override {
      sys_.add_to(values_, cursor_, v, nv, H);
    }
    void add_outer(const int* v, int nv, double c, const double* u) override {
      sys_.add_outer_to(values_, cursor_, v, nv, c, u);
    }

   private:
    const SparseSystem& sys_;
    std::vector<double>& values_;
    std::array<int, 2> cursor_{};  // see add_to
  };
  /// Precomputes the value positions of the 3- and 4-vertex elements given (their vertices must
  /// be in the pattern), so that add() of those elements skips the index search. Energies add
  /// their elements in the order given here (tets, boundary triangles, boundary pairs).
  void cache_elements(const std::vector<std::vector<int>>& elements);
  /// Adds mu to every diagonal entry.
  void add_diagonal(double mu);
  double mean_diagonal() const;

  /// The symbolic analysis (fill-reducing ordering, supernodes), which factorize() otherwise makes
  /// on its first call. It reads only the pattern, so it may run on another thread while the
  /// elements are cached (cache_elements) and values added; no other call meanwhile. Call
  /// set_float_factorization first. Once only: later calls do nothing.
  void analyze();
  /// Numeric factorization (symbolic analysis on first call). False if not positive definite.
  /// With set_float_factorization(true) and a supernodal analysis, the factorization is made in
  /// single precision (FloatFactor::factorize) and CHOLMOD's double one only where a float pivot
  /// is not positive; solve() and solve_pair() then refine with conjugate gradients.
  bool factorize();
  /// Off by default; to be set before the first factorize(). `shift` is added to the diagonal of
  /// the float factorizations only (see DeformOptions::float_factorization).
  void set_float_factorization(bool on, double shift = 0) {
    float_wanted_ = on;
    float_shift_ = shift;
  }
  /// Factorizations made in float, and float factorizations that broke down (then made in double).
  int float_factorizations() const { return float_factorizations_; }
  int float_breakdowns() const { return float_breakdowns_; }
  /// Tests: the float factor's two-thread threshold (FloatFactor::set_parallel_entries).
  void set_float_parallel_entries(size_t n) { float_factor_.set_parallel_entries(n); }
  /// Preconditioned CG iterations spent by solve_pair on the float factor of the current values.
  int refinement_iterations() const { return refinement_iterations_; }
  /// Cost model of the last factorization, from CHOLMOD's symbolic analysis (deterministic, unlike
  /// timings): floating-point operations of a factorization over those of one preconditioned CG
  /// iteration (two triangular solves with the factor and one product with the matrix).
  double factor_to_cg_cost() const;
  /// Nonzeros of the last factor and flops of one factorization (CHOLMOD's counts; 0 before one).
  double factor_nonzeros() const;
  double factor_flops() const;
  /// x = A^-1 b with the last factorization. Calls with different `slot`s may run concurrently.
  Eigen::VectorXd solve(const Eigen::VectorXd& b, int slot = 0) const;
  /// Applies the preconditioner: A^-1 b with the single-precision copy of the last factorization
  /// (CHOLMOD's double solve when the factor is not supernodal). Concurrent calls need different slots.
  Eigen::VectorXd precondition(const Eigen::VectorXd& b, int slot = 0) const;
  /// y = A x with the current values (the factorization may be of older ones).
  Eigen::VectorXd multiply(const Eigen::VectorXd& x) const;
  /// Solves A x = b with the current values by conjugate gradients preconditioned with the last
  /// factorization (its single-precision copy: a few iterations even when it is of the current
  /// values). Stops when the residual, in the 2-norm or in the preconditioner's energy norm
  /// (r.P^-1 r against b.P^-1 b), falls below `tol` relative to b's: the 2-norm alone is ruled by
  /// the stiff rows of slivers and boosted barriers, and asked for iterations that did not improve
  /// the SQP direction (fandisk 37.8k tets: 13 -> 8 factorizations, 18.3 -> 15.6 s; rod 51 -> 46 s,
  /// bumpy torus 68 -> 56 s; same l1_quality and ARAP). Returns the preconditioner applications
  /// used, or -1 if neither fell below `tol` within `max_iter`. (Starting
  /// from the previous iteration's solution was tried: its stale smooth components pass the
  /// residual test, and the SQP stalled on a sphere.)
  int solve_pcg(const Eigen::VectorXd& b, Eigen::VectorXd& x, double tol, int max_iter, int slot = 0) const;
  /// Two solve_pcg calls at once. With the float factor they run in lockstep, each preconditioner
  /// application serving both (FloatFactor::solve2, two threads); otherwise side by side (slots 0
  /// and 1, BLAS single-threaded meanwhile). Returns both results.
  std::array<int, 2> solve_pcg_pair(const Eigen::VectorXd& b0, Eigen::VectorXd& x0, const Eigen::VectorXd& b1,
                                    Eigen::VectorXd& x1, double tol, int max_iter) const;
  /// x0 = A^-1 b0 and x1 = A^-1 b1 with the last factorization, on two threads when available.
  /// After a float factorization: CG on it to kRefineTolerance (the double factorization made if
  /// that fails).
  void solve_pair(const Eigen::VectorXd& b0, Eigen::VectorXd& x0, const Eigen::VectorXd& b1,
                  Eigen::VectorXd& x1);
  static constexpr double kRefineTolerance = 1e-3;
  int dofs() const { return 3 * n_; }
  cholmod_factor* factor_ptr() const { return llt_ ? llt_->factor() : nullptr; }

 private:
  int position(int vi, int vj, int a, int b) const;  // vi <= vj
  // Adds H into `values`; `cursor` holds the sink's guesses of the next cached element of each
  // size (see add_to).
  void add_to(std::vector<double>& values, std::array<int, 2>& cursor, const int* v, int nv,
              const Eigen::Ref<const Eigen::MatrixXd>& H) const;
  // The same for the rank-1 Hessian (c u) u^T (see HessianSink::add_outer).
  void add_outer_to(std::vector<double>& values, std::array<int, 2>& cursor, const int* v, int nv, double c,
                    const double* u) const;
  // Adds element entry (i, j) = entry(i, j) at the cached or searched positions (see add_to).
  template <class Entry>
  void add_element(std::vector<double>& values, std::array<int, 2>& cursor, const int* v, int nv,
                   const Entry& entry) const;
  int n_;
  std::vector<std::vector<int>> lower_;  // per vertex: sorted neighbours with smaller index
  Eigen::SparseMatrix<double> A_;       // upper triangle, compressed
  std::vector<double> values_;
  std::vector<int> diag_;
  // Caches of the elements of 3 (index 0) and 4 (index 1) vertices: per element in the order
  // given, its nv x nv x 3 column-start positions (-1 below the diagonal); the keys (the vertex
  // lists, a triangle's with -1 last) sorted with their element's index, for elements added out
  // of order.
  struct ElementCache {
    std::vector<std::pair<std::array<int, 4>, int>> keys;
    std::vector<int> pos;
    std::vector<std::array<int, 4>> order;
  };
  std::array<ElementCache, 2> cache_;
  std::array<int, 2> cursor_{};  // add()'s guesses of the next cached element
  std::unique_ptr<CholmodLLT> llt_;
  // Per slot: CHOLMOD's common (workspace, status) and the solve's reused result and workspaces.
  struct Slot {
    cholmod_common common;
    cholmod_dense* x = nullptr;
    cholmod_dense* y = nullptr;
    cholmod_dense* e = nullptr;
    std::vector<float> work;  // FloatFactor::solve's scratch
  };
  mutable std::array<Slot, kSlots> slots_;
  bool analyzed_ = false;
  bool float_wanted_ = false, float_only_ = false;  // float_only_: no double factor of the current values
  int float_factorizations_ = 0, float_breakdowns_ = 0;
  double float_shift_ = 0;
  int refinement_iterations_ = 0;
  bool factorize_double();
  FloatFactor float_factor_;  // llt_'s factor copied to float, or the float factorization (empty if not supernodal)
};

}  // namespace polycube::deform
