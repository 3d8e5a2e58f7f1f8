// Round trips of every reader and writer, and format details (polygons, negative indices, welding).
#include <gmsh.h>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/gmsh_session.h"
#include "polycube/io/readers.h"
#include "polycube/io/writers.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {

void expect_same(const MatX3d& V1, const MatX3i& F1, const MeshData& m, double tol = 0) {
  ASSERT_EQ(m.V.rows(), V1.rows());
  ASSERT_EQ(m.F.rows(), F1.rows());
  EXPECT_LE((m.V - V1).cwiseAbs().maxCoeff(), tol);
  EXPECT_EQ(m.F, F1);
}

// One mesh with every element kind, on vertices with non-representable coordinates.
SurfaceMesh odd_sphere();
MeshData all_elements() {
  MeshData m;
  m.V = odd_sphere().V.topRows(12);
  m.F.resize(1, 3);
  m.F << 0, 1, 2;
  m.Q.resize(1, 4);
  m.Q << 0, 1, 2, 3;
  m.T.resize(2, 4);
  m.T << 0, 1, 2, 3, 4, 5, 6, 7;
  m.H.resize(1, 8);
  m.H << 0, 1, 2, 3, 4, 5, 6, 7;
  return m;
}

SurfaceMesh odd_sphere() {
  // Non-representable coordinates so that lossy writers would show.
  SurfaceMesh s = sphere(2, Vec3(0.1, -2.3, 1e3), 0.7);
  return s;
}

}  // namespace

TEST(IO, ObjRoundTrip) {
  auto s = odd_sphere();
  auto p = temp_dir("io") + "/a.obj";
  io::write_obj(p, s.V, s.F);
  auto m = io::read_mesh(p);
  EXPECT_EQ(m.format, "obj");
  expect_same(s.V, s.F, m);
}

TEST(IO, ObjPolygonsNegativeIndicesAndSlashes) {
  auto p = temp_dir("io") + "/poly.obj";
  write_text(p,
             "# comment\nmtllib x.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
             "g quad\nf 1/1/1 2/1/1 3/1/1 4/1/1\nv 2 0 0\nv 3 0 0\nv 3.5 1 0\nv 2.5 2 0\nv 1.5 1 0\n"
             "f -5 -4 -3 -2 -1\nf 1//1 2//1 3//1\n");
  auto m = io::read_mesh(p);
  ASSERT_EQ(m.V.rows(), 9);
  ASSERT_EQ(m.F.rows(), 2 + 3 + 1);
  EXPECT_EQ(m.face_source[0], 0);
  EXPECT_EQ(m.face_source[1], 0);
  EXPECT_EQ(m.face_source[2], 1);
  EXPECT_EQ(m.face_source[5], 2);
  EXPECT_EQ(m.face_line[5], 17);
  // Pentagon triangles use only its vertices 4..8 and cover its area (2.5 by the shoelace formula).
  double area = 0;
  for (int f = 2; f < 5; ++f) {
    for (int k = 0; k < 3; ++k) EXPECT_GE(m.F(f, k), 4);
    Vec3 a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    area += 0.5 * (b - a).cross(c - a).z();
  }
  EXPECT_NEAR(area, 2.5, 1e-12);
}

TEST(IO, NonConvexPolygonIsTriangulatedInside) {
  // An L-shaped hexagon: a fan from vertex 0 would leave the polygon.
  std::vector<Vec3> p = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {1, 1, 0}, {1, 2, 0}, {0, 2, 0}};
  // Rotate so that the reflex vertex comes first.
  std::rotate(p.begin(), p.begin() + 3, p.end());
  auto t = io::triangulate_polygon(p);
  ASSERT_EQ(t.size(), 4u);
  double area = 0;
  for (auto& tri : t) {
    double a = 0.5 * (p[tri[1]] - p[tri[0]]).cross(p[tri[2]] - p[tri[0]]).z();
    EXPECT_GT(a, 0);
    area += a;
  }
  EXPECT_NEAR(area, 3.0, 1e-12);
}

TEST(IO, OffRoundTripAndQuads) {
  auto s = odd_sphere();
  auto p = temp_dir("io") + "/a.off";
  io::write_off(p, s.V, s.F);
  expect_same(s.V, s.F, io::read_mesh(p));
  write_text(p, "OFF\n# c\n4 1 0\n0 0 0\n1 0 0 255 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n");
  auto m = io::read_mesh(p);
  EXPECT_EQ(m.F.rows(), 2);
}

TEST(IO, StlAsciiAndBinaryRoundTripWeld) {
  auto s = box(Vec3(-1, -2, -3), Vec3(4, 5, 6));
  for (bool binary : {false, true}) {
    auto p = temp_dir("io") + (binary ? "/b.stl" : "/a.stl");
    io::write_stl(p, s.V, s.F, binary);
    auto m = io::read_mesh(p);
    EXPECT_EQ(m.format, binary ? "stl-binary" : "stl-ascii");
    EXPECT_EQ(m.V.rows(), 8) << "coincident STL vertices must be welded";
    EXPECT_EQ(m.welded_vertices, 36 - 8);
    ASSERT_EQ(m.F.rows(), 12);
    for (int f = 0; f < 12; ++f)
      for (int k = 0; k < 3; ++k) EXPECT_EQ(m.V.row(m.F(f, k)), s.V.row(s.F(f, k)));
  }
}

TEST(IO, BinaryStlStartingWithSolid) {
  auto s = box();
  auto p = temp_dir("io") + "/solid.stl";
  io::write_stl(p, s.V, s.F, true);
  std::string d = read_text(p);
  d.replace(0, 5, "solid");
  write_text(p, d);
  auto m = io::read_mesh(p);
  EXPECT_EQ(m.format, "stl-binary");
  EXPECT_EQ(m.F.rows(), 12);
}

TEST(IO, PlyAllEncodingsRoundTrip) {
  auto s = odd_sphere();
  const char* names[] = {"ascii", "le", "be"};
  int i = 0;
  for (auto enc : {io::PlyEncoding::Ascii, io::PlyEncoding::BinaryLittleEndian, io::PlyEncoding::BinaryBigEndian}) {
    auto p = temp_dir("io") + "/" + names[i++] + ".ply";
    io::write_ply(p, s.V, s.F, enc);
    expect_same(s.V, s.F, io::read_mesh(p));
  }
}

TEST(IO, PlyWithExtraPropertiesAndFloat) {
  auto p = temp_dir("io") + "/x.ply";
  write_text(p,
             "ply\nformat ascii 1.0\ncomment hi\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "property uchar red\nelement face 1\nproperty list uchar uint vertex_index\nproperty int flags\n"
             "element edge 0\nproperty int v1\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n3 0 1 2 7\n");
  auto m = io::read_mesh(p);
  EXPECT_EQ(m.V.rows(), 3);
  EXPECT_EQ(m.F.rows(), 1);
  EXPECT_EQ(m.face_line[0], 18);
}

TEST(IO, MeditRoundTripAllElements) {
  MeshData m = all_elements();
  auto p = temp_dir("io") + "/a.mesh";
  io::write_medit(p, m);
  auto r = io::read_mesh(p);
  EXPECT_EQ(r.format, "medit");
  EXPECT_EQ(r.V, m.V);
  EXPECT_EQ(r.F, m.F);
  EXPECT_EQ(r.Q, m.Q);
  EXPECT_EQ(r.T, m.T);
  EXPECT_EQ(r.H, m.H);
}

TEST(IO, MeditSkipsKnownSections) {
  auto p = temp_dir("io") + "/b.mesh";
  write_text(p,
             "MeshVersionFormatted 1\nDimension\n3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n"
             "Edges\n1\n1 2 0\nCorners\n1\n1\nTetrahedra\n1\n1 2 3 4 0\nEnd\n");
  auto r = io::read_mesh(p);
  EXPECT_EQ(r.T.rows(), 1);
  EXPECT_EQ(r.vertex_line[1], 7);
}

TEST(IO, VtkAsciiAndBinaryRoundTrip) {
  MeshData m = all_elements();
  m.Q.resize(0, 4);  // quads of a volume file come back as quads; keep the cell count of the field
  for (bool binary : {false, true}) {
    auto p = temp_dir("io") + (binary ? "/b.vtk" : "/a.vtk");
    io::CellFields fields{{"label", {1, 2, 3, 4}}};
    io::write_vtk(p, m, binary, fields);
    auto r = io::read_mesh(p);
    EXPECT_EQ(r.format, binary ? "vtk-binary" : "vtk-ascii");
    EXPECT_EQ(r.V, m.V);
    EXPECT_EQ(r.F, m.F);
    EXPECT_EQ(r.T, m.T);
    EXPECT_EQ(r.H, m.H);
  }
}

TEST(IO, Vtk51OffsetsConnectivityLayout) {
  auto p = temp_dir("io") + "/c.vtk";
  write_text(p,
             "# vtk DataFile Version 5.1\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n"
             "CELLS 3 7\nOFFSETS vtktypeint64\n0 4 7\nCONNECTIVITY vtktypeint64\n0 1 2 3 0 2 1\nCELL_TYPES 2\n10\n5\n");
  auto r = io::read_mesh(p);
  ASSERT_EQ(r.T.rows(), 1);
  ASSERT_EQ(r.F.rows(), 1);
  EXPECT_EQ(r.F(0, 1), 2);
}

TEST(IO, VtkPolydata) {
  auto p = temp_dir("io") + "/d.vtk";
  write_text(p,
             "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 4 double\n0 0 0 1 0 0 1 1 0 0 1 0\n"
             "POLYGONS 1 5\n4 0 1 2 3\nPOINT_DATA 4\n");
  EXPECT_EQ(io::read_mesh(p).F.rows(), 2);
}

// Other programs read our files: Gmsh's own MEDIT and VTK readers (not ours) open them, with every
// element kind and the same corners in the same order (the hex and quad corner orders of MEDIT and
// VTK are Gmsh's too), the coordinates to the last bit where the format keeps them (ASCII at 17
// digits, VTK binary as doubles).
TEST(IO, GmshReadsOurMeditAndVtkFiles) {
  const MeshData m = all_elements();
  const std::string dir = temp_dir("io_gmsh");
  for (const char* name : {"a.mesh", "a.vtk", "b.vtk"}) {
    const std::string p = dir + "/" + name;
    if (std::string(name) == "a.mesh") io::write_medit(p, m);
    else io::write_vtk(p, m, std::string(name) == "b.vtk", {});
    io::Builder b;
    io::GmshSession g;
    g.run(ErrorKind::Parse, p, [&] {
      gmsh::open(p);
      EXPECT_EQ(g.last_error(), "") << name;
      io::collect_gmsh_mesh(b, p, false);
    });
    MeshData r;
    b.finish(r);
    // Corner coordinates element by element: the numbering may differ, the geometry may not.
    auto corners = [](const MeshData& d, const auto& E) {
      std::vector<double> xyz;
      for (Eigen::Index e = 0; e < E.rows(); ++e)
        for (Eigen::Index k = 0; k < E.cols(); ++k)
          for (int c = 0; c < 3; ++c) xyz.push_back(d.V(E(e, k), c));
      return xyz;
    };
    EXPECT_EQ(corners(r, r.F), corners(m, m.F)) << name;
    EXPECT_EQ(corners(r, r.Q), corners(m, m.Q)) << name;
    EXPECT_EQ(corners(r, r.T), corners(m, m.T)) << name;
    EXPECT_EQ(corners(r, r.H), corners(m, m.H)) << name;
  }
  // Orientation: a positive tet and a unit hex in our convention (core/types.h) have a positive
  // Jacobian in Gmsh's reading of each format (a corner order Gmsh read otherwise would turn them).
  MeshData c;
  c.V.resize(8, 3);
  c.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1;
  c.T.resize(1, 4);
  c.T << 0, 1, 3, 4;
  c.H.resize(1, 8);
  c.H << 0, 1, 2, 3, 4, 5, 6, 7;
  for (const char* name : {"c.mesh", "c.vtk"}) {
    const std::string p = dir + "/" + name;
    if (std::string(name) == "c.mesh") io::write_medit(p, c);
    else io::write_vtk(p, c, true, {});
    io::GmshSession g;
    g.run(ErrorKind::Parse, p, [&] {
      gmsh::open(p);
      for (int type : {4, 5}) {  // Gmsh's 4-node tetrahedron and 8-node hexahedron
        std::vector<double> local, weights, jac, det, xyz;
        gmsh::model::mesh::getIntegrationPoints(type, "Gauss1", local, weights);
        gmsh::model::mesh::getJacobians(type, local, jac, det, xyz);
        ASSERT_FALSE(det.empty()) << name << " type " << type;
        for (double d : det) EXPECT_GT(d, 0) << name << " type " << type;
      }
    });
  }
}

TEST(IO, MshRoundTripSurfaceAndVolume) {
  auto s = odd_sphere();
  auto p = temp_dir("io") + "/s.msh";
  io::write_msh(p, make_mesh_data(s.V, s.F));
  auto r = io::read_mesh(p);
  EXPECT_EQ(r.format, "msh");
  expect_same(s.V, s.F, r, 1e-15 * 1e3);  // Gmsh writes 16 significant digits
  MeshData m;
  m.V = s.V.topRows(8);
  m.T.resize(2, 4);
  m.T << 0, 1, 2, 3, 4, 5, 6, 7;
  io::write_msh(p, m);
  r = io::read_mesh(p);
  EXPECT_EQ(r.T, m.T);
  EXPECT_LE((r.V - m.V).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(IO, CadStepAndBrepImport) {
  // CAD files written by Gmsh's OpenCASCADE kernel, read back and meshed.
  std::string dir = temp_dir("io");
  for (const char* ext : {"step", "brep"}) {
    std::string path = dir + "/box." + ext;
    {
      io::GmshSession g;
      g.run(ErrorKind::Internal, "writing test CAD", [&] {
        gmsh::model::add("box");
        gmsh::model::occ::addBox(1, 2, 3, 2, 3, 4);
        gmsh::model::occ::synchronize();
        gmsh::write(path);
      });
    }
    auto m = io::read_mesh(path);
    EXPECT_EQ(m.format, ext);
    EXPECT_GT(m.F.rows(), 12);
    Vec3 lo = m.V.colwise().minCoeff(), hi = m.V.colwise().maxCoeff();
    EXPECT_NEAR((lo - Vec3(1, 2, 3)).norm(), 0, 1e-6) << "CAD import keeps the model's position";
    EXPECT_NEAR((hi - Vec3(3, 5, 7)).norm(), 0, 1e-6) << "CAD import keeps the model's scale";
  }
}
