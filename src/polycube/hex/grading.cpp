#include "polycube/hex/grading.h"

#include <algorithm>
#include <cmath>

#include "polycube/chart/realize.h"
#include "polycube/core/error.h"
#include "polycube/deform/energies.h"
#include "polycube/validate/tetmesh.h"

namespace polycube::hex {

double AxisWarp::operator()(double x) const {
  const double u = (x - lo) / width;
  if (u <= 0) return at.front() + (at[1] - at[0]) * u;
  const int n = static_cast<int>(at.size()) - 1;
  if (u >= n) return at[n] + (at[n] - at[n - 1]) * (u - n);
  const int i = std::min(static_cast<int>(u), n - 1);
  return at[i] + (at[i + 1] - at[i]) * (u - i);
}

double AxisWarp::inverse(double y) const {
  const int n = static_cast<int>(at.size()) - 1;
  if (y <= at[0]) return lo + width * (y - at[0]) / (at[1] - at[0]);
  if (y >= at[n]) return lo + width * (n + (y - at[n]) / (at[n] - at[n - 1]));
  const int i = std::min(static_cast<int>(std::upper_bound(at.begin(), at.end(), y) - at.begin()) - 1, n - 1);
  return lo + width * (i + (y - at[i]) / (at[i + 1] - at[i]));
}

namespace {

double volume_of_tet(const MatX3d& X, const MatX4i& T, int t) {
  return tet_volume(X.row(T(t, 0)), X.row(T(t, 1)), X.row(T(t, 2)), X.row(T(t, 3)));
}

double volume_of(const MatX3d& X, const MatX4i& T) {
  double v = 0;
  for (int t = 0; t < T.rows(); ++t) v += volume_of_tet(X, T, t);
  return v;
}

double area_of(const MatX3d& X, const MatX3i& F) {
  double l1 = 0, area = 0;
  deform::l1_measure(X, F, l1, area);
  return area;
}

}  // namespace

Grading grade_polycube(const MatX3d& rest, const MatX4i& T, const MatX3d& X, const MatX3i& B,
                       const std::vector<int>& labels, double s, const GradingOptions& opt) {
  POLYCUBE_ASSERT(static_cast<int>(labels.size()) == B.rows(), "one label per boundary triangle");
  POLYCUBE_ASSERT(s > 0 && opt.max_ratio >= 1, "grading: positive cell density and a ratio of at least 1");
  Grading g;
  const Vec3 lo = X.colwise().minCoeff().transpose(), hi = X.colwise().maxCoeff().transpose();
  const double width = 0.25 / s;

  if (opt.measure != "chord" && opt.measure != "stretch")
    throw Error(ErrorKind::Usage, "unknown grading measure '" + opt.measure + "' (chord or stretch)");
  // The measure along axis k on each boundary triangle of a chart of another axis, from the
  // triangle's 2D Jacobian J (polycube plane -> input): "stretch" |J e_k|; "chord" the square root
  // of the map's second derivative along k normal to the surface. Smoothed at the vertices (mean
  // over the incident triangles, weighted by polycube area), so that one crushed triangle does not
  // count.
  const int nv = static_cast<int>(X.rows());
  // Corner normals of the input surface, smooth across edges and split across sharp ones: the mean
  // of the (area-weighted) normals of the triangles around the corner within sharp_angle_deg of
  // this one.
  std::vector<Vec3> fn(B.rows()), un(B.rows());  // area-weighted and unit normals
  std::vector<std::vector<int>> vf(nv);
  for (int f = 0; f < B.rows(); ++f) {
    const Vec3 r0 = rest.row(B(f, 0)), r1 = rest.row(B(f, 1)), r2 = rest.row(B(f, 2));
    fn[f] = (r1 - r0).cross(r2 - r0);
    un[f] = fn[f].normalized();
    for (int c = 0; c < 3; ++c) vf[B(f, c)].push_back(f);
  }
  const bool chord = opt.measure == "chord";
  const double smooth_cos = std::cos(opt.sharp_angle_deg * M_PI / 180);
  auto corner_normal = [&](int f, int v) {
    Vec3 n = Vec3::Zero();
    for (int h : vf[v])
      if (un[h].dot(un[f]) > smooth_cos) n += fn[h];
    return n.normalized();
  };
  std::array<std::vector<double>, 3> vsum, vw;
  for (int k = 0; k < 3; ++k) vsum[k].assign(nv, 0.0), vw[k].assign(nv, 0.0);
  double ref_sum = 0, ref_w = 0;
  for (int f = 0; f < B.rows(); ++f) {
    const int a = labels[f] / 2;
    const int k1 = (a + 1) % 3, k2 = (a + 2) % 3;
    const Vec3 p0 = X.row(B(f, 0)), p1 = X.row(B(f, 1)), p2 = X.row(B(f, 2));
    Eigen::Matrix2d P;
    P << p1[k1] - p0[k1], p2[k1] - p0[k1], p1[k2] - p0[k2], p2[k2] - p0[k2];
    const double area = std::abs(P.determinant()) / 2;
    if (!(area > 1e-14 * (hi - lo).squaredNorm())) continue;
    Eigen::Matrix<double, 3, 2> R;
    R.col(0) = (rest.row(B(f, 1)) - rest.row(B(f, 0))).transpose();
    R.col(1) = (rest.row(B(f, 2)) - rest.row(B(f, 0))).transpose();
    const Eigen::Matrix<double, 3, 2> J = R * P.inverse();
    double sk[2] = {J.col(0).norm(), J.col(1).norm()};
    if (chord) {
      // The map's second derivative along k, normal to the surface: a cell of h polycube units
      // along k comes out of the surface by about c h^2 / 8 midway.
      const Vec3 n0 = corner_normal(f, B(f, 0)), n1 = corner_normal(f, B(f, 1)), n2 = corner_normal(f, B(f, 2));
      Eigen::Matrix<double, 3, 2> N;
      N.col(0) = n1 - n0;
      N.col(1) = n2 - n0;
      const Eigen::Matrix<double, 3, 2> Jn = N * P.inverse();
      sk[0] = std::sqrt(std::abs(J.col(0).dot(Jn.col(0))));
      sk[1] = std::sqrt(std::abs(J.col(1).dot(Jn.col(1))));
    }
    const int ks[2] = {k1, k2};
    for (int j = 0; j < 2; ++j) {
      for (int c = 0; c < 3; ++c) vsum[ks[j]][B(f, c)] += area * sk[j], vw[ks[j]][B(f, c)] += area;
      ref_sum += area * sk[j];
      ref_w += area;
    }
  }
  const double ref = ref_sum > 0 ? ref_sum / ref_w : 1;

  for (int k = 0; k < 3; ++k) {
    const int nb = std::max(1, static_cast<int>(std::ceil((hi[k] - lo[k]) / width)));
    std::vector<double> bin(nb, 0.0);
    std::vector<char> seen(nb, 0);
    for (int f = 0; f < B.rows(); ++f) {
      if (labels[f] / 2 == k) continue;
      double v = 0, xmin = 1e300, xmax = -1e300;
      int n = 0;
      for (int c = 0; c < 3; ++c) {
        const int p = B(f, c);
        if (vw[k][p] > 0) v += vsum[k][p] / vw[k][p], ++n;
        xmin = std::min(xmin, X(p, k)), xmax = std::max(xmax, X(p, k));
      }
      if (n == 0) continue;
      v /= n;
      const int b0 = std::clamp(static_cast<int>((xmin - lo[k]) / width), 0, nb - 1);
      const int b1 = std::clamp(static_cast<int>((xmax - lo[k]) / width), 0, nb - 1);
      for (int b = b0; b <= b1; ++b) bin[b] = std::max(bin[b], v), seen[b] = 1;
    }
    for (int b = 0; b < nb; ++b)
      if (!seen[b]) bin[b] = ref;
    // Over about a cell: the largest within half a cell, then the mean over a cell.
    std::vector<double> mx(nb), avg(nb);
    for (int b = 0; b < nb; ++b) {
      mx[b] = bin[b];
      for (int d = -2; d <= 2; ++d)
        if (b + d >= 0 && b + d < nb) mx[b] = std::max(mx[b], bin[b + d]);
    }
    for (int b = 0; b < nb; ++b) {
      double sum = 0;
      int n = 0;
      for (int d = -2; d <= 2; ++d)
        if (b + d >= 0 && b + d < nb) sum += mx[b + d], ++n;
      avg[b] = sum / n;
    }
    AxisWarp& w = g.warp[k];
    w.lo = lo[k];
    w.width = width;
    w.at.assign(nb + 1, lo[k]);
    g.max_slope[k] = 0;
    g.min_slope[k] = 1e300;
    for (int b = 0; b < nb; ++b) {
      const double slope =
          std::pow(std::clamp(avg[b] / ref, chord ? 1.0 : 1 / opt.max_ratio, opt.max_ratio), opt.strength);
      w.at[b + 1] = w.at[b] + slope * width;
      g.max_slope[k] = std::max(g.max_slope[k], slope);
      g.min_slope[k] = std::min(g.min_slope[k], slope);
    }
  }

  // Warp, then one scale for the three axes so that the volume (and so the hex count) is kept.
  // A map without stretch or curvature (the identity of a box) keeps the uniform grid exactly.
  bool uniform = true;
  for (int k = 0; k < 3; ++k) uniform = uniform && g.max_slope[k] == g.min_slope[k];
  if (uniform) {
    g.Y = X;
    for (int k = 0; k < 3; ++k) {
      g.warp[k].at.assign({lo[k], lo[k] + width});
      g.max_slope[k] = g.min_slope[k] = 1;
    }
    return g;
  }
  g.Y.resize(nv, 3);
  for (int v = 0; v < nv; ++v)
    for (int k = 0; k < 3; ++k) g.Y(v, k) = g.warp[k](X(v, k));
  // Surface polycube (no tets): the area is kept instead.
  double c = 1;
  if (T.rows() > 0) {
    const double vx = volume_of(X, T), vy = volume_of(g.Y, T);
    c = vy > 0 ? std::cbrt(vx / vy) : 1;
  } else {
    const double ax = area_of(X, B), ay = area_of(g.Y, B);
    c = ay > 0 ? std::sqrt(ax / ay) : 1;
  }
  for (int k = 0; k < 3; ++k) {
    for (double& a : g.warp[k].at) a = lo[k] + c * (a - lo[k]);
    g.max_slope[k] *= c;
    g.min_slope[k] *= c;
    for (int v = 0; v < nv; ++v) g.Y(v, k) = lo[k] + c * (g.Y(v, k) - lo[k]);
  }
  // A sliver straddling a change of slope may turn over: untangle it locally, the vertices of each
  // chart kept on their plane (the snapping's harmonic displacement needs positive tets).
  for (int t = 0; t < T.rows(); ++t) g.turned_over += !(volume_of_tet(g.Y, T, t) > 0);  // no tets in surface mode
  if (g.turned_over > 0) {
    std::array<std::vector<char>, 3> fixed;
    for (int k = 0; k < 3; ++k) fixed[k].assign(nv, 0);
    for (int f = 0; f < B.rows(); ++f)
      for (int c = 0; c < 3; ++c) fixed[labels[f] / 2][B(f, c)] = 1;
    // The untangling's rest shape is the polycube X: through a folded map (flat or inverted tets
    // there) it can make things worse, or non-finite (homer with --gap-barrier 1: 16 tets turned
    // over, 31432 after); then the warped polycube is kept as it was, those tets turned over.
    const MatX3d before = g.Y;
    chart::untangle_tets_locally(X, T, fixed, g.Y, g.left_inverted);
    if (!g.Y.allFinite() || g.left_inverted > g.turned_over) {
      g.Y = before;
      g.left_inverted = g.turned_over;
    }
  }
  return g;
}

}  // namespace polycube::hex
