// Tetrahedralization with Gmsh: boundary kept, no inverted tets, cavities, target counts, remeshing.
#include "polycube/core/error.h"
#include "polycube/tetra/tetrahedralize.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {
struct Prepared {
  SurfaceMesh s;
  SurfaceLayout l;
};
Prepared prepare(const SurfaceMesh& in) {
  MeshData m = make_mesh_data(in.V, in.F);
  Prepared p;
  validate_surface(m, p.l);
  p.s.V = m.V;
  p.s.F = m.F;
  return p;
}
double tet_mesh_volume(const TetMesh& tm) {
  double v = 0;
  for (int t = 0; t < tm.T.rows(); ++t)
    v += tet_volume(tm.V.row(tm.T(t, 0)), tm.V.row(tm.T(t, 1)), tm.V.row(tm.T(t, 2)), tm.V.row(tm.T(t, 3)));
  return v;
}
}  // namespace

TEST(Tetra, CubeKeepsItsBoundary) {
  auto p = prepare(box(Vec3(1, 2, 3), Vec3(3, 5, 7)));
  TetStats st;
  TetMesh tm = tetrahedralize(p.s, p.l, {}, {}, &st);
  EXPECT_EQ(st.quality.inverted, 0);
  EXPECT_EQ(st.quality.zero_volume, 0);
  EXPECT_EQ(tm.V.topRows(8), p.s.V);
  EXPECT_NEAR(tet_mesh_volume(tm), 2 * 3 * 4, 1e-9);
  check_tet_mesh(tm, &p.s, "cube");  // throws if the boundary differs
}

TEST(Tetra, SphereWithCavity) {
  auto p = prepare(merge(sphere(3, Vec3::Zero(), 2.0), sphere(2, Vec3(0.2, 0, 0), 1.0)));
  TetMesh tm = tetrahedralize(p.s, p.l, {}, {});
  const double expected = p.l.volume[0] + p.l.volume[1];
  EXPECT_NEAR(tet_mesh_volume(tm), expected, 1e-9 * std::abs(expected));
  EXPECT_EQ(measure_tets(tm.V, tm.T).inverted, 0);
  // The boundary has both shells.
  EXPECT_EQ(tet_boundary(tm.T).rows(), p.s.F.rows());
}

TEST(Tetra, TwoComponentsAndTorus) {
  auto t = torus();
  auto b = box(Vec3(3, 3, 3), Vec3(4, 4, 4));
  auto p = prepare(merge(t, b));
  TetMesh tm = tetrahedralize(p.s, p.l, {}, {});
  EXPECT_NEAR(tet_mesh_volume(tm), p.l.volume[0] + p.l.volume[1], 1e-9);
}

TEST(Tetra, TargetTetCount) {
  auto p = prepare(sphere(3));
  for (int target : {5000, 20000}) {
    TetOptions o;
    o.target_tets = target;
    TetMesh tm = tetrahedralize(p.s, p.l, o, {});
    EXPECT_GT(tm.T.rows(), 0.6 * target);
    EXPECT_LT(tm.T.rows(), 1.5 * target);
  }
}

TEST(Tetra, MaxSizeRefinesInterior) {
  // (Gmsh 4.8 does not refine a surface of 8 vertices only, so a coarse sphere is used.)
  auto p = prepare(sphere(2));
  TetOptions o;
  o.max_size = 0.05;
  TetMesh fine = tetrahedralize(p.s, p.l, o, {});
  TetMesh coarse = tetrahedralize(p.s, p.l, {}, {});
  EXPECT_GT(fine.T.rows(), 5 * coarse.T.rows());
  EXPECT_EQ(measure_tets(fine.V, fine.T).inverted, 0);
}

TEST(Tetra, HxtAlgorithm) {
  auto p = prepare(sphere(3));
  TetOptions o;
  o.algorithm = "hxt";
  TetStats st;
  TetMesh tm = tetrahedralize(p.s, p.l, o, {}, &st);
  EXPECT_EQ(measure_tets(tm.V, tm.T).inverted, 0);
  check_tet_mesh(tm, &p.s, "hxt");  // whichever algorithm made it, the result is valid
  EXPECT_TRUE(st.algorithm == "hxt" || st.algorithm == "delaunay");
}

TEST(Tetra, RemeshedSurface) {
  auto p = prepare(box(Vec3(0, 0, 0), Vec3(2, 1, 1)));
  SurfaceMesh r = remesh_surface(p.s, p.l, 0.1);
  auto q = prepare(r);
  EXPECT_GT(q.s.F.rows(), 500);
  EXPECT_EQ(q.l.num_components(), 1);
  // Sharp edges survive: the bounding box is unchanged.
  EXPECT_NEAR((q.s.V.colwise().maxCoeff() - p.s.V.colwise().maxCoeff()).norm(), 0, 1e-9);
  TetMesh tm = tetrahedralize(q.s, q.l, {}, {});
  EXPECT_NEAR(tet_mesh_volume(tm), 2.0, 1e-6);
}

TEST(Tetra, SelfIntersectionNamesFaces) {
  // Two boxes that overlap, given as one surface: not a valid solid boundary.
  auto p = prepare(merge(box(), box(Vec3(0.5, 0.5, 0.5), Vec3(1.5, 1.5, 1.5))));
  try {
    tetrahedralize(p.s, p.l, {}, {});
    FAIL() << "expected a self-intersection error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::InvalidMesh);
    EXPECT_NE(std::string(e.what()).find("intersects itself"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("faces "), std::string::npos) << e.what();
  }
}
