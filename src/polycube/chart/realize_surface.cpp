// Realization of an exact surface polycube (surface mode): see realize.h.
#include <Eigen/SVD>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "polycube/chart/labeling.h"
#include "polycube/chart/realize.h"
#include "polycube/core/topology.h"
#include "polycube/deform/energies.h"

namespace polycube::chart {

using SpMat = Eigen::SparseMatrix<double>;

std::vector<int> border_directions(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels,
                                   std::vector<std::array<int, 2>>* edges) {
  std::vector<int> dir;
  if (edges) edges->clear();
  for (const auto& loop : border_loops(F)) {
    const int n = static_cast<int>(loop.size());
    std::vector<int> d(n);
    for (int i = 0; i < n; ++i) {
      const int k = labels[loop[i][2]] / 2;
      const Vec3 e = (X.row(loop[i][1]) - X.row(loop[i][0])).transpose();
      int best = -1;
      for (int m = 0; m < 3; ++m)
        if (m != k && (best < 0 || std::abs(e[m]) > std::abs(e[best]))) best = m;
      d[i] = best;
    }
    // Zigzag straightening: an edge between two edges of another, common direction takes it
    // (when that direction lies in its chart), until nothing changes.
    for (bool changed = n > 2; changed;) {
      changed = false;
      for (int i = 0; i < n; ++i) {
        const int p = d[(i + n - 1) % n], q = d[(i + 1) % n];
        if (p == q && p != d[i] && p != labels[loop[i][2]] / 2) {
          d[i] = p;
          changed = true;
        }
      }
    }
    for (int i = 0; i < n; ++i) {
      dir.push_back(d[i]);
      if (edges) edges->push_back({loop[i][0], loop[i][1]});
    }
  }
  return dir;
}

Distortion isometric_distortion_surface(const MatX3d& rest, const MatX3d& X, const MatX3i& F) {
  Distortion d;
  d.min = F.rows() ? std::numeric_limits<double>::infinity() : 0;
  double wsum = 0;
  for (int f = 0; f < F.rows(); ++f) {
    Eigen::Matrix<double, 3, 2> Dm, Ds;
    for (int m = 0; m < 2; ++m) {
      Dm.col(m) = (rest.row(F(f, m + 1)) - rest.row(F(f, 0))).transpose();
      Ds.col(m) = (X.row(F(f, m + 1)) - X.row(F(f, 0))).transpose();
    }
    // Singular values of the map between the two triangles: sqrt of the eigenvalues of the
    // pull-back metric Ds^T Ds relative to Dm^T Dm.
    const Eigen::Matrix2d G0 = Dm.transpose() * Dm, G1 = Ds.transpose() * Ds;
    const double a = std::sqrt(std::max(0.0, G0.determinant()));
    if (!(a > 0)) continue;
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::Matrix2d> es(G1, G0);
    const Eigen::Vector2d ev = es.eigenvalues();
    const double s1 = std::sqrt(std::max(0.0, ev[1])), s2 = std::sqrt(std::max(0.0, ev[0]));
    const double iso = s2 > 0 ? std::max(s1, 1.0 / s2) : std::numeric_limits<double>::infinity();
    d.min = std::min(d.min, iso);
    d.max = std::max(d.max, iso);
    d.mean += a * iso;
    wsum += a;
  }
  d.mean = wsum > 0 ? d.mean / wsum : 0;
  return d;
}

RealizeResult realize_surface_polycube(const MatX3d& rest, const MatX3i& F, const MatX3d& deformed,
                                       const std::vector<int>& labels, const RealizeOptions& opt,
                                       const Hooks& hooks) {
  Stopwatch sw;
  RealizeResult r;
  r.start = "surface";
  const int n = static_cast<int>(rest.rows());
  hooks.report("polycube", 0.0);

  // ---- planes: per axis, vertices sharing that coordinate ----
  // Charts of axis k: their triangles' vertices. Border edges of open surfaces: each runs along
  // one axis d (border_directions), so its two vertices also share the third coordinate.
  std::array<UnionFind, 3> uf{UnionFind(n), UnionFind(n), UnionFind(n)};
  std::array<std::vector<char>, 3> constrained;
  for (auto& c : constrained) c.assign(n, 0);
  for (int f = 0; f < F.rows(); ++f) {
    const int k = labels[f] / 2;
    for (int j = 0; j < 3; ++j) constrained[k][F(f, j)] = 1;
    uf[k].unite(F(f, 0), F(f, 1));
    uf[k].unite(F(f, 0), F(f, 2));
  }
  std::vector<std::array<int, 2>> bedges;
  const std::vector<int> bdir = border_directions(deformed, F, labels, &bedges);
  {
    // The face of each border edge, for its chart axis.
    std::map<std::pair<int, int>, int> face_of;
    for (int f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) face_of[{F(f, k), F(f, (k + 1) % 3)}] = f;
    for (size_t i = 0; i < bedges.size(); ++i) {
      const int k = labels[face_of[{bedges[i][0], bedges[i][1]}]] / 2;
      const int m = 3 - k - bdir[i];
      constrained[m][bedges[i][0]] = constrained[m][bedges[i][1]] = 1;
      uf[m].unite(bedges[i][0], bedges[i][1]);
    }
  }
  // Per axis: unknown index of every vertex (its plane's, or its own), plane heights = mean of
  // the deformed coordinates of the plane's vertices.
  std::array<std::vector<int>, 3> var;
  std::array<int, 3> nvar{};
  Eigen::MatrixXd dummy;
  std::array<Eigen::VectorXd, 3> y;
  for (int k = 0; k < 3; ++k) {
    var[k].assign(n, -1);
    std::map<int, int> plane_var;
    for (int v = 0; v < n; ++v) {
      if (!constrained[k][v]) continue;
      const int root = uf[k].find(v);
      auto it = plane_var.find(root);
      if (it == plane_var.end()) it = plane_var.emplace(root, nvar[k]++).first;
      var[k][v] = it->second;
    }
    r.planes[k] = nvar[k];
    for (int v = 0; v < n; ++v)
      if (var[k][v] < 0) var[k][v] = nvar[k]++;
    y[k] = Eigen::VectorXd::Zero(nvar[k]);
    Eigen::VectorXd count = Eigen::VectorXd::Zero(nvar[k]);
    for (int v = 0; v < n; ++v) {
      y[k][var[k][v]] += deformed(v, k);
      count[var[k][v]] += 1;
    }
    y[k] = y[k].cwiseQuotient(count);
  }
  auto positions = [&] {
    MatX3d X(n, 3);
    for (int v = 0; v < n; ++v)
      for (int k = 0; k < 3; ++k) X(v, k) = y[k][var[k][v]];
    return X;
  };

  // ---- ARAP local/global with the constraints substituted ----
  // E = sum_t w_t sum_{i in t} (1/3) 0.5 |F_t - R_i P_t|^2 (deform::surface_arap_energy). With the
  // rotations fixed it is, per axis, 0.5 x^T L x - b^T x with L = sum_t w_t G_t G_t^T.
  const deform::SurfaceArapRest ar = deform::SurfaceArapRest::build(rest, F);
  std::vector<Eigen::Triplet<double>> trip;
  for (int f = 0; f < F.rows(); ++f) {
    const Eigen::Matrix3d K = ar.w[f] * ar.grad[f] * ar.grad[f].transpose();
    for (int p = 0; p < 3; ++p)
      for (int q = 0; q < 3; ++q) trip.emplace_back(F(f, p), F(f, q), K(p, q));
  }
  SpMat L(n, n);
  L.setFromTriplets(trip.begin(), trip.end());
  std::array<SpMat, 3> S;
  std::array<Eigen::SimplicialLDLT<SpMat>, 3> solver;
  double reg = 0;
  for (int k = 0; k < n; ++k) reg += L.coeff(k, k);
  reg = 1e-9 * reg / std::max(1, n);
  for (int k = 0; k < 3; ++k) {
    std::vector<Eigen::Triplet<double>> st;
    for (int v = 0; v < n; ++v) st.emplace_back(v, var[k][v], 1.0);
    S[k].resize(n, nvar[k]);
    S[k].setFromTriplets(st.begin(), st.end());
    SpMat A = S[k].transpose() * L * S[k];
    SpMat I(nvar[k], nvar[k]);
    I.setIdentity();
    A += reg * I;  // the translation along k is free: a tiny pull towards the current values fixes it
    solver[k].compute(A);
    if (solver[k].info() != Eigen::Success) {
      r.failure = "the surface realization system could not be factorized";
      r.seconds = sw.seconds();
      return r;
    }
  }
  MatX3d X = positions();
  double e_prev = deform::surface_arap_energy(X, F, ar, 1.0, nullptr, nullptr);
  const double e_start = e_prev;
  for (int it = 0; it < opt.max_iterations; ++it) {
    // Local step: rotations per vertex; right-hand sides b_p = sum_t w_t Rbar_t g_p.
    Eigen::VectorXd g = Eigen::VectorXd::Zero(3 * n);
    deform::surface_arap_energy(X, F, ar, 1.0, &g, nullptr);
    // g = L x - b, so b = L x - g.
    for (int k = 0; k < 3; ++k) {
      Eigen::VectorXd xk = X.col(k);
      Eigen::VectorXd gk(n);
      for (int v = 0; v < n; ++v) gk[v] = g[3 * v + k];
      const Eigen::VectorXd b = L * xk - gk;
      y[k] = solver[k].solve(S[k].transpose() * b + reg * y[k]);
    }
    X = positions();
    const double e = deform::surface_arap_energy(X, F, ar, 1.0, nullptr, nullptr);
    r.iterations = it + 1;
    hooks.report("polycube", 0.9 * (it + 1) / opt.max_iterations);
    if (e_prev - e < opt.tolerance * std::max(1e-300, e_start)) {
      e_prev = e;
      break;
    }
    e_prev = e;
  }
  hooks.debug("surface realization: ARAP " + std::to_string(e_start) + " -> " + std::to_string(e_prev) + " in " +
              std::to_string(r.iterations) + " local/global iterations");

  // ---- checks ----
  r.rest = rest;
  r.T.resize(0, 4);
  r.X = std::move(X);
  r.arap = e_prev;
  const double diag = (r.X.colwise().maxCoeff() - r.X.colwise().minCoeff()).norm();
  for (int f = 0; f < F.rows(); ++f) {
    const int k = labels[f] / 2;
    double lo = r.X(F(f, 0), k), hi = lo;
    for (int j = 1; j < 3; ++j) {
      lo = std::min(lo, r.X(F(f, j), k));
      hi = std::max(hi, r.X(F(f, j), k));
    }
    r.planarity_error = std::max(r.planarity_error, (hi - lo) / diag);
    const Vec3 N = deform::area_normal(r.X, F(f, 0), F(f, 1), F(f, 2));
    if (!(N.dot(label_direction(labels[f])) > 1e-14 * diag * diag)) r.misoriented_faces++;
  }
  for (size_t i = 0; i < bedges.size(); ++i) {
    const Vec3 e = (r.X.row(bedges[i][1]) - r.X.row(bedges[i][0])).transpose();
    if (!(e[bdir[i]] != 0)) r.degenerate_border_edges++;
  }
  r.isometric = isometric_distortion_surface(rest, r.X, F);
  r.seconds = sw.seconds();
  hooks.report("polycube", 1.0);
  if (r.misoriented_faces > 0) {
    r.failure = std::to_string(r.misoriented_faces) + " triangles do not face their chart's direction in the polycube";
    return r;
  }
  if (r.degenerate_border_edges > 0) {
    r.failure = std::to_string(r.degenerate_border_edges) + " border edges have zero length in the polycube";
    return r;
  }
  r.success = true;
  return r;
}

}  // namespace polycube::chart
