// Chart labelling, cleanup and exact polycube realization on shapes with known answers.
#include <algorithm>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include "polycube/chart/extract.h"
#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/deform/solver.h"
#include "polycube/examples/examples.h"
#include "polycube/pipeline/pipeline.h"
#include "polycube/validate/tetmesh.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {

// Exact planarity: every boundary triangle has one coordinate along its label's axis.
double max_planarity_spread(const MatX3d& X, const MatX3i& B, const std::vector<int>& labels) {
  double e = 0;
  for (int f = 0; f < B.rows(); ++f) {
    const int k = labels[f] / 2;
    for (int j = 1; j < 3; ++j) e = std::max(e, std::abs(X(B(f, j), k) - X(B(f, 0), k)));
  }
  return e;
}

chart::PolycubeExtraction deform_and_extract(const TetMesh& tm, double* l1 = nullptr) {
  auto d = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  if (l1) *l1 = d.l1_quality;
  return chart::extract_polycube(tm.V, tm.T, tm.boundary, d.X);
}

void expect_exact_polycube(const chart::PolycubeExtraction& e, const TetMesh& tm) {
  ASSERT_TRUE(e.realized.success) << e.realized.failure;
  EXPECT_EQ(max_planarity_spread(e.realized.X, tm.boundary, e.labels), 0.0);
  EXPECT_EQ(e.realized.planarity_error, 0.0);
  EXPECT_EQ(e.realized.misoriented_faces, 0);
  EXPECT_EQ(e.realized.inverted, 0);
  // Every tet positive in both meshes.
  EXPECT_EQ(measure_tets(e.realized.rest, e.realized.T).inverted, 0);
  EXPECT_EQ(measure_tets(e.realized.X, e.realized.T).inverted, 0);
  EXPECT_EQ(measure_tets(e.realized.X, e.realized.T).zero_volume, 0);
  // The boundary is untouched by edge splits: same vertices at the same rest positions.
  EXPECT_EQ((e.realized.rest.topRows(tm.V.rows()) - tm.V).cwiseAbs().maxCoeff(), 0.0);
}

}  // namespace

TEST(Chart, LabelCode) {
  EXPECT_EQ(chart::label_of(Vec3(0.9, 0.1, -0.2)), kPosX);
  EXPECT_EQ(chart::label_of(Vec3(0.1, -0.9, 0.2)), kNegY);
  EXPECT_EQ(chart::label_of(Vec3(0.1, 0.3, -0.4)), kNegZ);
  for (int l = 0; l < 6; ++l) EXPECT_EQ(chart::label_of(chart::label_direction(l)), l);
  EXPECT_STREQ(chart::label_name(kPosZ), "+Z");
}

TEST(Chart, BoxHasSixChartsEightCornersTwelveEdges) {
  for (auto s : {box(), grid_box(4)}) {
    const auto labels = chart::label_by_normal(s.V, s.F);
    const auto r = chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels);
    EXPECT_EQ(r.charts, 6);
    EXPECT_EQ(r.corners, 8);
    EXPECT_EQ(r.chart_edges, 12);
    ASSERT_GE(r.corner_valence.size(), 4u);
    EXPECT_EQ(r.corner_valence[3], 8);
    EXPECT_TRUE(r.valid);
    EXPECT_EQ(r.non_disk_charts, 0);
  }
}

TEST(Chart, LBlockHasEightChartsTwelveCorners) {
  MeshData l = examples::make("l_bracket", 0.1);
  const auto labels = chart::label_by_normal(l.V, l.F);
  const auto r = chart::check_charts(l.F, static_cast<int>(l.V.rows()), labels);
  EXPECT_EQ(r.charts, 8);
  EXPECT_EQ(r.corners, 12);
  EXPECT_EQ(r.chart_edges, 18);
  EXPECT_TRUE(r.valid);
}

TEST(Chart, CleanupStraightensAZigzag) {
  auto s = grid_box(6);
  const auto good = chart::label_by_normal(s.V, s.F);
  auto labels = good;
  // A +Z triangle on the +X border (away from corners), relabelled +X: a zigzag.
  int f0 = -1;
  for (int f = 0; f < s.F.rows() && f0 < 0; ++f) {
    if (good[f] != kPosZ) continue;
    const double y = (s.V(s.F(f, 0), 1) + s.V(s.F(f, 1), 1) + s.V(s.F(f, 2), 1)) / 3;
    if (y < 0.2 || y > 0.8) continue;  // away from the corners
    int on_x = 0;
    for (int j = 0; j < 3; ++j) on_x += s.V(s.F(f, j), 0) == 1.0;
    if (on_x == 2) f0 = f;
  }
  ASSERT_GE(f0, 0);
  labels[f0] = kPosX;
  const auto st = chart::cleanup_labels(s.V, s.F, labels);
  EXPECT_GE(st.zigzags, 1);
  EXPECT_EQ(labels, good);
  EXPECT_EQ(st.relabelled_faces, 1);
}

TEST(Chart, CleanupRemovesIslandsAndWedges) {
  auto s = grid_box(8);
  const auto good = chart::label_by_normal(s.V, s.F);
  auto labels = good;
  // An island (degree 1) in the middle of +Z, and a wedge (degree 2) on the +Z/+X border.
  for (int f = 0; f < s.F.rows(); ++f) {
    Vec3 c = (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3;
    if (good[f] == kPosZ && std::abs(c.x() - 0.5) < 0.2 && std::abs(c.y() - 0.5) < 0.2) labels[f] = kPosY;
    if (good[f] == kPosZ && c.x() > 0.75 && std::abs(c.y() - 0.5) < 0.2) labels[f] = kNegY;
  }
  EXPECT_GT(chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels).charts, 6);
  const auto st = chart::cleanup_labels(s.V, s.F, labels);
  EXPECT_GE(st.degree1 + st.degree2 + st.zigzags, 2);
  const auto r = chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels);
  EXPECT_EQ(r.charts, 6);
  EXPECT_EQ(r.corners, 8);
  EXPECT_TRUE(r.valid);
  EXPECT_EQ(labels, good);
}

TEST(Chart, CleanupRelabelsASingleFlatTriangleAtABorderVertex) {
  // A flat patch: vertex m touches three charts; its only +Z triangle (m, q, p) has an angle of
  // 180 - 2 atan(h) degrees at m: 157 for h = 0.2 (no polycube can open one triangle to the
  // 180 or 270 degrees the chart needs there), 90 for h = 1 (fine, kept).
  for (double h : {0.2, 1.0}) {
    MatX3d V(7, 3);
    V << 0, 0, 0, -1, h, 0, 1, h, 0, -2, 0, 0, 2, 0, 0, -1, 2, 0, 1, 2, 0;
    MatX3i F(7, 3);
    F << 0, 2, 1, 3, 0, 1, 0, 4, 2, 1, 2, 6, 1, 6, 5, 3, 1, 5, 2, 4, 6;
    std::vector<int> labels = {kPosZ, kNegY, kPosX, kPosZ, kPosZ, kNegY, kPosX};
    chart::CleanupOptions o;
    o.straighten = false;
    o.remove_low_degree = false;
    o.separate_opposite = false;
    const auto st = chart::cleanup_labels(V, F, labels, o);
    const std::vector<int> given = {kPosZ, kNegY, kPosX, kPosZ, kPosZ, kNegY, kPosX};
    if (h < 0.5) {
      // The first of the two tied neighbour labels; then (p, q, w) has its three vertices on the
      // grown +X chart and follows it (the older rule for triangles that would be flattened).
      EXPECT_EQ(labels[0], kPosX);
      EXPECT_GE(st.degenerate, 1);
    } else {
      EXPECT_EQ(st.degenerate, 0);
      EXPECT_EQ(labels, given);
    }
    for (int f : {1, 2, 5, 6}) EXPECT_EQ(labels[f], given[f]);
  }
}

// A step: a +Z square at height 0, a riser at x = 1, a +Z square at height 1. Labelled +Z all over
// (a riser relabelled into its neighbours), one chart spans the two heights; with the riser -X,
// each +Z chart is a plane.
TEST(Chart, UnflatChartsAreTheOnesSpanningHeights) {
  MatX3d V(8, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0,  // bottom square
      1, 0, 1, 1, 1, 1,                      // riser's top edge
      2, 0, 1, 2, 1, 1;                      // top square
  MatX3i F(6, 3);
  F << 0, 1, 2, 0, 2, 3,  // bottom (+Z)
      1, 4, 5, 1, 5, 2,   // riser (x = 1)
      4, 6, 7, 4, 7, 5;   // top (+Z)
  std::vector<int> all_up(6, 4);
  const auto u = chart::unflat_charts(V, F, all_up, 0.5);
  ASSERT_EQ(u.size(), 1u);
  EXPECT_EQ(u[0].label, 4);
  EXPECT_EQ(u[0].faces, 6);
  EXPECT_DOUBLE_EQ(u[0].spread, 1.0);  // centroid heights 0 to 1
  // The area-weighted median height is the riser's lower triangle's (1/3): the top is farther.
  EXPECT_GE(u[0].farthest, 4);
  EXPECT_TRUE(chart::unflat_charts(V, F, all_up, 1.0).empty());  // spread not over 1
  std::vector<int> stepped = all_up;
  stepped[2] = stepped[3] = 1;  // the riser -X
  EXPECT_TRUE(chart::unflat_charts(V, F, stepped, 0.01).empty());
}

TEST(Chart, OppositeChartsSideBySideAreReported) {
  auto s = grid_box(4);
  auto labels = chart::label_by_normal(s.V, s.F);
  for (int f = 0; f < s.F.rows(); ++f)
    if (labels[f] == kPosZ && s.V(s.F(f, 0), 0) + s.V(s.F(f, 1), 0) + s.V(s.F(f, 2), 0) < 1.5) labels[f] = kNegZ;
  const auto r = chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels);
  EXPECT_FALSE(r.valid);
  EXPECT_GE(r.opposite_adjacent, 1);
  ASSERT_FALSE(r.problems.empty());
  EXPECT_NE(r.problems[0].find("opposite"), std::string::npos) << r.problems[0];
}

namespace {
// The 1 x 2 x 3 box's tet mesh and a copy of its vertices each moved by up to `amplitude` per axis.
std::pair<TetMesh, MatX3d> perturbed_box(unsigned seed, double amplitude) {
  auto b = grid_box(3, Vec3(0, 0, 0), Vec3(1, 2, 3));
  TetMesh tm = tet_mesh_of(b.V, b.F);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  MatX3d D = tm.V;
  for (int i = 0; i < D.rows(); ++i)
    for (int k = 0; k < 3; ++k) D(i, k) += u(rng);
  return {std::move(tm), std::move(D)};
}

// Up to a translation, X is the 1 x 2 x 3 box.
void expect_box_size(const MatX3d& X) {
  const Vec3 size = X.colwise().maxCoeff() - X.colwise().minCoeff();
  EXPECT_NEAR(size.x(), 1, 1e-3);
  EXPECT_NEAR(size.y(), 2, 1e-3);
  EXPECT_NEAR(size.z(), 3, 1e-3);
}
}  // namespace

TEST(Realize, PerturbedBoxBecomesTheBoxAgain) {
  const auto [tm, D] = perturbed_box(3, 0.01);
  const auto e = chart::extract_polycube(tm.V, tm.T, tm.boundary, D);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.charts.charts, 6);
  EXPECT_EQ(e.charts.corners, 8);
  EXPECT_LT(e.realized.arap, 1e-6);
  EXPECT_LT(e.realized.isometric.max, 1.01);
  EXPECT_GE(e.realized.isometric.min, 1.0 - 1e-12);
  expect_box_size(e.realized.X);
}

TEST(Realize, SphereGivesAnExactSixChartPolycube) {
  auto s = sphere(3, Vec3(1, 2, 3), 2.0);
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  const auto e = deform_and_extract(tm);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.charts.charts, 6);
  EXPECT_EQ(e.charts.corners, 8);
  EXPECT_TRUE(e.charts.valid);
  EXPECT_LT(e.realized.arap, 0.15);
}

TEST(Realize, LBlockUnderRandomRotationsKeepsTwelveCorners) {
  MeshData l = examples::make("l_bracket", 0.08);
  const auto rotations = random_rotations(11, 3);
  for (int k = 0; k < 3; ++k) {
    MatX3d V = l.V * rotations[k].transpose();
    TetMesh tm = tet_mesh_of(V, l.F);
    const auto e = deform_and_extract(tm);
    expect_exact_polycube(e, tm);
    EXPECT_EQ(e.charts.charts, 8) << "rotation " << k;
    EXPECT_EQ(e.charts.corners, 12) << "rotation " << k;
    EXPECT_TRUE(e.charts.valid) << "rotation " << k;
  }
}

TEST(Realize, BoxWithThroughHoleIsAValidGenusOnePolycube) {
  MeshData m = examples::make("box_hole", 0.06);
  TetMesh tm = tet_mesh_of(m.V, m.F);
  const auto e = deform_and_extract(tm);
  expect_exact_polycube(e, tm);
  EXPECT_TRUE(e.charts.valid);
  for (const auto& p : e.charts.problems) ADD_FAILURE() << p;
  // Genus 1 from the chart graph: corners - chart edges + charts - (extra boundary loops) = 2 - 2g.
  // With the hole's faces the charts around it: 16 corners (8 outer, 8 around the hole).
  EXPECT_EQ(e.charts.corners, 16);
  EXPECT_GE(e.charts.non_disk_charts, 0);
}

TEST(Chart, CleanupSeparatesOppositeCharts) {
  auto s = grid_box(8);
  const auto good = chart::label_by_normal(s.V, s.F);
  auto labels = good;
  // A strip of the +Z face relabelled -Z, touching +Z: zero thickness if realized.
  for (int f = 0; f < s.F.rows(); ++f) {
    const double x = (s.V(s.F(f, 0), 0) + s.V(s.F(f, 1), 0) + s.V(s.F(f, 2), 0)) / 3;
    if (good[f] == kPosZ && x < 0.25) labels[f] = kNegZ;
  }
  chart::CleanupOptions o;
  o.remove_low_degree = false;  // the opposite rule alone
  o.straighten = false;
  const auto st = chart::cleanup_labels(s.V, s.F, labels, o);
  EXPECT_GE(st.opposite, 1);
  const auto r = chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels);
  EXPECT_EQ(r.opposite_adjacent, 0);
  for (int f = 0; f < s.F.rows(); ++f)
    if (good[f] == kPosZ) {
      EXPECT_NE(labels[f], kNegZ);
    }
}

// A thin wedge along y: knife edge at x = 0, back face at x = 1 (height 2h), top and bottom faces
// meeting at the knife with normals about +Z and -Z (a sheet folded flat, as surface mode's
// deformation leaves thin parts).
SurfaceMesh wedge(int n, double h) {
  std::vector<Eigen::Vector2d> profile;  // (x, z): knife -> top back -> bottom back
  const Eigen::Vector2d A(0, 0), B(1, h), C(1, -h);
  for (auto [p, q] : {std::pair{A, B}, std::pair{B, C}, std::pair{C, A}})
    for (int i = 0; i < n; ++i) profile.push_back(p + (q - p) * (double(i) / n));
  const int m = static_cast<int>(profile.size());
  std::vector<Vec3> V;
  std::vector<Eigen::Vector3i> F;
  for (int j = 0; j <= n; ++j)
    for (const auto& p : profile) V.emplace_back(p[0], double(j) / n, p[1]);
  auto id = [&](int i, int j) { return j * m + (i % m); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < m; ++i) {
      F.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      F.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  const Eigen::Vector2d c = (A + B + C) / 3;
  for (int j : {0, n}) {
    const int centre = static_cast<int>(V.size());
    V.emplace_back(c[0], double(j) / n, c[1]);
    for (int i = 0; i < m; ++i) {
      if (j == 0) F.emplace_back(centre, id(i + 1, j), id(i, j));
      else F.emplace_back(centre, id(i, j), id(i + 1, j));
    }
  }
  SurfaceMesh s;
  s.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  for (size_t v = 0; v < V.size(); ++v) s.V.row(static_cast<Eigen::Index>(v)) = V[v].transpose();
  s.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (size_t f = 0; f < F.size(); ++f) s.F.row(static_cast<Eigen::Index>(f)) = F[f].transpose();
  return s;
}

TEST(Chart, CleanupOpensARimWhereAFoldedSheetMeetsItself) {
  const auto s = wedge(8, 0.02);
  ASSERT_GT(enclosed_volume(s.V, s.F), 0);
  auto labels = chart::label_by_normal(s.V, s.F);
  const auto initial = labels;
  ASSERT_EQ(chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels).opposite_adjacent, 1);
  const auto st = chart::cleanup_labels(s.V, s.F, labels);
  EXPECT_EQ(st.rims, 1);
  const auto r = chart::check_charts(s.F, static_cast<int>(s.V.rows()), labels);
  EXPECT_TRUE(r.valid) << (r.problems.empty() ? "" : r.problems[0]);
  EXPECT_EQ(r.charts, 6);  // +Z, -Z, the rim (-X) at the knife, the back (+X) and the two ends
  EXPECT_EQ(r.corners, 8);
  // Both sides of the sheet keep their labels but for the rim (one row of triangles).
  for (int l : {kPosZ, kNegZ}) {
    int before = 0, kept = 0;
    for (size_t f = 0; f < labels.size(); ++f) {
      before += initial[f] == l;
      kept += initial[f] == l && labels[f] == l;
    }
    EXPECT_GE(kept, before * 3 / 4) << chart::label_name(l);
  }
  int rim = 0;
  for (size_t f = 0; f < labels.size(); ++f) rim += labels[f] == kNegX;
  EXPECT_GT(rim, 0);
  // With rims off, the removal of the degree-3 ends cascades: the layout is lost.
  auto whole = initial;
  chart::CleanupOptions o;
  o.rim_above = 1;
  EXPECT_EQ(chart::cleanup_labels(s.V, s.F, whole, o).rims, 0);
  const auto rw = chart::check_charts(s.F, static_cast<int>(s.V.rows()), whole);
  EXPECT_FALSE(rw.valid);
  EXPECT_LT(rw.charts, 6);
}

TEST(Chart, CleanupOpensTheMissingSideAtAPinchInsteadOfRemovingTheChart) {
  // A box whose top face is painted: +Z on the triangle |x - 1/2| < y/2 (apex at the -Y edge),
  // the rest of the top +X or -X by the side of x = 1/2 (as if the top were a ridge there). The
  // +Z chart then has degree 3 (+X, -X, +Y): its -Y side has length zero where +X and -X meet at
  // the apex. The cleanup gives the triangles around the apex, and along the rest of the +X / -X
  // contact (the staircase's first rows), the missing label -Y (joining the -Y face) instead of
  // relabelling the +Z chart whole, which would cascade.
  const SurfaceMesh s = grid_box(16);
  const auto good = chart::label_by_normal(s.V, s.F);
  auto labels = good;
  for (int f = 0; f < s.F.rows(); ++f) {
    if (good[f] != kPosZ) continue;
    const Vec3 c = (s.V.row(s.F(f, 0)) + s.V.row(s.F(f, 1)) + s.V.row(s.F(f, 2))).transpose() / 3;
    if (std::abs(c[0] - 0.5) >= c[1] / 2) labels[f] = c[0] > 0.5 ? kPosX : kNegX;
  }
  const auto painted = labels;
  int top = 0;
  for (int l : painted) top += l == kPosZ;
  auto degree_of_top = [&](const std::vector<int>& ls) {
    const chart::Charts c = chart::build_charts(s.V, s.F, ls);
    for (int i = 0; i < c.count(); ++i)
      if (c.label[i] == kPosZ) return c.degree(i);
    return -1;
  };
  ASSERT_EQ(degree_of_top(painted), 3);
  chart::CleanupOptions o;
  o.straighten = false;  // the staircase borders stay as painted
  o.fix_degenerate = false;
  const auto st = chart::cleanup_labels(s.V, s.F, labels, o);
  EXPECT_GE(st.pinches, 1);
  int kept = 0, opened = 0;
  for (int f = 0; f < s.F.rows(); ++f) {
    kept += painted[f] == kPosZ && labels[f] == kPosZ;
    opened += good[f] == kPosZ && labels[f] == kNegY;
  }
  EXPECT_GE(kept, top * 9 / 10);
  EXPECT_GT(opened, 0);
  EXPECT_EQ(degree_of_top(labels), 4);
  // Without the pinch rule the +Z chart goes whole.
  auto whole = painted;
  o.pinch_above = 1;
  EXPECT_EQ(chart::cleanup_labels(s.V, s.F, whole, o).pinches, 0);
  EXPECT_EQ(std::count(whole.begin(), whole.end(), kPosZ), 0);
}

TEST(Realize, SplitTetEdgesKeepsVolumeAndOrientation) {
  // Two tets sharing the edge (0, 1); splitting it and another edge of the first tet.
  MatX3d V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.3, 0.3, -1;
  MatX4i T(2, 4);
  T << 0, 1, 2, 3, 0, 2, 1, 4;
  const double before = measure_tets(V, T).min_volume;
  ASSERT_GT(before, 0);
  const auto made = split_tet_edges(T, 5, {{0, 1}, {2, 3}});
  ASSERT_EQ(made.size(), 2u);
  MatX3d W(7, 3);
  W.topRows(5) = V;
  for (int i = 0; i < 2; ++i) W.row(5 + i) = 0.5 * (V.row(made[i].first) + V.row(made[i].second));
  EXPECT_EQ(T.rows(), 6);  // (0,1): 2 tets -> 4; (2,3) is then in both halves of the first -> 6
  double vol = 0, vol0 = tet_volume(V.row(0), V.row(1), V.row(2), V.row(3)) + tet_volume(V.row(0), V.row(2), V.row(1), V.row(4));
  for (int t = 0; t < T.rows(); ++t) {
    const double v = tet_volume(W.row(T(t, 0)), W.row(T(t, 1)), W.row(T(t, 2)), W.row(T(t, 3)));
    EXPECT_GT(v, 0);
    vol += v;
  }
  EXPECT_NEAR(vol, vol0, 1e-15);
}

TEST(Realize, OppositeChartsSharingAPlaneFailWithAReason) {
  auto b = grid_box(3);
  TetMesh tm = tet_mesh_of(b.V, b.F);
  auto labels = chart::label_by_normal(tm.V, tm.boundary);
  for (int f = 0; f < tm.boundary.rows(); ++f) {
    const double x = (tm.V(tm.boundary(f, 0), 0) + tm.V(tm.boundary(f, 1), 0) + tm.V(tm.boundary(f, 2), 0)) / 3;
    if (labels[f] == kPosZ && x < 0.3) labels[f] = kNegZ;  // no cleanup: realize as given
  }
  const auto r = chart::realize_polycube(tm.V, tm.T, tm.boundary, tm.V, labels);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.failure.find("zero thickness"), std::string::npos) << r.failure;
}

TEST(Realize, EdgeVerticesPastACornerAreCounted) {
  // A box's polycube edges as the deformed mesh has them: in order on the box itself; one vertex
  // of the edge along x at y = z = 0 moved past the corner at the origin (x < 0) is counted, as
  // out of order and past a corner, and named (the realization must move it back past the corner).
  auto b = grid_box(4);
  TetMesh tm = tet_mesh_of(b.V, b.F);
  const auto labels = chart::label_by_normal(tm.V, tm.boundary);
  const auto r0 = chart::realize_polycube(tm.V, tm.T, tm.boundary, tm.V, labels);
  EXPECT_TRUE(r0.success) << r0.failure;
  EXPECT_GE(r0.edge_order.vertices, 12 * 3);
  EXPECT_EQ(r0.edge_order.out_of_order, 0);
  EXPECT_EQ(r0.edge_order.past_corner, 0);
  int v = -1, corner = -1;
  for (int i = 0; i < tm.V.rows(); ++i) {
    const Vec3 p = tm.V.row(i).transpose();
    if (p.norm() < 1e-12) corner = i;
    if (std::abs(p.x() - 0.25) < 1e-12 && std::abs(p.y()) < 1e-12 && std::abs(p.z()) < 1e-12) v = i;
  }
  ASSERT_GE(v, 0);
  ASSERT_GE(corner, 0);
  MatX3d D = tm.V;
  D(v, 0) = -0.05;
  const auto r = chart::realize_polycube(tm.V, tm.T, tm.boundary, D, labels);
  EXPECT_EQ(r.edge_order.vertices, r0.edge_order.vertices);
  EXPECT_GE(r.edge_order.out_of_order, 1);
  EXPECT_EQ(r.edge_order.past_corner, 1);
  EXPECT_EQ(r.edge_order.example,
            "vertex " + std::to_string(v) + " past corner " + std::to_string(corner) + " along X");
  // With names (extract_polycube's retries realize a compacted copy): the message keeps the
  // caller's numbering, here vertex i named 1000 + 2 i.
  chart::RealizeOptions named;
  for (int i = 0; i < tm.V.rows(); ++i) named.names.vertices.push_back(1000 + 2 * i);
  named.names.next_vertex = 5000;
  EXPECT_EQ(named.names.vertex(static_cast<int>(tm.V.rows()) + 3), 5003);
  const auto rn = chart::realize_polycube(tm.V, tm.T, tm.boundary, D, labels, named);
  EXPECT_EQ(rn.edge_order.past_corner, 1);
  EXPECT_EQ(rn.edge_order.example, "vertex " + std::to_string(1000 + 2 * v) + " past corner " +
                                       std::to_string(1000 + 2 * corner) + " along X");
}

TEST(Realize, FailureAfterUntanglingReturnsTheStateItReached) {
  // One triangle inside the top face labelled +X (no cleanup): its three vertices would share x
  // and z, so the triangle and its tet collapse onto a line and no start untangles them. The
  // failure comes back with the state reached, in which that triangle does not face +X, so that
  // extract_polycube can relabel it.
  auto b = grid_box(3);
  TetMesh tm = tet_mesh_of(b.V, b.F);
  auto labels = chart::label_by_normal(tm.V, tm.boundary);
  int odd = -1;
  for (int f = 0; f < tm.boundary.rows() && odd < 0; ++f) {
    Vec3 c = Vec3::Zero();
    for (int k = 0; k < 3; ++k) c += tm.V.row(tm.boundary(f, k)).transpose() / 3;
    if (labels[f] == kPosZ && (c.head<2>() - Eigen::Vector2d(0.5, 0.5)).norm() < 0.2) odd = f;
  }
  ASSERT_GE(odd, 0);
  labels[odd] = kPosX;
  const auto r = chart::realize_polycube(tm.V, tm.T, tm.boundary, tm.V, labels);
  EXPECT_FALSE(r.success);
  ASSERT_GT(r.X.rows(), 0);
  ASSERT_EQ(r.X.rows(), r.rest.rows());
  EXPECT_GT(r.inverted, 0);
  EXPECT_GE(r.misoriented_faces, 1);
  const Vec3 N = deform::area_normal(r.X, tm.boundary(odd, 0), tm.boundary(odd, 1), tm.boundary(odd, 2));
  EXPECT_FALSE(N.x() > 1e-12) << "the odd triangle should not face +X";

  // The state reached, written for inspection (--write-failed): the inverted field marks exactly
  // the tets the realization counts, the label field the triangles' labels.
  const std::string path = testing::TempDir() + "failed_polycube.vtk";
  EXPECT_EQ(write_failed_polycube(path, r.rest, r.X, r.T, tm.boundary, labels), r.inverted);
  std::ifstream in(path);
  std::string tok;
  std::map<std::string, std::vector<int>> field;
  while (in >> tok)
    if (tok == "SCALARS") {
      std::string name, type, lut, def;
      int ncomp = 0;
      in >> name >> type >> ncomp >> lut >> def;
      auto& v = field[name];
      for (long i = 0; i < tm.boundary.rows() + r.T.rows(); ++i) {
        int x = 0;
        in >> x;
        v.push_back(x);
      }
    }
  ASSERT_EQ(field["inverted"].size(), static_cast<size_t>(tm.boundary.rows() + r.T.rows()));
  EXPECT_EQ(std::count(field["inverted"].begin(), field["inverted"].end(), 1), r.inverted);
  for (int f = 0; f < tm.boundary.rows(); ++f) EXPECT_EQ(field["inverted"][f], 0);
  ASSERT_EQ(field["label"].size(), field["inverted"].size());
  EXPECT_EQ(field["label"][odd], kPosX);
  for (int f = 0; f < tm.boundary.rows(); ++f) ASSERT_EQ(field["label"][f], labels[f]) << f;
  EXPECT_EQ(field["label"].back(), -1);
}

namespace {

// box_hole (surface edge 0.04) tetrahedralized, deformed and realized from the given start.
// local_first: RealizeOptions::local_first; `hooks` receive the extraction's messages.
std::pair<TetMesh, chart::PolycubeExtraction> box_hole_realized(const std::string& start, int eq17_budget = 300,
                                                                int local_first = chart::RealizeOptions{}.local_first,
                                                                const Hooks& hooks = {}) {
  MeshData m = examples::make("box_hole", 0.04);
  TetMesh tm = tet_mesh_of(m.V, m.F);
  auto d = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  chart::ExtractOptions opt;
  opt.realize.start = start;
  opt.realize.eq17_budget = eq17_budget;
  opt.realize.local_first = local_first;
  auto e = chart::extract_polycube(tm.V, tm.T, tm.boundary, d.X, opt, hooks);
  return {std::move(tm), std::move(e)};
}

}  // namespace

TEST(Realize, Eq17StartIsUntangledOnBoxWithThroughHole) {
  // The relaxation of Eq. 17 inverts tets around the hole; plain ARAP steps left one inverted
  // there. Without the local untangling first, the elliptic untangling (Garanzha et al. 2021)
  // removes them all.
  const auto [tm, e] = box_hole_realized("eq17", 300, -1);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.realized.start, "eq17");
  // More steps than the plain ARAP untangling may take: the elliptic untangling ran.
  EXPECT_GT(e.realized.untangle_iterations, chart::RealizeOptions{}.untangle_iterations);
}

TEST(Realize, LocalUntanglingFirstRepairsTheEq17StartWithoutTheEllipticOne) {
  // The default: the local sweeps around the inverted tets run before the global elliptic
  // untangling, which is not needed here. The result is an exact polycube all the same, with an
  // ARAP distortion within 1% of the elliptic route's.
  std::vector<std::string> messages;
  Hooks hooks;
  hooks.log = [&](LogLevel, const std::string& m) { messages.push_back(m); };
  const auto [tm, e] = box_hole_realized("eq17", 300, chart::RealizeOptions{}.local_first, hooks);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.realized.start, "eq17");
  bool local = false;
  for (const auto& m : messages) {
    EXPECT_EQ(m.find("elliptic untangling"), std::string::npos) << m;
    local = local || m.rfind("local untangling", 0) == 0;
  }
  EXPECT_TRUE(local);
  const auto [tm2, elliptic] = box_hole_realized("eq17", 300, -1);
  EXPECT_LT(std::abs(e.realized.arap - elliptic.realized.arap), 0.01 * elliptic.realized.arap);
}

TEST(Realize, PenaltyStartRealizesBoxWithThroughHoleLikeTheContinuation) {
  // The penalty path alone (plane heights free, gaps penalized ever more strongly): an exact,
  // valid polycube whose ARAP distortion is close to the continuation start's.
  MeshData m = examples::make("box_hole", 0.06);
  TetMesh tm = tet_mesh_of(m.V, m.F);
  const auto d = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  chart::ExtractOptions opt;
  opt.realize.start = "penalty";
  const auto e = chart::extract_polycube(tm.V, tm.T, tm.boundary, d.X, opt);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.realized.start, "penalty");
  EXPECT_GT(e.realized.untangle_iterations, 0);  // its Newton steps
  opt.realize.start = "continuation";
  const auto c = chart::extract_polycube(tm.V, tm.T, tm.boundary, d.X, opt);
  expect_exact_polycube(c, tm);
  EXPECT_EQ(e.charts.corners, c.charts.corners);
  EXPECT_LT(e.realized.arap, 1.05 * c.realized.arap);
}

TEST(Realize, PenaltyStartFindsTheHeightsOfAStronglyPerturbedBox) {
  // Every vertex moved by up to 2.5% of the smallest side: the heights are unknowns of the path,
  // and it lands on the box itself (up to a translation), every tet positive.
  const auto [tm, D] = perturbed_box(5, 0.025);
  ASSERT_EQ(measure_tets(D, tm.T).inverted, 0);
  chart::ExtractOptions opt;
  opt.realize.start = "penalty";
  const auto e = chart::extract_polycube(tm.V, tm.T, tm.boundary, D, opt);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.charts.corners, 8);
  EXPECT_LT(e.realized.arap, 1e-6);
  expect_box_size(e.realized.X);
}

TEST(Realize, Eq17StartPastItsBudgetDoesNotCompeteWithASuccessfulContinuation) {
  // box_hole's eq17 start needs the elliptic untangling when the local one does not run first
  // (test above), so with a budget of 0 it is past it: "auto" must then give the continuation
  // start's result, whichever thread finishes first, and the same bits on every run. (Alone, a
  // start's factorizations use both BLAS threads, beside the other one: hence 1e-6, as in the
  // test above.)
  const auto [tm, cont] = box_hole_realized("continuation", 300, -1);
  expect_exact_polycube(cont, tm);
  MatX3d first;
  for (int run = 0; run < 2; ++run) {
    const auto [tm2, e] = box_hole_realized("auto", 0, -1);
    expect_exact_polycube(e, tm2);
    EXPECT_EQ(e.realized.start, "continuation");
    EXPECT_NEAR(e.realized.arap, cont.realized.arap, 1e-9 * cont.realized.arap);
    EXPECT_LE((e.realized.X - cont.realized.X).cwiseAbs().maxCoeff(), 1e-6);
    if (run == 0)
      first = e.realized.X;
    else
      EXPECT_EQ((e.realized.X - first).cwiseAbs().maxCoeff(), 0.0);
  }
  // Without a budget the eq17 start competes again and wins here (lower ARAP), as before.
  const auto [tm3, eq] = box_hole_realized("eq17", 300, -1);
  ASSERT_LT(eq.realized.arap, cont.realized.arap);
  const auto [tm4, any] = box_hole_realized("auto", -1, -1);
  EXPECT_EQ(any.realized.start, "eq17");
  // Side by side, the BLAS keeps one thread throughout (set_blas_threads), alone it has two: the
  // factorizations round differently (1.2e-9 relative on an AVX2 machine with the ARAP iterations'
  // tolerance at 1e-6), and the iterations may then stop one step apart, a step that lowers the
  // energy by less than the tolerance (1.7e-7 apart with 1e-5).
  EXPECT_NEAR(any.realized.arap, eq.realized.arap, chart::RealizeOptions{}.volume_tolerance * eq.realized.arap);
}

TEST(Chart, CollapsedTrianglesTakeTheirNeighboursLabel) {
  // A flat 6 x 6 grid labelled +Z, except the strip of triangles between rows 2 and 3, labelled
  // +X, which the "deformation" squeezes to zero width (row 3 moved onto row 2): its labels come
  // from the reliable neighbours, +Z.
  const int n = 6;
  MatX3d rest((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) rest.row(j * (n + 1) + i) = Vec3(i, j, 0).transpose();
  MatX3i F(2 * n * n, 3);
  std::vector<int> labels(F.rows(), 4);
  for (int j = 0, f = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      F.row(f) = Eigen::RowVector3i(a, b, c);
      if (j == 2) labels[f] = 0;
      ++f;
      F.row(f) = Eigen::RowVector3i(a, c, d);
      if (j == 2) labels[f] = 0;
      ++f;
    }
  MatX3d deformed = rest;
  for (int i = 0; i <= n; ++i) deformed(3 * (n + 1) + i, 1) = 2.0 + 1e-6;
  std::vector<int> l = labels;
  EXPECT_EQ(chart::relabel_collapsed(rest, deformed, F, l), 2 * n);
  for (int f = 0; f < F.rows(); ++f) EXPECT_EQ(l[f], 4) << "triangle " << f;
  // Without collapse nothing changes.
  l = labels;
  EXPECT_EQ(chart::relabel_collapsed(rest, rest, F, l), 0);
  EXPECT_EQ(l, labels);
}

TEST(Realize, AutoKeepsTheBetterOfTheTwoStartsRunSideBySide) {
  // "auto" runs the continuation and Eq. 17 starts on two threads; the result must be the one
  // each start gives alone, the lower ARAP distortion winning.
  auto s = sphere(3, Vec3(0, 0, 0), 1.0);
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  auto d = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  chart::ExtractOptions opt;
  double arap[2];
  MatX3d X[2];
  const char* names[2] = {"continuation", "eq17"};
  for (int i = 0; i < 2; ++i) {
    opt.realize.start = names[i];
    const auto e = chart::extract_polycube(tm.V, tm.T, tm.boundary, d.X, opt);
    expect_exact_polycube(e, tm);
    arap[i] = e.realized.arap;
    X[i] = e.realized.X;
  }
  opt.realize.start = "auto";
  const auto e = chart::extract_polycube(tm.V, tm.T, tm.boundary, d.X, opt);
  expect_exact_polycube(e, tm);
  const int best = arap[1] < arap[0] ? 1 : 0;
  EXPECT_EQ(e.realized.start, names[best]);
  EXPECT_NEAR(e.realized.arap, arap[best], 1e-9 * arap[best]);
  EXPECT_LE((e.realized.X - X[best]).cwiseAbs().maxCoeff(), 1e-6);
}

namespace {

// Moves vertex v of X through the far side of its star: past its farthest neighbour by `beyond`
// times their distance.
void push_through_star(const MatX4i& T, int v, double beyond, MatX3d& X) {
  const Vec3 p = X.row(v).transpose();
  Vec3 far = p;
  for (int t = 0; t < T.rows(); ++t)
    for (int j = 0; j < 4; ++j)
      if (T(t, j) == v)
        for (int k = 0; k < 4; ++k)
          if ((Vec3(X.row(T(t, k)).transpose()) - p).norm() > (far - p).norm()) far = X.row(T(t, k)).transpose();
  X.row(v) = (far + beyond * (far - p)).transpose();
}

}  // namespace

TEST(Realize, PreviousStartRepairsAFewInvertedTetsOfAnEarlierResult) {
  // The retries of extract_polycube start from the failed realization's state ("previous"): on
  // or near the planes, a few tets inverted. Here: box_hole's exact polycube with one interior
  // vertex pushed through its star's far side and the plane vertices nudged off their planes.
  // The previous start lands them, untangles locally and minimizes ARAP: the same polycube.
  const auto [tm, e] = box_hole_realized("continuation");
  expect_exact_polycube(e, tm);
  const int n = static_cast<int>(tm.V.rows());
  MatX3d start = e.realized.X.topRows(n);
  std::vector<char> on_boundary(n, 0);
  for (int f = 0; f < tm.boundary.rows(); ++f)
    for (int j = 0; j < 3; ++j) on_boundary[tm.boundary(f, j)] = 1;
  // The interior vertex with the most tets, moved to twice the distance of its farthest neighbour.
  std::vector<int> valence(n, 0);
  for (int t = 0; t < tm.T.rows(); ++t)
    for (int j = 0; j < 4; ++j) valence[tm.T(t, j)]++;
  int v = -1;
  for (int i = 0; i < n; ++i)
    if (!on_boundary[i] && (v < 0 || valence[i] > valence[v])) v = i;
  ASSERT_GE(v, 0);
  push_through_star(tm.T, v, 1.0, start);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1e-4, 1e-4);
  for (int i = 0; i < n; ++i)
    if (on_boundary[i])
      for (int k = 0; k < 3; ++k) start(i, k) += u(rng);
  ASSERT_GT(measure_tets(start, tm.T).inverted, 0);
  chart::RealizeOptions ro;
  ro.start = "previous";
  const auto r = chart::realize_polycube(tm.V, tm.T, tm.boundary, start, e.labels, ro);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(r.start, "previous");
  EXPECT_EQ(r.inverted, 0);
  EXPECT_EQ(r.planarity_error, 0.0);
  EXPECT_EQ(max_planarity_spread(r.X, tm.boundary, e.labels), 0.0);
  EXPECT_EQ(measure_tets(r.X, r.T).inverted, 0);
  EXPECT_NEAR(r.arap, e.realized.arap, 0.02 * e.realized.arap);
  EXPECT_EQ(r.planes[0], e.realized.planes[0]);
  EXPECT_EQ(r.planes[1], e.realized.planes[1]);
  EXPECT_EQ(r.planes[2], e.realized.planes[2]);
}

namespace {

std::set<std::array<int, 3>> sorted_faces(const MatX3i& B) {
  std::set<std::array<int, 3>> out;
  for (int f = 0; f < B.rows(); ++f) {
    std::array<int, 3> a{B(f, 0), B(f, 1), B(f, 2)};
    std::sort(a.begin(), a.end());
    out.insert(a);
  }
  return out;
}

}  // namespace

TEST(Chart, SlimTriangleCollapseKeepsAValidTetMeshOnBothSides) {
  // The slim-triangle collapse on a sphere deformed into a polycube.
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  const auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  // Smallest angle (degrees) per triangle.
  auto angles = [](const MatX3d& X, const MatX3i& B) {
    std::vector<double> out(B.rows());
    for (int f = 0; f < B.rows(); ++f) {
      double worst = -1;
      for (int k = 0; k < 3; ++k) {
        const Vec3 a = X.row(B(f, k)), b = X.row(B(f, (k + 1) % 3)), c = X.row(B(f, (k + 2) % 3));
        worst = std::max(worst, (b - a).normalized().dot((c - a).normalized()));
      }
      out[f] = std::acos(std::clamp(worst, -1.0, 1.0)) * 180 / M_PI;
    }
    return out;
  };
  // "Slim": the most slender 5% of the triangles (a sphere's stay fairly round).
  std::vector<double> a0 = angles(r.X, tm.boundary);
  std::sort(a0.begin(), a0.end());
  const double limit = a0[a0.size() / 20];
  auto slim = [&](const MatX3d& X, const MatX3i& B) {
    const auto a = angles(X, B);
    return static_cast<int>(std::count_if(a.begin(), a.end(), [&](double x) { return x < limit; }));
  };
  const int before = slim(r.X, tm.boundary);
  ASSERT_GT(before, 0);
  MatX3d rest = tm.V, X = r.X;
  MatX4i T = tm.T;
  MatX3i B = tm.boundary;
  std::vector<int> merged;
  int left = -1;
  const int made = chart::collapse_slim_triangles(rest, X, T, B, limit, merged, 10, &left);
  ASSERT_GT(made, 0);
  EXPECT_GE(left, 0);
  EXPECT_LT(slim(X, B), before);
  // Two triangles per collapse; the merged vertices referenced by nothing and sitting on their
  // partner at rest and in X; the others where they were, or on the collapsed edge at rest.
  EXPECT_EQ(B.rows(), tm.boundary.rows() - 2 * made);
  int merged_count = 0;
  for (int v = 0; v < tm.V.rows(); ++v) {
    if (merged[v] < 0) continue;
    ++merged_count;
    EXPECT_LT(merged[merged[v]], 0);
    EXPECT_EQ(rest.row(v), rest.row(merged[v]));
    EXPECT_EQ(X.row(v), X.row(merged[v]));
  }
  EXPECT_EQ(merged_count, made);
  for (int t = 0; t < T.rows(); ++t)
    for (int j = 0; j < 4; ++j) EXPECT_LT(merged[T(t, j)], 0);
  // Every tet positive at rest and in X, the tets' boundary exactly B, a closed genus-0 surface.
  for (const MatX3d* P : {&rest, &X}) {
    const auto q = measure_tets(*P, T);
    EXPECT_EQ(q.inverted + q.zero_volume, 0);
  }
  EXPECT_EQ(sorted_faces(tet_boundary(T)), sorted_faces(B));
  std::set<int> used;
  for (int f = 0; f < B.rows(); ++f)
    for (int j = 0; j < 3; ++j) used.insert(B(f, j));
  EXPECT_EQ(static_cast<int>(used.size()) - static_cast<int>(unique_edges(B).size()) + static_cast<int>(B.rows()), 2);
  // At rest every vertex stays where it was.
  for (int v = 0; v < tm.V.rows(); ++v) {
    if (merged[v] < 0) {
      EXPECT_EQ(rest.row(v), tm.V.row(v)) << "vertex " << v;
    }
  }
}

TEST(Chart, CollapseTetEdgeKeepsAValidTetMeshAndItsBoundary) {
  auto b = grid_box(4);
  TetMesh tm = tet_mesh_of(b.V, b.F);
  auto labels = chart::label_by_normal(tm.V, tm.boundary);
  // A boundary edge inside the top face, away from its border, whose collapse keeps every tet
  // positive (on a flat face many would leave a tet with three collinear vertices: refused).
  int keep = -1, drop = -1;
  auto inner = [&](int w) {
    const Vec3 p = tm.V.row(w);
    return p.z() > 1 - 1e-12 && p.x() > 0.2 && p.x() < 0.8 && p.y() > 0.2 && p.y() < 0.8;
  };
  for (auto [u, v] : unique_edges(tm.boundary)) {
    if (!inner(u) || !inner(v)) continue;
    MatX4i T1 = tm.T;
    MatX3i B1 = tm.boundary;
    std::vector<int> L1 = labels;
    std::string why;
    if (chart::collapse_tet_edge(tm.V, tm.V, T1, B1, L1, u, v, &why)) {
      // ...and in the other direction too (used below).
      MatX4i T2 = tm.T;
      MatX3i B2 = tm.boundary;
      std::vector<int> L2 = labels;
      if (!chart::collapse_tet_edge(tm.V, tm.V, T2, B2, L2, v, u, &why)) continue;
      keep = u, drop = v;
      break;
    }
    EXPECT_EQ(why, "a tet would turn over at rest");
  }
  ASSERT_GE(keep, 0);
  MatX4i T = tm.T;
  MatX3i B = tm.boundary;
  std::vector<int> L = labels;
  // Not an edge of the boundary: refused, nothing changed.
  int far = -1;
  for (int v = 0; v < tm.V.rows() && far < 0; ++v)
    if (tm.V(v, 2) < 1e-12 && (tm.V.row(v) - tm.V.row(keep)).norm() > 0.9) far = v;
  ASSERT_GE(far, 0);
  std::string why;
  EXPECT_FALSE(chart::collapse_tet_edge(tm.V, tm.V, T, B, L, keep, far, &why));
  EXPECT_EQ(why, "not an edge of the boundary");
  EXPECT_EQ(T, tm.T);
  EXPECT_EQ(B, tm.boundary);
  // A deformed state in which the collapse would turn a tet over: refused.
  MatX3d D = tm.V;
  D.row(keep) += Eigen::RowVector3d(0, 0, -0.9);
  EXPECT_FALSE(chart::collapse_tet_edge(tm.V, D, T, B, L, keep, drop, &why));
  EXPECT_EQ(why, "a tet would turn over in the deformed mesh");
  EXPECT_EQ(T, tm.T);
  {
    // Allowed to move in the deformed mesh, the merged vertex takes the other end's position or
    // the midpoint, and every tet of the deformed mesh stays positive.
    MatX4i T2 = T;
    MatX3i B2 = B;
    std::vector<int> L2 = L;
    Vec3 at(9, 9, 9);
    ASSERT_TRUE(chart::collapse_tet_edge(tm.V, D, T2, B2, L2, keep, drop, &why, nullptr, &at));
    const Vec3 mid = 0.5 * (D.row(keep) + D.row(drop)).transpose();
    EXPECT_TRUE((at - Vec3(D.row(drop).transpose())).norm() < 1e-15 || (at - mid).norm() < 1e-15);
    EXPECT_GT((at - Vec3(D.row(keep).transpose())).norm(), 0.1);
    MatX3d D2 = D;
    D2.row(keep) = at.transpose();
    for (int t = 0; t < T2.rows(); ++t) {
      const Vec3 a = D2.row(T2(t, 0)), b = D2.row(T2(t, 1)), c = D2.row(T2(t, 2)), d = D2.row(T2(t, 3));
      EXPECT_GT((b - a).dot((c - a).cross(d - a)), 0) << "tet " << t;
    }
    int both = 0;  // tets holding the edge: they go
    for (int t = 0; t < T.rows(); ++t) {
      bool hk = false, hd = false;
      for (int j = 0; j < 4; ++j) hk |= T(t, j) == keep, hd |= T(t, j) == drop;
      both += hk && hd;
    }
    EXPECT_GT(both, 0);
    EXPECT_EQ(T2.rows(), T.rows() - both);
  }
  // The collapse itself.
  int ring = 0;
  for (int t = 0; t < T.rows(); ++t) {
    bool hk = false, hd = false;
    for (int j = 0; j < 4; ++j) hk |= T(t, j) == keep, hd |= T(t, j) == drop;
    ring += hk && hd;
  }
  std::vector<int> removed;
  ASSERT_TRUE(chart::collapse_tet_edge(tm.V, tm.V, T, B, L, keep, drop, nullptr, &removed));
  ASSERT_EQ(removed.size(), 2u);
  for (int f : removed) {
    int hits = 0;
    for (int j = 0; j < 3; ++j) hits += tm.boundary(f, j) == keep || tm.boundary(f, j) == drop;
    EXPECT_EQ(hits, 2) << "removed row " << f << " is not a triangle of the edge";
  }
  EXPECT_EQ(T.rows(), tm.T.rows() - ring);
  EXPECT_EQ(B.rows(), tm.boundary.rows() - 2);
  EXPECT_EQ(static_cast<int>(L.size()), B.rows());
  for (int t = 0; t < T.rows(); ++t)
    for (int j = 0; j < 4; ++j) EXPECT_NE(T(t, j), drop);
  for (int f = 0; f < B.rows(); ++f)
    for (int j = 0; j < 3; ++j) EXPECT_NE(B(f, j), drop);
  // Every tet positive, the tets' boundary is exactly B, still a closed surface of genus 0
  // (Euler characteristic 2 over the referenced vertices), and the labels follow their triangles.
  const auto q = measure_tets(tm.V, T);
  EXPECT_EQ(q.inverted, 0);
  EXPECT_EQ(q.zero_volume, 0);
  EXPECT_EQ(sorted_faces(tet_boundary(T)), sorted_faces(B));
  std::set<int> used;
  for (int f = 0; f < B.rows(); ++f)
    for (int j = 0; j < 3; ++j) used.insert(B(f, j));
  const int edges = static_cast<int>(unique_edges(B).size());
  EXPECT_EQ(static_cast<int>(used.size()) - edges + static_cast<int>(B.rows()), 2);
  const auto relabelled = chart::label_by_normal(tm.V, B);
  EXPECT_EQ(relabelled, L);
}

namespace {

// A fan of 12 triangles on the plane z = 0 (a = (0,0), b = (1,0), p1 and p2 between them, a
// hexagonal rim around) coned to an apex o = (0.5, 0, -1): a closed tet mesh of 12 tets.
struct Fan {
  enum Vertex { a, b, p1, p2, y, yr, yb, ybr, l, r, o };
  MatX3d V;
  MatX4i T;
  MatX3i B;
};
Fan make_fan(const Vec3& at_p1, const Vec3& at_p2) {
  using enum Fan::Vertex;
  Fan f;
  f.V.resize(11, 3);
  f.V << 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0.2, 0.5, 0, 0.8, 0.5, 0, 0.2, -0.5, 0, 0.8, -0.5, 0, -0.5, 0, 0, 1.5,
      0, 0, 0.5, 0, -1;
  f.V.row(p1) = at_p1.transpose();
  f.V.row(p2) = at_p2.transpose();
  const std::vector<std::array<int, 3>> top{{a, b, p1},  {a, p1, y},  {a, y, l},    {a, l, yb},
                                            {a, yb, p2}, {a, p2, b},  {b, yr, p1},  {b, r, yr},
                                            {b, ybr, r}, {b, p2, ybr}, {p1, yr, y}, {p2, yb, ybr}};
  const std::vector<std::array<int, 2>> rim{{y, l}, {l, yb}, {yb, ybr}, {ybr, r}, {r, yr}, {yr, y}};
  f.T.resize(static_cast<Eigen::Index>(top.size()), 4);
  f.B.resize(static_cast<Eigen::Index>(top.size() + rim.size()), 3);
  for (size_t i = 0; i < top.size(); ++i) {
    // Counter-clockwise seen from above: the tet (i, k, j, apex) is positive.
    const auto& t = top[i];
    f.T.row(i) << t[0], t[2], t[1], o;
    f.B.row(i) << t[0], t[1], t[2];
  }
  for (size_t i = 0; i < rim.size(); ++i) f.B.row(top.size() + i) << rim[i][1], rim[i][0], o;
  return f;
}

struct Collapsed {
  MatX4i T;
  MatX3i B;
  Vec3 at, rest_at;
};
// The collapse of the fan's edge (keep, drop) with the deformed state D: refused with `expected`
// (nothing changed) unless the caller will untangle (the deformed mesh; the rest one too with
// rest_tangle), then made.
Collapsed refused_unless_tangle_allowed(const Fan& fan, const MatX3d& D, int keep, int drop, const std::string& expected,
                                        bool rest_tangle) {
  Collapsed c{fan.T, fan.B, Vec3::Zero(), Vec3::Zero()};
  std::vector<int> labels(fan.B.rows(), 4);
  std::string why;
  EXPECT_FALSE(chart::collapse_tet_edge(fan.V, D, c.T, c.B, labels, keep, drop, &why, nullptr, &c.at, &c.rest_at));
  EXPECT_EQ(why, expected);
  EXPECT_EQ(c.T, fan.T);
  EXPECT_TRUE(chart::collapse_tet_edge(fan.V, D, c.T, c.B, labels, keep, drop, &why, nullptr, &c.at, &c.rest_at, true,
                                       rest_tangle))
      << why;
  EXPECT_EQ(c.T.rows(), fan.T.rows() - 2);
  EXPECT_EQ(c.B.rows(), fan.B.rows() - 2);
  return c;
}

}  // namespace

// A fan of 12 triangles on the plane z = 0 coned to an apex below: a closed tet mesh (12 tets)
// whose top edge a-b can be collapsed onto neither end (each end's star has a triangle the other
// end lies beyond: a at x = 0, b at x = 1, their neighbours y at x = 0.2 and y' at x = 0.8 with
// p1 = (0.5, 0.1) between) but onto its midpoint.
TEST(Chart, CollapseTetEdgeMayMoveTheMergedVertexToTheMidpointAtRest) {
  using enum Fan::Vertex;
  const Fan fan = make_fan(Vec3(0.5, 0.1, 0), Vec3(0.5, -0.1, 0));
  const MatX3d& V = fan.V;
  const MatX4i& T = fan.T;
  const MatX3i& B = fan.B;
  ASSERT_EQ(measure_tets(V, T).inverted, 0);
  ASSERT_EQ(sorted_faces(tet_boundary(T)), sorted_faces(B));
  const std::vector<int> labels(B.rows(), 4);
  for (auto [keep, drop] : {std::pair{int(a), int(b)}, std::pair{int(b), int(a)}}) {
    // Onto either end: refused, nothing changed.
    MatX4i T1 = T;
    MatX3i B1 = B;
    std::vector<int> L1 = labels;
    std::string why;
    EXPECT_FALSE(chart::collapse_tet_edge(V, V, T1, B1, L1, keep, drop, &why));
    EXPECT_EQ(why, "a tet would turn over at rest");
    EXPECT_EQ(T1, T);
    // Allowed to move at rest: onto the midpoint, every remaining tet positive there.
    Vec3 at, rest_at(9, 9, 9);
    ASSERT_TRUE(chart::collapse_tet_edge(V, V, T1, B1, L1, keep, drop, &why, nullptr, &at, &rest_at)) << why;
    EXPECT_LT((rest_at - Vec3(0.5, 0, 0)).norm(), 1e-15);
    EXPECT_EQ(T1.rows(), T.rows() - 2);
    EXPECT_EQ(B1.rows(), B.rows() - 2);
    MatX3d V1 = V;
    V1.row(keep) = rest_at.transpose();
    V1.row(drop).setConstant(1e3);  // referenced by nothing any more
    const auto q = measure_tets(V1, T1);
    EXPECT_EQ(q.inverted, 0);
    EXPECT_EQ(q.zero_volume, 0);
    EXPECT_EQ(sorted_faces(tet_boundary(T1)), sorted_faces(B1));
  }
  // A deformed state in which no place of the merged vertex keeps its star positive (here the
  // mirror image: every tet is turned over): refused, unless the caller will untangle it, in
  // which case the merged vertex takes the deformed midpoint.
  MatX3d D = V;
  D.col(0) *= -1;
  const Collapsed c = refused_unless_tangle_allowed(fan, D, a, b, "a tet would turn over in the deformed mesh", false);
  EXPECT_LT((c.at - Vec3(-0.5, 0, 0)).norm(), 1e-15);
}

TEST(Chart, CollapseTetEdgeRefusedAtRestEverywhereOnTheEdgeMayTangleForTheCallerToUntangle) {
  // The fan of the test above with p1 and p2 moved (p1 towards a, p2 towards b): no place on the
  // edge (ends, midpoint, quarter points) keeps every tet positive at rest. With rest_may_tangle
  // the collapse is made with the merged vertex at the midpoint, for the caller to untangle the
  // rest mesh's interior there (here every vertex is on the boundary, so the test stops at that).
  using enum Fan::Vertex;
  const Fan fan = make_fan(Vec3(0.2, 0.25, 0), Vec3(0.72, -0.22, 0));
  ASSERT_EQ(measure_tets(fan.V, fan.T).inverted, 0);
  for (auto [keep, drop] : {std::pair{int(a), int(b)}, std::pair{int(b), int(a)}}) {
    const Collapsed c = refused_unless_tangle_allowed(fan, fan.V, keep, drop, "a tet would turn over at rest", true);
    EXPECT_LT((c.rest_at - Vec3(0.5, 0, 0)).norm(), 1e-15);
    EXPECT_EQ(sorted_faces(tet_boundary(c.T)), sorted_faces(c.B));
    MatX3d V1 = fan.V;
    V1.row(keep) = c.rest_at.transpose();
    EXPECT_GT(measure_tets(V1, c.T).inverted + measure_tets(V1, c.T).zero_volume, 0);
  }
}

namespace {
// Local untangling tests: every axis of the boundary vertices fixed, and the first vertex that is not.
std::array<std::vector<char>, 3> boundary_fixed(const TetMesh& tm) {
  std::array<std::vector<char>, 3> fixed;
  for (auto& f : fixed) f.assign(tm.V.rows(), 0);
  for (int f = 0; f < tm.boundary.rows(); ++f)
    for (int j = 0; j < 3; ++j)
      for (auto& x : fixed) x[tm.boundary(f, j)] = 1;
  return fixed;
}
int first_interior(const std::array<std::vector<char>, 3>& fixed) {
  for (size_t i = 0; i < fixed[0].size(); ++i)
    if (!fixed[0][i]) return static_cast<int>(i);
  return -1;
}
}  // namespace

TEST(Realize, NearlyFlatTetsOfAValidMapAreOpened) {
  // An interior vertex of a box's tet mesh moved to 1e-6 of the way from a face of its star: that
  // tet is nearly flat but positive. The local sweeps with flat = 1e-3 open it (volume ratio above
  // 1e-3 of the mean), turn no tet over and leave the fixed boundary where it was.
  auto b = grid_box(3);
  TetMesh tm = tet_mesh_of(b.V, b.F);
  const int n = static_cast<int>(tm.V.rows());
  const auto fixed = boundary_fixed(tm);
  const int v = first_interior(fixed);
  ASSERT_GE(v, 0) << "no interior vertex";
  const deform::ArapRest reference = deform::ArapRest::build(tm.V, tm.T);
  auto min_ratio = [&](const MatX3d& X) {
    double m = std::numeric_limits<double>::infinity();
    for (int t = 0; t < tm.T.rows(); ++t) {
      Eigen::Matrix3d Ds;
      for (int k = 0; k < 3; ++k) Ds.col(k) = (X.row(tm.T(t, k + 1)) - X.row(tm.T(t, 0))).transpose();
      m = std::min(m, (Ds * reference.Dm_inv[t]).determinant());
    }
    return m;
  };
  MatX3d X = tm.V;
  for (int t = 0; t < tm.T.rows(); ++t) {
    int at = -1;
    for (int j = 0; j < 4; ++j)
      if (tm.T(t, j) == v) at = j;
    if (at < 0) continue;
    Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
    for (int j = 0; j < 4; ++j)
      if (j != at) c += tm.V.row(tm.T(t, j)) / 3.0;
    X.row(v) = c + 1e-6 * (tm.V.row(v) - c);
    break;
  }
  ASSERT_EQ(measure_tets(X, tm.T).inverted, 0);
  ASSERT_LT(min_ratio(X), 1e-5);
  int left = -1;
  chart::untangle_tets_locally(reference, tm.T, fixed, X, left, 3, 30, 1e-3);
  EXPECT_EQ(left, 0);
  EXPECT_EQ(measure_tets(X, tm.T).inverted, 0);
  EXPECT_GT(min_ratio(X), 1e-3);
  for (int i = 0; i < n; ++i)
    if (fixed[0][i]) {
      EXPECT_EQ((X.row(i) - tm.V.row(i)).norm(), 0.0) << "boundary vertex " << i << " moved";
    }
}

TEST(Realize, LocalUntanglingWithAPerTetReferenceKeepsTheBoundary) {
  // The rest mesh's repair after such a collapse: each tet's reference is its own shape before
  // (a soup of tets), the boundary vertices fixed, the interior ones free. An interior vertex of
  // a box's tet mesh pushed through its star: untangled, the boundary unchanged.
  auto b = grid_box(3);
  TetMesh tm = tet_mesh_of(b.V, b.F);
  const int n = static_cast<int>(tm.V.rows());
  MatX3d soup(4 * tm.T.rows(), 3);
  MatX4i ST(tm.T.rows(), 4);
  for (int t = 0; t < tm.T.rows(); ++t)
    for (int j = 0; j < 4; ++j) soup.row(4 * t + j) = tm.V.row(tm.T(t, j)), ST(t, j) = 4 * t + j;
  const deform::ArapRest reference = deform::ArapRest::build(soup, ST);
  const auto fixed = boundary_fixed(tm);
  const int v = first_interior(fixed);
  ASSERT_GE(v, 0) << "no interior vertex";
  MatX3d X = tm.V;
  push_through_star(tm.T, v, 0.5, X);
  ASSERT_GT(measure_tets(X, tm.T).inverted, 0);
  int left = -1;
  chart::untangle_tets_locally(reference, tm.T, fixed, X, left);
  EXPECT_EQ(left, 0);
  EXPECT_EQ(measure_tets(X, tm.T).inverted, 0);
  EXPECT_EQ(measure_tets(X, tm.T).zero_volume, 0);
  for (int i = 0; i < n; ++i)
    if (fixed[0][i]) {
      EXPECT_EQ((X.row(i) - tm.V.row(i)).norm(), 0.0) << "boundary vertex " << i << " moved";
    }
}

TEST(Realize, GivenPolycubeMapIsLabelledFlattenedAndChecked) {
  auto b = grid_box(3, Vec3(0, 0, 0), Vec3(1, 2, 3));
  TetMesh tm = tet_mesh_of(b.V, b.F);
  // The box scaled and moved is its own polycube: 6 charts, 8 corners, ARAP distortion of the scale.
  MatX3d X = 2 * tm.V;
  X.col(0).array() += 5;
  // Coordinates written with few digits: each plane within 1e-7 of the diagonal; put back exactly.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1e-7, 1e-7);
  for (int v = 0; v < X.rows(); ++v)
    for (int k = 0; k < 3; ++k) X(v, k) += u(rng);
  const auto e = chart::polycube_from_map(tm.V, tm.T, tm.boundary, X);
  expect_exact_polycube(e, tm);
  EXPECT_EQ(e.realized.start, "given");
  EXPECT_EQ(e.charts.charts, 6);
  EXPECT_EQ(e.charts.corners, 8);
  EXPECT_TRUE(e.charts.valid);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(e.realized.planes[k], 2);
  EXPECT_NEAR(e.realized.isometric.mean, 2.0, 1e-5);
  // Labels follow the normals: the face at x = min is -X (code 1), at z = max +Z (code 4).
  for (int f = 0; f < tm.boundary.rows(); ++f) {
    const Vec3 c = (tm.V.row(tm.boundary(f, 0)) + tm.V.row(tm.boundary(f, 1)) + tm.V.row(tm.boundary(f, 2))) / 3;
    if (c.x() < 1e-9) {
      EXPECT_EQ(e.labels[f], 1);
    }
    if (c.z() > 3 - 1e-9) {
      EXPECT_EQ(e.labels[f], 4);
    }
  }
  // A vertex pushed off its plane by 1e-3 of the diagonal: not a polycube, named.
  int corner = -1;
  for (int v = 0; v < tm.V.rows() && corner < 0; ++v)
    if (tm.V.row(v).norm() == 0) corner = v;
  ASSERT_GE(corner, 0);
  MatX3d bent = 2 * tm.V;
  bent(corner, 2) -= 1e-3 * (bent.colwise().maxCoeff() - bent.colwise().minCoeff()).norm();
  try {
    chart::polycube_from_map(tm.V, tm.T, tm.boundary, bent);
    ADD_FAILURE() << "a bent polycube was accepted";
  } catch (const Error& err) {
    EXPECT_EQ(err.kind(), ErrorKind::InvalidMesh);
    EXPECT_NE(std::string(err.what()).find("vertex " + std::to_string(corner)), std::string::npos) << err.what();
  }
  // A mirrored map turns every tet over.
  MatX3d mirrored = tm.V;
  mirrored.col(0) *= -1;
  EXPECT_THROW(chart::polycube_from_map(tm.V, tm.T, tm.boundary, mirrored), Error);
  // Another vertex count.
  EXPECT_THROW(chart::polycube_from_map(tm.V, tm.T, tm.boundary, X.topRows(X.rows() - 1)), Error);
}

TEST(Chart, SplittingEdgesLetsACollapseMeetTheLinkCondition) {
  // In Delaunay tet meshes of the examples a few boundary edges cannot collapse because a tet at
  // each end stands on one triangle (they would coincide: the link condition fails; tet/hand and
  // humanoid stall at such edges). Splitting the interior edges from the dropped end to the shared
  // vertices (and chords between the two ends' links, whose midpoints are split off in turn) keeps
  // the volume, its boundary and every tet positive, and lets every such collapse through the link
  // checks (at rest the merged vertex may still need the caller's untangling). With the vertex
  // splits alone 4 of box_hole's 6 and 3 of rocker's 6 passed.
  for (const char* name : {"l_bracket", "box_hole", "rocker"}) {
  SCOPED_TRACE(name);
  const MeshData l = examples::make(name, 0.04);
  const TetMesh tm = tet_mesh_of(l.V, l.F);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  int found = 0, passed = 0;
  double volume = 0;
  for (int t = 0; t < tm.T.rows(); ++t)
    volume += tet_volume(tm.V.row(tm.T(t, 0)).transpose(), tm.V.row(tm.T(t, 1)).transpose(),
                         tm.V.row(tm.T(t, 2)).transpose(), tm.V.row(tm.T(t, 3)).transpose());
  auto vol = [](const MatX3d& V, const MatX4i& T, int t) {
    return tet_volume(V.row(T(t, 0)).transpose(), V.row(T(t, 1)).transpose(), V.row(T(t, 2)).transpose(),
                      V.row(T(t, 3)).transpose());
  };
  for (auto [a, b] : unique_edges(tm.boundary)) {
    MatX4i T = tm.T;
    MatX3i B = tm.boundary;
    std::vector<int> L = labels;
    std::string why;
    Vec3 at, rest_at;
    if (chart::collapse_tet_edge(tm.V, tm.V, T, B, L, a, b, &why, nullptr, &at, &rest_at) ||
        why != "two tets would coincide")
      continue;
    ++found;
    MatX3d R = tm.V, D = tm.V;
    const auto parents = chart::split_edges_for_collapse(R, D, T, B, a, b);
    ASSERT_FALSE(parents.empty()) << a << "-" << b;
    ASSERT_EQ(R.rows(), tm.V.rows() + static_cast<Eigen::Index>(parents.size()));
    for (size_t i = 0; i < parents.size(); ++i) {
      ASSERT_LT(std::max(parents[i].first, parents[i].second), tm.V.rows() + static_cast<Eigen::Index>(i));
      EXPECT_EQ((R.row(tm.V.rows() + i) - 0.5 * (R.row(parents[i].first) + R.row(parents[i].second))).norm(), 0.0);
    }
    EXPECT_EQ(measure_tets(R, T).inverted + measure_tets(R, T).zero_volume, 0);
    double v2 = 0;
    for (int t = 0; t < T.rows(); ++t) v2 += vol(R, T, t);
    EXPECT_NEAR(v2, volume, 1e-12 * volume);
    EXPECT_EQ(sorted_faces(tet_boundary(T)), sorted_faces(B));
    if (!chart::collapse_tet_edge(R, D, T, B, L, a, b, &why, nullptr, &at, &rest_at, true, true)) {
      ADD_FAILURE() << "edge " << a << "-" << b << " still refused after " << parents.size() << " splits: " << why;
      continue;
    }
    ++passed;
    EXPECT_EQ(sorted_faces(tet_boundary(T)), sorted_faces(B));
    std::set<std::array<int, 4>> distinct;
    for (int t = 0; t < T.rows(); ++t) {
      std::array<int, 4> q{T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
      std::sort(q.begin(), q.end());
      EXPECT_TRUE(distinct.insert(q).second) << "two tets coincide";
    }
  }
  EXPECT_GT(found, 0) << "no boundary edge refused for the link condition: the test needs one";
  EXPECT_EQ(passed, found);
  }
}

// Isometric distortion max(s1, 1/s3) with known answers: a tet scaled by 2 along x has 2; one
// squashed to 1e-4 of its height along z has 1e4 and counts as nearly flat; one at 0.01 does not.
TEST(Chart, IsometricDistortionCountsNearlyFlatTets) {
  MatX3d rest(5, 3);
  rest << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1;
  MatX4i T(2, 4);
  T << 0, 1, 2, 3, 0, 2, 1, 4;
  auto run = [&](double sx, double sz) {
    MatX3d X = rest;
    X.col(0) *= sx;
    X(3, 2) *= sz;
    return chart::isometric_distortion(rest, X, T);
  };
  const chart::Distortion a = run(2.0, 1.0);
  EXPECT_NEAR(a.min, 2.0, 1e-12);
  EXPECT_NEAR(a.max, 2.0, 1e-12);
  EXPECT_EQ(a.nearly_flat, 0);
  const chart::Distortion b = run(1.0, 1e-4);
  EXPECT_NEAR(b.max, 1e4, 1e-6);
  EXPECT_NEAR(b.min, 1.0, 1e-12);  // the other tet is untouched
  EXPECT_EQ(b.nearly_flat, 1);
  EXPECT_EQ(run(1.0, 1e-2).nearly_flat, 0);
}
