// Self-intersection search on a triangle surface (uniform grid + segment/triangle tests).
// Used to name the faces when the tet mesher reports an intersecting input.
#pragma once
#include <utility>
#include <vector>

#include "polycube/core/types.h"

namespace polycube {

/// Pairs of faces (i < j) that share no vertex and whose interiors cross, at most `max_pairs`.
/// Coplanar overlaps are not detected.
std::vector<std::pair<int, int>> find_self_intersections(const MatX3d& V, const MatX3i& F, size_t max_pairs = 20);

}  // namespace polycube
