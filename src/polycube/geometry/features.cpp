#include "polycube/geometry/features.h"

#include <algorithm>
#include <cmath>

#include "polycube/core/topology.h"

namespace polycube::geometry {

std::vector<unsigned char> sharp_edges(const SurfaceMesh& s, double angle_deg) {
  const MatX3i adj = face_adjacency(s.F);
  const double c = std::cos(angle_deg * M_PI / 180);
  auto normal = [&](int f) {
    const Vec3 a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), d = s.V.row(s.F(f, 2));
    const Vec3 n = (b - a).cross(d - a);
    return n.norm() > 0 ? Vec3(n.normalized()) : n;
  };
  std::vector<unsigned char> sharp(s.F.rows(), 0);
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (adj(f, k) < 0 || normal(f).dot(normal(adj(f, k))) < c) sharp[f] |= 1 << k;
  return sharp;
}

bool near_sharp_edge(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, const MatX3i& adj,
                     const TriangleTree& tree, const Vec3& p, double tol) {
  Vec3 q;
  return closest_on_sharp_edge(s, sharp, adj, tree, p, tol, q);
}

bool closest_on_sharp_edge(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, const MatX3i& adj,
                           const TriangleTree& tree, const Vec3& p, double tol, Vec3& on_edge) {
  double best = tol;
  bool found = false;
  for_each_sharp_edge_near(s, sharp, adj, tree, p, [&](int ia, int ib) {
    const Vec3 a = s.V.row(ia), b = s.V.row(ib), ab = b - a;
    const double t = closest_point_on_segment(p, a, b);
    const double d = (a + t * ab - p).norm();
    if (d <= best) {
      best = d;
      found = true;
      on_edge = a + t * ab;
    }
  });
  return found;
}

std::vector<Vec3> sharp_corners(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, double turn_deg) {
  std::vector<std::vector<int>> nb(s.V.rows());
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (sharp[f] >> k & 1) {
        const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
        nb[a].push_back(b);
        nb[b].push_back(a);
      }
  std::vector<Vec3> out;
  const double c = std::cos(turn_deg * M_PI / 180);
  for (int v = 0; v < s.V.rows(); ++v) {
    std::sort(nb[v].begin(), nb[v].end());
    nb[v].erase(std::unique(nb[v].begin(), nb[v].end()), nb[v].end());
    if (nb[v].empty()) continue;
    bool corner = nb[v].size() != 2;
    if (!corner) {
      const Vec3 p = s.V.row(v), d0 = (p - Vec3(s.V.row(nb[v][0]))).normalized(),
                 d1 = (Vec3(s.V.row(nb[v][1])) - p).normalized();
      corner = d0.dot(d1) < c;
    }
    if (corner) out.push_back(s.V.row(v).transpose());
  }
  return out;
}

std::vector<int> smooth_patches(const SurfaceMesh& s, const std::vector<unsigned char>& sharp) {
  const MatX3i adj = face_adjacency(s.F);
  UnionFind uf(s.F.rows());
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (!(sharp[f] >> k & 1) && adj(f, k) >= 0) uf.unite(f, adj(f, k));
  std::vector<int> patch(s.F.rows());
  for (int f = 0; f < s.F.rows(); ++f) patch[f] = uf.find(f);
  return patch;
}

}  // namespace polycube::geometry
