#include "polycube/tetra/tetrahedralize.h"


#include <gmsh.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include "polycube/core/error.h"
#include "polycube/io/builder.h"
#include "polycube/io/gmsh_session.h"
#include "polycube/validate/intersections.h"

namespace polycube {

namespace {

struct CoordHash {
  size_t operator()(const std::array<double, 3>& k) const {
    std::hash<double> h;
    return h(k[0]) * 73856093u ^ h(k[1]) * 19349663u ^ h(k[2]) * 83492791u;
  }
};

double bbox_diagonal(const MatX3d& V) {
  if (V.rows() == 0) return 0;
  return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
}

std::vector<std::vector<int>> faces_by_component(const SurfaceLayout& layout) {
  std::vector<std::vector<int>> cf(layout.num_components());
  for (size_t f = 0; f < layout.component_of_face.size(); ++f) cf[layout.component_of_face[f]].push_back(static_cast<int>(f));
  return cf;
}

// Adds one discrete surface per component, holding its nodes (tag = vertex index + 1) and triangles.
std::vector<int> add_surfaces(const SurfaceMesh& s, const std::vector<std::vector<int>>& cf) {
  std::vector<int> vcomp(s.V.rows(), -1);
  for (size_t c = 0; c < cf.size(); ++c)
    for (int f : cf[c])
      for (int k = 0; k < 3; ++k) vcomp[s.F(f, k)] = static_cast<int>(c);
  std::vector<int> ent(cf.size());
  for (size_t c = 0; c < cf.size(); ++c) {
    ent[c] = gmsh::model::addDiscreteEntity(2);
    std::vector<std::size_t> tags;
    std::vector<double> xyz;
    for (int v = 0; v < s.V.rows(); ++v)
      if (vcomp[v] == static_cast<int>(c)) {
        tags.push_back(v + 1);
        xyz.insert(xyz.end(), {s.V(v, 0), s.V(v, 1), s.V(v, 2)});
      }
    gmsh::model::mesh::addNodes(2, ent[c], tags, xyz);
    std::vector<std::size_t> tri;
    tri.reserve(3 * cf[c].size());
    for (int f : cf[c])
      for (int k = 0; k < 3; ++k) tri.push_back(s.F(f, k) + 1);
    gmsh::model::mesh::addElementsByType(ent[c], 2, {}, tri);
  }
  return ent;
}

// Throws Error(InvalidMesh) naming the crossing face pairs, if any, after `what`.
void refuse_intersections(const SurfaceMesh& s, const std::string& what) {
  auto pairs = find_self_intersections(s.V, s.F, 10);
  if (pairs.empty()) return;
  std::ostringstream os;
  os << what << "; intersecting face pairs:";
  for (auto [a, b] : pairs) {
    Vec3 c = (s.V.row(s.F(a, 0)) + s.V.row(s.F(a, 1)) + s.V.row(s.F(a, 2))).transpose() / 3;
    os << "\n  faces " << a << " and " << b << " (near " << c.x() << ", " << c.y() << ", " << c.z() << ")";
  }
  throw Error(ErrorKind::InvalidMesh, os.str());
}

[[noreturn]] void mesher_failed(const SurfaceMesh& s, const std::string& gmsh_message) {
  refuse_intersections(s, "the surface intersects itself (the tet mesher reports: " + gmsh_message + ")");
  throw Error(ErrorKind::Tetrahedralization, "tetrahedralization failed: " + gmsh_message);
}

// Tets of tm whose four vertices are all on tm.boundary (split_boundary_tets splits them).
std::vector<int> boundary_only_tets(const TetMesh& tm) {
  std::vector<char> on_boundary(tm.V.rows(), 0);
  for (int f = 0; f < tm.boundary.rows(); ++f)
    for (int k = 0; k < 3; ++k) on_boundary[tm.boundary(f, k)] = 1;
  std::vector<int> tets;
  for (int t = 0; t < tm.T.rows(); ++t)
    if (on_boundary[tm.T(t, 0)] && on_boundary[tm.T(t, 1)] && on_boundary[tm.T(t, 2)] && on_boundary[tm.T(t, 3)])
      tets.push_back(t);
  return tets;
}

}  // namespace

void check_tet_mesh(const TetMesh& tm, const SurfaceMesh* surface, const std::string& name) {
  TetQuality q = measure_tets(tm.V, tm.T);
  if (q.inverted || q.zero_volume) {
    std::ostringstream os;
    os << name << ": " << q.inverted << " inverted and " << q.zero_volume << " zero-volume tets, e.g. tets";
    for (int t : q.bad) os << " " << t;
    throw Error(ErrorKind::Tetrahedralization, os.str());
  }
  if (!surface) return;
  const MatX3i B = tet_boundary(tm.T, name);
  auto canon = [](int a, int b, int c) {  // rotation-invariant, orientation-preserving key
    std::array<int, 3> k{a, b, c};
    std::rotate(k.begin(), std::min_element(k.begin(), k.end()), k.end());
    return k;
  };
  std::vector<std::array<int, 3>> want, got;
  for (int f = 0; f < surface->F.rows(); ++f) want.push_back(canon(surface->F(f, 0), surface->F(f, 1), surface->F(f, 2)));
  for (int f = 0; f < B.rows(); ++f) got.push_back(canon(B(f, 0), B(f, 1), B(f, 2)));
  std::sort(want.begin(), want.end());
  std::sort(got.begin(), got.end());
  if (want != got) {
    std::vector<std::array<int, 3>> missing, extra;
    std::set_difference(want.begin(), want.end(), got.begin(), got.end(), std::back_inserter(missing));
    std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
    std::ostringstream os;
    os << name << ": the tet mesh boundary differs from the input surface: " << missing.size()
       << " input triangles missing, " << extra.size() << " extra boundary triangles";
    if (!missing.empty())
      os << " (e.g. missing triangle " << missing[0][0] << " " << missing[0][1] << " " << missing[0][2] << ")";
    throw Error(ErrorKind::Tetrahedralization, os.str());
  }
}

int split_boundary_tets(TetMesh& tm) {
  const std::vector<int> split = boundary_only_tets(tm);
  if (split.empty()) return 0;
  const Eigen::Index nv = tm.V.rows(), nt = tm.T.rows();
  tm.V.conservativeResize(nv + static_cast<Eigen::Index>(split.size()), 3);
  tm.T.conservativeResize(nt + 3 * static_cast<Eigen::Index>(split.size()), 4);
  for (size_t i = 0; i < split.size(); ++i) {
    const int t = split[i];
    const int c = static_cast<int>(nv + static_cast<Eigen::Index>(i));
    const std::array<int, 4> v{tm.T(t, 0), tm.T(t, 1), tm.T(t, 2), tm.T(t, 3)};
    tm.V.row(c) = 0.25 * (tm.V.row(v[0]) + tm.V.row(v[1]) + tm.V.row(v[2]) + tm.V.row(v[3]));
    // Tet i of the split replaces vertex i by the centroid: same orientation as the original.
    for (int k = 0; k < 4; ++k) {
      const Eigen::Index row = k == 0 ? t : nt + 3 * static_cast<Eigen::Index>(i) + (k - 1);
      for (int j = 0; j < 4; ++j) tm.T(row, j) = j == k ? c : v[j];
    }
  }
  return static_cast<int>(split.size());
}

std::vector<std::pair<int, int>> split_tet_edges(MatX4i& T, int nv, std::vector<std::pair<int, int>> edges) {
  std::vector<std::pair<int, int>> made;
  while (!edges.empty()) {
    std::vector<std::vector<int>> tets(edges.size());
    for (int t = 0; t < T.rows(); ++t)
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
          const std::pair<int, int> e(std::min(T(t, i), T(t, j)), std::max(T(t, i), T(t, j)));
          auto it = std::lower_bound(edges.begin(), edges.end(), e);
          if (it != edges.end() && *it == e) tets[it - edges.begin()].push_back(t);
        }
    std::vector<char> used(T.rows(), 0);
    std::vector<std::array<int, 4>> added;
    std::vector<std::pair<int, int>> later;
    for (size_t e = 0; e < edges.size(); ++e) {
      bool free = !tets[e].empty();
      for (int t : tets[e]) free = free && !used[t];
      if (!free) {
        if (!tets[e].empty()) later.push_back(edges[e]);
        continue;
      }
      const int m = nv + static_cast<int>(made.size());
      const auto [u, v] = edges[e];
      made.push_back(edges[e]);
      for (int t : tets[e]) {
        used[t] = 1;
        // Replacing one end of the edge by its midpoint keeps the orientation.
        std::array<int, 4> a{T(t, 0), T(t, 1), T(t, 2), T(t, 3)}, b = a;
        for (int i = 0; i < 4; ++i) {
          if (a[i] == v) a[i] = m;
          if (b[i] == u) b[i] = m;
        }
        for (int i = 0; i < 4; ++i) T(t, i) = a[i];
        added.push_back(b);
      }
    }
    const Eigen::Index nt = T.rows();
    T.conservativeResize(nt + static_cast<Eigen::Index>(added.size()), 4);
    for (size_t i = 0; i < added.size(); ++i)
      for (int j = 0; j < 4; ++j) T(nt + static_cast<Eigen::Index>(i), j) = added[i][j];
    edges = std::move(later);
  }
  return made;
}

SurfaceMesh remesh_surface(const SurfaceMesh& s, const SurfaceLayout& layout, double h) {
  const auto cf = faces_by_component(layout);
  std::vector<double> V;
  std::vector<int> F;
  for (size_t c = 0; c < cf.size(); ++c) {
    // The component alone, compactly numbered.
    SurfaceMesh one;
    std::vector<int> map(s.V.rows(), -1), tri;
    int n = 0;
    for (int f : cf[c])
      for (int k = 0; k < 3; ++k) {
        int v = s.F(f, k);
        if (map[v] < 0) map[v] = n++;
        tri.push_back(map[v]);
      }
    one.V.resize(n, 3);
    for (int v = 0; v < s.V.rows(); ++v)
      if (map[v] >= 0) one.V.row(map[v]) = s.V.row(v);
    one.F.resize(static_cast<Eigen::Index>(tri.size() / 3), 3);
    for (size_t i = 0; i < tri.size(); ++i) one.F(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = tri[i];
    std::vector<std::vector<int>> all(1);
    for (int f = 0; f < one.F.rows(); ++f) all[0].push_back(f);

    // Split the surface into smooth patches at sharp edges and build a parametrizable geometry
    // from them, then mesh it anew. Gmsh's patch splitting depends on the angle: try a few.
    std::string last_error;
    bool done = false;
    for (double angle : {40.0, 25.0, 60.0}) {
      try {
        io::GmshSession g;
        g.run(ErrorKind::Tetrahedralization, "surface remeshing of component " + std::to_string(c), [&] {
          gmsh::model::add("remesh");
          add_surfaces(one, all);
          gmsh::model::mesh::classifySurfaces(angle * M_PI / 180, true, true, M_PI);
          gmsh::model::mesh::createGeometry();
          gmsh::option::setNumber("Mesh.MeshSizeMax", h);
          gmsh::option::setNumber("Mesh.MeshSizeMin", 0.2 * h);
          gmsh::option::setNumber("Mesh.MeshSizeFromPoints", 0);
          gmsh::option::setNumber("Mesh.MeshSizeExtendFromBoundary", 0);
          gmsh::option::setNumber("Mesh.Algorithm", 6);
          gmsh::model::mesh::generate(2);
          io::Builder b;
          io::collect_gmsh_mesh(b, "remeshed surface", true);
          if (b.f.empty()) throw Error(ErrorKind::Tetrahedralization, "no triangles generated");
          const int base = static_cast<int>(V.size() / 3);
          V.insert(V.end(), b.v.begin(), b.v.end());
          for (int v : b.f) F.push_back(base + v);
        });
        done = true;
        break;
      } catch (const Error& e) {
        last_error = e.what();
      }
    }
    if (!done)
      throw Error(ErrorKind::Tetrahedralization,
                  last_error + " (surface remeshing failed at feature angles 40, 25 and 60 degrees; keep the input "
                               "triangles by leaving --edge-length at 0)");
  }
  SurfaceMesh out;
  out.V.resize(static_cast<Eigen::Index>(V.size() / 3), 3);
  for (size_t i = 0; i < V.size(); ++i) out.V(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = V[i];
  out.F.resize(static_cast<Eigen::Index>(F.size() / 3), 3);
  for (size_t i = 0; i < F.size(); ++i) out.F(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = F[i];
  return out;
}

TetMesh tetrahedralize(const SurfaceMesh& s, const SurfaceLayout& layout, const TetOptions& opt, const Hooks& hooks,
                       TetStats* stats) {
  TetStats st;
  // Components that cross each other bound no solid (two overlapping spheres): each outer shell
  // becomes a volume of its own and Gmsh meshes them overlapping, without an error, and the
  // polycubes overlap too (exit 7 after the whole deformation). A single component that crosses
  // itself is caught when the mesher fails (mesher_failed).
  if (layout.num_components() > 1)
    refuse_intersections(s, "the surface intersects itself: its " + std::to_string(layout.num_components()) +
                                " components cross each other (a solid's boundary components must be disjoint, "
                                "cavities nested inside their shell; --surface takes each component's surface on "
                                "its own)");
  const double diag = bbox_diagonal(s.V);
  const auto cf = faces_by_component(layout);
  double volume = 0;
  for (double v : layout.volume) volume += v;  // cavities are negative
  // Interior size for a target count: a Delaunay mesh has about 1/(0.1 h^3) tets per unit
  // volume at edge length h (regular tets: 1/0.118 h^3); calibrated on spheres and boxes.
  auto size_for = [&](double n) { return std::cbrt(std::max(volume, 0.0) / (0.1 * n)); };
  double h = opt.max_size > 0 ? opt.max_size * diag : 0;
  if (opt.target_tets > 0) h = size_for(opt.target_tets);

  // Tets with four boundary vertices are split into four by the pipeline (split_boundary_tets), so
  // that target_tets counts 3 more tets per such tet.
  auto counted = [&](const TetMesh& m) {
    return static_cast<double>(m.T.rows() + 3 * static_cast<Eigen::Index>(boundary_only_tets(m).size()));
  };
  // Meshed again (up to kRuns in all) until the count is within kBand of target_tets: the first
  // size comes from the volume alone, the next from the count missed (N ~ h^-3 at first, then the
  // exponent measured between the last two runs: the kept surface's share does not scale).
  constexpr int kRuns = 4;
  constexpr double kBand = 0.05;
  TetMesh tm, best;
  double best_miss = -1, prev_h = 0, prev_n = 0;
  for (int attempt = 0; attempt < kRuns; ++attempt) {
    st.attempts++;
    io::GmshSession g;
    std::string failure;
    try {
      g.run(ErrorKind::Tetrahedralization, "tetrahedralization", [&] {
        gmsh::model::add("tet");
        std::vector<int> ent = add_surfaces(s, cf);
        // One volume per outer shell, with the cavities directly inside it as holes.
        for (int c = 0; c < layout.num_components(); ++c) {
          if (layout.depth[c] % 2) continue;
          std::vector<int> loops{gmsh::model::geo::addSurfaceLoop({ent[c]})};
          for (int d = 0; d < layout.num_components(); ++d)
            if (layout.parent[d] == c) loops.push_back(gmsh::model::geo::addSurfaceLoop({ent[d]}));
          gmsh::model::geo::addVolume(loops);
        }
        gmsh::model::geo::synchronize();
        gmsh::option::setNumber("Mesh.Algorithm3D", opt.algorithm == "hxt" ? 10 : 1);
        gmsh::option::setNumber("General.NumThreads", opt.algorithm == "hxt" ? 2 : 1);
        gmsh::option::setNumber("Mesh.Optimize", opt.optimize ? 1 : 0);
        if (h > 0) {
          gmsh::option::setNumber("Mesh.MeshSizeMax", h);
          // The interior follows h instead of the boundary spacing (Gmsh's Delaunay refinement
          // ignores MeshSizeMax when sizes are extended from the boundary).
          gmsh::option::setNumber("Mesh.MeshSizeExtendFromBoundary", 0);
          gmsh::option::setNumber("Mesh.MeshSizeFromPoints", 0);
        }
        hooks.report("tet", 0.1);
        gmsh::model::mesh::generate(3);
        std::string err = g.last_error();
        if (!err.empty()) throw Error(ErrorKind::Tetrahedralization, err);
      });
    } catch (const Error& e) {
      failure = e.what();
    }
    if (!failure.empty()) mesher_failed(s, failure);

    // Collect: surface vertices keep their index, new interior vertices follow. Gmsh may renumber
    // nodes while meshing, so surface nodes are recognized by their (unchanged) coordinates.
    std::vector<std::size_t> tags;
    std::vector<double> xyz, par;
    gmsh::model::mesh::getNodes(tags, xyz, par, -1, -1, true, false);
    const int ns = static_cast<int>(s.V.rows());
    std::unordered_map<std::array<double, 3>, int, CoordHash> by_coord;
    by_coord.reserve(ns);
    for (int v = 0; v < ns; ++v) by_coord.emplace(std::array<double, 3>{s.V(v, 0), s.V(v, 1), s.V(v, 2)}, v);
    std::unordered_map<std::size_t, int> id;
    std::vector<double> extra;
    for (size_t i = 0; i < tags.size(); ++i) {
      if (id.count(tags[i])) continue;
      auto it = by_coord.find({xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
      if (it != by_coord.end()) {
        id[tags[i]] = it->second;
      } else {
        id[tags[i]] = ns + static_cast<int>(extra.size() / 3);
        extra.insert(extra.end(), {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
      }
    }
    tm.V.resize(ns + static_cast<Eigen::Index>(extra.size() / 3), 3);
    tm.V.topRows(ns) = s.V;
    for (size_t i = 0; i < extra.size(); ++i) tm.V(ns + static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = extra[i];
    std::vector<std::size_t> et, en;
    gmsh::model::mesh::getElementsByType(4, et, en, -1);
    tm.T.resize(static_cast<Eigen::Index>(et.size()), 4);
    for (size_t i = 0; i < en.size(); ++i) {
      auto it = id.find(en[i]);
      POLYCUBE_ASSERT(it != id.end(), "tet node without coordinates");
      tm.T(static_cast<Eigen::Index>(i / 4), static_cast<Eigen::Index>(i % 4)) = it->second;
    }
    tm.boundary = s.F;  // the surface's vertices come first, unchanged
    hooks.report("tet", 0.9);
    if (opt.target_tets > 0) {
      const double n = counted(tm);
      const double miss = std::abs(std::log(n / opt.target_tets));
      if (best_miss < 0 || miss < best_miss) {
        best_miss = miss;
        best = tm;
      }
      // (The same count twice: the size does not reach the mesh, e.g. Gmsh 4.8 does not refine the
      // interior of a surface of a few vertices: a cube's 12 tets.)
      if (std::abs(n / opt.target_tets - 1) > kBand && attempt + 1 < kRuns && n != prev_n) {
        double exponent = -3;  // N ~ h^exponent
        if (prev_h > 0 && prev_h != h && prev_n > 0 && prev_n != n)
          exponent = std::clamp(std::log(n / prev_n) / std::log(h / prev_h), -4.0, -1.0);
        hooks.debug("tet count " + std::to_string(static_cast<long>(n)) + " (after the boundary tets' splits) vs target " +
                    std::to_string(opt.target_tets) + ": adjusting the size and meshing again");
        prev_h = h;
        prev_n = n;
        h *= std::pow(opt.target_tets / n, 1 / exponent);
        continue;
      }
      tm = std::move(best);
    }
    break;
  }
  if (tm.T.rows() == 0) throw Error(ErrorKind::Tetrahedralization, "tetrahedralization produced no tetrahedra");
  try {
    check_tet_mesh(tm, &s, "tetrahedralization");
  } catch (const Error& e) {
    if (opt.algorithm != "hxt") throw;
    // Gmsh 4.8's HXT occasionally leaves a few tets out; its Delaunay mesher does not.
    hooks.warn(std::string("HXT result rejected (") + e.what() + "); meshing again with the Delaunay algorithm");
    TetOptions o2 = opt;
    o2.algorithm = "delaunay";
    TetMesh r = tetrahedralize(s, layout, o2, hooks, stats);
    if (stats) stats->attempts += st.attempts;
    return r;
  }
  st.algorithm = opt.algorithm;
  st.surface_vertices = static_cast<int>(s.V.rows());
  st.surface_triangles = static_cast<int>(s.F.rows());
  st.quality = measure_tets(tm.V, tm.T);
  if (stats) *stats = st;
  return tm;
}

int remove_spikes(SurfaceMesh& s, double max_height_abs) {
  const int n = static_cast<int>(s.V.rows());
  std::vector<std::array<int, 3>> F(s.F.rows());
  for (int f = 0; f < s.F.rows(); ++f) F[f] = {s.F(f, 0), s.F(f, 1), s.F(f, 2)};
  std::vector<char> alive(F.size(), 1);
  std::vector<std::vector<int>> faces_of(n);
  for (int f = 0; f < static_cast<int>(F.size()); ++f)
    for (int k = 0; k < 3; ++k) faces_of[F[f][k]].push_back(f);
  std::set<std::array<int, 3>> keys;  // sorted vertex triples of the live triangles
  auto key = [](std::array<int, 3> t) {
    std::sort(t.begin(), t.end());
    return t;
  };
  for (const auto& t : F) keys.insert(key(t));
  int removed = 0;
  for (bool again = true; again;) {
    again = false;
    for (int v = 0; v < n; ++v) {
      std::vector<int> fs;
      for (int f : faces_of[v])
        if (alive[f]) fs.push_back(f);
      if (fs.size() != 3) continue;
      // The ring: for each triangle (v, a, b) in its orientation, the edge a -> b.
      std::map<int, int> next;
      for (int f : fs) {
        int k = 0;
        while (F[f][k] != v) ++k;
        next[F[f][(k + 1) % 3]] = F[f][(k + 2) % 3];
      }
      if (next.size() != 3) continue;
      const int a = next.begin()->first, b = next[a], c = next[b];
      if (next[c] != a) continue;  // not one closed ring of three
      const std::array<int, 3> base{a, b, c};
      if (keys.count(key(base))) continue;  // the base triangle exists already (a tetrahedron)
      const Vec3 pa = s.V.row(a), pb = s.V.row(b), pc = s.V.row(c), pv = s.V.row(v);
      const Vec3 nrm = (pb - pa).cross(pc - pa);
      if (!(nrm.norm() > 0)) continue;
      if (!(std::abs(nrm.normalized().dot(pv - pa)) < max_height_abs)) continue;
      for (int f : fs) {
        alive[f] = 0;
        keys.erase(key(F[f]));
      }
      alive[fs[0]] = 1;
      F[fs[0]] = base;
      keys.insert(key(base));
      for (int w : base)
        if (std::find(faces_of[w].begin(), faces_of[w].end(), fs[0]) == faces_of[w].end()) faces_of[w].push_back(fs[0]);
      faces_of[v].clear();
      ++removed;
      again = true;
    }
  }
  if (removed == 0) return 0;
  std::vector<int> id(n, -1);  // the kept vertices in their order
  for (int f = 0; f < static_cast<int>(F.size()); ++f)
    if (alive[f])
      for (int w : F[f]) id[w] = 0;
  int m = 0;
  for (int w = 0; w < n; ++w)
    if (id[w] == 0) id[w] = m++;
  MatX3d V(m, 3);
  for (int w = 0; w < n; ++w)
    if (id[w] >= 0) V.row(id[w]) = s.V.row(w);
  const int nf = static_cast<int>(std::count(alive.begin(), alive.end(), 1));
  MatX3i G(nf, 3);
  for (int f = 0, r = 0; f < static_cast<int>(F.size()); ++f)
    if (alive[f]) {
      for (int k = 0; k < 3; ++k) G(r, k) = id[F[f][k]];
      ++r;
    }
  s.V = std::move(V);
  s.F = std::move(G);
  return removed;
}

}  // namespace polycube
