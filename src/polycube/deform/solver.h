// The l1 polycube deformation (Huang et al. 2014, Section 4): minimize
//   alpha E1 + E_delta + beta E_eta + E_e + barrier   subject to   total boundary area = const,
// by SQP steps (Eqs. 15-16, Schur complement, sparse Cholesky with the symbolic analysis reused),
// a global rotation re-solved at every step, and the alpha/epsilon schedule of Section 4.
//
// Internally the mesh is centred and scaled to a unit bounding-box diagonal and E1, E_eta are
// divided by the boundary area, so that every weight below is independent of the input's units.
#pragma once
#include <string>
#include <vector>

#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/deform/energies.h"

namespace polycube::deform {

struct DeformOptions {
  double alpha0 = 0.05;         ///< initial weight of E1 (authors' code; the paper says 0.1)
  double alpha_factor = 2.0;    ///< alpha is multiplied by this at each schedule step
  double eps0 = 0.5;            ///< initial smoothing of |c| ~ sqrt(c^2 + eps) (authors' code; paper: 1)
  double eps_factor = 1.41421356237309515;  ///< eps is divided by this at each step...
  double eps_min = 0.01;        ///< ...but never below this
  double beta = 0.0;            ///< weight of the complexity penalty E_eta (Eq. 10); larger = fewer corners
  double barrier_weight = 0.01; ///< weight of the anti-foldover log barrier (Eq. 11), per edge / #edges
  /// Weight of a log barrier on tet volumes (not in the paper): keeps tets from flattening, which
  /// would otherwise block the line search. In surface mode, the weight of the same barrier on
  /// triangle areas (area_barrier_energy). 0 disables it.
  double volume_barrier_weight = 0.1;
  /// Form of the volume barrier: false (default) sum w_t -log J_t; true sum w_t (J_t - 1 - log J_t),
  /// which leaves tets of unchanged volume alone, where -log J pulls every tet outwards (under the
  /// constant boundary area the shape rounds off at small alpha). Measured with the paper's models
  /// (polycube_bench, 2026-11-26): polycube ARAP within noise of the default (bumpy torus 0.0900 ->
  /// 0.0844, fandisk 0.0411 -> 0.0404, rod 0.0714 -> 0.0709, rocker see README), more charts on
  /// fandisk (39 -> 43) and a nearly flat tet in spot's realization at 20k tets: kept as an option.
  bool neutral_volume_barrier = false;
  /// Weight of the crush guard (crush_guard_energy; 0 = off): tets pressed under crush_guard_ratio
  /// of their rest volume are pushed open with the weight of a tet of mean volume, however small.
  double crush_guard_weight = 0.0;
  double crush_guard_ratio = 0.05;
  /// The volume-barrier weight is multiplied by 4 whenever tets about to invert cut a line search
  /// short, up to this value.
  double volume_barrier_max = 0.1;
  /// Per tet, the volume barrier is multiplied by this whenever the full SQP step would invert the
  /// tet, up to volume_boost_max (1 disables it). Slivers weigh almost nothing in the
  /// volume-weighted barrier, and one sliver flattened by the step cuts the whole step short.
  /// (fandisk 37.8k tets / rod 68k tets: 3 gives 24.6 / 73.0 s, 10 gives 27.5 / 85.7 s with more
  /// backtracking, 1 stalls fandisk at l1_quality 1.3e-2 and takes 78.9 s on the rod.)
  double volume_boost_factor = 3.0;
  double volume_boost_max = 1e3;
  /// Open surfaces (surface mode): weight of the border l1 term relative to E1. The border edges
  /// weigh like a band of width border_weight x area / border length (see border_l1_energy).
  double border_weight = 1.0;
  /// Closed surfaces in surface mode: weight of the thickness barrier (thickness_energy; 0 = off),
  /// which keeps the two sides of thin parts (thinner than thickness_max of the bounding-box
  /// diagonal) at least thickness_keep of their rest distance apart, so that thin parts are not
  /// folded flat into double sheets (the surface ARAP does not see folds).
  double thickness_weight = 1.0;
  /// Surface mode: the thickness barrier as a contact barrier (contact_energy: every vertex of a
  /// thin part against every triangle across that comes near it in the current shape, with a
  /// continuous collision check in the line search) rather than fixed pairs (thickness_energy),
  /// which the two sides of a part fool when they slide along each other as it is pressed flat.
  bool thickness_contact = false;
  /// Volume mode: weight of the same barrier across the gaps between parts narrower than
  /// thickness_max (exterior pairs, see thickness_pairs; thickness_keep and thickness_retry_above
  /// as for thin parts), which nothing else keeps open; 0 = off (default). Homer's legs are pressed
  /// into each other without it (its deformed surface intersects itself; with 1 it does not, but
  /// the polycube realized from it still overlaps itself). On by default it would deform the
  /// bumpy torus twice (its bumps press into each other: 0.28% of the area) for the same polycube.
  double gap_weight = 0.0;
  double thickness_keep = 0.5;
  double thickness_max = 0.05;
  /// The shape is deformed without the barrier first, and again with it when the pairs pressed
  /// under thickness_keep of their rest distance (or, across gaps, through each other) carry more
  /// than this fraction of the area.
  double thickness_retry_above = 1e-3;
  /// Surface mode starts at alpha0 times this: the surface ARAP resists less than the volumetric
  /// one, and a sphere of 2048 triangles folded into 19 charts from 0.05 (6 from 0.01, with a
  /// lower distortion, 0.066 against 0.10).
  double surface_alpha_scale = 0.2;
  /// SQP with the Hessian of the Lagrangian: the l1 term's Hessian includes lambda x the curvature
  /// of the total boundary area (lambda the constraint's multiplier at the previous step, times
  /// alpha_factor after an alpha doubling), projected to PSD per triangle. The area's curvature is
  /// negative where the l1 term's is positive, so without it the steps are too short and each
  /// schedule step converges slowly (measured: fandisk 37.8k tets 150 -> 99 SQP iterations, ARAP
  /// 0.0452 -> 0.0433; 4-5k tets 99-119 -> 74-89).
  bool lagrangian_hessian = true;
  int max_alpha_steps = 20;     ///< schedule steps (alpha doublings) at most
  int max_inner_iterations = 100;  ///< SQP iterations per schedule step at most
  double target_quality = 1e-3; ///< stop when sum|N|_1 / sum|N|_2 - 1 falls below this
  /// A schedule step also ends when the SQP has converged for its alpha (the paper's second test):
  /// a full step, from the second iteration on, lowers the merit energy by less than this fraction.
  /// The paper's error test alone needs five small changes of the error, which the first schedule
  /// steps (small alpha, where the shape barely moves) spend converging linearly to a state the
  /// next alpha leaves at once (measured, polycube_bench --deform-only, one run: 4-5k tets 74-89
  /// -> 33-49 SQP iterations, 0.65-0.95 -> 0.28-0.52 s; spot 17.4k 110 -> 75, 8.2 -> 4.8 s;
  /// fandisk 37.8k 99 -> 72, 14.6 -> 9.5 s, ARAP 0.0433 -> 0.0439; rod 68k 35.5 -> 29.4 s; bumpy
  /// torus and rocker unchanged in time, where the steps keep decreasing; the same layouts, polycube
  /// ARAP within 2.5%). Negative (default): 3e-5 for the volume deformation, 0 in surface mode,
  /// where the quads' Hausdorff distance turned out sensitive to the path (fandisk --surface
  /// --quads 724: 3.88e-3 with 0, 5.8e-3 / 8.1e-3 / 4.7e-3 with 1e-5 / 3e-5 / 1e-4). 0 = the
  /// paper's error test only.
  double sqp_tolerance = -1;
  /// The tolerance in effect: sqp_tolerance, or its default for the mode when negative.
  double sqp_tolerance_for(bool surface) const { return sqp_tolerance >= 0 ? sqp_tolerance : (surface ? 0.0 : 3e-5); }
  bool global_rotation = true;  ///< re-solve the best global rotation (Eq. 3) during the solve
  /// ...at the first SQP iteration of each schedule step (as the authors' code does) and, if > 0,
  /// every this many iterations after it. Rotating between factorizations makes the reused
  /// factorization a worse CG preconditioner: 0 is 25% faster than 1 on a 4k-tet sphere, same result.
  int rotation_interval = 0;
  std::vector<EdgeConstraint> edges;  ///< user edge terms (Eqs. 12-13), on face_pairs(boundary)
  /// The SQP systems are solved by conjugate gradients preconditioned with the last Cholesky
  /// factorization, to this relative residual; a new factorization is made at each schedule step
  /// and when CG needs more iterations than a tenth of a factorization's cost (CHOLMOD's flop
  /// counts, so that a run does not depend on the machine's load; at least cg_max_iterations).
  double cg_tolerance = 1e-2;
  int cg_max_iterations = 12;
  /// From schedule step cg_late_from_step on (0-based), the CG tolerance is cg_tolerance_late
  /// instead (0 = cg_tolerance throughout; set by the stall rescue below).
  double cg_tolerance_late = 0;
  int cg_late_from_step = 0;
  /// Volume mode, stall rescue: when the schedule ends with l1_quality above target_quality after
  /// at least rescue_from_step + 2 steps (not a schedule cut short for a quick look), the
  /// deformation runs again from rest with the SQP systems solved to rescue_cg_tolerance from
  /// schedule step rescue_from_step on, and the better result (the lower l1_quality, no tet
  /// inverted) is kept. Late in the schedule the inexact CG directions invert tets at a small
  /// fraction of their length, the barrier of the tets they invert is raised, and the shape
  /// stiffens until the steps stall (blub, 52k tets: steps of 1e-3 to 1e-4 from alpha 400 on, half
  /// the tets' barriers raised, l1_quality 1.23e-3 after the 20 steps; the directions of fresh
  /// factorizations went 0.25-1 of their length where CG's went 0.004-0.06). Solved to 1e-4 from
  /// alpha 12.8 on, blub reaches 9.9e-4 (208 iterations). Runs that reach the target are unchanged;
  /// the others cost a second deformation. 0 = off.
  double rescue_cg_tolerance = 1e-4;
  int rescue_from_step = 8;
  /// A new factorization is also made, without trying CG, when that limit is above its floor
  /// (cg_max_iterations: the large meshes) and the last solve needed more than this fraction of it
  /// and more iterations than the one before it: the count grows as
  /// the factorization ages (alpha doubled, the shape moved), and the next solve would most likely
  /// run to the limit and be thrown away (rocker, 132k tets: 9 such solves of 30 iterations, 0.6 s
  /// each, each followed by the factorization anyway). 0 = off. Measured (`polycube_bench
  /// --deform-only`, same machine and hour, off -> 0.5): fandisk 39k tets 9.2 -> 6.5 s, rod 80k
  /// 27.8 -> 25.1 s, bumpy torus 112k 64.9 -> 52.5 s, rocker 132k 66.5 -> 61.4 s, the same ARAP
  /// and l1_quality < 1e-3; 0.35 and 0.7 were slower on two of the four each.
  double cg_refactor_fraction = 0.5;
  /// Supernodal factors (volume and surface mode alike): the SQP systems are factorized in single
  /// precision (FloatFactor::factorize: CHOLMOD's symbolic analysis, our left-looking numeric factorization
  /// with float BLAS, the two subtrees of the elimination tree on two threads), with 1e-5 of the
  /// ARAP diagonal added to the diagonal: every term is invariant under translations, and the
  /// damping mu (1e-8 of it) that alone holds those directions lies under float's resolution
  /// (unshifted, a third of rocker's float factorizations broke down). The direction after a
  /// factorization is CG on its factor to SparseSystem::kRefineTolerance (about two iterations),
  /// and the factor preconditions the next systems as the float copy of CHOLMOD's does. Where a
  /// float factorization breaks down anyway (also with 100 times the shift), CHOLMOD's double one
  /// takes over for the rest of the run. Measured (`polycube_bench --deform-only`, one run each,
  /// the same hour, off -> on): rocker 132k tets 65.4 -> 62.1 s (its factorizations 2.3 -> 1.1 s
  /// each; CLI pairs 70.3 / 70.5 -> 57.2 s), bumpy torus 113k 50.6 -> 41.9 s, tet/hand 22.0 ->
  /// 16.1 s, fandisk 6.66 -> 6.44 s, but the rod 26.6 -> 30.4 s (its path changed: 61 -> 73 SQP
  /// iterations); the ten models 178.5 -> 163.8 s in all, l1_quality under 1e-3 and ARAP within
  /// 1% on each. Off by default: it changes the SQP path, and the polycube extraction after it
  /// depends on the path's last digits. With it, rod, fandisk, bumpy torus and rocker gave the
  /// same charts, corners and polycube ARAP (within 0.3%), but rocker's extraction took 405 s
  /// (25 edge collapses; 68-85 s without it): its retries ended with 11 boundary triangles facing
  /// away, over chart::ExtractOptions::max_folded_collapses (then 10); with 30 (fiftieth session)
  /// the same deformation's extraction takes 74 s. On by default in volume mode only, the suite
  /// failed three tests calibrated on the double path, one of them an exit 7 (the hex stage from
  /// box_hole's polycube map with a vertex pushed past its neighbours); see the README.
  bool float_factorization = false;
  /// Volume mode: inside the deformation, renumber the interior vertices (those on no boundary
  /// triangle, among their own ids) along a Morton curve and sort the tets by their smallest
  /// vertex, so that the assembly's and the solves' scattered accesses stay local; the result is
  /// given back in the input's numbering. Boundary ids, hence the boundary pairs and user edges,
  /// are unchanged. Off by default: it changes the order of the sums, hence the last digits and the
  /// SQP path (rocker at 178k tets: 1.84 -> 1.21 s per SQP iteration, the assembly 314 -> 192 ms).
  bool locality_order = false;
  /// Resuming a deformation (the pipeline's slim-triangle collapse, see below): the positions to
  /// start from (input units, one row per vertex; empty = the rest positions V) and the schedule
  /// step to start at (alpha = alpha0 x alpha_factor^k, eps reduced k times; max_alpha_steps counts
  /// from 0, so the resumed run takes max_alpha_steps - k steps at most).
  MatX3d start;
  int first_alpha_step = 0;
  /// The paper's slim-triangle collapse (Section 4) needs the tet mesh to change, which the caller
  /// does (chart::collapse_slim_triangles): with this set (volume mode), a line search cut short
  /// (a step under 1/16 of the SQP direction, or none) by tets about to invert or an infinite
  /// barrier, while boundary triangles with an angle under slim_angle_deg exist in the deformed
  /// mesh, ends the deformation there (DeformResult::slim_stall), to be resumed after the collapse.
  bool stop_at_slim_stall = false;
  double slim_angle_deg = 5.0;
};

/// One SQP iteration, for convergence plots like the paper's Fig. 3.
struct IterationRecord {
  int alpha_step = 0, iteration = 0;
  double alpha = 0, eps = 0;
  double e1 = 0;          ///< sum_f |N_f|_1 / boundary area (1 for a polycube)
  double e_arap = 0;      ///< E_delta
  double error_d = 0;     ///< Eq. 1 in input units (area)
  double l1_quality = 0;  ///< sum|N|_1 / sum|N|_2 - 1
  double step = 0;        ///< accepted line-search step length
  double seconds = 0;     ///< since the start of the deformation
};

struct DeformResult {
  MatX3d X;                  ///< deformed positions, input units, centred where the input was
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  ///< global rotation applied (deformed = R * input-ish)
  double l1_quality = 0;     ///< sum|N|_1 / sum|N|_2 - 1 at the end
  double error_d = 0;        ///< Eq. 1, input units
  double arap = 0;           ///< E_delta at the end (surface ARAP in surface mode)
  double border_quality = 0; ///< open surfaces: sum|e|_1 / sum|e|_2 - 1 over the border edges
  int iterations = 0, alpha_steps = 0, inverted = 0;
  int factorizations = 0;    ///< sparse Cholesky factorizations made
  int float_factorizations = 0;  ///< of those, made in single precision (DeformOptions::float_factorization)
  double volume_barrier_weight = 0;  ///< final (possibly raised) volume-barrier weight
  int boosted_tets = 0;      ///< tets whose volume barrier was raised (they blocked a full step)
  /// Volume mode: tets left with under kCrushedRatio of their rest volume (nearly flat; such tets
  /// can block the realization, see DeformOptions::crush_guard_weight).
  int crushed_tets = 0;
  static constexpr double kCrushedRatio = 1e-3;
  /// Vertex pairs kept apart (thickness_energy): across thin parts (surface mode) or gaps (volume).
  int thickness_pairs = 0;
  /// Area fraction of the thin parts (surface mode) or gaps (volume mode) pressed under
  /// thickness_keep of their rest distance by the deformation without the barrier (above
  /// thickness_retry_above: deformed again with it).
  double thin_crushed = 0;
  /// The same fraction at the end, over the pairs the barrier kept (0 without the barrier).
  double thin_crushed_after = 0;
  /// With the contact barrier (DeformOptions::thickness_contact, in the pass that used it): the
  /// vertex-triangle pairs within their contact distance at the end, and the SQP iterations whose
  /// step the collision check shortened.
  int contact_active = 0, contact_step_cuts = 0;
  /// Surface mode, closed surfaces: the thin parts pressed flat at the end, their gaps measured
  /// across (flattened_parts with thickness_keep): what the barrier's distances miss when the two
  /// sides slide along each other. places: vertices of V, worst first, up to five, at least 0.1 of
  /// the bounding-box diagonal apart.
  Flattened thin_flattened;
  /// Stall rescue (DeformOptions::rescue_cg_tolerance): the first run's l1_quality when it ran
  /// (-1: not needed or off), and whether its result was kept.
  double rescue_from_quality = -1;
  bool rescued = false;
  /// DeformOptions::stop_at_slim_stall: the deformation stopped at a stall with slim boundary
  /// triangles (slim_triangles of them) during schedule step stall_step (0-based); X is that state.
  bool slim_stall = false;
  int slim_triangles = 0;
  int stall_step = 0;
  bool converged = false;    ///< l1_quality reached target_quality
  double seconds = 0;
  std::vector<IterationRecord> history;
};

/// Deforms the tet mesh (V, T) with boundary triangles B (outward) towards a polycube.
/// Throws Error(Internal) if the input has inverted tets. Without the gap barrier first; when gaps
/// between parts close (thin_crushed above thickness_retry_above after a schedule step) again
/// from rest with it (thickness_pairs > 0 then; `seconds` counts both passes).
DeformResult deform_to_polycube(const MatX3d& V, const MatX4i& T, const MatX3i& B, const DeformOptions& opt,
                                const Hooks& hooks = {});

/// Surface mode (paper Section 5.3): the same energy, solver and schedule on the triangle mesh
/// (V, F) alone, with the surface ARAP distortion instead of the volumetric one and no volume
/// barrier. F may be open: its border edges then get a smoothed l1 term that makes them
/// axis-aligned (the paper's open-boundary inset). `inverted` stays 0 (no tets). A closed F is
/// deformed without the thickness barrier first; when thin parts are pressed flat (thin_crushed
/// above thickness_retry_above after a schedule step) it is deformed again from rest with it
/// (thickness_pairs > 0 then; `seconds` counts both passes, `iterations` the second).
DeformResult deform_surface_to_polycube(const MatX3d& V, const MatX3i& F, const DeformOptions& opt,
                                        const Hooks& hooks = {});

/// The rotation R minimizing the smoothed l1 norm of R n over the boundary normals (Eq. 3),
/// found by Newton steps on the rotation vector. Returns the identity if nothing improves.
Eigen::Matrix3d best_rotation(const MatX3d& X, const MatX3i& B, double eps);

}  // namespace polycube::deform
