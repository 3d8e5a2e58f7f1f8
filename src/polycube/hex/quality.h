// Hex-mesh quality: the scaled Jacobian in the Verdict convention, and the two-sided Hausdorff
// distance between two surfaces. Used by the hex stage and by `polycube measure`, so that our
// meshes and other tools' meshes are measured the same way.
#pragma once
#include <algorithm>
#include <array>
#include <vector>

#include "polycube/core/types.h"

namespace polycube::hex {

/// Local faces of a hexahedron (convention in core/types.h), oriented outward for a positive hex.
inline constexpr int kHexFaces[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                        {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
/// Local edges of a hexahedron: the bottom and top quads' edges, then the four vertical ones.
inline constexpr int kHexEdges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                         {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
/// Corners of a hexahedron: each corner, then the three corners joined to it by an edge in
/// Verdict's order (right-handed for a positive hex). As a tet (core/types.h convention), row j
/// is positive exactly when the hex's corner j is.
inline constexpr int kHexCorners[8][4] = {{0, 1, 3, 4}, {1, 2, 0, 5}, {2, 3, 1, 6}, {3, 0, 2, 7},
                                          {4, 7, 5, 0}, {5, 4, 6, 1}, {6, 5, 7, 2}, {7, 6, 4, 3}};

/// Scaled Jacobian of one hex (Verdict's hex_scaled_jacobian): the minimum, over the 8 corners
/// and the centre, of det of the three unit edge (or principal axis) vectors. 1 for a cube or
/// any rectangular box, negative for an inverted hex, 0 when an edge has zero length.
double scaled_jacobian(const std::array<Vec3, 8>& p);
double scaled_jacobian(const MatX3d& V, const MatX8i& H, int h);
/// The 9 values it is the minimum of: the 8 corners (in vertex order), then the centre.
std::array<double, 9> scaled_jacobian_samples(const std::array<Vec3, 8>& p);
/// Sample k of scaled_jacobian_samples(p) alone (0..7: corner k, 8: the centre), the same value.
double scaled_jacobian_sample(const std::array<Vec3, 8>& p, int k);
/// Sample k alone, as scaled_jacobian_sample (the same bits), and in `grad` its gradient with
/// respect to corner j's position (zero when sample k does not depend on it, or is degenerate).
double scaled_jacobian_sample_gradient(const std::array<Vec3, 8>& p, int k, int j, Vec3& grad);
/// The samples that depend on corner j's position: bit k set for sample k (j itself, the three
/// corners joined to it by an edge, and the centre).
unsigned scaled_jacobian_dependents(int j);

/// Elements whose edge ratio exceeds this are slivers (QualityStats::edge_ratio_above_100).
inline constexpr double kSliverEdgeRatio = 100;

/// Statistics of per-element scaled Jacobians (hexes or quads).
struct QualityStats {
  int count = 0;
  double sj_min = 0, sj_mean = 0, sj_max = 0;
  int inverted = 0;      ///< scaled Jacobian <= 0
  int below_0_2 = 0;
  int below_0_5 = 0;
  /// Histogram of the scaled Jacobian over [-1, 1] in 20 bins of 0.1 (bin 0 = [-1, -0.9)).
  std::array<int, 20> histogram{};
  std::vector<double> per_element;  ///< scaled Jacobian of every element
  /// Edge ratio (Verdict's edge_ratio: longest over shortest edge of an element, 1e30 when an edge
  /// has zero length): the scaled Jacobian is 1 for any rectangle or box, however thin, so slivers
  /// (a 5 x 0.001 quad along a thin chamfer) show here only.
  double edge_ratio_max = 0;
  double edge_ratio_mean = 0;  ///< over the elements without a zero-length edge
  int edge_ratio_above_10 = 0;
  int edge_ratio_above_100 = 0;
};
using HexQuality = QualityStats;

/// Statistics of the given per-element values.
QualityStats quality_stats(std::vector<double> values);
/// Adds the edge ratio statistics of the given per-element edge ratios to q.
void add_edge_ratios(QualityStats& q, const std::vector<double>& ratios);
/// Verdict's edge ratio of a polygon or polyhedron given by its edge lengths (1e30 when one is 0).
double edge_ratio(const double* lengths, int count);

HexQuality hex_quality(const MatX3d& V, const MatX8i& H);

/// Boundary quads of a hex mesh (faces used by one hex), oriented outward. Faces used by more than
/// two hexes (a non-manifold mesh) are counted in *nonmanifold when given.
MatX4i boundary_quads(const MatX8i& H, int* nonmanifold = nullptr);
/// Quads split into two triangles each (along the 0-2 diagonal).
MatX3i triangulate_quads(const MatX4i& Q);

/// Two-sided Hausdorff distance between surfaces A and B, estimated by sampling: every vertex of a
/// triangle and points spread on every triangle (about `samples` per surface, at least the vertices and
/// centroids), each measured exactly to the other surface (closest point). Like Metro/M.E.S.H.:
/// besides the maxima, the one-sided mean and root-mean-square distances as integrals over the
/// sampled surface divided by its area (each triangle's samples weigh its area equally; the
/// vertices, sampled for the maximum, weigh nothing).
struct Hausdorff {
  double a_to_b = 0;     ///< max over samples of A of the distance to B
  double b_to_a = 0;
  double max = 0;        ///< two-sided: max of both
  double mean_a_to_b = 0, mean_b_to_a = 0;  ///< area-weighted mean distance
  double rms_a_to_b = 0, rms_b_to_a = 0;    ///< area-weighted root-mean-square distance
  Vec3 a_to_b_at = Vec3::Zero();  ///< the sample of A farthest from B (where a_to_b is reached)
  Vec3 b_to_a_at = Vec3::Zero();
  /// The two one-sided means, averaged; the larger one-sided RMS (the reports' figures).
  double mean() const { return 0.5 * (mean_a_to_b + mean_b_to_a); }
  double rms() const { return std::max(rms_a_to_b, rms_b_to_a); }
};
Hausdorff hausdorff(const MatX3d& VA, const MatX3i& FA, const MatX3d& VB, const MatX3i& FB, int samples = 200000);

/// Fraction of the volume of the hexes (V, H) in hexes whose centre lies outside the closed
/// oriented surface (SV, SF) (generalized winding number under 1/2). About 0 when the hexes fill
/// the surface's volume; a map that overlaps itself fills gaps of the input (between two legs
/// pressed together), which the Hausdorff distance, as small as the gap, does not show.
double volume_outside(const MatX3d& V, const MatX8i& H, const MatX3d& SV, const MatX3i& SF);

}  // namespace polycube::hex
