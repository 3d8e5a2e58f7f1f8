// Surface mode (paper Section 5.3): the l1 deformation with surface ARAP, the surface polycube,
// its quad mesh, and open surfaces, on shapes built in code.
#include <cmath>
#include <map>

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
