// Surface mode (paper Section 5.3): the l1 deformation with surface ARAP, the surface polycube,
// its quad mesh, and open surfaces, on shapes built in code.
#include <cmath>
#include <map>
#include <set>

#include "polycube/chart/extract.h"
#include "polycube/chart/labeling.h"
#include "polycube/deform/energies.h"
#include "polycube/deform/solver.h"
#include "polycube/examples/examples.h"
#include "polycube/quad/quad.h"
#include "polycube/io/readers.h"
#include "polycube/io/writers.h"
#include <filesystem>
#include <nlohmann/json.hpp>
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {

int count_charts(const MatX3d& X, const MatX3i& F) { return chart::build_charts(X, F, chart::label_by_normal(X, F)).count(); }

// Open cylinder of radius r and height h along z: n x m quads split into triangles, two border loops.
SurfaceMesh open_cylinder(double r = 1.0, double h = 2.0, int n = 32, int m = 12) {
  SurfaceMesh s;
  s.V.resize(n * (m + 1), 3);
  for (int j = 0; j <= m; ++j)
    for (int i = 0; i < n; ++i) {
      const double u = 2 * M_PI * i / n;
      s.V.row(j * n + i) << r * std::cos(u), r * std::sin(u), h * j / m;
    }
  s.F.resize(2 * n * m, 3);
  int k = 0;
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * n + i, b = j * n + (i + 1) % n, c = (j + 1) * n + (i + 1) % n, d = (j + 1) * n + i;
      s.F.row(k++) << a, b, c;
      s.F.row(k++) << a, c, d;
    }
  return s;
}

// Upper half of sphere(levels): the triangles with every vertex at z >= 0 (one border loop).
SurfaceMesh hemisphere(int levels = 3) {
  const SurfaceMesh s = sphere(levels);
  std::vector<int> keep;
  for (int f = 0; f < s.F.rows(); ++f)
    if (s.V(s.F(f, 0), 2) >= -1e-12 && s.V(s.F(f, 1), 2) >= -1e-12 && s.V(s.F(f, 2), 2) >= -1e-12) keep.push_back(f);
  SurfaceMesh h;
  h.V = s.V;
  h.F.resize(keep.size(), 3);
  for (size_t i = 0; i < keep.size(); ++i) h.F.row(i) = s.F.row(keep[i]);
  return h;
}

}  // namespace

TEST(SurfaceDeform, CubeStaysACube) {
  auto b = grid_box(3, Vec3(0, 0, 0), Vec3(1, 2, 3));
  auto r = deform::deform_surface_to_polycube(b.V, b.F, {});
  EXPECT_EQ(r.iterations, 0);
  EXPECT_NEAR(r.l1_quality, 0, 1e-12);
  EXPECT_NEAR(r.arap, 0, 1e-12);
}

// A thin plate is already a polycube: nothing moves and nothing is pressed flat, though its
// faces' vertices have their pairs across (deform::flattened_parts measured at the end).
TEST(SurfaceDeform, ThinPlateIsNotReportedFlattened) {
  auto b = grid_box(4, Vec3(0, 0, 0), Vec3(1, 1, 0.04));
  auto r = deform::deform_surface_to_polycube(b.V, b.F, {});
  EXPECT_EQ(r.iterations, 0);
  EXPECT_EQ(r.thin_flattened.fraction, 0.0);
  EXPECT_EQ(r.thin_flattened.vertex(), -1);
  EXPECT_FALSE(deform::thickness_pairs(b.V, b.F, 0.05 * std::sqrt(2.0)).empty());
}

// A leaf: an ellipsoid 2 x 0.6 x 0.06 (8192 triangles). The plain deformation presses it flat
// (thin_crushed), and the thickness barrier's fixed pairs do not hold it: its two faces slid along
// each other by up to 0.03 along x while pressed to 0.0012 apart in z (every pair still at half its
// rest distance; measured 2026-12-08). The contact barrier sees the face across wherever it slides:
// the leaf keeps 0.022 of its 0.06 (mirror vertices 0.021 apart at the median, 0.006 at the rim), and
// no vertex passes to the other side. (At the default target 1e-3; the test stops at 5e-3, where
// the pairs leave it 0.0069 thick with its faces crossed, and the test fails with them.)
TEST(SurfaceDeform, ContactBarrierKeepsALeafThick) {
  SurfaceMesh s = sphere(5);
  for (int i = 0; i < s.V.rows(); ++i) s.V.row(i) = s.V.row(i).cwiseProduct(Eigen::RowVector3d(1, 0.3, 0.03));
  deform::DeformOptions o;
  o.thickness_contact = true;
  o.target_quality = 5e-3;  // (the schedule's last steps add 5 s to the test)
  const auto r = deform::deform_surface_to_polycube(s.V, s.F, o);
  EXPECT_GT(r.thin_crushed, 0.1);  // the plain first pass pressed it
  EXPECT_TRUE(r.converged);
  EXPECT_LT(r.l1_quality, 5e-3);
  EXPECT_GT(r.thickness_pairs, 0);
  EXPECT_GT(r.contact_active, 0);
  const Vec3 extent = (r.X.colwise().maxCoeff() - r.X.colwise().minCoeff()).transpose();
  int thin = 0;
  extent.minCoeff(&thin);
  EXPECT_GT(extent[thin], 0.015) << extent.transpose();
  // Each vertex of the upper face against its mirror image (x, y, -z) of the lower face: on the
  // same side as at rest, along the thin axis.
  std::map<std::pair<double, double>, int> lower;
  for (int v = 0; v < s.V.rows(); ++v)
    if (s.V(v, 2) < 0) lower[{s.V(v, 0), s.V(v, 1)}] = v;
  std::vector<double> gaps;
  for (int v = 0; v < s.V.rows(); ++v) {
    if (!(s.V(v, 2) > 0)) continue;
    auto it = lower.find({s.V(v, 0), s.V(v, 1)});
    if (it == lower.end()) continue;
    gaps.push_back(r.X(v, thin) - r.X(it->second, thin));
  }
  ASSERT_GT(gaps.size(), 1000u);
  std::sort(gaps.begin(), gaps.end());
  const double sign = gaps[gaps.size() / 2] > 0 ? 1 : -1;  // (the polycube may face the leaf either way)
  EXPECT_GT(sign * (sign > 0 ? gaps.front() : gaps.back()), 0.0);
  EXPECT_GT(std::abs(gaps[gaps.size() / 2]), 0.015);
}

TEST(SurfaceDeform, SphereBecomesASixChartPolycube) {
  auto s = sphere(4, Vec3(5, -3, 2), 4.0);
  auto r = deform::deform_surface_to_polycube(s.V, s.F, {});
  EXPECT_TRUE(r.converged);
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_EQ(count_charts(r.X, s.F), 6);
  EXPECT_LT(r.arap, 0.15);
  double l1, a0, a1;
  deform::l1_measure(s.V, s.F, l1, a0);
  deform::l1_measure(r.X, s.F, l1, a1);
  EXPECT_NEAR(a1 / a0, 1.0, 1e-6);
}

TEST(SurfaceDeform, OpenCylinderBorderBecomesAxisAligned) {
  auto c = open_cylinder();
  auto r = deform::deform_surface_to_polycube(c.V, c.F, {});
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_LT(r.border_quality, 1e-3);
  EXPECT_EQ(count_charts(r.X, c.F), 4);  // a square tube
  EXPECT_LT(r.arap, 0.1);
}

TEST(SurfaceDeform, HemisphereBorderBecomesAxisAligned) {
  auto h = hemisphere(4);
  auto r = deform::deform_surface_to_polycube(h.V, h.F, {});
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_LT(r.border_quality, 1e-3);
  EXPECT_EQ(count_charts(r.X, h.F), 5);  // an open box
  EXPECT_LT(r.arap, 0.15);
}

namespace {

// Surface mode through the polycube stage: deformation, labels, cleanup, realization.
chart::PolycubeExtraction surface_polycube(const SurfaceMesh& s, const deform::DeformOptions& o = {}) {
  const auto d = deform::deform_surface_to_polycube(s.V, s.F, o);
  return chart::extract_polycube(s.V, MatX4i(0, 4), s.F, d.X);
}

// Every triangle facing its label's direction (no flip) and lying in its chart's plane.
void expect_exact_polycube(const SurfaceMesh& s, const chart::PolycubeExtraction& e) {
  ASSERT_TRUE(e.realized.success) << e.realized.failure;
  EXPECT_LT(e.realized.planarity_error, 1e-12);
  EXPECT_EQ(e.realized.misoriented_faces, 0);
  const MatX3d& X = e.realized.X;
  for (int f = 0; f < s.F.rows(); ++f) {
    const Vec3 N = deform::area_normal(X, s.F(f, 0), s.F(f, 1), s.F(f, 2));
    EXPECT_GT(N.dot(chart::label_direction(e.labels[f])), 0) << "triangle " << f;
  }
}

}  // namespace

TEST(SurfacePolycube, EdgeFlipUnfoldsATriangle) {
  // Two triangles of one +Z chart: (0, 1, 2) folded (2 on the wrong side of edge 0-1), (1, 0, 3)
  // facing +Z; flipping their shared edge gives (2, 0, 3) and (2, 3, 1), both facing +Z.
  MatX3d X(4, 3);
  X << 0, 0, 0, 1, 0, 0, 0.5, -0.2, 0, 0.5, -1, 0;
  MatX3i F(2, 3);
  F << 0, 1, 2, 1, 0, 3;
  const std::vector<int> labels = {kPosZ, kPosZ};
  EXPECT_EQ(chart::flip_folded_edges(X, F, labels), 1);
  for (int f = 0; f < 2; ++f) EXPECT_GT(deform::area_normal(X, F(f, 0), F(f, 1), F(f, 2)).z(), 0) << f;
  // Triangles of different charts are never flipped.
  MatX3i G(2, 3);
  G << 0, 1, 2, 1, 0, 3;
  EXPECT_EQ(chart::flip_folded_edges(X, G, {kPosZ, kNegY}), 0);
}

TEST(SurfacePolycube, EdgeCollapseRemovesAChartEdgeSegmentRunningTheWrongWay) {
  // A 4 x 4 grid box whose -X/+Y edge line (x = 0, y = 1) has two consecutive vertices swapped
  // along z in X: the segment between them runs the wrong way, folding its -X and +Y triangles
  // (the situation of basic/eight.off). Collapsing it removes both and leaves a closed manifold
  // with the same labels elsewhere, which realizes as an exact box.
  const auto s = grid_box(4);
  const std::vector<int> labels0 = chart::label_by_normal(s.V, s.F);
  int p = -1, q = -1;
  for (int v = 0; v < s.V.rows(); ++v) {
    if (std::abs(s.V(v, 0)) > 1e-12 || std::abs(s.V(v, 1) - 1) > 1e-12) continue;
    if (std::abs(s.V(v, 2) - 0.25) < 1e-12) p = v;
    if (std::abs(s.V(v, 2) - 0.5) < 1e-12) q = v;
  }
  ASSERT_GE(p, 0);
  ASSERT_GE(q, 0);
  MatX3d X = s.V;
  std::swap(X(p, 2), X(q, 2));
  const double diag = std::sqrt(3.0);
  ASSERT_GT(chart::count_misoriented(X, s.F, labels0, diag), 0);
  MatX3i F = s.F;
  std::vector<int> labels = labels0;
  std::vector<int> merged;
  const int c = chart::collapse_folded_edges(s.V, X, F, labels, merged);
  ASSERT_GE(c, 1);
  EXPECT_TRUE(merged[p] == q || merged[q] == p);
  EXPECT_EQ(F.rows(), s.F.rows() - 2 * c);
  ASSERT_EQ(static_cast<Eigen::Index>(labels.size()), F.rows());
  std::map<std::pair<int, int>, int> use;
  std::set<int> used;
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      EXPECT_LT(merged[a], 0) << "triangle " << f << " uses a merged vertex";
      ASSERT_NE(a, b);
      use[{std::min(a, b), std::max(a, b)}]++;
      used.insert(a);
    }
  for (const auto& [e, n] : use) EXPECT_EQ(n, 2) << e.first << "-" << e.second;
  EXPECT_EQ(static_cast<int>(used.size()) - static_cast<int>(use.size()) + F.rows(), 2);  // still a sphere
  // The collapsed mesh realizes as an exact box: every triangle faces its label, planes exact.
  const chart::RealizeResult r = chart::realize_surface_polycube(s.V, F, X, labels);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(chart::count_misoriented(r.X, F, labels, diag), 0);
  EXPECT_LT(r.planarity_error, 1e-12);
}

TEST(SurfacePolycube, LocalUntanglingUnfoldsTrianglesInsideCharts) {
  // An 8 x 8 grid box whose layout has three vertices of the +Z face pushed across their
  // neighbours (folding the triangles around them) and one of the -X face likewise: the local
  // untangling alone unfolds them (the global rounds never run), and the ARAP iterations that
  // follow keep every triangle facing its label. With it off, the global rounds do the same.
  const auto s = grid_box(8);
  const std::vector<int> labels = chart::label_by_normal(s.V, s.F);
  MatX3d X = s.V;
  auto find = [&](double x, double y, double z) {
    for (int v = 0; v < s.V.rows(); ++v)
      if ((s.V.row(v) - Eigen::RowVector3d(x, y, z)).norm() < 1e-12) return v;
    return -1;
  };
  const int a = find(0.5, 0.5, 1), b = find(0.25, 0.75, 1), c = find(0.75, 0.25, 1), d = find(0, 0.5, 0.5);
  ASSERT_TRUE(a >= 0 && b >= 0 && c >= 0 && d >= 0);
  X(a, 0) += 0.2;
  X(b, 1) -= 0.19;
  X(c, 0) -= 0.17;
  X(c, 1) += 0.16;
  X(d, 2) += 0.21;
  const double diag = std::sqrt(3.0);
  ASSERT_GE(chart::count_misoriented(X, s.F, labels, diag), 8);
  const chart::RealizeResult r = chart::realize_surface_polycube(s.V, s.F, X, labels, {}, {}, &X);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(chart::count_misoriented(r.X, s.F, labels, diag), 0);
  EXPECT_LT(r.planarity_error, 1e-12);
  EXPECT_EQ(r.untangle_iterations, 0) << "the global untangling ran";
  // The box is the rest shape: ARAP brings the layout back to it.
  EXPECT_LT((r.X - s.V).cwiseAbs().maxCoeff(), 1e-3);
  chart::RealizeOptions global_only;
  global_only.local_first = -1;
  const chart::RealizeResult g = chart::realize_surface_polycube(s.V, s.F, X, labels, global_only, {}, &X);
  ASSERT_TRUE(g.success) << g.failure;
  EXPECT_EQ(chart::count_misoriented(g.X, s.F, labels, diag), 0);
  EXPECT_GT(g.untangle_iterations, 0);
}

TEST(SurfacePolycube, RelaxationUncrushesTrianglesInsideCharts) {
  // An 8 x 8 grid box whose +Z face layout has the 5 x 5 vertices around its centre squeezed 20x towards
  // it (valid, every triangle facing +Z, but crushed). Without ARAP iterations (max_iterations 0)
  // the relaxation alone (RealizeOptions::relax_iterations) brings the face back towards the rest
  // box, the minimum of its energy: the worst isometric distortion drops from over 10 to under 2,
  // the planes stay exact and no triangle folds. Off, the layout is returned as given.
  const auto s = grid_box(8);
  const std::vector<int> labels = chart::label_by_normal(s.V, s.F);
  MatX3d X = s.V;
  int squeezed = 0;
  for (int v = 0; v < s.V.rows(); ++v)
    if (std::abs(s.V(v, 2) - 1) < 1e-12 && std::abs(s.V(v, 0) - 0.5) < 0.3 && std::abs(s.V(v, 1) - 0.5) < 0.3) {
      X(v, 0) = 0.5 + (s.V(v, 0) - 0.5) / 20;
      X(v, 1) = 0.5 + (s.V(v, 1) - 0.5) / 20;
      ++squeezed;
    }
  ASSERT_EQ(squeezed, 25);
  const double diag = std::sqrt(3.0);
  ASSERT_EQ(chart::count_misoriented(X, s.F, labels, diag), 0);
  chart::RealizeOptions off;
  off.max_iterations = 0;
  const chart::RealizeResult a = chart::realize_surface_polycube(s.V, s.F, X, labels, off, {}, &X);
  ASSERT_TRUE(a.success) << a.failure;
  EXPECT_GT(a.isometric.max, 10);
  chart::RealizeOptions on = off;
  on.relax_iterations = 500;
  const chart::RealizeResult b = chart::realize_surface_polycube(s.V, s.F, X, labels, on, {}, &X);
  ASSERT_TRUE(b.success) << b.failure;
  EXPECT_EQ(chart::count_misoriented(b.X, s.F, labels, diag), 0);
  EXPECT_LT(b.planarity_error, 1e-12);
  EXPECT_LT(b.isometric.max, 2.0);  // 23.9 -> 1.52 (ARAP 0.184 -> 0.0045)
  EXPECT_LT((b.X - s.V).cwiseAbs().maxCoeff(), 0.05) << "a grid step is 0.125";
  EXPECT_LT(b.arap, a.arap);
}

TEST(SurfacePolycube, SphereGivesACube) {
  const auto s = sphere(4);
  const auto e = surface_polycube(s);
  expect_exact_polycube(s, e);
  EXPECT_EQ(e.charts.charts, 6);
  EXPECT_EQ(e.charts.corners, 8);
  EXPECT_LT(e.realized.arap, 0.2);
  EXPECT_EQ(e.realized.T.rows(), 0);
}

TEST(SurfacePolycube, TorusGivesAValidGenusOnePolycube) {
  const auto t = torus(1.0, 0.4, 48, 16);
  const auto e = surface_polycube(t);
  expect_exact_polycube(t, e);
  EXPECT_TRUE(e.charts.valid);
}

TEST(SurfacePolycube, OpenCylinderKeepsItsBorderAxisAligned) {
  const auto c = open_cylinder();
  const auto e = surface_polycube(c);
  expect_exact_polycube(c, e);
  EXPECT_EQ(e.charts.charts, 4);
  // Every border edge runs along exactly one axis.
  std::vector<std::array<int, 3>> edges;
  chart::border_directions(e.realized.X, c.F, e.labels, &edges);
  ASSERT_EQ(edges.size(), 64u);
  for (const auto& ab : edges) {
    const Vec3 d = (e.realized.X.row(ab[1]) - e.realized.X.row(ab[0])).transpose();
    int nonzero = 0;
    for (int k = 0; k < 3; ++k) nonzero += d[k] != 0;
    EXPECT_EQ(nonzero, 1);
  }
}

TEST(SurfacePolycube, HemisphereGivesAnOpenBox) {
  const auto h = hemisphere(4);
  const auto e = surface_polycube(h);
  expect_exact_polycube(h, e);
  EXPECT_EQ(e.charts.charts, 5);
}

namespace {

quad::QuadResult surface_quads(const SurfaceMesh& s, double cells_per_unit, chart::PolycubeExtraction* out = nullptr) {
  const auto e = surface_polycube(s);
  EXPECT_TRUE(e.realized.success) << e.realized.failure;
  if (out) *out = e;
  return quad::quad_mesh_from_surface_polycube(s.V, s.F, e.realized.X, e.labels, cells_per_unit, s);
}

int euler_characteristic(const quad::QuadResult& q) {
  std::set<std::pair<int, int>> edges;
  for (int f = 0; f < q.Q.rows(); ++f)
    for (int t = 0; t < 4; ++t) {
      const int a = q.Q(f, t), b = q.Q(f, (t + 1) % 4);
      edges.insert({std::min(a, b), std::max(a, b)});
    }
  return static_cast<int>(q.V.rows()) - static_cast<int>(edges.size()) + static_cast<int>(q.Q.rows());
}

}  // namespace

TEST(SurfaceQuads, BoxGivesItsRegularGrid) {
  const auto b = grid_box(4, Vec3(0, 0, 0), Vec3(2, 1, 1));
  const auto q = surface_quads(b, 3.0);  // 3 cells per unit: 6 x 3 x 3
  EXPECT_EQ(q.Q.rows(), 2 * (6 * 3 + 6 * 3 + 3 * 3));
  EXPECT_EQ(q.V.rows(), 2 * (6 * 3 + 6 * 3 + 3 * 3) + 2);  // Euler: V - E + F = 2
  EXPECT_NEAR(q.quality.sj_min, 1.0, 1e-9);
  EXPECT_EQ(q.irregular_vertices, 8);
  EXPECT_EQ(q.border_vertices, 0);
  // On the box's surface.
  for (int v = 0; v < q.V.rows(); ++v) {
    const Vec3 p = q.V.row(v).transpose();
    const double d = std::min({p.x(), 2 - p.x(), p.y(), 1 - p.y(), p.z(), 1 - p.z()});
    EXPECT_NEAR(d, 0, 1e-12);
  }
}

TEST(SurfaceQuads, SphereGivesAValidClosedQuadMesh) {
  const auto s = sphere(4);
  const auto q = surface_quads(s, 12.0);
  EXPECT_EQ(q.quality.inverted, 0);
  EXPECT_GT(q.quality.sj_min, 0.3);
  EXPECT_EQ(euler_characteristic(q), 2);
  EXPECT_EQ(q.irregular_vertices, 8);
  EXPECT_EQ(q.border_loops, 0);
}

TEST(SurfaceQuads, OverlappingComponentsGiveAQuadMeshEach) {
  // Two boxes that overlap, one component each (volume mode refuses them, surface mode takes each
  // for itself), on the planes y = 0, 1 and z = 0, 1 over 1 <= x <= 2: their grid points there
  // have the same integers. They were taken for one point, and the quads of both boxes met at
  // them (2026-12-02, basic/two_spheres at one thread, whose cubes share four planes: 1982
  // vertices for 2028 quads, quads stretched across both spheres, Hausdorff 0.12 of the diagonal,
  // worst quad 0.25; with the points kept apart 2032 vertices, 0.002, 0.80).
  const auto a = grid_box(4, Vec3(0, 0, 0), Vec3(2, 1, 1)), b = grid_box(4, Vec3(1, 0, 0), Vec3(3, 1, 1));
  SurfaceMesh s;
  s.V.resize(a.V.rows() + b.V.rows(), 3);
  s.V << a.V, b.V;
  s.F.resize(a.F.rows() + b.F.rows(), 3);
  s.F << a.F, b.F.array() + static_cast<int>(a.V.rows());
  const auto q = quad::quad_mesh_from_surface_polycube(s.V, s.F, s.V, chart::label_by_normal(s.V, s.F), 3.0, s);
  const int per_box = 2 * (6 * 3 + 6 * 3 + 3 * 3);  // 3 cells per unit on a 2 x 1 x 1 box
  EXPECT_EQ(q.Q.rows(), 2 * per_box);
  EXPECT_EQ(q.V.rows(), 2 * (per_box + 2));  // two closed genus-0 meshes: V - E + F = 4
  EXPECT_EQ(euler_characteristic(q), 4);
  EXPECT_EQ(q.irregular_vertices, 16);
  EXPECT_NEAR(q.quality.sj_min, 1.0, 1e-9);
}

TEST(SurfaceQuads, TorusGivesAGenusOneQuadMesh) {
  const auto t = torus(1.0, 0.4, 48, 16);
  const auto q = surface_quads(t, 6.0);
  EXPECT_EQ(q.quality.inverted, 0);
  EXPECT_EQ(euler_characteristic(q), 0);
}

TEST(SurfaceQuads, OpenCylinderKeepsItsTwoBorderLoops) {
  const auto c = open_cylinder();
  const auto q = surface_quads(c, 4.0);
  EXPECT_EQ(q.quality.inverted, 0);
  EXPECT_GT(q.quality.sj_min, 0.5);
  EXPECT_EQ(q.border_loops, 2);
  EXPECT_EQ(euler_characteristic(q), 0);  // an annulus
  EXPECT_EQ(q.irregular_vertices, 0);     // a tube: every inner vertex of valence 4
  // Border vertices on the input border circles (z = 0 or 2, radius 1 up to the chords).
  for (int v = 0; v < q.V.rows(); ++v) {
    const Vec3 p = q.V.row(v).transpose();
    if (std::abs(p.z()) < 1e-9 || std::abs(p.z() - 2) < 1e-9) {
      EXPECT_GT(std::hypot(p.x(), p.y()), 0.99);
    }
  }
  int on_border = 0;
  for (int v = 0; v < q.V.rows(); ++v) on_border += std::abs(q.V(v, 2)) < 1e-9 || std::abs(q.V(v, 2) - 2) < 1e-9;
  EXPECT_EQ(on_border, q.border_vertices);
}

TEST(SurfaceQuads, HemisphereKeepsItsBorderLoop) {
  const auto h = hemisphere(4);
  const auto q = surface_quads(h, 5.0);
  EXPECT_EQ(q.quality.inverted, 0);
  EXPECT_GT(q.quality.sj_min, 0.3);
  EXPECT_EQ(q.border_loops, 1);
  EXPECT_EQ(euler_characteristic(q), 1);  // a disk
  for (int v = 0; v < q.V.rows(); ++v) EXPECT_NEAR(q.V.row(v).norm(), 1.0, 0.02);
}

TEST(SurfaceQuads, BetterQuadsAreCloserToTheSurfaceAtASimilarQuality) {
  quad::QuadQuality a;
  a.sj_min = 0.30;
  a.sj_mean = 0.95;
  quad::QuadQuality b = a;
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 1.0));
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 0.99)) << "closer by 1% only";
  EXPECT_TRUE(quad::better_quads(a, 1.0, b, 0.9));
  b.sj_min = 0.26;  // more than 10% of the minimum given up
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 0.5));
  b.sj_min = 0.28;
  b.sj_mean = 0.92;  // 0.03 of the mean given up
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 0.5));
  b.sj_mean = 0.94;
  EXPECT_TRUE(quad::better_quads(a, 1.0, b, 0.5));
  b.inverted = 1;  // a folded quad loses whatever the distance
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 0.1));
  EXPECT_TRUE(quad::better_quads(b, 0.1, a, 1.0));
}

TEST(SurfaceQuads, FewerSliverQuadsWinUnlessFarFromTheSurface) {
  quad::QuadQuality a;
  a.sj_min = 0.30;
  a.sj_mean = 0.95;
  quad::QuadQuality b = a;
  b.edge_ratio_above_100 = 1;  // one quad over edge ratio 100
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 0.9)) << "a sliver is not worth 10% of the distance";
  EXPECT_TRUE(quad::better_quads(b, 0.9, a, 1.0));
  EXPECT_TRUE(quad::better_quads(b, 1.0, a, 1.4)) << "nor worth 40% more of it";
  EXPECT_FALSE(quad::better_quads(b, 1.0, a, 2.0)) << "a mesh twice as far (a part lost) does not win by its slivers";
  EXPECT_TRUE(quad::better_quads(a, 2.0, b, 1.0));
  b.inverted = 1;  // folded quads still come first
  a.edge_ratio_above_100 = 5;
  EXPECT_FALSE(quad::better_quads(a, 1.0, b, 1.0));
}

// Two polycubes of one layout (ExtractOptions::repair_deformed_start keeps the other start's as
// PolycubeExtraction::alternative): quads are extracted from both and the better kept, whichever of
// the two the extraction itself kept.
TEST(SurfaceQuads, TheStartWhoseQuadsAreBetterIsKept) {
  const auto s = sphere(3);
  chart::PolycubeExtraction e = surface_polycube(s);
  ASSERT_TRUE(e.realized.success) << e.realized.failure;
  EXPECT_FALSE(e.alternative) << "the sphere's deformed start realizes its layout";
  // A worse map of the same layout: each axis warped by a monotone cubic (planes stay planes and
  // the polycube exact) crowds the grid lines to one side of the sphere.
  chart::PolycubeExtraction warped = e;
  MatX3d& X = warped.realized.X;
  for (int k = 0; k < 3; ++k) {
    const double lo = X.col(k).minCoeff(), hi = X.col(k).maxCoeff();
    for (int v = 0; v < X.rows(); ++v) {
      const double t = (X(v, k) - lo) / (hi - lo);
      X(v, k) = lo + (hi - lo) * (0.15 * t + 0.85 * t * t * t);
    }
  }
  const int target = 300;
  // The quads of `own` with `other` as its alternative.
  auto compared = [&](const chart::PolycubeExtraction& own, const chart::PolycubeExtraction& other,
                      const quad::QuadOptions& o = {}) {
    chart::PolycubeExtraction x = own;
    x.alternative = std::make_shared<const chart::PolycubeExtraction>(other);
    return quad::surface_quads_best_start(x, s.V, s.F, target, s, o);
  };
  const auto a = compared(e, warped);
  ASSERT_EQ(a.size(), 2u);
  EXPECT_FALSE(a[0].alternative);
  EXPECT_TRUE(a[1].alternative);
  EXPECT_LT(a[0].distance.max, 0.98 * a[1].distance.max);
  EXPECT_TRUE(a[0].kept);
  EXPECT_FALSE(a[1].kept);
  // The other way round: the warped polycube is the extraction's, the even one its alternative.
  const auto b = compared(warped, e);
  ASSERT_EQ(b.size(), 2u);
  EXPECT_FALSE(b[0].kept);
  EXPECT_TRUE(b[1].kept);
  EXPECT_EQ(b[1].quads.Q, a[0].quads.Q) << "the same polycube gives the same quads";
  EXPECT_EQ(b[1].quads.V, a[0].quads.V);
  // Off: the extraction's own polycube alone.
  quad::QuadOptions off;
  off.compare_starts = false;
  const auto c = compared(warped, e, off);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_TRUE(c[0].kept);
  EXPECT_EQ(c[0].quads.V, b[0].quads.V);
  std::printf("even map: %d quads, min %.3f mean %.3f, Hausdorff %.4f; warped: %d, %.3f, %.3f, %.4f\n",
              a[0].quads.quality.count, a[0].quads.quality.sj_min, a[0].quads.quality.sj_mean, a[0].distance.max,
              a[1].quads.quality.count, a[1].quads.quality.sj_min, a[1].quads.quality.sj_mean, a[1].distance.max);
}

// The l_bracket with its upright leg squashed to a step 0.00075 high above the foot (0.006 cell at
// the 7.6 cells per unit of 400 quads): an exact polycube of itself. Every step kept a cell apart (merge_thin_steps 0), the riser gets a row of
// quads far thinner than long; the thin-step retry merges the step's planes.
TEST(SurfaceQuads, SliverRowsOverAThinStepAreExtractedAgainWithTheStepMerged) {
  const MeshData l = examples::make("l_bracket", 0.1);
  MatX3d X = l.V;
  for (int v = 0; v < X.rows(); ++v)
    if (X(v, 2) > 0.5) X(v, 2) = 0.5 + 0.0005 * (X(v, 2) - 0.5);
  const SurfaceMesh s{X, l.F};
  chart::PolycubeExtraction e;
  e.realized.success = true;
  e.realized.start = "given";
  e.realized.X = X;
  e.labels = chart::label_by_normal(X, l.F);
  quad::QuadOptions o;
  o.merge_thin_steps = 0;
  o.thin_step_retries = false;
  const auto plain = quad::surface_quads_best_start(e, X, l.F, 400, s, o);
  ASSERT_EQ(plain.size(), 1u);
  EXPECT_TRUE(plain[0].retries.empty());
  EXPECT_EQ(plain[0].quads.merged_planes, 0);
  ASSERT_GT(plain[0].quads.quality.edge_ratio_above_100, 0)
      << "a row of slivers over the riser: edge ratio max " << plain[0].quads.quality.edge_ratio_max;
  o.thin_step_retries = true;
  const auto retried = quad::surface_quads_best_start(e, X, l.F, 400, s, o);
  ASSERT_EQ(retried.size(), 1u);
  const quad::StartQuads& r = retried[0];
  ASSERT_EQ(r.retries.size(), 1u) << "no sliver left after the first retry: no second";
  EXPECT_EQ(r.retries[0].thin_steps, 0.05);
  EXPECT_TRUE(r.retries[0].replaced);
  EXPECT_EQ(r.quads.merged_planes, 1);
  EXPECT_EQ(r.quads.quality.edge_ratio_above_100, 0);
  EXPECT_EQ(r.quads.quality.inverted, 0);
  EXPECT_LT(r.quads.quality.edge_ratio_max, plain[0].quads.quality.edge_ratio_max);
  // The step's height is the distance it costs (the plain quads lie on the shape).
  EXPECT_NEAR(r.distance.max, 0.00075, 1e-5);
  EXPECT_LT(plain[0].distance.max, 1e-9);
  // The rule: fewer slivers, the distance within the slack the merge may cost.
  EXPECT_TRUE(quad::fewer_sliver_quads(plain[0].quads.quality, plain[0].distance.max, r.quads.quality, r.distance.max, 0.001));
  EXPECT_FALSE(quad::fewer_sliver_quads(plain[0].quads.quality, plain[0].distance.max, r.quads.quality, r.distance.max, 0.0005));
  EXPECT_FALSE(quad::fewer_sliver_quads(r.quads.quality, r.distance.max, plain[0].quads.quality, plain[0].distance.max, 1.0));
}

// ---- CLI ------------------------------------------------------------------------------------

TEST(SurfaceCli, OpenHemisphereGivesQuadsWithItsBorder) {
  const std::string dir = temp_dir("surface_cli");
  const auto h = hemisphere(3);
  // Shifted and scaled: the quads must come out at the input's place and size.
  const MatX3d V = (h.V * 5.0).rowwise() + Eigen::RowVector3d(10, -4, 2);
  io::write_obj(dir + "/in.obj", V, h.F);
  // Without --surface an open surface is refused, and the message says what to do.
  RunResult bad = run_cli(dir + "/in.obj -o " + dir + "/vol -q");
  EXPECT_EQ(bad.code, 4) << bad.output;
  EXPECT_NE(bad.output.find("--surface"), std::string::npos) << bad.output;
  RunResult r = run_cli(dir + "/in.obj --surface --quad --quads 600 -o " + dir + "/out -q");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto rep = nlohmann::json::parse(read_text(dir + "/out/report.json"));
  EXPECT_EQ(rep["mode"], "surface");
  EXPECT_EQ(rep["input"]["border_loops"], 1);
  EXPECT_EQ(rep["polycube"]["charts"], 5);
  EXPECT_EQ(rep["tetmesh"]["tets"], 0);
  EXPECT_LT(rep["polycube"]["border_l1_quality"].get<double>(), 1e-3);
  EXPECT_EQ(rep["quad"]["inverted"], 0);
  EXPECT_EQ(rep["quad"]["border_loops"], 1);
  EXPECT_GT(rep["quad"]["count"].get<int>(), 400);
  EXPECT_LT(rep["quad"]["count"].get<int>(), 900);
  EXPECT_LT(rep["quad"]["hausdorff_rel"].get<double>(), 0.02);
  const MeshData q = io::read_mesh(dir + "/out/quad.mesh", {});
  // The reader may give quads, or (for a surface-only file) split them into triangle pairs.
  EXPECT_EQ(q.Q.rows() > 0 ? q.Q.rows() : q.F.rows() / 2, rep["quad"]["count"].get<int>());
  for (int v = 0; v < q.V.rows(); ++v)
    EXPECT_NEAR((q.V.row(v) - Eigen::RowVector3d(10, -4, 2)).norm(), 5.0, 0.1);
  EXPECT_FALSE(std::filesystem::exists(dir + "/out/tetmesh.mesh"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/out/labels.txt"));
  // Hexes need the volume.
  RunResult hx = run_cli(dir + "/in.obj --surface --hex -o " + dir + "/hex -q");
  EXPECT_EQ(hx.code, 2) << hx.output;
}

TEST(SurfaceCli, ExampleInSurfaceModeIsFast) {
  const std::string dir = temp_dir("surface_cli_example");
  RunResult r = run_cli("--example box_hole --surface --quad -o " + dir + "/out -q");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto rep = nlohmann::json::parse(read_text(dir + "/out/report.json"));
  EXPECT_EQ(rep["input"]["genus"], 1);
  EXPECT_EQ(rep["quad"]["inverted"], 0);
  EXPECT_GT(rep["quad"]["sj_min"].get<double>(), 0.5);
}

TEST(SurfaceCli, QuadCountAloneAsksForQuads) {
  // --quads N without --quad runs to the quads (it used to stop at the polycube silently).
  const std::string dir = temp_dir("surface_cli_quads_alone");
  RunResult r = run_cli("--example box_hole --surface --quads 600 -o " + dir + "/out -q");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto rep = nlohmann::json::parse(read_text(dir + "/out/report.json"));
  ASSERT_TRUE(rep.contains("quad")) << rep.dump();
  EXPECT_NEAR(rep["quad"]["count"].get<double>(), 600, 120);
  EXPECT_TRUE(std::filesystem::exists(dir + "/out/quad.obj"));
  // An explicit --until wins (no quads); --hexes alone asks for hexes, which surface mode refuses.
  EXPECT_EQ(run_cli("--example box_hole --surface --quads 600 --until polycube -o " + dir + "/o2 -q").code, 0);
  EXPECT_FALSE(std::filesystem::exists(dir + "/o2/quad.obj"));
  EXPECT_EQ(run_cli("--example box_hole --surface --hexes 600 -o " + dir + "/o3 -q").code, 2);
}

TEST(SurfaceQuads, GradedRowsFollowTheCurvedPart) {
  // A 4 x 1 x 1 bar's surface as its own polycube; the rest shape bends x > 2 round a circle of
  // radius 1.5 by 76 degrees (as Hex.GradedGridFollowsTheCurvedPart). Graded rows (the area kept)
  // put more rows of quads in the bent half and come closer to it with about as many quads.
  const SurfaceMesh bar = grid_box(16, Vec3(0, 0, 0), Vec3(4, 1, 1));
  SurfaceMesh bent = bar;
  const double Rc = 1.5;
  for (int v = 0; v < bent.V.rows(); ++v) {
    const double x = bar.V(v, 0), z = bar.V(v, 2);
    if (x <= 2) continue;
    const double th = (x - 2) / Rc, r = Rc - (z - 0.5);
    bent.V(v, 0) = 2 + r * std::sin(th);
    bent.V(v, 2) = 0.5 + Rc - r * std::cos(th);
  }
  const std::vector<int> labels = chart::label_by_normal(bar.V, bar.F);
  quad::QuadOptions o;
  auto distance = [&](const quad::QuadResult& q) {
    return hex::hausdorff(q.V, hex::triangulate_quads(q.Q), bent.V, bent.F, 50000).max;
  };
  const quad::QuadResult uniform = quad::quad_mesh_from_surface_polycube(bent.V, bent.F, bar.V, labels, 3, bent, o);
  o.grading.strength = 1;
  const quad::QuadResult graded = quad::quad_mesh_from_surface_polycube(bent.V, bent.F, bar.V, labels, 3, bent, o);
  EXPECT_EQ(uniform.grading_max[0], 0.0);
  EXPECT_GT(graded.grading_max[0], graded.grading_min[0]);
  EXPECT_DOUBLE_EQ(graded.grading_max[1], graded.grading_min[1]);
  EXPECT_NEAR(static_cast<double>(graded.Q.rows()) / uniform.Q.rows(), 1.0, 0.2);
  EXPECT_EQ(graded.quality.inverted, 0);
  EXPECT_LT(distance(graded), 0.8 * distance(uniform));
}
