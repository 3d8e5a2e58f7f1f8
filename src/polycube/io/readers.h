// Mesh file readers. Each returns the file's elements as a MeshData, or throws Error(Parse) naming
// the file and line (text formats) or element (binary formats) where it went wrong.
// Indices out of range are parse errors; geometric problems are left to validate/.
#pragma once
#include <string>

#include "polycube/core/log.h"
#include "polycube/io/mesh_data.h"

namespace polycube::io {

MeshData read_obj(const std::string& path);
MeshData read_off(const std::string& path);
MeshData read_stl(const std::string& path);    ///< ASCII or binary, decided by content; exact duplicates welded
MeshData read_ply(const std::string& path);    ///< ascii, binary_little_endian, binary_big_endian
MeshData read_medit(const std::string& path);  ///< ASCII .mesh
MeshData read_vtk(const std::string& path);    ///< legacy .vtk, ASCII or BINARY, UNSTRUCTURED_GRID or POLYDATA
MeshData read_msh(const std::string& path);    ///< Gmsh .msh (any version Gmsh reads), through the Gmsh library

/// Options for CAD import (STEP, IGES, BREP).
struct CadOptions {
  /// Target surface edge length relative to the bounding-box diagonal.
  double mesh_size = 0.02;
};
/// Imports a CAD file with Gmsh's OpenCASCADE kernel and meshes its surfaces with triangles.
MeshData read_cad(const std::string& path, const CadOptions& opt = {});

/// Lower-case file extension without the dot ("obj", "mesh", "step"...).
std::string extension(const std::string& path);
/// True if read_mesh knows the extension.
bool is_supported(const std::string& path);
/// Reads any supported format, chosen by extension.
/// keep_quads: quadrilaterals of a quad-only surface in a volume format (MEDIT, VTK, msh) stay in
/// Q (by default they are triangulated into F, as the pipeline wants a triangle surface).
MeshData read_mesh(const std::string& path, const CadOptions& cad = {}, bool keep_quads = false);

}  // namespace polycube::io
