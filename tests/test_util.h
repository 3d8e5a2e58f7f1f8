// Meshes built in code and small helpers shared by the tests.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include "polycube/core/types.h"
#include "polycube/examples/examples.h"
#include "polycube/io/mesh_data.h"
#include "polycube/tetra/tetrahedralize.h"
#include "polycube/validate/surface.h"

namespace polycube::test {

/// Axis-aligned box [lo, hi] as 8 vertices and 12 outward triangles.
inline SurfaceMesh box(Vec3 lo = Vec3(0, 0, 0), Vec3 hi = Vec3(1, 1, 1)) {
  SurfaceMesh m;
  m.V.resize(8, 3);
  for (int i = 0; i < 8; ++i) m.V.row(i) << (i & 1 ? hi.x() : lo.x()), (i & 2 ? hi.y() : lo.y()), (i & 4 ? hi.z() : lo.z());
  m.F.resize(12, 3);
  m.F << 0, 2, 1, 1, 2, 3,  // z = lo
      4, 5, 6, 5, 7, 6,     // z = hi
      0, 1, 4, 1, 5, 4,     // y = lo
      2, 6, 3, 3, 6, 7,     // y = hi
      0, 4, 2, 2, 4, 6,     // x = lo
      1, 3, 5, 3, 7, 5;     // x = hi
  return m;
}

/// Unit-radius sphere around c: an octahedron subdivided `levels` times, projected.
inline SurfaceMesh sphere(int levels = 3, Vec3 c = Vec3::Zero(), double r = 1.0) {
  std::vector<Vec3> V = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  std::vector<std::array<int, 3>> F = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                                       {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto m = [&](int a, int b) {
      auto k = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(k);
      if (it != mid.end()) return it->second;
      V.push_back((V[a] + V[b]).normalized());
      return mid[k] = static_cast<int>(V.size()) - 1;
    };
    std::vector<std::array<int, 3>> G;
    for (auto& f : F) {
      int a = m(f[0], f[1]), b = m(f[1], f[2]), d = m(f[2], f[0]);
      G.push_back({f[0], a, d});
      G.push_back({a, f[1], b});
      G.push_back({d, b, f[2]});
      G.push_back({a, b, d});
    }
    F = G;
  }
  SurfaceMesh s;
  s.V.resize(V.size(), 3);
  for (size_t i = 0; i < V.size(); ++i) s.V.row(i) = c + r * V[i];
  s.F.resize(F.size(), 3);
  for (size_t i = 0; i < F.size(); ++i) s.F.row(i) << F[i][0], F[i][1], F[i][2];
  return s;
}

/// Torus with radii R > r, n x m quads split into triangles (genus 1).
inline SurfaceMesh torus(double R = 1.0, double r = 0.4, int n = 24, int m = 12) {
  SurfaceMesh s;
  s.V.resize(n * m, 3);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      double u = 2 * M_PI * i / n, v = 2 * M_PI * j / m;
      s.V.row(i * m + j) << (R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u), r * std::sin(v);
    }
  s.F.resize(2 * n * m, 3);
  int k = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      int a = i * m + j, b = ((i + 1) % n) * m + j, c = ((i + 1) % n) * m + (j + 1) % m, d = i * m + (j + 1) % m;
      s.F.row(k++) << a, b, c;
      s.F.row(k++) << a, c, d;
    }
  return s;
}

/// Box [lo, hi] with every face an n x n grid of quads split into triangles (welded, outward).
inline SurfaceMesh grid_box(int n, Vec3 lo = Vec3(0, 0, 0), Vec3 hi = Vec3(1, 1, 1)) {
  std::map<std::array<int, 3>, int> id;
  std::vector<Vec3> V;
  std::vector<std::array<int, 3>> F;
  auto vertex = [&](std::array<int, 3> g) {
    auto it = id.find(g);
    if (it != id.end()) return it->second;
    Vec3 p;
    for (int k = 0; k < 3; ++k) p[k] = lo[k] + (hi[k] - lo[k]) * g[k] / n;
    V.push_back(p);
    return id[g] = static_cast<int>(V.size()) - 1;
  };
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, w = (axis + 2) % 3;  // (u, w, axis) right-handed
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          std::array<int, 3> g[4];
          const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 0, 1, 1};
          for (int c = 0; c < 4; ++c) {
            g[c][axis] = side * n;
            g[c][u] = i + di[c];
            g[c][w] = j + dj[c];
          }
          int q[4];
          for (int c = 0; c < 4; ++c) q[c] = vertex(g[c]);
          if (side == 1) {
            F.push_back({q[0], q[1], q[2]});
            F.push_back({q[0], q[2], q[3]});
          } else {
            F.push_back({q[0], q[2], q[1]});
            F.push_back({q[0], q[3], q[2]});
          }
        }
    }
  SurfaceMesh s;
  s.V.resize(V.size(), 3);
  for (size_t i = 0; i < V.size(); ++i) s.V.row(i) = V[i];
  s.F.resize(F.size(), 3);
  for (size_t i = 0; i < F.size(); ++i) s.F.row(i) << F[i][0], F[i][1], F[i][2];
  return s;
}

/// Tetrahedralizes a closed surface (target tet count, 0 = Gmsh's default sizing) and splits
/// tets with four boundary vertices, as the pipeline does.
inline TetMesh tet_mesh_of(const MatX3d& V, const MatX3i& F, int target_tets = 0) {
  MeshData m = make_mesh_data(V, F);
  SurfaceLayout l;
  validate_surface(m, l);
  SurfaceMesh s{m.V, m.F};
  TetOptions o;
  o.target_tets = target_tets;
  TetMesh tm = tetrahedralize(s, l, o, {});
  split_boundary_tets(tm);
  return tm;
}

/// The l_bracket example's tet mesh (about 3000 tets, with interior vertices) as its own
/// polycube (V), and `rest`: a smooth bend of it (x += 0.1 sin(pi y), z += 0.1 sin(pi x): volume
/// kept, injective), so that hexes or quads mapped back have to be fitted to a curved surface.
struct BentL {
  TetMesh tm;
  MatX3d rest;
};
inline BentL bent_l_block() {
  const MeshData l = examples::make("l_bracket", 0.1);
  BentL b{tet_mesh_of(l.V, l.F, 3000), MatX3d()};
  b.rest = b.tm.V;
  for (int v = 0; v < b.rest.rows(); ++v) {
    b.rest(v, 0) += 0.1 * std::sin(M_PI * b.tm.V(v, 1));
    b.rest(v, 2) += 0.1 * std::sin(M_PI * b.tm.V(v, 0));
  }
  return b;
}

/// n random rotations (uniform quaternions from a seeded generator).
inline std::vector<Eigen::Matrix3d> random_rotations(unsigned seed, int n) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  std::vector<Eigen::Matrix3d> r;
  for (int k = 0; k < n; ++k) {
    Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
    q.normalize();
    r.push_back(q.toRotationMatrix());
  }
  return r;
}

/// Concatenates two surfaces.
inline SurfaceMesh merge(const SurfaceMesh& a, const SurfaceMesh& b) {
  SurfaceMesh s;
  s.V.resize(a.V.rows() + b.V.rows(), 3);
  s.V << a.V, b.V;
  s.F.resize(a.F.rows() + b.F.rows(), 3);
  MatX3i bf = b.F.array() + static_cast<int>(a.V.rows());
  s.F << a.F, bf;
  return s;
}

inline SurfaceMesh flipped(SurfaceMesh s) {
  for (int f = 0; f < s.F.rows(); ++f) std::swap(s.F(f, 1), s.F(f, 2));
  return s;
}

inline double enclosed_volume(const MatX3d& V, const MatX3i& F) {
  double v = 0;
  for (int f = 0; f < F.rows(); ++f)
    v += Vec3(V.row(F(f, 0))).dot(Vec3(V.row(F(f, 1))).cross(Vec3(V.row(F(f, 2))))) / 6;
  return v;
}

/// This test process's temp dir; removed when the process exits (set POLYCUBE_KEEP_TEST_FILES to
/// keep it for inspection).
inline std::filesystem::path test_temp_root() {
  struct Root {
    std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("polycube_test_" + std::to_string(::getpid()));
    ~Root() {
      std::error_code ec;
      if (!std::getenv("POLYCUBE_KEEP_TEST_FILES")) std::filesystem::remove_all(path, ec);
    }
  };
  static const Root root;
  return root.path;
}

/// A fresh empty folder under the test temp dir.
inline std::string temp_dir(const std::string& name) {
  auto p = test_temp_root() / name;
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p.string();
}

inline void write_text(const std::string& path, const std::string& text) {
  std::ofstream o(path, std::ios::binary);
  o << text;
}

inline std::string read_text(const std::string& path) {
  std::ifstream i(path, std::ios::binary);
  std::stringstream s;
  s << i.rdbuf();
  return s.str();
}

struct RunResult {
  int code;
  std::string output;
};

/// Runs the polycube executable with `args` (shell syntax), capturing stdout+stderr.
inline RunResult run_cli(const std::string& args) {
  std::string log = temp_dir("cli_log") + "/out.txt";
  std::string cmd = std::string(POLYCUBE_EXE) + " " + args + " > " + log + " 2>&1";
  int st = std::system(cmd.c_str());
  RunResult r;
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  r.output = read_text(log);
  return r;
}

}  // namespace polycube::test
