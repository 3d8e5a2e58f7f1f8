#include "polycube/geometry/tet_locator.h"

#include <algorithm>
#include <cmath>

#include "polycube/core/error.h"

namespace polycube::geometry {

TetLocator::TetLocator(const MatX3d& V, const MatX4i& T) : V_(V), T_(T) {
  // (Non-finite coordinates would give a non-finite bucket grid, and indices out of range.)
  POLYCUBE_ASSERT(V.allFinite(), "TetLocator: non-finite vertex coordinates");
  const int nt = static_cast<int>(T.rows());
  inv_.resize(nt);
  for (int v = 0; v < V.rows(); ++v) box_.extend(V.row(v).transpose());
  for (int t = 0; t < nt; ++t) {
    Eigen::Matrix3d M;
    for (int j = 0; j < 3; ++j) M.col(j) = (V.row(T(t, j + 1)) - V.row(T(t, 0))).transpose();
    inv_[t] = M.inverse();
  }
  if (nt == 0) return;
  // About one tet per bucket.
  const Vec3 ext = (box_.max() - box_.min()).cwiseMax(1e-300);
  const double h = std::cbrt(ext.prod() / nt);
  for (int k = 0; k < 3; ++k) {
    dims_[k] = std::clamp(static_cast<int>(std::ceil(ext[k] / std::max(h, 1e-300))), 1, 1024);
    cell_[k] = ext[k] / dims_[k];
  }
  const size_t nb = static_cast<size_t>(dims_[0]) * dims_[1] * dims_[2];
  std::vector<int> count(nb + 1, 0);
  auto for_buckets = [&](int t, auto&& f) {
    Eigen::AlignedBox3d b;
    for (int j = 0; j < 4; ++j) b.extend(V.row(T(t, j)).transpose());
    int lo[3], hi[3];
    for (int k = 0; k < 3; ++k) {
      lo[k] = bucket_of(b.min(), k);
      hi[k] = bucket_of(b.max(), k);
    }
    for (int x = lo[0]; x <= hi[0]; ++x)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int z = lo[2]; z <= hi[2]; ++z) f((static_cast<size_t>(x) * dims_[1] + y) * dims_[2] + z);
  };
  for (int t = 0; t < nt; ++t) for_buckets(t, [&](size_t b) { ++count[b + 1]; });
  for (size_t b = 0; b < nb; ++b) count[b + 1] += count[b];
  start_ = count;
  items_.resize(count[nb]);
  for (int t = 0; t < nt; ++t) for_buckets(t, [&](size_t b) { items_[count[b]++] = t; });
}

int TetLocator::bucket_of(const Vec3& p, int k) const {
  const double u = (p[k] - box_.min()[k]) / cell_[k];
  if (!(u > 0)) return 0;
  return std::min(static_cast<int>(u), dims_[k] - 1);
}

Eigen::Vector4d TetLocator::barycentric(int t, const Vec3& p) const {
  const Vec3 b = inv_[t] * (p - V_.row(T_(t, 0)).transpose());
  return Eigen::Vector4d(1 - b.sum(), b[0], b[1], b[2]);
}

TetHit TetLocator::locate(const Vec3& p, bool search_all) const {
  TetHit hit;
  if (T_.rows() == 0) return hit;
  const int c[3] = {bucket_of(p, 0), bucket_of(p, 1), bucket_of(p, 2)};
  auto consider = [&](int t) {
    const Eigen::Vector4d w = barycentric(t, p);
    const double m = w.minCoeff();  // NaN for a flat tet: never taken
    if (m > hit.min_bary) {
      hit.min_bary = m;
      hit.tet = t;
      hit.bary = w;
    }
  };
  auto scan = [&](int x, int y, int z) {
    const size_t b = (static_cast<size_t>(x) * dims_[1] + y) * dims_[2] + z;
    for (int i = start_[b]; i < start_[b + 1]; ++i) consider(items_[i]);
  };
  scan(c[0], c[1], c[2]);
  // Outside (or on the boundary up to round-off): widen the search ring by ring.
  for (int r = 1; r <= 3 && hit.min_bary < -1e-9; ++r)
    for (int x = std::max(0, c[0] - r); x <= std::min(dims_[0] - 1, c[0] + r); ++x)
      for (int y = std::max(0, c[1] - r); y <= std::min(dims_[1] - 1, c[1] + r); ++y)
        for (int z = std::max(0, c[2] - r); z <= std::min(dims_[2] - 1, c[2] + r); ++z)
          if (std::max({std::abs(x - c[0]), std::abs(y - c[1]), std::abs(z - c[2])}) == r) scan(x, y, z);
  // No tet within three rings of buckets (far outside, or only flat tets there: a folded map):
  // every tet, so that a point always gets one.
  if (hit.tet < 0 && search_all)
    for (int t = 0; t < T_.rows(); ++t) consider(t);
  return hit;
}

}  // namespace polycube::geometry
