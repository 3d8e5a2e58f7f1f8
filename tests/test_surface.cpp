// Surface mode (paper Section 5.3): the l1 deformation with surface ARAP, the surface polycube,
// its quad mesh, and open surfaces, on shapes built in code.
#include <cmath>
#include <map>

#include "polycube/chart/extract.h"
#include "polycube/chart/labeling.h"
#include "polycube/deform/energies.h"
#include "polycube/deform/solver.h"
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
  std::vector<std::array<int, 2>> edges;
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
