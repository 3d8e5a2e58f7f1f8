#include "polycube/core/topology.h"

#include <map>

#include <algorithm>
#include <array>

namespace polycube {

MatX3i face_adjacency(const MatX3i& F) {
  // Directed edges sorted by (from, to); the twin of (a, b) is (b, a).
  std::vector<std::array<int, 3>> he;  // from, to, face*3+k
  he.reserve(3 * F.rows());
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) he.push_back({F(f, k), F(f, (k + 1) % 3), 3 * f + k});
  std::sort(he.begin(), he.end());
  MatX3i N = MatX3i::Constant(F.rows(), 3, -1);
  for (const auto& h : he) {
    const std::array<int, 3> key{h[1], h[0], -1};
    auto it = std::lower_bound(he.begin(), he.end(), key);
    if (it != he.end() && (*it)[0] == h[1] && (*it)[1] == h[0]) N(h[2] / 3, h[2] % 3) = (*it)[2] / 3;
  }
  return N;
}

std::vector<std::pair<int, int>> unique_edges(
    const Eigen::Ref<const Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& E) {
  std::vector<std::pair<int, int>> e;
  const int n = static_cast<int>(E.cols());
  e.reserve(E.rows() * n * (n - 1) / 2);
  for (int r = 0; r < E.rows(); ++r)
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j < n; ++j) e.emplace_back(std::min(E(r, i), E(r, j)), std::max(E(r, i), E(r, j)));
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  return e;
}

bool has_unreferenced_vertices(Eigen::Index nv, const MatX3i& F) {
  std::vector<char> used(static_cast<size_t>(nv), 0);
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) used[F(f, k)] = 1;
  return std::find(used.begin(), used.end(), 0) != used.end();
}

const SurfaceMesh& surface_alone(const SurfaceMesh& s, SurfaceMesh& storage) {
  if (!has_unreferenced_vertices(s.V.rows(), s.F)) return s;
  storage = compact_surface(s.V, s.F);
  return storage;
}

SurfaceMesh compact_surface(const MatX3d& V, const MatX3i& F, std::vector<int>* kept) {
  std::vector<int> id(V.rows(), -1), back;
  SurfaceMesh s;
  s.F = F;
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      int& v = s.F(f, k);
      if (id[v] < 0) {
        id[v] = static_cast<int>(back.size());
        back.push_back(v);
      }
      v = id[v];
    }
  s.V.resize(static_cast<Eigen::Index>(back.size()), 3);
  for (size_t i = 0; i < back.size(); ++i) s.V.row(static_cast<Eigen::Index>(i)) = V.row(back[i]);
  if (kept) *kept = std::move(back);
  return s;
}

std::vector<std::vector<int>> vertex_neighbors(int nv, const std::vector<std::pair<int, int>>& edges) {
  std::vector<std::vector<int>> nb(nv);
  for (auto [a, b] : edges) {
    nb[a].push_back(b);
    nb[b].push_back(a);
  }
  for (auto& l : nb) std::sort(l.begin(), l.end());
  return nb;
}

std::vector<std::vector<std::array<int, 3>>> border_loops(const MatX3i& F) {
  std::map<std::pair<int, int>, int> half;
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) half[{F(f, k), F(f, (k + 1) % 3)}] = f;
  std::map<int, std::array<int, 3>> next;  // border edges by start vertex
  for (const auto& [e, f] : half)
    if (!half.count({e.second, e.first})) next[e.first] = {e.first, e.second, f};
  std::vector<std::vector<std::array<int, 3>>> loops;
  while (!next.empty()) {
    std::vector<std::array<int, 3>> loop;
    auto it = next.begin();
    while (it != next.end()) {
      loop.push_back(it->second);
      const int b = it->second[1];
      next.erase(it);
      it = next.find(b);
    }
    loops.push_back(std::move(loop));
  }
  return loops;
}

}  // namespace polycube
