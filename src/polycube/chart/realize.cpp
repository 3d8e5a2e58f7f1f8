#include "polycube/chart/realize.h"

#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <Eigen/Sparse>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <memory>
#include <mutex>
#include <array>
#include <initializer_list>
#include <numeric>

#include "polycube/chart/labeling.h"
#include "polycube/core/lbfgs.h"
#include "polycube/core/memory.h"
#include "polycube/core/parallel.h"
#include "polycube/core/topology.h"
#include "polycube/deform/energies.h"
#include "polycube/deform/untangle.h"
#include "polycube/tetra/tetrahedralize.h"
#include "polycube/validate/tetmesh.h"

namespace polycube::chart {

namespace {

using SpMat = Eigen::SparseMatrix<double>;
// Eigen's CHOLMOD wrapper, with a symbolic analysis from a given fill-reducing ordering.
class Cholmod : public Eigen::CholmodDecomposition<SpMat, Eigen::Lower> {
 public:
  /// As analyzePattern, but with `perm` (new -> old) or AMD's ordering, the better by CHOLMOD's
  /// measure (METIS is not run).
  void analyze_pattern_given(const SpMat& A, std::vector<int>& perm) {
    if (m_cholmodFactor) {
      cholmod_free_factor(&m_cholmodFactor, &this->cholmod());
      m_cholmodFactor = nullptr;
    }
    cholmod_sparse view = Eigen::viewAsCholmod(A.selfadjointView<Eigen::Lower>());
    const int nmethods = this->cholmod().nmethods;
    const int second = this->cholmod().method[1].ordering;
    this->cholmod().nmethods = 2;  // method[0]: the given ordering
    this->cholmod().method[1].ordering = CHOLMOD_AMD;
    m_cholmodFactor = cholmod_analyze_p(&view, perm.data(), nullptr, 0, &this->cholmod());
    this->cholmod().nmethods = nmethods;
    this->cholmod().method[1].ordering = second;
    m_isInitialized = true;
    m_info = m_cholmodFactor ? Eigen::Success : Eigen::NumericalIssue;
    m_analysisIsOk = m_cholmodFactor != nullptr;
    m_factorizationIsOk = false;
  }
  /// The fill-reducing ordering of the last analysis (new -> old), empty without one.
  std::vector<int> ordering() const {
    if (!m_cholmodFactor || !m_cholmodFactor->Perm) return {};
    const int* p = static_cast<const int*>(m_cholmodFactor->Perm);
    return std::vector<int>(p, p + m_cholmodFactor->n);
  }
};


std::unique_ptr<Cholmod> make_solver() {
  auto s = std::make_unique<Cholmod>();
  s->cholmod().print = 0;
  s->setMode(Eigen::CholmodSupernodalLLt);
  return s;
}

// CHOLMOD's fill-reducing ordering may call METIS, whose random state is global: two analyses at
// once (the two realization starts run side by side) interleave it and give orderings, hence
// round-off and results, that depend on timing (the rod's hexes came out different on every
// run). Analyses are serialized; the numeric factorizations still run in parallel.
std::mutex& analysis_mutex() {
  static std::mutex m;
  return m;
}
void analyze(Cholmod& s, const SpMat& A) {
  const std::lock_guard<std::mutex> lock(analysis_mutex());
  const SerialOpenMP serial_openmp;
  s.analyzePattern(A);
}
void factorize(Cholmod& s, const SpMat& A) {
  const SerialOpenMP serial_openmp;
  s.factorize(A);
}
void analyze_and_factorize(Cholmod& s, const SpMat& A) {
  analyze(s, A);
  factorize(s, A);
}
// The same from a given ordering or AMD's (no METIS, whose state is global: no lock needed).
void analyze_and_factorize(Cholmod& s, const SpMat& A, std::vector<int>& perm) {
  {
    const SerialOpenMP serial_openmp;
    s.analyze_pattern_given(A, perm);
  }
  factorize(s, A);
}

// The unknowns 0..count-1 of a system over the mesh's vertices, in the order of their vertices
// in `vertex_order` (a fill-reducing ordering of the vertex graph), each vertex's coordinates
// together; unknown(v, k) for coordinate k of vertex v (< 0: none). Unknowns shared by many
// vertices (plane heights: dense rows), marked by shared(u), go last, as a minimum-degree
// ordering puts them.
template <class Unknown, class Shared>
std::vector<int> restricted_order(const std::vector<int>& vertex_order, int count, Unknown unknown, Shared shared) {
  std::vector<int> perm;
  perm.reserve(count);
  std::vector<char> seen(count, 0);
  for (int v : vertex_order)
    for (int k = 0; k < 3; ++k) {
      const int u = unknown(v, k);
      if (u >= 0 && !seen[u] && !shared(u)) {
        seen[u] = 1;
        perm.push_back(u);
      }
    }
  for (int u = 0; u < count; ++u)
    if (!seen[u]) perm.push_back(u);
  return perm;
}

// Volume ratio J = det(F) of tet t (rest -> X) and its gradient over the tet's 12 coordinates.
struct TetJacobian {
  double J = 0;
  Eigen::Matrix<double, 12, 1> dJ;
};
TetJacobian tet_jacobian(const MatX3d& X, const MatX4i& T, const deform::ArapRest& rest, int t, bool gradient) {
  TetJacobian r;
  Eigen::Matrix3d Ds;
  for (int m = 0; m < 3; ++m) Ds.col(m) = (X.row(T(t, m + 1)) - X.row(T(t, 0))).transpose();
  const Eigen::Matrix3d& Di = rest.Dm_inv[t];
  const Eigen::Matrix3d F = Ds * Di;
  r.J = F.determinant();
  if (!gradient || !(r.J > 0)) return r;
  const Eigen::Matrix3d dJdF = r.J * F.inverse().transpose();  // cofactor of F
  const Eigen::Matrix<double, 4, 3> Bm = deform::shape_gradients(Di);
  for (int p = 0; p < 4; ++p) r.dJ.segment<3>(3 * p) = dJdF * Bm.row(p).transpose();
  return r;
}

using deform::count_inverted;
using deform::untangle_locally;
using deform::volume_ratio;



// Planes: per axis, the plane (group of charts) of every vertex, -1 for none.
struct Planes {
  std::vector<int> of_vertex[3];
  int count[3] = {0, 0, 0};
  std::vector<double> height[3];
};

// Two parametrizations of the unknowns, per axis k:
//   reduced: every vertex maps to a variable; the vertices of one plane share the plane's
//            variable (its height), the others have their own (planes free, exactly planar);
//   pinned:  only vertices on no plane of axis k are unknowns; the others are prescribed.
struct Reduced {
  std::vector<int> var[3];   // reduced variable of every vertex
  int nvar[3] = {0, 0, 0};
  std::vector<int> fvar[3];  // pinned: unknown of every vertex, -1 if prescribed
  int nfree[3] = {0, 0, 0};
};

enum class Mode { Reduced, Pinned };

class Realizer {
 public:
  Realizer(MatX3d rest, MatX4i T, const Planes& planes, const RealizeOptions& opt, const Hooks& hooks)
      : rest_(std::move(rest)), T_(std::move(T)), planes_(planes), opt_(opt), hooks_(hooks) {
    arap_rest_ = deform::ArapRest::build(rest_, T_);
    const int n = static_cast<int>(rest_.rows());
    for (int k = 0; k < 3; ++k) {
      auto& var = red_.var[k];
      auto& fvar = red_.fvar[k];
      var.assign(n, -1);
      fvar.assign(n, -1);
      int nf = 0;
      for (int v = 0; v < n; ++v)
        if (planes_.of_vertex[k][v] < 0) var[v] = fvar[v] = nf++;
      for (int v = 0; v < n; ++v)
        if (planes_.of_vertex[k][v] >= 0) var[v] = nf + planes_.of_vertex[k][v];
      red_.nfree[k] = nf;
      red_.nvar[k] = nf + planes_.count[k];
    }
    // The constant ARAP Hessian, the same for the three coordinates: sum_t w_t B B^T.
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(16 * T_.rows());
    double diag = 0;
    for (int t = 0; t < T_.rows(); ++t) {
      const Eigen::Matrix3d& Di = arap_rest_.Dm_inv[t];
      const Eigen::Matrix<double, 4, 3> Bm = deform::shape_gradients(Di);
      const Eigen::Matrix4d Ke = arap_rest_.w[t] * Bm * Bm.transpose();
      for (int p = 0; p < 4; ++p)
        for (int q = 0; q < 4; ++q) trip.emplace_back(T_(t, p), T_(t, q), Ke(p, q));
      diag += Ke.trace();
    }
    K_.resize(n, n);
    K_.setFromTriplets(trip.begin(), trip.end());
    // One fill-reducing ordering of the vertices for the coupled steps (see coupled_step), whose
    // own orderings (METIS on the larger meshes) were most of the analyses' time, 39 s of a 95 s
    // extraction (rocker, 155k tets, 99 analyses).
    {
      Cholmod ordering;
      ordering.cholmod().print = 0;
      // Both AMD and METIS, the better kept (by default CHOLMOD tries METIS only where AMD fills
      // much; on fandisk's vertices AMD's ordering restricted to the per-axis systems had 1.8x
      // the flops of METIS's).
      ordering.cholmod().nmethods = 2;
      ordering.cholmod().method[0].ordering = CHOLMOD_AMD;
      ordering.cholmod().method[1].ordering = CHOLMOD_METIS;
      const SpMat lower = K_.triangularView<Eigen::Lower>();
      analyze(ordering, lower);
      vertex_order_ = ordering.ordering();
      if (static_cast<int>(vertex_order_.size()) != n) {
        vertex_order_.resize(n);
        for (int v = 0; v < n; ++v) vertex_order_[v] = v;
      }
    }
    // Translations along k are free in reduced mode: a tiny diagonal makes the system definite.
    const double reg = 1e-10 * diag / std::max(1, n);
    for (int k = 0; k < 3; ++k) {
      for (Mode m : {Mode::Reduced, Mode::Pinned}) {
        const auto& map = m == Mode::Reduced ? red_.var[k] : red_.fvar[k];
        const int nv = m == Mode::Reduced ? red_.nvar[k] : red_.nfree[k];
        std::vector<Eigen::Triplet<double>> tk;
        tk.reserve(K_.nonZeros() / 2 + nv);
        for (int j = 0; j < n; ++j)
          for (SpMat::InnerIterator it(K_, j); it; ++it) {
            const int a = map[it.row()], b = map[j];
            if (a >= 0 && b >= 0 && a >= b) tk.emplace_back(a, b, it.value());
          }
        for (int i = 0; i < nv; ++i) tk.emplace_back(i, i, reg);
        SpMat Kk(nv, nv);
        Kk.setFromTriplets(tk.begin(), tk.end());
        auto& solver = m == Mode::Reduced ? solver_[k] : pinned_solver_[k];
        solver = make_solver();
        // (The vertex ordering above, restricted to these unknowns, halved their flops on rocker
        // but changed the round-off enough for spot at 20k tets to end unrealized: CHOLMOD's own
        // ordering stays here.)
        if (nv > 0) analyze_and_factorize(*solver, Kk);
        ok_ = ok_ && (nv == 0 || solver->info() == Eigen::Success);
      }
    }
  }

  bool ok() const { return ok_; }
  const deform::ArapRest& arap_rest() const { return arap_rest_; }

  // The step -K^-1 g in the unknowns of `mode`, expanded to every vertex (0 where prescribed).
  MatX3d newton_step(const Eigen::VectorXd& g, Mode mode) const {
    const int n = static_cast<int>(rest_.rows());
    MatX3d d = MatX3d::Zero(n, 3);
    for (int k = 0; k < 3; ++k) {
      const auto& map = mode == Mode::Reduced ? red_.var[k] : red_.fvar[k];
      const int nv = mode == Mode::Reduced ? red_.nvar[k] : red_.nfree[k];
      if (nv == 0) continue;
      Eigen::VectorXd gk = Eigen::VectorXd::Zero(nv);
      for (int v = 0; v < n; ++v)
        if (map[v] >= 0) gk[map[v]] += g[3 * v + k];
      const Eigen::VectorXd dk = (mode == Mode::Reduced ? solver_[k] : pinned_solver_[k])->solve(-gk);
      for (int v = 0; v < n; ++v)
        if (map[v] >= 0) d(v, k) = dk[map[v]];
    }
    return d;
  }

  // Moves the prescribed coordinates by dc and the unknowns by the linear response of the ARAP
  // quadratic with rotations frozen: K_ff dx_f = -K_fc dc.
  MatX3d extend(const MatX3d& dc) const {
    const int n = static_cast<int>(rest_.rows());
    MatX3d d = dc;
    for (int k = 0; k < 3; ++k) {
      const auto& f = red_.fvar[k];
      if (red_.nfree[k] == 0) continue;
      Eigen::VectorXd r = Eigen::VectorXd::Zero(red_.nfree[k]);
      for (int j = 0; j < n; ++j) {
        if (f[j] >= 0 || dc(j, k) == 0) continue;
        for (SpMat::InnerIterator it(K_, j); it; ++it)
          if (f[it.row()] >= 0) r[f[it.row()]] -= it.value() * dc(j, k);
      }
      const Eigen::VectorXd x = pinned_solver_[k]->solve(r);
      for (int v = 0; v < n; ++v)
        if (f[v] >= 0) d(v, k) = x[f[v]];
    }
    return d;
  }

  // ARAP + near-flat barrier; +inf if a tet is inverted (when `barrier`).
  double energy(const MatX3d& X, Eigen::VectorXd* g, bool barrier) const {
    // An inverted tet is found from the volumes alone, before the ARAP term's per-tet rotations
    // (line searches try many such points: fandisk's continuation, 15 trials per iteration).
    if (barrier)
      for (int t = 0; t < T_.rows(); ++t)
        if (!(volume_ratio(X, T_, arap_rest_, t) > 0)) return std::numeric_limits<double>::infinity();
    if (g) g->setZero(3 * X.rows());
    double E = deform::arap_energy(X, T_, arap_rest_, 1.0, g, nullptr);
    if (!barrier) return E;
    for (int t = 0; t < T_.rows(); ++t) {
      if (volume_ratio(X, T_, arap_rest_, t) >= tau_) continue;  // barrier off
      const TetJacobian tj = tet_jacobian(X, T_, arap_rest_, t, g != nullptr);
      const double l = std::log(tj.J / tau_);
      const double w = barrier_weight_ * arap_rest_.w[t];
      E += w * l * l;
      if (g)
        for (int p = 0; p < 4; ++p) g->segment<3>(3 * T_(t, p)) += (2 * w * l / tj.J) * tj.dJ.segment<3>(3 * p);
    }
    return E;
  }

  // The barrier acts below barrier_threshold x the median volume ratio of X.
  void set_barrier_scale(const MatX3d& X) {
    std::vector<double> J(T_.rows());
    for (int t = 0; t < T_.rows(); ++t) J[t] = volume_ratio(X, T_, arap_rest_, t);
    std::nth_element(J.begin(), J.begin() + J.size() / 2, J.end());
    tau_ = opt_.barrier_threshold * std::max(J[J.size() / 2], 1e-300);
  }

  // Local/global ARAP steps (reduced mode) while tets are inverted. Returns the steps taken.
  int untangle(MatX3d& X, int& inverted) const {
    inverted = count_inverted(X, T_, arap_rest_);
    int it = 0;
    Eigen::VectorXd g;
    for (; inverted > 0 && it < opt_.untangle_iterations; ++it) {
      energy(X, &g, false);
      X += newton_step(g, Mode::Reduced);
      inverted = count_inverted(X, T_, arap_rest_);
    }
    return it;
  }

  // The first inverted (or flat) tet of X, -1 if none.
  int first_inverted_tet(const MatX3d& X) const {
    for (int t = 0; t < T_.rows(); ++t)
      if (!(volume_ratio(X, T_, arap_rest_, t) > 0)) return t;
    return -1;
  }

  // The first inverted tets of X, named with the planes of their vertices, e.g. "tet 7 (3:X-- 9:--Z
  // ...)"; count receives how many are inverted.
  std::string inverted_tets(const MatX3d& X, int* count, int show = 3) const {
    std::string who;
    *count = 0;
    for (int t = 0; t < T_.rows(); ++t)
      if (!(volume_ratio(X, T_, arap_rest_, t) > 0) && (*count)++ < show) {
        who += (who.empty() ? "" : "; ") + std::string("tet ") + std::to_string(t) + " (";
        for (int j = 0; j < 4; ++j) {
          const int v = T_(t, j);
          who += (j ? " " : "") + std::to_string(opt_.names.vertex(v)) + ":";
          for (int k = 0; k < 3; ++k) who += planes_.of_vertex[k][v] >= 0 ? "XYZ"[k] : '-';
        }
        who += ")";
      }
    return who;
  }

  // Untangling by the regularized elliptic energy of Garanzha et al. ("Foldover-free maps in 50
  // lines of code", 2021), over the reduced unknowns (planes stay exact, heights free):
  //   sum_t w_t [(1 - theta) tr(J^T J) / chi(det J)^(2/3) + theta (det J^2 + 1) / chi(det J)],
  //   chi(D) = (D + sqrt(eps^2 + D^2)) / 2,
  // J the rest -> X Jacobian scaled to unit mean volume ratio. The energy is finite for inverted
  // tets and, as eps falls, penalizes them without bound; each eps is minimized by L-BFGS
  // preconditioned with the ARAP matrix (the factorizations at hand), then eps is updated by the
  // paper's rule. Stops once no tet is inverted. Returns the L-BFGS iterations taken.
  // mode Pinned: the plane heights stay where X has them (only the other coordinates move), which
  // also keeps the mesh from shrinking as a whole.
  int untangle_elliptic(MatX3d& X, int& inverted, Mode mode = Mode::Reduced, int max_rounds = 30,
                        int max_inner = 300) const {
    const int n = static_cast<int>(rest_.rows());
    const int nt = static_cast<int>(T_.rows());
    const bool reduced = mode == Mode::Reduced;
    const std::vector<int>* map = reduced ? red_.var : red_.fvar;
    int off[4] = {0, 0, 0, 0};
    for (int k = 0; k < 3; ++k) off[k + 1] = off[k] + (reduced ? red_.nvar[k] : red_.nfree[k]);
    const int N = off[3];
    auto to_z = [&](const MatX3d& Y) {
      Eigen::VectorXd z = Eigen::VectorXd::Zero(N);
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < n; ++v)
          if (map[k][v] >= 0) z[off[k] + map[k][v]] = Y(v, k);
      return z;
    };
    auto to_X = [&](const Eigen::VectorXd& z, MatX3d& Y) {
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < n; ++v)
          if (map[k][v] >= 0) Y(v, k) = z[off[k] + map[k][v]];
    };
    // Scale: J / s has mean volume ratio 1.
    double vol = 0;
    for (int t = 0; t < nt; ++t) vol += arap_rest_.w[t] * volume_ratio(X, T_, arap_rest_, t);
    const double s = std::cbrt(std::max(vol, 1e-300));
    constexpr double theta = 0.5;
    auto chi = [](double D, double e) { return 0.5 * (D + std::sqrt(e * e + D * D)); };
    auto min_det = [&](const MatX3d& Y) {
      double m = std::numeric_limits<double>::infinity();
      for (int t = 0; t < nt; ++t) m = std::min(m, volume_ratio(Y, T_, arap_rest_, t) / (s * s * s));
      return m;
    };
    double edge = 0;  // mean tet edge length in X
    for (int t = 0; t < nt; ++t) edge += (X.row(T_(t, 0)) - X.row(T_(t, 1))).norm();
    edge /= std::max(1, nt);
    MatX3d Y = X;
    // Energy and gradient over z.
    Eigen::VectorXd gX;
    auto evaluate = [&](const Eigen::VectorXd& z, double eps, Eigen::VectorXd* gz) {
      to_X(z, Y);
      if (gz) gX.setZero(3 * n);
      const double E = deform::untangle_energy(Y, T_, arap_rest_, eps, s, theta, gz ? &gX : nullptr);
      if (gz) {
        gz->setZero(N);
        for (int k = 0; k < 3; ++k)
          for (int v = 0; v < n; ++v)
            if (map[k][v] >= 0) (*gz)[off[k] + map[k][v]] += gX[3 * v + k];
      }
      return E;
    };
    auto precondition = [&](const Eigen::VectorXd& q) {
      Eigen::VectorXd r(N);
      for (int k = 0; k < 3; ++k) {
        const int m = off[k + 1] - off[k];
        if (m > 0) r.segment(off[k], m) = (reduced ? solver_[k] : pinned_solver_[k])->solve(q.segment(off[k], m));
      }
      return r;
    };

    Eigen::VectorXd z = to_z(X);
    double dmin = min_det(X);
    double eps = std::sqrt(1e-12 + 0.04 * std::pow(std::min(dmin, 0.0), 2));
    int total = 0;
    inverted = count_inverted(X, T_, arap_rest_);
    int best = inverted, since_best = 0;
    Eigen::VectorXd best_z = z;
    const int patience = std::max(1, opt_.untangle_patience);
    for (int round = 0; round < max_rounds && inverted > 0 && since_best < patience && !(stop_ && stop_(total));
         ++round) {
      // L-BFGS at this eps. The inverted tets are few and local: a global relative test would stop
      // long before they are repaired, so run until they are gone or the energy stops moving at all.
      double E = 0;
      const double E0 = evaluate(z, eps, nullptr);
      LbfgsOptions lo;
      lo.max_iterations = max_inner;
      lo.max_change = 0.1 * edge;
      total += lbfgs_minimize(
          z, [&](const Eigen::VectorXd& zz, Eigen::VectorXd* g) { return evaluate(zz, eps, g); }, precondition, lo, E,
          [&](int it) {
            if (it % 10 != 9) return false;
            to_X(z, Y);
            return count_inverted(Y, T_, arap_rest_) == 0;
          });
      to_X(z, Y);
      inverted = count_inverted(Y, T_, arap_rest_);
      dmin = min_det(Y);
      hooks_.debug(std::string("elliptic untangling ") + (reduced ? "" : "(heights fixed) ") + "round " +
                   std::to_string(round) + ": eps " + std::to_string(eps) +
                   ", min det " + std::to_string(dmin) + ", " + std::to_string(inverted) + " inverted, " +
                   std::to_string(total) + " iterations" +
                   (inverted > 0 && inverted < 4 ? ": " + inverted_tets(Y, &inverted) : std::string()));
      if (inverted < best) best = inverted, best_z = z, since_best = 0;
      else ++since_best;
      // With the plane heights free and a large eps, shrinking the whole mesh costs less than
      // untangling it (chi(0, eps) = eps / 2 is finite): rocker's eq17 start went from 5331 inverted
      // tets to a flat mesh with 30-123k "inverted" (det ~ 0). Stop when the volume halves.
      double vol_now = 0;
      for (int t = 0; t < nt; ++t) vol_now += arap_rest_.w[t] * volume_ratio(Y, T_, arap_rest_, t);
      if (vol_now < 0.5 * vol) {
        hooks_.debug("elliptic untangling: the mesh is collapsing (volume x " + std::to_string(vol_now / vol) + "), stopped");
        break;
      }
      // The paper's eps update.
      const double sigma = std::max(1 - E / E0, 0.1);
      const double mu = (1 - sigma) * chi(dmin, eps);
      eps = dmin < mu ? 2 * std::sqrt(mu * (mu - dmin)) : 1e-13;
    }
    if (inverted > best) {
      // Return the round with the fewest inverted tets, not a later, worse (or collapsed) state.
      z = best_z;
      inverted = best;
      hooks_.debug("elliptic untangling: back to the round with " + std::to_string(best) + " inverted tets");
    }
    to_X(z, X);
    return total;
  }

  // Local untangling (untangle_locally below) with the planes' coordinates fixed.
  // The stop callback (set_stop) is asked before each sweep, with 100 x the sweeps so far.
  int untangle_local(MatX3d& X, int& inverted, int rings = 3, int max_sweeps = 300) const {
    const int sweeps = untangle_locally(
        T_, arap_rest_, [&](int v, int k) { return planes_.of_vertex[k][v] >= 0; }, X, inverted, rings, max_sweeps,
        0.0, stop_);
    int shown = 0;
    hooks_.debug("local untangling: " + std::to_string(sweeps) + " sweeps, " + std::to_string(inverted) +
                 " tets inverted" + (inverted > 0 && inverted < 4 ? ": " + inverted_tets(X, &shown) : std::string()));
    return sweeps;
  }

  // A valid X with nearly flat tets (volume ratio under kOpenFlat x the mean): their regions are
  // swept by the local untangling, each sweep kept only while it raises the smallest volume ratio
  // and turns no tet over. Where a failed realization's state is the start ("previous"), landing can leave tets
  // at 1e-9 of the mean volume; the ARAP Newton steps then stop at their first iteration (bumpy
  // torus, 55k tets, after 19 collapses: ARAP 0.148, 34 tets with isometric distortion over 1e3).
  static constexpr double kOpenFlat = 1e-3;
  void open_flat(MatX3d& X) const {
    int flat = 0;
    const int sweeps = untangle_locally(
        T_, arap_rest_, [&](int v, int k) { return planes_.of_vertex[k][v] >= 0; }, X, flat, 3, 30, kOpenFlat);
    if (sweeps > 0)
      hooks_.debug("opening nearly flat tets: " + std::to_string(sweeps) + " sweeps, " + std::to_string(flat) +
                   " left under " + std::to_string(kOpenFlat) + " of the mean volume ratio");
  }

  /// The elliptic untangling stops before a round when stop(iterations so far in the call) is
  /// true, the local untangling before a sweep when stop(100 x its sweeps so far) is (against
  /// RealizeOptions::eq17_budget a sweep counts as 100 iterations: past 3 sweeps, a budgeted eq17
  /// start is abandoned once the continuation has succeeded; its wins needed 1).
  void set_stop(std::function<bool(int)> stop) { stop_ = std::move(stop); }

  // The barrier's Gauss-Newton curvature on tet t at X: b'' of (w log(J / tau))^2, the tet's
  // Hessian being b'' dJ dJ^T; 0 where the barrier is off (J >= tau) or the tet is inverted.
  double barrier_curvature(const MatX3d& X, int t, TetJacobian& tj) const {
    if (!(volume_ratio(X, T_, arap_rest_, t) < tau_)) return 0;
    tj = tet_jacobian(X, T_, arap_rest_, t, true);
    if (!(tj.J > 0)) return 0;
    const double w = barrier_weight_ * arap_rest_.w[t];
    return 2 * w * (1 - std::log(tj.J / tau_)) / (tj.J * tj.J);
  }

  // Newton iterations on ARAP + barrier from a tangle-free X. Returns iterations.
  // A Newton step with the barrier's curvature: (K (x) I3 + sum_active b''(J) dJ dJ^T) d = -g over
  // the unknowns of `mode`, all axes coupled, factorized afresh. Used when the constant-Hessian
  // step stalls on nearly flat tets, whose barrier it ignores.
  MatX3d coupled_step(const MatX3d& X, const Eigen::VectorXd& g, Mode mode) const {
    const int n = static_cast<int>(rest_.rows());
    int offset[4] = {0, 0, 0, 0};
    for (int k = 0; k < 3; ++k)
      offset[k + 1] = offset[k] + (mode == Mode::Reduced ? red_.nvar[k] : red_.nfree[k]);
    auto dof = [&](int v, int k) {
      const int m = mode == Mode::Reduced ? red_.var[k][v] : red_.fvar[k][v];
      return m < 0 ? -1 : offset[k] + m;
    };
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(3 * K_.nonZeros() / 2 + offset[3]);
    double diag = 0;
    for (int j = 0; j < n; ++j)
      for (SpMat::InnerIterator it(K_, j); it; ++it)
        for (int k = 0; k < 3; ++k) {
          const int a = dof(static_cast<int>(it.row()), k), b = dof(j, k);
          if (a >= 0 && b >= 0 && a >= b) trip.emplace_back(a, b, it.value());
          if (a >= 0 && a == b) diag += it.value();
        }
    for (int t = 0; t < T_.rows(); ++t) {
      TetJacobian tj;
      const double b2 = barrier_curvature(X, t, tj);
      if (b2 == 0) continue;
      for (int p = 0; p < 12; ++p)
        for (int q = 0; q < 12; ++q) {
          const int a = dof(T_(t, p / 3), p % 3), b = dof(T_(t, q / 3), q % 3);
          if (a >= 0 && b >= 0 && a >= b) trip.emplace_back(a, b, b2 * tj.dJ[p] * tj.dJ[q]);
        }
    }
    const double reg = 1e-10 * diag / std::max(1, offset[3]);
    for (int i = 0; i < offset[3]; ++i) trip.emplace_back(i, i, reg);
    SpMat H(offset[3], offset[3]);
    H.setFromTriplets(trip.begin(), trip.end());
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(offset[3]);
    for (int v = 0; v < n; ++v)
      for (int k = 0; k < 3; ++k)
        if (dof(v, k) >= 0) rhs[dof(v, k)] -= g[3 * v + k];
    auto solver = make_solver();
    // Ordering: the vertex ordering with each vertex's coordinates together, or AMD's of this
    // pattern, whichever CHOLMOD finds better. Where few tets have barrier curvature the axes
    // barely couple and AMD wins (fandisk: 0.6 Gflop against 2.8); where many do, AMD's ordering
    // is poor (rocker, 155k tets: 3x the flops of METIS's) and METIS afresh cost about 1 s per
    // step (the vertex ordering: 1.6x METIS's flops, no ordering time).
    std::vector<int> perm = restricted_order(vertex_order_, offset[3], dof, [&](int u) {
      const int k = u >= offset[2] ? 2 : u >= offset[1] ? 1 : 0;
      return mode == Mode::Reduced && u - offset[k] >= red_.nfree[k];
    });
    analyze_and_factorize(*solver, H, perm);
    MatX3d d = MatX3d::Zero(n, 3);
    if (solver->info() != Eigen::Success) return d;
    const Eigen::VectorXd x = solver->solve(rhs);
    for (int v = 0; v < n; ++v)
      for (int k = 0; k < 3; ++k)
        if (dof(v, k) >= 0) d(v, k) = x[dof(v, k)];
    return d;
  }

  int minimize(MatX3d& X, Mode mode, int max_iterations, double tolerance = -1) const {
    if (tolerance < 0) tolerance = opt_.volume_tolerance;
    Eigen::VectorXd g, gt;
    double E = energy(X, &g, true);
    int it = 0;
    bool coupled = false;
    for (; it < max_iterations && std::isfinite(E); ++it) {
      const MatX3d d = coupled ? coupled_step(X, g, mode) : newton_step(g, mode);
      const double slope = Eigen::Map<const Eigen::VectorXd>(d.data(), d.size()).dot(g);
      if (!(slope < 0)) break;
      double s = 1, Et = E;
      MatX3d Xt;
      bool accepted = false;
      for (int ls = 0; ls < 40; ++ls, s *= 0.5) {
        Xt = X + s * d;
        Et = energy(Xt, &gt, true);
        if (Et <= E + 1e-4 * s * slope) {
          accepted = true;
          break;
        }
      }
      if (!accepted) {
        if (coupled) break;
        coupled = true;  // retry this iteration with the barrier's curvature
        continue;
      }
      const double decrease = E - Et;
      X = std::move(Xt);
      g = gt;
      E = Et;
      // Short steps mean nearly flat tets: take the next one with the barrier's curvature.
      coupled = s < 0.25;
      if (decrease <= tolerance * E + 1e-15 && s >= 0.25) {  // absolute floor: E ~ 0 for a polycube input
        ++it;
        break;
      }
    }
    return it;
  }

  // Continuation from a tangle-free X whose plane vertices are off their planes: the prescribed
  // coordinates travel to the plane heights in steps small enough to keep every tet positive,
  // the others following (extend) and relaxing (pinned Newton). Returns false if a step collapses.
  bool continuation(MatX3d& X, int& steps) const {
    constexpr int max_steps = 60;  // block: 25; a stalling run halves dt to nothing
    const int n = static_cast<int>(rest_.rows());
    MatX3d gap = MatX3d::Zero(n, 3);  // plane height - start, on prescribed coordinates
    for (int k = 0; k < 3; ++k)
      for (int v = 0; v < n; ++v)
        if (planes_.of_vertex[k][v] >= 0) gap(v, k) = planes_.height[k][planes_.of_vertex[k][v]] - X(v, k);
    double t = 0, dt = 1.0;
    steps = 0;
    // A tet that flattens as t -> 1 (its shape at the planes is flat whatever the free
    // coordinates do) lets each accepted step cover only a fixed fraction of the remaining way
    // (rocker, 155k tets: about 1/7, from t = 0.6 on): the run creeps to the step limit and
    // stalls at t = 0.99, some 20 accepted steps of 2 s each after the outcome was clear. Past
    // kStallFrom, a failed step whose first inverted tet already blocked one there counts as a
    // repeat; opt_.stall_repeats repeats end the run as stalled.
    constexpr double kStallFrom = 0.75;
    std::set<int> blockers;
    int repeated_blocks = 0;
    // Open up nearly flat tets of the start first (the unknowns only): any step would invert them.
    minimize(X, Mode::Pinned, 5);
    while (t < 1) {
      const double t1 = std::min(1.0, t + dt);
      MatX3d Xt = X + extend((t1 - t) * gap);
      if (t1 == 1.0)  // land exactly on the planes
        for (int k = 0; k < 3; ++k)
          for (int v = 0; v < n; ++v)
            if (planes_.of_vertex[k][v] >= 0) Xt(v, k) = planes_.height[k][planes_.of_vertex[k][v]];
      ++steps;
      const int first_inverted = first_inverted_tet(Xt);
      if (first_inverted >= 0 || steps > max_steps) {  // a step must keep every tet positive
        dt *= 0.5;
        if (first_inverted >= 0 && t >= kStallFrom && !blockers.insert(first_inverted).second) ++repeated_blocks;
        if (dt < 1e-4 || steps > max_steps || (opt_.stall_repeats > 0 && repeated_blocks >= opt_.stall_repeats)) {
          // Name the tets that block the path, for the failure message.
          int count = 0;
          const std::string who = inverted_tets(Xt, &count);
          blocked_ = count > 0 ? std::to_string(count) + " tets would invert at t = " + std::to_string(t) + ", e.g. " +
                                     who + " (vertex:axes of its planes)"
                               : std::to_string(max_steps) + " steps reached only t = " + std::to_string(t);
          return false;  // X: the last tangle-free state
        }
        continue;
      }
      X = std::move(Xt);
      t = t1;
      minimize(X, Mode::Pinned, 3);
      dt = std::min(1.0, 2 * dt);
      hooks_.report("polycube", 0.1 + 0.5 * t);
    }
    return true;
  }

  // Penalty path from a tangle-free X, for where the continuation stalls: its plane heights (the
  // means of the deformed coordinates) are fixed, and where a chart is far from flat in the
  // deformed mesh (homer: 2% of the diagonal) they can ask a thin part for a thickness it does not
  // have. Here the heights are unknowns beside the coordinates, and
  //   ARAP(X) + barrier(X) + (w / 2) sum_k sum_{v on plane p of axis k} a_v (X_vk - h_kp)^2
  // (a_v: v's diagonal entry of the ARAP matrix, so w = 1 weighs a gap like an ARAP strain of
  // that size) is minimized for w = 1e-2, 1e-1, ... by Newton steps with the barrier's
  // Gauss-Newton curvature (all axes coupled, factorized afresh) and a line search that keeps
  // every tet positive; once the largest gap is below 1e-9 of the diagonal (or w reaches 1e10)
  // the plane vertices land on their heights and any tet that turns over is untangled locally.
  // Returns the tets left inverted (0: X is on the planes, every tet positive); `steps` receives
  // the Newton steps.
  int penalty_path(MatX3d& X, int& steps) const {
    const int n = static_cast<int>(rest_.rows());
    int hoff[4] = {0, 0, 0, 0};
    for (int k = 0; k < 3; ++k) hoff[k + 1] = hoff[k] + planes_.count[k];
    const int nh = hoff[3], N = 3 * n + nh;
    const Eigen::VectorXd a = K_.diagonal();
    // Heights: the a-weighted means of X over each plane.
    Eigen::VectorXd h = Eigen::VectorXd::Zero(nh), wsum = Eigen::VectorXd::Zero(nh);
    for (int k = 0; k < 3; ++k)
      for (int v = 0; v < n; ++v)
        if (const int p = planes_.of_vertex[k][v]; p >= 0) {
          h[hoff[k] + p] += a[v] * X(v, k);
          wsum[hoff[k] + p] += a[v];
        }
    for (int i = 0; i < nh; ++i) h[i] = wsum[i] > 0 ? h[i] / wsum[i] : 0.0;
    const double diag = (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
    auto max_gap = [&](const MatX3d& Y, const Eigen::VectorXd& hh) {
      double m = 0;
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < n; ++v)
          if (const int p = planes_.of_vertex[k][v]; p >= 0) m = std::max(m, std::abs(Y(v, k) - hh[hoff[k] + p]));
      return m;
    };
    // Energy and gradient (x: 3 v + k, as energy(); heights after).
    auto total = [&](const MatX3d& Y, const Eigen::VectorXd& hh, double w, Eigen::VectorXd* g) {
      Eigen::VectorXd gx;
      double E = energy(Y, g ? &gx : nullptr, true);
      if (!std::isfinite(E)) return E;
      if (g) {
        g->setZero(N);
        g->head(3 * n) = gx;
      }
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < n; ++v)
          if (const int p = planes_.of_vertex[k][v]; p >= 0) {
            const double r = Y(v, k) - hh[hoff[k] + p];
            E += 0.5 * w * a[v] * r * r;
            if (g) {
              (*g)[3 * v + k] += w * a[v] * r;
              (*g)[3 * n + hoff[k] + p] -= w * a[v] * r;
            }
          }
      return E;
    };
    // The Newton matrix is A + w P + B (lower triangles): A = the ARAP matrix on every axis with
    // every tet's 12 x 12 block and the diagonal in its pattern (zeros there), P the penalty for
    // w = 1, B the barrier's curvature on the tets where it acts, inside A's pattern. A and P are
    // built once, and the pattern, so CHOLMOD's analysis of it, stays the same along the path.
    SpMat A(N, N), P(N, N);
    {
      std::vector<Eigen::Triplet<double>> trip;
      trip.reserve(3 * K_.nonZeros() / 2 + 78 * T_.rows() + N);
      for (int j = 0; j < n; ++j)
        for (SpMat::InnerIterator e(K_, j); e; ++e)
          if (e.row() >= j)
            for (int k = 0; k < 3; ++k) trip.emplace_back(3 * static_cast<int>(e.row()) + k, 3 * j + k, e.value());
      for (int t = 0; t < T_.rows(); ++t)
        for (int p = 0; p < 12; ++p)
          for (int q = 0; q <= p; ++q) {
            const int r = 3 * T_(t, p / 3) + p % 3, c = 3 * T_(t, q / 3) + q % 3;
            trip.emplace_back(std::max(r, c), std::min(r, c), 0.0);
          }
      for (int i = 0; i < N; ++i) trip.emplace_back(i, i, 0.0);
      A.setFromTriplets(trip.begin(), trip.end());
      trip.clear();
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < n; ++v)
          if (const int p = planes_.of_vertex[k][v]; p >= 0) {
            const int hd = 3 * n + hoff[k] + p;
            trip.emplace_back(3 * v + k, 3 * v + k, a[v]);
            trip.emplace_back(hd, 3 * v + k, -a[v]);
            trip.emplace_back(hd, hd, a[v]);
          }
      P.setFromTriplets(trip.begin(), trip.end());
    }
    SpMat I(N, N);
    I.setIdentity();
    const double reg = 1e-10 * a.sum() / std::max(1, 3 * n);
    auto chol = make_solver();
    bool analyzed = false;
    steps = 0;
    // (Landing early once three stages in a row failed to halve the largest gap was tried: on
    // homer it landed from a gap of 0.9% of the diagonal, 2454 tets inverted.)
    for (double w = 1e-2; w <= 1e10 && max_gap(X, h) > 1e-9 * diag; w *= 10) {
      Eigen::VectorXd g;
      double E = total(X, h, w, &g);
      if (!std::isfinite(E)) {
        hooks_.debug("penalty path: a tet is inverted at its start");
        return count_inverted(X, T_, arap_rest_);
      }
      const SpMat Aw = A + w * P;
      for (int it = 0; it < 20; ++it) {
        std::vector<Eigen::Triplet<double>> trip;
        for (int t = 0; t < T_.rows(); ++t) {
          TetJacobian tj;
          double b2 = barrier_curvature(X, t, tj);
          if (b2 == 0) continue;
          // On a nearly flat tet this rank-one term can be 1e20 x the ARAP entries beside it,
          // more than a factorization resolves (negative pivots): capped at 1e8 x the ARAP
          // stiffness of the tet's vertices (the line search keeps the barrier exact).
          double stiff = 0;
          for (int j = 0; j < 4; ++j) stiff += a[T_(t, j)];
          b2 = std::min(b2, 1e8 * stiff / std::max(tj.dJ.squaredNorm(), 1e-300));
          for (int p = 0; p < 12; ++p)
            for (int q = 0; q < 12; ++q) {
              const int r = 3 * T_(t, p / 3) + p % 3, c = 3 * T_(t, q / 3) + q % 3;
              if (r >= c) trip.emplace_back(r, c, b2 * tj.dJ[p] * tj.dJ[q]);
            }
        }
        SpMat B(N, N);
        B.setFromTriplets(trip.begin(), trip.end());
        const SpMat H = Aw + B;
        if (!analyzed) {
          analyze(*chol, H);
          analyzed = true;
        }
        // Damped more until it factorizes (the cap above mostly suffices).
        double damping = reg;
        for (int tries = 0;; ++tries, damping *= 100) {
          factorize(*chol, H + damping * I);
          if (chol->info() == Eigen::Success) break;
          if (tries == 8) {
            hooks_.debug("penalty path: the Newton matrix is not positive definite");
            return count_inverted(X, T_, arap_rest_);
          }
        }
        const Eigen::VectorXd d = chol->solve(-g);
        const double slope = d.dot(g);
        if (!(slope < 0)) break;
        const Eigen::Map<const MatX3d> dx(d.data(), n, 3);
        double s = 1;
        bool accepted = false;
        MatX3d Xt;
        Eigen::VectorXd ht, gt;
        double Et = E;
        for (int ls = 0; ls < 40 && !accepted; ++ls, s *= 0.5) {
          Xt = X + s * dx;
          ht = h + s * d.tail(nh);
          Et = total(Xt, ht, w, &gt);
          accepted = std::isfinite(Et) && Et <= E + 1e-4 * s * slope;
        }
        if (!accepted) break;
        ++steps;
        const double decrease = E - Et;
        X = std::move(Xt);
        h = std::move(ht);
        g = std::move(gt);
        E = Et;
        if (decrease <= 1e-6 * E + 1e-300) break;
      }
      hooks_.report("polycube", 0.1 + 0.05 * std::log10(w / 1e-2));
    }
    // Land: the plane vertices on their heights, any tet turned over untangled locally.
    const double gap = max_gap(X, h);
    for (int k = 0; k < 3; ++k)
      for (int v = 0; v < n; ++v)
        if (const int p = planes_.of_vertex[k][v]; p >= 0) X(v, k) = h[hoff[k] + p];
    int inverted = count_inverted(X, T_, arap_rest_);
    hooks_.debug("penalty path: " + std::to_string(steps) + " Newton steps, largest gap to the planes " +
                 std::to_string(gap / diag) + " x diag, " + std::to_string(inverted) + " tets inverted on landing");
    if (inverted > 0) untangle_local(X, inverted);
    return inverted;
  }

  // Puts the plane vertices on their planes at once (the others following by the ARAP response).
  void land(MatX3d& X) const {
    const int n = static_cast<int>(rest_.rows());
    MatX3d gap = MatX3d::Zero(n, 3);
    for (int k = 0; k < 3; ++k)
      for (int v = 0; v < n; ++v)
        if (planes_.of_vertex[k][v] >= 0) gap(v, k) = planes_.height[k][planes_.of_vertex[k][v]] - X(v, k);
    X += extend(gap);
    for (int k = 0; k < 3; ++k)
      for (int v = 0; v < n; ++v)
        if (planes_.of_vertex[k][v] >= 0) X(v, k) = planes_.height[k][planes_.of_vertex[k][v]];
  }

 private:
  MatX3d rest_;
  MatX4i T_;
  const Planes& planes_;
  const RealizeOptions& opt_;
  const Hooks& hooks_;
  std::function<bool(int)> stop_;  // see set_stop
  deform::ArapRest arap_rest_;
  Reduced red_;
  SpMat K_;
  std::unique_ptr<Cholmod> solver_[3], pinned_solver_[3];
  std::vector<int> vertex_order_;  // fill-reducing ordering of the vertices (new -> old)
  bool ok_ = true;
  double tau_ = 0;
  mutable std::string blocked_;
  double barrier_weight_ = 0;

 public:
  void set_barrier_weight(double w) { barrier_weight_ = w; }
  double barrier_weight() const { return barrier_weight_; }

 public:
  const std::string& blocked() const { return blocked_; }
};

// Eq. 17 with the plane heights fixed: per axis, minimize the weighted sum of squared uniform
// Laplacians (boundary vertices over their surface neighbours, interior ones over their tet
// neighbours) over the unconstrained coordinates.
bool relax_eq17(const MatX3i& B, const MatX4i& T, const Planes& planes, MatX3d& X) {
  const int n = static_cast<int>(X.rows());
  std::vector<char> on_boundary(n, 0);
  for (int f = 0; f < B.rows(); ++f)
    for (int k = 0; k < 3; ++k) on_boundary[B(f, k)] = 1;
  const auto nb_s = vertex_neighbors(n, unique_edges(B));
  const auto nb_t = vertex_neighbors(n, unique_edges(T));
  int nb = 0;
  for (char c : on_boundary) nb += c;
  const double wb = 1.0 / std::sqrt(std::max(1, nb)), wi = 1.0 / std::sqrt(std::max(1, n - nb));
  for (int k = 0; k < 3; ++k) {
    std::vector<int> fidx(n, -1);
    int nf = 0;
    for (int v = 0; v < n; ++v)
      if (planes.of_vertex[k][v] < 0) fidx[v] = nf++;
    if (nf == 0) continue;
    std::vector<Eigen::Triplet<double>> trip;
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n);
    for (int i = 0; i < n; ++i) {
      const auto& N = on_boundary[i] ? nb_s[i] : nb_t[i];
      if (N.empty()) continue;
      const double w = on_boundary[i] ? wb : wi;
      auto put = [&](int v, double c) {
        if (fidx[v] >= 0) trip.emplace_back(i, fidx[v], w * c);
        else rhs[i] -= w * c * planes.height[k][planes.of_vertex[k][v]];
      };
      put(i, 1.0);
      for (int j : N) put(j, -1.0 / static_cast<double>(N.size()));
    }
    SpMat A(n, nf);
    A.setFromTriplets(trip.begin(), trip.end());
    const SpMat AtA = (A.transpose() * A).triangularView<Eigen::Lower>();
    auto solver = make_solver();
    analyze_and_factorize(*solver, AtA);
    if (solver->info() != Eigen::Success) return false;
    const Eigen::VectorXd y = solver->solve(A.transpose() * rhs);
    for (int v = 0; v < n; ++v)
      X(v, k) = fidx[v] >= 0 ? y[fidx[v]] : planes.height[k][planes.of_vertex[k][v]];
  }
  return X.allFinite();
}

// What surrounds the inverted tets of r (a debug message): their vertices in r.X and deformed, and
// the boundary triangles there with chart, label and both normals.
std::string describe_inverted(const RealizeResult& r, const MatX3i& B, const std::vector<int>& labels,
                              const std::vector<int>& chart_of_face, const MatX3d& deformed, const MeshNames& names) {
  std::ostringstream os;
  os.precision(4);
  std::vector<std::vector<int>> vf(deformed.rows());
  for (int f = 0; f < B.rows(); ++f)
    for (int j = 0; j < 3; ++j) vf[B(f, j)].push_back(f);
  auto normal = [&](const MatX3d& P, int f) {
    return deform::area_normal(P, B(f, 0), B(f, 1), B(f, 2));
  };
  for (int t = 0; t < r.T.rows(); ++t) {
    const double vr = tet_volume(r.rest.row(r.T(t, 0)).transpose(), r.rest.row(r.T(t, 1)).transpose(),
                                 r.rest.row(r.T(t, 2)).transpose(), r.rest.row(r.T(t, 3)).transpose());
    const double vx = tet_volume(r.X.row(r.T(t, 0)).transpose(), r.X.row(r.T(t, 1)).transpose(),
                                 r.X.row(r.T(t, 2)).transpose(), r.X.row(r.T(t, 3)).transpose());
    if (vr * vx > 0) continue;
    os << "inverted tet " << t << ":";
    for (int j = 0; j < 4; ++j) {
      const int v = r.T(t, j);
      os << "\n  vertex " << names.vertex(v) << " at (" << r.X.row(v) << ")";
      if (v >= deformed.rows()) continue;  // made by a split
      os << " deformed (" << deformed.row(v) << ")";
      for (int f : vf[v]) {
        const Vec3 nx = normal(r.X, f), nd = normal(deformed, f);
        os << "\n    tri " << names.face(f) << " (" << names.vertex(B(f, 0)) << " " << names.vertex(B(f, 1)) << " "
           << names.vertex(B(f, 2)) << ") chart "
           << chart_of_face[f] << " " << label_name(labels[f]) << " n_polycube (" << nx.normalized().transpose()
           << ") area " << 0.5 * nx.norm() << " n_deformed (" << nd.normalized().transpose() << ") area "
           << 0.5 * nd.norm();
      }
    }
    os << "\n";
  }
  return os.str();
}

}  // namespace

Distortion isometric_distortion(const MatX3d& rest, const MatX3d& X, const MatX4i& T) {
  Distortion d;
  d.min = std::numeric_limits<double>::infinity();
  double wsum = 0;
  for (int t = 0; t < T.rows(); ++t) {
    Eigen::Matrix3d Dm, Ds;
    for (int m = 0; m < 3; ++m) {
      Dm.col(m) = (rest.row(T(t, m + 1)) - rest.row(T(t, 0))).transpose();
      Ds.col(m) = (X.row(T(t, m + 1)) - X.row(T(t, 0))).transpose();
    }
    const Vec3 s = Eigen::JacobiSVD<Eigen::Matrix3d>(Ds * Dm.inverse()).singularValues();
    const double iso = s[2] > 0 ? std::max(s[0], 1.0 / s[2]) : std::numeric_limits<double>::infinity();
    d.min = std::min(d.min, iso);
    d.max = std::max(d.max, iso);
    d.nearly_flat += iso > kNearlyFlat;
    const double w = std::abs(Dm.determinant());
    d.mean += w * iso;
    wsum += w;
  }
  d.mean = wsum > 0 ? d.mean / wsum : 0;
  if (T.rows() == 0) d.min = 0;
  return d;
}

bool faces_label(const MatX3d& X, int a, int b, int c, int label, double diag) {
  return deform::area_normal(X, a, b, c).dot(label_direction(label)) > 1e-14 * diag * diag;
}

int count_misoriented(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels, double diag) {
  int m = 0;
  for (int f = 0; f < B.rows(); ++f) m += !faces_label(X, B(f, 0), B(f, 1), B(f, 2), labels[f], diag);
  return m;
}

void check_faces(const MatX3i& B, const std::vector<int>& labels, RealizeResult& r) {
  r.planarity_error = 0;
  r.misoriented_faces = 0;
  const double diag = (r.X.colwise().maxCoeff() - r.X.colwise().minCoeff()).norm();
  for (int f = 0; f < B.rows(); ++f) {
    const int k = labels[f] / 2;
    double lo = r.X(B(f, 0), k), hi = lo;
    for (int j = 1; j < 3; ++j) {
      lo = std::min(lo, r.X(B(f, j), k));
      hi = std::max(hi, r.X(B(f, j), k));
    }
    r.planarity_error = std::max(r.planarity_error, (hi - lo) / diag);
  }
  r.misoriented_faces = count_misoriented(r.X, B, labels, diag);
}

bool is_folded(const RealizeResult& r) {
  return !r.success && r.X.rows() > 0 && r.T.rows() > 0 && r.inverted > 0 && r.planarity_error <= 1e-9;
}

namespace {
double signed_volume(const MatX3d& X, int a, int b, int c, int d) {
  return tet_volume(X.row(a), X.row(b), X.row(c), X.row(d));
}

// Vertices made by splitting an interior edge (or face) whose ends lie on one plane sit on the
// chord between plane vertices, i.e. nearly on the plane in the deformed mesh: the tets between
// the chord and the surface are nearly flat, and the first step towards the planes inverts them
// (spot and tet/hand stalled at t = 0). Each such vertex moves inward (against its planes' label
// directions) by the fraction of `len[i]` among 0, 1/32 .. 1/2 that gives its tets the largest
// smallest volume ratio (deformed over rest).
void open_split_vertices(const MatX3d& rest, MatX3d& def, const MatX4i& T, int first,
                         const std::vector<Vec3>& inward, const std::vector<double>& len) {
  std::vector<std::vector<int>> tets(inward.size());
  for (int t = 0; t < T.rows(); ++t)
    for (int j = 0; j < 4; ++j)
      if (T(t, j) >= first) tets[T(t, j) - first].push_back(t);
  for (size_t i = 0; i < inward.size(); ++i) {
    if (inward[i].squaredNorm() == 0) continue;
    const int m = first + static_cast<int>(i);
    const Eigen::RowVector3d start = def.row(m), dir = inward[i].normalized().transpose();
    auto worst = [&] {
      double w = std::numeric_limits<double>::infinity();
      for (int t : tets[i]) {
        const double r = signed_volume(rest, T(t, 0), T(t, 1), T(t, 2), T(t, 3));
        w = std::min(w, signed_volume(def, T(t, 0), T(t, 1), T(t, 2), T(t, 3)) / r);
      }
      return w;
    };
    double best = worst(), best_f = 0;
    for (double f = 1.0 / 32; f <= 0.5; f *= 2) {
      def.row(m) = start + f * len[i] * dir;
      const double w = worst();
      if (w > best) {
        best = w;
        best_f = f;
      }
    }
    def.row(m) = start + best_f * len[i] * dir;
  }
}

// The planes of a labelling (charts of one axis that touch form a plane; its height the mean
// deformed coordinate of its vertices). Returns why there are none ("" when made).
// charts / vcharts: the labelling's charts, and per vertex the charts around it.
std::string make_planes(const MatX3d& deformed, const MatX3i& B, const std::vector<int>& labels, int n, Planes& planes,
                        const Hooks& hooks, Charts& charts, std::vector<std::vector<int>>& vcharts,
                        const MeshNames& names) {
  charts = build_charts(deformed, B, labels);
  vcharts.assign(n, {});
  for (int f = 0; f < B.rows(); ++f)
    for (int j = 0; j < 3; ++j) {
      auto& l = vcharts[B(f, j)];
      const int c = charts.of_face[f];
      if (std::find(l.begin(), l.end(), c) == l.end()) l.push_back(c);
    }
  for (int k = 0; k < 3; ++k) {
    UnionFind uf(charts.count());
    for (int v = 0; v < n; ++v) {
      int first = -1;
      for (int c : vcharts[v])
        if (charts.label[c] / 2 == k) {
          if (first >= 0) uf.unite(c, first);
          first = c;
        }
    }
    std::vector<int> id(charts.count(), -1);
    std::vector<int> label_of_plane;
    for (int c = 0; c < charts.count(); ++c) {
      if (charts.label[c] / 2 != k) continue;
      const int root = uf.find(c);
      if (id[root] < 0) {
        id[root] = planes.count[k]++;
        label_of_plane.push_back(charts.label[c]);
      } else if (label_of_plane[id[root]] != charts.label[c]) {
        // Find a vertex where opposite charts of this plane meet, for the message.
        for (int v = 0; v < n; ++v)
          for (int a : vcharts[v])
            for (int b : vcharts[v])
              if (charts.label[a] / 2 == k && charts.label[b] == (charts.label[a] ^ 1) && uf.find(a) == root)
                return "charts " + std::to_string(a) + " (" + label_name(charts.label[a]) + ") and " +
                       std::to_string(b) + " (" + label_name(charts.label[b]) + ") meet at vertex " +
                       std::to_string(names.vertex(v)) + ": the polycube would have zero thickness there";
        return std::string("opposite charts of axis ") + "XYZ"[k] + " share a plane";
      }
      id[c] = id[root];
    }
    for (int c = 0; c < charts.count(); ++c)
      if (charts.label[c] / 2 == k) id[c] = id[uf.find(c)];
    planes.of_vertex[k].assign(n, -1);
    for (int v = 0; v < n; ++v)
      for (int c : vcharts[v])
        if (charts.label[c] / 2 == k) planes.of_vertex[k][v] = id[c];
    // Heights: mean deformed coordinate of the plane's vertices.
    planes.height[k].assign(planes.count[k], 0.0);
    std::vector<int> cnt(planes.count[k], 0);
    for (int v = 0; v < n; ++v)
      if (planes.of_vertex[k][v] >= 0) {
        planes.height[k][planes.of_vertex[k][v]] += deformed(v, k);
        cnt[planes.of_vertex[k][v]]++;
      }
    for (int p = 0; p < planes.count[k]; ++p) planes.height[k][p] /= std::max(1, cnt[p]);
    {
      // How far the deformed vertices of each plane are from it: large spreads mean a chart that
      // is far from flat, or charts joined into one plane that the deformation put apart.
      std::vector<double> spread(planes.count[k], 0.0);
      for (int v = 0; v < n; ++v)
        if (planes.of_vertex[k][v] >= 0)
          spread[planes.of_vertex[k][v]] = std::max(spread[planes.of_vertex[k][v]],
                                                    std::abs(deformed(v, k) - planes.height[k][planes.of_vertex[k][v]]));
      const double diag = (deformed.colwise().maxCoeff() - deformed.colwise().minCoeff()).norm();
      for (int p = 0; p < planes.count[k]; ++p)
        if (spread[p] > 0.01 * diag)
          hooks.debug(std::string("plane ") + "XYZ"[k] + std::to_string(p) + " at " + std::to_string(planes.height[k][p]) +
                      ": deformed vertices up to " + std::to_string(spread[p] / diag) + " x diag away");
    }
    if (planes.count[k] < 2) return std::string("fewer than two planes normal to ") + "XYZ"[k];
  }

  return "";
}

// The paths of vertices along the polycube's edges: a boundary vertex on two planes (axes i, j)
// lies on an edge along the third axis k, between two corners (on the same two planes and one of
// axis k), linked by boundary edges. Calls f(k, c0, path, c1) for each simple path.
template <class F>
void for_each_edge_path(const MatX3i& B, const Planes& planes, int n, F&& f) {
  auto on = [&](int v) {
    int c = 0;
    for (int k = 0; k < 3; ++k) c += planes.of_vertex[k][v] >= 0;
    return c;
  };
  auto free_axis = [&](int v) {
    for (int k = 0; k < 3; ++k)
      if (planes.of_vertex[k][v] < 0) return k;
    return -1;
  };
  // Neighbours of each edge vertex on its line (the same planes of the two other axes).
  std::vector<std::vector<int>> nb(n);
  auto link = [&](int v, int u) {
    if (on(v) != 2 || on(u) < 2) return;
    const int k = free_axis(v);
    for (int a = 0; a < 3; ++a)
      if (a != k && planes.of_vertex[a][u] != planes.of_vertex[a][v]) return;
    if (on(u) == 2 && free_axis(u) != k) return;
    if (std::find(nb[v].begin(), nb[v].end(), u) == nb[v].end()) nb[v].push_back(u);
  };
  for (int t = 0; t < B.rows(); ++t)
    for (int a = 0; a < 3; ++a) {
      link(B(t, a), B(t, (a + 1) % 3));
      link(B(t, (a + 1) % 3), B(t, a));
    }
  std::vector<char> seen(n, 0);
  for (int s = 0; s < n; ++s) {
    if (seen[s] || on(s) != 2) continue;
    std::vector<int> comp{s}, corners;
    seen[s] = 1;
    bool simple = true;
    for (size_t q = 0; q < comp.size(); ++q) {
      const int v = comp[q];
      if (nb[v].size() != 2) simple = false;
      for (int u : nb[v]) {
        if (on(u) == 3) {
          if (std::find(corners.begin(), corners.end(), u) == corners.end()) corners.push_back(u);
        } else if (!seen[u]) {
          seen[u] = 1;
          comp.push_back(u);
        }
      }
    }
    if (!simple || corners.size() != 2) continue;
    const int c0 = corners[0], c1 = corners[1];
    std::vector<int> path;
    int prev = c0, cur = -1;
    for (int v : comp)
      if (std::find(nb[v].begin(), nb[v].end(), c0) != nb[v].end()) {
        if (cur >= 0) simple = false;
        cur = v;
      }
    while (simple && cur >= 0 && on(cur) == 2 && path.size() <= comp.size()) {
      path.push_back(cur);
      const int next = nb[cur][0] == prev ? nb[cur][1] : nb[cur][0];
      prev = cur;
      cur = next;
    }
    if (simple && cur == c1 && path.size() == comp.size()) f(free_axis(s), c0, path, c1);
  }
}

// The deformed mesh against the polycube's edges (see EdgeOrder): per simple path c0 -> c1 along
// axis k, the sequence of the corners' plane heights and the path's deformed k coordinates must be
// strictly monotone.
EdgeOrder check_edge_order(const MatX3i& B, const Planes& planes, const MatX3d& deformed, const MeshNames& names) {
  const int n = static_cast<int>(deformed.rows());
  EdgeOrder r;
  for_each_edge_path(B, planes, n, [&](int k, int c0, const std::vector<int>& path, int c1) {
    const double h0 = planes.height[k][planes.of_vertex[k][c0]], h1 = planes.height[k][planes.of_vertex[k][c1]];
    r.vertices += static_cast<int>(path.size());
    const double sgn = h1 > h0 ? 1 : -1;
    const int m = static_cast<int>(path.size());
    for (int i = 0; i < m; ++i) {
      const double prev = i == 0 ? h0 : deformed(path[i - 1], k), next = i == m - 1 ? h1 : deformed(path[i + 1], k);
      const double z = deformed(path[i], k);
      if (sgn * (z - prev) > 0 && sgn * (next - z) > 0) continue;
      ++r.out_of_order;
      const bool past0 = !(sgn * (z - h0) > 0), past1 = !(sgn * (h1 - z) > 0);
      if (!past0 && !past1) continue;
      ++r.past_corner;
      if (r.example.empty())
        r.example = "vertex " + std::to_string(names.vertex(path[i])) + " past corner " +
                    std::to_string(names.vertex(past0 ? c0 : c1)) +
                    " along " + "XYZ"[k];
    }
  });
  return r;
}

}  // namespace

RealizeResult realize_polycube(const MatX3d& rest_in, const MatX4i& T_in, const MatX3i& B, const MatX3d& deformed,
                               const std::vector<int>& labels, const RealizeOptions& opt, const Hooks& hooks) {
  if (T_in.rows() == 0) return realize_surface_polycube(rest_in, B, deformed, labels, opt, hooks);
  // The fresh factor of every coupled Newton step faults in huge pages (rocker: 2.1M page faults
  // -> 0.1M, see core/memory.h).
  const CholmodHugePages huge_pages;
  Stopwatch sw;
  RealizeResult r;
  auto fail = [&](const std::string& why) {
    r.success = false;
    r.failure = why;
    r.seconds = sw.seconds();
    return r;
  };
  hooks.report("polycube", 0.0);
  int n = static_cast<int>(rest_in.rows());

  // ---- planes ----
  Planes planes;
  Charts charts;
  std::vector<std::vector<int>> vcharts;
  if (const std::string why = make_planes(deformed, B, labels, n, planes, hooks, charts, vcharts, opt.names);
      !why.empty())
    return fail(why);
  for (int k = 0; k < 3; ++k) r.planes[k] = planes.count[k];
  r.edge_order = check_edge_order(B, planes, deformed, opt.names);
  const EdgeOrder& eo = r.edge_order;
  if (eo.out_of_order > 0)
    hooks.debug(std::to_string(eo.out_of_order) + " of the " + std::to_string(eo.vertices) +
                " vertices of polycube edges are out of order along their edge in the deformed mesh, " +
                std::to_string(eo.past_corner) + " past a corner's plane" +
                (eo.example.empty() ? std::string() : " (e.g. " + eo.example + ")"));

  // Inward direction at a vertex made between input vertices `vs`: against the label of every plane
  // they all lie on (zero if none).
  auto inward_of = [&](std::initializer_list<int> vs) {
    Vec3 in = Vec3::Zero();
    const int v0 = *vs.begin();
    for (int k = 0; k < 3; ++k) {
      const int pl = planes.of_vertex[k][v0];
      bool shared = pl >= 0;
      for (int v : vs) shared = shared && v < static_cast<int>(vcharts.size()) && planes.of_vertex[k][v] == pl;
      if (!shared) continue;
      for (int c : vcharts[v0])
        if (charts.label[c] / 2 == k) {
          in -= label_direction(charts.label[c]);
          break;
        }
    }
    return in;
  };
  // ---- split interior edges whose ends lie on one plane (and, with split_corner_edges, those from
  // a corner to a vertex on no plane) ----
  MatX3d rest = rest_in, def = deformed;
  MatX4i T = T_in;
  {
    const auto bedges = unique_edges(B);
    auto same_plane = [&](int u, int v) {
      for (int k = 0; k < 3; ++k)
        if (planes.of_vertex[k][u] >= 0 && planes.of_vertex[k][u] == planes.of_vertex[k][v]) return true;
      return false;
    };
    std::vector<std::pair<int, int>> cand;
    auto planes_of = [&](int u) {
      int c = 0;
      for (int k = 0; k < 3; ++k) c += planes.of_vertex[k][u] >= 0;
      return c;
    };
    for (auto e : unique_edges(T)) {
      if (std::binary_search(bedges.begin(), bedges.end(), e)) continue;
      if (same_plane(e.first, e.second) ||
          (opt.split_corner_edges && ((planes_of(e.first) == 3 && planes_of(e.second) == 0) ||
                                      (planes_of(e.second) == 3 && planes_of(e.first) == 0))))
        cand.push_back(e);
    }
    const auto made = split_tet_edges(T, n, cand);
    const int nn = n + static_cast<int>(made.size());
    rest.conservativeResize(nn, 3);
    def.conservativeResize(nn, 3);
    std::vector<Vec3> inward(made.size(), Vec3::Zero());
    std::vector<double> len(made.size(), 0.0);
    for (size_t i = 0; i < made.size(); ++i) {
      const auto [u, v] = made[i];
      rest.row(n + static_cast<Eigen::Index>(i)) = 0.5 * (rest.row(u) + rest.row(v));
      def.row(n + static_cast<Eigen::Index>(i)) = 0.5 * (def.row(u) + def.row(v));
      len[i] = (def.row(u) - def.row(v)).norm();
      inward[i] = inward_of({u, v});
    }
    open_split_vertices(rest, def, T, n, inward, len);
    for (int k = 0; k < 3; ++k) planes.of_vertex[k].resize(nn, -1);
    n = nn;
    r.split_edges = static_cast<int>(made.size());
  }
  // ---- split interior faces whose three vertices lie on one plane (their edges are boundary edges:
  // the tets on both sides would have to flatten) at their centroid ----
  {
    auto same_plane3 = [&](int a, int b, int c) {
      for (int k = 0; k < 3; ++k) {
        const int p = planes.of_vertex[k][a];
        if (p >= 0 && planes.of_vertex[k][b] == p && planes.of_vertex[k][c] == p) return true;
      }
      return false;
    };
    std::map<std::array<int, 3>, std::vector<int>> faces;  // sorted face -> tets
    for (int t = 0; t < T.rows(); ++t)
      for (int i = 0; i < 4; ++i) {
        std::array<int, 3> f{T(t, kTetFaces[i][0]), T(t, kTetFaces[i][1]), T(t, kTetFaces[i][2])};
        if (!same_plane3(f[0], f[1], f[2])) continue;
        std::sort(f.begin(), f.end());
        faces[f].push_back(t);
      }
    std::vector<char> used(T.rows(), 0);
    std::vector<std::array<int, 4>> added;
    std::vector<Vec3> new_rest, new_def, face_inward;
    std::vector<double> face_len;
    for (const auto& [f, tets] : faces) {
      if (tets.size() != 2 || used[tets[0]] || used[tets[1]]) continue;  // boundary face, or done
      const int m = n + static_cast<int>(new_rest.size());
      new_rest.push_back((rest.row(f[0]) + rest.row(f[1]) + rest.row(f[2])).transpose() / 3);
      new_def.push_back((def.row(f[0]) + def.row(f[1]) + def.row(f[2])).transpose() / 3);
      face_inward.push_back(inward_of({f[0], f[1], f[2]}));
      face_len.push_back(((def.row(f[0]) - def.row(f[1])).norm() + (def.row(f[1]) - def.row(f[2])).norm() +
                          (def.row(f[2]) - def.row(f[0])).norm()) / 3);
      for (int t : tets) {
        used[t] = 1;
        const std::array<int, 4> orig{T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
        // Three tets: each face vertex in turn replaced by the centroid (same orientation).
        bool first = true;
        for (int fv : f) {
          std::array<int, 4> nt = orig;
          for (int& x : nt)
            if (x == fv) x = m;
          if (first) {
            for (int j = 0; j < 4; ++j) T(t, j) = nt[j];
            first = false;
          } else {
            added.push_back(nt);
          }
        }
      }
      r.split_faces++;
    }
    if (!new_rest.empty()) {
      const int nt = static_cast<int>(T.rows());
      T.conservativeResize(nt + static_cast<Eigen::Index>(added.size()), 4);
      for (size_t i = 0; i < added.size(); ++i)
        for (int j = 0; j < 4; ++j) T(nt + static_cast<Eigen::Index>(i), j) = added[i][j];
      const int nn = n + static_cast<int>(new_rest.size());
      rest.conservativeResize(nn, 3);
      def.conservativeResize(nn, 3);
      for (size_t i = 0; i < new_rest.size(); ++i) {
        rest.row(n + static_cast<Eigen::Index>(i)) = new_rest[i].transpose();
        def.row(n + static_cast<Eigen::Index>(i)) = new_def[i].transpose();
      }
      for (int k = 0; k < 3; ++k) planes.of_vertex[k].resize(nn, -1);
      open_split_vertices(rest, def, T, n, face_inward, face_len);
      n = nn;
    }
  }
  if (r.split_edges + r.split_faces > 0)
    hooks.debug("split " + std::to_string(r.split_edges) + " interior edges and " + std::to_string(r.split_faces) +
                " interior faces lying on a plane");
  hooks.report("polycube", 0.1);

  Realizer solver(rest, T, planes, opt, hooks);
  if (!solver.ok()) return fail("the ARAP system of the realization is not positive definite");

  // ---- starts ----
  std::vector<std::string> starts;
  if (opt.start == "continuation" || opt.start == "auto") starts.push_back("continuation");
  if (opt.start == "eq17" || opt.start == "auto") starts.push_back("eq17");
  if (opt.start == "previous") starts.push_back("previous");
  if (opt.start == "penalty") starts.push_back("penalty");
  if (starts.empty())
    return fail("unknown realization start '" + opt.start + "' (continuation, eq17, auto, previous, penalty)");
  const double diag0 = (def.colwise().maxCoeff() - def.colwise().minCoeff()).norm();
  // Boundary triangles not facing their label's direction (or of zero area) in X.
  auto misoriented = [&](const MatX3d& X) {
    int count = 0;
    for (int f = 0; f < B.rows(); ++f) {
      const Vec3 N = deform::area_normal(X, B(f, 0), B(f, 1), B(f, 2));
      count += !(N.dot(label_direction(labels[f])) > 1e-14 * diag0 * diag0);
    }
    return count;
  };
  // One start, through to the ARAP minimum: a candidate, or the reason it failed.
  struct Attempt {
    bool ok = false;
    MatX3d X;
    double arap = 0;
    int flipped = 0, ut = 0, it = 0;
    std::string failure;
    MatX3d tangled;    ///< failed after untangling: the state it reached
    int inverted = 0;  ///< and its inverted tets
    bool over_budget = false;  ///< eq17 start: untangled beyond opt.eq17_budget (see RealizeOptions)
  };
  // Set once the continuation start has succeeded (auto: the eq17 start, over its budget, stops).
  std::atomic<bool> continuation_succeeded{false};
  const bool budgeted = starts.size() == 2 && opt.eq17_budget >= 0;
  // The local untangling first (RealizeOptions::local_first): true, with X and `inverted` its
  // result, when it leaves at most local_first tets inverted (the global untangling is then
  // skipped: the tets it leaves are flat, det ~ 0, where the elliptic energy's eps schedule has
  // nothing to work with); otherwise X stays as it was.
  auto local_first = [&](const Realizer& solver, MatX3d& X, int& inverted, int& steps) {
    if (opt.local_first < 0) return false;
    MatX3d Y = X;
    int left = inverted;
    steps += solver.untangle_local(Y, left);
    if (left > opt.local_first) return false;
    X = std::move(Y);
    inverted = left;
    return true;
  };
  auto attempt = [&](const std::string& name, Realizer& solver, const Hooks& log) {
    Attempt a;
    MatX3d X = def;
    int ut = 0;
    int elliptic = 0;  // eq17: elliptic untangling iterations before the current call
    auto abandoned = [&] { return a.over_budget && continuation_succeeded.load(); };
    if (name == "eq17" && budgeted)
      solver.set_stop([&](int it) {
        a.over_budget = a.over_budget || elliptic + it > opt.eq17_budget;
        return abandoned();
      });
    struct ClearStop {  // the lambda above refers to this call's locals
      Realizer& s;
      ~ClearStop() { s.set_stop(nullptr); }
    } clear_stop{solver};
    if (name == "eq17" || name == "previous") {
      int inverted = 0;
      if (name == "previous") {
        // An earlier realization's state, on the planes but for moved heights, with at most a few
        // tets inverted: untangled where they are (a global ARAP step or the elliptic untangling
        // with free heights would undo what that realization reached: humanoid, 5 inverted after
        // landing, 5324 after them).
        solver.land(X);
        inverted = count_inverted(X, T, solver.arap_rest());
        log.debug("previous realization landed on the planes: " + std::to_string(inverted) + " tets inverted");
        if (inverted > 0) ut += solver.untangle_local(X, inverted);
      } else {
        if (!relax_eq17(B, T, planes, X)) {
          a.failure = "the relaxation of Eq. 17 failed";
          return a;
        }
        ut = solver.untangle(X, inverted);
        const bool local_done = inverted > 0 && local_first(solver, X, inverted, ut);
        if (inverted > 0 && !local_done) {
          elliptic = solver.untangle_elliptic(X, inverted);
          ut += elliptic;
          if (budgeted && elliptic > opt.eq17_budget) a.over_budget = true;
        }
        // Heights free, the mesh may shrink instead of untangling (humanoid, rocker): again with
        // them fixed. (Not for the previous start: its few inverted tets are flat, det ~ 0, where
        // the elliptic energy's eps schedule has nothing to work with.)
        if (inverted > 0) a.over_budget = true;
        if (inverted > 0 && !local_done && !abandoned()) ut += solver.untangle_elliptic(X, inverted, Mode::Pinned);
        if (inverted > 0 && !local_done && !abandoned()) ut += solver.untangle_local(X, inverted);
        if (abandoned()) {
          log.debug("realization from the eq17 start: abandoned after " + std::to_string(ut) +
                    " untangling steps (" + std::to_string(inverted) +
                    " tets inverted), past its budget, the continuation start having succeeded");
          a.failure = "the eq17 start was abandoned (the continuation start succeeded)";
          return a;
        }
      }
      if (inverted > 0) {
        log.debug("realization from the " + name + " start: " + std::to_string(inverted) +
                  " tets still inverted after " + std::to_string(ut) + " untangling steps");
        a.failure = std::to_string(inverted) + " tets remain inverted after " + std::to_string(ut) +
                    (name == "eq17" ? " untangling steps from the relaxation of Eq. 17"
                                    : " untangling steps from the previous realization");
        a.tangled = std::move(X);
        a.inverted = inverted;
        return a;
      }
      solver.set_barrier_weight(opt.barrier_weight);
      solver.set_barrier_scale(X);
    } else {
      const int inv = count_inverted(X, T, solver.arap_rest());
      if (inv > 0) {
        a.failure = "the deformed mesh has " + std::to_string(inv) + " inverted tets";
        return a;
      }
      solver.set_barrier_scale(X);
      // Where the continuation stalls on nearly flat tets, a stronger barrier may keep them open:
      // retried with the barrier weight x10, x100, ... (opt.continuation_retries times).
      bool landed = false;
      double f = 1;
      const int continuations = name == "penalty" ? 0 : 1 + opt.continuation_retries;  // "penalty": none
      for (int k = 0; k < continuations && !landed; ++k, f *= 10) {
        X = def;
        solver.set_barrier_weight(f * opt.barrier_weight);
        int steps = 0;
        landed = solver.continuation(X, steps);
        ut += steps;
        if (!landed)
          log.debug("continuation stalled with barrier weight " + std::to_string(f * opt.barrier_weight) + ": " +
                    solver.blocked());
      }
      // The penalty path from the deformed mesh; if it too leaves tets inverted, its state
      // competes with the forced landing's below (the fewer inverted tets; on a tie, its own).
      MatX3d penalty_state;
      int penalty_inverted = 0;
      if (!landed && (name == "penalty" || opt.penalty_path)) {
        MatX3d Y = def;
        solver.set_barrier_weight(opt.barrier_weight);
        int steps = 0;
        penalty_inverted = solver.penalty_path(Y, steps);
        ut += steps;
        landed = penalty_inverted == 0;
        if (landed) {
          X = std::move(Y);
        } else {
          penalty_state = std::move(Y);
          if (name == "penalty") {
            a.failure = "the penalty path left " + std::to_string(penalty_inverted) + " tets inverted";
            a.tangled = std::move(penalty_state);
            a.inverted = penalty_inverted;
            return a;
          }
        }
      }
      if (!landed) {
        solver.land(X);
        int inverted = 0;
        int u2 = solver.untangle(X, inverted);
        if (inverted > 0 && !local_first(solver, X, inverted, u2)) {
          u2 += solver.untangle_elliptic(X, inverted);
          // Heights free, the mesh may shrink instead of untangling (humanoid, rocker): again with them fixed.
          if (inverted > 0) u2 += solver.untangle_elliptic(X, inverted, Mode::Pinned);
          if (inverted > 0) u2 += solver.untangle_local(X, inverted);
        }
        log.debug("realization by continuation stalled (" + solver.blocked() + "); after landing on the planes, " +
                  std::to_string(u2) + " untangling steps leave " + std::to_string(inverted) + " tets inverted");
        ut += u2;
        if (inverted > 0) {
          a.failure = "moving the deformed mesh onto the planes: " + solver.blocked() + "; " +
                      std::to_string(inverted) + " tets remain inverted after landing and untangling";
          if (penalty_state.rows() > 0 && penalty_inverted <= inverted) {
            a.failure += " (" + std::to_string(penalty_inverted) + " after the penalty path)";
            a.tangled = std::move(penalty_state);
            a.inverted = penalty_inverted;
          } else {
            a.tangled = std::move(X);
            a.inverted = inverted;
          }
          return a;
        }
      }
    }
    solver.open_flat(X);
    // A boundary triangle that faces away from its label on the planes stays so: it is a face of
    // one tet, whose volume is its signed area times the height of the fourth vertex over its
    // plane, and the ARAP iterations keep its three vertices on that plane and every tet
    // positive, so the area cannot pass through zero. The attempt then fails whatever they do, and
    // they only prepare the retries' start: to RealizeOptions::folded_tolerance (see there).
    a.flipped = misoriented(X);
    if (a.flipped > 0)
      log.debug("realization from the " + name + " start: " + std::to_string(a.flipped) +
                " boundary triangles face away from their chart's direction on the planes; ARAP iterations to " +
                std::to_string(opt.folded_tolerance));
    a.it = solver.minimize(X, Mode::Reduced, opt.max_iterations, a.flipped > 0 ? opt.folded_tolerance : -1);
    a.flipped = misoriented(X);
    a.arap = deform::arap_energy(X, T, solver.arap_rest(), 1.0, nullptr, nullptr);
    a.ut = ut;
    log.debug("realization from the " + name + " start: ARAP " + std::to_string(a.arap) + " after " +
              std::to_string(ut) + " untangling/continuation steps and " + std::to_string(a.it) +
              " ARAP iterations, " + std::to_string(a.flipped) + " misoriented boundary triangles, " +
              std::to_string(sw.seconds()) + " s");
    if (a.flipped > 0)
      a.failure = std::to_string(a.flipped) + " boundary triangles do not face their chart's direction";
    a.ok = true;
    a.X = std::move(X);
    return a;
  };
  std::vector<Attempt> attempts(starts.size());
  if (starts.size() == 2) {
    // The two starts are independent: side by side, the second with its own solver and its
    // messages held back until the first is done, so that the log reads as if they ran in turn.
    std::vector<std::pair<LogLevel, std::string>> held;
    Hooks second;
    second.log = [&held](LogLevel l, const std::string& m) { held.emplace_back(l, m); };
    run_pair([&](int k) {
      if (k == 0) {
        attempts[0] = attempt(starts[0], solver, hooks);
        if (attempts[0].ok && attempts[0].flipped == 0) continuation_succeeded = true;
      } else {
        Realizer other(rest, T, planes, opt, second);
        if (other.ok())
          attempts[1] = attempt(starts[1], other, second);
        else
          attempts[1].failure = "the ARAP system of the realization is not positive definite";
      }
    });
    for (const auto& [level, m] : held)
      if (hooks.log) hooks.log(level, m);
  } else {
    attempts[0] = attempt(starts[0], solver, hooks);
  }
  bool have = false;
  int have_flipped = 0;
  std::string failures;
  for (size_t i = 0; i < starts.size(); ++i) {
    Attempt& a = attempts[i];
    if (!a.failure.empty()) failures += (failures.empty() ? "" : "; ") + a.failure;
    if (!a.ok) continue;
    // Past its budget, the eq17 start competes only when the continuation failed (whether it got
    // that far before the continuation finished is a matter of timing).
    if (a.over_budget && continuation_succeeded.load()) {
      hooks.debug("realization from the eq17 start: not compared (past its untangling budget)");
      continue;
    }
    // A valid candidate (every boundary triangle facing its label) beats any invalid one.
    if (!have || (a.flipped == 0 && have_flipped > 0) || ((a.flipped == 0) == (have_flipped == 0) && a.arap < r.arap)) {
      have = true;
      have_flipped = a.flipped;
      r.X = std::move(a.X);
      r.arap = a.arap;
      r.start = starts[i];
      r.untangle_iterations = a.ut;
      r.iterations = a.it;
    }
  }
  if (!have) {
    // No start untangled: the state with the fewest inverted tets goes back with the failure, so
    // that the caller can relabel the boundary triangles that face the wrong way there.
    // The continuation start's state comes first when it has one: every tet stayed positive on its
    // way to the planes (continuation or penalty path), so its inverted tets are the few the
    // layout pins, where the eq17 start's state comes from an untangling that may have shrunk the
    // mesh (homer, --tets 20000: eq17 left 13 inverted, the penalty path 16; the retries from
    // the eq17 state failed after 11 edge collapses, those from the penalty path's realized it).
    Attempt* least = nullptr;
    std::pair<int, int> least_key;
    for (size_t i = 0; i < attempts.size(); ++i) {
      Attempt& a = attempts[i];
      const std::pair<int, int> key{starts[i] == "eq17" ? 1 : 0, a.inverted};
      if (a.tangled.rows() > 0 && (!least || key < least_key)) least = &a, least_key = key;
    }
    if (least) {
      r.X = std::move(least->tangled);
      r.rest = rest;
      r.T = T;
      r.inverted = least->inverted;
      check_faces(B, labels, r);
      if (r.inverted > 0 && r.inverted <= 3 && hooks.log)
        hooks.debug(describe_inverted(r, B, labels, charts.of_face, deformed, opt.names));
    }
    return fail(failures);
  }
  hooks.report("polycube", 0.95);

  // ---- checks ----
  r.rest = std::move(rest);
  r.T = std::move(T);
  r.inverted = count_inverted(r.X, r.T, solver.arap_rest());
  check_faces(B, labels, r);
  r.isometric = isometric_distortion(r.rest, r.X, r.T);
  r.seconds = sw.seconds();
  hooks.report("polycube", 1.0);
  if (r.inverted > 0) return fail(std::to_string(r.inverted) + " tets are inverted in the polycube");
  if (r.misoriented_faces > 0)
    return fail(std::to_string(r.misoriented_faces) + " boundary triangles do not face their chart's direction");
  r.success = true;
  return r;
}

int untangle_tets_locally(const MatX3d& rest, const MatX4i& T, const std::array<std::vector<char>, 3>& fixed, MatX3d& X,
                          int& inverted, int rings, int max_sweeps) {
  return untangle_tets_locally(deform::ArapRest::build(rest, T), T, fixed, X, inverted, rings, max_sweeps);
}

int untangle_tets_locally(const deform::ArapRest& reference, const MatX4i& T,
                          const std::array<std::vector<char>, 3>& fixed, MatX3d& X, int& inverted, int rings,
                          int max_sweeps, double flat) {
  return untangle_locally(
      T, reference, [&](int v, int k) { return fixed[k][v] != 0; }, X, inverted, rings, max_sweeps, flat);
}

}  // namespace polycube::chart
