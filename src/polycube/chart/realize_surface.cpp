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
#include "polycube/core/lbfgs.h"
#include "polycube/core/topology.h"
#include "polycube/deform/energies.h"

namespace polycube::chart {

using SpMat = Eigen::SparseMatrix<double>;

std::vector<int> border_directions(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels,
                                   std::vector<std::array<int, 3>>* edges) {
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
      if (edges) edges->push_back(loop[i]);
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
    d.nearly_flat += iso > kNearlyFlat;
    d.mean += a * iso;
    wsum += a;
  }
  d.mean = wsum > 0 ? d.mean / wsum : 0;
  return d;
}

namespace {
double chi(double D, double eps) { return 0.5 * (D + std::sqrt(eps * eps + D * D)); }

// Elliptic untangling energy (Garanzha et al. 2021, 2D) of one triangle laid out in its chart's
// plane: corners q (mirrored for negative labels so that facing the label = positive area), rest
// shape Dm_inv, lengths divided by scale, weight w. det: the Jacobian's determinant; gq (optional):
// the gradient with respect to each corner.
double untangle_triangle(const Eigen::Vector2d q[3], const Eigen::Matrix2d& Dm_inv, double scale, double w, double eps,
                         double theta, double& det, Eigen::Vector2d* gq) {
  Eigen::Matrix2d Ds;
  Ds << q[1] - q[0], q[2] - q[0];
  const Eigen::Matrix2d J = Ds * Dm_inv / scale;
  const double D = J.determinant();
  det = D;
  const double c = chi(D, eps), r2 = std::sqrt(eps * eps + D * D);
  const double tr = J.squaredNorm();
  const double E = w * ((1 - theta) * tr / c + theta * (1 + D * D) / c);
  if (!gq) return E;
  Eigen::Matrix2d cof;
  cof << J(1, 1), -J(1, 0), -J(0, 1), J(0, 0);
  const double dc = c / r2;  // d chi / dD
  const Eigen::Matrix2d dJ = w * ((1 - theta) * (2 * J / c - tr / (c * c) * dc * cof) +
                                  theta * (2 * D / c - (1 + D * D) / (c * c) * dc) * cof);
  const Eigen::Matrix2d G = dJ * Dm_inv.transpose() / scale;  // d E / d Ds
  gq[0] = -(G.col(0) + G.col(1));
  gq[1] = G.col(0);
  gq[2] = G.col(1);
  return E;
}
}  // namespace

RealizeResult realize_surface_polycube(const MatX3d& rest, const MatX3i& F, const MatX3d& deformed,
                                       const std::vector<int>& labels, const RealizeOptions& opt,
                                       const Hooks& hooks, const MatX3d* start) {
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
  std::vector<std::array<int, 3>> bedges;  // (a, b, face)
  const std::vector<int> bdir = border_directions(deformed, F, labels, &bedges);
  for (size_t i = 0; i < bedges.size(); ++i) {
    const int m = 3 - labels[bedges[i][2]] / 2 - bdir[i];
    constrained[m][bedges[i][0]] = constrained[m][bedges[i][1]] = 1;
    uf[m].unite(bedges[i][0], bedges[i][1]);
  }
  // Per axis: unknown index of every vertex (its plane's, or its own), plane heights = mean of
  // the deformed coordinates of the plane's vertices.
  std::array<std::vector<int>, 3> var;
  std::array<int, 3> nvar{};
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
  const double diag0 = (deformed.colwise().maxCoeff() - deformed.colwise().minCoeff()).norm();
  auto misoriented = [&](const MatX3d& X) { return count_misoriented(X, F, labels, diag0); };
  // Local/global iterations from y. guard: an iterate with more misoriented triangles than the
  // best so far ends the run (the best is kept).
  auto arap = [&](std::array<Eigen::VectorXd, 3>& yy, bool guard, int& iterations) {
    y = yy;
    MatX3d X = positions();
    Eigen::VectorXd g = Eigen::VectorXd::Zero(3 * n);
    double e_prev = deform::surface_arap_energy(X, F, ar, 1.0, &g, nullptr);
    const double e_start = e_prev;
    int bad = guard ? misoriented(X) : 0;
    iterations = 0;
    for (int it = 0; it < opt.max_iterations; ++it) {
      const std::array<Eigen::VectorXd, 3> y_old = y;
      for (int k = 0; k < 3; ++k) {
        // g = L x - b (rotations fixed), so b = L x - g.
        Eigen::VectorXd gk(n);
        for (int v = 0; v < n; ++v) gk[v] = g[3 * v + k];
        const Eigen::VectorXd b = L * Eigen::VectorXd(X.col(k)) - gk;
        y[k] = solver[k].solve(S[k].transpose() * b + reg * y[k]);
      }
      MatX3d Xn = positions();
      if (guard) {
        // A step that folds a triangle is shortened (halved up to 8 times; positions are linear
        // in y); if every length folds, the iterations end.
        int m = misoriented(Xn);
        const std::array<Eigen::VectorXd, 3> y_full = y;
        for (int h = 1; m > bad && h <= 8; ++h) {
          const double t = std::ldexp(1.0, -h);
          for (int k = 0; k < 3; ++k) y[k] = y_old[k] + t * (y_full[k] - y_old[k]);
          Xn = positions();
          m = misoriented(Xn);
        }
        if (m > bad) {
          y = y_old;
          break;
        }
        bad = m;
      }
      X = std::move(Xn);
      g.setZero();
      const double e = deform::surface_arap_energy(X, F, ar, 1.0, &g, nullptr);
      iterations = it + 1;
      hooks.report("polycube", 0.9 * (it + 1) / opt.max_iterations);
      const bool done = e_prev - e < opt.tolerance * std::max(1e-300, e_start);
      e_prev = e;
      if (done) break;
    }
    yy = y;
    return X;
  };
  std::vector<std::vector<int>> vf(n);
  for (int f = 0; f < F.rows(); ++f)
    for (int j = 0; j < 3; ++j) vf[F(f, j)].push_back(f);
  // The elliptic energy of the triangles around vertex v with v at p (the others at X), each laid
  // out in its chart's plane (mirrored for negative labels), and its gradient in 3D coordinates.
  struct Elliptic {
    std::vector<Eigen::Matrix2d> Dm_inv;
    double scale = 1, theta = 1.0 / 128;
  };
  auto star = [&](const MatX3d& X, const Elliptic& el, int v, const Vec3& p, double eps, Vec3* g) {
    double E = 0;
    if (g) g->setZero();
    for (int f : vf[v]) {
      const int k = labels[f] / 2, a = (k + 1) % 3, b = (k + 2) % 3;
      const double sg = labels[f] % 2 ? -1.0 : 1.0;
      Eigen::Vector2d q[3], gq[3];
      int corner = 0;
      for (int j = 0; j < 3; ++j) {
        const int u = F(f, j);
        if (u == v) corner = j;
        const Vec3 x = u == v ? p : Vec3(X.row(u).transpose());
        q[j] = Eigen::Vector2d(sg * x[a], x[b]);
      }
      double D;
      E += untangle_triangle(q, el.Dm_inv[f], el.scale, ar.w[f], eps, el.theta, D, g ? gq : nullptr);
      if (!g) continue;
      (*g)[a] += sg * gq[corner][0];
      (*g)[b] += gq[corner][1];
    }
    return E;
  };
  // The Jacobian determinant of triangle f's map (rest -> its chart's plane, scaled).
  auto triangle_det = [&](const MatX3d& X, const Elliptic& el, int f) {
    const int k = labels[f] / 2, a = (k + 1) % 3, b = (k + 2) % 3;
    const double sg = labels[f] % 2 ? -1.0 : 1.0;
    Eigen::Vector2d q[3];
    for (int j = 0; j < 3; ++j) q[j] = Eigen::Vector2d(sg * X(F(f, j), a), X(F(f, j), b));
    double D;
    untangle_triangle(q, el.Dm_inv[f], el.scale, 1.0, 1.0, el.theta, D, nullptr);
    return D;
  };
  // One Newton step of vertex v over its free coordinates (those no plane holds) on the elliptic
  // energy of its triangles: Hessian by central differences of the gradient, its eigenvalues
  // made positive, a backtracking line search (Armijo) from at most half the mean edge length.
  auto newton_vertex = [&](MatX3d& X, const Elliptic& el, int v, double eps) {
    int free_axes[3], nf = 0;
    for (int k = 0; k < 3; ++k)
      if (var[k][v] >= r.planes[k]) free_axes[nf++] = k;
    if (nf == 0 || vf[v].empty()) return false;
    const Vec3 p0 = X.row(v).transpose();
    double len = 0;
    for (int f : vf[v]) len += (X.row(F(f, 0)) - X.row(F(f, 1))).norm();
    len /= static_cast<double>(vf[v].size());
    if (!(len > 0)) return false;
    Vec3 g3;
    const double E0 = star(X, el, v, p0, eps, &g3);
    const double h = 1e-6 * len;
    Eigen::Vector2d gf;
    Eigen::Matrix2d H = Eigen::Matrix2d::Identity();
    for (int c = 0; c < nf; ++c) {
      gf[c] = g3[free_axes[c]];
      Vec3 pp = p0, pm = p0, gp, gm;
      pp[free_axes[c]] += h;
      pm[free_axes[c]] -= h;
      star(X, el, v, pp, eps, &gp);
      star(X, el, v, pm, eps, &gm);
      for (int a = 0; a < nf; ++a) H(a, c) = (gp[free_axes[a]] - gm[free_axes[a]]) / (2 * h);
    }
    const Eigen::MatrixXd Hs = 0.5 * (H.topLeftCorner(nf, nf) + H.topLeftCorner(nf, nf).transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Hs);
    Eigen::VectorXd ev = es.eigenvalues();
    const double floor = 1e-8 * std::max(ev.cwiseAbs().maxCoeff(), 1e-300);
    for (int a = 0; a < nf; ++a) ev[a] = std::max(std::abs(ev[a]), floor);
    const Eigen::VectorXd gv = gf.head(nf);
    const Eigen::VectorXd df = -es.eigenvectors() * (es.eigenvectors().transpose() * gv).cwiseQuotient(ev);
    const double slope = df.dot(gv);
    if (!(slope < 0)) return false;
    Vec3 d = Vec3::Zero();
    for (int a = 0; a < nf; ++a) d[free_axes[a]] = df[a];
    double step = d.norm() > 0.5 * len ? 0.5 * len / d.norm() : 1.0;
    for (int ls = 0; ls < 30; ++ls, step *= 0.5) {
      const Vec3 p = p0 + step * d;
      if (star(X, el, v, p, eps, nullptr) <= E0 + 1e-4 * step * slope) {
        X.row(v) = p.transpose();
        return true;
      }
    }
    return false;
  };
  // Vertices of the triangles marked in `seed`, and those within `rings` rings of them.
  auto grow_region = [&](const std::vector<char>& seed, int rings) {
    std::vector<char> in(n, 0);
    std::vector<int> region;
    for (int f = 0; f < F.rows(); ++f)
      if (seed[f])
        for (int j = 0; j < 3; ++j)
          if (!in[F(f, j)]) in[F(f, j)] = 1, region.push_back(F(f, j));
    for (int ring = 0; ring < rings; ++ring) {
      const size_t m = region.size();
      for (size_t i = 0; i < m; ++i)
        for (int f : vf[region[i]])
          for (int j = 0; j < 3; ++j)
            if (!in[F(f, j)]) in[F(f, j)] = 1, region.push_back(F(f, j));
    }
    return region;
  };
  // Local untangling: Gauss-Seidel sweeps of Newton steps (newton_vertex) around the misoriented
  // triangles (within two rings, found again every sweep). A handful of folds near chart borders
  // is what the starts leave; the global rounds below cost a linear solve per L-BFGS iteration
  // over the whole surface for them. Returns the fewest misoriented triangles reached (X holds
  // that state); initial: the count at the call.
  auto untangle_locally = [&](MatX3d& X, const Elliptic& el, int& initial, int& sweeps) {
    initial = misoriented(X);
    int best = initial, since_best = 0;
    MatX3d X_best = X;
    int sweep = 0;
    // At most 100 sweeps, 10 without fewer folds; and after 10 sweeps, over half the folds left
    // (and more than the global rounds are skipped for) means the layout needs more than local
    // steps: the global rounds (RealizeOptions::surface_untangle_rounds, none by default) go on
    // from the best state, or the start fails and the next one takes over (organic/cow: 1058 ->
    // 818 after 100 sweeps, 4 s per call, where bumpy torus went 385 -> 1 in 13 sweeps).
    for (; sweep < 100 && best > 0 && since_best < 10 && !(sweep == 10 && best > opt.local_first && 2 * best > initial);
         ++sweep) {
      std::vector<char> folded(F.rows(), 0);
      for (int f = 0; f < F.rows(); ++f) folded[f] = !faces_label(X, F(f, 0), F(f, 1), F(f, 2), labels[f], diag0);
      const std::vector<int> region = grow_region(folded, 2);
      double dmin = std::numeric_limits<double>::infinity();
      for (int v : region)
        for (int f : vf[v]) dmin = std::min(dmin, triangle_det(X, el, f));
      const double eps = dmin < 0 ? std::max(1e-12, 0.1 * -dmin) : 1e-8;
      for (int inner = 0; inner < 10; ++inner)
        for (int v : region) newton_vertex(X, el, v, eps);
      const int m = misoriented(X);
      if (m < best) best = m, since_best = 0, X_best = X;
      else ++since_best;
    }
    X = X_best;
    sweeps = sweep;
    return best;
  };
  // The rest shapes of the triangles for the elliptic energy, and the scale that makes the
  // polycube's total area the rest's.
  auto elliptic_rest = [&](const MatX3d& X) {
    Elliptic el;
    el.Dm_inv.resize(F.rows());
    double rest_area = 0, poly_area = 0;
    for (int f = 0; f < F.rows(); ++f) {
      const Vec3 e1 = (rest.row(F(f, 1)) - rest.row(F(f, 0))).transpose();
      const Vec3 e2 = (rest.row(F(f, 2)) - rest.row(F(f, 0))).transpose();
      const double l1 = e1.norm(), a2 = e1.cross(e2).norm();
      Eigen::Matrix2d Dm;
      Dm << l1, e2.dot(e1) / std::max(l1, 1e-300), 0, a2 / std::max(l1, 1e-300);
      el.Dm_inv[f] = a2 > 0 ? Eigen::Matrix2d(Dm.inverse()) : Eigen::Matrix2d::Identity();
      rest_area += 0.5 * a2;
      poly_area += std::abs(deform::area_normal(X, F(f, 0), F(f, 1), F(f, 2)).dot(label_direction(labels[f])));
    }
    el.scale = std::sqrt(poly_area / std::max(rest_area, 1e-300));
    return el;
  };
  // The elliptic energy over the unknowns z (per axis: the plane heights, then the free
  // coordinates; plane heights fixed, the gradient zero there), its minimum determinant, and the
  // ARAP factorizations as the preconditioner.
  std::array<int, 4> off{0, 0, 0, 0};
  for (int k = 0; k < 3; ++k) off[k + 1] = off[k] + nvar[k];
  auto to_z = [&](const MatX3d& X) {
    Eigen::VectorXd z(off[3]);
    for (int v = 0; v < n; ++v)
      for (int k = 0; k < 3; ++k) z[off[k] + var[k][v]] = X(v, k);
    return z;
  };
  auto to_X = [&](const Eigen::VectorXd& zz) {
    MatX3d Y(n, 3);
    for (int v = 0; v < n; ++v)
      for (int k = 0; k < 3; ++k) Y(v, k) = zz[off[k] + var[k][v]];
    return Y;
  };
  double min_det = 0;
  auto energy = [&](const Elliptic& el, const Eigen::VectorXd& zz, double eps, Eigen::VectorXd* g) {
    if (g) g->setZero(zz.size());
    double E = 0;
    min_det = std::numeric_limits<double>::infinity();
    for (int f = 0; f < F.rows(); ++f) {
      const int k = labels[f] / 2, a = (k + 1) % 3, b = (k + 2) % 3;
      const double sg = labels[f] % 2 ? -1.0 : 1.0;
      Eigen::Vector2d q[3];
      for (int j = 0; j < 3; ++j)
        q[j] = Eigen::Vector2d(sg * zz[off[a] + var[a][F(f, j)]], zz[off[b] + var[b][F(f, j)]]);
      double D;
      Eigen::Vector2d gq[3];
      E += untangle_triangle(q, el.Dm_inv[f], el.scale, ar.w[f], eps, el.theta, D, g ? gq : nullptr);
      min_det = std::min(min_det, D);
      if (!g) continue;
      for (int j = 0; j < 3; ++j) {
        const int ia = off[a] + var[a][F(f, j)], ib = off[b] + var[b][F(f, j)];
        if (var[a][F(f, j)] >= r.planes[a]) (*g)[ia] += sg * gq[j][0];
        if (var[b][F(f, j)] >= r.planes[b]) (*g)[ib] += gq[j][1];
      }
    }
    return E;
  };
  auto precondition = [&](const Eigen::VectorXd& g) {
    Eigen::VectorXd d(g.size());
    for (int k = 0; k < 3; ++k) {
      d.segment(off[k], nvar[k]) = solver[k].solve(g.segment(off[k], nvar[k]));
      d.segment(off[k], r.planes[k]).setZero();
    }
    return d;
  };
  auto untangle = [&](MatX3d& X) {
    if (misoriented(X) == 0) return;
    // Elliptic untangling (Garanzha et al. 2021, 2D) of the chart layouts: every triangle in its
    // chart's plane, mirrored for negative labels so that facing its label = positive area; plane
    // heights fixed, the other unknowns free; L-BFGS preconditioned by the ARAP factorizations,
    // eps decreasing by the paper's rule.
    const Elliptic el = elliptic_rest(X);
    if (opt.local_first >= 0) {
      int before = 0, sweeps = 0;
      const int m = untangle_locally(X, el, before, sweeps);
      hooks.debug("surface local untangling: " + std::to_string(before) + " -> " + std::to_string(m) +
                  " misoriented triangles in " + std::to_string(sweeps) + " sweeps");
      if (m <= opt.local_first || opt.surface_untangle_rounds <= 0) return;
    }
    const int max_rounds = opt.local_first < 0 ? 30 : opt.surface_untangle_rounds;
    // Unknowns from X (each variable's value is shared by its vertices).
    Eigen::VectorXd z = to_z(X);
    double eps = 1.0;
    if (start) {
      // A given start is a layout with a few folds at most (e.g. after edge collapses): eps of the
      // order of its worst determinant keeps the rest in the barrier regime, so the untangling
      // stays local (eps = 1 rearranges whole charts: fandisk 0 -> 9 folds in one round).
      energy(el, z, eps, nullptr);
      eps = std::clamp(4 * std::abs(std::min(min_det, 0.0)), 1e-3, 1.0);
    }
    int best = misoriented(X), since_best = 0, total = 0;
    Eigen::VectorXd z_best = z;  // the round with the fewest misoriented triangles
    // At most max_rounds rounds, and 5 without fewer folds (on fandisk, eight and rocker the fewest
    // came by round 6, the count then oscillating, when these rounds were the only untangling).
    for (int round = 0; round < max_rounds && best > 0 && since_best < 5; ++round) {
      const double E0 = energy(el, z, eps, nullptr);
      double E = E0;
      LbfgsOptions lo;
      lo.max_iterations = 300;
      total += lbfgs_minimize(
          z, [&](const Eigen::VectorXd& zz, Eigen::VectorXd* gg) { return energy(el, zz, eps, gg); }, precondition, lo, E);
      energy(el, z, eps, nullptr);
      const int m = misoriented(to_X(z));
      hooks.debug("surface untangling round " + std::to_string(round) + ": eps " + std::to_string(eps) +
                  ", min det " + std::to_string(min_det) + ", " + std::to_string(m) + " misoriented");
      if (m < best) best = m, since_best = 0, z_best = z;
      else ++since_best;
      const double sigma = std::max(1 - E / E0, 0.1);
      const double mu = (1 - sigma) * chi(min_det, eps);
      eps = min_det < mu ? 2 * std::sqrt(mu * (mu - min_det)) : 1e-13;
      if (m == 0) break;
    }
    r.untangle_iterations += total;
    if (best < misoriented(X)) X = to_X(z_best);
  };
  // Starts, in order, until one ends with every triangle facing its label:
  //  1. the deformed surface with every plane at its height (each triangle of the deformed
  //     surface faces its label, so only triangles near chart borders, whose vertices moved onto
  //     the other chart's plane, can fold), untangled if needed;
  //  2. ARAP iterations from it (unguarded), untangled if needed;
  //  3. every coordinate no plane holds harmonic (uniform weights: a Tutte-like layout of each
  //     chart between its borders), untangled if needed.
  // Each start that ends flip-free is finished by ARAP iterations that never fold a triangle.
  const std::array<Eigen::VectorXd, 3> y_start = y;
  int its = 0;
  auto finish = [&](MatX3d& X, const char* name) {
    untangle(X);
    const int m = misoriented(X);
    hooks.debug(std::string("surface realization, start ") + name + ": " + std::to_string(m) +
                " misoriented triangles after untangling");
    if (m > 0) return m;
    std::array<Eigen::VectorXd, 3> yy;
    for (int k = 0; k < 3; ++k) {
      yy[k].resize(nvar[k]);
      for (int v = 0; v < n; ++v) yy[k][var[k][v]] = X(v, k);
    }
    X = arap(yy, true, its);
    r.iterations = its;
    r.start = name;
    return 0;
  };
  MatX3d X;
  int bad = 0;
  if (start) {
    // A given start (an exact polycube layout of these triangles, e.g. after edge flips): only
    // the never-folding ARAP iterations (untangled first if it folds).
    X = *start;
    bad = finish(X, "given");
  } else {
    y = y_start;
    X = positions();
    bad = finish(X, "surface_deformed");
  }
  if (bad > 0 && !start && opt.surface_starts >= 2) {
    std::array<Eigen::VectorXd, 3> y1 = y_start;
    MatX3d X1 = arap(y1, false, its);
    const int bad1 = finish(X1, "surface_arap");
    if (bad1 < bad) X = std::move(X1), bad = bad1;
  }
  if (bad > 0 && !start && opt.surface_starts >= 3) {
    std::vector<Eigen::Triplet<double>> ut;
    // Vertices no triangle uses (merged away by collapse_folded_edges) stay where they are.
    std::vector<char> used(n, 0);
    for (int f = 0; f < F.rows(); ++f)
      for (int j = 0; j < 3; ++j) used[F(f, j)] = 1;
    for (int v = 0; v < n; ++v)
      if (!used[v]) ut.emplace_back(v, v, 1.0);
    for (const auto& [a, b] : unique_edges(F)) {
      ut.emplace_back(a, a, 1.0);
      ut.emplace_back(b, b, 1.0);
      ut.emplace_back(a, b, -1.0);
      ut.emplace_back(b, a, -1.0);
    }
    SpMat U(n, n);
    U.setFromTriplets(ut.begin(), ut.end());
    std::array<Eigen::VectorXd, 3> y2 = y_start;
    for (int k = 0; k < 3; ++k) {
      // Plane unknowns [0, planes) held at their heights by a stiff penalty; the rest harmonic.
      SpMat A = S[k].transpose() * U * S[k];
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(nvar[k]);
      for (int v = 0; v < n; ++v)
        if (!used[v]) rhs[var[k][v]] = y_start[k][var[k][v]];
      const double stiff = 1e8;
      for (int i = 0; i < r.planes[k]; ++i) {
        A.coeffRef(i, i) += stiff;
        rhs[i] = stiff * y_start[k][i];
      }
      Eigen::SimplicialLDLT<SpMat> h(A);
      if (h.info() == Eigen::Success) {
        y2[k] = h.solve(rhs);
        for (int i = 0; i < r.planes[k]; ++i) y2[k][i] = y_start[k][i];
      }
    }
    y = y2;
    MatX3d X2 = positions();
    const int bad2 = finish(X2, "surface_harmonic");
    if (bad2 < bad) X = std::move(X2), bad = bad2;
  }
  if (bad == 0 && opt.relax_iterations > 0) {
    // Relaxation (RealizeOptions::relax_iterations): L-BFGS on the elliptic energy with equal shape
    // and area weights (2 per triangle at a rotation) over the free coordinates, the plane heights
    // kept; eps far below any determinant makes it a barrier against folding.
    Elliptic el = elliptic_rest(X);
    el.theta = 0.5;
    const double eps = 1e-12;
    const MatX3d X0 = X;
    Eigen::VectorXd z = to_z(X);
    LbfgsOptions lo;
    lo.max_iterations = opt.relax_iterations;
    lo.max_change = 0.1 * diag0 / std::sqrt(static_cast<double>(n));
    double E = energy(el, z, eps, nullptr);
    const double E0 = E;
    const int its = lbfgs_minimize(
        z, [&](const Eigen::VectorXd& zz, Eigen::VectorXd* gg) { return energy(el, zz, eps, gg); }, precondition, lo, E);
    X = to_X(z);
    const int folded = misoriented(X);
    if (hooks.log)  // the distortion figures are for the log only
      hooks.debug("surface relaxation: " + std::to_string(its) + " iterations, elliptic energy " +
                  std::to_string(E0) + " -> " + std::to_string(E) + ", max isometric distortion " +
                  std::to_string(isometric_distortion_surface(rest, X0, F).max) + " -> " +
                  std::to_string(isometric_distortion_surface(rest, X, F).max) +
                  (folded > 0 ? ", " + std::to_string(folded) + " misoriented: undone" : ""));
    if (folded > 0) X = X0;
  }
  const double e_prev = deform::surface_arap_energy(X, F, ar, 1.0, nullptr, nullptr);

  // ---- checks ----
  r.rest = rest;
  r.T.resize(0, 4);
  r.X = std::move(X);
  r.arap = e_prev;
  check_faces(F, labels, r);
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
