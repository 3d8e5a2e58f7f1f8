#include "polycube/deform/sparse_system.h"

#include <dlfcn.h>

#include <algorithm>
#include <cstring>

#include "polycube/core/error.h"
#include "polycube/core/memory.h"
#include "polycube/core/parallel.h"

namespace polycube::deform {

SparseSystem::SparseSystem(int n, const std::vector<std::vector<int>>& elements) : n_(n), lower_(n) {
  for (const auto& e : elements)
    for (int a : e)
      for (int b : e)
        if (a < b) lower_[b].push_back(a);
  for (auto& l : lower_) {
    std::sort(l.begin(), l.end());
    l.erase(std::unique(l.begin(), l.end()), l.end());
  }
  // CSC upper triangle: column 3vj+b holds rows of lower neighbours (3 each) then 3vj..3vj+b.
  std::vector<int> outer(3 * n + 1, 0), inner;
  for (int vj = 0; vj < n; ++vj)
    for (int b = 0; b < 3; ++b) {
      for (int vi : lower_[vj])
        for (int a = 0; a < 3; ++a) inner.push_back(3 * vi + a);
      for (int a = 0; a <= b; ++a) inner.push_back(3 * vj + a);
      outer[3 * vj + b + 1] = static_cast<int>(inner.size());
    }
  values_.assign(inner.size(), 0.0);
  A_ = Eigen::SparseMatrix<double>(3 * n, 3 * n);
  A_.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), A_.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), A_.innerIndexPtr());
  diag_.resize(3 * n);
  for (int c = 0; c < 3 * n; ++c) diag_[c] = outer[c + 1] - 1;
  for (Slot& s : slots_) {
    cholmod_start(&s.common);
    s.common.print = 0;  // the library never prints
  }
}

SparseSystem::~SparseSystem() {
  for (Slot& s : slots_) {
    cholmod_free_dense(&s.x, &s.common);
    cholmod_free_dense(&s.y, &s.common);
    cholmod_free_dense(&s.e, &s.common);
    cholmod_finish(&s.common);
  }
}

int SparseSystem::position(int vi, int vj, int a, int b) const {
  const int col = 3 * vj + b;
  const int start = A_.outerIndexPtr()[col];
  if (vi == vj) return start + 3 * static_cast<int>(lower_[vj].size()) + a;
  const auto& l = lower_[vj];
  const int rank = static_cast<int>(std::lower_bound(l.begin(), l.end(), vi) - l.begin());
  return start + 3 * rank + a;
}

void SparseSystem::cache_elements(const std::vector<std::vector<int>>& elements) {
  for (ElementCache& c : cache_) c = ElementCache();
  for (const auto& e : elements) {
    const int nv = static_cast<int>(e.size());
    if (nv != 3 && nv != 4) continue;
    ElementCache& c = cache_[nv - 3];
    const std::array<int, 4> k{e[0], e[1], e[2], nv == 4 ? e[3] : -1};
    c.keys.push_back({k, static_cast<int>(c.order.size())});
    c.order.push_back(k);
    for (int p = 0; p < nv; ++p)
      for (int q = 0; q < nv; ++q)
        for (int b = 0; b < 3; ++b) c.pos.push_back(k[p] <= k[q] ? position(k[p], k[q], 0, b) : -1);
  }
  for (ElementCache& c : cache_) std::sort(c.keys.begin(), c.keys.end());
}

void SparseSystem::add(const int* v, int nv, const Eigen::Ref<const Eigen::MatrixXd>& H) {
  add_to(values_, cursor_, v, nv, H);
}

template <class Entry>
void SparseSystem::add_element(std::vector<double>& vals, std::array<int, 2>& cursors, const int* v, int nv,
                               const Entry& entry) const {
  if ((nv == 3 || nv == 4) && !cache_[nv - 3].order.empty()) {
    const ElementCache& c = cache_[nv - 3];
    int& cursor = cursors[nv - 3];
    const std::array<int, 4> k{v[0], v[1], v[2], nv == 4 ? v[3] : -1};
    // The energies add their elements in the order given to cache_elements: try the element after
    // the last one first, and search the sorted keys only when that is not it (fandisk, 37.8k
    // tets: a binary search over 57k keys per element was a third of the assembly).
    const int stride = nv * nv * 3;
    const int count = static_cast<int>(c.order.size());
    int e = -1;
    if (cursor >= 0 && cursor < count && c.order[cursor] == k) {
      e = cursor;
    } else {
      auto it = std::lower_bound(c.keys.begin(), c.keys.end(), std::make_pair(k, -1));
      if (it != c.keys.end() && it->first == k) e = it->second;
    }
    if (e >= 0) {
      cursor = e + 1;
      // The values an element adds to are scattered over the array (cache misses: most of the
      // assembly's time): fetch the next element's while this one is added (rocker, 132k tets:
      // the volume barrier's assembly 91 -> 66 ms per iteration). The arithmetic is unchanged.
      if (cursor < count) {
        const int* next = &c.pos[static_cast<size_t>(cursor) * stride];
        for (int i = 0; i < stride; ++i)
          if (next[i] >= 0) __builtin_prefetch(&vals[next[i]], 1, 1);
      }
      const int* pos = &c.pos[static_cast<size_t>(e) * stride];
      for (int p = 0; p < nv; ++p)
        for (int q = 0; q < nv; ++q) {
          if (v[p] > v[q] || (v[p] == v[q] && p != q)) continue;
          for (int b = 0; b < 3; ++b) {
            const int base = pos[(nv * p + q) * 3 + b];
            const int amax = v[p] == v[q] ? b : 2;
            for (int a = 0; a <= amax; ++a) vals[base + a] += entry(3 * p + a, 3 * q + b);
          }
        }
      return;
    }
  }
  for (int p = 0; p < nv; ++p)
    for (int q = 0; q < nv; ++q) {
      const int vi = v[p], vj = v[q];
      if (vi > vj) continue;
      if (vi == vj && p != q) {
        // Repeated vertex in an element: never happens for valid elements.
        continue;
      }
      for (int b = 0; b < 3; ++b) {
        int pos = position(vi, vj, 0, b);
        const int amax = vi == vj ? b : 2;
        for (int a = 0; a <= amax; ++a) vals[pos + a] += entry(3 * p + a, 3 * q + b);
      }
    }
}

void SparseSystem::add_to(std::vector<double>& vals, std::array<int, 2>& cursors, const int* v, int nv,
                          const Eigen::Ref<const Eigen::MatrixXd>& H) const {
  add_element(vals, cursors, v, nv, [&H](int i, int j) { return H(i, j); });
}

void SparseSystem::add_outer_to(std::vector<double>& vals, std::array<int, 2>& cursors, const int* v, int nv,
                                double c, const double* u) const {
  POLYCUBE_ASSERT(nv <= 4, "rank-1 element Hessians have at most 4 vertices");
  double w[12];
  for (int i = 0; i < 3 * nv; ++i) w[i] = c * u[i];
  add_element(vals, cursors, v, nv, [&w, u](int i, int j) { return w[i] * u[j]; });
}

void SparseSystem::add_outer(const int* v, int nv, double c, const double* u) {
  add_outer_to(values_, cursor_, v, nv, c, u);
}

void SparseSystem::add_diagonal(double mu) {
  for (int d : diag_) values_[d] += mu;
}

double SparseSystem::mean_diagonal() const {
  double s = 0;
  for (int d : diag_) s += values_[d];
  return s / static_cast<double>(diag_.size());
}

namespace {
// OpenBLAS's worker threads spin (sched_yield) between the many small dense kernels of a supernodal
// factorization; with more than two threads that costs more than it gains at our sizes (measured:
// 2 threads 20% faster than 1 on an 8k-tet sphere). OpenMP (used by CHOLMOD) is kept at one
// thread.
void factorization_blas_threads() {
  set_blas_threads(hardware_threads());
  static bool done = false;
  if (done) return;
  done = true;
  using SetThreads = void (*)(int);
  if (auto f = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "omp_set_num_threads"))) f(1);
}
}  // namespace

void SparseSystem::analyze() {
  if (analyzed_) return;
  const SerialOpenMP serial_openmp;
  llt_ = std::make_unique<CholmodLLT>();
  llt_->setMode(Eigen::CholmodAuto);
  llt_->cholmod().print = 0;  // the library never prints
  llt_->analyzePattern(A_);  // (the pattern only; factorize_double copies the values)
  analyzed_ = true;
  // The factor's values, allocated here (as CHOLMOD's numeric factorization would) in huge pages
  // and written once (not for the float factorization, which may never need them): in 4 KB pages
  // the first factorization faulted each page of a block it then kept for the whole run (fandisk,
  // 35.6k tets, 69 MB: first numeric factorization 0.45-0.56 s against 0.22 s for the later ones;
  // with this 0.20-0.21 s, and 0.01 s here).
  if (cholmod_factor* L = llt_->factor(); L && L->is_super && L->xtype == CHOLMOD_PATTERN && !float_wanted_) {
    {
      const CholmodHugePages huge;
      cholmod_change_factor(CHOLMOD_REAL, true, true, true, true, L, &llt_->cholmod());
    }
    if (L->x) std::memset(L->x, 0, L->xsize * sizeof(double));
  }
  if (float_wanted_) float_factor_.analyze(llt_->factor(), A_.outerIndexPtr(), A_.innerIndexPtr());
}

bool SparseSystem::factorize() {
  factorization_blas_threads();
  const SerialOpenMP serial_openmp;
  analyze();
  if (float_wanted_ && float_factor_.analyzed()) {
    // A pivot that is not positive in float: once more with 100 times the shift, then, if that
    // fails too, the double factorization from then on (with a diagonal shifted further, a float
    // factor is a poor preconditioner: relative shifts of 1e-5 on every diagonal entry gave the
    // rod 7 solves over the limit and 20 factorizations instead of 13).
    for (const double shift : {float_shift_, 100 * float_shift_}) {
      if (float_factor_.factorize(values_.data(), shift)) {
        ++float_factorizations_;
        float_only_ = true;
        return true;
      }
      ++float_breakdowns_;
      if (float_shift_ <= 0) break;
    }
    float_wanted_ = false;
  }
  return factorize_double();
}

bool SparseSystem::factorize_double() {
  float_only_ = false;
  factorization_blas_threads();
  const SerialOpenMP serial_openmp;
  std::copy(values_.begin(), values_.end(), A_.valuePtr());
  llt_->factorize(A_);
  if (llt_->info() != Eigen::Success) {
    float_factor_.assign(nullptr);
    return false;
  }
  float_factor_.assign(llt_->factor());
  return true;
}

double SparseSystem::factor_to_cg_cost() const {
  if (!llt_) return 0;
  const cholmod_common& c = llt_->cholmod();
  // (The float copy makes a CG iteration about 1.6x cheaper than this model says; counting it so,
  // 2 or 3 x lnz, allowed longer CG runs that cost more than the factorizations they saved:
  // fandisk 37.8k tets 7-8 factorizations and 2620-3007 CG iterations against 10 and 2053.)
  const double cg = 4.0 * c.lnz + 4.0 * static_cast<double>(values_.size());
  return cg > 0 ? c.fl / cg : 0;
}

double SparseSystem::factor_nonzeros() const { return llt_ ? llt_->cholmod().lnz : 0; }
double SparseSystem::factor_flops() const { return llt_ ? llt_->cholmod().fl : 0; }

Eigen::VectorXd SparseSystem::solve(const Eigen::VectorXd& b, int slot) const {
  POLYCUBE_ASSERT(llt_ && slot >= 0 && slot < kSlots, "solve without a factorization or with a bad slot");
  if (float_only_) {
    // The float factor of the current values: refined to double accuracy by CG.
    Eigen::VectorXd x;
    const int its = solve_pcg(b, x, 1e-12, 100, slot);
    POLYCUBE_ASSERT(its > 0, "CG on the float factor did not converge");
    return x;
  }
  Slot& s = slots_[slot];
  cholmod_dense B{};
  B.nrow = static_cast<size_t>(b.size());
  B.ncol = 1;
  B.nzmax = B.nrow;
  B.d = B.nrow;
  B.x = const_cast<double*>(b.data());
  B.xtype = CHOLMOD_REAL;
  B.dtype = CHOLMOD_DOUBLE;
  const int ok = cholmod_solve2(CHOLMOD_A, llt_->factor(), &B, nullptr, &s.x, nullptr, &s.y, &s.e, &s.common);
  POLYCUBE_ASSERT(ok && s.x, "CHOLMOD solve failed");
  return Eigen::Map<const Eigen::VectorXd>(static_cast<const double*>(s.x->x), b.size());
}

Eigen::VectorXd SparseSystem::precondition(const Eigen::VectorXd& b, int slot) const {
  if (float_factor_.empty()) return solve(b, slot);
  POLYCUBE_ASSERT(slot >= 0 && slot < kSlots && float_factor_.size() == b.size(), "bad preconditioner call");
  Eigen::VectorXd x(b.size());
  float_factor_.solve(b.data(), x.data(), slots_[slot].work);
  return x;
}

Eigen::VectorXd SparseSystem::multiply(const Eigen::VectorXd& x) const {
  Eigen::VectorXd y = Eigen::VectorXd::Zero(x.size());
  const int* outer = A_.outerIndexPtr();
  const int* inner = A_.innerIndexPtr();
  for (int c = 0; c < 3 * n_; ++c) {
    double acc = 0;
    const double xc = x[c];
    for (int k = outer[c]; k < outer[c + 1]; ++k) {
      const int r = inner[k];
      const double v = values_[k];
      acc += v * x[r];
      if (r != c) y[r] += v * xc;
    }
    y[c] += acc;
  }
  return y;
}

namespace {

// Preconditioned conjugate gradients on `count` (1 or 2) independent systems in lockstep, so that
// one preconditioner application P(in, out) can serve both. Per system: x = P b; stop when the
// residual falls below tol relative to b in the 2-norm, or in the preconditioner's energy norm
// (r.P^-1 r against b.P^-1 b). Returns per system the preconditioner applications used, or -1.
// `parallel`: the two products with the matrix on two threads.
template <class Multiply, class Precondition>
std::array<int, 2> lockstep_pcg(int count, const std::array<const Eigen::VectorXd*, 2>& b,
                                const std::array<Eigen::VectorXd*, 2>& x, double tol, int max_iter, bool parallel,
                                Multiply&& multiply, Precondition&& precondition) {
  std::array<int, 2> its{-1, -1};
  std::array<Eigen::VectorXd, 2> r, z, p, Ap;
  std::array<double, 2> bn{}, rz{}, bz{};
  std::array<bool, 2> active{};
  auto each = [&](auto&& f) {
    if (parallel && count == 2) {
      run_pair(f);
    } else {
      for (int k = 0; k < count; ++k) f(k);
    }
  };
  precondition(b, x);
  each([&](int k) { r[k] = *b[k] - multiply(*x[k]); });
  for (int k = 0; k < count; ++k) {
    bn[k] = b[k]->norm();
    active[k] = !(bn[k] == 0 || r[k].norm() <= tol * bn[k]);
    its[k] = active[k] ? -1 : 1;
    z[k].resize(r[k].size());
  }
  if (!active[0] && !active[1]) return its;
  precondition({&r[0], &r[1]}, {&z[0], &z[1]});
  for (int k = 0; k < count; ++k) {
    p[k] = z[k];
    rz[k] = r[k].dot(z[k]);
    bz[k] = b[k]->dot(*x[k]);
    if (active[k] && rz[k] <= tol * tol * bz[k]) {
      its[k] = 2;
      active[k] = false;
    }
  }
  for (int it = 1; it <= max_iter && (active[0] || active[1]); ++it) {
    each([&](int k) {
      if (active[k]) Ap[k] = multiply(p[k]);
    });
    for (int k = 0; k < count; ++k) {
      if (!active[k]) continue;
      const double pAp = p[k].dot(Ap[k]);
      if (!(pAp > 0)) {
        active[k] = false;  // its[k] stays -1
        continue;
      }
      const double a = rz[k] / pAp;
      *x[k] += a * p[k];
      r[k] -= a * Ap[k];
      if (r[k].norm() <= tol * bn[k]) {
        its[k] = it + 1;
        active[k] = false;
      }
    }
    if (!active[0] && !active[1]) break;
    precondition({&r[0], &r[1]}, {&z[0], &z[1]});
    for (int k = 0; k < count; ++k) {
      if (!active[k]) continue;
      const double rz_new = r[k].dot(z[k]);
      if (rz_new <= tol * tol * bz[k]) {
        its[k] = it + 2;
        active[k] = false;
        continue;
      }
      p[k] = z[k] + (rz_new / rz[k]) * p[k];
      rz[k] = rz_new;
    }
  }
  return its;
}

}  // namespace

int SparseSystem::solve_pcg(const Eigen::VectorXd& b, Eigen::VectorXd& x, double tol, int max_iter,
                            int slot) const {
  auto mul = [&](const Eigen::VectorXd& v) { return multiply(v); };
  auto pre = [&](const std::array<const Eigen::VectorXd*, 2>& in, const std::array<Eigen::VectorXd*, 2>& out) {
    *out[0] = precondition(*in[0], slot);
  };
  return lockstep_pcg(1, {&b, nullptr}, {&x, nullptr}, tol, max_iter, false, mul, pre)[0];
}

std::array<int, 2> SparseSystem::solve_pcg_pair(const Eigen::VectorXd& b0, Eigen::VectorXd& x0,
                                                const Eigen::VectorXd& b1, Eigen::VectorXd& x1, double tol,
                                                int max_iter) const {
  std::array<int, 2> its{};
  if (float_factor_.empty()) {
    run_pair([&](int k) { its[k] = solve_pcg(k == 0 ? b0 : b1, k == 0 ? x0 : x1, tol, max_iter, k); });
    return its;
  }
  // Both systems in lockstep, so that each preconditioner application serves the two (the float
  // factor is read once, by two threads over their own subtrees).
  auto mul = [&](const Eigen::VectorXd& v) { return multiply(v); };
  auto pre = [&](const std::array<const Eigen::VectorXd*, 2>& in, const std::array<Eigen::VectorXd*, 2>& out) {
    for (int k = 0; k < 2; ++k) out[k]->resize(in[k]->size());
    float_factor_.solve2(in[0]->data(), in[1]->data(), out[0]->data(), out[1]->data(), slots_[0].work);
  };
  return lockstep_pcg(2, {&b0, &b1}, {&x0, &x1}, tol, max_iter, float_factor_.parallel(), mul, pre);
}

void SparseSystem::solve_pair(const Eigen::VectorXd& b0, Eigen::VectorXd& x0, const Eigen::VectorXd& b1,
                              Eigen::VectorXd& x1) {
  if (float_only_) {
    // CG on the float factor of these very values: a few iterations to 1e-3 (the SQP direction
    // needs no more; the reused factors' solves stop at 1e-2).
    const auto its = solve_pcg_pair(b0, x0, b1, x1, kRefineTolerance, 50);
    if (its[0] > 0 && its[1] > 0) {
      refinement_iterations_ += std::max(its[0], its[1]);
      return;
    }
    // Not converged (the float factor too far from the matrix): the double factorization.
    const bool factorized = factorize_double();  // (positive definite in float: it does not fail)
    POLYCUBE_ASSERT(factorized, "the double factorization failed after the float one succeeded");
  }
  run_pair([&](int k) { (k == 0 ? x0 : x1) = solve(k == 0 ? b0 : b1, k); });
}

}  // namespace polycube::deform
