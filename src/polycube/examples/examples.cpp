#include "polycube/examples/examples.h"

#include <gmsh.h>

#include <cmath>
#include <unordered_map>

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
  };
  return l;
}

namespace {
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
    double x0, y0, z0, x1, y1, z1;
    gmsh::model::getBoundingBox(-1, -1, x0, y0, z0, x1, y1, z1);
    const double diag = std::sqrt((x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0) + (z1 - z0) * (z1 - z0));
    gmsh::option::setNumber("Mesh.MeshSizeMax", mesh_size * diag);
    gmsh::option::setNumber("Mesh.MeshSizeMin", 0.25 * mesh_size * diag);
    gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 16);
    gmsh::model::mesh::generate(2);
    std::vector<std::size_t> tags;
    std::vector<double> xyz, par;
    gmsh::model::mesh::getNodes(tags, xyz, par, -1, -1, true, false);
    std::unordered_map<std::size_t, int> id;
    for (size_t i = 0; i < tags.size(); ++i)
      if (!id.count(tags[i])) {
        id[tags[i]] = b.num_vertices();
        b.add_vertex(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2], 0);
      }
    std::vector<std::size_t> et, en;
    gmsh::model::mesh::getElementsByType(2, et, en, -1);
    for (size_t i = 0; i < et.size(); ++i)
      b.add_triangle(id.at(en[3 * i]), id.at(en[3 * i + 1]), id.at(en[3 * i + 2]), static_cast<int>(i), 0);
  });
  MeshData m;
  m.format = "example:" + name;
  b.finish(m);
  return m;
}

}  // namespace polycube::examples
