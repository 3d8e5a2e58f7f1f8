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
  const int f0 = tree.closest(p).face;
  for (int f : {f0, adj(f0, 0), adj(f0, 1), adj(f0, 2)}) {
    if (f < 0) continue;
    for (int k = 0; k < 3; ++k) {
      if (!(sharp[f] >> k & 1)) continue;
      const Vec3 a = s.V.row(s.F(f, k)), b = s.V.row(s.F(f, (k + 1) % 3)), ab = b - a;
      const double t = ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
      if ((a + t * ab - p).norm() <= tol) return true;
    }
  }
  return false;
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
