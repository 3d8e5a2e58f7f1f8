#include "polycube/deform/float_factor.h"

#include <algorithm>

#include "polycube/core/memory.h"
#include "polycube/core/parallel.h"

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

inline __attribute__((always_inline)) float hsum(v8f a) {
  return ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7]));
}

inline __attribute__((always_inline)) void axpy2(float* __restrict y0, float* __restrict y1, const float* __restrict x,
                                                 float a0, float a1, int n) {
  int i = 0;
  const v8f va0 = {a0, a0, a0, a0, a0, a0, a0, a0}, va1 = {a1, a1, a1, a1, a1, a1, a1, a1};
  for (; i + 8 <= n; i += 8) {
    const v8f xi = load8(x + i);
    store8(y0 + i, load8(y0 + i) + va0 * xi);
    store8(y1 + i, load8(y1 + i) + va1 * xi);
  }
  for (; i < n; ++i) {
    y0[i] += a0 * x[i];
    y1[i] += a1 * x[i];
  }
}

// x dotted with y0 and with y1, two accumulators of eight lanes each (the additions' latency, not
// the loads, bounds one chain).
inline __attribute__((always_inline)) void dot2(const float* __restrict x, const float* __restrict y0,
                                                const float* __restrict y1, int n, float& d0, float& d1) {
  v8f a0 = {0, 0, 0, 0, 0, 0, 0, 0}, b0 = a0, a1 = a0, b1 = a0;
  int i = 0;
  for (; i + 16 <= n; i += 16) {
    const v8f xa = load8(x + i), xb = load8(x + i + 8);
    a0 += xa * load8(y0 + i);
    b0 += xb * load8(y0 + i + 8);
    a1 += xa * load8(y1 + i);
    b1 += xb * load8(y1 + i + 8);
  }
  if (i + 8 <= n) {
    const v8f xa = load8(x + i);
    a0 += xa * load8(y0 + i);
    a1 += xa * load8(y1 + i);
    i += 8;
  }
  float s0 = 0, s1 = 0;
  for (; i < n; ++i) {
    s0 += x[i] * y0[i];
    s1 += x[i] * y1[i];
  }
  d0 = s0 + hsum(a0 + b0);
  d1 = s1 + hsum(a1 + b1);
}

// Four columns (x, x + ld, x + 2 ld, x + 3 ld) dotted with y0 and y1: d[c] and d[4 + c]. One load
// of y0 and y1 serves four columns, and eight independent chains hide the additions' latency.
inline __attribute__((always_inline)) void dot4x2(const float* __restrict x, int ld, const float* __restrict y0,
                                                  const float* __restrict y1, int n, float* d) {
  const v8f z = {0, 0, 0, 0, 0, 0, 0, 0};
  v8f a[4] = {z, z, z, z}, b[4] = {z, z, z, z};
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    const v8f u = load8(y0 + i), w = load8(y1 + i);
    for (int c = 0; c < 4; ++c) {
      const v8f xc = load8(x + static_cast<long>(c) * ld + i);
      a[c] += xc * u;
      b[c] += xc * w;
    }
  }
  for (int c = 0; c < 4; ++c) {
    float s0 = 0, s1 = 0;
    for (int k = i; k < n; ++k) {
      s0 += x[static_cast<long>(c) * ld + k] * y0[k];
      s1 += x[static_cast<long>(c) * ld + k] * y1[k];
    }
    d[c] = s0 + hsum(a[c]);
    d[4 + c] = s1 + hsum(b[c]);
  }
}

// Four columns (x, x + n, x + 2 n, x + 3 n, one contiguous block) times a0[0..4) and a1[0..4),
// subtracted from y0 and y1: one load and store of y0 and y1 serves four columns.
inline __attribute__((always_inline)) void axpy4x2(float* __restrict y0, float* __restrict y1, const float* __restrict x,
                                                   const float* a0, const float* a1, int n) {
  const float b00 = a0[0], b01 = a0[1], b02 = a0[2], b03 = a0[3];
  const float b10 = a1[0], b11 = a1[1], b12 = a1[2], b13 = a1[3];
  const long n2 = 2L * n, n3 = 3L * n;
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    const v8f x0 = load8(x + i), x1 = load8(x + n + i), x2 = load8(x + n2 + i), x3 = load8(x + n3 + i);
    v8f u = load8(y0 + i), w = load8(y1 + i);
    u -= b00 * x0;
    w -= b10 * x0;
    u -= b01 * x1;
    w -= b11 * x1;
    u -= b02 * x2;
    w -= b12 * x2;
    u -= b03 * x3;
    w -= b13 * x3;
    store8(y0 + i, u);
    store8(y1 + i, w);
  }
  for (; i < n; ++i) {
    float u = y0[i], w = y1[i];
    for (int c = 0; c < 4; ++c) {
      u -= a0[c] * x[static_cast<long>(c) * n + i];
      w -= a1[c] * x[static_cast<long>(c) * n + i];
    }
    y0[i] = u;
    y1[i] = w;
  }
}

// The float copy's layout (see FloatFactor::assign): per supernode of nscol columns and nsrow rows,
// first the rows below the diagonal block (m = nsrow - nscol rows, column-major, leading dimension
// m), then the strictly lower triangle of the diagonal block, packed by columns (column j: rows
// j + 1 .. nscol - 1). Both sweeps then read each part front to back: the prefetchers see one
// stream per part instead of one per column, and the diagonal block's unused upper half is not
// stored.
inline long tri_offset(int nscol, int j) { return static_cast<long>(j) * (nscol - 1) - static_cast<long>(j) * (j - 1) / 2; }

// Supernode s of the float copy: its first column k1, its nscol columns, the m rows below its
// diagonal block (indices `rows`), the block of those rows R and the packed triangle T.
struct Supernode {
  int k1, nscol, m;
  const float* R;
  const float* T;
  const int* rows;
};
inline __attribute__((always_inline)) Supernode supernode(int s, const int* super, const int* pi, const long* off,
                                                          const int* srows, const float* X) {
  Supernode n;
  n.k1 = super[s];
  n.nscol = super[s + 1] - n.k1;
  n.m = pi[s + 1] - pi[s] - n.nscol;
  n.R = X + off[s];
  n.T = n.R + static_cast<long>(n.m) * n.nscol;
  n.rows = srows + pi[s] + n.nscol;
  return n;
}

// L y = y (permuted vectors) over a range of supernodes, for two right-hand sides at once (the
// factor is read once for both: the sweeps are bound by memory access): each supernode's diagonal
// block is solved column by column, then its rows below are updated four columns at a time and
// scattered back. `owner` gives, per column, the part it belongs to; the sweep of part `part` adds
// its updates of other parts' rows (its ancestors, always in the top part) into `extra` instead of
// y when extra is given.
POLYCUBE_MULTIVERSION
void forward2(int s_begin, int s_end, const int* super, const int* pi, const long* off, const int* srows,
              const float* X, const float* dinv, float* y0, float* y1, float* t0, float* t1, const signed char* owner,
              int part, float* extra0, float* extra1) {
  for (int s = s_begin; s < s_end; ++s) {
    const auto [k1, nscol, m, R, T, rows] = supernode(s, super, pi, off, srows, X);
    float* u0 = t0 + nscol;
    float* u1 = t1 + nscol;
    for (int i = 0; i < nscol; ++i) {
      t0[i] = y0[k1 + i];
      t1[i] = y1[k1 + i];
    }
    for (int j = 0; j < nscol; ++j) {
      const float a0 = t0[j] * dinv[k1 + j], a1 = t1[j] * dinv[k1 + j];
      t0[j] = a0;
      t1[j] = a1;
      axpy2(t0 + j + 1, t1 + j + 1, T + tri_offset(nscol, j), -a0, -a1, nscol - j - 1);
    }
    for (int i = 0; i < nscol; ++i) {
      y0[k1 + i] = t0[i];
      y1[k1 + i] = t1[i];
    }
    if (m == 0) continue;
    std::fill(u0, u0 + m, 0.0f);
    std::fill(u1, u1 + m, 0.0f);
    int j = 0;
    for (; j + 4 <= nscol; j += 4) axpy4x2(u0, u1, R + static_cast<long>(j) * m, t0 + j, t1 + j, m);
    for (; j < nscol; ++j) axpy2(u0, u1, R + static_cast<long>(j) * m, -t0[j], -t1[j], m);
    for (int i = 0; i < m; ++i) {
      const int r = rows[i];
      if (extra0 && owner[r] != part) {
        extra0[r] += u0[i];
        extra1[r] += u1[i];
      } else {
        y0[r] += u0[i];
        y1[r] += u1[i];
      }
    }
  }
}

// L^T y = y over a range of supernodes in reverse order, two right-hand sides: the rows below each
// diagonal block first, four columns at a time, then the triangle of the diagonal block backwards.
POLYCUBE_MULTIVERSION
void backward2(int s_begin, int s_end, const int* super, const int* pi, const long* off, const int* srows,
               const float* X, const float* dinv, float* y0, float* y1, float* t0, float* t1) {
  for (int s = s_end - 1; s >= s_begin; --s) {
    const auto [k1, nscol, m, R, T, rows] = supernode(s, super, pi, off, srows, X);
    float* g0 = t0 + nscol;
    float* g1 = t1 + nscol;
    for (int i = 0; i < nscol; ++i) {
      t0[i] = y0[k1 + i];
      t1[i] = y1[k1 + i];
    }
    for (int i = 0; i < m; ++i) {
      g0[i] = y0[rows[i]];
      g1[i] = y1[rows[i]];
    }
    float d0, d1;
    int j = 0;
    if (m > 0) {
      for (; j + 4 <= nscol; j += 4) {
        float d[8];
        dot4x2(R + static_cast<long>(j) * m, m, g0, g1, m, d);
        for (int c = 0; c < 4; ++c) {
          t0[j + c] -= d[c];
          t1[j + c] -= d[4 + c];
        }
      }
      for (; j < nscol; ++j) {
        dot2(R + static_cast<long>(j) * m, g0, g1, m, d0, d1);
        t0[j] -= d0;
        t1[j] -= d1;
      }
    }
    for (int j = nscol - 1; j >= 0; --j) {
      dot2(T + tri_offset(nscol, j), t0 + j + 1, t1 + j + 1, nscol - j - 1, d0, d1);
      t0[j] = (t0[j] - d0) * dinv[k1 + j];
      t1[j] = (t1[j] - d1) * dinv[k1 + j];
    }
    for (int i = 0; i < nscol; ++i) {
      y0[k1 + i] = t0[i];
      y1[k1 + i] = t1[i];
    }
  }
}

}  // namespace

void FloatFactor::set_structure(const cholmod_factor* L) {
  const int n = static_cast<int>(L->n), nsuper = static_cast<int>(L->nsuper);
  const int* super = static_cast<const int*>(L->super);
  const int* pi = static_cast<const int*>(L->pi);
  const int* srows = static_cast<const int*>(L->s);
  const int* perm = static_cast<const int*>(L->Perm);
  super_.assign(super, super + nsuper + 1);
  pi_.assign(pi, pi + nsuper + 1);
  s_.assign(srows, srows + pi[nsuper]);
  if (perm)
    perm_.assign(perm, perm + n);
  else {
    perm_.resize(n);
    for (int i = 0; i < n; ++i) perm_[i] = i;
  }
  off_.resize(nsuper + 1);
  off_[0] = 0;
  for (int s = 0; s < nsuper; ++s) {
    const long nscol = super[s + 1] - super[s], nsrow = pi[s + 1] - pi[s];
    off_[s + 1] = off_[s] + (nsrow - nscol) * nscol + nscol * (nscol - 1) / 2;
  }
  const size_t entries = static_cast<size_t>(off_[nsuper]);
  if (x_.capacity() < entries) {
    // In huge pages where the system has them (memory.h): written first here, the block is kept
    // for the run (fandisk, 9.0M entries: the first copy took 0.10 s against 0.011 s later).
    std::vector<float>().swap(x_);
    x_.reserve(entries);
    advise_huge_pages(x_.data(), entries * sizeof(float));
  }
  x_.resize(entries);
  dinv_.resize(n);
  max_rows_ = 0;
  for (int s = 0; s < nsuper; ++s) max_rows_ = std::max(max_rows_, pi[s + 1] - pi[s]);
  nsuper_ = nsuper;
}

bool FloatFactor::assign(const cholmod_factor* L) {
  n_ = 0;
  if (!L || !L->is_super || !L->is_ll || L->itype != CHOLMOD_INT || L->xtype != CHOLMOD_REAL ||
      L->dtype != CHOLMOD_DOUBLE || !L->x)
    return false;
  const int n = static_cast<int>(L->n), nsuper = static_cast<int>(L->nsuper);
  const int* super = static_cast<const int*>(L->super);
  const int* pi = static_cast<const int*>(L->pi);
  const int* px = static_cast<const int*>(L->px);
  if (L != analyzed_for_) a_dest_.clear();  // another factor: analyze() again before factorize()
  set_structure(L);
  const double* x = static_cast<const double*>(L->x);
  for (int s = 0; s < nsuper; ++s) {
    const int nscol = super[s + 1] - super[s], nsrow = pi[s + 1] - pi[s], m = nsrow - nscol;
    const double* Ls = x + px[s];
    float* R = x_.data() + off_[s];
    float* T = R + static_cast<long>(m) * nscol;
    for (int j = 0; j < nscol; ++j) {
      const double* col = Ls + static_cast<long>(j) * nsrow;
      dinv_[super[s] + j] = static_cast<float>(1.0 / col[j]);
      std::transform(col + j + 1, col + nscol, T + tri_offset(nscol, j), [](double v) { return static_cast<float>(v); });
      std::transform(col + nscol, col + nsrow, R + static_cast<long>(j) * m, [](double v) { return static_cast<float>(v); });
    }
  }
  n_ = n;
  partition();
  return true;
}

}  // namespace polycube::deform

// The BLAS and LAPACK kernels of the float factorization (Fortran interface).
extern "C" {
void ssyrk_(const char* uplo, const char* trans, const int* n, const int* k, const float* alpha, const float* a,
            const int* lda, const float* beta, float* c, const int* ldc);
void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k, const float* alpha,
            const float* a, const int* lda, const float* b, const int* ldb, const float* beta, float* c,
            const int* ldc);
void spotrf_(const char* uplo, const int* n, float* a, const int* lda, int* info);
void strsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m, const int* n,
            const float* alpha, const float* a, const int* lda, float* b, const int* ldb);
}

namespace polycube::deform {

bool FloatFactor::analyze(const cholmod_factor* L, const int* Ap, const int* Ai) {
  n_ = 0;
  a_dest_.clear();
  if (!L || !L->is_super || L->itype != CHOLMOD_INT || !L->super || !L->pi || !L->s) return false;
  set_structure(L);
  const int n = static_cast<int>(L->n);
  analyzed_for_ = L;
  col_super_.resize(n);
  for (int s = 0; s < nsuper_; ++s)
    for (int k = super_[s]; k < super_[s + 1]; ++k) col_super_[k] = s;
  std::vector<int> pinv(n);
  for (int k = 0; k < n; ++k) pinv[perm_[k]] = k;
  a_dest_.resize(static_cast<size_t>(Ap[n]));
  for (int j = 0; j < n; ++j)
    for (int p = Ap[j]; p < Ap[j + 1]; ++p) {
      const int a = pinv[Ai[p]], b = pinv[j];
      const int c = std::min(a, b), r = std::max(a, b);
      const int s = col_super_[c];
      const int k1 = super_[s], nscol = super_[s + 1] - k1, nsrow = pi_[s + 1] - pi_[s], m = nsrow - nscol;
      const int jc = c - k1;
      if (r < super_[s + 1]) {  // in the diagonal block
        const int ir = r - k1;
        a_dest_[p] = ir == jc ? -1L - c : off_[s] + static_cast<long>(m) * nscol + tri_offset(nscol, jc) + (ir - jc - 1);
      } else {
        const int* rows = s_.data() + pi_[s] + nscol;
        const int ir = static_cast<int>(std::lower_bound(rows, rows + m, r) - rows);
        if (ir >= m || rows[ir] != r) {  // not in the factor's pattern: not this matrix's analysis
          a_dest_.clear();
          return false;
        }
        a_dest_[p] = off_[s] + ir + static_cast<long>(jc) * m;
      }
    }
  n_ = n;  // (partition() reads it)
  partition();
  n_ = 0;  // nothing to solve with before factorize()
  return true;
}

bool FloatFactor::factorize(const double* Ax, double shift) {
  n_ = 0;
  if (a_dest_.empty()) return false;
  const int n = static_cast<int>(perm_.size());
  std::fill(x_.begin(), x_.end(), 0.0f);
  std::fill(dinv_.begin(), dinv_.end(), 0.0f);
  for (size_t p = 0; p < a_dest_.size(); ++p) {
    const long d = a_dest_[p];
    if (d >= 0)
      x_[static_cast<size_t>(d)] += static_cast<float>(Ax[p]);
    else
      dinv_[static_cast<size_t>(-1 - d)] += static_cast<float>(Ax[p] + shift);  // the diagonal, for now
  }
  // Left-looking: supernode s gathers the updates of its descendants d (the supernodes whose rows
  // below their diagonal block reach s's columns), listed in head[t][s] / next[d] (t: the thread
  // that factorized d); lpos[d] is the first of d's rows not yet used. The subtrees of partition()
  // are factorized on two threads (their descendants are their own), each with a one-thread BLAS,
  // then the top part on this thread with the BLAS's threads.
  std::array<std::vector<int>, 2> head;
  for (auto& h : head) h.assign(nsuper_, -1);
  std::vector<int> next(nsuper_, -1), lpos(nsuper_, 0);
  struct Scratch {
    std::vector<int> map;
    std::vector<float> D, C;
  };
  std::array<Scratch, 2> scratch;
  const float one = 1.0f, zero = 0.0f;
  const char L = 'L', N = 'N', T = 'T', R = 'R';
  // Factorizes supernode s on thread t; false if a pivot is not positive.
  auto supernode_step = [&](int s, int t) {
    Scratch& w = scratch[t];
    if (w.map.empty()) w.map.assign(n, 0);
    const int k1 = super_[s], k2 = super_[s + 1], nscol = k2 - k1, nsrow = pi_[s + 1] - pi_[s], m = nsrow - nscol;
    const int* rows = s_.data() + pi_[s];
    for (int k = 0; k < nsrow; ++k) w.map[rows[k]] = k;
    float* Rs = x_.data() + off_[s];
    float* Ts = Rs + static_cast<long>(m) * nscol;
    std::vector<float>& D = w.D;
    D.assign(static_cast<size_t>(nscol) * nscol, 0.0f);
    for (int j = 0; j < nscol; ++j) {
      D[static_cast<size_t>(j) * nscol + j] = dinv_[k1 + j];
      for (int i = j + 1; i < nscol; ++i) D[static_cast<size_t>(j) * nscol + i] = Ts[tri_offset(nscol, j) + (i - j - 1)];
    }
    for (int list = 0; list < 2; ++list) {
      for (int d = head[list][s]; d >= 0;) {
        const int dnext = next[d];
        const int nd = super_[d + 1] - super_[d], md = pi_[d + 1] - pi_[d] - nd;
        const int* drows = s_.data() + pi_[d] + nd;
        const int p1 = lpos[d];
        int p2 = p1;
        while (p2 < md && drows[p2] < k2) ++p2;
        const int n1 = p2 - p1, n2 = md - p1, n3 = n2 - n1;
        const float* Ad = x_.data() + off_[d] + p1;  // rows p1.. of d's block below its diagonal, ld md
        w.C.resize(static_cast<size_t>(n2) * n1);
        float* C = w.C.data();
        ssyrk_(&L, &N, &n1, &nd, &one, Ad, &md, &zero, C, &n2);
        if (n3 > 0) sgemm_(&N, &T, &n3, &n1, &nd, &one, Ad + n1, &md, Ad, &md, &zero, C + n1, &n2);
        for (int jj = 0; jj < n1; ++jj) {
          const int col = drows[p1 + jj] - k1;
          const float* c = C + static_cast<size_t>(jj) * n2;
          float* Dc = D.data() + static_cast<size_t>(col) * nscol - k1;
          for (int ii = jj; ii < n1; ++ii) Dc[drows[p1 + ii]] -= c[ii];
          float* Rc = Rs + static_cast<long>(col) * m - nscol;
          for (int ii = n1; ii < n2; ++ii) Rc[w.map[drows[p1 + ii]]] -= c[ii];
        }
        lpos[d] = p2;
        if (p2 < md) {
          const int a = col_super_[drows[p2]];
          next[d] = head[t][a];
          head[t][a] = d;
        }
        d = dnext;
      }
      head[list][s] = -1;
    }
    int info = 0;
    spotrf_(&L, &nscol, D.data(), &nscol, &info);
    if (info != 0) return false;
    if (m > 0) strsm_(&R, &L, &T, &N, &m, &nscol, &one, D.data(), &nscol, Rs, &m);
    for (int j = 0; j < nscol; ++j) {
      dinv_[k1 + j] = 1.0f / D[static_cast<size_t>(j) * nscol + j];
      for (int i = j + 1; i < nscol; ++i) Ts[tri_offset(nscol, j) + (i - j - 1)] = D[static_cast<size_t>(j) * nscol + i];
    }
    if (m > 0) {
      lpos[s] = 0;
      const int a = col_super_[rows[nscol]];
      next[s] = head[t][a];
      head[t][a] = s;
    }
    return true;
  };
  std::array<bool, 2> ok{true, true};
  if (parallel()) {
    run_pair([&](int t) {
      for (const auto& r : ranges_[t])
        for (int s = r[0]; s < r[1] && ok[t]; ++s) ok[t] = supernode_step(s, t);
    });
    if (!ok[0] || !ok[1]) return false;
    for (const auto& r : top_ranges_)
      for (int s = r[0]; s < r[1]; ++s)
        if (!supernode_step(s, 0)) return false;
  } else {
    for (int s = 0; s < nsuper_; ++s)
      if (!supernode_step(s, 0)) return false;
  }
  n_ = n;
  return true;
}

// Splits the supernodal elimination tree for two threads: a top part (processed by one thread,
// after the rest in the forward sweep and before it in the backward one) and independent subtrees
// dealt to the two threads. The supernodes are in postorder (CHOLMOD's default), so a subtree is a
// contiguous range ending at its root. Starting from the roots, the heaviest subtree is moved to
// the top part (its children become subtrees) as long as that lowers the estimated time, the top's
// work plus the larger thread's (work = entries of the factor read).
void FloatFactor::partition() {
  const int ns = nsuper_;
  std::vector<int> col_super(n_), parent(ns, -1), first(ns);
  std::vector<double> work(ns), subtree(ns);
  for (int s = 0; s < ns; ++s) {
    for (int k = super_[s]; k < super_[s + 1]; ++k) col_super[k] = s;
    first[s] = s;
    const int nscol = super_[s + 1] - super_[s], nsrow = pi_[s + 1] - pi_[s];
    work[s] = subtree[s] = static_cast<double>(nscol) * nsrow;
  }
  std::vector<std::vector<int>> children(ns);
  std::vector<int> roots;
  for (int s = 0; s < ns; ++s) {
    const int nscol = super_[s + 1] - super_[s], nsrow = pi_[s + 1] - pi_[s];
    if (nsrow > nscol) parent[s] = col_super[s_[pi_[s] + nscol]];
    if (parent[s] >= 0) {
      children[parent[s]].push_back(s);
      subtree[parent[s]] += subtree[s];
      first[parent[s]] = std::min(first[parent[s]], first[s]);
    } else {
      roots.push_back(s);
    }
  }
  // Greedy dealing (largest first, to the lighter thread) of a set of subtrees.
  auto deal = [&](std::vector<int> set, std::vector<int>* bin0, std::vector<int>* bin1) {
    std::sort(set.begin(), set.end(), [&](int a, int b) { return subtree[a] > subtree[b] || (subtree[a] == subtree[b] && a < b); });
    double w0 = 0, w1 = 0;
    for (int r : set) {
      if (w0 <= w1) {
        w0 += subtree[r];
        if (bin0) bin0->push_back(r);
      } else {
        w1 += subtree[r];
        if (bin1) bin1->push_back(r);
      }
    }
    return std::max(w0, w1);
  };
  std::vector<int> set = roots, top, best_set = roots, best_top;
  double top_work = 0, best = deal(set, nullptr, nullptr);
  for (int round = 0; round < 256 && !set.empty(); ++round) {
    const auto h = std::max_element(set.begin(), set.end(), [&](int a, int b) { return subtree[a] < subtree[b]; });
    const int r = *h;
    set.erase(h);
    top.push_back(r);
    top_work += work[r];
    set.insert(set.end(), children[r].begin(), children[r].end());
    const double cost = top_work + deal(set, nullptr, nullptr);
    if (cost < best) {
      best = cost;
      best_set = set;
      best_top = top;
    }
  }
  std::vector<int> bins[2];
  deal(best_set, &bins[0], &bins[1]);
  owner_.assign(n_, 2);
  for (int t = 0; t < 2; ++t) {
    ranges_[t].clear();
    std::sort(bins[t].begin(), bins[t].end());
    for (int r : bins[t]) {
      ranges_[t].push_back({first[r], r + 1});
      for (int k = super_[first[r]]; k < super_[r + 1]; ++k) owner_[k] = static_cast<signed char>(t);
    }
  }
  // The top part as ranges of consecutive supernodes, in increasing order.
  std::sort(best_top.begin(), best_top.end());
  top_ranges_.clear();
  for (int r : best_top) {
    if (!top_ranges_.empty() && top_ranges_.back()[1] == r)
      top_ranges_.back()[1] = r + 1;
    else
      top_ranges_.push_back({r, r + 1});
  }
}

void FloatFactor::solve2(const double* b0, const double* b1, double* x0, double* x1, std::vector<float>& work) const {
  const size_t n = static_cast<size_t>(n_), m = static_cast<size_t>(max_rows_);
  work.resize(4 * n + 4 * m);
  float* y0 = work.data();
  float* y1 = y0 + n;
  float* e0 = y1 + n;  // thread 1's updates of the top part's rows (forward sweep)
  float* e1 = e0 + n;
  std::fill(e0, e1 + n, 0.0f);
  float* t[2][2] = {{e1 + n, e1 + n + m}, {e1 + n + 2 * m, e1 + n + 3 * m}};
  for (size_t k = 0; k < n; ++k) {
    y0[k] = static_cast<float>(b0[perm_[k]]);
    y1[k] = static_cast<float>(b1[perm_[k]]);
  }
  const int* sup = super_.data();
  // Small factors in one thread (the same arithmetic): a thread costs more than their sweeps.
  auto both = [&](auto&& f) {
    if (parallel()) {
      run_pair(f);
    } else {
      f(0);
      f(1);
    }
  };
  both([&](int th) {
    for (const auto& r : ranges_[th])
      forward2(r[0], r[1], sup, pi_.data(), off_.data(), s_.data(), x_.data(), dinv_.data(), y0, y1, t[th][0], t[th][1],
               owner_.data(), th, th == 1 ? e0 : nullptr, th == 1 ? e1 : nullptr);
  });
  for (const auto& r : top_ranges_)
    for (int k = sup[r[0]]; k < sup[r[1]]; ++k) {
      y0[k] += e0[k];
      y1[k] += e1[k];
    }
  for (const auto& r : top_ranges_)
    forward2(r[0], r[1], sup, pi_.data(), off_.data(), s_.data(), x_.data(), dinv_.data(), y0, y1, t[0][0], t[0][1],
             owner_.data(), 2, nullptr, nullptr);
  for (auto r = top_ranges_.rbegin(); r != top_ranges_.rend(); ++r)
    backward2((*r)[0], (*r)[1], sup, pi_.data(), off_.data(), s_.data(), x_.data(), dinv_.data(), y0, y1, t[0][0], t[0][1]);
  both([&](int th) {
    for (auto r = ranges_[th].rbegin(); r != ranges_[th].rend(); ++r)
      backward2((*r)[0], (*r)[1], sup, pi_.data(), off_.data(), s_.data(), x_.data(), dinv_.data(), y0, y1, t[th][0],
                t[th][1]);
  });
  for (size_t k = 0; k < n; ++k) {
    x0[perm_[k]] = y0[k];
    x1[perm_[k]] = y1[k];
  }
}

void FloatFactor::solve(const double* b, double* x, std::vector<float>& work) const {
  // The two-column sweeps with b twice: they read the factor once, as a one-column sweep would.
  std::vector<double> unused(static_cast<size_t>(n_));
  solve2(b, b, x, unused.data(), work);
}

}  // namespace polycube::deform
