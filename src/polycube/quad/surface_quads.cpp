// Quads from an exact surface polycube (surface mode): see quad.h.
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/deform/energies.h"
#include "polycube/hex/snap.h"
#include "polycube/quad/quad.h"

namespace polycube::quad {

namespace {

// Per-axis piecewise-linear map: sorted heights h_i -> integers n_i, slope s outside.
struct AxisMap {
  std::vector<double> h;
  std::vector<int> n;
  double s = 1;
  const hex::AxisWarp* warp = nullptr;  ///< graded grid: h are warped heights, x is warped first
  double operator()(double x) const { return warp ? snapped((*warp)(x)) : snapped(x); }
  double inverse(double y) const { return warp ? warp->inverse(unsnapped(y)) : unsnapped(y); }
  double snapped(double x) const {
    if (h.empty()) return s * x;
    if (x <= h.front()) return n.front() + s * (x - h.front());
    if (x >= h.back()) return n.back() + s * (x - h.back());
    const size_t i = static_cast<size_t>(std::upper_bound(h.begin(), h.end(), x) - h.begin()) - 1;
    if (x == h[i]) return n[i];
    return n[i] + (x - h[i]) / (h[i + 1] - h[i]) * (n[i + 1] - n[i]);
  }
  /// The inverse (n is non-decreasing; where merged heights share an integer, it gives the highest
  /// of them, the map being constant between them).
  double unsnapped(double y) const {
    if (h.empty()) return y / s;
    if (y <= n.front()) return h.front() + (y - n.front()) / s;
    if (y >= n.back()) return h.back() + (y - n.back()) / s;
    const size_t i = static_cast<size_t>(std::upper_bound(n.begin(), n.end(), y) - n.begin()) - 1;
    if (y == n[i]) return h[i];
    return h[i] + (y - n[i]) / (n[i + 1] - n[i]) * (h[i + 1] - h[i]);
  }
};

}  // namespace

QuadResult quad_mesh_from_surface_polycube(const MatX3d& rest, const MatX3i& F, const MatX3d& X,
                                           const std::vector<int>& labels, double cells_per_unit,
                                           const SurfaceMesh& target, const QuadOptions& opt, const Hooks& hooks) {
  Stopwatch sw;
  POLYCUBE_ASSERT(cells_per_unit > 0, "cells_per_unit must be positive");
  POLYCUBE_ASSERT(static_cast<Eigen::Index>(labels.size()) == F.rows(), "one label per triangle");
  QuadResult r;
  r.cells_per_unit = cells_per_unit;
  const double diag = (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
  const double tol = 1e-9 * diag;

  // ---- planes: chart heights, and coordinates shared along border edges ----
  std::array<std::vector<double>, 3> raw;
  for (int f = 0; f < F.rows(); ++f) raw[labels[f] / 2].push_back(X(F(f, 0), labels[f] / 2));
  const auto loops = border_loops(F);
  for (const auto& loop : loops)
    for (const auto& e : loop)
      for (int m = 0; m < 3; ++m)
        if (X(e[0], m) == X(e[1], m)) raw[m].push_back(X(e[0], m));
  std::array<AxisMap, 3> map;
  // Graded rows (QuadOptions::grading): heights are snapped in the warped polycube.
  hex::Grading graded;
  if (opt.grading.strength > 0) {
    hex::GradingOptions go = opt.grading;
    go.sharp_angle_deg = opt.sharp_angle_deg;
    graded = hex::grade_polycube(rest, MatX4i(0, 4), X, F, labels, cells_per_unit, go);
    for (int k = 0; k < 3; ++k) {
      map[k].warp = &graded.warp[k];
      r.grading_min[k] = graded.min_slope[k];
      r.grading_max[k] = graded.max_slope[k];
    }
  }
  for (int k = 0; k < 3; ++k) {
    std::sort(raw[k].begin(), raw[k].end());
    std::vector<double> h;
    for (double x : raw[k])
      if (h.empty() || x - h.back() > tol) h.push_back(x);
    std::vector<double> hw = h;  // in the warped polycube
    if (map[k].warp)
      for (double& x : hw) x = (*map[k].warp)(x);
    map[k].h = hw;
    map[k].s = cells_per_unit;
    r.planes[k] = static_cast<int>(h.size());
    // Thin steps (QuadOptions::merge_thin_steps): runs of consecutive planes spanning less than
    // that many cells, no two of which face each other, share one integer (the per-axis map is
    // then constant between them: their risers lose their height). Closed surfaces only (the
    // border lines of an open one are heights too).
    const double merge = loops.empty() ? opt.merge_thin_steps : 0;
    const std::vector<std::vector<int>> facing =
        merge > 0 ? hex::facing_planes(X, F, labels, k, h, tol) : std::vector<std::vector<int>>(h.size());
    std::vector<double> hg;
    const std::vector<int> group = hex::thin_step_groups(hw, cells_per_unit, merge, facing, hg);
    r.merged_planes += static_cast<int>(h.size() - hg.size());
    const std::vector<int> ng = hex::snap_heights(hg, cells_per_unit);
    map[k].n.resize(h.size());
    for (size_t i = 0; i < h.size(); ++i) map[k].n[i] = ng[group[i]];
  }
  MatX3d Y(X.rows(), 3);
  for (int v = 0; v < X.rows(); ++v)
    for (int k = 0; k < 3; ++k) Y(v, k) = map[k](X(v, k));
  for (int k = 0; k < 3; ++k)
    r.cells[k] = static_cast<int>(std::lround(Y.col(k).maxCoeff() - Y.col(k).minCoeff()));

  // ---- grid points and unit squares of every chart ----
  // Located in the polycube itself (X), through the inverse of the per-axis maps: the maps are
  // monotone per axis but not affine, so the image of a sliver triangle (Y) can come out folded
  // (spot.obj: one polycube triangle of max isometric distortion 1e4 did, and a grid point was
  // then in no triangle), while X is fold-free.
  // Keyed by the surface's connected component too: the polycubes of separate components may
  // overlap (two overlapping spheres, each its own cube), and a grid point of one at the same
  // integers as the other's would be taken for it (basic/two_spheres: quads stretched across
  // both, Hausdorff 0.12 of the diagonal).
  std::vector<int> component(F.rows());
  {
    UnionFind uf(static_cast<size_t>(X.rows()));
    for (int f = 0; f < F.rows(); ++f) uf.unite(F(f, 0), F(f, 1)), uf.unite(F(f, 0), F(f, 2));
    for (int f = 0; f < F.rows(); ++f) component[f] = uf.find(F(f, 0));
  }
  std::map<std::array<int, 4>, int> vid;  // (component, x, y, z)
  std::vector<Vec3> pos;
  std::set<std::array<int, 5>> cells;  // (component, label, plane integer, i, j)
  for (int f = 0; f < F.rows(); ++f) {
    const int k = labels[f] / 2, a = (k + 1) % 3, b = (k + 2) % 3;
    const int c = static_cast<int>(std::lround(Y(F(f, 0), k)));
    Eigen::Vector2d p[3];
    for (int j = 0; j < 3; ++j) p[j] = Eigen::Vector2d(X(F(f, j), a), X(F(f, j), b));
    const double A = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
    if (!(std::abs(A) > 0)) continue;  // no area in the chart: holds no grid point of its own
    double edge_len[3];  // length of the edge opposite each vertex
    for (int t = 0; t < 3; ++t) edge_len[t] = (p[(t + 2) % 3] - p[(t + 1) % 3]).norm();
    auto bary = [&](const Eigen::Vector2d& q) {
      Eigen::Vector3d l;
      for (int j = 0; j < 3; ++j) {
        const Eigen::Vector2d u = p[(j + 1) % 3] - q, w = p[(j + 2) % 3] - q;
        l[j] = (u.x() * w.y() - u.y() * w.x()) / A;
      }
      return l;
    };
    // Inside up to tol from each edge (a distance, not a barycentric tolerance, which slivers
    // would blow up).
    auto inside = [&](const Eigen::Vector3d& l) {
      for (int t = 0; t < 3; ++t)
        if (l[t] * std::abs(A) / std::max(edge_len[t], 1e-300) < -tol) return false;
      return true;
    };
    auto at = [&](double i, double j) { return Eigen::Vector2d(map[a].inverse(i), map[b].inverse(j)); };
    const double eps = 1e-9;
    double lo_a = Y(F(f, 0), a), hi_a = lo_a, lo_b = Y(F(f, 0), b), hi_b = lo_b;
    for (int j = 1; j < 3; ++j) {
      lo_a = std::min(lo_a, Y(F(f, j), a)), hi_a = std::max(hi_a, Y(F(f, j), a));
      lo_b = std::min(lo_b, Y(F(f, j), b)), hi_b = std::max(hi_b, Y(F(f, j), b));
    }
    for (int i = static_cast<int>(std::ceil(lo_a - eps)); i <= static_cast<int>(std::floor(hi_a + eps)); ++i)
      for (int j = static_cast<int>(std::ceil(lo_b - eps)); j <= static_cast<int>(std::floor(hi_b + eps)); ++j) {
        Eigen::Vector3d l = bary(at(i, j));
        if (!inside(l)) continue;
        std::array<int, 4> key;
        key[0] = component[f];
        key[1 + k] = c;
        key[1 + a] = i;
        key[1 + b] = j;
        if (vid.count(key)) continue;
        l = l.cwiseMax(0.0);
        l /= l.sum();
        Vec3 x = Vec3::Zero();
        for (int t = 0; t < 3; ++t) x += l[t] * rest.row(F(f, t)).transpose();
        vid.emplace(key, static_cast<int>(pos.size()));
        pos.push_back(x);
      }
    for (int i = static_cast<int>(std::floor(lo_a)); i < static_cast<int>(std::ceil(hi_a)); ++i)
      for (int j = static_cast<int>(std::floor(lo_b)); j < static_cast<int>(std::ceil(hi_b)); ++j)
        if (inside(bary(at(i + 0.5, j + 0.5)))) cells.insert({component[f], labels[f], c, i, j});
  }
  r.V.resize(static_cast<Eigen::Index>(pos.size()), 3);
  for (size_t v = 0; v < pos.size(); ++v) r.V.row(static_cast<Eigen::Index>(v)) = pos[v].transpose();
  std::vector<std::array<int, 4>> quads;
  int missing = 0;
  for (const auto& [comp, label, c, i, j] : cells) {
    const int k = label / 2, a = (k + 1) % 3, b = (k + 2) % 3;
    const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 0, 1, 1};
    std::array<int, 4> q;
    bool ok = true;
    for (int t = 0; t < 4 && ok; ++t) {
      std::array<int, 4> key;
      key[0] = comp;
      key[1 + k] = c;
      key[1 + a] = i + di[t];
      key[1 + b] = j + dj[t];
      const auto it = vid.find(key);
      ok = it != vid.end();
      if (ok) q[t] = it->second;
    }
    if (!ok) {
      if (++missing <= 5)
        hooks.debug("grid square (label " + std::to_string(label) + ", plane " + std::to_string(c) + ", " +
                    std::to_string(i) + ", " + std::to_string(j) + ") misses a corner");
      continue;
    }
    if (label % 2) std::swap(q[1], q[3]);  // -k: clockwise in (a, b) is counter-clockwise seen from -k
    quads.push_back(q);
  }
  if (missing > 0 && r.merged_planes > 0 && opt.unmerge_on_missing_corners) {
    // A merged step whose riser was not thin everywhere (the planes' points no longer match):
    // every plane keeps its cell instead.
    hooks.debug(std::to_string(missing) + " grid squares miss a corner with " + std::to_string(r.merged_planes) +
                " planes of thin steps merged: extracting again without merging");
    QuadOptions o = opt;
    o.merge_thin_steps = 0;
    return quad_mesh_from_surface_polycube(rest, F, X, labels, cells_per_unit, target, o, hooks);
  }
  if (missing > 0)
    throw Error(ErrorKind::Polycube, std::to_string(missing) + " grid squares of the surface polycube miss a corner" +
                                         (r.merged_planes > 0 ? " with " + std::to_string(r.merged_planes) +
                                                                    " planes of thin steps merged"
                                                              : std::string()));
  r.Q.resize(static_cast<Eigen::Index>(quads.size()), 4);
  for (size_t q = 0; q < quads.size(); ++q)
    for (int t = 0; t < 4; ++t) r.Q(static_cast<Eigen::Index>(q), t) = quads[q][t];
  // Unused grid points (a chart's point no square uses cannot occur on a valid polycube; keep the
  // mesh clean anyway).
  {
    std::vector<int> used(r.V.rows(), -1);
    int n = 0;
    for (int q = 0; q < r.Q.rows(); ++q)
      for (int t = 0; t < 4; ++t)
        if (used[r.Q(q, t)] < 0) used[r.Q(q, t)] = n++;
    MatX3d V2(n, 3);
    for (int v = 0; v < r.V.rows(); ++v)
      if (used[v] >= 0) V2.row(used[v]) = r.V.row(v);
    for (int q = 0; q < r.Q.rows(); ++q)
      for (int t = 0; t < 4; ++t) r.Q(q, t) = used[r.Q(q, t)];
    r.V = std::move(V2);
  }

  // ---- border: quad edges used once stay on the input border ----
  std::map<std::pair<int, int>, int> edge_use;
  for (int q = 0; q < r.Q.rows(); ++q)
    for (int t = 0; t < 4; ++t) {
      const int u = r.Q(q, t), w = r.Q(q, (t + 1) % 4);
      edge_use[{std::min(u, w), std::max(u, w)}]++;
    }
  std::vector<char> pinned(r.V.rows(), 0);
  std::vector<std::vector<int>> bnb(r.V.rows());
  for (const auto& [e, cnt] : edge_use)
    if (cnt == 1) {
      pinned[e.first] = pinned[e.second] = 1;
      bnb[e.first].push_back(e.second);
      bnb[e.second].push_back(e.first);
    }
  for (char p : pinned) r.border_vertices += p;
  {
    std::vector<char> seen(r.V.rows(), 0);
    for (int v = 0; v < r.V.rows(); ++v) {
      if (!pinned[v] || seen[v]) continue;
      ++r.border_loops;
      std::vector<int> stack{v};
      seen[v] = 1;
      while (!stack.empty()) {
        const int u = stack.back();
        stack.pop_back();
        for (int w : bnb[u])
          if (!seen[w]) seen[w] = 1, stack.push_back(w);
      }
    }
  }
  hooks.debug("surface quads: " + std::to_string(r.Q.rows()) + " quads, " + std::to_string(r.V.rows()) +
              " vertices, planes " + std::to_string(r.planes[0]) + "/" + std::to_string(r.planes[1]) + "/" +
              std::to_string(r.planes[2]) + ", " + std::to_string(r.border_vertices) + " border vertices");
  smooth_on_surface(r, target, opt, hooks, loops.empty() ? std::vector<char>{} : pinned);
  r.seconds = sw.seconds();
  return r;
}

bool better_quads(const QuadQuality& a, double ha, const QuadQuality& b, double hb) {
  if (a.inverted != b.inverted) return b.inverted < a.inverted;
  // Slivers (edge ratio over hex::kSliverEdgeRatio, nearly degenerate): fewer win unless they are
  // more than kSliverDistanceSlack x farther from the surface (a layout that lost a part).
  constexpr double kSliverDistanceSlack = 1.5;
  const int sa = a.edge_ratio_above_100, sb = b.edge_ratio_above_100;
  if (sb < sa && hb <= kSliverDistanceSlack * ha) return true;
  if (sa < sb && ha <= kSliverDistanceSlack * hb) return false;
  return hb < 0.98 * ha && b.sj_min >= 0.9 * a.sj_min && b.sj_mean >= a.sj_mean - 0.02;
}

bool fewer_sliver_quads(const QuadQuality& a, double ha, const QuadQuality& b, double hb, double slack) {
  if (a.inverted != b.inverted) return b.inverted < a.inverted;
  return b.edge_ratio_above_10 < a.edge_ratio_above_10 && b.edge_ratio_max < a.edge_ratio_max &&
         b.sj_min >= 0.9 * a.sj_min && hb <= ha + std::max(0.1 * ha, slack);
}

namespace {
double mean_edge(const QuadResult& q) {
  double sum = 0;
  for (int f = 0; f < q.Q.rows(); ++f)
    for (int t = 0; t < 4; ++t) sum += (q.V.row(q.Q(f, t)) - q.V.row(q.Q(f, (t + 1) % 4))).norm();
  return q.Q.rows() > 0 ? sum / (4.0 * static_cast<double>(q.Q.rows())) : 0.0;
}
}  // namespace

std::vector<StartQuads> surface_quads_best_start(const chart::PolycubeExtraction& e, const MatX3d& rest,
                                                 const MatX3i& B, int target_quads, const SurfaceMesh& target,
                                                 const QuadOptions& opt, const Hooks& hooks) {
  if (!e.realized.success) throw Error(ErrorKind::Internal, "surface_quads_best_start: the polycube was not realized");
  if (target_quads <= 0) throw Error(ErrorKind::Usage, "surface_quads_best_start: the quad count must be positive");
  std::vector<const chart::PolycubeExtraction*> polycubes{&e};
  if (opt.compare_starts && e.alternative && e.alternative->realized.success) polycubes.push_back(e.alternative.get());
  std::vector<StartQuads> out;
  const double diag = (target.V.colwise().maxCoeff() - target.V.colwise().minCoeff()).norm();
  auto relative = [&](double h) { return std::to_string(h / diag); };
  for (const chart::PolycubeExtraction* p : polycubes) {
    double l1 = 0, area = 0;
    deform::l1_measure(p->realized.X, B, l1, area);
    StartQuads s;
    s.start = p->realized.start;
    s.polycube_arap = p->realized.arap;
    s.alternative = p != &e;
    auto extract = [&](const QuadOptions& o, hex::Hausdorff& h) {
      QuadResult q = quad_mesh_from_surface_polycube(rest, p->map_triangles(B), p->realized.X,
                                                     p->map_triangle_labels(), std::sqrt(target_quads / area), target,
                                                     o, hooks);
      h = hex::hausdorff(q.V, hex::triangulate_quads(q.Q), target.V, target.F);
      return q;
    };
    s.quads = extract(opt, s.distance);
    // Slivers: rows of quads over a riser far thinner than a cell (or where the map crushes the
    // surface); merging thicker steps removes the former. Slivers of the extracted grid count too:
    // the smoothing may have widened them (QuadOptions::widen_slivers) where the merge does better
    // (basic/eight: 0.668 / 0.947 after the widening alone, 0.761 / 0.953 with the merge, before
    // the shape pass; with it the unmerged quads have no sliver left and are kept: 0.693 / 0.966).
    auto slivers = [&] {
      return s.quads.quality.edge_ratio_above_100 > 0 || s.quads.extracted.edge_ratio_above_100 > 0;
    };
    for (const double thin : {0.05, 0.25}) {
      if (!opt.thin_step_retries || !slivers() || thin <= opt.merge_thin_steps) continue;
      QuadOptions o = opt;
      o.merge_thin_steps = thin;
      o.unmerge_on_missing_corners = false;
      QuadThinStepRetry t;
      t.thin_steps = thin;
      QuadResult q;
      hex::Hausdorff d;
      try {
        q = extract(o, d);
      } catch (const Error& err) {
        if (err.kind() != ErrorKind::Polycube) throw;
        hooks.info("quads with steps under " + std::to_string(thin) + " cells merged: " + err.what() + "; not kept");
        t.merged_planes = -1;
        s.retries.push_back(t);
        break;  // thicker steps merged miss corners too
      }
      t.hausdorff = d.max;
      t.merged_planes = q.merged_planes;
      t.over_10 = q.quality.edge_ratio_above_10;
      t.ratio_max = q.quality.edge_ratio_max;
      t.sj_min = q.quality.sj_min;
      t.replaced = q.merged_planes > s.quads.merged_planes &&
                   fewer_sliver_quads(s.quads.quality, s.distance.max, q.quality, d.max, thin * mean_edge(q));
      hooks.info("quads with steps under " + std::to_string(thin) + " cells merged (" +
                 std::to_string(q.merged_planes) + " planes): edge ratio max " + std::to_string(t.ratio_max) + ", " +
                 std::to_string(t.over_10) + " over 10, scaled Jacobian min " + std::to_string(t.sj_min) +
                 ", Hausdorff " + relative(t.hausdorff) + (t.replaced ? ": kept" : ": not kept"));
      if (t.replaced) {
        s.quads = std::move(q);
        s.distance = d;
      }
      s.retries.push_back(t);
    }
    if (polycubes.size() > 1)
      hooks.info("quads from the " + s.start + " start's polycube (ARAP " + std::to_string(s.polycube_arap) +
                 "): " + std::to_string(s.quads.quality.count) + ", scaled Jacobian min " +
                 std::to_string(s.quads.quality.sj_min) + " mean " + std::to_string(s.quads.quality.sj_mean) +
                 ", Hausdorff " + relative(s.distance.max) + " of the bbox diagonal");
    out.push_back(std::move(s));
  }
  size_t best = 0;
  for (size_t i = 1; i < out.size(); ++i)
    if (better_quads(out[best].quads.quality, out[best].distance.max, out[i].quads.quality, out[i].distance.max))
      best = i;
  out[best].kept = true;
  return out;
}

}  // namespace polycube::quad
