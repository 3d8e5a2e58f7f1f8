#include "polycube/validate/surface.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <queue>
#include <sstream>

#include "polycube/core/error.h"
#include "polycube/core/topology.h"

namespace polycube {

namespace {

// One half-edge record per face corner: the edge from F(f,k) to F(f,(k+1)%3).
struct HalfEdge {
  int lo, hi, face, k;
  bool forward;  // lo -> hi in the face's order
};

std::string where_list(const MeshData& m, const std::vector<int>& faces) {
  std::string s;
  for (size_t i = 0; i < faces.size(); ++i) s += (i ? ", " : "") + m.face_where(faces[i]);
  return s;
}

std::string section(const std::string& what, const std::vector<std::string>& items, size_t total, int max_listed) {
  std::ostringstream os;
  os << what;
  for (size_t i = 0; i < items.size() && static_cast<int>(i) < max_listed; ++i) os << "\n  " << items[i];
  if (total > static_cast<size_t>(max_listed)) os << "\n  ... and " << (total - max_listed) << " more";
  return os.str();
}

[[noreturn]] void refuse(const MeshData& m, const std::string& what, const std::vector<std::string>& items, size_t total,
                         int max_listed) {
  std::ostringstream os;
  os << (m.path.empty() ? std::string("input") : m.path) << ": " << what;
  for (size_t i = 0; i < items.size() && static_cast<int>(i) < max_listed; ++i) os << "\n  " << items[i];
  if (total > static_cast<size_t>(max_listed)) os << "\n  ... and " << (total - max_listed) << " more";
  throw Error(ErrorKind::InvalidMesh, os.str());
}

}  // namespace

double winding_number(const MatX3d& V, const MatX3i& F, const std::vector<int>& faces, const Vec3& p) {
  // Van Oosterom-Strackee solid angle of each triangle seen from p.
  double w = 0;
  for (int f : faces) {
    Vec3 a = V.row(F(f, 0)).transpose() - p, b = V.row(F(f, 1)).transpose() - p, c = V.row(F(f, 2)).transpose() - p;
    double la = a.norm(), lb = b.norm(), lc = c.norm();
    double num = a.dot(b.cross(c));
    double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    w += 2.0 * std::atan2(num, den);
  }
  return w / (4.0 * M_PI);
}

SurfaceReport validate_surface(MeshData& m, SurfaceLayout& layout, const ValidateOptions& opt) {
  SurfaceReport rep;
  rep.welded_vertices = m.welded_vertices;
  const std::string name = m.path.empty() ? std::string("input") : m.path;
  if (m.F.rows() == 0) throw Error(ErrorKind::Parse, name + ": no faces");

  // 1. Coordinates must be finite.
  {
    std::vector<std::string> bad;
    size_t n = 0;
    for (int i = 0; i < m.V.rows(); ++i)
      if (!m.V.row(i).allFinite()) {
        ++n;
        if (static_cast<int>(bad.size()) < opt.max_listed) {
          std::ostringstream os;
          os << m.vertex_where(i) << " has coordinates (" << m.V(i, 0) << ", " << m.V(i, 1) << ", " << m.V(i, 2) << ")";
          bad.push_back(os.str());
        }
      }
    if (n) refuse(m, std::to_string(n) + " vertices with NaN or infinite coordinates:", bad, n, opt.max_listed);
  }
  // 2. Indices in range (readers check this; meshes built in code may not).
  for (int f = 0; f < m.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (m.F(f, k) < 0 || m.F(f, k) >= m.V.rows())
        throw Error(ErrorKind::InvalidMesh, name + ": " + m.face_where(f) + " refers to vertex " +
                                                std::to_string(m.F(f, k)) + ", out of range [0, " +
                                                std::to_string(m.V.rows()) + ")");
  // 3. Remove unreferenced vertices.
  {
    std::vector<int> used(m.V.rows(), -1);
    int n = 0;
    for (int f = 0; f < m.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) used[m.F(f, k)] = 1;
    for (int i = 0; i < m.V.rows(); ++i)
      if (used[i] == 1) used[i] = n++;
    rep.unreferenced_removed = static_cast<int>(m.V.rows()) - n;
    if (rep.unreferenced_removed) {
      MatX3d V2(n, 3);
      std::vector<int> vl(n, 0);
      for (int i = 0; i < m.V.rows(); ++i)
        if (used[i] >= 0) {
          V2.row(used[i]) = m.V.row(i);
          if (i < static_cast<int>(m.vertex_line.size())) vl[used[i]] = m.vertex_line[i];
        }
      for (int f = 0; f < m.F.rows(); ++f)
        for (int k = 0; k < 3; ++k) m.F(f, k) = used[m.F(f, k)];
      m.V = std::move(V2);
      m.vertex_line = std::move(vl);
    }
  }
  const int nv = static_cast<int>(m.V.rows()), nf = static_cast<int>(m.F.rows());
  rep.vertices = nv;
  rep.triangles = nf;

  // 4-6. Degenerate faces, duplicate faces, non-manifold edges: reported together.
  std::vector<std::string> problems;
  // 4. Degenerate faces.
  {
    std::vector<std::string> bad;
    size_t n = 0;
    for (int f = 0; f < nf; ++f) {
      int a = m.F(f, 0), b = m.F(f, 1), c = m.F(f, 2);
      std::string why;
      if (a == b || b == c || a == c) {
        why = "repeats a vertex (" + std::to_string(a) + ", " + std::to_string(b) + ", " + std::to_string(c) + ")";
      } else {
        Vec3 pa = m.V.row(a), pb = m.V.row(b), pc = m.V.row(c);
        double area2 = (pb - pa).cross(pc - pa).norm();
        double l2 = std::max({(pb - pa).squaredNorm(), (pc - pb).squaredNorm(), (pa - pc).squaredNorm()});
        if (area2 <= opt.degenerate_area_rel * l2)
          why = "has zero area (vertices " + std::to_string(a) + ", " + std::to_string(b) + ", " + std::to_string(c) + ")";
      }
      if (!why.empty()) {
        ++n;
        if (static_cast<int>(bad.size()) < opt.max_listed) bad.push_back(m.face_where(f) + " " + why);
      }
    }
    if (n) problems.push_back(section(std::to_string(n) + " degenerate faces:", bad, n, opt.max_listed));
  }
  // 5. Duplicate faces (same three vertices, either orientation).
  {
    std::vector<std::pair<std::array<int, 3>, int>> keys(nf);
    for (int f = 0; f < nf; ++f) {
      std::array<int, 3> k{m.F(f, 0), m.F(f, 1), m.F(f, 2)};
      std::sort(k.begin(), k.end());
      keys[f] = {k, f};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<std::string> bad;
    size_t n = 0;
    for (int i = 1; i < nf; ++i)
      if (keys[i].first == keys[i - 1].first) {
        ++n;
        if (static_cast<int>(bad.size()) < opt.max_listed)
          bad.push_back(m.face_where(keys[i - 1].second) + " and " + m.face_where(keys[i].second) +
                        " use the same vertices (" + std::to_string(keys[i].first[0]) + ", " +
                        std::to_string(keys[i].first[1]) + ", " + std::to_string(keys[i].first[2]) + ")");
      }
    if (n) problems.push_back(section(std::to_string(n) + " duplicate faces:", bad, n, opt.max_listed));
  }
  // 6. Edges: sorted half-edges, grouped by undirected edge.
  std::vector<HalfEdge> he(3 * static_cast<size_t>(nf));
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      int a = m.F(f, k), b = m.F(f, (k + 1) % 3);
      he[3 * f + k] = {std::min(a, b), std::max(a, b), f, k, a < b};
    }
  std::sort(he.begin(), he.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.lo != y.lo ? x.lo < y.lo : x.hi != y.hi ? x.hi < y.hi : x.face < y.face;
  });
  std::vector<std::pair<int, int>> groups;  // [begin, end) into he
  for (size_t i = 0; i < he.size();) {
    size_t j = i;
    while (j < he.size() && he[j].lo == he[i].lo && he[j].hi == he[i].hi) ++j;
    groups.push_back({static_cast<int>(i), static_cast<int>(j)});
    i = j;
  }
  {
    std::vector<std::string> bad;
    size_t n = 0;
    for (auto [b, e] : groups)
      if (e - b > 2) {
        ++n;
        if (static_cast<int>(bad.size()) < opt.max_listed) {
          std::vector<int> fs;
          for (int i = b; i < e; ++i) fs.push_back(he[i].face);
          bad.push_back("edge (" + std::to_string(he[b].lo) + ", " + std::to_string(he[b].hi) + ") is shared by " +
                        std::to_string(e - b) + " faces: " + where_list(m, fs));
        }
      }
    if (n)
      problems.insert(problems.begin(),
                      section(std::to_string(n) + " non-manifold edges (vertex ids are 0-based):", bad, n, opt.max_listed));
  }
  if (!problems.empty()) {
    std::string msg = name + ": ";
    for (size_t i = 0; i < problems.size(); ++i) msg += (i ? "\n" : "") + problems[i];
    throw Error(ErrorKind::InvalidMesh, msg);
  }
  // 7. Non-manifold vertices: the faces around a vertex must form a single fan.
  {
    UnionFind uf(3 * nf);
    auto corner = [&](int f, int v) {
      for (int k = 0; k < 3; ++k)
        if (m.F(f, k) == v) return 3 * f + k;
      return -1;
    };
    for (auto [b, e] : groups)
      if (e - b == 2) {
        int f = he[b].face, g = he[b + 1].face;
        uf.unite(corner(f, he[b].lo), corner(g, he[b].lo));
        uf.unite(corner(f, he[b].hi), corner(g, he[b].hi));
      }
    std::vector<int> first(nv, -1);
    std::vector<char> bad_v(nv, 0);
    for (int c = 0; c < 3 * nf; ++c) {
      int v = m.F(c / 3, c % 3), r = uf.find(c);
      if (first[v] < 0) first[v] = r;
      else if (first[v] != r) bad_v[v] = 1;
    }
    std::vector<std::string> bad;
    size_t n = 0;
    for (int v = 0; v < nv; ++v)
      if (bad_v[v]) {
        ++n;
        if (static_cast<int>(bad.size()) < opt.max_listed)
          bad.push_back(m.vertex_where(v) + " joins separate sheets of faces (pinch point)");
      }
    if (n) refuse(m, std::to_string(n) + " non-manifold vertices (vertex ids are 0-based):", bad, n, opt.max_listed);
  }
  // 8. Open boundaries: chain the boundary edges into loops.
  std::vector<int> loop_start;  // first vertex of each loop
  {
    std::multimap<int, int> out;  // boundary half-edge a -> b, in face order
    for (auto [b, e] : groups)
      if (e - b == 1) {
        const HalfEdge& h = he[b];
        int a = h.forward ? h.lo : h.hi, c = h.forward ? h.hi : h.lo;
        out.emplace(a, c);
      }
    if (!out.empty()) {
      rep.closed = false;
      rep.border_edges = static_cast<int>(out.size());
      std::vector<std::string> loops;
      size_t nedges = out.size();
      while (!out.empty()) {
        auto it = out.begin();
        int start = it->first, cur = it->second;
        std::vector<int> loop{start};
        out.erase(it);
        while (cur != start) {
          loop.push_back(cur);
          auto nx = out.find(cur);
          if (nx == out.end()) break;
          cur = nx->second;
          out.erase(nx);
        }
        std::string s = "loop of " + std::to_string(loop.size()) + " edges through vertices";
        for (size_t i = 0; i < loop.size() && i < 12; ++i) s += " " + std::to_string(loop[i]);
        if (loop.size() > 12) s += " ...";
        Vec3 p = m.V.row(loop[0]);
        std::ostringstream os;
        os << " (starts at " << p.x() << ", " << p.y() << ", " << p.z() << ")";
        loops.push_back(s + os.str());
        loop_start.push_back(start);
      }
      rep.border_loops = static_cast<int>(loops.size());
      if (!opt.allow_open)
        refuse(m,
             "surface is not closed: " + std::to_string(nedges) + " boundary edges in " + std::to_string(loops.size()) +
                 " open loops (a volume needs a closed surface: fill the holes first, or use --surface for a surface polycube and quads):",
             loops, loops.size(), opt.max_listed);
    }
  }
  // 9. Components and consistent orientation (BFS across manifold edges).
  std::vector<std::vector<int>> adj(nf);  // (neighbour face, same_direction) packed as 2*g + same
  for (auto [b, e] : groups) {
    if (e - b != 2) continue;  // a border edge (allow_open): no neighbour across it
    const HalfEdge& x = he[b];
    const HalfEdge& y = he[b + 1];
    bool same = x.forward == y.forward;  // same traversal direction = inconsistent pair
    adj[x.face].push_back(2 * y.face + same);
    adj[y.face].push_back(2 * x.face + same);
  }
  layout.component_of_face.assign(nf, -1);
  std::vector<char> flip(nf, 0);
  int nc = 0;
  std::vector<std::vector<int>> comp_faces;
  for (int s = 0; s < nf; ++s) {
    if (layout.component_of_face[s] >= 0) continue;
    comp_faces.emplace_back();
    std::queue<int> q;
    q.push(s);
    layout.component_of_face[s] = nc;
    while (!q.empty()) {
      int f = q.front();
      q.pop();
      comp_faces[nc].push_back(f);
      for (int p : adj[f]) {
        int g = p / 2;
        char want = flip[f] ^ static_cast<char>(p & 1);
        if (layout.component_of_face[g] < 0) {
          layout.component_of_face[g] = nc;
          flip[g] = want;
          q.push(g);
        } else if (flip[g] != want) {
          throw Error(ErrorKind::InvalidMesh, name + ": component " + std::to_string(nc) + " (containing " +
                                                  m.face_where(s) + ") is not orientable (Moebius- or Klein-like); " +
                                                  "orientation conflict at " + m.face_where(g));
        }
      }
    }
    ++nc;
  }
  // Flip the minority within each component (fewer changes to the input).
  for (int c = 0; c < nc; ++c) {
    size_t nflip = 0;
    for (int f : comp_faces[c]) nflip += flip[f];
    bool invert = nflip * 2 > comp_faces[c].size();
    for (int f : comp_faces[c])
      if (flip[f] ^ static_cast<char>(invert)) {
        if (!opt.repair_orientation)
          throw Error(ErrorKind::InvalidMesh, name + ": inconsistent face orientation at " + m.face_where(f));
        std::swap(m.F(f, 1), m.F(f, 2));
        ++rep.faces_flipped;
      }
  }
  // 10. Genus, volume and nesting of components.
  layout.depth.assign(nc, 0);
  layout.parent.assign(nc, -1);
  layout.genus.assign(nc, 0);
  layout.volume.assign(nc, 0.0);
  {
    std::vector<int> ne(nc, 0), nvc(nc, 0);
    for (auto [b, e] : groups) ne[layout.component_of_face[he[b].face]]++;
    std::vector<int> vc(nv, -1);
    for (int f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) vc[m.F(f, k)] = layout.component_of_face[f];
    for (int v = 0; v < nv; ++v) nvc[vc[v]]++;
    std::vector<int> loops_of(nc, 0);
    for (int v : loop_start) loops_of[vc[v]]++;
    for (int c = 0; c < nc; ++c) {
      int chi = nvc[c] - ne[c] + static_cast<int>(comp_faces[c].size());
      layout.genus[c] = (2 - chi - loops_of[c]) / 2;
    }
  }
  const Vec3 center = m.V.colwise().mean();
  for (int c = 0; c < nc; ++c) {
    double vol = 0;
    for (int f : comp_faces[c]) {
      Vec3 a = m.V.row(m.F(f, 0)).transpose() - center, b = m.V.row(m.F(f, 1)).transpose() - center,
           d = m.V.row(m.F(f, 2)).transpose() - center;
      vol += a.dot(b.cross(d)) / 6.0;
    }
    layout.volume[c] = vol;
  }
  if (!rep.closed) {  // open surfaces (allow_open): no inside, no nesting; orientation as given
    rep.components = nc;
    for (int g : layout.genus) rep.genus += g;
    return rep;
  }
  if (nc > 1) {
    std::vector<std::vector<char>> inside(nc, std::vector<char>(nc, 0));
    for (int c = 0; c < nc; ++c) {
      int f0 = comp_faces[c][0];
      Vec3 p = (m.V.row(m.F(f0, 0)) + m.V.row(m.F(f0, 1)) + m.V.row(m.F(f0, 2))).transpose() / 3.0;
      for (int d = 0; d < nc; ++d)
        if (d != c && std::abs(winding_number(m.V, m.F, comp_faces[d], p)) > 0.5) {
          inside[c][d] = 1;
          layout.depth[c]++;
        }
    }
    for (int c = 0; c < nc; ++c)
      for (int d = 0; d < nc; ++d)
        if (inside[c][d] && layout.depth[d] == layout.depth[c] - 1) layout.parent[c] = d;
  }
  for (int c = 0; c < nc; ++c) {
    const bool cavity = layout.depth[c] % 2 == 1;
    const bool outward = cavity ? layout.volume[c] < 0 : layout.volume[c] > 0;
    if (!outward) {
      if (!opt.repair_orientation)
        throw Error(ErrorKind::InvalidMesh, name + ": component " + std::to_string(c) + " faces inward");
      for (int f : comp_faces[c]) std::swap(m.F(f, 1), m.F(f, 2));
      layout.volume[c] = -layout.volume[c];
      rep.components_reversed++;
    }
  }
  rep.components = nc;
  for (int g : layout.genus) rep.genus += g;
  return rep;
}

}  // namespace polycube
