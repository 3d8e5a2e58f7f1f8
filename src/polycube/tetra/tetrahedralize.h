// Tetrahedralization of a validated closed surface with Gmsh's library (in process).
//
// By default the input triangles are the boundary of the tet mesh, unchanged: the first
// #surface-vertices vertices of the result are the surface vertices in input order, and its
// boundary is exactly the input triangles. Optionally the surface is first remeshed to a target
// edge length. Sizes are relative to the bounding-box diagonal of the input.
#pragma once
#include <string>

#include "polycube/core/log.h"
#include "polycube/core/types.h"
#include "polycube/validate/surface.h"
#include "polycube/validate/tetmesh.h"

namespace polycube {

struct TetOptions {
  /// > 0: remesh the surface first, to this target edge length (fraction of the bbox diagonal).
  /// 0: keep the input triangles as the boundary.
  double edge_length = 0;
  /// > 0: largest tet edge inside the volume (fraction of the bbox diagonal). 0: sizes grow from
  /// the boundary (Gmsh's default), or follow target_tets.
  double max_size = 0;
  /// > 0: aim for about this many tets (sets the interior size, and the surface size when
  /// remeshing without edge_length), counted after split_boundary_tets (3 more per tet with four
  /// boundary vertices), so that the mesh the deformation gets has this count. Gmsh runs again (4
  /// runs at most) until the count is within 5%; the closest is kept. The kept input surface puts
  /// a floor under the count.
  int target_tets = 0;
  /// "delaunay" (Gmsh's default 3D Delaunay) or "hxt" (Gmsh's parallel Delaunay, faster on large
  /// meshes; if its result fails the checks, the mesh is made again with "delaunay").
  std::string algorithm = "delaunay";
  /// Run Gmsh's tet optimization (improves dihedral angles, keeps the boundary).
  bool optimize = true;
  /// > 0: before tetrahedralizing, remove the spikes of the surface lower than this (fraction of
  /// the bbox diagonal): see remove_spikes. 0: keep them.
  double spike_height = 0;
};

struct TetStats {
  bool remeshed = false;
  int surface_vertices = 0;       ///< vertices on the boundary of the result
  int surface_triangles = 0;
  TetQuality quality;
  int attempts = 0;               ///< Gmsh runs (target_tets may need up to four)
  std::string algorithm;          ///< algorithm of the accepted mesh (HXT falls back to Delaunay)
};

/// Tetrahedralizes the closed, outward-oriented surface `s` whose component structure is `layout`
/// (from validate_surface). Throws Error(Tetrahedralization) if Gmsh fails (naming intersecting
/// faces when it is a self-intersection) or if the result has inverted tets or a boundary that
/// differs from the surface.
TetMesh tetrahedralize(const SurfaceMesh& s, const SurfaceLayout& layout, const TetOptions& opt,
                       const Hooks& hooks, TetStats* stats = nullptr);

/// Remeshes each component of a surface with Gmsh (feature-preserving classification, then
/// 2D meshing at `edge_length_abs`). The result still needs validate_surface.
SurfaceMesh remesh_surface(const SurfaceMesh& s, const SurfaceLayout& layout, double edge_length_abs);

/// Removes the spikes of a closed surface: vertices with exactly three neighbours whose distance to
/// the plane of those neighbours is under max_height_abs. Their three triangles become the one
/// triangle of the neighbours (oriented as they were); repeated while one is found (a removal can
/// leave a neighbour with three). Such a vertex and its three triangles bound a single tet; when the
/// l1 deformation flattens the spike into its base that tet (and the four it is split into) is
/// crushed, and the polycube cannot be realized (homer: a spike 6.4e-4 of the diagonal high).
/// A removal that would duplicate an existing triangle is skipped. The vertices left without a
/// triangle are dropped, the others keep their order; returns the number of spikes removed.
int remove_spikes(SurfaceMesh& s, double max_height_abs);

/// Splits every tet whose four vertices all lie on the boundary by inserting its centroid (four
/// new tets). Such tets must flatten wherever the boundary around them becomes planar, which would
/// block the polycube deformation. The boundary is unchanged; new vertices are appended.
/// Returns the number of tets split.
int split_boundary_tets(TetMesh& tm);

/// Splits the given edges (a < b, sorted, unique) of the tets T over nv vertices at new vertices
/// nv, nv+1, ...: every tet holding an edge becomes two (same orientation). Edges sharing a tet are
/// split in successive rounds. Returns, per new vertex, the edge it splits (callers place it, e.g.
/// at the midpoint, in any configuration).
std::vector<std::pair<int, int>> split_tet_edges(MatX4i& T, int nv, std::vector<std::pair<int, int>> edges);


/// Checks a tet mesh against the surface it was built from: no inverted or zero-volume tet,
/// and when `surface` is given, a boundary equal to it (same oriented triangles on the first
/// surface.V.rows() vertices). Throws Error(Tetrahedralization) naming the problem.
void check_tet_mesh(const TetMesh& tm, const SurfaceMesh* surface, const std::string& name);

}  // namespace polycube
