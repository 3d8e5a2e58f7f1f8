#include "polycube/examples/examples.h"

#include <gmsh.h>

#include <cmath>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/gmsh_session.h"

namespace polycube::examples {

namespace occ = gmsh::model::occ;
using DimTags = std::vector<std::pair<int, int>>;

const std::vector<ExampleInfo>& list() {
  static const std::vector<ExampleInfo> l = {
      {"box_hole", "2 x 1.5 x 1 box with a round through-hole (genus 1)"},
      {"torus", "torus, radii 1 and 0.35 (genus 1, no flat faces)"},
      {"l_bracket", "L-shaped block, legs 2 long (8 charts and 12 corners expected as a polycube)"},
      {"sphere", "unit sphere (6 charts expected as a polycube)"},
      {"rocker", "rocker-arm-like part: two bosses with holes joined by an arm (genus 2)"},
      {"two_components", "a cube and a separate sphere (two components)"},
      {"chamfer_box", "unit cube with one edge chamfered at 45 degrees (15 feature curves at 30 degrees)"},
      {"bumpy_box", "2 x 2 x 1 box with four spherical bumps (radius 0.3) on its top (beta removes their charts)"},
      {"ramp", "2 x 1 x 1 block whose top-right edge is cut by a 35-degree slope (a polycube rounds the top edge of the slope away)"},
  };
  return l;
}

namespace {
// A prism: the polygon (x, z) pts in the plane y = 0, extruded by `depth` along +y.
void prism(const std::vector<std::pair<double, double>>& pts, double depth) {
  std::vector<int> p, l;
  for (auto [x, z] : pts) p.push_back(occ::addPoint(x, 0, z));
  for (size_t i = 0; i < p.size(); ++i) l.push_back(occ::addLine(p[i], p[(i + 1) % p.size()]));
  const int s = occ::addPlaneSurface({occ::addCurveLoop(l)});
  DimTags out;
  occ::extrude({{2, s}}, 0, depth, 0, out);
}

void build(const std::string& name) {
  if (name == "box_hole") {
    int b = occ::addBox(0, 0, 0, 2, 1.5, 1);
    int c = occ::addCylinder(1, 0.75, -0.5, 0, 0, 2, 0.35);
    DimTags out;
    std::vector<DimTags> map;
    occ::cut({{3, b}}, {{3, c}}, out, map);
  } else if (name == "torus") {
    occ::addTorus(0, 0, 0, 1, 0.35);
  } else if (name == "l_bracket") {
    int a = occ::addBox(0, 0, 0, 2, 1, 0.5);
    int b = occ::addBox(0, 0, 0, 0.5, 1, 2);
    DimTags out;
    std::vector<DimTags> map;
    occ::fuse({{3, a}}, {{3, b}}, out, map);
  } else if (name == "sphere") {
    occ::addSphere(0, 0, 0, 1);
  } else if (name == "rocker") {
    int b1 = occ::addCylinder(0, 0, 0, 0, 0, 0.6, 0.6);
    int b2 = occ::addCylinder(3, 0, 0, 0, 0, 0.6, 0.45);
    int arm = occ::addBox(0, -0.25, 0.1, 3, 0.5, 0.4);
    DimTags fused, out;
    std::vector<DimTags> map;
    occ::fuse({{3, b1}}, {{3, b2}, {3, arm}}, fused, map);
    int h1 = occ::addCylinder(0, 0, -0.5, 0, 0, 2, 0.3);
    int h2 = occ::addCylinder(3, 0, -0.5, 0, 0, 2, 0.2);
    occ::cut(fused, {{3, h1}, {3, h2}}, out, map);
  } else if (name == "chamfer_box") {
    prism({{0, 0}, {1, 0}, {1, 0.75}, {0.75, 1}, {0, 1}}, 1);
  } else if (name == "bumpy_box") {
    const int b = occ::addBox(0, 0, 0, 2, 2, 1);
    DimTags bumps, out;
    for (double x : {0.6, 1.4})
      for (double y : {0.6, 1.4}) bumps.push_back({3, occ::addSphere(x, y, 0.95, 0.3)});
    std::vector<DimTags> map;
    occ::fuse({{3, b}}, bumps, out, map);
  } else if (name == "ramp") {
    const double t = std::tan(35 * M_PI / 180);
    prism({{0, 0}, {2, 0}, {2, 1 - 0.8 * t}, {1.2, 1}, {0, 1}}, 1);
  } else if (name == "two_components") {
    occ::addBox(0, 0, 0, 1, 1, 1);
    occ::addSphere(2.5, 0.5, 0.5, 0.5);
  } else {
    std::string known;
    for (auto& e : list()) known += (known.empty() ? "" : ", ") + e.name;
    throw Error(ErrorKind::Usage, "unknown example '" + name + "' (known: " + known + ")");
  }
  occ::synchronize();
}
}  // namespace

MeshData make(const std::string& name, double mesh_size) {
  io::GmshSession s;
  io::Builder b;
  s.run(ErrorKind::Internal, "example " + name, [&] {
    gmsh::model::add(name);
    build(name);
    const double diag = io::gmsh_model_diagonal();
    gmsh::option::setNumber("Mesh.MeshSizeMax", mesh_size * diag);
    gmsh::option::setNumber("Mesh.MeshSizeMin", 0.25 * mesh_size * diag);
    gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 16);
    gmsh::model::mesh::generate(2);
    io::collect_gmsh_mesh(b, "example " + name, true);
  });
  MeshData m;
  m.format = "example:" + name;
  b.finish(m);
  return m;
}

}  // namespace polycube::examples
