// Chart labelling and topological cleanup of a near-polycube surface (Huang et al. 2014, Section 4.1).
//
// Every boundary triangle gets the label of the dominant axis of its normal, code 0..5 = +X, -X,
// +Y, -Y, +Z, -Z (core/types.h). A chart is a maximal edge-connected set of triangles with one
// label. The cleanup relabels triangles so that the chart graph can be realized as a polycube:
//   1. zigzag straightening: a triangle two of whose three neighbours carry another, common label
//      takes that label;
//   2. degenerate triangles: a triangle whose three vertices all lie on the border of one
//      neighbouring chart of another axis would be flattened onto the chart edge line; it takes
//      that chart's label;
//   3. charts of degree 1 take the surrounding label, charts of degree 2 the label of the
//      neighbour sharing the longest border, and (not in the paper, needed rarely) charts of
//      degree 3, which can only have three corners, likewise; smallest charts first;
//   4. (not in the paper) when nothing else applies: of two charts with opposite labels that meet
//      at an edge or a vertex (the polycube would have zero thickness there), the smaller takes the
//      label of its longest-bordered neighbour that is not opposite to it;
// all repeated until nothing changes.
//
// Valid chart graph (check_charts): no two adjacent charts with opposite labels; every corner
// (vertex where 3+ charts meet) of valence 3; every chart a planar region: a disk, or (on shapes
// of genus > 0) a disk with holes such as the top face of a box with a through-hole, whose faces
// are annuli; every chart boundary loop with at least 4 corners (a face of a polycube is a
// rectilinear polygon); no two corners on the same three planes (they would coincide).
#pragma once
#include <limits>
#include <string>
#include <vector>

#include "polycube/core/log.h"
#include "polycube/core/types.h"

namespace polycube::chart {

/// Label of a direction: the dominant axis of n and its sign (ties go to the lower axis).
int label_of(const Vec3& n);
/// Unit direction of a label.
Vec3 label_direction(int label);
/// "+X", "-X", ...
const char* label_name(int label);

/// Label of every triangle of (X, F) by the dominant axis of its normal.
std::vector<int> label_by_normal(const MatX3d& X, const MatX3i& F);

/// Charts of a labelled closed triangle mesh.
struct Charts {
  std::vector<int> of_face;                ///< chart id per triangle
  std::vector<int> label;                  ///< label per chart
  std::vector<int> faces;                  ///< triangle count per chart
  std::vector<double> area;                ///< area per chart (on the positions given)
  /// Per chart: (neighbour chart, shared border length), sorted by neighbour id.
  std::vector<std::vector<std::pair<int, double>>> neighbors;
  /// Open surfaces: per chart, the runs of consecutive border edges it holds (each counts as a
  /// side of the chart, like a neighbour, in the cleanup's degree); 0 on closed surfaces.
  std::vector<int> border_runs;
  /// Degree of a chart for the cleanup: neighbours plus border runs.
  int degree(int i) const { return static_cast<int>(neighbors[i].size()) + border_runs[i]; }
  int count() const { return static_cast<int>(label.size()); }
};

/// Connected components of equally labelled triangles and their adjacency.
Charts build_charts(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels);

struct CleanupOptions {
  bool straighten = true;        ///< zigzag straightening (step 1)
  bool fix_degenerate = true;    ///< relabel triangles that would be flattened (step 2)
  bool remove_low_degree = true; ///< remove charts of degree 1, 2 (and 3) (step 3)
  bool separate_opposite = true; ///< relabel the smaller of two opposite charts that meet (step 4)
  /// Step 4, when the smaller chart's area is above this fraction of the total: only its triangles
  /// at the meeting vertices are relabelled (a rim with the labels of the outward direction there)
  double rim_above = 0.01;
  /// Rims opened at most per cleanup (a rim can meet a chart opposite to its own label, be removed
  /// and be opened again; past this, step 4 relabels whole charts)
  int max_rims = 4;
  /// Step 3, for a chart of degree 2 or 3 above this fraction of the total area whose two opposite
  /// neighbours meet at its border (a pinch: the side between them has length zero): instead of
  /// relabelling the chart whole, the triangles of the three charts around the pinch vertices take
  /// the missing label (the side the polycube face needs there). At most max_pinches per cleanup.
  double pinch_above = 0.01;
  /// pinch_above for surface mode (extract_polycube with no tets; the volume pipeline keeps
  /// pinch_above). The surface ARAP lets thin parts such as legs become plates whose narrow sides
  /// are charts of a few triangles: relabelled whole, the part loses its thickness and the
  /// realization crushes it (cow: both hind legs missing from the quads). At 0.002 (2026-11-28):
  /// cow 3 pinches, Hausdorff 142 -> 120e-3, RMS 21.2 -> 16.2e-3, edge ratio max 501 -> 295;
  /// homer scaled Jacobian min 0.172 -> 0.234, 30.5 -> 26.7e-3; spot, blub, bumpy torus and the
  /// CAD models unchanged. Far lower (0.0002) opens dozens and homer and blub are not realized.
  /// When no start realizes the layout (humanoid), extract_polycube extracts again with
  /// pinch_above.
  double pinch_above_surface = 0.002;
  int max_pinches = 16;
  int max_rounds = 1000;         ///< cap on relabelling rounds (each round removes one chart or more)
};

/// What the cleanup changed.
struct CleanupStats {
  int zigzags = 0;     ///< triangles relabelled by straightening
  int degenerate = 0;  ///< triangles relabelled because they would be flattened
  int degree1 = 0, degree2 = 0, degree3 = 0;  ///< charts removed, by degree
  int opposite = 0;    ///< charts relabelled because they met a chart of the opposite label
  int rims = 0;        ///< rims opened between large opposite charts that met (see rim_above)
  int pinches = 0;     ///< sides opened at pinches of low-degree charts (see pinch_above)
  double pinch_above = 0;  ///< the CleanupOptions::pinch_above this cleanup ran with
  /// area of the smallest chart a pinch was opened on, as a fraction of the total (+inf: none);
  /// a cleanup with a higher pinch_above than this gives the same labels
  double smallest_pinch = std::numeric_limits<double>::infinity();
  int relabelled_faces = 0;  ///< triangles whose final label differs from the initial one
  int collapsed = 0;   ///< triangles relabelled by relabel_collapsed (set by extract_polycube)
  double collapsed_ratio = 0;  ///< the ratio relabel_collapsed ran with (set by extract_polycube)
  int misoriented = 0; ///< triangles relabelled after a realization left them facing away (extract_polycube)
  int rounds = 0;
};

/// Labels of collapsed triangles: a boundary triangle whose deformed area is below
/// `ratio` x (median deformed/rest area ratio) has no reliable normal (the deformation squeezed it
/// into a seam, e.g. a fillet of fandisk pressed flat between two charts), and its label by normal
/// can open a sliver of a third chart along the seam that no polycube realizes. Such triangles take
/// the most frequent label of their reliable edge neighbours, propagated inwards. Returns the
/// triangles relabelled.
int relabel_collapsed(const MatX3d& rest, const MatX3d& deformed, const MatX3i& F, std::vector<int>& labels,
                      double ratio = 1e-3);

/// Cleans `labels` (one per triangle of F) in place. X: positions used for border lengths.
/// hooks: a debug message for every whole chart above 5% of the area that a step relabels.
CleanupStats cleanup_labels(const MatX3d& X, const MatX3i& F, std::vector<int>& labels,
                            const CleanupOptions& opt = {}, const Hooks& hooks = {});

/// Structure of the chart graph and its problems.
struct ChartReport {
  int charts = 0;
  int corners = 0;       ///< vertices where 3 or more charts meet
  int chart_edges = 0;   ///< border chains between corners (closed loops without corners count 1)
  std::vector<int> corner_valence;  ///< histogram: [k] = corners where k charts meet (k >= 3)
  int opposite_adjacent = 0;   ///< pairs of adjacent charts with opposite labels
  int high_valence_corners = 0;///< corners of valence > 3
  int non_disk_charts = 0;     ///< charts that are not disks (holes allowed, see header)
  int invalid_topology_charts = 0;  ///< charts with handles (never a polycube face)
  int loops_with_few_corners = 0;   ///< chart boundary loops with fewer than 4 corners
  /// pairs of corners on the same three planes (charts of one axis that meet share a plane), which
  /// the polycube would put at one point
  int coincident_corners = 0;
  bool valid = false;          ///< none of the problems above except non-disk planar charts
  std::vector<std::string> problems;  ///< the first problems found, each naming charts/vertices
};

/// A chart whose triangles lie at different heights along its axis on the positions it was
/// labelled on (unflat_charts): the polycube puts it in one plane, which distorts or crushes the
/// parts it joins. The raw labelling of a converged deformation has none (its charts' triangles
/// all face their label); the cleanup makes them when it relabels triangles into a chart of their
/// new label at another height (a chart removed into a neighbour, a pinch's or a rim's triangles
/// joining a chart of that label).
struct UnflatChart {
  int chart = -1;       ///< id in build_charts(X, F, labels)
  int label = -1;
  int faces = 0;
  double spread = 0;    ///< range of its triangles' centroid heights along its axis
  int farthest = -1;    ///< its triangle farthest from its area-weighted median height
  Vec3 at = Vec3::Zero();  ///< that triangle's centroid at rest (set by extract_polycube)
};

/// Charts of (X, F, labels) whose triangles' centroids spread along the chart's axis over more
/// than `above` (a length in X's units), widest first.
std::vector<UnflatChart> unflat_charts(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels,
                                       double above);

/// Checks the chart graph of labelled triangles (closed, consistently oriented F over nv vertices).
ChartReport check_charts(const MatX3i& F, int nv, const std::vector<int>& labels);

}  // namespace polycube::chart
