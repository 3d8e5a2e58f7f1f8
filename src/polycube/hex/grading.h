// Graded hex grids: per-axis sheet density following the polycube map's stretch.
//
// The paper's grid is uniform in the polycube: every cell a cube there. Where the map stretches the
// boundary along an axis (a blend the polycube compresses), the cell edges along that axis come out
// that much longer on the input, and the boundary quads cut the curved surface by their chord
// (rod at 15k hexes: quads 3x the median edge over a fillet, Hausdorff 3.9e-3 of the diagonal
// there, the mean distance 0.24e-3). A hex grid stays a grid under a monotone map per axis: the
// sheets of hexes normal to axis k may sit at any increasing heights. So the polycube is warped per
// axis before the snapping, x_k -> W_k(x_k) with W_k' following the stretch of the map along k at
// the boundary (the longest mapped edge of any boundary triangle of another axis's chart in that
// slab, smoothed over about a cell), and the uniform integer grid of the warped polycube gives
// sheets denser where the map stretches and sparser where it shrinks; the warp keeps the volume, so
// the hex count stays about the requested one. Charts stay planes and the map stays exact (the
// hexes' vertices are located in the warped polycube tet mesh, which has the rest mesh's tets).
#pragma once
#include <array>
#include <string>
#include <vector>

#include "polycube/core/types.h"

namespace polycube::hex {

struct GradingOptions {
  /// Exponent applied to the measure's ratio to its mean: 0 = uniform grid (the paper's); 1 =
  /// sheets spaced to even out the measure (within max_ratio). Measured on saved polycube maps
  /// (rod 11k, sphere_coarse 7k, eight, torus, fandisk, spot 10k grid hexes), Hausdorff max
  /// 1e-3 at 0 / 0.5 / 1: rod 3.90 / 2.75 / 2.79, torus 2.48 / 2.20 / 2.00, eight 3.06 / 2.98 /
  /// 2.61, spot 12.2 / 8.5 / 10.0, fandisk 6.63 / 6.56 / 6.47, sphere_coarse 1.59 / 1.61 / 1.62;
  /// mean scaled Jacobian within 0.003 at 0.5 (0.013 lower on rod at 1).
  double strength = 0.5;
  /// The slope of a warp stays within [1 / max_ratio, max_ratio] of the mean slope (before the
  /// exponent): a few crushed triangles must not take all the sheets.
  double max_ratio = 4;
  /// "chord": sheets denser where cells would cut the curved surface by more (the map's second
  /// derivative normal to the surface, its square root: the density that evens the chord error);
  /// "stretch": where the map stretches the boundary (the first derivative).
  std::string measure = "chord";
  /// Edges of the input sharper than this (degrees) split the normals the chord measure uses.
  double sharp_angle_deg = 30;
};

/// Monotone piecewise-linear map of one axis (bins of equal width in the polycube).
struct AxisWarp {
  double lo = 0, width = 1;   ///< first breakpoint and the bins' width (polycube units)
  std::vector<double> at;     ///< warped coordinate at each breakpoint (strictly increasing)
  double operator()(double x) const;
  double inverse(double y) const;
};

struct Grading {
  std::array<AxisWarp, 3> warp;
  std::array<double, 3> max_slope{}, min_slope{};  ///< extreme slopes of the warps, relative to the mean
  /// The warped polycube (same tets as X).
  MatX3d Y;
  int turned_over = 0;    ///< tets the warp turned over (slivers across a change of slope), untangled locally
  int left_inverted = 0;  ///< of those, still not positive after the untangling
};

/// rest/T: the tet mesh; X: its exact polycube; B/labels: the boundary triangles and their labels
/// (code 0..5, axis = label / 2); s: cells per polycube unit of the grid (bins are a quarter cell).
/// The warp keeps the polycube's volume (one scale factor for the three axes); with no tets (T
/// empty: a surface polycube, B its triangles), its area.
Grading grade_polycube(const MatX3d& rest, const MatX4i& T, const MatX3d& X, const MatX3i& B,
                       const std::vector<int>& labels, double s, const GradingOptions& opt);

}  // namespace polycube::hex
