// Accumulates vertices and faces while a file is parsed, then fills a MeshData.
#pragma once
#include <array>
#include <vector>

#include "polycube/io/mesh_data.h"

namespace polycube::io {

struct Builder {
  std::vector<double> v;              // x y z per vertex
  std::vector<int> vline;
  std::vector<int> f;                 // triangles
  std::vector<int> fsrc, fline;
  std::vector<int> q, t, h;

  int num_vertices() const { return static_cast<int>(v.size() / 3); }
  void add_vertex(double x, double y, double z, int line) {
    v.insert(v.end(), {x, y, z});
    vline.push_back(line);
  }
  /// Adds a polygon (already validated 0-based indices), triangulated; `src` is its index in the file.
  void add_polygon(const std::vector<int>& poly, int src, int line);
  void add_triangle(int a, int b, int c, int src, int line) {
    f.insert(f.end(), {a, b, c});
    fsrc.push_back(src);
    fline.push_back(line);
  }
  void finish(MeshData& out) const;
};

/// Triangulates a planar-ish polygon given by 3D points (ear clipping in the plane of its Newell
/// normal; quads are split along the shorter diagonal). Returns index triples into `poly`.
std::vector<std::array<int, 3>> triangulate_polygon(const std::vector<Vec3>& pts);

}  // namespace polycube::io
