// Mesh file writers. Coordinates are written with 17 significant digits so that a round trip is
// exact. Each throws Error(Output) naming the file when it cannot be written.
#pragma once
#include <map>
#include <string>
#include <vector>

#include "polycube/core/types.h"
#include "polycube/io/mesh_data.h"

namespace polycube::io {

/// Integer fields attached to the cells of a written mesh (e.g. chart labels), by name.
/// Each vector has one entry per cell, in the order the cells are written
/// (triangles, quads, tets, hexes).
using CellFields = std::map<std::string, std::vector<int>>;
/// 3-vector fields on the cells (same order); each is written as VECTORS and, with components in
/// absolute value, as COLOR_SCALARS "<name>_rgb" (e.g. normals shown as colours, like the paper's Fig. 8).
using CellVectors = std::map<std::string, MatX3d>;
/// Real-valued fields on the cells (same order), e.g. the scaled Jacobian of every hex.
using CellScalars = std::map<std::string, std::vector<double>>;

/// MEDIT ASCII .mesh (MeshVersionFormatted 2). Any of F, Q, T, H may be empty.
void write_medit(const std::string& path, const MeshData& m);
/// Legacy VTK unstructured grid, ASCII or BINARY (big-endian), version 4.2 layout that ParaView,
/// Gmsh and VTK >= 5 read. Cells are written as triangles, quads, tets, hexes in that order.
void write_vtk(const std::string& path, const MeshData& m, bool binary = false, const CellFields& fields = {},
               const CellVectors& vectors = {}, const CellScalars& scalars = {});
void write_obj(const std::string& path, const MatX3d& V, const MatX3i& F);
/// OBJ with quad faces ("f a b c d").
void write_obj_quads(const std::string& path, const MatX3d& V, const MatX4i& Q);
void write_off(const std::string& path, const MatX3d& V, const MatX3i& F);
void write_stl(const std::string& path, const MatX3d& V, const MatX3i& F, bool binary);
enum class PlyEncoding { Ascii, BinaryLittleEndian, BinaryBigEndian };
void write_ply(const std::string& path, const MatX3d& V, const MatX3i& F, PlyEncoding enc);
/// Gmsh .msh 4.1 through the Gmsh library.
void write_msh(const std::string& path, const MeshData& m);

}  // namespace polycube::io
