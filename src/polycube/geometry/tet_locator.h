// Point location in a tetrahedral mesh: a uniform grid of buckets over the mesh's bounding box,
// each holding the tets whose bounding box overlaps it. Used to carry points of the polycube
// (hex-grid vertices) back to the input volume through the piecewise-linear map.
#pragma once
#include <vector>

#include "polycube/core/types.h"

namespace polycube::geometry {

struct TetHit {
  int tet = -1;       ///< containing tet, or the nearest one found when the point lies outside (-1 only when every tet is flat)
  Eigen::Vector4d bary = Eigen::Vector4d::Zero();  ///< barycentric coordinates in that tet (may be < 0 outside)
  double min_bary = -1e300;  ///< min of bary: >= 0 (up to round-off) inside the tet
};

class TetLocator {
 public:
  /// V, T are copied. Tets must have non-zero volume.
  TetLocator(const MatX3d& V, const MatX4i& T);
  /// The tet containing p (largest min barycentric coordinate among the tets near p). When p is
  /// outside the mesh, searches the buckets around it and returns the best tet found, with
  /// min_bary < 0 telling how far outside. When no tet lies within three rings of buckets, all
  /// the tets are searched (a point always gets one), unless `search_all` is false: then
  /// tet = -1, which callers that only ask "inside?" read as outside (a tet holding p lies in p's
  /// own bucket). Far outside points cost a scan of every tet otherwise: the hex grid's cells of a
  /// torus' bounding box took 12 s of the bumpy torus' 40 s hex stage that way.
  TetHit locate(const Vec3& p, bool search_all = true) const;
  /// Barycentric coordinates of p in tet t.
  Eigen::Vector4d barycentric(int t, const Vec3& p) const;

 private:
  int bucket_of(const Vec3& p, int axis) const;
  MatX3d V_;
  MatX4i T_;
  std::vector<Eigen::Matrix3d> inv_;  // per tet, inverse of [v1-v0, v2-v0, v3-v0]
  Eigen::AlignedBox3d box_;
  int dims_[3] = {1, 1, 1};
  Vec3 cell_ = Vec3::Ones();
  std::vector<int> start_, items_;  // CSR: tets of bucket b are items_[start_[b] .. start_[b+1])
};

}  // namespace polycube::geometry
