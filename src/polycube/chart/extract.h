// The polycube stage as one call: label the deformed boundary, clean the labels up, check the
// chart graph, realize the exact polycube (labeling.h, realize.h).
#pragma once
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "polycube/chart/labeling.h"
#include "polycube/chart/realize.h"
#include "polycube/core/log.h"

namespace polycube::chart {

struct ExtractOptions {
  /// Tet mode: split the interior edges from the polycube's corners to vertices on no plane before
  /// the realization (RealizeOptions::split_corner_edges): "auto" extracts again with them when no
  /// valid polycube was realized without, and keeps that extraction if it realizes the polycube or
  /// ends folded with fewer tets inverted (PolycubeExtraction::corner_split_retry); "on": from the
  /// start (realize.split_corner_edges); "off": as realize.split_corner_edges says.
  std::string corner_splits = "auto";
  /// Surface mode: when the realization leaves at most this many triangles folded, edge flips
  /// inside their charts are tried (see PolycubeExtraction::flipped_B); 0 = off.
  int max_flip_faces = 150;
  /// Surface mode: rounds of edge collapses (collapse_folded_edges, then a realization from the
  /// collapsed layout) when edge flips leave triangles folded; 0 = off.
  int collapse_rounds = 30;
  /// Surface mode: when no edge of a folded triangle can be collapsed any more (or 5 collapse
  /// rounds in a row left no fewer folded triangles), relabel the folded triangles from their
  /// neighbours (a label each has not had yet in this repair), clean the labels and realize again
  /// from the collapsed layout, at most this many times (within collapse_rounds); 0 = off.
  /// (blub: 12 charts realized after 81 folded triangles; 20 / 5 / 0 left it unrealized.)
  int repair_relabels = 10;
  /// Triangles whose deformed area is below this fraction of the median deformed/rest area ratio
  /// take their neighbours' label before cleanup (relabel_collapsed); 0 = off.
  double collapsed_ratio = 1e-3;
  /// collapsed_ratio for surface mode (extract_polycube with no tets). Off: the surface ARAP
  /// flattens thin parts into sheets whose edges are rows of slim triangles, and their labels taken
  /// from the neighbours start a cascade of removals (blub, 2026-12-07: 41 triangles relabelled,
  /// among them the rims of its tail fin, which then became part of the body's -Z bottom and was
  /// pressed onto it: Hausdorff 264e-3 of the diagonal; off, 140e-3, the tail kept).
  double collapsed_ratio_surface = 0;
  /// When the realization leaves boundary triangles facing away from their label (every tet
  /// positive), relabel them from their neighbours and retry, at most this many times.
  int relabel_attempts = 4;
  /// The same when the realization could not untangle every tet, if at most this many stay
  /// inverted and at most max_relabel_faces triangles face away in the state it reached (a few
  /// local folds of the labelling; a realization that failed wholesale is not patched up).
  int max_relabel_inverted = 200;
  int max_relabel_faces = 100;
  /// Tet mode: when the realization (after the relabelling) still leaves tets inverted where it
  /// pins the two ends of a boundary edge to one point, that edge is collapsed (collapse_tet_edge)
  /// and the polycube realized again, at most this many rounds; 0 = off. (humanoid, 72k tets:
  /// 16 collapses in 5 rounds leave no tet inverted, where 3 rounds left 3.)
  int tet_collapse_rounds = 8;
  /// Last resort, when relabelling has come to nothing and no tet is inverted: if at most this
  /// many boundary triangles face away from their label, the shortest edge of each is collapsed
  /// the same way (within tet_collapse_rounds). (10 until the fiftieth session: rocker at beta 1,
  /// from the float factorization's deformation, ended its retries with 11 such triangles and no
  /// tet inverted, went back to realizing from the deformed mesh and was realized after 405 s; with
  /// 30 its 11 collapses realized it at once, 74 s in all, ARAP 0.073203 against 0.073242.)
  int max_folded_collapses = 30;
  /// Retries (after edge collapses or relabelling) first start from the failed realization's
  /// state, with the collapsed edges' tets gone or the relabelled triangles' vertices moved to
  /// their new planes (RealizeOptions start "previous": untangled, then ARAP), and from the
  /// deformed mesh again only if that fails: one untangling instead of the continuation's path
  /// and a second start per retry. A failed retry that leaves fewer tets inverted (or as many and
  /// fewer triangles facing away) is kept as the next one's start; if the extraction then ends
  /// without a polycube, the retries are run again from the start, each from the deformed mesh
  /// (the first realization, the same in both passes, is not made again).
  bool warm_retries = true;
  /// Surface mode: when the deformed surface's start fails on a few folded triangles and a later
  /// start (RealizeOptions::surface_starts) realizes the layout, also repair the deformed start's
  /// state (edge flips and collapses, as for a failed realization) and keep the result with the
  /// lower ARAP distortion. The harmonic start spreads each chart between its borders far from the
  /// deformed surface (fandisk at 724 quads: ARAP 0.097 against the deformation's 0.035).
  bool repair_deformed_start = true;
  /// Charts of the cleaned labelling whose triangles spread along their axis over more than this
  /// fraction of the deformed shape's bounding-box diagonal are listed in
  /// PolycubeExtraction::unflat (a diagnostic; nothing is changed for them).
  double unflat_above = 0.05;
  CleanupOptions cleanup;
  RealizeOptions realize;
};

/// ExtractOptions::corner_splits "auto": the second extraction, when the first realized nothing.
struct CornerSplitRetry {
  bool tried = false;
  std::string reason;   ///< the first extraction's failure
  bool success = false; ///< the second realized the polycube
  int inverted = 0;     ///< tets the second left inverted
  bool kept = false;    ///< the result is the second extraction
};

struct PolycubeExtraction {
  std::vector<int> labels;   ///< per boundary triangle (row of B), after cleanup
  CornerSplitRetry corner_split_retry;
  int initial_charts = 0;    ///< charts of the raw labelling
  CleanupStats cleanup;
  ChartReport charts;        ///< the cleaned chart graph
  RealizeResult realized;    ///< realized.success tells whether an exact polycube was built
  /// Surface mode: the triangles of the polycube map when folded triangles were repaired (empty
  /// otherwise, the map's triangles are B): B with `edge_flips` edges flipped inside a chart (same
  /// vertices, another triangulation) and `edge_collapses` edges of sliver triangles collapsed (their
  /// two triangles removed, one vertex merged into the other: its polycube position is the other's).
  /// map_labels: one label per row of map_B.
  MatX3i map_B;
  std::vector<int> map_labels;
  int edge_flips = 0;
  /// Surface mode: collapses of folded triangles' edges; tet mode: boundary edges collapsed because
  /// the realization pinned their ends to one point (collapse_tet_edge); map_B / map_labels then hold
  /// the boundary without their triangles, and the merged vertex sits on its partner in realized.X.
  int edge_collapses = 0;
  /// Tet mode: interior edges split so that a collapse met the link condition
  /// (split_edges_for_collapse); their vertices come after the input's in realized.rest / X.
  int collapse_edge_splits = 0;
  /// Tet mode: the first realization's check of the deformed mesh against the labelling's polycube
  /// edges (EdgeOrder, as RealizeResult::edge_order): kept from the first realization.
  EdgeOrder edge_order;
  /// The map's triangles and their labels: map_B / map_labels when repaired, else B / labels.
  const MatX3i& map_triangles(const MatX3i& B) const { return map_B.rows() > 0 ? map_B : B; }
  const std::vector<int>& map_triangle_labels() const { return map_B.rows() > 0 ? map_labels : labels; }
  /// Surface mode (ExtractOptions::repair_deformed_start): when both the repaired deformed start
  /// and a later start realized the layout, the one not kept (the higher ARAP distortion), with its
  /// own map triangles; null otherwise. ARAP does not rank the quads the two give: fandisk at 724
  /// quads, Hausdorff 6.76e-3 from the repaired deformed start (ARAP 0.035) against 3.80e-3 from
  /// the harmonic start (0.097); quad::surface_quads_best_start extracts both and keeps the better.
  std::shared_ptr<const PolycubeExtraction> alternative;
  /// Charts of `labels` (over B, on the deformed positions) far from planar
  /// (ExtractOptions::unflat_above), widest first: where the polycube joins parts of the deformed
  /// shape at different heights into one plane (blub's tail fin pressed onto its body, octopus-low's
  /// tentacles, cow's hooves); each one's `at` is its farthest triangle's centroid at rest.
  std::vector<UnflatChart> unflat;
};

/// rest/T/B: tet mesh and outward boundary triangles; deformed: the deformation's result.
PolycubeExtraction extract_polycube(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                                    const ExtractOptions& opt = {}, const Hooks& hooks = {});

/// Flips edges of F shared by a triangle not facing its label in X (folded in its chart's plane)
/// and a triangle of the same label when both new triangles face it; repeated while it helps.
/// Returns the flips made.
int flip_folded_edges(const MatX3d& X, MatX3i& F, const std::vector<int>& labels);

/// Collapses, for triangles of F not facing their label in X, one edge each where that is safe:
/// an interior edge (neither end on a border) whose ends have exactly two common neighbours, whose
/// kept end gains no label (the labels of both ends' remaining triangles are among the kept end's
/// labels before), and whose collapse turns no triangle of `rest` over. Edges shared by two folded triangles go first, then the shortest at rest; one
/// collapse per neighbourhood. F and labels lose the two triangles of each collapsed edge;
/// merged_into[v] (sized to rest.rows(), -1 = kept) names the vertex v was merged into. Returns
/// the collapses made.
int collapse_folded_edges(const MatX3d& rest, const MatX3d& X, MatX3i& F, std::vector<int>& labels,
                          std::vector<int>& merged_into);

/// Tet mode: collapses the boundary edge (keep, drop) of the tet mesh (T over rest, boundary B with
/// one label per row): the tets holding both go, `drop` is replaced by `keep` in the others, and B and
/// labels lose the edge's two triangles; `drop` is then referenced by nothing. Refused (false, nothing
/// changed) unless (keep, drop) is an edge of B, the star of `keep` stays a ball with `keep` on its
/// surface (the triangles opposite `keep` form a disk, a manifold at each of its vertices, bounded
/// by the boundary triangles around `keep`) and every tet of the new star is positive at rest and in
/// `deformed`. This is the tet mesh's form of the slim-triangle collapse of Huang et al. 2014
/// (Section 4): two boundary vertices the polycube pins to one point. why: the reason of a refusal;
/// removed: the rows of B (before the call) that went, in increasing order. deformed_at: if given,
/// the merged vertex may take, in `deformed` only, the position of `drop`, the edge's midpoint, a
/// quarter point, or a point between the midpoint and the centroid of the star's other vertices
/// when its own would turn a tet over there (the first of these that keeps every tet positive is
/// written to it); without it, only its own. rest_at: the same at rest, on the edge only (keep's
/// own position, the midpoint, drop's position, the quarter points); callers then move `keep`
/// there in their rest mesh. Where the stars of both ends are not convex enough for either
/// end (humanoid: both orders refused), the midpoint often is. deformed_may_tangle (with
/// deformed_at): when no position keeps the deformed star positive, collapse anyway with the
/// merged vertex at the deformed midpoint (the caller untangles the deformed mesh there).
/// rest_may_tangle (with rest_at): the same at rest, the merged vertex at the edge's midpoint (on
/// the input surface); the caller then untangles the rest mesh's interior vertices around it.
bool collapse_tet_edge(const MatX3d& rest, const MatX3d& deformed, MatX4i& T, MatX3i& B, std::vector<int>& labels,
                       int keep, int drop, std::string* why = nullptr, std::vector<int>* removed = nullptr,
                       Vec3* deformed_at = nullptr, Vec3* rest_at = nullptr, bool deformed_may_tangle = false,
                       bool rest_may_tangle = false);

/// The slim-triangle collapse of Huang et al. 2014 (Section 4), on the tet mesh (T over rest, outward
/// boundary B) and its deformation X alike: for each boundary triangle with an angle under
/// min_angle_deg in X, most slender first, its shortest edge in X is collapsed (collapse_tet_edge,
/// either end kept where it is at rest, so that the rest boundary stays made of input vertices; in X
/// the merged vertex may take a position of the edge, or inwards, that keeps every tet positive:
/// X is moved there; a collapse that leaves a tet around it under deform::DeformResult::kCrushedRatio
/// of its rest volume in X is undone). One collapse per neighbourhood (the stars of both
/// ends) per round, rounds until one collapses nothing (at most max_rounds). B loses the collapsed
/// edges' triangles and T their tets; merged_into (sized rest.rows(), -1 = kept) names, per merged
/// vertex, the vertex it went into, whose position its rows of rest and X then hold. Returns the
/// collapses made; `refused` (optional) counts the slim triangles the last round left (all those
/// left when it collapsed nothing).
int collapse_slim_triangles(MatX3d& rest, MatX3d& X, MatX4i& T, MatX3i& B, double min_angle_deg,
                            std::vector<int>& merged_into, int max_rounds = 10, int* refused = nullptr,
                            const Hooks& hooks = {});

/// Removes the merged vertices (merged_into[v] >= 0, as the collapses leave them) from the
/// per-vertex rows of each of `positions` (the others keep their order) and renumbers T and B.
/// Returns, per old vertex, its new index (-1 for a merged one).
std::vector<int> drop_merged_vertices(const std::vector<int>& merged_into, std::initializer_list<MatX3d*> positions,
                                      MatX4i& T, MatX3i& B);

/// Tet mode: prepares the boundary edge (keep, drop) for collapse_tet_edge where the link
/// condition fails (the stars of the two ends meet outside the edge's ring): the edges from `drop`
/// to every vertex joined to both ends but not in a tet with both, and to the vertices of every
/// triangle with a tet at each end (the collapse would make those two tets coincide), are split at
/// their midpoints (the edges from `keep` where those are boundary edges); then, one per round, an
/// edge in both stars' links but not in the edge's ring (a chord) leaves a link: the edge from
/// `drop`, else from `keep`, to one of its ends is split, or else the chord itself (at most eight
/// rounds, the stars measured again each time). Each new vertex is appended
/// to rest and deformed (at the edge's midpoint in each: every tet of the edge is halved, its
/// orientation kept) and every tet of the edge replaced by its two halves (the first in place, the
/// second appended to T). Edges of B are not split (the surface stays). Returns the ends of each
/// split edge, in the order the new vertices were appended (a later one may end at an earlier new
/// vertex; empty: nothing changed); collapse_tet_edge still decides.
std::vector<std::pair<int, int>> split_edges_for_collapse(MatX3d& rest, MatX3d& deformed, MatX4i& T,
                                                          const MatX3i& B, int keep, int drop);

/// A polycube map given from outside (an earlier run's tetmesh.mesh / polycube.mesh pair, or another
/// tool's): X the polycube positions of the tet mesh (rest, T; B its outward boundary). Each boundary
/// triangle takes the label of its normal's dominant axis; the vertices of the charts of one axis
/// that touch (one plane) are put at their mean coordinate, which must be within
/// `tolerance` x the bbox diagonal of X of every one of them (files written with few digits pass,
/// a shape that is not a polycube does not). The result is as extract_polycube's on success
/// (realized.start = "given", cleanup counts zero). Throws Error(InvalidMesh) naming the first
/// triangle off its plane, of zero area, or the first tet that is not positive. max_inverted: up to
/// this many tets that are not positive are tolerated: the result then has realized.success false,
/// realized.inverted set and the reason in realized.failure (a folded map, through which hexes may
/// still be extracted: PipelineOptions::hex_through_folds).
PolycubeExtraction polycube_from_map(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& X,
                                     double tolerance = 1e-6, int max_inverted = 0);

}  // namespace polycube::chart
