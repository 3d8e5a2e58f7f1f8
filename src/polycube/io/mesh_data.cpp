#include "polycube/io/mesh_data.h"

namespace polycube {

std::string MeshData::face_where(int i) const {
  int src = i < static_cast<int>(face_source.size()) ? face_source[i] : i;
  std::string s = "face " + std::to_string(src);
  if (i < static_cast<int>(face_line.size()) && face_line[i] > 0) s += " (line " + std::to_string(face_line[i]) + ")";
  return s;
}

std::string MeshData::vertex_where(int i) const {
  std::string s = "vertex " + std::to_string(i);
  if (i < static_cast<int>(vertex_line.size()) && vertex_line[i] > 0) s += " (line " + std::to_string(vertex_line[i]) + ")";
  return s;
}

MeshData make_mesh_data(const MatX3d& V, const MatX3i& F, const std::string& format) {
  MeshData m;
  m.format = format;
  m.V = V;
  m.F = F;
  m.face_source.resize(F.rows());
  for (int i = 0; i < F.rows(); ++i) m.face_source[i] = i;
  return m;
}

}  // namespace polycube
