// Realization of an exact polycube from a labelled near-polycube tet mesh (Huang et al. 2014,
// end of Section 4.1).
//
// Every boundary vertex of a chart with axis k shares one coordinate x_k = h with the rest of its
// "plane": the union of the charts of axis k that touch it (charts of one axis meeting at a vertex
// must lie in one plane). These linear constraints are removed by substitution: per axis, the
// unknowns are the plane heights and the coordinates of unconstrained vertices, so the result is
// planar to the last bit. Then:
//   1. start, either
//      "continuation": from the deformed mesh (no tet inverted), the constrained coordinates travel
//      to their plane heights (mean of the plane's deformed coordinates) in steps that keep every
//      tet positive, the other coordinates following by the ARAP response and relaxing (optionally
//      retried with a stronger barrier when nearly flat tets stall it, see continuation_retries;
//      optionally, when it stalls, the penalty path first: heights free, gaps penalized, see
//      penalty_path); "penalty": that path alone;
//      "eq17": the valence-weighted relaxation of Eq. 17 with the same heights (a sparse
//      least-squares solve per axis), then plain ARAP local/global steps while tets are inverted;
//      either start, if tets are still inverted (the continuation landed by force, or ARAP steps
//      got stuck: box_hole at its default size), is untangled by the elliptic energy of Garanzha
//      et al. 2021 (deform::untangle_energy) with the paper's eps schedule, by L-BFGS
//      preconditioned with the ARAP matrix, planes kept exact (fandisk: 243 inverted -> 0), stopped
//      if the mesh shrinks as a whole (volume halved: free heights let it) and returning its best
//      round, then again with the plane heights fixed, then locally (untangle_tets_locally);
//   2. nearly flat tets (volume ratio under 1e-3 of the mean) opened by local sweeps (the local
//      untangling's Newton steps, kept while the smallest volume ratio grows), then
//      ARAP minimization (heights free) by Newton steps with the constant ARAP Hessian, with a line
//      search that keeps every tet positive, and a barrier that only acts on nearly flat tets; when
//      a step comes out short, the next one also uses the barrier's Gauss-Newton Hessian (all axes
//      coupled, one factorization): on cad/block this cut the time from 153 s to 8 s and the worst
//      isometric distortion from 228 to 10.5.
// Interior tet edges whose two ends lie on one plane would have to lie in the polycube's face: they
// are split at their midpoint first; interior faces whose three vertices lie on one plane, at their
// centroid (new interior vertices, appended).
#pragma once
#include <array>
#include <string>
#include <vector>

#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/deform/energies.h"

namespace polycube::chart {

/// How a realization's messages name vertices and boundary triangles. extract_polycube's retries
/// after edge collapses realize a compacted copy of the mesh (merged vertices and the collapsed
/// edges' triangles left out); these names keep the caller's numbering in what they say. Empty:
/// each one's own index.
struct MeshNames {
  std::vector<int> vertices;  ///< vertex i of the mesh given is vertices[i]
  int next_vertex = 0;        ///< a vertex the realization adds (a split), i >= vertices.size(): next_vertex + i - size
  std::vector<int> faces;     ///< row f of B is faces[f]
  int vertex(int v) const {
    const int m = static_cast<int>(vertices.size());
    return m == 0 ? v : v < m ? vertices[v] : next_vertex + (v - m);
  }
  int face(int f) const { return f < static_cast<int>(faces.size()) ? faces[f] : f; }
};

struct RealizeOptions {
  /// "continuation", "eq17" (the paper's), or "auto": both; a result with every boundary triangle
  /// facing its label beats one without, then the lower final ARAP distortion wins. "previous":
  /// `deformed` is an earlier realization's state (on or near the planes, maybe with tets
  /// inverted, e.g. before an edge collapse): landed on the planes, untangled locally (the
  /// vertices around the inverted tets), then the ARAP minimization. "penalty": the penalty path
  /// (see penalty_path) from the deformed mesh alone.
  std::string start = "auto";
  /// Tet mode: the interior edges from each polycube corner (a boundary vertex on three planes) to
  /// a vertex on no plane are split at their midpoints before the realization (with those between
  /// two vertices on one plane, which always are), so that each corner's star has free vertices
  /// close to it. tet/hand (30.9k tets, `--volume-boost 10`): realized with it (32 charts, 60
  /// corners, ARAP 0.1216) where every retry without it left one tet inverted at a corner; spot
  /// (17.4k tets) is realized without it and not with it, hence PipelineOptions::corner_splits.
  bool split_corner_edges = false;
  MeshNames names;  ///< set by extract_polycube's retries on a compacted mesh (see MeshNames)
  /// Surface mode: the starts tried in turn until one realizes the layout: 1 the deformed surface
  /// on the planes, 2 also ARAP iterations from it, 3 also the harmonic layout (see
  /// realize_surface.cpp).
  int surface_starts = 3;
  int max_iterations = 200;       ///< ARAP Newton iterations at most
  /// Surface mode: the ARAP iterations stop when one lowers the energy by less than this, relative
  /// to the energy they started from.
  double tolerance = 1e-6;
  /// Volume mode: the ARAP Newton iterations stop when a step of at least 1/4 lowers the energy by
  /// less than this, relatively. The last of them are coupled steps (a factorization each) through
  /// the near-flat barrier that gain little: with 1e-5, rocker's extraction (132k tets, 24 edge
  /// collapses) took 71 s against 90 s, for ARAP 0.073096 against 0.073095 with the same
  /// collapses; fandisk 10.9 against 15.0 s (0.03968 against 0.03975); the rod and the bumpy torus
  /// the same polycube ARAP. At `--tets 20000` every basic/ and cad/ mesh (22) gives the same
  /// charts, corners and edge collapses with 1e-5 as with 1e-6 (the earlier default), ARAP equal
  /// to 1e-5 relative, in 0-11 fewer iterations (forty-seventh session).
  double volume_tolerance = 1e-5;
  /// Volume mode: volume_tolerance for the ARAP iterations of a start whose landing on the planes
  /// left boundary triangles facing away from their chart's direction. The iterations cannot turn
  /// such a triangle back (each is the face of a tet kept positive; see realize.cpp), so that start
  /// fails whatever they do and its state only becomes the start of the retries (edge collapses,
  /// relabelling). Measured with 1e-5 (the volume_tolerance) -> 1e-3, from the saved deformations
  /// (forty-seventh session): rocker 132k tets 135 -> 106 s (the folded starts 37 and 45 -> 21
  /// and 8 iterations, the same 24 edge collapses, ARAP 0.073095 -> 0.073099); fandisk 35.6k
  /// 19.7-24.9 -> 14.0-17.2 s (7 -> 8 collapses, 0.03975 -> 0.03968); at `--tets 20000` rocker
  /// 58.6 -> 47.8 s, fandisk 48.6 -> 13.8 s (8 -> 3 collapses, 0.04439 -> 0.04459). Skipping the
  /// iterations altogether (rocker 108 s) made fandisk's retries take longer paths (48.6 -> 95.8
  /// s at 20000): their start is better relaxed.
  double folded_tolerance = 1e-3;
  int untangle_iterations = 20;   ///< eq17 start: local/global steps at most to remove inverted tets (its wins on the shared meshes needed <= 3)
  /// "auto": the eq17 start's elliptic untangling (L-BFGS iterations, free heights) within which
  /// its result may compete with a successful continuation start. Beyond it (or once it needs the
  /// fixed-height or local untangling) the eq17 result counts only if the continuation failed, and
  /// is abandoned as soon as the continuation has succeeded. The rule depends on the eq17 start's
  /// own arithmetic only, so results do not depend on thread timing. Its wins on the shared
  /// meshes needed 10 iterations (one round, ARAP 0.1-0.4% lower); where it went on, it failed
  /// (rod, 68k tets: 4277 untangling steps, ~120 s, 18 tets still inverted, beside a continuation
  /// that succeeded in 17 s). Negative: no budget (it always competes, as before).
  int eq17_budget = 300;
  /// Elliptic untangling: rounds (eps updates) in a row without fewer inverted tets before a call
  /// gives up and returns its best round. On the 20 realized shared meshes (--tets 20000) every
  /// call that untangled all tets improved at every round but at most one; the calls that went on
  /// after two rounds without progress never untangled all (fandisk 37.8k tets: 2 then 1 tets
  /// for 6 rounds each, ~25 s per start, before the edge collapse that realizes it).
  int untangle_patience = 2;
  /// After landing on the planes (continuation start) or the relaxation of Eq. 17 and its ARAP
  /// untangling, the local untangling (a Gauss-Seidel sweep around the inverted tets) runs first;
  /// when it leaves at most this many tets inverted, the global elliptic untangling is skipped and
  /// its state is the start's. On the shared meshes the elliptic untangling, where it ran after a
  /// landing, ended with the same count of inverted tets as the local one alone at 4-10x the time
  /// (fandisk 37.8k tets: 135 -> 2 inverted in 1.9 s, against 2 after ~12 s; spot: 339 -> 9 in 6 s
  /// against 9 after ~24 s, per start). -1: off (the elliptic untangling first, as before).
  /// Surface mode likewise, per triangle: Newton steps on one vertex at a time over its free
  /// coordinates, around the folded triangles; at most this many left folded and the global
  /// rounds (L-BFGS over the whole surface) are skipped, the edge flips and collapses take over
  /// (fandisk 25.2 -> 0.6 s, polycube ARAP 0.0461 -> 0.0373; rocker 124 -> 1.7 s, 0.0619 -> 0.0502).
  int local_first = 20;
  /// Surface mode: when the local untangling leaves more than local_first triangles folded, at
  /// most this many global rounds (L-BFGS over the whole surface, eps decreasing) follow; 0 = none,
  /// the start then fails and the next one (or the edge collapses) takes over. On the 14 shared
  /// surfaces measured (2026-11-28) the global rounds never realized a start the local untangling
  /// had not: where they ran (cow 594 -> 310 folded, blub 2579 -> 441, from the harmonic start 33
  /// -> none fewer) a later start or the collapses realized the layout, with the same polycube
  /// without them, and they cost 1.2 s per round on blub (28 of its 92 s). local_first = -1 still
  /// runs them (at most 30 rounds).
  int surface_untangle_rounds = 0;
  /// Surface mode: after the final ARAP iterations, this many L-BFGS iterations (0 = off) on the
  /// elliptic energy of the map (Garanzha et al., 2D, shape and area terms weighted equally: a
  /// barrier against crushing and folding), over the coordinates no plane holds. ARAP lets a few
  /// triangles be crushed where the labels flatten a part (bumpy torus: max isometric distortion
  /// 1460, 6.6 after 1000 iterations; cow 1.6e6 -> 3.6e4, humanoid 3.0e7 -> 1.6e6). Off by
  /// default: the quads built on the relaxed map are worse on the CAD models (fandisk at 724
  /// quads: Hausdorff 6.64e-3 -> 15.6e-3 with 300 iterations), and the crushed organic shapes'
  /// quads are no closer (their chart layouts lose the parts, see README).
  int relax_iterations = 0;
  /// Continuation start: when it stalls (a tet about to invert), retries from the deformed mesh
  /// with the barrier weight x10, x100, ... this many times before landing on the planes and
  /// untangling. Added when nothing came after the landing; now the untangling, the edge collapses
  /// and the relabellings do, and on the shared meshes no retry has landed since (fandisk 37.8k
  /// tets stalled at t = 0.99939, 0.99963, 0.949, 41 s for the three; spot 0.93, 0.80, 0.79;
  /// bumpy torus 0.991, 0.990): none by default.
  int continuation_retries = 0;
  /// Continuation start: past t = 0.75, this many failed steps blocked again by a tet that had
  /// already blocked one end it as stalled (0 = only the step limit, 60, or a step under 1e-4
  /// does). Such a run creeps towards t = 1 by a fixed fraction of the remaining way per step and
  /// reaches the step limit at t ~ 0.99 anyway (rocker, 155k tets: stalled at t = 0.9375 instead
  /// of 0.990, 32 s instead of 51 s, the same polycube after the collapses that follow).
  int stall_repeats = 8;
  /// Continuation start: when it stalls, a penalty path from the deformed mesh is tried before
  /// landing by force: the plane heights become unknowns beside the coordinates and the gaps to
  /// them are penalized with a weight raised x10 per stage (ARAP + barrier + penalty by Newton
  /// steps that keep every tet positive), so that a thin part is not asked for a thickness the
  /// mean heights leave it no room for. Start "penalty" runs it alone. Off by default: on the
  /// shared meshes whose continuation stalls it has not yet landed where the forced landing
  /// failed (spot: 36 tets inverted after it against 9; homer: 16-18 against 17), and it costs
  /// 100-260 Newton steps, each a factorization of the coupled system (see README).
  bool penalty_path = false;
  /// Barrier weight (relative to ARAP) on tets whose volume ratio J = det(F) falls below
  /// tau = barrier_threshold x (median J): weight (log(J / tau))^2 below tau, 0 above. ARAP alone
  /// lets tets flatten where charts meet (box_hole: max isometric distortion 59 with 0.01 / 0.05,
  /// 5.6 with these defaults, for 3% more ARAP distortion).
  double barrier_weight = 1.0;
  double barrier_threshold = 0.3;
};

/// Tet mode: the deformed mesh checked against the labelling's polycube edges. A boundary vertex on
/// two planes lies on a polycube edge, on a path of such vertices between two corners; `vertices`
/// counts them, `out_of_order` those whose deformed coordinate along the edge is not strictly
/// between its neighbours' on that path (the corners counted at their plane heights), `past_corner`
/// those of them past a corner's plane. The realization must move such a vertex back into order
/// while the planes pull the edge onto one line, which flattens the tets between it and its
/// neighbour (homer: 4 of the 9 boundary edges its failed realization collapsed have an end among
/// them; see README).
struct EdgeOrder {
  int vertices = 0, out_of_order = 0, past_corner = 0;
  std::string example;  ///< the first one past a corner ("vertex V past corner C along Z")
};

/// Isometric distortion max(s1, 1/s3) of the map from the rest tets to the polycube tets.
struct Distortion {
  double min = 0, mean = 0, max = 0;
  /// Elements whose isometric distortion exceeds kNearlyFlat: positive, so the map is valid, but
  /// nearly flat in the polycube (or at rest), where a hex or quad mapped through them is crushed.
  int nearly_flat = 0;
};
/// Threshold of Distortion::nearly_flat.
constexpr double kNearlyFlat = 1e3;

struct RealizeResult {
  bool success = false;
  std::string failure;           ///< why, when !success
  MatX3d rest;                   ///< rest positions: the input tet mesh plus the split-edge midpoints
  MatX4i T;                      ///< tets over `rest` / `X` (the input tets, some split)
  MatX3d X;                      ///< polycube positions; on failure after untangling, the state the best start reached
                                 ///< (with `inverted` and `misoriented_faces` set), for diagnosis and relabelling only
  int split_edges = 0;           ///< interior edges split because both ends lie on one plane
  int split_faces = 0;           ///< interior faces split (at the centroid) because their 3 vertices lie on one plane
  std::string start;             ///< start used ("continuation" or "eq17")
  int untangle_iterations = 0;   ///< continuation steps or untangling steps of the start used
  int iterations = 0;            ///< final ARAP iterations
  double arap = 0;               ///< volume-weighted mean ARAP distortion (Eq. 6) of the polycube map
  Distortion isometric;
  int inverted = 0;              ///< tets with non-positive volume in X
  double planarity_error = 0;    ///< max over boundary triangles of their extent along their label axis / bbox diagonal
  int misoriented_faces = 0;     ///< boundary triangles not facing their label's direction (or of zero area)
  int planes[3] = {0, 0, 0};     ///< distinct planes per axis (surface mode: with the border segments' lines)
  int degenerate_border_edges = 0;  ///< surface mode, open surfaces: border edges of zero length
  EdgeOrder edge_order;          ///< tet mode: the deformed mesh against the polycube's edges
  double seconds = 0;
};

/// A failed tet-mode realization whose state lies on its planes (planarity 1e-9) with tets inverted:
/// a folded map, through which hexes may still be extracted (PipelineOptions::hex_through_folds).
bool is_folded(const RealizeResult& r);

/// Realizes the polycube. rest/T/B: the tet mesh and its outward boundary triangles; deformed: the
/// deformed positions (axis-aligned frame); labels: one per row of B, cleaned (see labeling.h).
/// Never throws for a geometric failure: returns success = false with the reason. T empty: surface
/// mode (realize_surface_polycube on B).
RealizeResult realize_polycube(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                               const std::vector<int>& labels, const RealizeOptions& opt = {},
                               const Hooks& hooks = {});

/// Surface mode (no tets, T empty in realize_polycube, which calls this): the same plane
/// constraints on the triangles (F, labels), by substitution, and on open surfaces one more per
/// border edge: it runs along one axis (border_directions), so its ends share the third coordinate.
/// Started from the deformed surface with every plane at its mean height, then local/global
/// iterations of the surface ARAP energy (deform::surface_arap_energy, one factorization per axis).
/// Fails (success = false) when a triangle does not face its label's direction or a border edge
/// has zero length. `isometric` is over the triangles; `T` is empty. start: positions that satisfy
/// the plane constraints (e.g. a realization whose folded triangles were repaired by edge flips):
/// used instead of the three starts, then untangled if needed and finished by the ARAP iterations.
RealizeResult realize_surface_polycube(const MatX3d& rest, const MatX3i& F, const MatX3d& deformed,
                                       const std::vector<int>& labels, const RealizeOptions& opt = {},
                                       const Hooks& hooks = {}, const MatX3d* start = nullptr);

/// Open surfaces: the axis each border edge runs along in the polycube (the dominant axis of the
/// deformed edge other than its chart's axis, then single-edge zigzags straightened), in the
/// order of `edges` (filled: border edges (a, b, face) loop by loop, oriented as in their
/// triangle, as border_loops gives them).
std::vector<int> border_directions(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels,
                                   std::vector<std::array<int, 3>>* edges);

/// Isometric distortion max(s1, 1/s2) of the map between triangles (rest -> X).
Distortion isometric_distortion_surface(const MatX3d& rest, const MatX3d& X, const MatX3i& F);

/// Whether triangle (a, b, c) of X faces `label`'s direction: N . d > 1e-14 diag^2 (N its area
/// normal), so that a triangle of zero area fails too.
bool faces_label(const MatX3d& X, int a, int b, int c, int label, double diag);
/// Triangles of B that do not face their label (see faces_label).
int count_misoriented(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels, double diag);

/// Sets r.planarity_error (max extent of a triangle of B along its label's axis / bbox diagonal of
/// r.X) and r.misoriented_faces (triangles not facing their label's direction, or of zero area).
void check_faces(const MatX3i& B, const std::vector<int>& labels, RealizeResult& r);

/// Local untangling of X (tets T, reference shape rest): Gauss-Seidel sweeps over the vertices within
/// `rings` tet rings of the inverted tets, each moved along the axes k with fixed[k][v] == 0 by a
/// Newton step on the elliptic energy (Garanzha et al. 2021) of its tets, eps following the region's
/// smallest volume ratio, until no tet is inverted or 30 sweeps bring no progress. The realization
/// uses it with the planes' coordinates fixed; the hex snapping for the few tets its harmonic
/// displacement turns over. inverted receives the tets still inverted; returns the sweeps taken.
int untangle_tets_locally(const MatX3d& rest, const MatX4i& T, const std::array<std::vector<char>, 3>& fixed, MatX3d& X,
                          int& inverted, int rings = 3, int max_sweeps = 300);
/// The same with the reference shape given per tet (deform::ArapRest of any positive tets, e.g.
/// each tet's shape before an edge collapse moved one of its vertices).
/// flat > 0: the tets repaired are those whose volume ratio (to the reference) is under flat x the
/// mean one (nearly flat or inverted; `inverted` receives how many are left), and a sweep is kept
/// only while it raises the smallest volume ratio and turns no tet over: opening the nearly flat tets of a valid
/// map (the realization does so before its ARAP steps, with flat = 1e-3).
int untangle_tets_locally(const deform::ArapRest& reference, const MatX4i& T,
                          const std::array<std::vector<char>, 3>& fixed, MatX3d& X, int& inverted, int rings = 3,
                          int max_sweeps = 300, double flat = 0);

/// Isometric distortion statistics of the map rest -> X over tets T.
Distortion isometric_distortion(const MatX3d& rest, const MatX3d& X, const MatX4i& T);

}  // namespace polycube::chart
