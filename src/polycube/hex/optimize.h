// Hex-mesh optimization: vertices move to raise the worst scaled Jacobians, boundary vertices
// staying on a surface. Two passes per sweep:
//   1. "smart" Laplacian (Freitag 1997): a vertex moves (fully, half or a quarter of the way) to
//      the mean of its edge neighbours (boundary vertices: of their boundary neighbours, then back
//      onto the surface) when the worst scaled Jacobian of its hexes does not get worse;
//   2. local optimization of vertices whose hexes are below `optimize_below` (or inverted): descent on the soft minimum sum exp(-k sj) over the 9 samples of each incident
//      hex (analytic gradient, tangent to the surface on the boundary, backtracking
//      line search accepting only moves that raise the worst scaled Jacobian). This untangles.
#pragma once
#include <array>
#include <vector>

#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/geometry/closest_point.h"

namespace polycube::hex {

struct OptimizeStats {
  int sweeps = 0;
  int laplacian_moves = 0;
  int optimized_moves = 0;
};

/// fixed[v] != 0: v never moves. slide[v] = {a, b} (when given and both >= 0): v only moves along
/// the polyline a - v - b of the positions at the call (a feature curve, e.g. a polycube edge).
/// surface: boundary vertices are kept on it (nullptr: they stay); surface_patch (optional, one
/// id per surface triangle): each boundary vertex stays on the patch it starts on (patches bounded
/// by sharp edges, so that smoothing does not cut a sharp edge; only vertices of hexes below 0.3
/// may leave it, when the polycube has no hex edge along a sharp edge). optimize_below: pass 2 visits the
/// vertices whose worst hex is below this scaled Jacobian. max_edge_ratio (> 0): a move of a vertex
/// whose hexes are all at scaled Jacobian 0.5 or more may not take one of them above this edge
/// ratio (longest over shortest edge) unless it lowers that hex's ratio (0 = no such limit).
OptimizeStats optimize_hexes(MatX3d& V, const MatX8i& H, const std::vector<char>& fixed,
                             const std::vector<std::array<int, 2>>& slide, const geometry::TriangleTree* surface,
                             const std::vector<int>* surface_patch, int sweeps, double optimize_below = 0.9,
                             double max_edge_ratio = 0, const Hooks& hooks = {});

}  // namespace polycube::hex
