// Quad stage: the quad scaled Jacobian on known quads and the quad mesh of a box.
#include <map>

#include "polycube/chart/labeling.h"
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
  int moved = -1;
  for (int v = 0; v < h.V.rows() && moved < 0; ++v)
    if ((h.V.row(v) - Eigen::RowVector3d(0, 0, 1.5)).norm() < 1e-9) moved = v;
  ASSERT_GE(moved, 0);
  h.V(moved, 2) = 1.5 + 0.4;  // beyond its neighbour at z = 1.75, still on the edge x = y = 0
  const quad::QuadResult before = quad::quad_mesh_from_hexes(h.V, h.H, s, quad::QuadOptions{0});
  EXPECT_GT(before.quality.inverted, 0);
  const quad::QuadResult q = quad::quad_mesh_from_hexes(h.V, h.H, s);
  EXPECT_EQ(q.quality.inverted, 0);
  EXPECT_GT(q.quality.sj_min, 0.5);
}
