#include <algorithm>
#include <cctype>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/readers.h"

namespace polycube::io {

std::string extension(const std::string& path) {
  size_t slash = path.find_last_of("/\\");
  size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string e = path.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

static const char* kFormats = "obj, off, stl, ply, mesh, vtk, msh, step/stp, iges/igs, brep";

bool is_supported(const std::string& path) {
  const std::string e = extension(path);
  for (const char* k : {"obj", "off", "stl", "ply", "mesh", "vtk", "msh", "step", "stp", "iges", "igs", "brep", "brp"})
    if (e == k) return true;
  return false;
}

MeshData read_mesh(const std::string& path, const CadOptions& cad, bool keep_quads) {
  const std::string e = extension(path);
  MeshData m;
  if (e == "obj") m = read_obj(path);
  else if (e == "off") m = read_off(path);
  else if (e == "stl") m = read_stl(path);
  else if (e == "ply") m = read_ply(path);
  else if (e == "mesh") m = read_medit(path);
  else if (e == "vtk") m = read_vtk(path);
  else if (e == "msh") m = read_msh(path);
  else if (e == "step" || e == "stp" || e == "iges" || e == "igs" || e == "brep" || e == "brp") m = read_cad(path, cad);
  else
    throw Error(ErrorKind::Usage, path + ": unknown file extension '" + e + "' (supported: " + kFormats + ")");
  // A surface given as quads (no volume elements): its quads are surface polygons.
  if (!keep_quads && !m.is_volume() && m.Q.rows() > 0) {
    Builder b;
    for (int i = 0; i < m.V.rows(); ++i) b.add_vertex(m.V(i, 0), m.V(i, 1), m.V(i, 2), i < (int)m.vertex_line.size() ? m.vertex_line[i] : 0);
    for (int i = 0; i < m.F.rows(); ++i) b.add_triangle(m.F(i, 0), m.F(i, 1), m.F(i, 2), m.face_source[i], m.face_line[i]);
    int next = m.F.rows();
    for (int i = 0; i < m.Q.rows(); ++i) b.add_polygon({m.Q(i, 0), m.Q(i, 1), m.Q(i, 2), m.Q(i, 3)}, next++, 0);
    std::string p = m.path, f = m.format;
    b.finish(m);
    m.Q.resize(0, 4);
    m.path = p;
    m.format = f;
  }
  if (m.V.rows() == 0) throw Error(ErrorKind::Parse, path + ": file contains no vertices");
  if (m.F.rows() == 0 && m.Q.rows() == 0 && !m.is_volume())
    throw Error(ErrorKind::Parse, path + ": file contains no faces or cells (" + std::to_string(m.V.rows()) + " vertices only)");
  return m;
}

}  // namespace polycube::io
