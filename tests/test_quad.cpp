// Quad stage: the quad scaled Jacobian on known quads and the quad mesh of a box.
#include <map>

#include "polycube/chart/labeling.h"
#include "polycube/core/topology.h"
#include "polycube/examples/examples.h"
#include "polycube/geometry/feature_capture.h"
#include "polycube/geometry/features.h"
#include "polycube/geometry/surface_fit.h"
#include "polycube/hex/extract.h"
#include "polycube/quad/quad.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {
// The grid of a box taken as its own polycube, 4 cells per unit, no pillow, no smoothing.
hex::HexResult grid_of_box(const SurfaceMesh& s) {
  const TetMesh tm = tet_mesh_of(s.V, s.F);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  hex::HexOptions o;
  o.cells_per_unit = 4;
  o.pillow = "off";
  o.smooth_iterations = 0;
  return hex::hex_mesh_from_polycube(tm.V, tm.T, tm.V, tm.boundary, labels, &s, o);
}

// The surface z = height(x, y) over the unit square, n x n cells, each split along its
// anti-diagonal (so that the line x + y = 1 is made of edges).
template <class Height>
SurfaceMesh height_field(int n, Height height) {
  SurfaceMesh s;
  s.V.resize((n + 1) * (n + 1), 3);
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j) {
      const double x = double(i) / n, y = double(j) / n;
      s.V.row(i * (n + 1) + j) << x, y, height(x, y);
    }
  s.F.resize(2 * n * n, 3);
  for (int i = 0, f = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const int a = i * (n + 1) + j, b = a + n + 1;
      s.F.row(f++) << a, b, a + 1;
      s.F.row(f++) << b, b + 1, a + 1;
    }
  return s;
}

// The vertex of V at p (-1 if none).
int vertex_at(const MatX3d& V, const Eigen::RowVector3d& p) {
  for (int v = 0; v < V.rows(); ++v)
    if ((V.row(v) - p).norm() < 1e-9) return v;
  return -1;
}
}  // namespace

TEST(Quad, ScaledJacobianKnownValues) {
  std::array<Vec3, 4> sq = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
  EXPECT_NEAR(quad::scaled_jacobian(sq), 1.0, 1e-15);
  std::array<Vec3, 4> rect = {Vec3(0, 0, 0), Vec3(5, 0, 0), Vec3(5, 0, 2), Vec3(0, 0, 2)};
  EXPECT_NEAR(quad::scaled_jacobian(rect), 1.0, 1e-15);
  // Rhombus of angle theta: sin(theta) at every corner.
  for (double th : {M_PI / 3, M_PI / 6, 0.1}) {
    const Vec3 a(1, 0, 0), b(std::cos(th), std::sin(th), 0);
    std::array<Vec3, 4> r = {Vec3::Zero(), a, a + b, b};
    EXPECT_NEAR(quad::scaled_jacobian(r), std::sin(th), 1e-14) << th;
  }
  // Bow-tie (vertices 2 and 3 swapped): folded. Zero-length edge: 0. Reversed order: still 1
  // (the measure uses the quad's own normal).
  std::array<Vec3, 4> bow = {sq[0], sq[1], sq[3], sq[2]};
  EXPECT_LE(quad::scaled_jacobian(bow), 0.0);
  std::array<Vec3, 4> deg = {sq[0], sq[0], sq[2], sq[3]};
  EXPECT_EQ(quad::scaled_jacobian(deg), 0.0);
  // A non-convex (dart) quad: negative at the reflex corner.
  std::array<Vec3, 4> dart = {Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0.5, 0.5, 0), Vec3(0, 2, 0)};
  EXPECT_LT(quad::scaled_jacobian(dart), 0.0);
}

TEST(Quad, EdgeRatioSeesSliversTheScaledJacobianDoesNot) {
  // Verdict's edge ratio: longest over shortest edge. A 1 x 0.005 rectangle has scaled Jacobian 1
  // and edge ratio 200; a quad with a zero-length edge, 1e30. Hexes likewise over their 12 edges.
  MatX3d V(9, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 0.005, 0, 0, 0.005, 0,  // sliver
      0, 1, 0, 1, 1, 0, 1, 2, 0, 0, 2, 0,            // unit square (with 4: a zero edge below)
      0, 1, 0;
  MatX4i Q(3, 4);
  Q << 0, 1, 2, 3, 4, 5, 6, 7, 4, 8, 6, 7;
  const quad::QuadQuality q = quad::quad_quality(V, Q);
  EXPECT_NEAR(q.per_element[0], 1.0, 1e-12);
  EXPECT_NEAR(q.edge_ratio_max, 1e30, 1);
  EXPECT_EQ(q.edge_ratio_above_10, 2);
  EXPECT_EQ(q.edge_ratio_above_100, 2);
  EXPECT_NEAR(q.edge_ratio_mean, (200.0 + 1.0) / 2, 1e-9);  // the zero-edge quad left out
  const double lengths[4] = {1, 0.005, 1, 0.005};
  EXPECT_NEAR(hex::edge_ratio(lengths, 4), 200, 1e-9);
  // A 1 x 1 x 0.001 box: scaled Jacobian 1, edge ratio 1000.
  MatX3d HV(8, 3);
  HV << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 0.001, 1, 0, 0.001, 1, 1, 0.001, 0, 1, 0.001;
  MatX8i H(1, 8);
  H << 0, 1, 2, 3, 4, 5, 6, 7;
  const hex::HexQuality h = hex::hex_quality(HV, H);
  EXPECT_NEAR(h.sj_min, 1.0, 1e-12);
  EXPECT_NEAR(h.edge_ratio_max, 1000, 1e-6);
  EXPECT_EQ(h.edge_ratio_above_100, 1);
}

TEST(Quad, BoxGivesARegularQuadMeshWithEightIrregularVertices) {
  // 1 x 2 x 3 box at 4 cells per unit: 2 (4*8 + 8*12 + 4*12) = 352 squares, every scaled Jacobian
  // 1, valence 3 only at the 8 corners, closed, facing outward.
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  const hex::HexResult h = grid_of_box(s);
  const quad::QuadResult q = quad::quad_mesh_from_hexes(h.V, h.H, s);
  ASSERT_EQ(q.Q.rows(), 352);
  EXPECT_EQ(q.V.rows(), 352 + 2);  // Euler: V - E + F = 2 with E = 2F
  EXPECT_EQ(q.irregular_vertices, 8);
  EXPECT_NEAR(q.quality.sj_min, 1.0, 1e-9);
  EXPECT_EQ(q.quality.inverted, 0);
  std::map<std::pair<int, int>, int> edges;
  const Vec3 centre(0.5, 1, 1.5);
  for (int f = 0; f < q.Q.rows(); ++f) {
    Vec3 c = Vec3::Zero();
    for (int j = 0; j < 4; ++j) {
      c += q.V.row(q.Q(f, j)).transpose() / 4;
      ++edges[{q.Q(f, j), q.Q(f, (j + 1) % 4)}];
    }
    const Vec3 a = q.V.row(q.Q(f, 0)), b = q.V.row(q.Q(f, 1)), d = q.V.row(q.Q(f, 3));
    EXPECT_GT((b - a).cross(d - a).dot(c - centre), 0) << f;
  }
  for (const auto& [e, n] : edges) EXPECT_EQ(edges.count({e.second, e.first}), 1u);  // each edge once each way
}

TEST(Quad, FoldedQuadOnAFeatureIsUntangled) {
  // The box's grid with one vertex of a box edge slid along that edge past its neighbour: the
  // quads on both sides fold. Feature vertices normally stay put; those of folded quads move, and
  // the smoothing unfolds them.
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  hex::HexResult h = grid_of_box(s);
  const int moved = vertex_at(h.V, Eigen::RowVector3d(0, 0, 1.5));
  ASSERT_GE(moved, 0);
  h.V(moved, 2) = 1.5 + 0.4;  // beyond its neighbour at z = 1.75, still on the edge x = y = 0
  quad::QuadOptions none;
  none.smooth_iterations = 0;
  const quad::QuadResult before = quad::quad_mesh_from_hexes(h.V, h.H, s, none);
  EXPECT_GT(before.quality.inverted, 0);
  const quad::QuadResult q = quad::quad_mesh_from_hexes(h.V, h.H, s);
  EXPECT_EQ(q.quality.inverted, 0);
  EXPECT_GT(q.quality.sj_min, 0.5);
}

TEST(Quad, SharpChainsOfABoxAreItsTwelveEdges) {
  const SurfaceMesh s = grid_box(3);
  const std::vector<std::vector<int>> chains = geometry::sharp_chains(s, geometry::sharp_edges(s, 30));
  ASSERT_EQ(chains.size(), 12u);
  for (const std::vector<int>& c : chains) {
    ASSERT_EQ(c.size(), 4u);  // 3 segments from corner to corner
    const Vec3 d = (s.V.row(c.back()) - s.V.row(c.front())).transpose();
    EXPECT_NEAR(d.norm(), 1.0, 1e-12);
    EXPECT_NEAR(d.cwiseAbs().maxCoeff(), 1.0, 1e-12);  // along one axis
  }
}

// A prism of height 1 over the convex pentagon (0,0) (1,0) (2,0.4) (2,1) (0,1): its top outline
// turns by atan(0.4) = 21.8 degrees at (1,0), where the two side faces meet at that angle (not a
// sharp edge), so one chain of sharp edges runs (0,0,1) -> (1,0,1) -> (2,0.4,1) through the bend.
TEST(Quad, ChainPositionsFollowASharpEdgeThroughABend) {
  const double P[5][2] = {{0, 0}, {1, 0}, {2, 0.4}, {2, 1}, {0, 1}};
  SurfaceMesh s;
  s.V.resize(10, 3);
  for (int i = 0; i < 5; ++i) {
    s.V.row(i) << P[i][0], P[i][1], 0;
    s.V.row(5 + i) << P[i][0], P[i][1], 1;
  }
  std::vector<Eigen::RowVector3i> f;
  for (int i = 1; i + 1 < 5; ++i) {
    f.emplace_back(0, i + 1, i);          // bottom, facing -z
    f.emplace_back(5, 5 + i, 5 + i + 1);  // top, facing +z
  }
  for (int i = 0; i < 5; ++i) {  // sides, counter-clockwise outline: outward
    const int a = i, b = (i + 1) % 5;
    f.emplace_back(a, b, 5 + b);
    f.emplace_back(a, 5 + b, 5 + a);
  }
  s.F.resize(static_cast<Eigen::Index>(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) s.F.row(static_cast<Eigen::Index>(i)) = f[i];
  const std::vector<unsigned char> sharp = geometry::sharp_edges(s, 30);
  const geometry::TriangleTree tree(s.V, s.F);
  const MatX3i adj = face_adjacency(s.F);
  const geometry::SharpChainPositions chains(s, sharp);
  geometry::SharpChainPositions::Position a, b, c, far;
  ASSERT_TRUE(chains.locate(tree, adj, Vec3(0.5, 0, 1), 1e-6, a));
  ASSERT_TRUE(chains.locate(tree, adj, Vec3(1.5, 0.2, 1), 1e-6, b));
  // Along the chain: 0.5 to the bend, then half of the edge of length sqrt(1.16).
  EXPECT_NEAR(chains.distance(a, b), 0.5 + 0.5 * std::sqrt(1.16), 1e-12);
  EXPECT_NEAR(chains.distance(b, a), chains.distance(a, b), 0);
  // Just off the edge (within the tolerance) it is found at the same place.
  ASSERT_TRUE(chains.locate(tree, adj, Vec3(0.5, 0.01, 1), 0.05, c));
  EXPECT_NEAR(chains.distance(a, c), 0, 1e-12);
  EXPECT_FALSE(chains.locate(tree, adj, Vec3(0.5, 0.2, 1), 0.05, c));  // too far from any sharp edge
  // The vertical edge at (0,0) is another chain; so is the bottom outline.
  ASSERT_TRUE(chains.locate(tree, adj, Vec3(0, 0, 0.5), 1e-6, far));
  EXPECT_TRUE(std::isinf(chains.distance(a, far)));
  ASSERT_TRUE(chains.locate(tree, adj, Vec3(0.5, 0, 0), 1e-6, far));
  EXPECT_TRUE(std::isinf(chains.distance(a, far)));
}

TEST(Quad, CreaseNoQuadEdgeFollowsIsCaptured) {
  // The box's grid with the three inner vertices of one box edge (x = y = 0) moved 0.1 onto the
  // face x = 0: the quads chamfer that edge. The smoothing alone keeps them on their face; the
  // capture moves that path of quad edges back onto the edge: the box grid again.
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 1, 1));
  hex::HexResult h = grid_of_box(s);
  int moved = 0;
  for (int v = 0; v < h.V.rows(); ++v)
    if (std::abs(h.V(v, 0)) < 1e-12 && std::abs(h.V(v, 1)) < 1e-12 && h.V(v, 2) > 0.1 && h.V(v, 2) < 0.9) {
      h.V(v, 1) = 0.1;
      ++moved;
    }
  ASSERT_EQ(moved, 3);
  auto hausdorff = [&](const quad::QuadResult& q) {
    return hex::hausdorff(q.V, hex::triangulate_quads(q.Q), s.V, s.F, 20000).max;
  };
  quad::QuadOptions off;
  off.capture_creases = false;
  const quad::QuadResult a = quad::quad_mesh_from_hexes(h.V, h.H, s, off);
  EXPECT_LT(a.creases_before.followed, 0.95);  // after the smoothing (the fitting then slides some onto it)
  EXPECT_GT(hausdorff(a), 0.05);
  const quad::QuadResult b = quad::quad_mesh_from_hexes(h.V, h.H, s);
  EXPECT_EQ(b.crease_runs, 1);
  EXPECT_EQ(b.crease_captured, 1);
  EXPECT_EQ(b.crease_moved, 3);
  EXPECT_LT(b.creases_before.followed, 0.95);
  EXPECT_DOUBLE_EQ(b.creases_after.followed, 1.0);
  EXPECT_LT(hausdorff(b), 1e-9);
  EXPECT_GT(b.quality.sj_min, 0.999);
}

TEST(Quad, CaptureThatWouldFoldQuadsIsUndone) {
  // A crease across the grid: the surface z = 0 bent up by 45 degrees along the diagonal line
  // x + y = 1 (a sharp edge no grid line follows). A path of grid edges onto it is a staircase
  // whose quads would fold or flatten, so the capture is undone and the mesh is left as smoothed.
  auto height = [](double x, double y) { return std::max(0.0, (x + y - 1) / std::sqrt(2.0)); };
  const SurfaceMesh s = height_field(20, height);
  quad::QuadResult r;
  const int m = 6;
  r.V.resize((m + 1) * (m + 1), 3);
  for (int i = 0; i <= m; ++i)
    for (int j = 0; j <= m; ++j) {
      const double x = double(i) / m, y = double(j) / m;
      r.V.row(i * (m + 1) + j) << x, y, height(x, y);
    }
  r.Q.resize(m * m, 4);
  for (int i = 0, q = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      const int a = i * (m + 1) + j;
      r.Q.row(q++) << a, a + m + 1, a + m + 2, a + 1;
    }
  std::vector<char> pinned(r.V.rows(), 0);
  for (int i = 0; i <= m; ++i)
    for (int j = 0; j <= m; ++j) pinned[i * (m + 1) + j] = i == 0 || j == 0 || i == m || j == m;
  quad::smooth_on_surface(r, s, {}, {}, pinned);
  EXPECT_EQ(r.quality.inverted, 0);
  EXPECT_GE(r.quality.sj_min, std::min(0.3, r.extracted.sj_min) - 1e-12);
  EXPECT_GE(r.crease_runs, 1);
}

TEST(Quad, FeatureVerticesSlideAlongTheirSharpEdge) {
  // The box's grid (4 cells per unit) with a vertex of a box edge moved along that edge most of
  // the way to its neighbour: the quads on both sides are skewed (the smoothing of the other
  // vertices leaves 0.86). Sliding along the edge restores them; every vertex stays on the box.
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 1, 1));
  hex::HexResult h = grid_of_box(s);
  const int moved = vertex_at(h.V, Eigen::RowVector3d(0, 0, 0.5));
  ASSERT_GE(moved, 0);
  h.V(moved, 2) = 0.5 + 0.22;  // its neighbour on the edge is at 0.75
  quad::QuadOptions fixed_opt;
  fixed_opt.slide_on_features = false;
  const quad::QuadResult a = quad::quad_mesh_from_hexes(h.V, h.H, s, fixed_opt);
  quad::QuadOptions slide_opt;
  slide_opt.slide_below = 1.0;  // (by default only the vertices of quads below 0.4 slide)
  const quad::QuadResult b = quad::quad_mesh_from_hexes(h.V, h.H, s, slide_opt);
  EXPECT_GT(b.quality.sj_min, a.quality.sj_min + 0.1) << a.quality.sj_min << " " << b.quality.sj_min;
  EXPECT_EQ(b.quality.inverted, 0);
  // Every vertex is still on the box (on its edges where it was on one).
  for (int v = 0; v < b.V.rows(); ++v) {
    const Eigen::RowVector3d p = b.V.row(v);
    const double d = std::min({p.minCoeff(), 1 - p.maxCoeff()});
    EXPECT_NEAR(d, 0.0, 1e-9);
  }
}

TEST(Quad, PatternSearchUnfoldsQuadsOnAFace) {
  // The box's grid (4 cells per unit) with an inner vertex of the face z = 0 moved 0.2 along both
  // axes, past the diagonal of the cell it leaves: two quads fold (-0.88). Without smoothing, the
  // pattern search alone unfolds them (the vertex and its neighbours each to the best of their
  // trial positions: 0.69, a local optimum of the worst quad; the smoothing before it brings such
  // a vertex back by itself); every vertex stays on the box.
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 1, 1));
  hex::HexResult h = grid_of_box(s);
  const int moved = vertex_at(h.V, Eigen::RowVector3d(0.5, 0.5, 0));
  ASSERT_GE(moved, 0);
  h.V(moved, 0) += 0.2;
  h.V(moved, 1) += 0.2;
  quad::QuadOptions off;
  off.smooth_iterations = 0;
  off.fit.rounds = 0;
  off.search_sweeps = 0;
  const quad::QuadResult a = quad::quad_mesh_from_hexes(h.V, h.H, s, off);
  quad::QuadOptions on = off;
  on.search_sweeps = 20;
  const quad::QuadResult b = quad::quad_mesh_from_hexes(h.V, h.H, s, on);
  EXPECT_LT(a.quality.sj_min, 0);
  EXPECT_GT(b.quality.sj_min, 0.6) << a.quality.sj_min << " -> " << b.quality.sj_min;
  EXPECT_EQ(b.quality.inverted, 0);
  EXPECT_GT(b.search_moves, 0);
  for (int v = 0; v < b.V.rows(); ++v) {
    const Eigen::RowVector3d p = b.V.row(v);
    EXPECT_NEAR(std::min({p.minCoeff(), 1 - p.maxCoeff()}), 0.0, 1e-9);
  }
}

namespace {
// Open tube of radius 1 around the z axis, z in [0, 1], `seg` segments around and `rows` rows.
SurfaceMesh tube(int seg, int rows) {
  SurfaceMesh m;
  m.V.resize(seg * (rows + 1), 3);
  for (int r = 0; r <= rows; ++r)
    for (int i = 0; i < seg; ++i) {
      const double t = 2 * M_PI * i / seg;
      m.V.row(r * seg + i) << std::cos(t), std::sin(t), static_cast<double>(r) / rows;
    }
  m.F.resize(2 * seg * rows, 3);
  for (int r = 0; r < rows; ++r)
    for (int i = 0; i < seg; ++i) {
      const int a = r * seg + i, b = r * seg + (i + 1) % seg, c = a + seg, d = b + seg;
      m.F.row(2 * (r * seg + i)) << a, b, d;
      m.F.row(2 * (r * seg + i) + 1) << a, d, c;
    }
  return m;
}

// A ring of 8 quads on the tube with its vertices on the tube at uneven angles (gaps 60, 30, 45,
// 45 degrees, twice), and the worst quad around a vertex.
struct Ring {
  MatX3d V;
  MatX4i Q;
  std::vector<std::vector<int>> vq;
  double worst(int v) const {
    double m = 1e300;
    for (int q : vq[v]) {
      std::array<Vec3, 4> p;
      for (int j = 0; j < 4; ++j) p[j] = V.row(Q(q, j)).transpose();
      m = std::min(m, quad::scaled_jacobian(p));
    }
    return m;
  }
};
Ring uneven_ring() {
  Ring r;
  const double gaps[8] = {60, 30, 45, 45, 60, 30, 45, 45};
  r.V.resize(16, 3);
  double a = 0;
  for (int i = 0; i < 8; ++i) {
    const double t = a * M_PI / 180;
    r.V.row(i) << std::cos(t), std::sin(t), 0;
    r.V.row(8 + i) << std::cos(t), std::sin(t), 1;
    a += gaps[i];
  }
  r.Q.resize(8, 4);
  for (int i = 0; i < 8; ++i) r.Q.row(i) << i, (i + 1) % 8, 8 + (i + 1) % 8, 8 + i;  // outward
  r.vq.assign(16, {});
  for (int q = 0; q < 8; ++q)
    for (int j = 0; j < 4; ++j) r.vq[r.Q(q, j)].push_back(q);
  return r;
}
}  // namespace

TEST(SurfaceFit, AnUnevenRingOnATubeEvensOutToTheBestChords) {
  const SurfaceMesh s = tube(360, 4);
  const geometry::TriangleTree tree(s.V, s.F);
  Ring r = uneven_ring();
  const std::vector<char> free_vertex(16, 1);
  geometry::SurfaceFitOptions o;
  o.rounds = 60;
  o.quality_floor = 0.5;  // the default would keep the rectangles' 1: no vertex could move alone
  const geometry::SurfaceFitStats st =
      geometry::fit_to_surface(r.V, r.Q, s, tree, free_vertex, nullptr, [&](int v) { return r.worst(v); }, o);
  // Before: the 60-degree chords, 1 - cos 30 = 0.134 deep; at best (8 equal chords) 1 - cos 22.5.
  const double best = 1 - std::cos(22.5 * M_PI / 180);
  EXPECT_NEAR(st.max_before, 1 - std::cos(30 * M_PI / 180), 2e-3);
  EXPECT_GT(st.moves, 0);
  EXPECT_LT(st.max_after, 1.1 * best);
  EXPECT_GT(st.max_after, best - 2e-3);  // none can do better (up to the tube's own facets)
  EXPECT_LT(st.mean_after, st.mean_before);
  // Every vertex stays on the tube (within its facets' depth) and between its rims.
  for (int v = 0; v < 16; ++v) {
    const double rad = std::hypot(r.V(v, 0), r.V(v, 1));
    EXPECT_NEAR(rad, 1, 1e-4) << v;
    EXPECT_GE(r.V(v, 2), -1e-9);
    EXPECT_LE(r.V(v, 2), 1 + 1e-9);
  }
  EXPECT_GT(quad::quad_quality(r.V, r.Q).sj_min, 0.5);
}

TEST(SurfaceFit, VerticesOffTheSurfaceHalveTheChordsDepth) {
  // Eight equal chords round the unit tube, their corners on it: each cuts 1 - cos 22.5 deg under
  // the tube, which no vertex on the surface can improve. With the corners allowed off the surface
  // they move out to the radius R where the corners' distance R - 1 equals the chords' depth
  // 1 - R cos 22.5, R = 2 / (1 + cos 22.5): about half the depth either way.
  const SurfaceMesh s = tube(360, 4);
  const geometry::TriangleTree tree(s.V, s.F);
  const double c = std::cos(22.5 * M_PI / 180), on = 1 - c, R = 2 / (1 + c), off = R - 1;
  auto even_ring = [] {
    Ring r = uneven_ring();
    for (int i = 0; i < 8; ++i) {
      const double t = i * M_PI / 4;
      r.V.row(i) << std::cos(t), std::sin(t), 0;
      r.V.row(8 + i) << std::cos(t), std::sin(t), 1;
    }
    return r;
  };
  geometry::SurfaceFitOptions o;
  o.rounds = 60;
  o.quality_floor = 0.5;
  Ring kept = even_ring();
  const geometry::SurfaceFitStats k =
      geometry::fit_to_surface(kept.V, kept.Q, s, tree, std::vector<char>(16, 1), nullptr,
                               [&](int v) { return kept.worst(v); }, o);
  EXPECT_NEAR(k.max_after, on, 2e-3);  // on the surface: the chords' depth stays
  o.max_offset = 0.5;
  Ring r = even_ring();
  const geometry::SurfaceFitStats st = geometry::fit_to_surface(r.V, r.Q, s, tree, std::vector<char>(16, 1), nullptr,
                                                                [&](int v) { return r.worst(v); }, o);
  EXPECT_NEAR(st.max_before, on, 2e-3);
  EXPECT_GT(st.moves, 0);
  EXPECT_LT(st.max_after, 1.1 * off);
  EXPECT_GT(st.max_after, off - 2e-3);  // none can do better (up to the tube's facets)
  EXPECT_LT(st.mean_after, st.mean_before);
  const double len = 0.5 * (2 * std::sin(M_PI / 8) + 1);  // a vertex's mean quad edge: a chord and a height
  for (int v = 0; v < 16; ++v) {
    const double rad = std::hypot(r.V(v, 0), r.V(v, 1));
    EXPECT_GT(rad, 1 + 0.5 * off) << v;  // out, not in
    EXPECT_LT(rad, 1 + 1.1 * off) << v;
    EXPECT_LE(rad - 1, o.max_offset * len + 1e-4) << v;
  }
  EXPECT_GT(quad::quad_quality(r.V, r.Q).sj_min, 0.5);
  // With a tight limit the corners stop at it.
  o.max_offset = 0.01;
  Ring t = even_ring();
  geometry::fit_to_surface(t.V, t.Q, s, tree, std::vector<char>(16, 1), nullptr, [&](int v) { return t.worst(v); },
                           o);
  for (int v = 0; v < 16; ++v)  // (1e-4: the tube's facets)
    EXPECT_LE(std::hypot(t.V(v, 0), t.V(v, 1)) - 1, 0.01 * len + 1e-4) << v;
}

TEST(SurfaceFit, FocusedRoundsFinishWhatFewFullRoundsLeave) {
  const SurfaceMesh s = tube(360, 4);
  const geometry::TriangleTree tree(s.V, s.F);
  const double best = 1 - std::cos(22.5 * M_PI / 180);
  auto run = [&](int rounds, int focus, double share = 1.0) {
    Ring r = uneven_ring();
    geometry::SurfaceFitOptions o;
    o.rounds = rounds;
    o.focus_rounds = focus;
    o.focus_max_share = share;  // the far quads and their neighbours are most of this small ring
    o.quality_floor = 0.5;
    return geometry::fit_to_surface(r.V, r.Q, s, tree, std::vector<char>(16, 1), nullptr,
                                    [&](int v) { return r.worst(v); }, o);
  };
  const geometry::SurfaceFitStats few = run(2, 0), focused = run(2, 60);
  EXPECT_EQ(few.focus_rounds, 0);
  EXPECT_GT(focused.focus_rounds, 0);
  EXPECT_EQ(focused.rounds, 2 + focused.focus_rounds);
  EXPECT_GT(few.max_after, 1.1 * best);  // two rounds are not enough
  EXPECT_LT(focused.max_after, 1.1 * best);
  EXPECT_LT(focused.max_after, few.max_after);
  // Largest distances over more than the allowed share of the vertices: no focused round.
  const geometry::SurfaceFitStats capped = run(2, 60, 0.1);
  EXPECT_EQ(capped.focus_rounds, 0);
  EXPECT_EQ(capped.max_after, few.max_after);
}

TEST(SurfaceFit, VerticesOnASharpEdgeSlideAlongIt) {
  // The ring's bottom vertices are not free but slide on the rim circle z = 0 (a sharp edge).
  const SurfaceMesh s = tube(360, 4);
  const geometry::TriangleTree tree(s.V, s.F);
  const double best = 1 - std::cos(22.5 * M_PI / 180);
  std::vector<char> free_vertex(16, 1);
  for (int v = 0; v < 8; ++v) free_vertex[v] = 0;
  auto on_rim = [](int v, const Vec3& x, Vec3& p) {
    if (v >= 8) return false;
    const double a = std::atan2(x.y(), x.x());
    p = Vec3(std::cos(a), std::sin(a), 0);
    return true;
  };
  geometry::SurfaceFitOptions o;
  o.rounds = 60;
  o.quality_floor = 0.5;
  Ring r = uneven_ring();
  const geometry::SurfaceFitStats st = geometry::fit_to_surface(
      r.V, r.Q, s, tree, free_vertex, nullptr, [&](int v) { return r.worst(v); }, o, on_rim);
  EXPECT_LT(st.max_after, 1.1 * best);
  for (int v = 0; v < 8; ++v) {
    EXPECT_EQ(r.V(v, 2), 0.0) << v;  // on the rim
    EXPECT_NEAR(std::hypot(r.V(v, 0), r.V(v, 1)), 1, 1e-12) << v;
  }
  // Without the slide the bottom stays where it was and the chords stay uneven there.
  Ring k = uneven_ring();
  const geometry::SurfaceFitStats kept =
      geometry::fit_to_surface(k.V, k.Q, s, tree, free_vertex, nullptr, [&](int v) { return k.worst(v); }, o);
  for (int v = 0; v < 8; ++v) EXPECT_EQ((k.V.row(v) - uneven_ring().V.row(v)).norm(), 0.0) << v;
  EXPECT_GT(kept.max_after, st.max_after);
}

TEST(SurfaceFit, NoMoveTakesAQuadBelowTheFloor) {
  const SurfaceMesh s = tube(360, 4);
  const geometry::TriangleTree tree(s.V, s.F);
  Ring r = uneven_ring();
  // The 8 quads are rectangles (scaled Jacobian 1): a vertex moving alone makes trapezoids.
  ASSERT_NEAR(quad::quad_quality(r.V, r.Q).sj_min, 1, 1e-12);
  geometry::SurfaceFitOptions o;
  o.rounds = 20;
  o.quality_floor = 0.999;
  std::vector<char> free_vertex(16, 1);
  free_vertex[0] = 0;  // a vertex that stays does not move
  const Vec3 v0 = r.V.row(0).transpose();
  const geometry::SurfaceFitStats st =
      geometry::fit_to_surface(r.V, r.Q, s, tree, free_vertex, nullptr, [&](int v) { return r.worst(v); }, o);
  EXPECT_GE(quad::quad_quality(r.V, r.Q).sj_min, 0.999 - 1e-12);
  EXPECT_LE(st.max_after, st.max_before + 1e-12);
  EXPECT_EQ((r.V.row(0).transpose() - v0).norm(), 0.0);
  // The default floor is the mesh's worst element before (here 1): nothing moves.
  r = uneven_ring();
  const geometry::SurfaceFitStats d = geometry::fit_to_surface(r.V, r.Q, s, tree, std::vector<char>(16, 1), nullptr,
                                                               [&](int v) { return r.worst(v); });
  EXPECT_NEAR(d.floor, 1, 1e-12);
  EXPECT_EQ(d.moves, 0);
}

TEST(SurfaceFit, DenseSamplesFindTheLargestDistanceBetweenTheCoarseOnes) {
  // A flat unit square (two triangles) under a roof of two quads whose ridge runs along y at
  // x = 0.4, 0.1 high. The distance from (x, y, 0) to the roof is min(x sin a, (1 - x) sin b)
  // (a, b: the slopes' angles), largest at x = 0.404, between the square's vertices and centroids
  // (x = 1/3, 2/3); a grid of tenths on the triangles near the largest distance has x = 0.4. No vertex may move: the figures are measurements.
  SurfaceMesh s;
  s.V.resize(4, 3);
  s.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  s.F.resize(2, 3);
  s.F << 0, 1, 2, 0, 2, 3;
  const geometry::TriangleTree tree(s.V, s.F);
  const double h = 0.1, sa = h / std::hypot(0.4, h), sb = h / std::hypot(0.6, h);
  auto run = [&](int dense) {
    MatX3d V(6, 3);
    V << 0, 0, 0, 0.4, 0, h, 0.4, 1, h, 0, 1, 0, 1, 0, 0, 1, 1, 0;
    MatX4i Q(2, 4);
    Q << 0, 1, 2, 3, 1, 4, 5, 2;
    geometry::SurfaceFitOptions o;
    o.focus_dense = dense;
    const geometry::SurfaceFitStats st = geometry::fit_to_surface(V, Q, s, tree, std::vector<char>(6, 0), nullptr,
                                                                  [](int) { return 1.0; }, o);
    EXPECT_EQ(st.moves, 0);
    return st.max_after;
  };
  double truth = 0;  // on a fine grid of x
  for (int i = 0; i <= 10000; ++i) truth = std::max(truth, std::min(sa * i / 1e4, sb * (1 - i / 1e4)));
  const double coarse = run(0), fine = run(10);
  EXPECT_NEAR(coarse, sa / 3, 1e-9);  // the centroid at x = 1/3
  EXPECT_LT(coarse, truth - 0.01);
  EXPECT_NEAR(fine, std::min(sa * 0.4, sb * 0.6), 1e-9);  // x = 0.4
  EXPECT_GT(fine, truth - 2e-3);
}

TEST(Quad, TheTargetsUnusedVerticesAreNotTakenForSurfacePoints) {
  // As for hexes: a tet mesh's V with its boundary as the target gives the quads of its surface
  // alone (the interior vertices were samples of the fitting and of the crease checks).
  const BentL bent = bent_l_block();  // the polycube is the L itself, the rest a bend of it
  const TetMesh& tm = bent.tm;
  const MatX3d& rest = bent.rest;
  ASSERT_TRUE(has_unreferenced_vertices(tm.V.rows(), tm.boundary));
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  hex::HexOptions o;
  o.target_hexes = 800;
  o.pillow = "off";
  o.smooth_iterations = 0;
  o.fit.rounds = 0;
  const SurfaceMesh surface = compact_surface(rest, tm.boundary);
  const hex::HexResult h = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &surface, o);
  const quad::QuadResult a = quad::quad_mesh_from_hexes(h.V, h.H, SurfaceMesh{rest, tm.boundary});
  const quad::QuadResult b = quad::quad_mesh_from_hexes(h.V, h.H, surface);
  EXPECT_GT(b.fit.moves, 0) << "the fitting should have work to do on the bent L";
  ASSERT_EQ(a.V.rows(), b.V.rows());
  EXPECT_EQ((a.V - b.V).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(a.quality.inverted, 0);
}

namespace {
// A flat 1 x 1 square meshed by a grid of quads with columns at xs and rows at ys, its boundary
// vertices pinned (pinned[v]).
quad::QuadResult flat_grid(const std::vector<double>& xs, const std::vector<double>& ys, std::vector<char>& pinned) {
  const int nx = static_cast<int>(xs.size()), ny = static_cast<int>(ys.size());
  quad::QuadResult r;
  r.V.resize(nx * ny, 3);
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) r.V.row(i * ny + j) << xs[i], ys[j], 0;
  r.Q.resize((nx - 1) * (ny - 1), 4);
  for (int i = 0, q = 0; i + 1 < nx; ++i)
    for (int j = 0; j + 1 < ny; ++j) {
      const int a = i * ny + j;
      r.Q.row(q++) << a, a + ny, a + ny + 1, a + 1;
    }
  pinned.assign(r.V.rows(), 0);
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) pinned[i * ny + j] = i == 0 || j == 0 || i == nx - 1 || j == ny - 1;
  return r;
}

double shortest_edge(const quad::QuadResult& r, int q) {
  double shortest = 1e300;
  for (int j = 0; j < 4; ++j) shortest = std::min(shortest, (r.V.row(r.Q(q, j)) - r.V.row(r.Q(q, (j + 1) % 4))).norm());
  return shortest;
}
}  // namespace

TEST(Quad, SliverColumnIsWidened) {
  // A flat 1 x 1 square meshed by quads in 6 columns and 4 rows, one column 1e-4 wide (as a thin
  // step kept a cell wide gives): its 4 quads have edge ratios of 2500. The boundary is pinned,
  // so the two end quads keep a short edge on it; the two middle ones have both short edges
  // free, and no single corner move lowers their edge ratio (the other short edge stays), nor
  // raises any scaled Jacobian (they are rectangles). With QuadOptions::widen_slivers the
  // smoothing takes the moves that lower their aspect instead: the middle ones widen.
  const SurfaceMesh s = height_field(10, [](double, double) { return 0.0; });
  const std::vector<double> xs{0, 0.2, 0.4, 0.4001, 0.6, 0.8, 1.0}, ys{0, 0.25, 0.5, 0.75, 1.0};
  const int ny = static_cast<int>(ys.size());
  auto run = [&](bool widen) {
    std::vector<char> pinned;
    quad::QuadResult r = flat_grid(xs, ys, pinned);
    quad::QuadOptions o;
    o.widen_slivers = widen;
    o.shape_sweeps = 0;  // (the shape pass widens the column too: see ShapePassWidensASliverColumn)
    quad::smooth_on_surface(r, s, o, {}, pinned);
    return r;
  };
  const quad::QuadResult off = run(false), on = run(true);
  EXPECT_EQ(off.extracted.edge_ratio_above_100, 4);
  EXPECT_EQ(off.quality.edge_ratio_above_100, 4);
  EXPECT_EQ(on.quality.edge_ratio_above_100, 2);  // the end quads, on the pinned boundary
  EXPECT_EQ(on.quality.inverted, 0);
  EXPECT_GE(on.quality.sj_min, 0.5);
  // The middle quads of the column (rows 1 and 2 of column 2) are now at least 0.01 wide.
  for (int q : {2 * (ny - 1) + 1, 2 * (ny - 1) + 2}) EXPECT_GT(shortest_edge(on, q), 0.01) << "quad " << q;
  for (int v = 0; v < on.V.rows(); ++v) EXPECT_NEAR(on.V(v, 2), 0.0, 1e-12);
}


TEST(Quad, ShapePassWidensASliverColumn) {
  // The column of SliverColumnIsWidened (1e-4 wide, edge ratios 2500), without the smoothing's
  // widening: the shape pass (QuadOptions::shape_sweeps) lowers the corner condition numbers of
  // its quads, (a + 1/a) / 2 for a rectangle of aspect a, so its free vertices spread the column
  // towards the even spacing of 0.2 that the pinned boundary leaves (the end quads keep their
  // short edge on it).
  const SurfaceMesh s = height_field(10, [](double, double) { return 0.0; });
  const std::vector<double> xs{0, 0.2, 0.4, 0.4001, 0.6, 0.8, 1.0}, ys{0, 0.25, 0.5, 0.75, 1.0};
  const int ny = static_cast<int>(ys.size());
  auto run = [&](int sweeps) {
    std::vector<char> pinned;
    quad::QuadResult r = flat_grid(xs, ys, pinned);
    quad::QuadOptions o;
    o.widen_slivers = false;
    o.shape_sweeps = sweeps;
    quad::smooth_on_surface(r, s, o, {}, pinned);
    return r;
  };
  const quad::QuadResult off = run(0), on = run(40);
  EXPECT_EQ(off.shape_moves, 0);
  EXPECT_EQ(off.quality.edge_ratio_above_100, 4);
  EXPECT_GT(on.shape_moves, 0);
  EXPECT_EQ(on.quality.edge_ratio_above_100, 2);  // the end quads, on the pinned boundary
  EXPECT_EQ(on.quality.inverted, 0);
  EXPECT_GE(on.quality.sj_min, 0.5);
  // The middle quads of the column are now at least 0.05 wide (a quarter of the even spacing).
  for (int q : {2 * (ny - 1) + 1, 2 * (ny - 1) + 2}) EXPECT_GT(shortest_edge(on, q), 0.05) << "quad " << q;
  for (int v = 0; v < on.V.rows(); ++v) EXPECT_NEAR(on.V(v, 2), 0.0, 1e-12);
}

TEST(Quad, ShapePassLeavesGoodQuadsAlone) {
  // An even 5 x 5 grid has no quad over the edge ratio of QuadOptions::max_edge_ratio: the shape
  // pass moves nothing, and every quad stays a square.
  const SurfaceMesh s = height_field(10, [](double, double) { return 0.0; });
  const std::vector<double> even{0, 0.2, 0.4, 0.6, 0.8, 1.0};
  std::vector<char> pinned;
  quad::QuadResult r = flat_grid(even, even, pinned);
  const MatX3d before = r.V;
  quad::smooth_on_surface(r, s, {}, {}, pinned);
  EXPECT_EQ(r.shape_moves, 0);
  EXPECT_LT((r.V - before).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_GT(r.quality.sj_min, 1 - 1e-9);
}
