// Local untangling of tet maps with the elliptic energy of Garanzha et al. 2021
// (deform::untangle_energy), vertex by vertex: used by the polycube realization (chart/realize.cpp)
// on its tet mesh and by the hex stage (hex/untangle.h) on the corner tets of hexes.
#pragma once
#include <functional>

#include "polycube/core/types.h"
#include "polycube/deform/energies.h"

namespace polycube::deform {

/// Volume ratio det(F) of tet t of T (rest -> X); not positive for a flat or inverted tet.
double volume_ratio(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t);

/// Tets of T whose volume ratio is not positive.
int count_inverted(const MatX3d& X, const MatX4i& T, const ArapRest& rest);

/// Local untangling: Gauss-Seidel sweeps over the vertices within `rings` tet rings of the
/// inverted tets, each moved along its free axes (those with fixed(v, k) false) by a Newton step
/// on the elliptic energy of its tets (untangle_tet_energy, theta 0.5), the exact 3 x 3
/// Hessian (untangle_tet_corner; next to the energy's wall, central differences of the
/// gradient) made definite, with backtracking. eps follows the
/// region's smallest volume ratio. After a global solve a few inverted tets often remain where
/// the global preconditioner (the ARAP matrix) says nothing about their vertices; here each
/// vertex sees only its own tets. Returns the sweeps taken.
/// flat > 0: the tets to repair are those whose volume ratio is below flat x the mean one (nearly
/// flat or inverted), `inverted` counts them, and a sweep is kept only while it raises the smallest
/// volume ratio and turns no tet over (opening nearly flat tets of a valid map).
/// stop: asked before each sweep with 100 x the sweeps so far; true ends it.
/// directions (optional): per vertex v, the directions it may move along instead of its free axes,
/// as the first columns of B (orthonormal), their count returned (-1: its free axes after all);
/// after_move (optional) is called with each vertex moved (e.g. to put it back onto a surface it
/// moves tangent to).
using MoveDirections = std::function<int(int v, const MatX3d& X, Eigen::Matrix3d& B)>;
int untangle_locally(const MatX4i& T, const ArapRest& rest, const std::function<bool(int, int)>& fixed, MatX3d& X,
                     int& inverted, int rings, int max_sweeps, double flat = 0,
                     const std::function<bool(int)>& stop = {}, const MoveDirections& directions = {},
                     const std::function<void(int, MatX3d&)>& after_move = {});

}  // namespace polycube::deform
