// Fitting the boundary of a quad or hex mesh to the surface it remeshes: vertices already on the
// surface slide along it so that the points of the surface come closer to the quads.
//
// Smoothing places the vertices for element quality only; where the surface curves (fillets, holes,
// ridges of an organic shape) the flat quads between them then cut far under it (the sagitta of a
// chord). Here each round assigns every sample of the target surface (its vertices and triangle
// centroids) to its closest quad (triangulated along the 0-2 diagonal, as hex::hausdorff measures)
// and moves each free vertex, one at a time, by the Gauss-Newton step of the fitting energy
// sum_s w_s |p_s - c_s|^2 over the samples of its quads (c_s: the sample's closest point, w_s =
// |p_s - c_s|^(power-2), so that the farthest samples weigh most), projected on the tangent plane
// and back onto the surface. A move is kept only when, over the samples of the vertex's quads, the
// largest distance does not grow and the power sum drops, and when the worst element around the
// vertex (the caller's measure: quads or hexes) stays at or above min(its value before, floor).
#pragma once
#include <functional>
#include <vector>

#include "polycube/core/types.h"
#include "polycube/geometry/closest_point.h"

namespace polycube::geometry {

struct SurfaceFitOptions {
  int rounds = 8;               ///< fitting rounds (0 = off); each visits every free vertex once
  double power = 4;             ///< distances are fitted in this power (2 = least squares)
  /// A move never takes the worst element around a vertex below min(floor, its value before).
  /// floor = quality_floor when >= 0; by default (< 0) the worst element of the whole mesh before
  /// the fitting, or 0.5 if that is lower: the fitting never lowers the mesh's minimum quality.
  double quality_floor = -1;
  /// Also fit the quads to the surface: the centre and edge midpoints of a vertex's quads, measured
  /// to the surface, join its energy and its largest distance (the other side of the Hausdorff distance).
  bool two_sided = true;
  /// Then up to this many focused rounds: only the vertices of the quads that hold the largest
  /// distances (a sample of the surface, or a quad point, within focus_ratio of the largest) and of
  /// their neighbour quads move; they stop after 3 rounds without a 0.1% smaller largest distance,
  /// or when those vertices are over focus_max_share of the mesh (largest distances everywhere).
  /// The largest distance (the Hausdorff distance) is set by a few places the full rounds reach
  /// slowly (rocker, 8828 quads: 1.79e-3 after 8 full rounds, 1.64e-3 after 20).
  int focus_rounds = 60;
  double focus_ratio = 0.7;
  /// No focused round when its vertices are more than this share of the mesh's vertices.
  double focus_max_share = 0.3;
  /// The surface's edge midpoints are samples too (besides its vertices and triangle centroids):
  /// where the quads are smaller than the input's triangles, vertices and centroids alone let the
  /// fitting lower their distances while the points between them get farther (basic/eight: the
  /// quads' Hausdorff distance 4.22e-3 without them, 3.60e-3 with them; on by default for quads,
  /// see QuadOptions). Off for hexes, whose fitting is followed by their optimization (rod:
  /// 4.03e-3 without, 4.48e-3 with).
  bool edge_samples = false;
  /// In the focused rounds, the target triangles with a sample within focus_ratio of the largest
  /// distance get a denser grid of samples (barycentric steps of 1/focus_dense; 0 = off): the
  /// largest distance is often reached between a triangle's vertices, centroid and edge midpoints
  /// (fandisk's quads: 3.74e-3 at those samples, 3.88e-3 at the Hausdorff measure's 200k).
  int focus_dense = 0;
  /// A free vertex may leave the surface along the surface's normal by up to this fraction of the
  /// mean length of its quad edges (0 = the vertices stay on the surface). A flat quad over a curved
  /// patch with its corners on the surface cuts under it by the chord's sagitta s; with its corners
  /// s/2 outside, the largest distance either way is about s/2. The vertex's own distance to the
  /// surface then joins its energy and its largest distance, so the fitting balances the two sides.
  double max_offset = 0;
};

struct SurfaceFitStats {
  int rounds = 0;        ///< all rounds, focused ones included
  int focus_rounds = 0;  ///< of those, focused rounds
  int moves = 0;
  double floor = 0;                        ///< the quality floor used
  double max_before = 0, max_after = 0;    ///< largest sample-to-quads distance before and after
  double mean_before = 0, mean_after = 0;  ///< mean sample-to-quads distance
};

/// V: vertex positions (moved in place); Q: the boundary quads over V (outward). free_vertex[v]:
/// v may move (a vertex of Q not on a feature). target/tree: the surface and its tree; with
/// patch_of_face (one id per target triangle), a vertex stays on the smooth patch it starts on.
/// worst(v): the worst element quality around v at the current V (quads or hexes).
/// slide (optional): for a vertex that is not free, slide(v, x, p) sets p to the point of v's sharp
/// edge nearest x and returns true when v may slide along that edge (false: v stays, e.g. at a
/// corner of the sharp edges); such vertices move like free ones, projected on their edge.
/// shape (optional): a second quality around v, 1 where fine (e.g. against slivers, which the
/// scaled Jacobian does not see), under the same rule as worst: a move never takes it below
/// min(its floor, its value before), the floor being its smallest value before the fitting, or
/// 0.5 if that is lower.
SurfaceFitStats fit_to_surface(MatX3d& V, const MatX4i& Q, const SurfaceMesh& target, const TriangleTree& tree,
                               const std::vector<char>& free_vertex, const std::vector<int>* patch_of_face,
                               const std::function<double(int)>& worst, const SurfaceFitOptions& opt = {},
                               const std::function<bool(int, const Vec3&, Vec3&)>& slide = {},
                               const std::function<double(int)>& shape = {});

}  // namespace polycube::geometry
