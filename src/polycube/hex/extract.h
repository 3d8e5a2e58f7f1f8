// All-hex meshing from an exact polycube (Huang et al. 2014, Section 5.2).
//
// 1. Planes: per axis, the distinct heights of the polycube's charts (exact after realization).
// 2. Integer snapping: with s cells per unit length, per axis the sorted heights h_0 < ... < h_m
//    get integers n_0 = 0, n_i = max(n_{i-1} + 1, round(s (h_i - h_0))), one by one: distinct
//    planes never merge or swap and every slab between two planes keeps at least one cell.
//    The snapped polycube is the image of the polycube under the per-axis piecewise-linear,
//    strictly increasing map f_k sending h_i to n_i; its faces lie on integer planes, so it is a
//    union of unit cells.
// 3. Extraction: the unit cells whose centre c has f^-1(c) inside the polycube tet mesh are the
//    hexes; each grid vertex g goes back to the input volume as f^-1(g), located in the polycube
//    tet mesh (bucket grid) and carried to the rest mesh by its barycentric coordinates. Shared
//    grid vertices are one vertex; hexes are ordered as in core/types.h, positive.
// 4. Fidelity: boundary vertices are projected on the target surface (the input surface).
// 5. Optimization: "smart" Laplacian sweeps (Freitag 1997): a vertex moves to the mean of its hex
//    neighbours (boundary vertices: of their boundary neighbours, then back onto the surface)
//    only when the worst scaled Jacobian of its hexes improves; vertices on polycube edges and
//    corners stay, so that the hex mesh keeps its polycube structure.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/hex/quality.h"

namespace polycube::hex {

struct HexOptions {
  /// Approximate number of hexes; 0 = use `hex_size`.
  int target_hexes = 0;
  /// Hex edge length as a fraction of the bounding-box diagonal of the rest mesh (when target_hexes = 0).
  double hex_size = 0.03;
  /// Project boundary vertices on the target surface (when one is given).
  bool project = true;
  /// Smoothing sweeps (0 = off). Each sweep visits every movable vertex once.
  int smooth_iterations = 30;
  /// One layer of hexes along the boundary (pillowing): every boundary quad gets a hex between it
  /// and an inner copy, so that no hex has two faces on a smooth part of the surface (on a sphere
  /// min scaled Jacobian 0.18 -> 0.53), but hexes along sharp 90-degree edges lose (box: 1 -> 0.7).
  /// "on", "off", or "auto": both, the higher min scaled Jacobian (then mean) wins.
  std::string pillow = "auto";
  /// Dihedral angle (degrees) above which an edge of the target surface is a sharp feature: hex
  /// vertices on polycube edges that lie on one slide along it, the others move freely on the surface.
  double sharp_angle_deg = 30;
  /// Polycube corners move on the surface like other boundary vertices (else those on sharp input
  /// features stay where the map put them).
  bool free_corners = true;
  /// Pillow layer thickness: each boundary vertex's inner copy starts this fraction of the way to
  /// the mean centroid of its hexes.
  double pillow_thickness = 0.5;
};

struct HexResult {
  MatX3d V;                       ///< hex vertices, in the rest mesh's (input) frame
  MatX8i H;                       ///< hexes (core/types.h order), positive
  MatX3i grid;                    ///< per vertex of the grid part, its integer polycube coordinates (-1 for pillow vertices)
  double cells_per_unit = 0;      ///< s: unit cells per length unit of the polycube
  std::array<int, 3> cells{};     ///< grid extent per axis (n_m)
  std::array<std::vector<double>, 3> heights;  ///< distinct plane heights per axis (polycube units)
  std::array<std::vector<int>, 3> snapped;     ///< their integers
  int grid_hexes = 0;             ///< hexes of the grid (before pillowing)
  int pillow_hexes = 0;           ///< hexes of the boundary layer (0: not pillowed)
  int sharp_vertices = 0;         ///< grid vertices kept on sharp features of the target (fixed or sliding)
  struct Tried {
    std::string variant;          ///< "no_pillow" or "pillow"
    double sj_min = 0, sj_mean = 0;
  };
  std::vector<Tried> tried;       ///< variants optimized (pillow auto: both), the best is the result
  int max_locate_outside = 0;     ///< grid vertices found only outside every tet (by more than round-off)
  HexQuality extracted;           ///< quality right after extraction (and projection, pillowing)
  HexQuality quality;             ///< final quality
  int smooth_moves = 0;           ///< vertex moves accepted by the smoothing
  double seconds = 0;
};

/// rest/T: the tet mesh (input frame); X: its exact polycube (same connectivity); B/labels: the
/// outward boundary triangles and their chart labels; target: the surface boundary vertices are
/// projected on (nullptr: none). Throws Error(Polycube) when the polycube has no volume.
HexResult hex_mesh_from_polycube(const MatX3d& rest, const MatX4i& T, const MatX3d& X, const MatX3i& B,
                                 const std::vector<int>& labels, const SurfaceMesh* target, const HexOptions& opt = {},
                                 const Hooks& hooks = {});

/// The snapping of step 2 for one axis: sorted distinct heights -> integers (n_0 = 0).
std::vector<int> snap_heights(const std::vector<double>& heights, double cells_per_unit);

}  // namespace polycube::hex
