#include "polycube/geometry/feature_capture.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <queue>
#include <set>
#include <unordered_map>

#include "polycube/core/topology.h"
#include "polycube/geometry/closest_point.h"
#include "polycube/geometry/features.h"

namespace polycube::geometry {

namespace {

double point_segment_distance(const Vec3& p, const Vec3& a, const Vec3& b, double* t_out = nullptr) {
  const double t = closest_point_on_segment(p, a, b);
  if (t_out) *t_out = t;
  return (a + t * (b - a) - p).norm();
}

// Uniform bucket grid of items with a bounding box (segments or points), cell size h.
class BucketGrid {
 public:
  explicit BucketGrid(double h) : h_(h) {}
  void insert(int item, const Vec3& lo, const Vec3& hi) {
    const auto a = cell(lo), b = cell(hi);
    for (long long i = a[0]; i <= b[0]; ++i)
      for (long long j = a[1]; j <= b[1]; ++j)
        for (long long k = a[2]; k <= b[2]; ++k) cells_[key(i, j, k)].push_back(item);
  }
  /// Calls f(item) for the items of the cells the box around p of half-size r meets (items may repeat).
  template <class F>
  void visit(const Vec3& p, double r, F&& f) const {
    const auto a = cell(p - Vec3::Constant(r)), b = cell(p + Vec3::Constant(r));
    for (long long i = a[0]; i <= b[0]; ++i)
      for (long long j = a[1]; j <= b[1]; ++j)
        for (long long k = a[2]; k <= b[2]; ++k) {
          const auto it = cells_.find(key(i, j, k));
          if (it != cells_.end())
            for (int item : it->second) f(item);
        }
  }

 private:
  std::array<long long, 3> cell(const Vec3& p) const {
    return {static_cast<long long>(std::floor(p.x() / h_)), static_cast<long long>(std::floor(p.y() / h_)),
            static_cast<long long>(std::floor(p.z() / h_))};
  }
  static long long key(long long i, long long j, long long k) {
    return ((i & 0x1FFFFF) << 42) | ((j & 0x1FFFFF) << 21) | (k & 0x1FFFFF);
  }
  double h_;
  std::unordered_map<long long, std::vector<int>> cells_;
};

// Closest point of a polyline to p: distance and arc length there.
double polyline_distance(const std::vector<Vec3>& pl, const std::vector<double>& arc, const Vec3& p,
                         double* s_out = nullptr, Vec3* q_out = nullptr) {
  double best = 1e300;
  for (size_t i = 0; i + 1 < pl.size(); ++i) {
    double t;
    const double d = point_segment_distance(p, pl[i], pl[i + 1], &t);
    if (d < best) {
      best = d;
      if (s_out) *s_out = arc[i] + t * (arc[i + 1] - arc[i]);
      if (q_out) *q_out = pl[i] + t * (pl[i + 1] - pl[i]);
    }
  }
  return best;
}


// The distinct edges of a quad mesh.
std::vector<std::array<int, 2>> quad_edges(const MatX4i& Q, int n, std::vector<std::vector<int>>* neighbours) {
  std::vector<std::array<int, 2>> edges;
  std::vector<std::vector<int>> nb(n);
  for (int q = 0; q < Q.rows(); ++q)
    for (int j = 0; j < 4; ++j) {
      const int a = Q(q, j), b = Q(q, (j + 1) % 4);
      if (std::find(nb[a].begin(), nb[a].end(), b) != nb[a].end()) continue;
      nb[a].push_back(b);
      nb[b].push_back(a);
      edges.push_back({std::min(a, b), std::max(a, b)});
    }
  if (neighbours) *neighbours = std::move(nb);
  return edges;
}

double mean_length(const MatX3d& V, const std::vector<std::array<int, 2>>& edges) {
  double l = 0;
  for (const auto& e : edges) l += (V.row(e[0]) - V.row(e[1])).norm();
  return edges.empty() ? 0.0 : l / static_cast<double>(edges.size());
}

BucketGrid edge_grid(const MatX3d& V, const std::vector<std::array<int, 2>>& edges, double h) {
  BucketGrid g(h);
  for (size_t i = 0; i < edges.size(); ++i) {
    const Vec3 a = V.row(edges[i][0]), b = V.row(edges[i][1]);
    g.insert(static_cast<int>(i), a.cwiseMin(b), a.cwiseMax(b));
  }
  return g;
}

// Distance from p to the nearest edge running along `tangent` (within 45 degrees; edges across a
// crease do not follow it), at most `radius`.
double edge_distance(const BucketGrid& g, const MatX3d& V, const std::vector<std::array<int, 2>>& edges, const Vec3& p,
                     const Vec3& tangent, double radius) {
  double d = radius;
  g.visit(p, radius, [&](int i) {
    const Vec3 a = V.row(edges[i][0]), b = V.row(edges[i][1]);
    const double l = (b - a).norm();
    if (l > 0 && std::abs((b - a).dot(tangent)) >= std::sqrt(0.5) * l) d = std::min(d, point_segment_distance(p, a, b));
  });
  return d;
}

// Points along a chain at most `step` apart, its vertices included, with the unit tangent there.
std::vector<std::pair<Vec3, Vec3>> chain_samples(const SurfaceMesh& s, const std::vector<int>& c, double step) {
  std::vector<std::pair<Vec3, Vec3>> pts;
  Vec3 t = Vec3::UnitX();
  for (size_t i = 0; i + 1 < c.size(); ++i) {
    const Vec3 a = s.V.row(c[i]), b = s.V.row(c[i + 1]);
    if ((b - a).norm() > 0) t = (b - a).normalized();
    const int k = std::max(1, static_cast<int>(std::ceil((b - a).norm() / step)));
    for (int j = 0; j < k; ++j) pts.push_back({a + (b - a) * (static_cast<double>(j) / k), t});
  }
  pts.push_back({s.V.row(c.back()), t});
  return pts;
}

}  // namespace

std::vector<std::vector<int>> sharp_chains(const SurfaceMesh& s, const std::vector<unsigned char>& sharp) {
  const MatX3i adj = face_adjacency(s.F);
  std::map<std::pair<int, int>, int> edge_id;
  std::vector<std::vector<std::pair<int, int>>> inc(s.V.rows());  // (neighbour, edge id)
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      if (!(sharp[f] >> k & 1) || adj(f, k) < 0) continue;
      const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
      const auto key = std::minmax(a, b);
      if (edge_id.count(key)) continue;
      const int id = static_cast<int>(edge_id.size());
      edge_id[key] = id;
      inc[a].push_back({b, id});
      inc[b].push_back({a, id});
    }
  std::vector<char> used(edge_id.size(), 0);
  std::vector<std::vector<int>> chains;
  auto walk = [&](int start, int first_nb, int first_edge) {
    std::vector<int> c{start};
    int cur = first_nb, e = first_edge;
    used[e] = 1;
    c.push_back(cur);
    while (inc[cur].size() == 2 && cur != start) {
      const auto& [n0, e0] = inc[cur][0];
      const auto& [n1, e1] = inc[cur][1];
      const int next = e0 == e ? n1 : n0, ne = e0 == e ? e1 : e0;
      if (used[ne]) break;
      used[ne] = 1;
      cur = next;
      e = ne;
      c.push_back(cur);
    }
    chains.push_back(std::move(c));
  };
  for (int v = 0; v < s.V.rows(); ++v)
    if (inc[v].size() != 2)
      for (const auto& [nb, e] : inc[v])
        if (!used[e]) walk(v, nb, e);
  for (int v = 0; v < s.V.rows(); ++v)  // closed loops
    for (const auto& [nb, e] : inc[v])
      if (!used[e]) walk(v, nb, e);
  return chains;
}

SharpChainPositions::SharpChainPositions(const SurfaceMesh& s, const std::vector<unsigned char>& sharp)
    : s_(s), sharp_(sharp) {
  for (const std::vector<int>& c : sharp_chains(s, sharp)) {
    const int id = static_cast<int>(length_.size());
    double at = 0;
    for (size_t i = 0; i + 1 < c.size(); ++i) {
      edges_[std::minmax(c[i], c[i + 1])] = EdgeAt{id, at, c[i]};
      at += (s.V.row(c[i + 1]) - s.V.row(c[i])).norm();
    }
    length_.push_back(at);
    closed_.push_back(c.size() > 2 && c.front() == c.back());
  }
}

bool SharpChainPositions::locate(const TriangleTree& tree, const MatX3i& adj, const Vec3& p, double tol,
                                 Position& out) const {
  double best = tol;
  bool found = false;
  for_each_sharp_edge_near(s_, sharp_, adj, tree, p, [&](int a, int b) {
    const auto it = edges_.find(std::minmax(a, b));
    if (it == edges_.end()) return;  // an open edge
    double t = 0;
    const double d = point_segment_distance(p, s_.V.row(a), s_.V.row(b), &t);
    if (d > best) return;
    best = d;
    found = true;
    const double len = (s_.V.row(b) - s_.V.row(a)).norm();
    out.chain = it->second.chain;
    out.s = it->second.s_from + (a == it->second.from ? t : 1 - t) * len;
  });
  return found;
}

double SharpChainPositions::distance(const Position& a, const Position& b) const {
  if (a.chain < 0 || a.chain != b.chain) return std::numeric_limits<double>::infinity();
  const double d = std::abs(a.s - b.s);
  return closed_[a.chain] ? std::min(d, length_[a.chain] - d) : d;
}

std::vector<unsigned char> crease_edges(const SurfaceMesh& s, double weak_deg, double strong_deg) {
  const std::vector<unsigned char> weak = sharp_edges(s, weak_deg), strong = sharp_edges(s, strong_deg);
  auto key = [](int a, int b) { return std::pair<int, int>(std::min(a, b), std::max(a, b)); };
  std::set<std::pair<int, int>> strong_edges, keep;
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (strong[f] >> k & 1) strong_edges.insert(key(s.F(f, k), s.F(f, (k + 1) % 3)));
  for (const std::vector<int>& c : sharp_chains(s, weak)) {
    bool any = false;
    for (size_t i = 0; i + 1 < c.size() && !any; ++i) any = strong_edges.count(key(c[i], c[i + 1])) > 0;
    if (any)
      for (size_t i = 0; i + 1 < c.size(); ++i) keep.insert(key(c[i], c[i + 1]));
  }
  std::vector<unsigned char> out(s.F.rows(), 0);
  for (int f = 0; f < s.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (keep.count(key(s.F(f, k), s.F(f, (k + 1) % 3)))) out[f] |= 1 << k;
  return out;
}

FeatureCaptureStats capture_sharp_edges(MatX3d& V, const MatX4i& Q, const SurfaceMesh& s,
                                        const std::vector<unsigned char>& sharp, const std::vector<char>& locked,
                                        std::vector<char>& snapped, const FeatureCaptureOptions& opt) {
  FeatureCaptureStats st;
  const int n = static_cast<int>(V.rows());
  snapped.assign(n, 0);
  if (Q.rows() == 0) return st;
  std::vector<std::vector<int>> nb;
  const std::vector<std::array<int, 2>> edges = quad_edges(Q, n, &nb);
  const double elen = mean_length(V, edges);
  if (!(elen > 0)) return st;
  const double tol = opt.cover_tolerance * elen, corridor = opt.corridor * elen;


  // Each chain sampled at most a quarter edge length apart; runs of samples no mesh edge passes near.
  struct Run {
    std::vector<Vec3> pl;
    std::vector<double> arc;
  };
  std::vector<Run> runs;
  {
    const BucketGrid g = edge_grid(V, edges, elen);
    for (const std::vector<int>& c : sharp_chains(s, sharp)) {
      const std::vector<std::pair<Vec3, Vec3>> samples = chain_samples(s, c, 0.25 * elen);
      std::vector<Vec3> pts;
      for (const auto& [p, t] : samples) pts.push_back(p);
      std::vector<char> cov(pts.size());
      for (size_t i = 0; i < pts.size(); ++i) {
        cov[i] = edge_distance(g, V, edges, samples[i].first, samples[i].second, tol) < tol;
      }
      for (size_t i = 0; i < pts.size();) {
        if (cov[i]) {
          ++i;
          continue;
        }
        size_t j = i;
        while (j + 1 < pts.size() && !cov[j + 1]) ++j;
        Run r;
        for (size_t k = i > 0 ? i - 1 : 0; k <= std::min(j + 1, pts.size() - 1); ++k) r.pl.push_back(pts[k]);
        r.arc.assign(r.pl.size(), 0.0);
        for (size_t k = 1; k < r.pl.size(); ++k) r.arc[k] = r.arc[k - 1] + (r.pl[k] - r.pl[k - 1]).norm();
        if (r.arc.back() >= opt.min_run * elen) runs.push_back(std::move(r));
        i = j + 1;
      }
    }
  }
  st.runs = static_cast<int>(runs.size());

  BucketGrid vgrid(elen);  // the vertices of the quads (V may hold others, e.g. inner hex vertices)
  for (int v = 0; v < n; ++v)
    if (!nb[v].empty()) vgrid.insert(v, V.row(v), V.row(v));
  auto nearest_vertex = [&](const Vec3& p) {
    int best = -1;
    double bd = corridor;
    vgrid.visit(p, corridor, [&](int v) {
      const double d = (V.row(v).transpose() - p).norm();
      if (d <= bd) {
        bd = d;
        best = v;
      }
    });
    return best;
  };
  auto is_locked = [&](int v) { return (!locked.empty() && locked[v]) || snapped[v]; };

  for (const Run& r : runs) {
    const int a = nearest_vertex(r.pl.front()), b = nearest_vertex(r.pl.back());
    if (a < 0 || b < 0 || a == b) continue;
    // Dijkstra through the corridor: length plus twice the distances to the crease.
    std::unordered_map<int, double> dist_to_run, best;
    std::unordered_map<int, int> from;
    auto crease_distance = [&](int v) {
      const auto it = dist_to_run.find(v);
      if (it != dist_to_run.end()) return it->second;
      const double d = polyline_distance(r.pl, r.arc, V.row(v).transpose());
      dist_to_run[v] = d;
      return d;
    };
    using Item = std::pair<double, int>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> pq;
    best[a] = 0;
    pq.push({0, a});
    while (!pq.empty()) {
      const auto [d, v] = pq.top();
      pq.pop();
      if (d > best[v]) continue;
      if (v == b) break;
      for (int u : nb[v]) {
        if (u != b && (is_locked(u) || crease_distance(u) > corridor)) continue;
        const double w = (V.row(u) - V.row(v)).norm() + 2 * (crease_distance(u) + crease_distance(v));
        const auto it = best.find(u);
        if (it == best.end() || d + w < it->second) {
          best[u] = d + w;
          from[u] = v;
          pq.push({d + w, u});
        }
      }
    }
    if (!best.count(b)) continue;
    std::vector<int> path{b};
    while (path.back() != a) path.push_back(from[path.back()]);
    std::reverse(path.begin(), path.end());
    // Targets in order along the run; locked vertices (only the ends can be) stay.
    std::vector<Vec3> target(path.size());
    std::vector<int> moved;
    double last = -1e300;
    bool ok = true;
    for (size_t i = 0; i < path.size() && ok; ++i) {
      if (is_locked(path[i])) continue;
      double sarc = 0;
      polyline_distance(r.pl, r.arc, V.row(path[i]).transpose(), &sarc, &target[i]);
      if (!(sarc > last + 1e-9 * elen)) ok = false;
      last = sarc;
      moved.push_back(static_cast<int>(i));
    }
    if (!ok || moved.empty()) continue;
    for (int i : moved) V.row(path[i]) = target[i].transpose();
    ++st.captured;
    std::vector<int> ids;
    for (int i : moved) {
      snapped[path[i]] = 1;
      ids.push_back(path[i]);
      ++st.moved;
    }
    st.captured_runs.push_back({std::move(ids), r.pl});
  }

  return st;
}

CreaseCoverage crease_coverage(const MatX3d& V, const MatX4i& Q, const SurfaceMesh& s,
                               const std::vector<unsigned char>& sharp, double tolerance) {
  CreaseCoverage c;
  const std::vector<std::array<int, 2>> edges = quad_edges(Q, static_cast<int>(V.rows()), nullptr);
  const double elen = mean_length(V, edges);
  if (!(elen > 0)) return c;
  const BucketGrid g = edge_grid(V, edges, elen);
  int samples = 0, near = 0;
  for (const std::vector<int>& chain : sharp_chains(s, sharp))
    for (const auto& [p, t] : chain_samples(s, chain, 0.25 * elen)) {
      const double d = edge_distance(g, V, edges, p, t, 2 * elen);
      c.max_gap = std::max(c.max_gap, d);
      ++samples;
      near += d <= tolerance * elen;
    }
  c.followed = samples > 0 ? static_cast<double>(near) / samples : 1.0;
  return c;
}

}  // namespace polycube::geometry

