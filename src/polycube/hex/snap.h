// Integer snapping of the polycube planes (Huang et al. 2014, Section 5.2), with order constraints.
//
// Per axis k, a plane is a distinct height of the charts normal to k. Two planes "face each other"
// when a line along k meets one and then the other with no plane between (through the volume, or
// across a gap outside it): such a pair must keep its order with at least one cell between, or the
// volume (or the gap) would collapse. Planes that never face each other (the tops of two separate
// bumps) may share an integer height; forcing them apart, as a plain sort does, leaves slabs a
// fraction of a cell thick (two_spheres: planes 3e-4 apart) and folded hexes.
// The planes bounding one chart of another axis (a step, a side face) face each other too.
// Snapping: planes in increasing height, n_i = max(round(s (h_i - h_min)), n_p + 1 over the planes p
// that face i from below). Then the polycube is deformed so that every plane sits at its integer:
// per axis, a displacement, fixed on the plane's vertices and harmonic (P1 Laplacian of the polycube
// tet mesh) elsewhere, small because snapping moves planes by about half a cell at most; the few tets
// it may turn over (where planes move towards each other) are untangled locally, planes kept.
#pragma once
#include <array>
#include <vector>

#include "polycube/core/types.h"

namespace polycube::hex {

/// Plain sorted snapping: n_0 = 0, n_i = max(n_{i-1} + 1, round(s (h_i - h_0))).
std::vector<int> snap_heights(const std::vector<double>& heights, double cells_per_unit);
/// Snapping with order constraints: above[i] lists the planes that must be at least one cell
/// above plane i (each higher than i). heights sorted increasing.
std::vector<int> snap_heights(const std::vector<double>& heights, double cells_per_unit,
                              const std::vector<std::vector<int>>& above);

struct Snapping {
  std::array<std::vector<double>, 3> heights;  ///< distinct plane heights per axis, increasing
  std::array<std::vector<int>, 3> snapped;     ///< their integers (lowest 0)
  std::array<int, 3> shared{};                 ///< planes sharing their integer with another plane, per axis
  std::array<int, 3> merged{};                 ///< planes of thin steps merged into the plane below (merge_below)
  /// Thinnest slab: min over consecutive planes with different integers of s (h_j - h_i) / (n_j - n_i);
  /// well below 1 when planes much closer than a cell had to be kept a cell apart.
  double min_slab_ratio = 1e300;
  /// Per axis, sample lines that meet two faces of the same orientation in a row (constrained
  /// snapping only): the polycube overlaps itself, and no hex grid can represent it.
  std::array<int, 3> overlap_lines{};
  MatX3d Y;                                    ///< polycube vertices in grid units: planes at their integers
  int inverted = 0;                            ///< tets of Y with non-positive volume (after the untangling)
  int untangled = 0;                           ///< tets the harmonic displacement turned over that the local untangling repaired
  int untangle_sweeps = 0;
  double inverted_volume = 0;                  ///< their total |volume|, in cells
};

/// X/T: the exact polycube tet mesh; B/labels: its boundary triangles and chart labels;
/// constrained = false: plain sorted snapping (every plane a cell above the previous one).
/// merge_below (constrained only): consecutive planes of an axis spanning less than this many
/// cells share one integer unless two of them face each other (a thin step loses its riser rather
/// than get a layer of hexes a fraction of a cell thick in the input); 0 = never.
Snapping snap_polycube(const MatX3d& X, const MatX4i& T, const MatX3i& B, const std::vector<int>& labels,
                       double cells_per_unit, bool constrained = true, double merge_below = 0);

/// The order constraints of the planes of axis k, as the constrained snapping finds them: h the
/// distinct heights (increasing) of the charts of axis k (a triangle's plane: the first height at
/// or above its height less tol); out[i] lists the planes j > i that face plane i (a line along k
/// meets i, then j, with no plane between).
std::vector<std::vector<int>> facing_planes(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels, int k,
                                            const std::vector<double>& h, double tol);

/// Thin steps: runs of consecutive planes (heights h, increasing) spanning less than merge_below
/// cells (s cells per unit), no two of which face each other (facing: as facing_planes gives),
/// share one integer; their risers (the charts between them) lose their height instead of getting
/// a one-cell layer of hexes, or row of quads, that maps into a fraction of a cell. Returns each
/// plane's group; group_heights receives the groups' mean heights (increasing). merge_below <= 0:
/// every plane its own group.
std::vector<int> thin_step_groups(const std::vector<double>& h, double s, double merge_below,
                                  const std::vector<std::vector<int>>& facing, std::vector<double>& group_heights);

/// Per axis, the sample lines (through every chart face, as in the snapping) that meet two faces
/// of the same orientation in a row: > 0 when the polycube overlaps itself.
std::array<int, 3> overlap_lines(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels);

}  // namespace polycube::hex
