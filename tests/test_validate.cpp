// Validation and repair on meshes with known answers.
#include "polycube/core/error.h"
#include "polycube/validate/surface.h"
#include "polycube/validate/tetmesh.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {
SurfaceReport check(SurfaceMesh s, SurfaceLayout* out = nullptr, MeshData* md = nullptr) {
  MeshData m = make_mesh_data(s.V, s.F);
  SurfaceLayout l;
  auto r = validate_surface(m, l);
  if (out) *out = l;
  if (md) *md = m;
  return r;
}
}  // namespace

TEST(Validate, CubeIsClosedGenus0) {
  auto r = check(box());
  EXPECT_EQ(r.components, 1);
  EXPECT_EQ(r.genus, 0);
  EXPECT_TRUE(r.closed);
  EXPECT_FALSE(r.repaired());
}

TEST(Validate, EulerCharacteristicGivesGenus) {
  EXPECT_EQ(check(torus()).genus, 1);
  EXPECT_EQ(check(sphere(2)).genus, 0);
  auto two = merge(torus(), torus(1.0, 0.4, 20, 10));
  // Shift the second torus away.
  auto t2 = torus(1.0, 0.4, 20, 10);
  t2.V.col(0).array() += 5;
  auto r = check(merge(torus(), t2));
  EXPECT_EQ(r.components, 2);
  EXPECT_EQ(r.genus, 2);
}

TEST(Validate, InconsistentFacesAreFlipped) {
  auto s = sphere(2);
  for (int f = 0; f < s.F.rows(); f += 7) std::swap(s.F(f, 1), s.F(f, 2));
  MeshData m;
  auto r = check(s, nullptr, &m);
  EXPECT_EQ(r.faces_flipped, (s.F.rows() + 6) / 7);
  EXPECT_EQ(r.components_reversed, 0);
  EXPECT_GT(enclosed_volume(m.V, m.F), 0);
  EXPECT_EQ(m.F, sphere(2).F);
}

TEST(Validate, InwardComponentIsReversed) {
  MeshData m;
  auto r = check(flipped(sphere(2)), nullptr, &m);
  EXPECT_EQ(r.components_reversed, 1);
  EXPECT_TRUE(r.repaired());
  EXPECT_GT(enclosed_volume(m.V, m.F), 0);
}

TEST(Validate, CavityFacesIntoTheCavity) {
  // A sphere of radius 2 with a spherical cavity of radius 1, both given outward-facing.
  auto s = merge(sphere(2, Vec3::Zero(), 2.0), sphere(2, Vec3(0.1, 0, 0), 1.0));
  SurfaceLayout l;
  MeshData m;
  auto r = check(s, &l, &m);
  EXPECT_EQ(r.components, 2);
  EXPECT_EQ(l.depth, (std::vector<int>{0, 1}));
  EXPECT_EQ(l.parent, (std::vector<int>{-1, 0}));
  EXPECT_EQ(r.components_reversed, 1);
  EXPECT_GT(l.volume[0], 0);
  EXPECT_LT(l.volume[1], 0);
  EXPECT_NEAR(l.volume[0] + l.volume[1], enclosed_volume(m.V, m.F), 1e-9);
}

TEST(Validate, UnreferencedVerticesRemoved) {
  auto s = box();
  s.V.conservativeResize(10, 3);
  s.V.row(8) << 5, 5, 5;
  s.V.row(9) << 6, 6, 6;
  EXPECT_EQ(check(s).unreferenced_removed, 2);
}

TEST(Validate, WindingNumber) {
  auto s = sphere(3);
  std::vector<int> all(s.F.rows());
  for (int i = 0; i < s.F.rows(); ++i) all[i] = i;
  EXPECT_NEAR(winding_number(s.V, s.F, all, Vec3(0.1, 0.2, 0.3)), 1.0, 1e-9);
  EXPECT_NEAR(winding_number(s.V, s.F, all, Vec3(3, 0, 0)), 0.0, 1e-9);
}

TEST(TetCheck, BoundaryOfTwoTetsAndOrientation) {
  MatX3d V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1;
  MatX4i T(2, 4);
  T << 0, 1, 2, 3, 0, 2, 1, 4;
  auto q = measure_tets(V, T);
  EXPECT_EQ(q.inverted, 0);
  EXPECT_NEAR(tet_volume(V.row(0), V.row(1), V.row(2), V.row(3)), 1.0 / 6, 1e-15);
  MatX3i B = tet_boundary(T);
  EXPECT_EQ(B.rows(), 6);
  MatX3d dummy;
  EXPECT_NEAR(enclosed_volume(V, B), 2.0 / 6, 1e-12);
  // A regular tet's dihedral angles are all acos(1/3).
  MatX3d R(4, 3);
  R << 1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1;
  MatX4i T1(1, 4);
  T1 << 0, 1, 2, 3;
  if (tet_volume(R.row(0), R.row(1), R.row(2), R.row(3)) < 0) std::swap(T1(0, 1), T1(0, 2));
  auto qr = measure_tets(R, T1);
  EXPECT_NEAR(qr.min_dihedral_deg, std::acos(1.0 / 3) * 180 / M_PI, 1e-9);
  EXPECT_NEAR(qr.max_dihedral_deg, std::acos(1.0 / 3) * 180 / M_PI, 1e-9);
}

TEST(TetCheck, GloballyNegativeTetMeshIsReoriented) {
  MeshData m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  m.T.resize(1, 4);
  m.T << 0, 2, 1, 3;
  TetInputReport r;
  TetMesh tm = prepare_tet_input(m, r);
  EXPECT_EQ(r.tets_reoriented, 1);
  EXPECT_EQ(measure_tets(tm.V, tm.T).inverted, 0);
}
