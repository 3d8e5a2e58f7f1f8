#include "polycube/io/writers.h"

#include <gmsh.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>

#include "polycube/core/error.h"
#include "polycube/io/gmsh_session.h"

namespace polycube::io {

namespace {
struct File {
  std::FILE* f;
  std::string path;
  File(const std::string& p, const char* mode) : f(std::fopen(p.c_str(), mode)), path(p) {
    if (!f) throw Error(ErrorKind::Output, p + ": cannot open for writing (" + std::strerror(errno) + ")");
  }
  ~File() { if (f) std::fclose(f); }
  void close() {
    bool bad = std::ferror(f) != 0;
    if (std::fclose(f) != 0) bad = true;
    f = nullptr;
    if (bad) throw Error(ErrorKind::Output, path + ": write failed (disk full?)");
  }
};
template <class T>
void put_be(std::FILE* f, T v) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  std::reverse(b, b + sizeof(T));
  std::fwrite(b, 1, sizeof(T), f);
}
template <class T>
void put(std::FILE* f, T v, bool big) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big) std::reverse(b, b + sizeof(T));
  std::fwrite(b, 1, sizeof(T), f);
}
}  // namespace

void write_medit(const std::string& path, const MeshData& m) {
  File f(path, "w");
  std::fprintf(f.f, "MeshVersionFormatted 2\n\nDimension 3\n\nVertices\n%ld\n", (long)m.V.rows());
  for (int i = 0; i < m.V.rows(); ++i) std::fprintf(f.f, "%.17g %.17g %.17g 0\n", m.V(i, 0), m.V(i, 1), m.V(i, 2));
  if (m.F.rows()) {
    std::fprintf(f.f, "\nTriangles\n%ld\n", (long)m.F.rows());
    for (int i = 0; i < m.F.rows(); ++i) std::fprintf(f.f, "%d %d %d 0\n", m.F(i, 0) + 1, m.F(i, 1) + 1, m.F(i, 2) + 1);
  }
  if (m.Q.rows()) {
    std::fprintf(f.f, "\nQuadrilaterals\n%ld\n", (long)m.Q.rows());
    for (int i = 0; i < m.Q.rows(); ++i)
      std::fprintf(f.f, "%d %d %d %d 0\n", m.Q(i, 0) + 1, m.Q(i, 1) + 1, m.Q(i, 2) + 1, m.Q(i, 3) + 1);
  }
  if (m.T.rows()) {
    std::fprintf(f.f, "\nTetrahedra\n%ld\n", (long)m.T.rows());
    for (int i = 0; i < m.T.rows(); ++i)
      std::fprintf(f.f, "%d %d %d %d 0\n", m.T(i, 0) + 1, m.T(i, 1) + 1, m.T(i, 2) + 1, m.T(i, 3) + 1);
  }
  if (m.H.rows()) {
    std::fprintf(f.f, "\nHexahedra\n%ld\n", (long)m.H.rows());
    for (int i = 0; i < m.H.rows(); ++i) {
      for (int k = 0; k < 8; ++k) std::fprintf(f.f, "%d ", m.H(i, k) + 1);
      std::fprintf(f.f, "0\n");
    }
  }
  std::fprintf(f.f, "\nEnd\n");
  f.close();
}

void write_vtk(const std::string& path, const MeshData& m, bool binary, const CellFields& fields,
               const CellVectors& vectors, const CellScalars& scalars) {
  File f(path, binary ? "wb" : "w");
  const long nc = (long)(m.F.rows() + m.Q.rows() + m.T.rows() + m.H.rows());
  const long size = (long)(4 * m.F.rows() + 5 * m.Q.rows() + 5 * m.T.rows() + 9 * m.H.rows());
  for (auto& [name, v] : fields)
    POLYCUBE_ASSERT((long)v.size() == nc, "cell field '" + name + "' size does not match the cell count");
  std::fprintf(f.f, "# vtk DataFile Version 4.2\npolycube output\n%s\nDATASET UNSTRUCTURED_GRID\n", binary ? "BINARY" : "ASCII");
  std::fprintf(f.f, "POINTS %ld double\n", (long)m.V.rows());
  for (int i = 0; i < m.V.rows(); ++i) {
    if (binary) for (int k = 0; k < 3; ++k) put_be<double>(f.f, m.V(i, k));
    else std::fprintf(f.f, "%.17g %.17g %.17g\n", m.V(i, 0), m.V(i, 1), m.V(i, 2));
  }
  if (binary) std::fprintf(f.f, "\n");
  std::fprintf(f.f, "CELLS %ld %ld\n", nc, size);
  auto cell = [&](int n, const int* ids) {
    if (binary) {
      put_be<int32_t>(f.f, n);
      for (int k = 0; k < n; ++k) put_be<int32_t>(f.f, ids[k]);
    } else {
      std::fprintf(f.f, "%d", n);
      for (int k = 0; k < n; ++k) std::fprintf(f.f, " %d", ids[k]);
      std::fprintf(f.f, "\n");
    }
  };
  for (int i = 0; i < m.F.rows(); ++i) cell(3, m.F.row(i).data());
  for (int i = 0; i < m.Q.rows(); ++i) cell(4, m.Q.row(i).data());
  for (int i = 0; i < m.T.rows(); ++i) cell(4, m.T.row(i).data());
  for (int i = 0; i < m.H.rows(); ++i) cell(8, m.H.row(i).data());
  if (binary) std::fprintf(f.f, "\n");
  std::fprintf(f.f, "CELL_TYPES %ld\n", nc);
  auto types = [&](long n, int t) {
    for (long i = 0; i < n; ++i) {
      if (binary) put_be<int32_t>(f.f, t);
      else std::fprintf(f.f, "%d\n", t);
    }
  };
  types((long)m.F.rows(), 5);
  types((long)m.Q.rows(), 9);
  types((long)m.T.rows(), 10);
  types((long)m.H.rows(), 12);
  if (binary) std::fprintf(f.f, "\n");
  for (auto& [name, v] : vectors)
    POLYCUBE_ASSERT((long)v.rows() == nc, "cell vectors '" + name + "' size does not match the cell count");
  for (auto& [name, v] : scalars)
    POLYCUBE_ASSERT((long)v.size() == nc, "cell scalars '" + name + "' size does not match the cell count");
  if (!fields.empty() || !vectors.empty() || !scalars.empty()) std::fprintf(f.f, "CELL_DATA %ld\n", nc);
  for (auto& [name, v] : scalars) {
    std::fprintf(f.f, "SCALARS %s double 1\nLOOKUP_TABLE default\n", name.c_str());
    for (double x : v) {
      if (binary) put_be<double>(f.f, x);
      else std::fprintf(f.f, "%.9g\n", x);
    }
    if (binary) std::fprintf(f.f, "\n");
  }
  for (auto& [name, v] : vectors) {
    std::fprintf(f.f, "VECTORS %s double\n", name.c_str());
    for (int i = 0; i < v.rows(); ++i) {
      if (binary) for (int k = 0; k < 3; ++k) put_be<double>(f.f, v(i, k));
      else std::fprintf(f.f, "%.9g %.9g %.9g\n", v(i, 0), v(i, 1), v(i, 2));
    }
    if (binary) std::fprintf(f.f, "\n");
    // COLOR_SCALARS are unsigned bytes in binary files and floats in [0,1] in ASCII ones.
    std::fprintf(f.f, "COLOR_SCALARS %s_rgb 3\n", name.c_str());
    for (int i = 0; i < v.rows(); ++i) {
      if (binary) for (int k = 0; k < 3; ++k) std::fputc(static_cast<int>(std::min(1.0, std::abs(v(i, k))) * 255 + 0.5), f.f);
      else std::fprintf(f.f, "%.4f %.4f %.4f\n", std::min(1.0, std::abs(v(i, 0))), std::min(1.0, std::abs(v(i, 1))), std::min(1.0, std::abs(v(i, 2))));
    }
    if (binary) std::fprintf(f.f, "\n");
  }
  if (!fields.empty()) {
    for (auto& [name, v] : fields) {
      std::fprintf(f.f, "SCALARS %s int 1\nLOOKUP_TABLE default\n", name.c_str());
      for (int x : v) {
        if (binary) put_be<int32_t>(f.f, x);
        else std::fprintf(f.f, "%d\n", x);
      }
      if (binary) std::fprintf(f.f, "\n");
    }
  }
  f.close();
}

void write_obj(const std::string& path, const MatX3d& V, const MatX3i& F) {
  File f(path, "w");
  for (int i = 0; i < V.rows(); ++i) std::fprintf(f.f, "v %.17g %.17g %.17g\n", V(i, 0), V(i, 1), V(i, 2));
  for (int i = 0; i < F.rows(); ++i) std::fprintf(f.f, "f %d %d %d\n", F(i, 0) + 1, F(i, 1) + 1, F(i, 2) + 1);
  f.close();
}

void write_obj_quads(const std::string& path, const MatX3d& V, const MatX4i& Q) {
  File f(path, "w");
  for (int i = 0; i < V.rows(); ++i) std::fprintf(f.f, "v %.17g %.17g %.17g\n", V(i, 0), V(i, 1), V(i, 2));
  for (int i = 0; i < Q.rows(); ++i)
    std::fprintf(f.f, "f %d %d %d %d\n", Q(i, 0) + 1, Q(i, 1) + 1, Q(i, 2) + 1, Q(i, 3) + 1);
  f.close();
}

void write_off(const std::string& path, const MatX3d& V, const MatX3i& F) {
  File f(path, "w");
  std::fprintf(f.f, "OFF\n%ld %ld 0\n", (long)V.rows(), (long)F.rows());
  for (int i = 0; i < V.rows(); ++i) std::fprintf(f.f, "%.17g %.17g %.17g\n", V(i, 0), V(i, 1), V(i, 2));
  for (int i = 0; i < F.rows(); ++i) std::fprintf(f.f, "3 %d %d %d\n", F(i, 0), F(i, 1), F(i, 2));
  f.close();
}

void write_stl(const std::string& path, const MatX3d& V, const MatX3i& F, bool binary) {
  File f(path, binary ? "wb" : "w");
  auto normal = [&](int i) {
    Vec3 a = V.row(F(i, 0)), b = V.row(F(i, 1)), c = V.row(F(i, 2));
    Vec3 n = (b - a).cross(c - a);
    return n.norm() > 0 ? Vec3(n.normalized()) : Vec3(0, 0, 0);
  };
  if (binary) {
    char header[80] = "binary STL written by polycube";
    std::fwrite(header, 1, 80, f.f);
    put<uint32_t>(f.f, (uint32_t)F.rows(), false);
    for (int i = 0; i < F.rows(); ++i) {
      Vec3 n = normal(i);
      for (int k = 0; k < 3; ++k) put<float>(f.f, (float)n[k], false);
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) put<float>(f.f, (float)V(F(i, j), k), false);
      put<uint16_t>(f.f, 0, false);
    }
  } else {
    std::fprintf(f.f, "solid polycube\n");
    for (int i = 0; i < F.rows(); ++i) {
      Vec3 n = normal(i);
      std::fprintf(f.f, "facet normal %g %g %g\n outer loop\n", n[0], n[1], n[2]);
      for (int j = 0; j < 3; ++j)
        std::fprintf(f.f, "  vertex %.17g %.17g %.17g\n", V(F(i, j), 0), V(F(i, j), 1), V(F(i, j), 2));
      std::fprintf(f.f, " endloop\nendfacet\n");
    }
    std::fprintf(f.f, "endsolid polycube\n");
  }
  f.close();
}

void write_ply(const std::string& path, const MatX3d& V, const MatX3i& F, PlyEncoding enc) {
  File f(path, enc == PlyEncoding::Ascii ? "w" : "wb");
  const char* fmt = enc == PlyEncoding::Ascii ? "ascii" : enc == PlyEncoding::BinaryLittleEndian ? "binary_little_endian" : "binary_big_endian";
  std::fprintf(f.f,
               "ply\nformat %s 1.0\ncomment written by polycube\nelement vertex %ld\nproperty double x\nproperty double y\n"
               "property double z\nelement face %ld\nproperty list uchar int vertex_indices\nend_header\n",
               fmt, (long)V.rows(), (long)F.rows());
  const bool big = enc == PlyEncoding::BinaryBigEndian;
  for (int i = 0; i < V.rows(); ++i) {
    if (enc == PlyEncoding::Ascii) std::fprintf(f.f, "%.17g %.17g %.17g\n", V(i, 0), V(i, 1), V(i, 2));
    else for (int k = 0; k < 3; ++k) put<double>(f.f, V(i, k), big);
  }
  for (int i = 0; i < F.rows(); ++i) {
    if (enc == PlyEncoding::Ascii) std::fprintf(f.f, "3 %d %d %d\n", F(i, 0), F(i, 1), F(i, 2));
    else {
      put<uint8_t>(f.f, 3, big);
      for (int k = 0; k < 3; ++k) put<int32_t>(f.f, F(i, k), big);
    }
  }
  f.close();
}

void write_msh(const std::string& path, const MeshData& m) {
  GmshSession s;
  s.run(ErrorKind::Output, path, [&] {
    gmsh::model::add("out");
    std::vector<std::size_t> tags(m.V.rows());
    std::vector<double> xyz(3 * m.V.rows());
    for (int i = 0; i < m.V.rows(); ++i) {
      tags[i] = i + 1;
      for (int k = 0; k < 3; ++k) xyz[3 * i + k] = m.V(i, k);
    }
    const int dim = m.is_volume() ? 3 : 2;
    int e = gmsh::model::addDiscreteEntity(dim);
    gmsh::model::mesh::addNodes(dim, e, tags, xyz);
    auto add = [&](int type, const auto& M) {
      if (!M.rows()) return;
      std::vector<std::size_t> n;
      for (int i = 0; i < M.rows(); ++i)
        for (int k = 0; k < M.cols(); ++k) n.push_back(M(i, k) + 1);
      gmsh::model::mesh::addElementsByType(e, type, {}, n);
    };
    if (dim == 2) { add(2, m.F); add(3, m.Q); }
    else { add(4, m.T); add(5, m.H); }
    gmsh::option::setNumber("Mesh.MshFileVersion", 4.1);
    gmsh::option::setNumber("Mesh.Binary", 0);
    gmsh::write(path);
  });
}

}  // namespace polycube::io
