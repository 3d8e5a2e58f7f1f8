#include "polycube/hex/snap.h"

#include <Eigen/Sparse>
#include <algorithm>
#include <cmath>
#include <set>

#include "polycube/chart/realize.h"
#include "polycube/core/error.h"
#include "polycube/core/topology.h"

namespace polycube::hex {

std::vector<int> snap_heights(const std::vector<double>& h, double s) {
  std::vector<std::vector<int>> above(h.size());
  for (size_t i = 0; i + 1 < h.size(); ++i) above[i].push_back(static_cast<int>(i + 1));
  return snap_heights(h, s, above);
}

std::vector<int> snap_heights(const std::vector<double>& h, double s, const std::vector<std::vector<int>>& above) {
  std::vector<int> n(h.size(), 0), floor(h.size(), 0);
  for (size_t i = 0; i < h.size(); ++i) {
    n[i] = std::max(floor[i], static_cast<int>(std::lround((h[i] - h[0]) * s)));
    for (int j : above[i]) {
      POLYCUBE_ASSERT(j > static_cast<int>(i), "order constraints must go upwards");
      floor[j] = std::max(floor[j], n[i] + 1);
    }
  }
  return n;
}

namespace {

// Order constraints of the planes of axis k: lines along k through points of every chart face of
// axis k; consecutive planes met on a line face each other.
// Also counts the lines that meet two faces of the same orientation in a row (two bottoms with no
// top between, both hit well inside): the polycube overlaps itself there.
std::vector<std::vector<int>> facing_planes(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels,
                                            const std::vector<int>& tri_plane, const std::vector<int>& tris, int k,
                                            int nplanes, int& overlap_lines) {
  const int u = (k + 1) % 3, w = (k + 2) % 3;
  Eigen::AlignedBox2d box;
  for (int f : tris)
    for (int j = 0; j < 3; ++j) box.extend(Eigen::Vector2d(X(B(f, j), u), X(B(f, j), w)));
  const int g = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(tris.size()))));
  const Eigen::Vector2d ext = (box.max() - box.min()).cwiseMax(1e-300);
  auto cell = [&](double x, int d) {
    return std::clamp(static_cast<int>((x - box.min()[d]) / ext[d] * g), 0, g - 1);
  };
  std::vector<std::vector<int>> bucket(static_cast<size_t>(g) * g);
  for (int f : tris) {
    Eigen::AlignedBox2d b;
    for (int j = 0; j < 3; ++j) b.extend(Eigen::Vector2d(X(B(f, j), u), X(B(f, j), w)));
    for (int a = cell(b.min()[0], 0); a <= cell(b.max()[0], 0); ++a)
      for (int c = cell(b.min()[1], 1); c <= cell(b.max()[1], 1); ++c) bucket[a * g + c].push_back(f);
  }
  std::vector<std::set<int>> above(nplanes);
  struct Hit {
    double height;
    int plane;
    int label;
    double depth;  // min barycentric coordinate: > 0 strictly inside the triangle
    bool operator<(const Hit& o) const { return height < o.height || (height == o.height && plane < o.plane); }
  };
  std::vector<Hit> hits;
  auto shoot = [&](double pu, double pw) {
    hits.clear();
    for (int f : bucket[cell(pu, 0) * g + cell(pw, 1)]) {
      const double ax = X(B(f, 0), u), ay = X(B(f, 0), w), bx = X(B(f, 1), u), by = X(B(f, 1), w),
                   cx = X(B(f, 2), u), cy = X(B(f, 2), w);
      const double d = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
      if (d == 0) continue;
      const double l1 = ((pu - ax) * (cy - ay) - (cx - ax) * (pw - ay)) / d;
      const double l2 = ((bx - ax) * (pw - ay) - (pu - ax) * (by - ay)) / d;
      if (l1 < -1e-9 || l2 < -1e-9 || l1 + l2 > 1 + 1e-9) continue;
      hits.push_back({X(B(f, 0), k), tri_plane[f], labels[f], std::min({l1, l2, 1 - l1 - l2})});
    }
    std::sort(hits.begin(), hits.end());
    bool overlap = false;
    for (size_t i = 0; i + 1 < hits.size(); ++i) {
      if (hits[i].plane == hits[i + 1].plane) continue;
      above[hits[i].plane].insert(hits[i + 1].plane);
      overlap = overlap || (hits[i].label == hits[i + 1].label && hits[i].depth > 1e-6 && hits[i + 1].depth > 1e-6);
    }
    overlap_lines += overlap;
  };
  for (int f : tris) {
    Eigen::Vector2d c(0, 0);
    for (int j = 0; j < 3; ++j) c += Eigen::Vector2d(X(B(f, j), u), X(B(f, j), w)) / 3;
    shoot(c[0], c[1]);
    for (int j = 0; j < 3; ++j) {
      const Eigen::Vector2d p = c + 0.9 * (Eigen::Vector2d(X(B(f, j), u), X(B(f, j), w)) - c);
      shoot(p[0], p[1]);
    }
  }
  std::vector<std::vector<int>> out(nplanes);
  for (int i = 0; i < nplanes; ++i) out[i].assign(above[i].begin(), above[i].end());
  return out;
}

// The triangles of axis k, the distinct heights of their planes (increasing) and each one's plane.
void axis_planes(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels, int k, double diag,
                 std::vector<int>& tris, std::vector<double>& h, std::vector<int>& tri_plane) {
  std::vector<double> hk;
  for (int f = 0; f < B.rows(); ++f)
    if (labels[f] / 2 == k) {
      tris.push_back(f);
      for (int j = 0; j < 3; ++j) hk.push_back(X(B(f, j), k));
    }
  std::sort(hk.begin(), hk.end());
  const double tol = 1e-12 * std::max(diag, 1e-300);
  h.clear();
  for (double x : hk)
    if (h.empty() || x - h.back() > tol) h.push_back(x);
  if (h.size() < 2) throw Error(ErrorKind::Polycube, "the polycube has fewer than two planes along an axis");
  tri_plane.assign(B.rows(), -1);
  for (int f : tris)
    tri_plane[f] = static_cast<int>(std::lower_bound(h.begin(), h.end(), X(B(f, 0), k) - tol) - h.begin());
}

double bbox_diagonal(const MatX3d& X) {
  Eigen::AlignedBox3d box;
  for (int v = 0; v < X.rows(); ++v) box.extend(X.row(v).transpose());
  return box.diagonal().norm();
}

}  // namespace

std::vector<int> thin_step_groups(const std::vector<double>& h, double s, double merge_below,
                                  const std::vector<std::vector<int>>& facing, std::vector<double>& group_heights) {
  const int np = static_cast<int>(h.size());
  std::vector<int> group(np);
  group_heights.clear();
  for (int p = 0; p < np;) {
    int q = p + 1;
    for (; merge_below > 0 && q < np && s * (h[q] - h[p]) < merge_below; ++q) {
      bool faces = false;
      for (int m = p; m < q && !faces; ++m) faces = std::find(facing[m].begin(), facing[m].end(), q) != facing[m].end();
      if (faces) break;
    }
    double mean = 0;
    for (int m = p; m < q; ++m) group[m] = static_cast<int>(group_heights.size()), mean += h[m] / (q - p);
    group_heights.push_back(mean);
    p = q;
  }
  return group;
}

std::vector<std::vector<int>> facing_planes(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels, int k,
                                            const std::vector<double>& h, double tol) {
  std::vector<int> tris, tri_plane(B.rows(), -1);
  for (int f = 0; f < B.rows(); ++f)
    if (labels[f] / 2 == k) {
      tris.push_back(f);
      tri_plane[f] = static_cast<int>(std::lower_bound(h.begin(), h.end(), X(B(f, 0), k) - tol) - h.begin());
    }
  int overlaps = 0;
  return facing_planes(X, B, labels, tri_plane, tris, k, static_cast<int>(h.size()), overlaps);
}

std::array<int, 3> overlap_lines(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels) {
  std::array<int, 3> o{};
  const double diag = bbox_diagonal(X);
  for (int k = 0; k < 3; ++k) {
    std::vector<int> tris, tri_plane;
    std::vector<double> h;
    axis_planes(X, B, labels, k, diag, tris, h, tri_plane);
    facing_planes(X, B, labels, tri_plane, tris, k, static_cast<int>(h.size()), o[k]);
  }
  return o;
}

Snapping snap_polycube(const MatX3d& X, const MatX4i& T, const MatX3i& B, const std::vector<int>& labels,
                       double s, bool constrained, double merge_below) {
  Snapping sn;
  const int nv = static_cast<int>(X.rows());
  const double diag = bbox_diagonal(X);
  // P1 Laplacian (stiffness matrix) of the polycube tet mesh.
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(16 * T.rows());
  for (int t = 0; t < T.rows(); ++t) {
    Eigen::Matrix3d M;
    for (int j = 0; j < 3; ++j) M.col(j) = (X.row(T(t, j + 1)) - X.row(T(t, 0))).transpose();
    const double vol = M.determinant() / 6;
    const Eigen::Matrix3d Mi = M.inverse();
    Eigen::Matrix<double, 4, 3> G;
    G.row(1) = Mi.row(0);
    G.row(2) = Mi.row(1);
    G.row(3) = Mi.row(2);
    G.row(0) = -(G.row(1) + G.row(2) + G.row(3));
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) trip.emplace_back(T(t, a), T(t, b), vol * G.row(a).dot(G.row(b)));
  }
  Eigen::SparseMatrix<double> K(nv, nv);
  K.setFromTriplets(trip.begin(), trip.end());
  // Vertices of no tet (merged into a neighbour by an edge collapse) have no Laplacian row: they
  // keep a zero displacement.
  std::vector<char> in_tet(nv, 0);
  for (int t = 0; t < T.rows(); ++t)
    for (int j = 0; j < 4; ++j) in_tet[T(t, j)] = 1;

  // Charts: edge-connected triangles of one label.
  std::vector<int> chart(B.rows());
  {
    const MatX3i adj = face_adjacency(B);
    UnionFind uf(static_cast<int>(B.rows()));
    for (int f = 0; f < B.rows(); ++f)
      for (int j = 0; j < 3; ++j)
        if (adj(f, j) >= 0 && labels[adj(f, j)] == labels[f]) uf.unite(f, adj(f, j));
    for (int f = 0; f < B.rows(); ++f) chart[f] = uf.find(f);
  }

  sn.Y.resize(nv, 3);
  std::array<std::vector<int>, 3> vplanes;  // per axis, the plane of every vertex (-1: none)
  for (int k = 0; k < 3; ++k) {
    // Planes of axis k and the plane of each of its vertices.
    std::vector<int> tris, tri_plane;
    std::vector<double>& h = sn.heights[k];
    axis_planes(X, B, labels, k, diag, tris, h, tri_plane);
    std::vector<int>& vplane = vplanes[k];
    vplane.assign(nv, -1);
    for (int f : tris)
      for (int j = 0; j < 3; ++j) vplane[B(f, j)] = tri_plane[f];
    const int np = static_cast<int>(h.size());
    if (constrained) {
      const std::vector<std::vector<int>> facing = facing_planes(X, B, labels, tri_plane, tris, k, np, sn.overlap_lines[k]);
      // The planes of axis k bounding one chart of another axis keep their order and a cell
      // between them, or that chart (a step, a side face) would lose its height.
      std::vector<std::vector<int>> above = facing;
      std::vector<std::pair<int, int>> cp;  // (chart, plane)
      for (int f = 0; f < B.rows(); ++f)
        if (labels[f] / 2 != k)
          for (int j = 0; j < 3; ++j)
            if (vplane[B(f, j)] >= 0) cp.push_back({chart[f], vplane[B(f, j)]});
      std::sort(cp.begin(), cp.end());
      cp.erase(std::unique(cp.begin(), cp.end()), cp.end());
      for (size_t i = 0; i + 1 < cp.size(); ++i)
        if (cp[i].first == cp[i + 1].first) above[cp[i].second].push_back(cp[i + 1].second);
      std::vector<double> hg;
      const std::vector<int> group = thin_step_groups(h, s, merge_below, facing, hg);
      sn.merged[k] += np - static_cast<int>(hg.size());
      std::vector<std::vector<int>> above_g(hg.size());
      for (int i = 0; i < np; ++i)
        for (int j : above[i])
          if (group[j] != group[i]) above_g[group[i]].push_back(group[j]);
      const std::vector<int> ng = snap_heights(hg, s, above_g);
      sn.snapped[k].resize(np);
      for (int i = 0; i < np; ++i) sn.snapped[k][i] = ng[group[i]];
    } else {
      sn.snapped[k] = snap_heights(h, s);
    }
    const std::vector<int>& n = sn.snapped[k];
    for (int i = 0; i < np; ++i)
      if ((i > 0 && n[i] == n[i - 1]) || (i + 1 < np && n[i] == n[i + 1])) ++sn.shared[k];
    for (int i = 0; i + 1 < np; ++i)
      if (n[i + 1] != n[i]) sn.min_slab_ratio = std::min(sn.min_slab_ratio, s * (h[i + 1] - h[i]) / std::abs(n[i + 1] - n[i]));
    // Displacement d (grid units) of Y_k = s (X_k - h_0) + d: fixed on plane vertices, harmonic elsewhere.
    Eigen::VectorXd d = Eigen::VectorXd::Zero(nv);
    std::vector<int> free_id(nv, -1);
    int nf = 0;
    for (int v = 0; v < nv; ++v) {
      if (vplane[v] >= 0) d[v] = n[vplane[v]] - s * (h[vplane[v]] - h[0]);
      else if (in_tet[v]) free_id[v] = nf++;
    }
    if (nf > 0 && d.cwiseAbs().maxCoeff() > 0) {
      std::vector<Eigen::Triplet<double>> ff;
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(nf);
      for (int c = 0; c < K.outerSize(); ++c)
        for (Eigen::SparseMatrix<double>::InnerIterator it(K, c); it; ++it) {
          const int i = static_cast<int>(it.row()), j = static_cast<int>(it.col());
          if (free_id[i] < 0) continue;
          if (free_id[j] >= 0) ff.emplace_back(free_id[i], free_id[j], it.value());
          else rhs[free_id[i]] -= it.value() * d[j];
        }
      Eigen::SparseMatrix<double> Kff(nf, nf);
      Kff.setFromTriplets(ff.begin(), ff.end());
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(Kff);
      if (solver.info() != Eigen::Success)
        throw Error(ErrorKind::Polycube, "snapping: the Laplacian of the polycube could not be factorized");
      const Eigen::VectorXd x = solver.solve(rhs);
      for (int v = 0; v < nv; ++v)
        if (free_id[v] >= 0) d[v] = x[free_id[v]];
    }
    for (int v = 0; v < nv; ++v) sn.Y(v, k) = vplane[v] >= 0 ? n[vplane[v]] : s * (X(v, k) - h[0]) + d[v];
  }
  auto count_inverted = [&] {
    sn.inverted = 0;
    sn.inverted_volume = 0;
    for (int t = 0; t < T.rows(); ++t) {
      const Vec3 a = sn.Y.row(T(t, 0)), b = sn.Y.row(T(t, 1)), c = sn.Y.row(T(t, 2)), e = sn.Y.row(T(t, 3));
      const double vol = (b - a).dot((c - a).cross(e - a)) / 6;
      if (!(vol > 0)) {
        ++sn.inverted;
        sn.inverted_volume -= vol;
      }
    }
  };
  count_inverted();
  if (sn.inverted > 0) {
    // The harmonic displacement turned a few tets over (where planes had to move much farther apart
    // than the tets between them are thick, e.g. a thin step kept a cell thick): untangle them locally, each plane's coordinate kept at its integer, the polycube in grid units
    // the reference shape.
    std::array<std::vector<char>, 3> fixed;
    for (int k = 0; k < 3; ++k) {
      fixed[k].assign(nv, 0);
      for (int v = 0; v < nv; ++v) fixed[k][v] = vplanes[k][v] >= 0 || !in_tet[v];
    }
    const MatX3d ref = s * X;
    int left = 0;
    sn.untangle_sweeps = chart::untangle_tets_locally(ref, T, fixed, sn.Y, left);
    sn.untangled = sn.inverted - left;
    count_inverted();
  }
  return sn;
}

}  // namespace polycube::hex
