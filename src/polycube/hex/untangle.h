// Untangling of hex meshes whose optimization (hex/optimize.h) left hexes with inverted corners.
//
// optimize_hexes moves one vertex at a time and accepts a move only if the worst scaled Jacobian
// of the vertex's hexes rises: a cluster of hexes folded over one another (a grid mapped through a
// polycube map that folds, or a pillow layer over a tight concave spot) can need moves that first
// make one of them worse. Here every hex is its 8 corner tets (kHexCorners: a corner and the three
// corners joined to it by an edge, positive exactly when the hex's corner is), and the elliptic
// untangling energy of Garanzha et al. 2021 (deform::untangle_energy: finite for inverted tets,
// eps shrinking with the worst one) is minimized vertex by vertex around the inverted corners
// (deform::untangle_locally), the rest shape of each corner tet a right corner of the hex's mean
// edge length. The Verdict scaled Jacobian's ninth sample (the centre) is not in the energy; the
// caller optimizes the hexes again afterwards.
#pragma once
#include <functional>
#include <vector>

#include "polycube/core/types.h"

namespace polycube::hex {

/// The 8 corner tets of every hex: row 8 h + j is hex h's corner j (kHexCorners), a tet in the
/// core/types.h convention.
MatX4i hex_corner_tets(const MatX8i& H);

/// Corner tets of H (hex_corner_tets) that are flat or inverted in V.
int inverted_hex_corners(const MatX3d& V, const MatX8i& H);

/// Per hex of H: 1 when one of its corners (hex_corner_tets) is flat or inverted in V.
std::vector<char> hexes_with_inverted_corners(const MatX3d& V, const MatX8i& H);

struct HexUntangleStats {
  int corners_before = 0;  ///< flat or inverted corner tets at the start
  int corners_after = 0;   ///< ... at the end
  int sweeps = 0;          ///< sweeps of deform::untangle_locally
};

/// Moves the vertices within `rings` corner-tet rings of the inverted corners of H (fixed[v] != 0:
/// v stays; the caller fixes the boundary) to untangle them, in runs of 20 sweeps, up to
/// max_sweeps or two runs without fewer inverted corners. V takes the state with the fewest
/// inverted corners, and is left as it was when none has fewer than at the start. open_below > 0: once none is
/// inverted, corners whose volume ratio is under open_below x the mean are opened (sweeps kept
/// while the smallest ratio grows), so that a later small move (back onto a surface) or the
/// scaled Jacobian's centre sample does not turn them over again.
/// slide (optional, with project): vertices v with (*slide)[v] != 0 and not fixed move in the
/// tangent plane of a surface and are put back onto it after each move (a boundary quad folded
/// on the surface cannot be opened from inside). project(p, normal) returns the surface point
/// for p and sets the surface's unit normal there.
using SurfaceProjection = std::function<Vec3(int v, const Vec3& p, Vec3& normal)>;
HexUntangleStats untangle_hex_corners(MatX3d& V, const MatX8i& H, const std::vector<char>& fixed, int rings = 4,
                                      int max_sweeps = 200, double open_below = 0,
                                      const SurfaceProjection& project = {}, const std::vector<char>* slide = nullptr);

}  // namespace polycube::hex
