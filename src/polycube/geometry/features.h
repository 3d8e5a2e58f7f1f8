// Sharp features of a triangle surface: sharp edges by dihedral angle, the smooth patches they
// bound, and whether a point lies on a sharp edge. Used to keep hex and quad meshes on features.
#pragma once
#include <vector>

#include "polycube/core/types.h"
#include "polycube/geometry/closest_point.h"

namespace polycube::geometry {

/// Per triangle, bit k set when its edge k (F(f,k), F(f,k+1)) is sharp: the normals of the two
/// triangles differ by more than angle_deg (or the edge is open).
std::vector<unsigned char> sharp_edges(const SurfaceMesh& s, double angle_deg);

/// Per triangle, the id of its smooth patch: triangles connected across non-sharp edges.
std::vector<int> smooth_patches(const SurfaceMesh& s, const std::vector<unsigned char>& sharp);

/// Calls f(a, b) for every sharp edge (vertex ids a, b: the edge k of a triangle, F(f,k), F(f,k+1))
/// of the triangle holding p's closest point on s and of its edge neighbours (tree: over s; adj:
/// face_adjacency(s.F)); an edge shared by two of them is visited twice.
template <class Visit>
void for_each_sharp_edge_near(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, const MatX3i& adj,
                              const TriangleTree& tree, const Vec3& p, Visit&& f) {
  const int f0 = tree.closest(p).face;
  for (int t : {f0, adj(f0, 0), adj(f0, 1), adj(f0, 2)}) {
    if (t < 0) continue;
    for (int k = 0; k < 3; ++k)
      if (sharp[t] >> k & 1) f(s.F(t, k), s.F(t, (k + 1) % 3));
  }
}

/// Whether p lies within tol of a sharp edge of the triangles around its closest point on s
/// (tree: over s; adj: face_adjacency(s.F)).
bool near_sharp_edge(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, const MatX3i& adj,
                     const TriangleTree& tree, const Vec3& p, double tol);

/// The point of a sharp edge (of the triangles around p's closest point on s) nearest to p, if one
/// lies within tol.
bool closest_on_sharp_edge(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, const MatX3i& adj,
                           const TriangleTree& tree, const Vec3& p, double tol, Vec3& on_edge);

/// Corners of the sharp edges: vertices with other than two sharp edges, or two that turn by more
/// than turn_deg.
std::vector<Vec3> sharp_corners(const SurfaceMesh& s, const std::vector<unsigned char>& sharp, double turn_deg = 30);

}  // namespace polycube::geometry
