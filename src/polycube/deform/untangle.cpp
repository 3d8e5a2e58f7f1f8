#include "polycube/deform/untangle.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

namespace polycube::deform {

double volume_ratio(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t) {
  Eigen::Matrix3d Ds;
  for (int m = 0; m < 3; ++m) Ds.col(m) = (X.row(T(t, m + 1)) - X.row(T(t, 0))).transpose();
  return (Ds * rest.Dm_inv[t]).determinant();
}

int count_inverted(const MatX3d& X, const MatX4i& T, const ArapRest& rest) {
  int n = 0;
  for (int t = 0; t < T.rows(); ++t) n += !(volume_ratio(X, T, rest, t) > 0);
  return n;
}

int untangle_locally(const MatX4i& T_, const ArapRest& arap_rest_, const std::function<bool(int, int)>& fixed,
                     MatX3d& X, int& inverted, int rings, int max_sweeps, double flat,
                     const std::function<bool(int)>& stop, const MoveDirections& directions,
                     const std::function<void(int, MatX3d&)>& after_move) {
  const int n = static_cast<int>(X.rows());
  const int nt = static_cast<int>(T_.rows());
  std::vector<std::vector<int>> vt(n);
  for (int t = 0; t < nt; ++t)
    for (int j = 0; j < 4; ++j) vt[T_(t, j)].push_back(t);
  double vol = 0;
  for (int t = 0; t < nt; ++t) vol += arap_rest_.w[t] * volume_ratio(X, T_, arap_rest_, t);
  const double s = std::cbrt(std::max(vol, 1e-300));
  constexpr double theta = 0.5;
  const double bad_below = flat * s * s * s;
  auto bad = [&](int t) { return !(volume_ratio(X, T_, arap_rest_, t) > bad_below); };
  // One pass over the tets: those to repair, those inverted, the smallest volume ratio.
  struct Scan {
    int bad = 0, inverted = 0;
    double min = std::numeric_limits<double>::infinity();
  };
  auto scan = [&] {
    Scan r;
    for (int t = 0; t < nt; ++t) {
      const double J = volume_ratio(X, T_, arap_rest_, t);
      r.bad += !(J > bad_below);
      r.inverted += !(J > 0);
      r.min = std::min(r.min, J);
    }
    return r;
  };
  Scan now = scan();
  inverted = now.bad;
  int sweep = 0, best = inverted, since_best = 0;
  MatX3d kept;  // flat > 0: the state before the sweep, whose scan is `before`
  Scan before;
  for (; sweep < max_sweeps && inverted > 0 && since_best < 30 && !(stop && stop(100 * sweep)); ++sweep) {
    if (flat > 0) kept = X, before = now;
    // The region: vertices within `rings` of a tet to repair, found again every sweep (a sweep
    // is 10 passes over it).
    std::vector<char> in(n, 0);
    std::vector<int> region;
    for (int t = 0; t < nt; ++t)
      if (bad(t))
        for (int j = 0; j < 4; ++j)
          if (!in[T_(t, j)]) in[T_(t, j)] = 1, region.push_back(T_(t, j));
    for (int r = 0; r < rings; ++r) {
      const size_t m = region.size();
      for (size_t i = 0; i < m; ++i)
        for (int t : vt[region[i]])
          for (int j = 0; j < 4; ++j)
            if (!in[T_(t, j)]) in[T_(t, j)] = 1, region.push_back(T_(t, j));
    }
    double dmin = std::numeric_limits<double>::infinity();
    for (int v : region)
      for (int t : vt[v]) dmin = std::min(dmin, volume_ratio(X, T_, arap_rest_, t) / (s * s * s));
    const double eps = dmin < 0 ? std::max(1e-12, 0.1 * -dmin) : 1e-8;
    for (int inner = 0; inner < 10; ++inner)
      for (int v : region) {
        // v moves along its free axes, or along the columns of B (`custom`, from `directions`).
        int free_axes[3], nf = 0;
        Eigen::Matrix3d B;
        const bool custom = directions && (nf = directions(v, X, B)) >= 0;
        if (!custom) {
          nf = 0;
          for (int k = 0; k < 3; ++k)
            if (!fixed(v, k)) free_axes[nf++] = k;
        }
        if (nf == 0) continue;
        // Energy of v's tets with v at p, and their gradient over v's coordinates.
        auto star = [&](const Eigen::RowVector3d& p, Vec3* g) {
          const Eigen::RowVector3d keep = X.row(v);
          X.row(v) = p;
          double E = 0;
          if (g) g->setZero();
          Eigen::Matrix<double, 12, 1> ge;
          for (int t : vt[v]) {
            E += untangle_tet_energy(X, T_, arap_rest_, t, eps, s, theta, g ? &ge : nullptr);
            if (g)
              for (int j = 0; j < 4; ++j)
                if (T_(t, j) == v) *g += ge.segment<3>(3 * j);
          }
          X.row(v) = keep;
          return E;
        };
        const Eigen::RowVector3d p0 = X.row(v);
        double len = 0;
        for (int t : vt[v]) len += (X.row(T_(t, 0)) - X.row(T_(t, 1))).norm();
        len /= std::max<size_t>(1, vt[v].size());
        // Energy, gradient and exact 3 x 3 Hessian of v's tets at v's position.
        Vec3 g = Vec3::Zero();
        Eigen::Matrix3d H3 = Eigen::Matrix3d::Zero();
        double E0 = 0, wall = 0;
        for (int t : vt[v]) {
          int j = 0;
          while (T_(t, j) != v) ++j;
          Vec3 gt;
          Eigen::Matrix3d Ht;
          double w;
          E0 += untangle_tet_corner(X, T_, arap_rest_, t, j, eps, s, theta, &gt, &Ht, &w);
          g += gt;
          H3 += Ht;
          wall = std::max(wall, w);
        }
        Eigen::VectorXd gf(nf);
        Eigen::MatrixXd H(nf, nf);
        for (int a = 0; a < nf; ++a) {
          gf[a] = custom ? B.col(a).dot(g) : g[free_axes[a]];
          for (int b = 0; b < nf; ++b) H(a, b) = custom ? B.col(a).dot(H3 * B.col(b)) : H3(free_axes[a], free_axes[b]);
        }
        // Next to a wall (the curvature changing by a percent within 1e-6 len) the Hessian is the
        // central difference of the gradient over +-1e-6 len, which sees the wall's growth (the
        // exact one at the point gave longer steps into it: spot, one more tet left inverted per
        // untangling, and no realization).
        double hstep = 1e-6 * len;
        if (flat > 0) {
          // Nearly flat tets: v may be far closer than 1e-6 len to the plane of an opposite face,
          // where a difference across it would see the energy's pole; a thousandth of v's
          // smallest height over its opposite faces instead.
          for (int t : vt[v]) {
            int a = 0;
            while (T_(t, a) != v) ++a;
            const Vec3 p = X.row(T_(t, (a + 1) % 4)), q = X.row(T_(t, (a + 2) % 4)), r = X.row(T_(t, (a + 3) % 4));
            const Vec3 nrm = (q - p).cross(r - p);
            const double area2 = nrm.norm();
            if (area2 > 0) hstep = std::min(hstep, 1e-3 * std::abs(nrm.dot(Vec3(X.row(v)) - p)) / area2);
          }
          hstep = std::max(hstep, 1e-15 * len);
        }
        if (wall * hstep > 1e-4)
          for (int b = 0; b < nf; ++b) {
            Eigen::RowVector3d pp = p0, pm = p0;
            if (custom) {
              pp += hstep * B.col(b).transpose();
              pm -= hstep * B.col(b).transpose();
            } else {
              pp[free_axes[b]] += hstep;
              pm[free_axes[b]] -= hstep;
            }
            Vec3 gp, gm;
            star(pp, &gp);
            star(pm, &gm);
            for (int a = 0; a < nf; ++a)
              H(a, b) = custom ? B.col(a).dot(gp - gm) / (2 * hstep)
                               : (gp[free_axes[a]] - gm[free_axes[a]]) / (2 * hstep);
          }
        H = 0.5 * (H + H.transpose()).eval();
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(H);
        Eigen::VectorXd ev = es.eigenvalues();
        const double floor = 1e-8 * std::max(ev.cwiseAbs().maxCoeff(), 1e-300);
        for (int a = 0; a < nf; ++a) ev[a] = std::max(std::abs(ev[a]), floor);
        const Eigen::VectorXd df = -es.eigenvectors() * (es.eigenvectors().transpose() * gf).cwiseQuotient(ev);
        Eigen::RowVector3d d = Eigen::RowVector3d::Zero();
        if (custom)
          d = (B.leftCols(nf) * df).transpose();
        else
          for (int a = 0; a < nf; ++a) d[free_axes[a]] = df[a];
        const double dn = d.norm();
        double step = dn > 0.5 * len ? 0.5 * len / dn : 1.0;
        const double slope = df.dot(gf);
        if (!(slope < 0)) continue;
        for (int ls = 0; ls < 30; ++ls, step *= 0.5) {
          const Eigen::RowVector3d p = p0 + step * d;
          if (star(p, nullptr) <= E0 + 1e-4 * step * slope) {
            X.row(v) = p;
            if (after_move) after_move(v, X);
            break;
          }
        }
      }
    now = scan();
    inverted = now.bad;
    if (flat > 0) {
      // Kept while the smallest volume ratio grows and no tet turns over; otherwise back, and stop.
      if (!(now.min > before.min) || now.inverted > 0) {
        X = kept;
        inverted = before.bad;
        ++sweep;
        break;
      }
      continue;
    }
    if (inverted < best) best = inverted, since_best = 0;
    else ++since_best;
  }
  return sweep;
}

}  // namespace polycube::deform
