// User control: feature detection, the constraint file, mapping to the tet boundary, and the
// effect of sharp constraints and of beta on the polycube.
#include <fstream>

#include "polycube/constraints/constraints.h"
#include "polycube/core/error.h"
#include "polycube/examples/examples.h"
#include "polycube/io/readers.h"
#include "polycube/pipeline/pipeline.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;
using nlohmann::json;

namespace {

SurfaceMesh surface_of(const MeshData& m) {
  SurfaceMesh s;
  s.V = m.V;
  s.F = m.F;
  return s;
}

// Largest distance of a curve's vertices from the line through its two ends.
double straightness(const SurfaceMesh& s, const constraints::Constraint& c) {
  const Vec3 a = s.V.row(c.edges.front()[0]), b = s.V.row(c.edges.back()[1]);
  double d = 0;
  for (const auto& e : c.edges)
    for (int v : e) {
      const Vec3 p = s.V.row(v);
      d = std::max(d, (p - a).cross(b - a).norm() / (b - a).norm());
    }
  return d;
}

}  // namespace

TEST(Constraints, AutoFeaturesOfAChamferedBox) {
  // A unit cube with one edge chamfered at 45 degrees has 15 straight feature edges; at 50
  // degrees the two chamfer edges drop out and the curves of the two end faces join through the
  // chamfer's corners: 2 x 2 + 2 x 1 ... = 9 curves (3 per end face, 3 along the prism).
  const SurfaceMesh s = surface_of(examples::make("chamfer_box", 0.1));
  const auto f30 = constraints::detect_features(s, 30);
  ASSERT_EQ(f30.size(), 15u);
  for (const auto& c : f30) {
    EXPECT_TRUE(c.sharp);
    EXPECT_LT(straightness(s, c), 1e-9) << c.name;
    // Consecutive edges chain end to start.
    for (size_t i = 1; i < c.edges.size(); ++i) EXPECT_EQ(c.edges[i][0], c.edges[i - 1][1]) << c.name;
  }
  EXPECT_EQ(constraints::detect_features(s, 50).size(), 9u);
  // No feature on a sphere at 30 degrees.
  EXPECT_TRUE(constraints::detect_features(sphere(3), 30).empty());
}

TEST(Constraints, FileRoundTripRegionsAndErrors) {
  const std::string dir = temp_dir("constraints_io");
  std::vector<constraints::Constraint> cs(2);
  cs[0].name = "rim";
  cs[0].edges = {{0, 1}, {1, 2}};
  cs[0].weight = 50;
  cs[1].sharp = false;
  cs[1].faces = {0, 1};
  constraints::write_constraints(dir + "/c.json", cs);
  const auto back = constraints::read_constraints(dir + "/c.json");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].name, "rim");
  EXPECT_TRUE(back[0].sharp);
  EXPECT_EQ(back[0].weight, 50);
  EXPECT_EQ(back[0].edges, cs[0].edges);
  EXPECT_FALSE(back[1].sharp);
  EXPECT_EQ(back[1].faces, cs[1].faces);

  // Regions on a box: its two triangles of one face share one edge (flat: that edge), and their
  // border is the square's 4 edges (sharp).
  const SurfaceMesh b = box();
  int f0 = -1, f1 = -1;
  for (int f = 0; f < b.F.rows() && f1 < 0; ++f) {
    bool top = true;
    for (int k = 0; k < 3; ++k) top = top && b.V(b.F(f, k), 2) == 1.0;
    if (top) (f0 < 0 ? f0 : f1) = f;
  }
  ASSERT_GE(f1, 0);
  constraints::Constraint region;
  region.faces = {f0, f1};
  region.sharp = false;
  EXPECT_EQ(constraints::constraint_edges(region, b, 0).size(), 1u);
  region.sharp = true;
  EXPECT_EQ(constraints::constraint_edges(region, b, 0).size(), 4u);

  // Errors name the file, the constraint and the problem.
  auto parse_error = [&](const std::string& text) {
    write_text(dir + "/bad.json", text);
    try {
      constraints::read_constraints(dir + "/bad.json");
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::Parse);
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(parse_error("{\"constraints\": [").find("not valid JSON"), std::string::npos);
  EXPECT_NE(parse_error("{\"constraints\": [{\"type\": \"round\", \"edges\": [[0, 1]]}]}").find("constraint 0"),
            std::string::npos);
  EXPECT_NE(parse_error("{\"constraints\": [{\"type\": \"flat\"}]}").find("neither"), std::string::npos);
  EXPECT_NE(parse_error("{\"constraints\": [{\"type\": \"sharp\", \"edges\": [[0, 1, 2]]}]}").find("pair"),
            std::string::npos);
  constraints::Constraint far;
  far.edges = {{0, 1000}};
  EXPECT_THROW(constraints::constraint_edges(far, b, 3), Error);
  far.edges = {{0, 6}};  // opposite corners of the box: not an edge
  try {
    constraints::constraint_edges(far, b, 3);
    ADD_FAILURE() << "no error for a non-edge";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not joined by an edge"), std::string::npos) << e.what();
  }
}

TEST(Constraints, SharpConstraintTurnsARoundedEdgeIntoAPolycubeEdge) {
  // The ramp's slope (35 degrees) joins the top at an edge whose normals differ by 35 degrees: the
  // plain deformation rounds it away (the ramp becomes a box, 6 charts). A sharp constraint on
  // that edge makes it a polycube edge: normals at 90 degrees, 8 charts, 12 corners.
  const std::string dir = temp_dir("ramp_sharp");
  const MeshData m = examples::make("ramp", 0.04);
  constraints::Constraint c;
  c.name = "slope top";
  for (int f = 0; f < m.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = m.F(f, k), b = m.F(f, (k + 1) % 3);
      auto on = [&](int v) { return std::abs(m.V(v, 0) - 1.2) < 1e-9 && std::abs(m.V(v, 2) - 1.0) < 1e-9; };
      if (a < b && on(a) && on(b)) c.edges.push_back({a, b});
    }
  ASSERT_GE(c.edges.size(), 5u);
  constraints::write_constraints(dir + "/c.json", {c});

  PipelineOptions opt;
  opt.example = "ramp";
  opt.until = Stage::Polycube;
  opt.out_dir = dir + "/free";
  const json free = run_pipeline(opt);
  EXPECT_EQ(free["polycube"]["charts"], 6);
  opt.out_dir = dir + "/sharp";
  opt.constraints_file = dir + "/c.json";
  const json sharp = run_pipeline(opt);
  EXPECT_EQ(sharp["polycube"]["charts"], 8);
  EXPECT_EQ(sharp["polycube"]["corners"], 12);
  const json& cj = sharp["constraints"];
  EXPECT_EQ(cj["count"], 1);
  EXPECT_EQ(cj["sharp"], 1);
  EXPECT_EQ(cj["edges"].get<size_t>(), c.edges.size());
  EXPECT_LT(cj["worst_dihedral_error_deg"].get<double>(), 5.0);
  EXPECT_EQ(cj["polycube_satisfied"], 1.0);
  EXPECT_EQ(cj["per_constraint"][0]["name"], "slope top");
}

TEST(Constraints, BetaAndAFlatRegionRemoveBumps) {
  // bumpy_box: a 2 x 2 x 1 box with four spherical bumps on its top. Without the complexity
  // penalty every bump becomes a small cube (5 charts, 8 corners each: 26 charts, 40 corners);
  // beta = 1 flattens them all (6 charts, 8 corners); a flat region on one bump's triangles
  // removes only that bump (21 charts, 32 corners).
  const std::string dir = temp_dir("bumpy");
  PipelineOptions opt;
  opt.example = "bumpy_box";
  opt.until = Stage::Polycube;
  opt.out_dir = dir + "/beta0";
  const json b0 = run_pipeline(opt);
  EXPECT_EQ(b0["polycube"]["charts"], 26);
  EXPECT_EQ(b0["polycube"]["corners"], 40);
  opt.deform.beta = 1;
  opt.out_dir = dir + "/beta1";
  const json b1 = run_pipeline(opt);
  EXPECT_EQ(b1["polycube"]["charts"], 6);
  EXPECT_EQ(b1["polycube"]["corners"], 8);

  const MeshData m = examples::make("bumpy_box", opt.example_mesh_size);
  constraints::Constraint flat;
  flat.sharp = false;
  flat.name = "bump at (0.6, 0.6)";
  for (int f = 0; f < m.F.rows(); ++f) {
    const Vec3 c = (m.V.row(m.F(f, 0)) + m.V.row(m.F(f, 1)) + m.V.row(m.F(f, 2))).transpose() / 3;
    if (c.z() > 1.0 && (c - Vec3(0.6, 0.6, 0.95)).norm() < 0.31) flat.faces.push_back(f);
  }
  ASSERT_GT(flat.faces.size(), 10u);
  constraints::write_constraints(dir + "/flat.json", {flat});
  opt.deform.beta = 0;
  opt.constraints_file = dir + "/flat.json";
  opt.out_dir = dir + "/flat";
  const json fl = run_pipeline(opt);
  EXPECT_EQ(fl["polycube"]["charts"], 21);
  EXPECT_EQ(fl["polycube"]["corners"], 32);
  EXPECT_EQ(fl["constraints"]["flat"], 1);
  EXPECT_EQ(fl["constraints"]["polycube_satisfied"], 1.0);
}

TEST(Constraints, PaintedRegionsFromObjGroupsAndPlyProperties) {
  const std::string dir = temp_dir("painted");
  // A box whose top face (two triangles) is the group "lid".
  const SurfaceMesh b = box();
  std::string obj;
  for (int v = 0; v < b.V.rows(); ++v)
    obj += "v " + std::to_string(b.V(v, 0)) + " " + std::to_string(b.V(v, 1)) + " " + std::to_string(b.V(v, 2)) + "\n";
  std::string ply = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(b.V.rows()) +
                    "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                    std::to_string(b.F.rows()) + "\nproperty list uchar int vertex_indices\nproperty int region\nend_header\n";
  for (int v = 0; v < b.V.rows(); ++v)
    ply += std::to_string(b.V(v, 0)) + " " + std::to_string(b.V(v, 1)) + " " + std::to_string(b.V(v, 2)) + "\n";
  std::vector<int> top;
  for (int f = 0; f < b.F.rows(); ++f) {
    bool up = true;
    for (int k = 0; k < 3; ++k) up = up && b.V(b.F(f, k), 2) == 1.0;
    if (up) top.push_back(f);
    obj += std::string(up ? "g lid\n" : "g body\n") + "f " + std::to_string(b.F(f, 0) + 1) + " " +
           std::to_string(b.F(f, 1) + 1) + " " + std::to_string(b.F(f, 2) + 1) + "\n";
    ply += "3 " + std::to_string(b.F(f, 0)) + " " + std::to_string(b.F(f, 1)) + " " + std::to_string(b.F(f, 2)) +
           (up ? " 7\n" : " 0\n");
  }
  write_text(dir + "/box.obj", obj);
  write_text(dir + "/box.ply", ply);
  const MeshData mo = io::read_mesh(dir + "/box.obj"), mp = io::read_mesh(dir + "/box.ply");
  ASSERT_EQ(mo.face_group.size(), static_cast<size_t>(b.F.rows()));
  ASSERT_EQ(mp.face_group.size(), static_cast<size_t>(b.F.rows()));
  for (int f : top) {
    EXPECT_EQ(mo.face_group[f], "lid");
    EXPECT_EQ(mp.face_group[f], "7");
  }
  std::vector<constraints::Constraint> cs(1);
  cs[0].sharp = false;
  cs[0].group = "lid";
  constraints::resolve_groups(cs, mo.face_group);
  EXPECT_EQ(cs[0].faces, top);
  cs[0].group = "7";
  cs[0].faces.clear();
  constraints::resolve_groups(cs, mp.face_group);
  EXPECT_EQ(cs[0].faces, top);
  cs[0].group = "nose";
  EXPECT_THROW(constraints::resolve_groups(cs, mo.face_group), Error);
  // A file without groups has none.
  EXPECT_TRUE(io::read_mesh(dir + "/box.obj").face_group.size() == static_cast<size_t>(b.F.rows()));
  write_text(dir + "/plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_TRUE(io::read_mesh(dir + "/plain.obj").face_group.empty());
}
