// Validation and repair of an input triangle surface.
//
// Refused (Error(InvalidMesh) naming the elements): NaN/inf coordinates, degenerate faces (repeated
// vertex or zero area), duplicate faces, non-manifold edges and vertices, open boundaries (the loops
// are listed; accepted with allow_open), non-orientable components. Repaired and reported: unreferenced vertices (removed),
// inconsistent orientation (faces flipped), components facing the wrong way (reversed so that every
// component bounds the solid with outward normals; cavities face into the cavity).
// Several components and any genus are allowed.
#pragma once
#include <vector>

#include "polycube/io/mesh_data.h"

namespace polycube {

struct ValidateOptions {
  /// Flip faces/components to a consistent outward orientation (otherwise such input is refused).
  bool repair_orientation = true;
  /// A face is degenerate when its area is below this fraction of its longest edge squared.
  double degenerate_area_rel = 1e-12;
  /// How many offending elements an error message lists.
  int max_listed = 10;
  /// Accept open boundaries (surface mode): the border loops are counted instead of refused, the
  /// majority orientation of an open component is kept (it has no inside), and the genus of a
  /// component with b border loops is (2 - chi - b) / 2.
  bool allow_open = false;
};

/// Connected components of a valid closed surface and how they nest.
struct SurfaceLayout {
  std::vector<int> component_of_face;  ///< per face
  std::vector<int> depth;              ///< per component: how many other components enclose it (odd = cavity)
  std::vector<int> parent;             ///< per component: innermost enclosing component, -1 if none
  std::vector<int> genus;              ///< per component
  std::vector<double> volume;          ///< per component: signed enclosed volume after repair (cavities < 0)
  int num_components() const { return static_cast<int>(depth.size()); }
};

struct SurfaceReport {
  int vertices = 0, triangles = 0, components = 0, genus = 0;
  bool closed = true;
  int border_loops = 0;           ///< open boundary loops (allow_open only; otherwise refused)
  int border_edges = 0;
  int unreferenced_removed = 0;   ///< vertices not used by any face
  int faces_flipped = 0;          ///< faces flipped to make orientation consistent
  int components_reversed = 0;    ///< components turned to face outward
  int welded_vertices = 0;        ///< coincident vertices merged by the reader (STL)
  bool repaired() const { return unreferenced_removed + faces_flipped + components_reversed > 0; }
};

/// Checks `m.V`/`m.F` and repairs what can be repaired in place (see the file comment).
/// Throws Error(InvalidMesh) for what cannot. `layout` receives the component structure.
SurfaceReport validate_surface(MeshData& m, SurfaceLayout& layout, const ValidateOptions& opt = {});

/// Generalized winding number of the closed oriented surface (V, F restricted to `faces`) at p.
double winding_number(const MatX3d& V, const MatX3i& F, const std::vector<int>& faces, const Vec3& p);

}  // namespace polycube
