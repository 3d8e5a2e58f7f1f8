#include "polycube/io/builder.h"

#include <Eigen/Geometry>
#include <cmath>

namespace polycube::io {

std::vector<std::array<int, 3>> triangulate_polygon(const std::vector<Vec3>& p) {
  const int n = static_cast<int>(p.size());
  std::vector<std::array<int, 3>> tris;
  if (n < 3) return tris;
  if (n == 3) return {{0, 1, 2}};
  if (n == 4) {
    if ((p[0] - p[2]).squaredNorm() <= (p[1] - p[3]).squaredNorm()) return {{0, 1, 2}, {0, 2, 3}};
    return {{0, 1, 3}, {1, 2, 3}};
  }
  // Newell normal, then ear clipping in 2D.
  Vec3 nrm = Vec3::Zero();
  for (int i = 0; i < n; ++i) {
    const Vec3& a = p[i];
    const Vec3& b = p[(i + 1) % n];
    nrm += Vec3((a.y() - b.y()) * (a.z() + b.z()), (a.z() - b.z()) * (a.x() + b.x()), (a.x() - b.x()) * (a.y() + b.y()));
  }
  std::vector<int> idx(n);
  for (int i = 0; i < n; ++i) idx[i] = i;
  auto fan = [&]() {
    std::vector<std::array<int, 3>> t;
    for (int i = 1; i + 1 < n; ++i) t.push_back({0, i, i + 1});
    return t;
  };
  if (nrm.norm() == 0) return fan();
  nrm.normalize();
  Vec3 u = nrm.unitOrthogonal();
  Vec3 w = nrm.cross(u);
  std::vector<Eigen::Vector2d> q(n);
  for (int i = 0; i < n; ++i) q[i] = Eigen::Vector2d(p[i].dot(u), p[i].dot(w));
  auto cross2 = [&](int a, int b, int c) {
    Eigen::Vector2d e1 = q[b] - q[a], e2 = q[c] - q[a];
    return e1.x() * e2.y() - e1.y() * e2.x();
  };
  int guard = 0;
  while (idx.size() > 3 && guard++ < n * n) {
    bool clipped = false;
    const int m = static_cast<int>(idx.size());
    for (int k = 0; k < m; ++k) {
      int a = idx[(k + m - 1) % m], b = idx[k], c = idx[(k + 1) % m];
      if (cross2(a, b, c) <= 0) continue;  // reflex
      bool inside = false;
      for (int j : idx) {
        if (j == a || j == b || j == c) continue;
        if (cross2(a, b, j) >= 0 && cross2(b, c, j) >= 0 && cross2(c, a, j) >= 0) { inside = true; break; }
      }
      if (inside) continue;
      tris.push_back({a, b, c});
      idx.erase(idx.begin() + k);
      clipped = true;
      break;
    }
    if (!clipped) return fan();
  }
  tris.push_back({idx[0], idx[1], idx[2]});
  return tris;
}

void Builder::add_polygon(const std::vector<int>& poly, int src, int line) {
  if (poly.size() == 3) {
    add_triangle(poly[0], poly[1], poly[2], src, line);
    return;
  }
  std::vector<Vec3> pts;
  pts.reserve(poly.size());
  for (int i : poly) pts.emplace_back(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
  for (auto& t : triangulate_polygon(pts)) add_triangle(poly[t[0]], poly[t[1]], poly[t[2]], src, line);
}

template <int C, class M>
static void fill(M& m, const std::vector<int>& a) {
  m.resize(static_cast<Eigen::Index>(a.size() / C), C);
  for (size_t i = 0; i < a.size(); ++i) m(static_cast<Eigen::Index>(i / C), static_cast<Eigen::Index>(i % C)) = a[i];
}

void Builder::finish(MeshData& out) const {
  out.V.resize(num_vertices(), 3);
  for (size_t i = 0; i < v.size(); ++i) out.V(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = v[i];
  fill<3>(out.F, f);
  fill<4>(out.Q, q);
  fill<4>(out.T, t);
  fill<8>(out.H, h);
  out.face_source = fsrc;
  out.face_line = fline;
  out.vertex_line = vline;
}

}  // namespace polycube::io
