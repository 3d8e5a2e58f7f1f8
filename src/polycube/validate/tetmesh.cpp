#include "polycube/validate/tetmesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <sstream>

#include "polycube/core/error.h"

namespace polycube {

double tet_volume(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  return (b - a).dot((c - a).cross(d - a)) / 6.0;
}

TetQuality measure_tets(const MatX3d& V, const MatX4i& T) {
  TetQuality q;
  q.tets = static_cast<int>(T.rows());
  double mind = 180, maxd = 0, minv = std::numeric_limits<double>::infinity();
  for (int t = 0; t < T.rows(); ++t) {
    Vec3 p[4];
    for (int k = 0; k < 4; ++k) p[k] = V.row(T(t, k));
    double vol = tet_volume(p[0], p[1], p[2], p[3]);
    double l = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) l = std::max(l, (p[i] - p[j]).norm());
    minv = std::min(minv, vol);
    bool zero = std::abs(6 * vol) <= 1e-12 * l * l * l;
    if (zero) q.zero_volume++;
    else if (vol < 0) q.inverted++;
    if ((zero || vol < 0) && q.bad.size() < 10) q.bad.push_back(t);
    // Dihedral angle at the edge shared by faces i and j: pi - angle between outward normals.
    Vec3 n[4];
    for (int i = 0; i < 4; ++i) {
      const int* f = kTetFaces[i];
      n[i] = (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]);
      double len = n[i].norm();
      n[i] = len > 0 ? Vec3(n[i] / len) : Vec3::Zero();
    }
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) {
        double c = std::clamp(-n[i].dot(n[j]), -1.0, 1.0);
        double a = std::acos(c) * 180.0 / M_PI;
        mind = std::min(mind, a);
        maxd = std::max(maxd, a);
      }
  }
  q.min_volume = T.rows() ? minv : 0;
  q.min_dihedral_deg = T.rows() ? mind : 0;
  q.max_dihedral_deg = T.rows() ? maxd : 0;
  return q;
}

MatX3i tet_boundary(const MatX4i& T, const std::string& name) {
  struct Face {
    std::array<int, 3> key;
    int tet, local;
  };
  std::vector<Face> faces(4 * static_cast<size_t>(T.rows()));
  for (int t = 0; t < T.rows(); ++t)
    for (int i = 0; i < 4; ++i) {
      std::array<int, 3> k{T(t, kTetFaces[i][0]), T(t, kTetFaces[i][1]), T(t, kTetFaces[i][2])};
      std::sort(k.begin(), k.end());
      faces[4 * t + i] = {k, t, i};
    }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.key < b.key; });
  std::vector<int> out;
  for (size_t i = 0; i < faces.size();) {
    size_t j = i;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i > 2) {
      std::ostringstream os;
      os << name << ": face (" << faces[i].key[0] << ", " << faces[i].key[1] << ", " << faces[i].key[2]
         << ") is shared by " << (j - i) << " tets:";
      for (size_t k = i; k < j; ++k) os << " " << faces[k].tet;
      os << " (overlapping or duplicate tets)";
      throw Error(ErrorKind::InvalidMesh, os.str());
    }
    if (j - i == 1) {
      const int* f = kTetFaces[faces[i].local];
      for (int k = 0; k < 3; ++k) out.push_back(T(faces[i].tet, f[k]));
    }
    i = j;
  }
  MatX3i B(static_cast<Eigen::Index>(out.size() / 3), 3);
  for (size_t i = 0; i < out.size(); ++i) B(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = out[i];
  return B;
}

namespace {
// The file's triangles F (file vertex ids, `used`: their new ids) as the boundary B, in F's order,
// when they are exactly B's faces, each once: a triangle in B's cyclic order keeps its rotation,
// another takes B's outward face. Nothing otherwise.
std::optional<MatX3i> boundary_in_file_order(const MatX3i& F, const std::vector<int>& used, const MatX3i& B) {
  if (F.rows() != B.rows()) return std::nullopt;
  auto key = [](std::array<int, 3> k) {
    std::sort(k.begin(), k.end());
    return k;
  };
  std::vector<std::pair<std::array<int, 3>, int>> faces(static_cast<size_t>(B.rows()));
  for (int f = 0; f < B.rows(); ++f) faces[f] = {key({B(f, 0), B(f, 1), B(f, 2)}), f};
  std::sort(faces.begin(), faces.end());
  MatX3i out(B.rows(), 3);
  std::vector<char> taken(static_cast<size_t>(B.rows()), 0);
  for (int f = 0; f < F.rows(); ++f) {
    std::array<int, 3> r{};
    for (int k = 0; k < 3; ++k) {
      const int v = F(f, k);
      r[k] = v >= 0 && v < static_cast<int>(used.size()) ? used[v] : -1;
      if (r[k] < 0) return std::nullopt;
    }
    const std::array<int, 3> k = key(r);
    const auto it = std::lower_bound(faces.begin(), faces.end(), std::make_pair(k, -1));
    if (it == faces.end() || it->first != k || taken[it->second]) return std::nullopt;
    const int b = it->second;
    taken[b] = 1;
    bool outward = false;
    for (int s = 0; s < 3; ++s)
      outward = outward || (r[0] == B(b, s) && r[1] == B(b, (s + 1) % 3) && r[2] == B(b, (s + 2) % 3));
    for (int c = 0; c < 3; ++c) out(f, c) = outward ? r[c] : B(b, c);
  }
  return out;
}
}  // namespace

TetMesh prepare_tet_input(const MeshData& m, TetInputReport& rep) {
  const std::string name = m.path.empty() ? std::string("input") : m.path;
  TetMesh tm;
  for (int i = 0; i < m.V.rows(); ++i)
    if (!m.V.row(i).allFinite()) {
      std::ostringstream os;
      os << name << ": " << m.vertex_where(i) << " has coordinates (" << m.V(i, 0) << ", " << m.V(i, 1) << ", "
         << m.V(i, 2) << ")";
      throw Error(ErrorKind::InvalidMesh, os.str());
    }
  for (int t = 0; t < m.T.rows(); ++t) {
    std::array<int, 4> k{m.T(t, 0), m.T(t, 1), m.T(t, 2), m.T(t, 3)};
    std::sort(k.begin(), k.end());
    if (k[0] == k[1] || k[1] == k[2] || k[2] == k[3])
      throw Error(ErrorKind::InvalidMesh, name + ": tetrahedron " + std::to_string(t) + " repeats a vertex");
  }
  std::vector<int> used(m.V.rows(), -1);
  int n = 0;
  for (int t = 0; t < m.T.rows(); ++t)
    for (int k = 0; k < 4; ++k) used[m.T(t, k)] = 1;
  for (int i = 0; i < m.V.rows(); ++i)
    if (used[i] == 1) used[i] = n++;
  rep.unreferenced_removed = static_cast<int>(m.V.rows()) - n;
  rep.vertex_map = used;
  tm.V.resize(n, 3);
  for (int i = 0; i < m.V.rows(); ++i)
    if (used[i] >= 0) tm.V.row(used[i]) = m.V.row(i);
  tm.T.resize(m.T.rows(), 4);
  for (int t = 0; t < m.T.rows(); ++t)
    for (int k = 0; k < 4; ++k) tm.T(t, k) = used[m.T(t, k)];

  TetQuality q = measure_tets(tm.V, tm.T);
  if (q.inverted == q.tets && q.tets > 0) {  // the file uses the opposite orientation convention
    for (int t = 0; t < tm.T.rows(); ++t) std::swap(tm.T(t, 1), tm.T(t, 2));
    rep.tets_reoriented = q.tets;
    q = measure_tets(tm.V, tm.T);
  }
  if (q.inverted || q.zero_volume) {
    std::ostringstream os;
    os << name << ": " << q.inverted << " inverted and " << q.zero_volume << " zero-volume tetrahedra, e.g. tets";
    for (int t : q.bad) os << " " << t;
    throw Error(ErrorKind::InvalidMesh, os.str());
  }
  tm.boundary = tet_boundary(tm.T, name);
  if (auto B = boundary_in_file_order(m.F, used, tm.boundary)) {
    tm.boundary = std::move(*B);
    rep.boundary_in_file_order = true;
  }
  return tm;
}

}  // namespace polycube
