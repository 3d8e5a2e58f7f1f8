// The l1 polycube deformation on shapes with known answers.
#include <random>

#include "polycube/chart/labeling.h"
#include "polycube/deform/solver.h"
#include "polycube/examples/examples.h"
#include "polycube/tetra/tetrahedralize.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {

// Charts: connected sets of boundary triangles with the same dominant normal axis and sign.
int count_charts(const MatX3d& X, const MatX3i& F) { return chart::build_charts(X, F, chart::label_by_normal(X, F)).count(); }

double boundary_area(const MatX3d& X, const MatX3i& F) {
  double l1, a;
  deform::l1_measure(X, F, l1, a);
  return a;
}

}  // namespace

TEST(Deform, CubeStaysACube) {
  auto b = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  TetMesh tm = tet_mesh_of(b.V, b.F);
  auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_EQ(r.iterations, 0);
  EXPECT_NEAR(r.l1_quality, 0, 1e-12);
  EXPECT_NEAR(r.arap, 0, 1e-12);
  EXPECT_LE((r.X - tm.V).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Deform, SphereBecomesASixChartPolycube) {
  auto s = sphere(3, Vec3(5, -3, 2), 4.0);  // off-centre and scaled: result must not depend on it
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_TRUE(r.converged);
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_EQ(r.inverted, 0);
  EXPECT_EQ(count_charts(r.X, tm.boundary), 6);
  EXPECT_LT(r.arap, 0.15);
  // The area constraint holds.
  EXPECT_NEAR(boundary_area(r.X, tm.boundary) / boundary_area(tm.V, tm.boundary), 1.0, 1e-6);
  // Output at the input's position and scale.
  EXPECT_LT((Vec3(r.X.colwise().mean()) - Vec3(tm.V.colwise().mean())).norm(), 0.01 * 8);
  // A convergence record per iteration, with decreasing error over the run.
  ASSERT_EQ(static_cast<int>(r.history.size()), r.iterations);
  EXPECT_LT(r.history.back().l1_quality, r.history.front().l1_quality);
}

TEST(Deform, TorusConverges) {
  auto t = torus(1.0, 0.4, 32, 16);
  TetMesh tm = tet_mesh_of(t.V, t.F, 4000);
  auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_EQ(r.inverted, 0);
}

TEST(Deform, RotatedLBracketFindsItsFrame) {
  // The same L-shaped block under three random rotations ends as the same 8-chart polycube.
  MeshData l = examples::make("l_bracket", 0.08);
  const auto rotations = random_rotations(7, 3);
  for (int k = 0; k < 3; ++k) {
    MatX3d V = l.V * rotations[k].transpose();
    TetMesh tm = tet_mesh_of(V, l.F);
    auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
    EXPECT_LT(r.l1_quality, 1e-3) << "rotation " << k;
    EXPECT_EQ(count_charts(r.X, tm.boundary), 8) << "rotation " << k;
    EXPECT_LT(r.arap, 0.01) << "a rotated polycube needs almost no deformation";
  }
}

TEST(Deform, BestRotationAlignsARotatedBox) {
  auto b = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Vec3(1, 2, 0.5).normalized()).toRotationMatrix();
  MatX3d V = b.V * R.transpose();
  Eigen::Matrix3d Q = deform::best_rotation(V, b.F, 0.01);
  MatX3d W = V * Q.transpose();
  double l1, a;
  deform::l1_measure(W, b.F, l1, a);
  EXPECT_LT(l1 / a - 1, 1e-4);  // from 0.2 before the rotation
}
