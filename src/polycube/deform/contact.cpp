#include "polycube/deform/contact.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

#include "polycube/geometry/closest_point.h"

namespace polycube::deform {

namespace {

inline Vec3 row(const MatX3d& X, int i) { return X.row(i).transpose(); }

// Triangles of (X, F) binned in a uniform grid of their bounding boxes, for the queries "every
// triangle whose box meets this box". Each query reports a triangle once.
class TriangleGrid {
 public:
  TriangleGrid(const MatX3d& X, const MatX3i& F, double cell) : stamp_(F.rows(), -1) {
    lo_ = X.colwise().minCoeff().transpose();
    const Vec3 extent = X.colwise().maxCoeff().transpose() - lo_;
    // At most about 2^21 cells: coarser cells on a large extent.
    cell_ = std::max(cell, 1e-12);
    while ((extent / cell_).array().floor().prod() > (1 << 21)) cell_ *= 2;
    for (int a = 0; a < 3; ++a) dims_[a] = static_cast<int>(std::floor(extent[a] / cell_)) + 1;
    std::vector<std::array<int, 6>> range(F.rows());
    start_.assign(static_cast<size_t>(dims_[0]) * dims_[1] * dims_[2] + 1, 0);
    for (int f = 0; f < F.rows(); ++f) {
      Vec3 a = row(X, F(f, 0)), b = a;
      for (int k = 1; k < 3; ++k) {
        a = a.cwiseMin(row(X, F(f, k)));
        b = b.cwiseMax(row(X, F(f, k)));
      }
      range[f] = cells(a, b);
      each_cell(range[f], [&](size_t c) { ++start_[c + 1]; });
    }
    for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
    items_.resize(start_.back());
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (int f = 0; f < F.rows(); ++f) each_cell(range[f], [&](size_t c) { items_[fill[c]++] = f; });
  }

  // Calls fn(f) once for every triangle whose box meets [a, b].
  template <class Fn>
  void query(const Vec3& a, const Vec3& b, Fn&& fn) {
    ++query_;
    each_cell(cells(a, b), [&](size_t c) {
      for (int i = start_[c]; i < start_[c + 1]; ++i) {
        const int f = items_[i];
        if (stamp_[f] == query_) continue;
        stamp_[f] = query_;
        fn(f);
      }
    });
  }

 private:
  std::array<int, 6> cells(const Vec3& a, const Vec3& b) const {
    std::array<int, 6> r;
    for (int k = 0; k < 3; ++k) {
      r[k] = std::clamp(static_cast<int>(std::floor((a[k] - lo_[k]) / cell_)), 0, dims_[k] - 1);
      r[3 + k] = std::clamp(static_cast<int>(std::floor((b[k] - lo_[k]) / cell_)), 0, dims_[k] - 1);
    }
    return r;
  }
  template <class Fn>
  void each_cell(const std::array<int, 6>& r, Fn&& fn) const {
    for (int z = r[2]; z <= r[5]; ++z)
      for (int y = r[1]; y <= r[4]; ++y)
        for (int x = r[0]; x <= r[3]; ++x)
          fn((static_cast<size_t>(z) * dims_[1] + y) * dims_[0] + x);
  }
  Vec3 lo_;
  double cell_ = 1;
  std::array<int, 3> dims_{};
  std::vector<int> start_, items_, stamp_;
  int query_ = 0;
};

// Distance from p to triangle f of (X, F), with the closest point's barycentric coordinates.
double distance_to(const MatX3d& X, const MatX3i& F, int f, const Vec3& p, Vec3* bary) {
  const Vec3 a = row(X, F(f, 0)), b = row(X, F(f, 1)), c = row(X, F(f, 2));
  const Vec3 w = geometry::closest_point_barycentric(p, a, b, c);
  if (bary) *bary = w;
  return (p - (w[0] * a + w[1] * b + w[2] * c)).norm();
}

// True if triangle f's bounding box in X comes within r of x (per axis).
inline bool near_box(const MatX3d& X, const MatX3i& F, int f, const Vec3& x, double r) {
  for (int a = 0; a < 3; ++a) {
    const double p = X(F(f, 0), a), q = X(F(f, 1), a), t = X(F(f, 2), a);
    if (std::min({p, q, t}) > x[a] + r || std::max({p, q, t}) < x[a] - r) return false;
  }
  return true;
}

}  // namespace

ContactRest ContactRest::build(const MatX3d& X, const MatX3i& F, double keep, double max_thickness) {
  ContactRest r;
  r.X = X;
  r.F = F;
  r.keep = keep;
  const int n = static_cast<int>(X.rows());
  r.vertex_normal.assign(n, Vec3::Zero());
  r.face_normal.assign(F.rows(), Vec3::Zero());
  r.dhat.assign(n, 0.0);
  r.w.assign(n, 0.0);
  double total = 0;
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 N = area_normal(X, F(f, 0), F(f, 1), F(f, 2));
    const double A = N.norm();
    total += A;
    if (A > 0) r.face_normal[f] = N / A;
    for (int k = 0; k < 3; ++k) {
      r.vertex_normal[F(f, k)] += N;
      r.w[F(f, k)] += A / 3;
    }
  }
  for (int v = 0; v < n; ++v) {
    const double len = r.vertex_normal[v].norm();
    r.vertex_normal[v] = len > 0 ? Vec3(r.vertex_normal[v] / len) : Vec3::Zero();
    if (total > 0) r.w[v] /= total;
  }
  for (const ThicknessPair& p : thickness_pairs(X, F, max_thickness)) {
    r.dhat[p.v] = keep * p.d0;
    r.dhat_max = std::max(r.dhat_max, r.dhat[p.v]);
    ++r.vertices;
  }
  return r;
}

bool ContactRest::facing(int v, int f) const {
  return dhat[v] > 0 && F(f, 0) != v && F(f, 1) != v && F(f, 2) != v && face_normal[f].dot(vertex_normal[v]) < 0;
}

double ContactRest::threshold(int v, int f) const {
  if (!facing(v, f)) return 0;
  const double d = distance_to(X, F, f, row(X, v), nullptr);
  if (d < 0.1 * dhat[v] / keep) return 0;
  return std::min(dhat[v], keep * d);
}

namespace {

// Calls fn(f, d, tau, bary) for every triangle f that vertex v (dhat > 0) has a contact with in X:
// across (ContactRest::facing) and closer than tau = threshold(v, f); d the distance, bary the
// closest point's barycentric coordinates.
template <class Fn>
void near_contacts(const MatX3d& X, const ContactRest& rest, TriangleGrid& grid, int v, Fn&& fn) {
  const double dh = rest.dhat[v];
  const Vec3 x = row(X, v), r3 = Vec3::Constant(dh);
  grid.query(x - r3, x + r3, [&](int f) {
    if (!rest.facing(v, f) || !near_box(X, rest.F, f, x, dh)) return;
    Vec3 bary;
    const double d = distance_to(X, rest.F, f, x, &bary);
    if (d >= dh) return;  // (the threshold is at most dh: the rest distance is cheaper to skip)
    const double tau = rest.threshold(v, f);
    if (tau > 0 && d < tau) fn(f, d, tau, bary);
  });
}

}  // namespace

double contact_energy(const MatX3d& X, const ContactRest& rest, double weight, Eigen::VectorXd* grad,
                      HessianSink* hess, int* active) {
  if (active) *active = 0;
  if (rest.vertices == 0 || !(weight > 0)) return 0;
  const MatX3i& F = rest.F;
  TriangleGrid grid(X, F, rest.dhat_max);
  // One vertex's contacts, one per closest feature: a point over a vertex or an edge of the surface
  // across is as close to each of its triangles, and counting it once per triangle would make the
  // barrier jump as the sides slide (6 triangles at a vertex, 1 inside a triangle).
  struct Contact {
    std::array<int, 2> key;  // (vertex, -1), (edge's smaller vertex, larger one) or (-1 - triangle, -1)
    double tau, d;
    int f;
    Vec3 bary;
  };
  std::vector<Contact> found;
  double E = 0;
  bool infinite = false;
  for (int v = 0; v < X.rows() && !infinite; ++v) {
    if (!(rest.dhat[v] > 0)) continue;
    const Vec3 x = row(X, v);
    found.clear();
    near_contacts(X, rest, grid, v, [&](int f, double d, double tau, const Vec3& bary) {
      if (infinite) return;
      if (!(d > 0)) {
        infinite = true;
        return;
      }
      std::array<int, 2> key{-1 - f, -1};
      int corners[3], n = 0;
      for (int k = 0; k < 3; ++k)
        if (bary[k] > 0) corners[n++] = F(f, k);
      if (n == 1) key = {corners[0], -1};
      if (n == 2) key = {std::min(corners[0], corners[1]), std::max(corners[0], corners[1])};
      for (Contact& c : found)
        if (c.key == key) {  // the same feature: the smaller threshold (zero energy at rest for all)
          if (tau < c.tau) c.tau = tau, c.d = d, c.f = f, c.bary = bary;
          return;
        }
      found.push_back({key, tau, d, f, bary});
    });
    const double wv = rest.w[v];
    for (const Contact& c : found) {
      const double r = c.d / c.tau, lr = std::log(r);
      E += wv * -(r - 1) * (r - 1) * lr;
      if (active) ++*active;
      if (!grad && !hess) continue;
      const double b1 = -2 * (r - 1) * lr - (r - 1) * (r - 1) / r;
      const double b2 = -2 * lr - 2 * (r - 1) / r - (r - 1) * (r + 1) / (r * r);
      const int f = c.f;
      const Vec3 p = c.bary[0] * row(X, F(f, 0)) + c.bary[1] * row(X, F(f, 1)) + c.bary[2] * row(X, F(f, 2));
      const Vec3 u = (x - p) / c.d;  // d(distance)/dx_v; -bary_i u for the triangle's corners
      const int vs[4] = {v, F(f, 0), F(f, 1), F(f, 2)};
      const double sc[4] = {1.0, -c.bary[0], -c.bary[1], -c.bary[2]};
      const double gscale = weight * wv * b1 / c.tau;
      const double hscale = 2 * weight * wv * b2 / (c.tau * c.tau);
      for (int k = 0; k < 4; ++k) {
        if (grad) grad->segment<3>(3 * vs[k]) += gscale * sc[k] * u;
        if (hess && sc[k] != 0) hess->add_outer(&vs[k], 1, hscale * sc[k] * sc[k], u.data());
      }
    }
  }
  if (infinite) return std::numeric_limits<double>::infinity();
  return weight * E;
}

void contact_ratios(const MatX3d& X, const ContactRest& rest, std::vector<double>& ratio) {
  ratio.assign(X.rows(), std::numeric_limits<double>::infinity());
  if (rest.vertices == 0) return;
  TriangleGrid grid(X, rest.F, rest.dhat_max);
  for (int v = 0; v < X.rows(); ++v)
    if (rest.dhat[v] > 0)
      near_contacts(X, rest, grid, v, [&](int, double d, double tau, const Vec3&) {
        ratio[v] = std::min(ratio[v], rest.keep * d / tau);
      });
}

Flattened contact_flattened(const MatX3d& X, const ContactRest& rest, double spacing, int max_places) {
  std::vector<double> ratio;
  contact_ratios(X, rest, ratio);
  std::vector<std::pair<double, int>> pressed;  // (ratio, v)
  double fraction = 0;
  for (int v = 0; v < X.rows(); ++v)
    if (ratio[v] < rest.keep) {
      fraction += rest.w[v];
      pressed.emplace_back(ratio[v], v);
    }
  return pressed_places(rest.X, std::move(pressed), fraction, spacing, max_places);
}

namespace {

inline double det3(const Vec3& a, const Vec3& b, const Vec3& c) { return a.dot(b.cross(c)); }

// The roots in [0, T] of c0 + c1 s + c2 s^2 + c3 s^3, ascending: the interval cut at the
// derivative's roots into monotone pieces, each sign change bisected.
std::vector<double> cubic_roots(double c0, double c1, double c2, double c3, double T) {
  auto p = [&](double s) { return ((c3 * s + c2) * s + c1) * s + c0; };
  std::vector<double> cuts = {0.0};
  // p'(s) = c1 + 2 c2 s + 3 c3 s^2
  const double a = 3 * c3, b = 2 * c2, c = c1;
  if (std::abs(a) > 1e-300) {
    const double disc = b * b - 4 * a * c;
    if (disc >= 0) {
      const double r = std::sqrt(disc);
      for (double x : {(-b - r) / (2 * a), (-b + r) / (2 * a)})
        if (x > 0 && x < T) cuts.push_back(x);
    }
  } else if (std::abs(b) > 1e-300) {
    const double x = -c / b;
    if (x > 0 && x < T) cuts.push_back(x);
  }
  cuts.push_back(T);
  std::sort(cuts.begin(), cuts.end());
  std::vector<double> roots;
  for (size_t k = 0; k + 1 < cuts.size(); ++k) {
    double lo = cuts[k], hi = cuts[k + 1], plo = p(lo), phi = p(hi);
    if (plo == 0) {
      roots.push_back(lo);
      continue;
    }
    if ((plo > 0) == (phi > 0)) continue;
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi), pm = p(mid);
      if ((pm > 0) == (plo > 0))
        lo = mid, plo = pm;
      else
        hi = mid;
    }
    roots.push_back(hi);
  }
  return roots;
}

// The first s in [0, T] at which point x + s dx lies in triangle (a + s da, b + s db, c + s dc)
// (the four coplanar and the point's barycentric coordinates in [-1e-6, 1 + 1e-6]); -1 if none.
double first_hit(const Vec3& x, const Vec3& dx, const Vec3 (&q)[3], const Vec3 (&dq)[3], double T) {
  const Vec3 a0 = q[0] - x, b0 = q[1] - x, c0 = q[2] - x;
  const Vec3 a1 = dq[0] - dx, b1 = dq[1] - dx, c1 = dq[2] - dx;
  const double k0 = det3(a0, b0, c0);
  const double k1 = det3(a1, b0, c0) + det3(a0, b1, c0) + det3(a0, b0, c1);
  const double k2 = det3(a1, b1, c0) + det3(a1, b0, c1) + det3(a0, b1, c1);
  const double k3 = det3(a1, b1, c1);
  for (double s : cubic_roots(k0, k1, k2, k3, T)) {
    const Vec3 p = x + s * dx, A = q[0] + s * dq[0], B = q[1] + s * dq[1], C = q[2] + s * dq[2];
    const Vec3 n = (B - A).cross(C - A);
    const double nn = n.squaredNorm();
    if (!(nn > 0)) continue;
    const double u = (C - B).cross(p - B).dot(n) / nn, v = (A - C).cross(p - C).dot(n) / nn;
    const double w = 1 - u - v, tol = 1e-6;
    if (u >= -tol && v >= -tol && w >= -tol) return s;
  }
  return -1;
}

}  // namespace

double contact_step_bound(const MatX3d& X, const MatX3d& D, const ContactRest& rest) {
  if (rest.vertices == 0) return 1.0;
  const double max_move = D.rowwise().norm().maxCoeff();
  if (!(max_move > 0)) return 1.0;
  const MatX3i& F = rest.F;
  // Pairs farther apart than 2 max_move cannot meet within a full step.
  const double reach = 2 * max_move;
  TriangleGrid grid(X, F, std::max(rest.dhat_max, reach));
  double t = 1.0;
  for (int v = 0; v < X.rows(); ++v) {
    if (!(rest.dhat[v] > 0)) continue;
    const Vec3 x = row(X, v), dx = D.row(v).transpose(), r3 = Vec3::Constant(reach);
    grid.query(x - r3, x + r3, [&](int f) {
      if (!rest.facing(v, f)) return;
      // The relative motion of v and the triangle's point: at most the largest of v's against a corner's.
      double m = 0;
      for (int k = 0; k < 3; ++k) m = std::max(m, (dx - D.row(F(f, k)).transpose()).norm());
      if (!(m > 0)) return;
      const double d = distance_to(X, F, f, x, nullptr);
      if (d >= t * m) return;  // they cannot meet within [0, t]
      if (!(rest.threshold(v, f) > 0)) return;
      const Vec3 q[3] = {row(X, F(f, 0)), row(X, F(f, 1)), row(X, F(f, 2))};
      const Vec3 dq[3] = {D.row(F(f, 0)).transpose(), D.row(F(f, 1)).transpose(), D.row(F(f, 2)).transpose()};
      const double s = first_hit(x, dx, q, dq, t);
      if (s >= 0) t = std::min(t, 0.8 * s);
    });
  }
  return t;
}

}  // namespace polycube::deform
