// All-hex meshing from an exact polycube (Huang et al. 2014, Section 5.2).
//
// 1. Planes: per axis, the distinct heights of the polycube's charts (exact after realization).
// 2. Integer snapping (snap.h): planes that face each other keep their order and at least one cell
//    between them, the others may share an integer; the polycube tet mesh is deformed (harmonic
//    displacement per axis) so that its planes lie at their integers: its faces lie on integer
//    planes, so it is a union of unit cells. Fallbacks when that deformation inverts a tet: plain
//    sorted snapping, then the per-axis piecewise-linear map sending the sorted heights to their
//    integers (exact, never inverts, but stretches thin slabs).
// 3. Extraction: the unit cells whose centre lies inside the snapped polycube tet mesh are the
//    hexes; each grid vertex is located in that mesh (bucket grid) and carried to the input volume
//    by its barycentric coordinates in the rest tet. Shared grid vertices are one vertex; hexes are
//    ordered as in core/types.h, positive.
// 4. Fidelity: boundary vertices are projected on the target surface (the input surface); vertices
//    on polycube edges lying on a sharp edge of the target slide along the polycube edge.
// 5. Pillowing (optional, "auto" tries both) and optimization (optimize.h).
#pragma once
#include <array>
#include <string>
#include <vector>

#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/geometry/surface_fit.h"
#include "polycube/hex/grading.h"
#include "polycube/hex/quality.h"

namespace polycube::hex {

struct HexOptions {
  /// Approximate number of grid hexes (the polycube's volume over the cell volume; pillowing adds
  /// a boundary layer). Like the paper's Table II counts (7k-220k); used when hex_size is 0.
  int target_hexes = 10000;
  /// Hex edge length as a fraction of the bounding-box diagonal of the rest mesh; > 0 overrides
  /// target_hexes.
  double hex_size = 0;
  /// Cells per length unit of the polycube; > 0 overrides both (the quad stage sets it from a quad count).
  double cells_per_unit = 0;
  /// Project boundary vertices on the target surface (when one is given).
  bool project = true;
  /// Smoothing sweeps (0 = off). Each sweep visits every movable vertex once.
  int smooth_iterations = 30;
  /// The local optimization visits vertices whose worst hex is below this scaled Jacobian: 0.5
  /// only lifts the worst; 0.9 also raises the mean (mambo_B9 at 10k hexes: min 0.50 -> 0.56, mean
  /// 0.905 -> 0.94; block: 0.50 -> 0.58, 0.923 -> 0.935), at about twice the time.
  double optimize_below = 0.9;
  /// The optimization may not take a hex above this edge ratio (longest over shortest edge) unless
  /// it lowers that hex's ratio, at vertices whose hexes are all at scaled Jacobian 0.5 or more (the
  /// scaled Jacobian is 1 on a box however thin, and moves it accepted squeezed pillow hexes to an
  /// edge 1/500 of their longest). 0 = no limit. Measured (2026-11-27, --polycube-map, limit 10 /
  /// none): rocker at 24631 grid hexes: edge ratio max 112 / 495, hexes over 10 138 / 351, over 100
  /// 2 / 21; min scaled Jacobian 0.553 / 0.755, mean 0.9531 / 0.9539, Hausdorff 2.25e-3 / 2.31e-3.
  /// Bumpy torus at 28557: max 144 / 568, over 10 294 / 920, over 100 4 / 47; 0.534 / 0.638,
  /// 0.9339 / 0.9364, 5.55e-3 / 5.96e-3.
  double max_edge_ratio = 10;
  /// One layer of hexes along the boundary (pillowing): every boundary quad gets a hex between it
  /// and an inner copy, so that no hex has two faces on a smooth part of the surface (on a sphere
  /// min scaled Jacobian 0.18 -> 0.53), but hexes along sharp 90-degree edges lose (box: 1 -> 0.7).
  /// "on", "off", or "auto": both, the higher min scaled Jacobian (then mean) wins.
  std::string pillow = "auto";
  /// Dihedral angle (degrees) above which an edge of the target surface is a sharp feature: hex
  /// vertices on polycube edges that lie on one slide along it, the others move freely on the surface.
  double sharp_angle_deg = 30;
  /// Polycube corners move on the surface like other boundary vertices unless they lie on a corner
  /// of the target (3+ sharp edges); false: every polycube corner on a sharp feature stays.
  bool free_corners = true;
  /// Pillow layer thickness: each boundary vertex's inner copy starts this fraction of the way to
  /// the mean centroid of its hexes.
  double pillow_thickness = 0.5;
  /// Thin steps: consecutive planes of an axis spanning less than this many cells share one integer
  /// (unless two of them face each other through the volume or a gap), so that a step far thinner
  /// than a hex loses its riser instead of getting a layer of hexes squeezed into it. Only the
  /// thinnest: a step thin in the polycube is not always thin in the input. Measured (polycube maps
  /// from the pipeline, --polycube-map): bumpy torus (paper's setting), 29000 grid hexes: 6 hexes
  /// inverted at 0, valid at 0.01 (6 planes merged, 0.689/0.940); at 38665: 0.694/0.943, Hausdorff
  /// 5.7e-3 at 0, 0.731/0.943, 5.5e-3 at 0.01, inverted hexes at 0.05, 0.008/0.894 at 0.25 (39
  /// merged); spot: 3 merged, mean and Hausdorff a little better; rod, fandisk: no step that thin
  /// (rod at 0.25: 0.673 against 0.702). 0 = every step keeps a cell.
  double merge_thin_steps = 0.01;
  /// hex_mesh_thin_step_retries: a result whose worst hex is under this scaled Jacobian next to
  /// planes closer than 0.05 (then 0.25) cells is extracted again with those steps merged (0 =
  /// only when hexes are inverted).
  double thin_step_retry_below = 0.3;
  /// Creases of the target (chains of edges sharper than sharp_angle_deg with one edge sharper
  /// than capture_angle_deg) that no boundary quad edge follows: a variant of the chosen mesh moves
  /// the nearest path of boundary vertices onto each and keeps it there (geometry/feature_capture.h);
  /// a run whose hexes stay under min(0.3, the worst elsewhere) is undone, and the variant is kept
  /// when its boundary is closer to the target and its worst hex at least min(0.3, the worst
  /// without). Costs one more optimization when a crease is not followed.
  bool capture_creases = false;
  double capture_angle_deg = 45;
  /// Graded grid (grading.h): sheets of hexes denser where cells would cut the curved surface more
  /// (measure "chord", default) or where the map stretches the boundary ("stretch"); strength 0 =
  /// the paper's uniform grid.
  GradingOptions grading;
  /// The polycube map has inverted tets (PipelineOptions::hex_through_folds): sample lines meeting
  /// two faces of one orientation in a row (there, around the folds) do not stop the extraction;
  /// the snapping is then the sorted one (or the piecewise-linear map).
  bool folded_map = false;
  /// After the optimization, boundary vertices off features slide on the target so that it comes
  /// closer to the hex boundary, no hex around a moved vertex dropping below min(floor, its worst
  /// before) (geometry/surface_fit.h; rounds = 0: off).
  geometry::SurfaceFitOptions fit;
  /// Hexes still inverted after the optimization: their inverted corners are untangled (every
  /// vertex but the boundary's and the features' free; hex/untangle.h), the mesh optimized again,
  /// and the result kept when it has fewer inverted hexes (false: off; also off with
  /// smooth_iterations 0).
  bool untangle = true;
};

struct HexResult {
  MatX3d V;                       ///< hex vertices, in the rest mesh's (input) frame
  MatX8i H;                       ///< hexes (core/types.h order), positive
  MatX3i grid;                    ///< per vertex of the grid part, its integer polycube coordinates (-1 for pillow vertices)
  double cells_per_unit = 0;      ///< s: unit cells per length unit of the polycube
  std::array<int, 3> cells{};     ///< grid extent per axis (n_m)
  std::array<std::vector<double>, 3> heights;  ///< distinct plane heights per axis (polycube units)
  std::array<std::vector<int>, 3> snapped;     ///< their integers (lowest 0)
  std::string snapping;           ///< "constrained", "sorted" or "piecewise_linear" (see snap.h)
  int shared_planes = 0;          ///< planes sharing their integer height with another (constrained snapping)
  int merged_planes = 0;          ///< of those, planes of thin steps merged (HexOptions::merge_thin_steps)
  std::array<double, 3> grading_max_slope{}, grading_min_slope{};  ///< the grading's extreme sheet densities per axis (relative; 0: uniform grid)
  double min_slab_ratio = 0;      ///< thinnest slab between planes, in cells, over the cell it got (see snap.h)
  int grid_hexes = 0;             ///< hexes of the grid (before pillowing)
  int pillow_hexes = 0;           ///< hexes of the boundary layer (0: not pillowed)
  int crease_runs = 0, crease_captured = 0;  ///< creases no boundary edge followed; runs kept captured (capture_creases)
  int sharp_vertices = 0;         ///< grid vertices kept on sharp features of the target (fixed or sliding)
  struct Tried {
    std::string variant;          ///< "no_pillow" or "pillow"
    double sj_min = 0, sj_mean = 0;
    /// Left with inverted hexes, not untangled: the other variant (pillow auto) had none and its
    /// worst hex at 0.3 or more, which an untangled mesh (worst hex barely positive) does not
    /// beat.
    bool untangle_skipped = false;
  };
  std::vector<Tried> tried;       ///< variants optimized (pillow auto: both), the best is the result
  int max_locate_outside = 0;     ///< grid vertices found only outside every tet (by more than round-off)
  HexQuality extracted;           ///< quality right after extraction (and projection, pillowing)
  HexQuality quality;             ///< final quality
  int smooth_moves = 0;           ///< vertex moves accepted by the smoothing
  /// HexOptions::untangle on the result: its inverted hexes before, and after (kept) or -1 (not
  /// kept, or not needed).
  int untangle_inverted_before = 0, untangle_inverted_after = -1;
  /// The boundary was fitted to the target again after the untangling (whose optimization lets it
  /// slide for quality alone), the fit statistics then cover both fittings.
  bool refitted_after_untangling = false;
  /// The Hausdorff distance (absolute, as hex::hausdorff measures it) before that fitting was
  /// tried; -1 when it was not (no untangling kept, or no fitting).
  double hausdorff_before_refit = -1;
  geometry::SurfaceFitStats fit;  ///< the fitting of the boundary to the target (target samples to hex boundary)
  double seconds = 0;
};

/// rest/T: the tet mesh (input frame); X: its exact polycube (same connectivity); B/labels: the
/// outward boundary triangles and their chart labels; target: the surface boundary vertices are
/// projected on (nullptr: none). Throws Error(Polycube) when the polycube has no volume.
HexResult hex_mesh_from_polycube(const MatX3d& rest, const MatX4i& T, const MatX3d& X, const MatX3i& B,
                                 const std::vector<int>& labels, const SurfaceMesh* target, const HexOptions& opt = {},
                                 const Hooks& hooks = {});

/// One more extraction with thicker steps merged (hex_mesh_thin_step_retries).
struct ThinStepRetry {
  double thin_steps = 0;  ///< HexOptions::merge_thin_steps of the result it replaced or not
  int inverted = 0;       ///< that result's inverted hexes
  double sj_min = 0;      ///< and its worst scaled Jacobian
  bool replaced = false;  ///< the retry was better (fewer inverted hexes, then a worst hex higher by 0.05+)
};

/// hex_mesh_from_polycube, extracted again with the planes of thicker steps merged (merge_thin_steps
/// 0.05, then 0.25) while the result has inverted hexes or a worst scaled Jacobian under
/// opt.thin_step_retry_below next to planes closer than that many cells (min_slab_ratio): a riser far thinner
/// than a hex gets a row of strip-like boundary quads, whose hexes fold or nearly so. A retry is kept
/// only when better. Measured: bumpy torus (Table II's setting, bench polycube, 28557 grid hexes):
/// min 0.005 (slab 0.023 cells kept) -> 0.715 at 0.05, Hausdorff 4.1e-3 -> 6.0e-3 (the riser's
/// planes merged). `used_thin_steps` (optional): merge_thin_steps of the result returned.
HexResult hex_mesh_thin_step_retries(const MatX3d& rest, const MatX4i& T, const MatX3d& X, const MatX3i& B,
                                     const std::vector<int>& labels, const SurfaceMesh* target, const HexOptions& opt,
                                     std::vector<ThinStepRetry>* retries = nullptr,
                                     double* used_thin_steps = nullptr, const Hooks& hooks = {});

}  // namespace polycube::hex
