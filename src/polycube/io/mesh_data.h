// What a reader returns: the elements of a mesh file, with enough provenance to name the line or
// element of the file in an error message.
#pragma once
#include <string>
#include <vector>

#include "polycube/core/types.h"

namespace polycube {

struct MeshData {
  std::string path;    ///< file read ("" for meshes made in code)
  std::string format;  ///< "obj", "off", "stl-ascii", "stl-binary", "ply-ascii", ..., "medit", "vtk-ascii", "msh", "step"...
  MatX3d V;            ///< vertices, in file units
  MatX3i F;            ///< triangles; polygons of the file are triangulated (see face_source)
  MatX4i Q;            ///< quadrilaterals of volume formats (MEDIT, VTK, msh), kept as quads
  MatX4i T;            ///< tetrahedra
  MatX8i H;            ///< hexahedra
  /// Per row of F: index of the file's face (polygon, facet, cell) it came from, 0-based.
  std::vector<int> face_source;
  /// Per row of F: 1-based line of the file that defined it, 0 for binary files.
  std::vector<int> face_line;
  /// Per vertex: 1-based line of the file that defined it, 0 for binary files.
  std::vector<int> vertex_line;
  /// Per row of F: the painted region of its file face, "" for none: OBJ `g` (or `o`) names; the
  /// integer face property `region`, `group`, `label` or `segment` of PLY files. Empty when the
  /// file has none. Constraint files select regions by these names ("group": "name").
  std::vector<std::string> face_group;
  /// Vertices merged because they had identical coordinates (STL only).
  int welded_vertices = 0;

  bool is_volume() const { return T.rows() > 0 || H.rows() > 0; }

  /// "face 12 (line 40)" or "face 12" for error messages; i indexes F.
  std::string face_where(int i) const;
  /// "vertex 7 (line 9)" or "vertex 7".
  std::string vertex_where(int i) const;
};

/// Builds MeshData from arrays (face_source = row index, no lines).
MeshData make_mesh_data(const MatX3d& V, const MatX3i& F, const std::string& format = "memory");

}  // namespace polycube
