// Closest-point queries on triangle meshes: a bounding-box hierarchy over the triangles, used to
// carry labels and positions between a surface and its remeshed or tetrahedralized version.
#pragma once
#include <vector>

#include "polycube/core/types.h"

namespace polycube::geometry {

/// Closest point of triangle (a, b, c) to p, as barycentric coordinates (sum 1, all >= 0).
Vec3 closest_point_barycentric(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// Closest point of segment [a, b] to p, as the parameter t in [0, 1] of a + t (b - a) (0 for a
/// zero-length segment).
double closest_point_on_segment(const Vec3& p, const Vec3& a, const Vec3& b);

struct ClosestHit {
  int face = -1;       ///< triangle id
  Vec3 bary = Vec3::Zero();   ///< barycentric coordinates of the closest point in that triangle
  Vec3 point = Vec3::Zero();  ///< the closest point
  double dist2 = 0;    ///< squared distance
};

/// Bounding-box tree over the triangles of (V, F); V and F are copied.
class TriangleTree {
 public:
  TriangleTree(const MatX3d& V, const MatX3i& F);
  /// Closest point of the mesh to p (exact, branch and bound). With `facing`, only among the
  /// triangles whose normal has a positive dot product with it (all of them if none has): in a
  /// thin wall, a point of one side must not be projected on the other side. With `group`, only
  /// among the triangles f with (*group)[f] == group_id (e.g. one smooth patch between sharp edges).
  ClosestHit closest(const Vec3& p, const Vec3* facing = nullptr, const std::vector<int>* group = nullptr,
                     int group_id = -1) const;

 private:
  struct Node {
    Eigen::AlignedBox3d box;
    int left = -1, right = -1;  // children, or -1 for a leaf
    int begin = 0, end = 0;     // leaf: range in order_
  };
  // A triangle as the queries read it, stored in leaf order: corners, (b - a) x (c - a) (the
  // facing test) and the unit normal with the plane's offset (a lower bound of the distance that
  // skips the exact closest point; zero normal for a degenerate triangle: never skipped).
  struct Tri {
    Vec3 a, b, c, cross, unit;
    double offset = 0;
  };
  int build(int begin, int end);
  MatX3d V_;
  MatX3i F_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
  std::vector<Tri> tris_;
};

}  // namespace polycube::geometry
