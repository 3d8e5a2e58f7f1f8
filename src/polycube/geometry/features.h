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
