// Energies of the l1 polycube deformation (Huang et al. 2014, Sections 2-3), each with an analytic
// gradient and a symmetric positive semi-definite Hessian approximation.
//
// Positions X are #V x 3 (row-major), so the degree of freedom of coordinate k of vertex v is 3v+k.
// Every function adds weight * (its term) to `grad` and `hess` when they are non-null and returns
// weight * value. Hessians are handed over per element through HessianSink.
#pragma once
#include <Eigen/Core>
#include <array>
#include <utility>
#include <vector>

#include "polycube/core/error.h"
#include "polycube/core/types.h"

namespace polycube::deform {

/// Receives symmetric element Hessians: `H` is (3 nv) x (3 nv) over the vertices v[0..nv).
/// Receives element Hessians (3nv x 3nv, vertex-major). Callers pass fixed-size matrices, which
/// bind to the Ref without a heap temporary (an expression would allocate one per element).
class HessianSink {
 public:
  virtual ~HessianSink() = default;
  virtual void add(const int* v, int nv, const Eigen::Ref<const Eigen::MatrixXd>& H) = 0;
  /// Adds the rank-1 element Hessian (c u) u^T, u of size 3 nv (at most 12): entry (i, j) is
  /// (c u_i) u_j, as Eigen's outer product `c * u * u.transpose()` rounds it. Sinks may add it
  /// without forming the matrix.
  virtual void add_outer(const int* v, int nv, double c, const double* u) {
    POLYCUBE_ASSERT(nv <= 4, "rank-1 element Hessians have at most 4 vertices");
    Eigen::Matrix<double, 12, 1> w;
    for (int i = 0; i < 3 * nv; ++i) w[i] = c * u[i];
    Eigen::Matrix<double, 12, 12> H;
    for (int j = 0; j < 3 * nv; ++j)
      for (int i = 0; i < 3 * nv; ++i) H(i, j) = w[i] * u[j];
    add(v, nv, H.topLeftCorner(3 * nv, 3 * nv));
  }
};

/// Dense sink for tests and small problems.
class DenseHessian : public HessianSink {
 public:
  explicit DenseHessian(int nvertices) : H(Eigen::MatrixXd::Zero(3 * nvertices, 3 * nvertices)) {}
  void add(const int* v, int nv, const Eigen::Ref<const Eigen::MatrixXd>& h) override;
  Eigen::MatrixXd H;
};

/// Two boundary triangles sharing an edge: f = (a, b, c), g contains b, a; c and d are the
/// vertices opposite the shared edge in f and g.
struct FacePair {
  int f, g;
  int a, b, c, d;
};

/// Adjacent boundary-triangle pairs of a closed oriented triangle set.
std::vector<FacePair> face_pairs(const MatX3i& F);

/// Area-weighted normal of triangle (a, b, c): N = (b - a) x (c - a) / 2; |N| is the area.
Vec3 area_normal(const MatX3d& X, int a, int b, int c);

/// Cosine of the smallest angle of triangle (a, b, c) (1 for a degenerate one): the triangle is
/// slim under angle A where this exceeds cos A (the slim-triangle collapse, Section 4).
double smallest_angle_cos(const MatX3d& X, int a, int b, int c);

/// Smoothed l1 energy (Eq. 2 with |c| ~ sqrt(c^2 + eps), Eqs. 4-5):
///   sum_f A_f sum_k sqrt(n_fk^2 + eps) = sum_f sum_k sqrt(N_fk^2 + eps |N_f|^2).
/// Hessian: per triangle, the second term of Eq. 5 projected to PSD by clamping its eigenvalues
/// (in closed form); `project` = false gives the exact Hessian, for tests.
/// area_multiplier lambda != 0 (with project): the Hessian is that of weight E1 + lambda x (total
/// area), per triangle projected to PSD, i.e. the Lagrangian's Hessian under the area constraint
/// (energy and gradient unchanged).
double l1_energy(const MatX3d& X, const MatX3i& F, double eps, double weight, Eigen::VectorXd* grad, HessianSink* hess,
                 bool project = true, double area_multiplier = 0);

/// Exact (non-smoothed) l1 energy sum_f |N_f|_1 and total area sum_f |N_f|.
void l1_measure(const MatX3d& X, const MatX3i& F, double& l1, double& area);

/// Gradients of a tet's deformation gradient F = Ds Dm^-1 with respect to its vertices: row p is
/// d F / d x_p (as a row vector multiplying x_p^T); rows 1-3 are Dm^-1, row 0 minus their sum.
inline Eigen::Matrix<double, 4, 3> shape_gradients(const Eigen::Matrix3d& Dm_inv) {
  Eigen::Matrix<double, 4, 3> B;
  B.bottomRows<3>() = Dm_inv;
  B.row(0) = -Dm_inv.colwise().sum();
  return B;
}

/// Precomputed rest-state data for ARAP.
struct ArapRest {
  std::vector<Eigen::Matrix3d> Dm_inv;  ///< inverse rest edge matrix per tet
  std::vector<double> w;                ///< rest volume / total rest volume
  static ArapRest build(const MatX3d& X_rest, const MatX4i& T);
};

/// Volumetric ARAP distortion (Eqs. 6-7): sum_t w_t * 0.5 |F_t - polar(F_t)|_F^2.
/// Gradient exact; Hessian G^T G (constant, PSD). `per_tet` optionally receives each delta_t.
double arap_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight, Eigen::VectorXd* grad,
                   HessianSink* hess, std::vector<double>* per_tet = nullptr);

/// From this many tets on, arap_energy without a Hessian splits its tets in two halves, [0, n/2)
/// and [n/2, n), on two threads: weight (E0 + E1), where the first half's gradient is added into
/// grad tet after tet and the second half's is summed into a zeroed vector that is then added.
constexpr int kArapSplitTets = 4000;

/// One half (0 or 1) of that split: its energy sum_t w_t delta_t (not yet multiplied by weight),
/// weight times its gradient added into grad (if given) tet after tet. For callers that run the
/// halves on threads of their own in the same arithmetic (the SQP solver puts the second half
/// beside the boundary terms, which end first).
double arap_energy_half(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight, int half,
                        Eigen::VectorXd* grad);

/// Rest-state data for the surface ARAP distortion (surface mode).
struct SurfaceArapRest {
  /// Per triangle, row p: g_p, with F_t = sum_p x_p g_p^T the 3 x 3 Jacobian of the affine map
  /// from the rest triangle (zero on its normal): rows 1-2 the pseudo-inverse of the rest edges.
  std::vector<Eigen::Matrix3d> grad;
  std::vector<Vec3> normal;  ///< rest unit normal per triangle
  std::vector<double> w;     ///< rest area / total rest area
  std::vector<double> area;  ///< rest area
  static SurfaceArapRest build(const MatX3d& X_rest, const MatX3i& F);
};

/// Surface ARAP distortion with one rotation per vertex (Sorkine and Alexa 2007, in the per-triangle
/// form of Chao et al. 2010's "spokes and rims"):
///   sum_t w_t sum_{i in t} (1/3) 0.5 |F_t - R_i P_t|_F^2,
/// P_t the projector on the rest triangle's plane, R_i the rotation closest to sum_{t ni i} w_t F_t.
/// A rotation shared by the triangles around a vertex resists bending, which a rotation per
/// triangle would not: with that, a sphere's surface folds into many small steps (16 charts
/// instead of 6). Gradient exact (each R_i is optimal for its terms); Hessian G^T G (constant,
/// PSD). `per_face` optionally receives each triangle's delta.
double surface_arap_energy(const MatX3d& X, const MatX3i& F, const SurfaceArapRest& rest, double weight,
                           Eigen::VectorXd* grad, HessianSink* hess, std::vector<double>* per_face = nullptr);

/// Area barrier of surface mode (not in the paper; the counterpart of volume_barrier_energy):
/// sum_f w_f * -log(A_f / A_f^rest), w_f the rest area fraction. Keeps every triangle from
/// degenerating: a triangle whose area reaches ~0 flips its normal under the smallest step, the
/// anti-foldover barrier of its edges jumps, and every line search fails from there (basic/eight,
/// a triangle of area 4e-9 where its neighbours had 6e-4). +inf at zero area. Hessian: Gauss-Newton.
double area_barrier_energy(const MatX3d& X, const MatX3i& F, const SurfaceArapRest& rest, double weight,
                           Eigen::VectorXd* grad, HessianSink* hess);

/// Thickness of a closed surface (surface mode; not in the paper): a boundary vertex v and the point
/// across the part below it, on triangle f at barycentric coordinates `bary`, at rest distance d0.
/// The surface ARAP measures lengths within the surface only: folding a thin part flat (a horn
/// pressed into a double sheet whose two sides then face +Y and -Y) costs it almost nothing, and the
/// sheet is crushed when the polycube is realized (spot's horns: 0.2% of their area left). These
/// pairs keep the two sides of thin parts apart.
struct ThicknessPair {
  int v = -1, f = -1;
  Vec3 bary = Vec3::Zero();
  double d0 = 0;  ///< rest distance
  double w = 0;   ///< v's share of the total rest area (a third of its triangles' areas)
  /// The point is across the gap outside the surface (exterior pairs, volume mode) rather than
  /// across the part below it.
  bool exterior = false;
};

/// For each vertex of the closed surface (X, F): the closest point on a triangle facing the other
/// way (normal against v's), not incident to v, within 60 degrees of v's inward normal and closer
/// than max_thickness. Vertices with no such point get no pair (thick parts, open surfaces' borders).
/// `exterior`: within 60 degrees of v's outward normal instead, i.e. across a gap between two parts
/// of the shape (two legs, an arm and the body); the tets keep the parts themselves thick, nothing
/// keeps the gaps open (homer's legs were pressed into each other).
std::vector<ThicknessPair> thickness_pairs(const MatX3d& X, const MatX3i& F, double max_thickness,
                                           bool exterior = false);

/// Area fraction (sum of w) of the pairs whose two sides are closer than keep x their rest distance
/// in X; exterior pairs also when their two sides have passed through each other (the point across
/// no longer on v's outer side).
double crushed_fraction(const MatX3d& X, const MatX3i& F, const std::vector<ThicknessPair>& pairs, double keep);

/// Gap of pair p in X along the unit normal of its triangle across: the distance from v to the
/// plane of f, positive on the side of the part's inside (exterior pairs: of the gap outside),
/// negative once v has passed through that plane (0 if f has no area). Unlike the plain distance
/// that crushed_fraction and thickness_energy measure, it does not stay large when the part's two
/// sides slide along each other as it is pressed flat: cow's hind legs in surface mode came out
/// of the deformation as plates 0.001 thick (0.033 across at rest) with every pair at half its
/// rest distance or more, the two sides shifted along the plate (2026-12-07).
double pair_gap(const MatX3d& X, const MatX3i& F, const ThicknessPair& p);

/// Thin parts pressed flat in X: the pairs whose gap (pair_gap) is under `keep` x their gap at
/// rest R (pairs whose rest gap is under half their rest distance, across a triangle that leans
/// too far for its plane to measure the gap, are left out).
struct Flattened {
  double fraction = 0;  ///< area fraction (sum of w) of those pairs
  double ratio = 1;     ///< the smallest gap ratio among them: gap in X over gap at rest
  /// The places pressed: v of the worst pair, then of the next worst farther than `spacing` (at
  /// rest) from those already listed, and so on, at most `max_places` (cow: a hind hoof, the head's
  /// tip, both ears, the tail).
  std::vector<int> places;
  /// v of the worst pair (-1: none).
  int vertex() const { return places.empty() ? -1 : places.front(); }
};
Flattened flattened_parts(const MatX3d& R, const MatX3d& X, const MatX3i& F, const std::vector<ThicknessPair>& pairs,
                          double keep, double spacing = 0.1, int max_places = 5);
/// The Flattened of the pressed vertices given as (ratio, vertex) with their area fraction: the
/// smallest ratio, and the places, worst first, each farther than `spacing` in R (rest) from those
/// already listed, at most max_places (flattened_parts and contact_flattened share it).
Flattened pressed_places(const MatX3d& R, std::vector<std::pair<double, int>> pressed, double fraction,
                         double spacing, int max_places);

/// sum_p w_p phi(d_p / (keep d0_p)), d_p = |x_v - sum_i bary_i x_fi|, with
/// phi(r) = r - 1 - log r for r < 1 and 0 above: zero while the part keeps at least `keep` of its
/// rest thickness, +inf when its two sides meet. C1 at r = 1, convex in r. Hessian: Gauss-Newton
/// (phi'' grad r grad r^T; the term in phi' hess r is negative there and left out).
double thickness_energy(const MatX3d& X, const MatX3i& F, const std::vector<ThicknessPair>& pairs, double keep,
                        double weight, Eigen::VectorXd* grad, HessianSink* hess);

/// sum_k sqrt(v_k^2 + eps |v|^2), the smoothed l1 norm of one vector, with (when asked) its gradient
/// and Hessian in v: exact, and PSD (each term is the norm of a linear map of v).
double smoothed_l1(const Vec3& v, double eps, Vec3* grad, Eigen::Matrix3d* hess);

/// Open surfaces (the paper's inset of Section 5.3): smoothed l1 norm of the border edges,
///   sum_e h [sum_k sqrt(e_k^2 + eps |e|^2) - c_eps |e|],   e = x_b - x_a,
/// c_eps = sqrt(1 + eps) + 2 sqrt(eps) its value for an axis-aligned unit edge, so each term is
/// >= 0, zero exactly for axis-aligned edges, and the border gains nothing by shrinking (the plain
/// l1 norm pulls a border loop together: an open cylinder's ARAP distortion went to 0.3-3).
/// h is a length (the caller's choice) that gives the term the units of the area-weighted normals
/// of E1. `edges` are (a, b) vertex pairs. Hessian: the exact Hessian of the first (convex) part,
/// PSD; the concave -c_eps |e| part is left out.
double border_l1_energy(const MatX3d& X, const std::vector<std::array<int, 2>>& edges, double h, double eps,
                        double weight, Eigen::VectorXd* grad, HessianSink* hess);

/// Border edges (a, b) of a triangle set, oriented as in their triangle; empty for a closed surface.
std::vector<std::array<int, 2>> border_edges(const MatX3i& F);

/// Volume barrier (not in the paper): sum_t w_t b_t phi(J_t), J_t = det F_t, w_t the rest volume
/// fraction, b_t an optional per-tet multiplier (`boost`, 1 when null; the solver raises it on the
/// tets that block its line search). Keeps every tet positively oriented so that the line search is
/// never blocked by a tet that the SQP direction flattens. +inf for an inverted tet.
/// Default: phi(J) = -log J, whose gradient at J = 1 pushes every tet to grow: under the constant
/// boundary area the shape rounds off while alpha is small (fandisk's l1_quality 0.200 -> 0.213
/// over the first schedule step). `neutral`: phi(J) = J - 1 - log J, zero with a zero gradient at
/// J = 1, so that the barrier does not act on tets of unchanged volume (see
/// DeformOptions::neutral_volume_barrier for why it is not the default).
/// Hessian: the Gauss-Newton part of either, (grad J grad J^T)/J^2.
double volume_barrier_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight,
                             Eigen::VectorXd* grad, HessianSink* hess, const std::vector<double>* boost = nullptr,
                             bool neutral = false);

/// Crush guard (not in the paper): sum_t (1/#tets) psi(J_t / j0), J_t = det F_t, with
/// psi(r) = r - 1 - log r for r < 1 and 0 above. Zero on every tet that keeps at least j0 of its
/// rest volume; below that, each tet weighs as a tet of mean volume, whatever its own size. The
/// volume-weighted barrier hardly sees small tets, and the l1 term presses some of them flat
/// against polycube edges (homer: 106 tets under a volume ratio of 1e-3), where they later block
/// the realization. C1 at J = j0, convex in J, +inf for an inverted tet. Hessian: Gauss-Newton
/// (psi'' grad J grad J^T).
double crush_guard_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double j0, double weight,
                          Eigen::VectorXd* grad, HessianSink* hess);

/// Untangling energy of Garanzha et al. ("Foldover-free maps in 50 lines of code", ACM ToG 2021):
/// sum_t w_t [(1 - theta) tr(J^T J) / chi(D)^(2/3) + theta (D^2 + 1) / chi(D)], J = F_t / scale,
/// D = det J, chi(D) = (D + sqrt(eps^2 + D^2)) / 2. Finite for inverted tets (unlike a barrier);
/// as eps -> 0 an inverted tet costs without bound, so minimizing it with eps decreasing untangles
/// a map. `scale` sets the volume ratio the energy prefers (cube root of the mean det F).
/// Gradient exact (no Hessian: it is minimized by quasi-Newton).
double untangle_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double eps, double scale,
                       double theta, Eigen::VectorXd* grad);

/// The term of untangle_energy for one tet t of T; `grad` (optional) receives its gradient over
/// the tet's 12 coordinates (vertex-major).
double untangle_tet_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t, double eps, double scale,
                           double theta, Eigen::Matrix<double, 12, 1>* grad);

/// The term of untangle_energy for tet t as a function of its corner j (0..3) alone: `grad` and
/// `hess` (optional) receive the exact gradient and Hessian over that corner's 3 coordinates. The
/// volume is affine in one corner, so the Hessian has a closed form (no differences across the
/// energy's steep walls near D = 0). Not made definite. `wall` (optional, with grad or hess):
/// |dD/dx| / sqrt(eps^2 + D^2), the inverse of the distance over which the corner's move changes
/// the energy's curvature (large next to the wall D = 0).
double untangle_tet_corner(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t, int j, double eps,
                           double scale, double theta, Vec3* grad, Eigen::Matrix3d* hess, double* wall = nullptr);

/// Anti-foldover log barrier (Eq. 11): -sum_pairs log(1 + n_f . n_g). Returns +inf when a pair
/// folds over (1 + n_f . n_g <= 0). Hessian: Gauss-Newton (grad D grad D^T / D^2).
double barrier_energy(const MatX3d& X, const MatX3i& F, const std::vector<FacePair>& pairs, double weight,
                      Eigen::VectorXd* grad, HessianSink* hess);

/// Complexity penalty (Eqs. 8-10): sum_pairs A_e |n_f - n_g|^2 / A_total with the gamma-weighted
/// edge areas of Eq. 9 (held constant in the derivatives). Hessian: Gauss-Newton.
double complexity_energy(const MatX3d& X, const MatX3i& F, const std::vector<FacePair>& pairs, double weight,
                         Eigen::VectorXd* grad, HessianSink* hess);

/// A user edge constraint (Eqs. 12-13) on pair `pair`: sharp wants n_f . n_g = 0, flat wants 1.
struct EdgeConstraint {
  int pair;
  bool sharp;
  double omega;
};
/// sum omega (n_f . n_g - target)^2. Hessian: Gauss-Newton.
double edge_energy(const MatX3d& X, const MatX3i& F, const std::vector<FacePair>& pairs,
                   const std::vector<EdgeConstraint>& edges, double weight, Eigen::VectorXd* grad, HessianSink* hess);

/// Area constraint C(X) = sum_f |N_f| - area0 (Eq. 2) and its gradient.
double area_constraint(const MatX3d& X, const MatX3i& F, double area0, Eigen::VectorXd* grad);

}  // namespace polycube::deform
