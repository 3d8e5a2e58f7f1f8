// Connectivity helpers over the plain arrays of types.h.
#pragma once
#include <array>
#include <numeric>
#include <utility>
#include <vector>

#include "polycube/core/types.h"

namespace polycube {

/// Disjoint sets over 0..n-1 (path halving).
struct UnionFind {
  std::vector<int> p;
  explicit UnionFind(size_t n) : p(n) { std::iota(p.begin(), p.end(), 0); }
  int find(int x) {
    while (p[x] != x) x = p[x] = p[p[x]];
    return x;
  }
  void unite(int a, int b) { p[find(a)] = find(b); }
};

/// Triangle adjacency of an oriented triangle mesh: N(f, k) is the triangle across edge
/// (F(f,k), F(f,(k+1)%3)), found as the triangle holding the reversed edge; -1 on open edges.
MatX3i face_adjacency(const MatX3i& F);

/// Border loops of an oriented triangle mesh (edges without a reversed twin), each as its edges
/// (a, b, face) in order, b of one edge = a of the next; empty for a closed mesh.
std::vector<std::vector<std::array<int, 3>>> border_loops(const MatX3i& F);

/// Unique undirected edges (a < b), sorted, of triangles or tets (`cols` = 3 or 4 vertices per row).
std::vector<std::pair<int, int>> unique_edges(const Eigen::Ref<const Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic,
                                                                                    Eigen::RowMajor>>& E);

/// The triangles F alone, with only their vertices, numbered in order of first use; `kept`
/// (if given) receives the original index of every kept vertex.
SurfaceMesh compact_surface(const MatX3d& V, const MatX3i& F, std::vector<int>* kept = nullptr);

/// Whether some vertex 0..nv-1 is used by no triangle of F.
bool has_unreferenced_vertices(Eigen::Index nv, const MatX3i& F);

/// `s` itself if every vertex is used by a triangle, else its triangles alone (compact_surface)
/// kept in `storage`: for code that takes a surface's vertices for points of it (a tet mesh's V
/// passed with its boundary would add the interior).
const SurfaceMesh& surface_alone(const SurfaceMesh& s, SurfaceMesh& storage);

/// Sorted neighbour lists of every vertex (0..nv) along the given undirected edges.
std::vector<std::vector<int>> vertex_neighbors(int nv, const std::vector<std::pair<int, int>>& edges);

}  // namespace polycube
