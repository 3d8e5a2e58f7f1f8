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

// target_tets counts the tets after split_boundary_tets (the mesh the deformation gets), aimed at
// within 5% in up to four Gmsh runs.
TEST(Tetra, TargetTetCount) {
  auto p = prepare(sphere(3));
  for (int target : {5000, 20000}) {
    TetOptions o;
    o.target_tets = target;
    TetStats st;
    TetMesh tm = tetrahedralize(p.s, p.l, o, {}, &st);
    split_boundary_tets(tm);
    EXPECT_NEAR(static_cast<double>(tm.T.rows()) / target, 1.0, 0.05) << tm.T.rows() << " tets in " << st.attempts << " runs";
    EXPECT_LE(st.attempts, 4);
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

TEST(Tetra, RemoveSpikesFlattensLowSpikesOnly) {
  // A box whose face triangle f gets a spike: a vertex above its centroid, joined to its corners
  // (1-to-3 split), at height h.
  const SurfaceMesh b = grid_box(3);
  auto spiked = [&](double h) {
    SurfaceMesh s = b;
    const int f = 5, a = s.F(f, 0), c = s.F(f, 1), d = s.F(f, 2);
    const Vec3 pa = s.V.row(a), pc = s.V.row(c), pd = s.V.row(d);
    const Vec3 n = (pc - pa).cross(pd - pa).normalized();
    const int v = static_cast<int>(s.V.rows());
    s.V.conservativeResize(v + 1, 3);
    s.V.row(v) = ((pa + pc + pd) / 3 + h * n).transpose();
    s.F.row(f) << a, c, v;
    s.F.conservativeResize(s.F.rows() + 2, 3);
    s.F.row(s.F.rows() - 2) << c, d, v;
    s.F.row(s.F.rows() - 1) << d, a, v;
    return s;
  };
  // Higher than the limit: kept, and nothing else either (the box's corners are not low).
  SurfaceMesh high = spiked(0.01);
  EXPECT_EQ(remove_spikes(high, 0.005), 0);
  EXPECT_EQ(high.F.rows(), b.F.rows() + 2);
  // Lower: the three triangles become the face triangle again, the vertex is dropped.
  SurfaceMesh low = spiked(0.001);
  EXPECT_EQ(remove_spikes(low, 0.005), 1);
  ASSERT_EQ(low.V.rows(), b.V.rows());
  ASSERT_EQ(low.F.rows(), b.F.rows());
  EXPECT_LE((low.V - b.V).cwiseAbs().maxCoeff(), 0.0);
  // Same triangles as the box, with their orientation (as sorted rotations of each row).
  auto canon = [](const MatX3i& F) {
    std::vector<std::array<int, 3>> r;
    for (int f = 0; f < F.rows(); ++f) {
      std::array<int, 3> t{F(f, 0), F(f, 1), F(f, 2)};
      while (t[0] != std::min({t[0], t[1], t[2]})) std::rotate(t.begin(), t.begin() + 1, t.end());
      r.push_back(t);
    }
    std::sort(r.begin(), r.end());
    return r;
  };
  EXPECT_EQ(canon(low.F), canon(b.F));
  // The surface is still a valid closed surface and tetrahedralizes.
  Prepared p = prepare(low);
  EXPECT_NO_THROW(tetrahedralize(p.s, p.l, {}, Hooks{}));
  // A tetrahedron is all spikes of itself: nothing to flatten into (its base triangle exists).
  SurfaceMesh tet;
  tet.V.resize(4, 3);
  tet.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0.001;
  tet.F.resize(4, 3);
  tet.F << 0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2;
  EXPECT_EQ(remove_spikes(tet, 0.01), 0);
  EXPECT_EQ(tet.F.rows(), 4);
}
