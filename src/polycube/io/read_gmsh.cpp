// Formats read through the Gmsh library: .msh and CAD (STEP, IGES, BREP via OpenCASCADE).
#include <gmsh.h>

#include <cmath>
#include <filesystem>
#include <unordered_map>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/gmsh_session.h"
#include "polycube/io/readers.h"

namespace polycube::io {

namespace {
void require_file(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error(ErrorKind::Parse, path + ": no such file");
  if (std::filesystem::is_directory(path, ec)) throw Error(ErrorKind::Parse, path + ": is a directory, not a mesh file");
  if (std::filesystem::file_size(path, ec) == 0) throw Error(ErrorKind::Parse, path + ": file is empty");
}

}  // namespace

// Copies the current Gmsh model's mesh (all entities) into a Builder. Element types: first-order
// and higher-order variants of triangle, quad, tet, hex (only corner nodes are kept).
void collect_gmsh_mesh(Builder& b, const std::string& path, bool surface_only) {
  std::vector<std::size_t> tags;
  std::vector<double> coord, param;
  gmsh::model::mesh::getNodes(tags, coord, param, -1, -1, false, false);
  std::unordered_map<std::size_t, int> id;
  id.reserve(tags.size());
  for (size_t i = 0; i < tags.size(); ++i) {
    if (id.count(tags[i])) continue;
    id[tags[i]] = b.num_vertices();
    b.add_vertex(coord[3 * i], coord[3 * i + 1], coord[3 * i + 2], 0);
  }
  auto map = [&](std::size_t t) {
    auto it = id.find(t);
    if (it == id.end()) throw Error(ErrorKind::Parse, path + ": element refers to undefined node " + std::to_string(t));
    return it->second;
  };
  std::vector<int> types;
  gmsh::model::mesh::getElementTypes(types, -1, -1);
  int nface = 0;
  for (int type : types) {
    std::string name;
    int dim, order, nn, npv;
    std::vector<double> lc;
    gmsh::model::mesh::getElementProperties(type, name, dim, order, nn, lc, npv);
    if (dim < 2) continue;
    if (surface_only && dim != 2) continue;
    std::vector<std::size_t> et, en;
    gmsh::model::mesh::getElementsByType(type, et, en, -1);
    const int corners = npv;  // primary vertices
    for (size_t e = 0; e < et.size(); ++e) {
      const std::size_t* n = &en[e * nn];
      if (dim == 2 && corners == 3) {
        b.add_triangle(map(n[0]), map(n[1]), map(n[2]), nface++, 0);
      } else if (dim == 2 && corners == 4) {
        if (surface_only) b.add_polygon({map(n[0]), map(n[1]), map(n[2]), map(n[3])}, nface++, 0);
        else for (int k = 0; k < 4; ++k) b.q.push_back(map(n[k]));
      } else if (dim == 3 && corners == 4) {
        for (int k = 0; k < 4; ++k) b.t.push_back(map(n[k]));
      } else if (dim == 3 && corners == 8) {
        for (int k = 0; k < 8; ++k) b.h.push_back(map(n[k]));
      } else {
        throw Error(ErrorKind::Parse, path + ": unsupported element type '" + name +
                                          "' (supported: triangles, quadrangles, tetrahedra, hexahedra)");
      }
    }
  }
}
double gmsh_model_diagonal() {
  double x0, y0, z0, x1, y1, z1;
  gmsh::model::getBoundingBox(-1, -1, x0, y0, z0, x1, y1, z1);
  return std::sqrt((x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0) + (z1 - z0) * (z1 - z0));
}

MeshData read_msh(const std::string& path) {
  require_file(path);
  GmshSession s;
  Builder b;
  s.run(ErrorKind::Parse, path, [&] {
    gmsh::open(path);
    std::string err = s.last_error();
    if (!err.empty()) throw Error(ErrorKind::Parse, path + ": " + err);
    collect_gmsh_mesh(b, path, false);
  });
  MeshData m;
  m.path = path;
  m.format = "msh";
  b.finish(m);
  return m;
}

MeshData read_cad(const std::string& path, const CadOptions& opt) {
  require_file(path);
  GmshSession s;
  Builder b;
  s.run(ErrorKind::Parse, path, [&] {
    std::vector<std::pair<int, int>> out;
    gmsh::model::occ::importShapes(path, out, true);
    gmsh::model::occ::synchronize();
    if (out.empty()) throw Error(ErrorKind::Parse, path + ": the CAD file contains no shape");
    const double diag = gmsh_model_diagonal();
    gmsh::option::setNumber("Mesh.MeshSizeMax", opt.mesh_size * diag);
    gmsh::option::setNumber("Mesh.MeshSizeMin", 0.1 * opt.mesh_size * diag);
    gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 12);
  });
  s.run(ErrorKind::InvalidMesh, path + ": surface meshing of the CAD model failed", [&] {
    gmsh::model::mesh::generate(2);
    collect_gmsh_mesh(b, path, true);
  });
  MeshData m;
  m.path = path;
  m.format = extension(path);
  b.finish(m);
  if (m.F.rows() == 0) throw Error(ErrorKind::InvalidMesh, path + ": the CAD model has no surface to mesh");
  return m;
}

}  // namespace polycube::io
