#include "polycube/validate/intersections.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <unordered_map>

namespace polycube {

namespace {
// Does segment pq cross triangle abc (strictly, up to a tiny tolerance)?
bool segment_hits_triangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 d = q - p, e1 = b - a, e2 = c - a;
  const Vec3 h = d.cross(e2);
  const double det = e1.dot(h);
  const double scale = e1.norm() * e2.norm() * d.norm();
  if (std::abs(det) <= 1e-12 * scale) return false;  // parallel or coplanar
  const double inv = 1.0 / det;
  const Vec3 s = p - a;
  const double u = s.dot(h) * inv;
  // Closed tests: touching counts, since the faces share no vertex.
  if (u < -1e-12 || u > 1 + 1e-12) return false;
  const Vec3 qv = s.cross(e1);
  const double v = d.dot(qv) * inv;
  if (v < -1e-12 || u + v > 1 + 1e-12) return false;
  const double t = e2.dot(qv) * inv;
  return t >= -1e-12 && t <= 1 + 1e-12;
}
}  // namespace

std::vector<std::pair<int, int>> find_self_intersections(const MatX3d& V, const MatX3i& F, size_t max_pairs) {
  std::vector<std::pair<int, int>> out;
  const int nf = static_cast<int>(F.rows());
  if (nf == 0) return out;
  std::vector<Eigen::AlignedBox3d> box(nf);
  double avg = 0;
  for (int f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) box[f].extend(Vec3(V.row(F(f, k))));
    avg += box[f].diagonal().norm();
  }
  avg /= nf;
  const double cell = std::max(avg * 1.5, 1e-300);
  Eigen::AlignedBox3d all;
  for (auto& b : box) all.extend(b);
  auto idx = [&](const Vec3& p) {
    Eigen::Vector3i i;
    for (int k = 0; k < 3; ++k) i[k] = static_cast<int>(std::floor((p[k] - all.min()[k]) / cell));
    return i;
  };
  auto key = [](const Eigen::Vector3i& i) {
    return (static_cast<int64_t>(i[0]) * 73856093) ^ (static_cast<int64_t>(i[1]) * 19349663) ^
           (static_cast<int64_t>(i[2]) * 83492791);
  };
  struct Cell {
    Eigen::Vector3i id;
    std::vector<int> faces;
  };
  std::unordered_map<int64_t, std::vector<Cell>> grid;
  for (int f = 0; f < nf; ++f) {
    Eigen::Vector3i lo = idx(box[f].min()), hi = idx(box[f].max());
    for (int x = lo[0]; x <= hi[0]; ++x)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int z = lo[2]; z <= hi[2]; ++z) {
          Eigen::Vector3i id(x, y, z);
          auto& bucket = grid[key(id)];
          auto it = std::find_if(bucket.begin(), bucket.end(), [&](const Cell& c) { return c.id == id; });
          if (it == bucket.end()) {
            bucket.push_back({id, {}});
            it = bucket.end() - 1;
          }
          it->faces.push_back(f);
        }
  }
  auto crosses = [&](int f, int g) {
    Vec3 a[3], b[3];
    for (int k = 0; k < 3; ++k) {
      a[k] = V.row(F(f, k));
      b[k] = V.row(F(g, k));
    }
    for (int k = 0; k < 3; ++k) {
      if (segment_hits_triangle(a[k], a[(k + 1) % 3], b[0], b[1], b[2])) return true;
      if (segment_hits_triangle(b[k], b[(k + 1) % 3], a[0], a[1], a[2])) return true;
    }
    return false;
  };
  for (auto& [h, bucket] : grid)
    for (const Cell& c : bucket) {
      const auto& fs = c.faces;
      for (size_t i = 0; i < fs.size(); ++i)
        for (size_t j = i + 1; j < fs.size(); ++j) {
          int f = fs[i], g = fs[j];
          if (!box[f].intersects(box[g])) continue;
          // Test each pair once: in the cell holding the min corner of the boxes' overlap.
          if (idx(box[f].intersection(box[g]).min()) != c.id) continue;
          bool share = false;
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) share |= F(f, a) == F(g, b);
          if (share || !crosses(f, g)) continue;
          out.push_back({std::min(f, g), std::max(f, g)});
          if (out.size() >= max_pairs) {
            std::sort(out.begin(), out.end());
            return out;
          }
        }
    }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace polycube
