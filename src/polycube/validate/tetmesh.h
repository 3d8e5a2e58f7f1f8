// Checks of tetrahedral meshes: orientation, quality, boundary extraction.
#pragma once
#include <string>
#include <vector>

#include "polycube/core/types.h"
#include "polycube/io/mesh_data.h"

namespace polycube {

struct TetQuality {
  int tets = 0;
  int inverted = 0;       ///< signed volume < 0
  int zero_volume = 0;    ///< |6 vol| <= 1e-12 * (longest edge)^3
  double min_volume = 0;  ///< smallest signed volume
  double min_dihedral_deg = 0, max_dihedral_deg = 0;
  std::vector<int> bad;   ///< first offending tets (inverted or zero volume), at most 10
};

/// Signed volume of tet (a, b, c, d): det[b-a, c-a, d-a] / 6, positive for the convention in types.h.
double tet_volume(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d);

/// Orientation and dihedral-angle statistics of every tet.
TetQuality measure_tets(const MatX3d& V, const MatX4i& T);

/// Faces used by exactly one tet, oriented outward (for positively oriented tets). Throws
/// Error(InvalidMesh) if a face is shared by more than two tets.
MatX3i tet_boundary(const MatX4i& T, const std::string& name = "tet mesh");

struct TetInputReport {
  int unreferenced_removed = 0;
  int tets_reoriented = 0;  ///< all tets were negatively oriented and have been flipped
  std::vector<int> vertex_map;  ///< new index of every input vertex (-1: unreferenced, removed)
  /// The file's triangles are exactly the boundary faces: the boundary keeps their order.
  bool boundary_in_file_order = false;
};

/// Turns a tet-mesh input into a checked TetMesh: unreferenced vertices removed, a globally
/// negative orientation flipped; refuses non-finite coordinates, inverted or flat tets among
/// positive ones, faces shared by 3+ tets. The boundary is not validated here (see pipeline).
/// When the file's triangles (m.F) are exactly the boundary faces, the boundary follows their order
/// and, where a triangle faces outward, its vertex order: a tet mesh this tool wrote
/// (OUTDIR/tetmesh.mesh) then gives back the run's boundary, and with it the same results, and
/// labels come in the file's triangle order. Otherwise it is tet_boundary's order.
TetMesh prepare_tet_input(const MeshData& m, TetInputReport& rep);

}  // namespace polycube
