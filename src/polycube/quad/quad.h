// Quad remeshing of the input surface from the volumetric polycube map (Huang et al. 2014,
// Section 5.3, here through the volume): the boundary quads of the integer grid inside the snapped
// polycube (hex/extract.h, no pillow) mapped back onto the input surface form a conforming quad
// mesh, one quad per unit square of the polycube's faces; its irregular vertices are the polycube's
// corners. The quads are then smoothed on the surface (smart Laplacian on the quad scaled Jacobian),
// vertices on sharp edges of the input staying put and the others on their smooth patch.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "polycube/chart/extract.h"
#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/geometry/feature_capture.h"
#include "polycube/geometry/surface_fit.h"
#include "polycube/hex/grading.h"
#include "polycube/hex/quality.h"

namespace polycube::quad {

/// Scaled Jacobian of a quad (Verdict's quad_scaled_jacobian): the minimum over the 4 corners of
/// (e_prev x e_next) . n / (|e_prev| |e_next|), n the unit normal of the quad's centre. 1 for any
/// rectangle, sin(theta) for a rhombus of angle theta, <= 0 for a folded quad, 0 for a zero edge.
double scaled_jacobian(const std::array<Vec3, 4>& p);

using QuadQuality = hex::QualityStats;
QuadQuality quad_quality(const MatX3d& V, const MatX4i& Q);

struct QuadOptions {
  int smooth_iterations = 30;    ///< smoothing sweeps on the surface (0 = off)
  /// The smoothing also takes moves that lower the largest edge ratio of a vertex's quads above
  /// this by 10%+, if its worst quad stays at 0.5 or more (or where it was); the scaled Jacobian
  /// is near 1 on a thin rectangle, so it alone never widens one. 0 = off.
  double max_edge_ratio = 10;
  /// Slivers (quads with an edge ratio over 100, the warning's threshold): a move of one corner
  /// never lowers a thin rectangle's edge ratio (its other short edge stays), so the smoothing also
  /// takes moves that lower the largest aspect of the vertex's quads (longest edge squared over
  /// area) by 10%+ without raising their edge ratio by more than 10%; and the fitting to the
  /// surface may not take a quad's edge ratio above the mesh's largest before it (counted as at
  /// least 50 and at most 100), nor raise it where it is above that. Homer at 2000 quads (surface mode):
  /// edge ratio max 586 -> 219, quads over 10 400 -> 134, scaled Jacobian 0.234 / 0.874 -> 0.278 /
  /// 0.903, Hausdorff 26.7e-3 -> 28.5e-3 (its thin-step retry now kept: 3212 -> 2958 quads); cow
  /// 295 -> 151, the same Hausdorff; spot 77.5 -> 68.6; fandisk and rocker at Table I's counts and
  /// blub unchanged (the thin-step retries also run when the extracted grid had slivers, see
  /// thin_step_retries). Nor may the pattern search or a feature vertex's slide take the quads
  /// around a vertex over an edge ratio of 100 unless they were (mambo_B1 at 2000 quads: the last
  /// pass's slides made one of 3278; 59.5 with the rule). false: none of these.
  bool widen_slivers = true;
  /// The shape pass, before the last passes: the vertices of quads with an edge ratio over
  /// max_edge_ratio, and shape_rings rings of neighbours around them, move on the surface (free
  /// vertices down a numerical gradient in the tangent plane, those on sharp edges along them) to
  /// lower the sum over their quads' corners of the condition number squared ((|e1|^2 + |e2|^2) /
  /// (2 |e1 x e2|): 1 at a square's corner, (a + 1/a) / 2 at a rectangle's of aspect a, infinite
  /// where a corner folds; Knupp's shape measure, which sees the thin rectangles the scaled
  /// Jacobian takes for perfect) plus a quarter of (s + 1/s) / 2, s the corner's area over a
  /// square of the mean edge's. Squared, so that no quad grows thinner for another to get square;
  /// with the size term, so that quads next to a short edge that cannot move do not shrink to
  /// squares of it; and quads with such an edge (both ends pinned, or on a sharp edge without
  /// room to slide) are left out of the sum, only kept from folding. Feature vertices of quads
  /// over edge ratio 100 that lie on no crease (capture_angle_deg: facets of a coarse smooth
  /// surface) move like free ones. A move may not take the worst quad around the vertex below
  /// 0.5 (or where it was, if lower). At most shape_sweeps sweeps (0 = off). polycube_bench
  /// --quad-table (surface mode, 2000 quads; edge ratio max / quads over 10, scaled Jacobian min /
  /// mean, Hausdorff 1e-3), with the pattern search's sliver guard: bumpy torus 361 / 1266, 0.342 /
  /// 0.793, 30.4 -> 107 / 46, 0.301 / 0.907, 7.5; homer 219 / 134 -> 69.7 / 71 (0.278 / 0.903 ->
  /// 0.234 / 0.892: its thin-step retry no longer kept); cow 151 / 45 -> 91 / 57; blub 29.9 / 4
  /// -> 14.4 / 3; spot 68.6 / 24 -> 68.6 / 12; fandisk unchanged, rocker 11 / 7 -> 10.5 / 1.
  int shape_sweeps = 40;
  int shape_rings = 2;
  /// Surface mode: consecutive chart planes of an axis less than this many cells apart that do
  /// not face each other share one integer (their risers lose their height), as
  /// HexOptions::merge_thin_steps; kept a cell apart, such a step gives a row of quads a fraction
  /// of a cell wide (cad/block at 2000 quads: 194 quads with an edge ratio over 100, up to 1e6).
  /// Closed surfaces only; 0 = every plane keeps a cell.
  double merge_thin_steps = 0.01;
  /// Surface mode (surface_quads_best_start): quads with an edge ratio over 100 (slivers, whose
  /// scaled Jacobian may be near 1), in the finished mesh or the extracted grid, are extracted
  /// again with thin steps up to 0.05, then 0.25 cells merged, and a retry is kept when it has
  /// fewer slivers (fewer_sliver_quads). spot at 2000 quads:
  /// 0.05 takes the edge ratio max 6059 -> 362, quads over 10 112 -> 45, mean 0.938 -> 0.949, the
  /// same Hausdorff. false: merge_thin_steps alone.
  bool thin_step_retries = true;
  /// Surface mode: when merged thin steps leave grid squares without a corner (a riser not thin
  /// everywhere), extract again with every step kept; false: throw Error(Polycube) instead (the
  /// thin-step retries, which have the result without the merge already).
  bool unmerge_on_missing_corners = true;
  /// Surface mode: rows of quads denser where the map curves more, as hex::HexOptions::grading
  /// (hex/grading.h; the area kept instead of the volume). Off by default (strength 0).
  hex::GradingOptions grading{0.0};
  double sharp_angle_deg = 30;   ///< dihedral angle above which an input edge is a sharp feature
  /// Move paths of quad edges onto the sharp edges no quad edge follows (creases the polycube has no
  /// edge along), before smoothing (geometry/feature_capture.h).
  bool capture_creases = true;
  /// Vertices on sharp edges slide along them (the best of a few positions towards their two
  /// neighbours on the edge) when that raises the worst quad around them; corners of the sharp
  /// edges (geometry::sharp_corners) stay.
  bool slide_on_features = true;
  /// Only feature vertices whose worst quad is below this slide (sliding cuts curved sharp edges
  /// a little: mambo_B2's Hausdorff 1.2e-3 -> 1.7e-3 at 0.4).
  double slide_below = 0.4;
  /// Chains of sharp edges are creases to capture when one of their edges is sharper than this:
  /// the facets of a coarse smooth surface are not taken for creases (geometry::crease_edges).
  double capture_angle_deg = 45;
  /// Last, the free vertices slide on the surface so that it comes closer to the quads
  /// (geometry/surface_fit.h; rounds = 0: off).
  /// (with the input's edge midpoints as samples: basic/eight 3.92e-3 -> 3.60e-3, torus 2.62e-3 ->
  /// 2.29e-3, fandisk and the spheres unchanged)
  geometry::SurfaceFitOptions fit{.edge_samples = true, .focus_dense = 4};
  /// After the smoothing, free vertices of quads below search_below move to the best of a few
  /// positions around them (pattern search on the worst quad around the vertex), at most
  /// search_sweeps times over the mesh (0 = off).
  double search_below = 0.5;
  int search_sweeps = 20;
  /// In the fitting, vertices on sharp edges slide along them too (those the smoothing may slide).
  bool fit_slide = true;
  /// Surface mode: when the polycube extraction holds another start's polycube
  /// (chart::PolycubeExtraction::alternative), quads are extracted from both and the better ones
  /// kept (better_quads); false: the extraction's own polycube alone.
  bool compare_starts = true;
};

struct QuadResult {
  MatX3d V;
  MatX4i Q;                      ///< oriented outward (counter-clockwise seen from outside)
  int irregular_vertices = 0;    ///< vertices of valence other than 4 (the polycube's corners, mostly)
  int feature_vertices = 0;      ///< vertices kept on sharp edges of the input
  QuadQuality extracted, quality;
  int smooth_moves = 0;
  int search_moves = 0;          ///< moves of the pattern search on the worst quads (QuadOptions::search_below)
  int shape_moves = 0;           ///< moves of the shape pass around slivers (QuadOptions::shape_sweeps)
  geometry::SurfaceFitStats fit;  ///< the fitting to the surface (distances from its samples to the quads)
  int crease_runs = 0;           ///< runs of sharp edges no quad edge followed after the extraction
  int crease_captured = 0;       ///< of those, runs a path of quad edges was moved onto
  int crease_moved = 0;          ///< vertices moved onto sharp edges
  /// How quad edges follow the sharp edges after the smoothing, without the capture; and in the
  /// final mesh (after the capture, the pattern search and the fitting to the surface).
  geometry::CreaseCoverage creases_before;
  geometry::CreaseCoverage creases_after;
  double seconds = 0;
  // Surface mode (quad_mesh_from_surface_polycube):
  double cells_per_unit = 0;              ///< grid cells per length unit of the polycube
  std::array<int, 3> planes{};            ///< distinct integer planes per axis
  std::array<double, 3> grading_min{}, grading_max{};  ///< graded rows: extreme densities per axis (0: uniform)
  int merged_planes = 0;                  ///< planes of thin steps sharing their integer with the one below (QuadOptions::merge_thin_steps)
  std::array<int, 3> cells{};             ///< grid extent per axis
  int border_vertices = 0;                ///< vertices on the border of an open surface (kept on it)
  int border_loops = 0;                   ///< border loops of the quad mesh
};

/// The quad mesh of the boundary of a hex mesh (HV, H), smoothed on `target` (the input surface).
QuadResult quad_mesh_from_hexes(const MatX3d& HV, const MatX8i& H, const SurfaceMesh& target,
                                const QuadOptions& opt = {}, const Hooks& hooks = {});

/// Smooths the quads (r.V, r.Q) on `target` as quad_mesh_from_hexes does; `pinned` (empty, or one
/// flag per vertex) marks vertices that stay (the border of an open surface). Sets r.extracted,
/// r.quality, r.irregular_vertices (pinned ones excepted), r.feature_vertices, r.smooth_moves.
void smooth_on_surface(QuadResult& r, const SurfaceMesh& target, const QuadOptions& opt, const Hooks& hooks,
                       const std::vector<char>& pinned);

/// Surface mode (paper Section 5.3): quads straight from an exact surface polycube, no volume.
/// X: the polycube positions of the triangles F (labels per triangle), the same connectivity as
/// `rest`, the surface being meshed (so the pair is the surface map). Per axis the distinct plane
/// heights (charts, and the lines of the border segments of an open surface) are snapped in
/// sorted order to integers, at least one cell apart (hex::snap_heights), and the polycube is
/// mapped by the per-axis piecewise-linear map sending them there (exact, injective). Every
/// integer point of a chart is carried to `rest` by its barycentric coordinates in its triangle
/// (shared points once: the mesh is conforming across chart borders), and every unit square of a
/// chart is a quad, oriented by its chart's label. Border vertices of an open surface lie on its
/// border and stay there; the others are smoothed on `target`. cells_per_unit > 0.
QuadResult quad_mesh_from_surface_polycube(const MatX3d& rest, const MatX3i& F, const MatX3d& X,
                                           const std::vector<int>& labels, double cells_per_unit,
                                           const SurfaceMesh& target, const QuadOptions& opt = {},
                                           const Hooks& hooks = {});

/// Whether quads b (Hausdorff distance hb to the surface) are better than quads a (ha): fewer
/// folded or degenerate quads; then fewer slivers (edge ratio over hex::kSliverEdgeRatio) unless
/// they are more than 1.5 x farther from the surface; else b must be closer to the surface by more
/// than 2% without giving up more than 10% of the minimum scaled Jacobian or 0.02 of the mean (the distance is
/// what differs most between polycube maps of one layout; the quality is the floor kept).
bool better_quads(const QuadQuality& a, double ha, const QuadQuality& b, double hb);

/// Whether quads b (Hausdorff distance hb) have fewer slivers than quads a (ha) without losing
/// elsewhere: fewer folded or degenerate quads; at as many, fewer quads over edge ratio 10 and a
/// lower maximum ratio, with the minimum scaled Jacobian at least 90% of a's and the distance
/// above ha by at most max(10% of ha, slack). slack: what the change may cost by construction (a
/// merged riser's height: the thin-step retries pass its bound, their threshold in cells times the
/// mean quad edge).
bool fewer_sliver_quads(const QuadQuality& a, double ha, const QuadQuality& b, double hb, double slack = 0);

/// One more extraction with thicker steps merged (QuadOptions::thin_step_retries).
struct QuadThinStepRetry {
  double thin_steps = 0;  ///< QuadOptions::merge_thin_steps of the retry
  int merged_planes = 0;  ///< planes it merged (-1: the merge left grid squares without a corner; not kept)
  int over_10 = 0;        ///< its quads over edge ratio 10
  double ratio_max = 0;   ///< its largest edge ratio
  double sj_min = 0;
  double hausdorff = 0;
  bool replaced = false;  ///< kept (fewer_sliver_quads than the result before it)
};

/// One polycube's quads in surface_quads_best_start.
struct StartQuads {
  std::string start;          ///< the realization's start (chart::RealizeResult::start)
  double polycube_arap = 0;   ///< its polycube's ARAP distortion
  bool alternative = false;   ///< from PolycubeExtraction::alternative
  QuadResult quads;
  hex::Hausdorff distance;    ///< to `target` (hex::hausdorff; distance.max: two-sided, absolute)
  std::vector<QuadThinStepRetry> retries;
  bool kept = false;
};

/// Surface mode: the quads of the extraction's polycube (e.realized over e.map_triangles(B)) at
/// about target_quads quads (cells per unit from the polycube's area over B) and, if
/// opt.compare_starts and e holds an alternative, of that polycube too; the better (better_quads,
/// the extraction's own first) is flagged `kept`. Each polycube's quads get their thin-step
/// retries first (QuadOptions::thin_step_retries). e.realized.success is required.
std::vector<StartQuads> surface_quads_best_start(const chart::PolycubeExtraction& e, const MatX3d& rest,
                                                 const MatX3i& B, int target_quads, const SurfaceMesh& target,
                                                 const QuadOptions& opt = {}, const Hooks& hooks = {});

}  // namespace polycube::quad
