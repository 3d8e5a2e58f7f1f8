#include "polycube/constraints/constraints.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include <Eigen/Geometry>

#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/geometry/features.h"

namespace polycube::constraints {

using nlohmann::json;

namespace {

std::array<int, 2> sorted_edge(int a, int b) { return a < b ? std::array<int, 2>{a, b} : std::array<int, 2>{b, a}; }

}  // namespace

std::vector<Constraint> read_constraints(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(ErrorKind::Parse, path + ": cannot open the constraint file");
  json j;
  try {
    in >> j;
  } catch (const json::exception& e) {
    throw Error(ErrorKind::Parse, path + ": not valid JSON (" + e.what() + ")");
  }
  if (!j.is_object() || !j.contains("constraints") || !j["constraints"].is_array())
    throw Error(ErrorKind::Parse, path + ": expected an object with a \"constraints\" array");
  std::vector<Constraint> out;
  int i = 0;
  for (const json& e : j["constraints"]) {
    const std::string where = path + ": constraint " + std::to_string(i++);
    auto bad = [&](const std::string& why) { return Error(ErrorKind::Parse, where + ": " + why); };
    if (!e.is_object()) throw bad("not an object");
    Constraint c;
    try {
      if (e.contains("name")) c.name = e["name"].get<std::string>();
      const std::string type = e.value("type", std::string());
      if (type != "sharp" && type != "flat") throw bad("\"type\" must be \"sharp\" or \"flat\"");
      c.sharp = type == "sharp";
      if (e.contains("weight")) {
        c.weight = e["weight"].get<double>();
        if (!(c.weight > 0) || !std::isfinite(c.weight)) throw bad("\"weight\" must be a positive number");
      }
      if (e.contains("edges")) {
        for (const json& p : e["edges"]) {
          if (!p.is_array() || p.size() != 2) throw bad("every edge must be a pair of vertex ids");
          const int a = p[0].get<int>(), b = p[1].get<int>();
          if (a < 0 || b < 0 || a == b) throw bad("edge [" + std::to_string(a) + ", " + std::to_string(b) + "] is not a pair of distinct vertex ids");
          c.edges.push_back({a, b});
        }
      }
      if (e.contains("group")) c.group = e["group"].get<std::string>();
      if (e.contains("faces")) {
        for (const json& f : e["faces"]) {
          const int id = f.get<int>();
          if (id < 0) throw bad("negative face id " + std::to_string(id));
          c.faces.push_back(id);
        }
      }
    } catch (const json::exception& ex) {
      throw bad(std::string("wrong value type (") + ex.what() + ")");
    }
    if (c.edges.empty() && c.faces.empty() && c.group.empty())
      throw bad("neither \"edges\", \"faces\" nor \"group\" given");
    if (c.name.empty()) c.name = "constraint " + std::to_string(out.size());
    out.push_back(std::move(c));
  }
  return out;
}

void write_constraints(const std::string& path, const std::vector<Constraint>& cs) {
  json arr = json::array();
  for (const Constraint& c : cs) {
    json e = {{"name", c.name}, {"type", c.sharp ? "sharp" : "flat"}};
    if (c.weight > 0) e["weight"] = c.weight;
    if (!c.edges.empty()) {
      e["edges"] = json::array();
      for (const auto& p : c.edges) e["edges"].push_back({p[0], p[1]});
    }
    if (!c.faces.empty()) e["faces"] = c.faces;
    if (!c.group.empty()) e["group"] = c.group;
    arr.push_back(e);
  }
  std::ofstream out(path);
  out << json{{"constraints", arr}}.dump(1) << "\n";
  if (!out) throw Error(ErrorKind::Output, path + ": cannot write the constraint file");
}

void resolve_groups(std::vector<Constraint>& cs, const std::vector<std::string>& face_group) {
  for (size_t i = 0; i < cs.size(); ++i) {
    Constraint& c = cs[i];
    if (c.group.empty()) continue;
    const size_t before = c.faces.size();
    for (size_t f = 0; f < face_group.size(); ++f)
      if (face_group[f] == c.group) c.faces.push_back(static_cast<int>(f));
    if (c.faces.size() == before)
      throw Error(ErrorKind::Usage, "constraint " + std::to_string(i) + " (" + c.name + "): no triangle of the input is in group '" +
                                        c.group + "'" + (face_group.empty() ? " (the input has no groups)" : ""));
  }
}

std::vector<Constraint> detect_features(const SurfaceMesh& s, double angle_deg) {
  const std::vector<unsigned char> sharp = geometry::sharp_edges(s, angle_deg);
  std::set<std::array<int, 2>> edges;
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (sharp[f] >> k & 1) edges.insert(sorted_edge(s.F(f, k), s.F(f, (k + 1) % 3)));
  std::vector<std::vector<int>> nb(s.V.rows());
  for (const auto& e : edges) {
    nb[e[0]].push_back(e[1]);
    nb[e[1]].push_back(e[0]);
  }
  std::set<std::array<int, 2>> used;
  std::vector<Constraint> out;
  auto walk = [&](int start, int next) {
    Constraint c;
    c.sharp = true;
    int prev = start, cur = next;
    c.edges.push_back({prev, cur});
    used.insert(sorted_edge(prev, cur));
    while (nb[cur].size() == 2) {
      const int nx = nb[cur][0] == prev ? nb[cur][1] : nb[cur][0];
      if (used.count(sorted_edge(cur, nx))) break;  // closed loop
      c.edges.push_back({cur, nx});
      used.insert(sorted_edge(cur, nx));
      prev = cur;
      cur = nx;
    }
    c.name = "feature " + std::to_string(out.size());
    out.push_back(std::move(c));
  };
  // Open curves from their ends (vertices with other than two sharp edges), then closed loops.
  for (int v = 0; v < static_cast<int>(nb.size()); ++v)
    if (nb[v].size() != 2)
      for (int w : nb[v])
        if (!used.count(sorted_edge(v, w))) walk(v, w);
  for (const auto& e : edges)
    if (!used.count(e)) walk(e[0], e[1]);
  return out;
}

std::vector<std::array<int, 2>> constraint_edges(const Constraint& c, const SurfaceMesh& s, int index) {
  const std::string who = "constraint " + std::to_string(index) + (c.name.empty() ? "" : " (" + c.name + ")");
  const int nv = static_cast<int>(s.V.rows()), nf = static_cast<int>(s.F.rows());
  // Surface edges -> how many of the region's triangles hold them.
  std::map<std::array<int, 2>, int> surface_edges;
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) surface_edges[sorted_edge(s.F(f, k), s.F(f, (k + 1) % 3))] = 0;
  std::set<std::array<int, 2>> out;
  for (const auto& e : c.edges) {
    if (e[0] >= nv || e[1] >= nv)
      throw Error(ErrorKind::Usage, who + ": vertex id " + std::to_string(std::max(e[0], e[1])) +
                                        " is out of range (the input has " + std::to_string(nv) + " vertices)");
    if (!surface_edges.count(sorted_edge(e[0], e[1])))
      throw Error(ErrorKind::Usage, who + ": vertices " + std::to_string(e[0]) + " and " + std::to_string(e[1]) +
                                        " are not joined by an edge of the input surface");
    out.insert(sorted_edge(e[0], e[1]));
  }
  for (int f : c.faces) {
    if (f >= nf)
      throw Error(ErrorKind::Usage, who + ": face id " + std::to_string(f) + " is out of range (the input has " +
                                        std::to_string(nf) + " triangles)");
    for (int k = 0; k < 3; ++k) surface_edges[sorted_edge(s.F(f, k), s.F(f, (k + 1) % 3))]++;
  }
  if (!c.faces.empty())
    for (const auto& [e, n] : surface_edges)
      if ((!c.sharp && n >= 2) || (c.sharp && n == 1)) out.insert(e);
  return {out.begin(), out.end()};
}

Mapped map_to_boundary(const std::vector<Constraint>& cs, const SurfaceMesh& s, const MatX3d& V, const MatX3i& B,
                       const std::vector<deform::FacePair>& pairs, const ConstraintOptions& opt) {
  Mapped m;
  // Boundary vertices by exact position, boundary edges -> pair.
  std::map<std::array<double, 3>, int> at;
  for (int f = 0; f < B.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int v = B(f, k);
      at.emplace(std::array<double, 3>{V(v, 0), V(v, 1), V(v, 2)}, v);
    }
  std::map<std::array<int, 2>, int> pair_of;
  for (int p = 0; p < static_cast<int>(pairs.size()); ++p) pair_of[sorted_edge(pairs[p].a, pairs[p].b)] = p;
  auto find = [&](int i) {
    auto it = at.find({s.V(i, 0), s.V(i, 1), s.V(i, 2)});
    return it == at.end() ? -1 : it->second;
  };
  for (int ci = 0; ci < static_cast<int>(cs.size()); ++ci) {
    const Constraint& c = cs[ci];
    const double omega = c.weight > 0 ? c.weight : opt.weight;
    const auto edges = constraint_edges(c, s, ci);
    std::set<int> got;
    std::vector<std::array<int, 2>> missing;  // input edges that are not boundary edges
    for (const auto& e : edges) {
      const int u = find(e[0]), w = find(e[1]);
      auto it = u >= 0 && w >= 0 ? pair_of.find(sorted_edge(u, w)) : pair_of.end();
      if (it != pair_of.end()) got.insert(it->second);
      else missing.push_back(e);
    }
    if (!missing.empty()) {
      // Remeshed: the boundary edges whose ends and midpoint lie on the polyline of the missing
      // input edges (a new edge may span several input edges), within 1% of their mean length.
      Eigen::AlignedBox3d box;
      double mean_len = 0;
      for (const auto& e : missing) {
        box.extend(s.V.row(e[0]).transpose());
        box.extend(s.V.row(e[1]).transpose());
        mean_len += (s.V.row(e[0]) - s.V.row(e[1])).norm();
      }
      const double tol = 0.01 * mean_len / static_cast<double>(missing.size());
      box.min().array() -= tol;
      box.max().array() += tol;
      auto on_polyline = [&](const Vec3& p) {
        if (!box.contains(p)) return false;
        for (const auto& e : missing) {
          const Vec3 a = s.V.row(e[0]), ab = Vec3(s.V.row(e[1])) - a;
          const double t = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-300), 0.0, 1.0);
          if ((a + t * ab - p).norm() <= tol) return true;
        }
        return false;
      };
      for (const auto& [key, p] : pair_of) {
        const Vec3 a = V.row(key[0]), b = V.row(key[1]);
        if (on_polyline(a) && on_polyline(b) && on_polyline(0.5 * (a + b))) got.insert(p);
      }
    }
    m.input_edges.push_back(static_cast<int>(edges.size()));
    m.mapped_edges.push_back(static_cast<int>(got.size()));
    for (int p : got) {
      m.terms.push_back({p, c.sharp, omega});
      m.owner.push_back(ci);
    }
  }
  return m;
}

std::vector<double> normal_angles_deg(const Mapped& m, const MatX3d& X, const MatX3i& B,
                                      const std::vector<deform::FacePair>& pairs) {
  std::vector<double> out;
  out.reserve(m.terms.size());
  for (const auto& t : m.terms) {
    const auto& p = pairs[t.pair];
    const Vec3 nf = deform::area_normal(X, B(p.f, 0), B(p.f, 1), B(p.f, 2)).normalized();
    const Vec3 ng = deform::area_normal(X, B(p.g, 0), B(p.g, 1), B(p.g, 2)).normalized();
    out.push_back(std::acos(std::clamp(nf.dot(ng), -1.0, 1.0)) * 180 / M_PI);
  }
  return out;
}

}  // namespace polycube::constraints
