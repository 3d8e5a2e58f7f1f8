#include "polycube/deform/float_factor.h"

#include <algorithm>

namespace polycube::deform {

namespace {

// The kernels are compiled for AVX2 as well as the baseline, the right one chosen at load time
// (GCC function multiversioning), so that the release build stays portable.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define POLYCUBE_MULTIVERSION __attribute__((target_clones("avx2", "default")))
#else
#define POLYCUBE_MULTIVERSION
#endif

// The helpers below are always inlined, so the ABI note on returning a 32-byte vector without AVX
// does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"

// Eight floats (one AVX register, two SSE ones in the baseline clone), unaligned loads and stores.
typedef float v8f __attribute__((vector_size(32)));

inline __attribute__((always_inline)) v8f load8(const float* p) {
  v8f v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}

inline __attribute__((always_inline)) void store8(float* p, v8f v) { __builtin_memcpy(p, &v, sizeof v); }

inline __attribute__((always_inline)) void axpy(float* __restrict y, const float* __restrict x, float a, int n) {
  int i = 0;
  const v8f va = {a, a, a, a, a, a, a, a};
  for (; i + 8 <= n; i += 8) store8(y + i, load8(y + i) + va * load8(x + i));
  for (; i < n; ++i) y[i] += a * x[i];
}

inline __attribute__((always_inline)) float dot(const float* __restrict x, const float* __restrict y, int n) {
  v8f acc = {0, 0, 0, 0, 0, 0, 0, 0};
  int i = 0;
  for (; i + 8 <= n; i += 8) acc += load8(x + i) * load8(y + i);
  float s = 0;
  for (; i < n; ++i) s += x[i] * y[i];
  return s + ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
}

// L y = y (permuted vector), supernode by supernode: the supernode's rows are gathered into t,
// solved against its dense lower-trapezoidal block column by column, and scattered back.
POLYCUBE_MULTIVERSION
void forward(int nsuper, const int* super, const int* pi, const int* px, const int* srows, const float* X,
             const float* dinv, float* y, float* t) {
  for (int s = 0; s < nsuper; ++s) {
    const int k1 = super[s], nscol = super[s + 1] - k1;
    const int psi = pi[s], nsrow = pi[s + 1] - psi;
    const float* L = X + px[s];
    const int* rows = srows + psi;
    for (int i = 0; i < nscol; ++i) t[i] = y[k1 + i];
    std::fill(t + nscol, t + nsrow, 0.0f);
    for (int j = 0; j < nscol; ++j) {
      const float tj = t[j] * dinv[k1 + j];
      t[j] = tj;
      axpy(t + j + 1, L + static_cast<long>(j) * nsrow + j + 1, -tj, nsrow - j - 1);
    }
    for (int i = 0; i < nscol; ++i) y[k1 + i] = t[i];
    for (int i = nscol; i < nsrow; ++i) y[rows[i]] += t[i];
  }
}

// L^T y = y, supernodes in reverse order.
POLYCUBE_MULTIVERSION
void backward(int nsuper, const int* super, const int* pi, const int* px, const int* srows, const float* X,
              const float* dinv, float* y, float* t) {
  for (int s = nsuper - 1; s >= 0; --s) {
    const int k1 = super[s], nscol = super[s + 1] - k1;
    const int psi = pi[s], nsrow = pi[s + 1] - psi;
    const float* L = X + px[s];
    const int* rows = srows + psi;
    for (int i = 0; i < nsrow; ++i) t[i] = y[rows[i]];
    for (int j = nscol - 1; j >= 0; --j) {
      const float* col = L + static_cast<long>(j) * nsrow;
      t[j] = (t[j] - dot(col + j + 1, t + j + 1, nsrow - j - 1)) * dinv[k1 + j];
    }
    for (int i = 0; i < nscol; ++i) y[k1 + i] = t[i];
  }
}

}  // namespace

bool FloatFactor::assign(const cholmod_factor* L) {
  n_ = 0;
  if (!L || !L->is_super || !L->is_ll || L->itype != CHOLMOD_INT || L->xtype != CHOLMOD_REAL ||
      L->dtype != CHOLMOD_DOUBLE || !L->x)
    return false;
  const int n = static_cast<int>(L->n), nsuper = static_cast<int>(L->nsuper);
  const int* super = static_cast<const int*>(L->super);
  const int* pi = static_cast<const int*>(L->pi);
  const int* px = static_cast<const int*>(L->px);
  const int* srows = static_cast<const int*>(L->s);
  const int* perm = static_cast<const int*>(L->Perm);
  super_.assign(super, super + nsuper + 1);
  pi_.assign(pi, pi + nsuper + 1);
  px_.assign(px, px + nsuper + 1);
  s_.assign(srows, srows + pi[nsuper]);
  if (perm)
    perm_.assign(perm, perm + n);
  else {
    perm_.resize(n);
    for (int i = 0; i < n; ++i) perm_[i] = i;
  }
  const double* x = static_cast<const double*>(L->x);
  x_.resize(static_cast<size_t>(px[nsuper]));
  std::transform(x, x + px[nsuper], x_.begin(), [](double v) { return static_cast<float>(v); });
  dinv_.resize(n);
  for (int s = 0; s < nsuper; ++s) {
    const int nsrow = pi[s + 1] - pi[s];
    for (int j = 0; j < super[s + 1] - super[s]; ++j)
      dinv_[super[s] + j] = static_cast<float>(1.0 / x[px[s] + static_cast<long>(j) * nsrow + j]);
  }
  max_rows_ = 0;
  for (int s = 0; s < nsuper; ++s) max_rows_ = std::max(max_rows_, pi[s + 1] - pi[s]);
  nsuper_ = nsuper;
  n_ = n;
  return true;
}

void FloatFactor::solve(const double* b, double* x, std::vector<float>& work) const {
  work.resize(static_cast<size_t>(n_) + max_rows_);
  float* y = work.data();
  float* t = y + n_;
  for (int k = 0; k < n_; ++k) y[k] = static_cast<float>(b[perm_[k]]);
  forward(nsuper_, super_.data(), pi_.data(), px_.data(), s_.data(), x_.data(), dinv_.data(), y, t);
  backward(nsuper_, super_.data(), pi_.data(), px_.data(), s_.data(), x_.data(), dinv_.data(), y, t);
  for (int k = 0; k < n_; ++k) x[perm_[k]] = y[k];
}

}  // namespace polycube::deform
