// Contact barrier of surface mode: keeps the two sides of thin parts apart in the current shape.
//
// The thickness barrier (thickness_energy) holds fixed pairs, each vertex against one point of the
// triangle across at rest. When a thin part is pressed flat with its two sides sliding along each
// other, every such pair can stay far apart while the sides meet (cow's hind legs in surface mode:
// plates 0.001 thick, 0.033 across at rest, every pair at half its rest distance or more). This
// barrier, after incremental potential contact (Li et al. 2020), instead looks at every triangle
// near each vertex in the current shape, so sliding does not fool it, and bounds the line search's
// step so that no vertex passes through a triangle between two evaluations.
#pragma once
#include <vector>

#include "polycube/core/types.h"
#include "polycube/deform/energies.h"

namespace polycube::deform {

/// What the contact barrier keeps from the rest shape (X, F) of a closed surface.
struct ContactRest {
  MatX3d X;                  ///< rest positions
  MatX3i F;
  std::vector<Vec3> vertex_normal, face_normal;  ///< unit normals at rest (zero where undefined)
  /// Per vertex: keep x its rest thickness across (the distance of its thickness pair, see
  /// thickness_pairs), 0 for vertices of thick parts (no contact is looked for from them).
  std::vector<double> dhat;
  std::vector<double> w;     ///< per vertex: its share of the total rest area (a third of its triangles')
  double keep = 0.5;
  double dhat_max = 0;
  int vertices = 0;          ///< vertices with dhat > 0

  /// Thin parts thinner than max_thickness (fraction of the diagonal when X is normalized).
  static ContactRest build(const MatX3d& X, const MatX3i& F, double keep, double max_thickness);

  /// The distance under which the pair (vertex v, triangle f) is pushed apart:
  /// min(dhat[v], keep x their rest distance), so that the barrier is zero at rest. 0 (no contact)
  /// when f is incident to v, when f's rest normal does not face against v's (same side of the
  /// surface: its neighbours there are not contacts), or when the pair is closer at rest than a
  /// tenth of v's thickness (a self-intersecting input's crossing: no barrier can start there).
  double threshold(int v, int f) const;
  /// The cheap part of threshold's test: dhat[v] > 0, f not incident to v, rest normals against.
  bool facing(int v, int f) const;
};

/// sum over the vertices v with dhat > 0 and the closest features (a triangle's inside, an edge, a
/// vertex: each once, with the smallest threshold of its triangles) of the triangles f within
/// threshold(v, f) of v in X of
///   weight w_v b(d / threshold),  b(r) = -(r - 1)^2 log r  (IPC's barrier: C2 at r = 1, +inf at 0),
/// d the distance from v to the feature. Gradient: exact (the closest point held, as its derivative
/// vanishes). Hessian: Gauss-Newton (b'' grad d grad d^T; the b' hess d part, negative, left out)
/// and block-diagonal per vertex (each vertex's 3x3 block of that rank-1 matrix, times 2), since
/// the pairs change with the shape and the system's sparsity pattern does not. Returns +inf when a
/// vertex lies on a triangle it must not touch.
double contact_energy(const MatX3d& X, const ContactRest& rest, double weight, Eigen::VectorXd* grad,
                      HessianSink* hess, int* active = nullptr);

/// Per vertex: the smallest distance to a triangle across within its contact distance, over
/// min(its thickness, its rest distance to that triangle) (+inf where none is that close).
void contact_ratios(const MatX3d& X, const ContactRest& rest, std::vector<double>& ratio);

/// Thin parts pressed in X, measured as the contact barrier sees them (unlike flattened_parts,
/// sliding does not fool it): the vertices with dhat > 0 whose contact_ratios are under keep.
/// ratio: the smallest of those (never negative: the barrier keeps the sides from crossing);
/// places as in flattened_parts (apart by `spacing` at rest).
Flattened contact_flattened(const MatX3d& X, const ContactRest& rest, double spacing = 0.1, int max_places = 5);

/// A step length t in (0, 1] along D from X such that no vertex with dhat > 0 passes through a
/// triangle it has a contact threshold with: 0.8 x the first time in [0, 1] at which such a vertex
/// lies in its triangle, moving linearly (the root of the cubic of their coplanarity, then the
/// point tested inside), or 1 if none does. Sliding along each other does not limit the step.
double contact_step_bound(const MatX3d& X, const MatX3d& D, const ContactRest& rest);

}  // namespace polycube::deform
