#include "polycube/hex/optimize.h"

#include <algorithm>
#include <cmath>

#include "polycube/hex/quality.h"

namespace polycube::hex {

namespace {

constexpr double kSoftMin = 10;  // sharpness of the soft minimum sum exp(-k sj)
// Vertices of hexes below this scaled Jacobian may leave their patch (block: min 0.12 -> 0.58).
constexpr double kCrossPatchBelow = 0.3;
// The edge-ratio guard (max_edge_ratio) holds for vertices whose worst hex is at least this scaled
// Jacobian: the others are repaired first.
constexpr double kGuardAbove = 0.5;

void sort_unique(std::vector<std::vector<int>>& lists) {
  for (auto& l : lists) {
    std::sort(l.begin(), l.end());
    l.erase(std::unique(l.begin(), l.end()), l.end());
  }
}

}  // namespace

OptimizeStats optimize_hexes(MatX3d& V, const MatX8i& H, const std::vector<char>& fixed,
                             const std::vector<std::array<int, 2>>& slide, const geometry::TriangleTree* surface,
                             const std::vector<int>* surface_patch, int sweeps, double optimize_below,
                             double max_edge_ratio, const Hooks& hooks) {
  OptimizeStats st;
  const int n = static_cast<int>(V.rows());
  std::vector<std::vector<int>> nb(n), bnb(n), vq(n);
  std::vector<std::vector<std::pair<int, int>>> vhj(n);  // per vertex: (hex, its corner index)
  for (int h = 0; h < H.rows(); ++h) {
    for (int i = 0; i < 8; ++i) vhj[H(h, i)].push_back({h, i});
    for (const auto& e : kHexEdges) {
      nb[H(h, e[0])].push_back(H(h, e[1]));
      nb[H(h, e[1])].push_back(H(h, e[0]));
    }
  }
  const MatX4i Q = boundary_quads(H);
  std::vector<char> boundary(n, 0);
  for (int q = 0; q < Q.rows(); ++q)
    for (int j = 0; j < 4; ++j) {
      boundary[Q(q, j)] = 1;
      vq[Q(q, j)].push_back(q);
      bnb[Q(q, j)].push_back(Q(q, (j + 1) % 4));
      bnb[Q(q, (j + 1) % 4)].push_back(Q(q, j));
    }
  sort_unique(nb);
  sort_unique(bnb);
  std::vector<char> movable(n, 0);
  for (int v = 0; v < n; ++v)
    movable[v] = !(v < static_cast<int>(fixed.size()) && fixed[v]) && !(boundary[v] && !surface) && !vhj[v].empty();

  // Per hex at the current positions: its scaled Jacobian samples, their soft-min terms
  // exp(-k sj) and its worst sample. The objective at a vertex's current position is read from
  // them, and at a trial position only the samples that depend on the vertex (5 of 9) are
  // computed again; the terms are summed in the same order either way, so the result has the
  // same bits as computing every sample. Updated for the hexes of every vertex moved.
  std::vector<std::array<double, 9>> samples(H.rows()), terms(H.rows());
  std::vector<double> hex_worst(H.rows());
  unsigned dependents[8];
  for (int j = 0; j < 8; ++j) dependents[j] = scaled_jacobian_dependents(j);
  auto corners = [&](int h, std::array<Vec3, 8>& c) {
    for (int i = 0; i < 8; ++i) c[i] = V.row(H(h, i)).transpose();
  };
  auto set_worst = [&](int h) {
    double w = 1e300;
    for (double x : samples[h]) w = std::min(w, x);
    hex_worst[h] = w;
  };
  auto refresh = [&](int h) {
    std::array<Vec3, 8> c;
    corners(h, c);
    samples[h] = scaled_jacobian_samples(c);
    for (int i = 0; i < 9; ++i) terms[h][i] = std::exp(-kSoftMin * samples[h][i]);
    set_worst(h);
  };
  for (int h = 0; h < H.rows(); ++h) refresh(h);
  // The last trial (eval's v and p) and the samples and terms it computed, per hex of v: a move
  // to that trial position takes them instead of computing them again.
  int trial_v = -1;
  Vec3 trial_p = Vec3::Zero();
  bool trial_terms_set = false;
  std::vector<std::array<double, 9>> trial_samples, trial_terms;
  // The trial's soft-min terms, from its samples (the same arithmetic as in eval).
  auto set_trial_terms = [&] {
    for (size_t e = 0; e < vhj[trial_v].size(); ++e) {
      const auto [h, j] = vhj[trial_v][e];
      const unsigned dep = dependents[j];
      for (int k = 0; k < 9; ++k)
        trial_terms[e][k] = dep >> k & 1u ? std::exp(-kSoftMin * trial_samples[e][k]) : terms[h][k];
    }
    trial_terms_set = true;
  };
  // Soft-min objective and worst scaled Jacobian of v's hexes with v at p. With !with_sum only the
  // worst is computed (the smart Laplacian reads nothing else): the exponentials are left to a move,
  // and the evaluation stops as soon as the worst is below `floor` (the trial is then forgotten).
  auto eval = [&](int v, const Vec3& p, double& worst, bool with_sum = true, double floor = -1e300) {
    worst = 1e300;
    trial_v = v;
    trial_p = p;
    trial_samples.resize(vhj[v].size());
    trial_terms.resize(vhj[v].size());
    for (size_t e = 0; e < vhj[v].size(); ++e) {
      const auto [h, j] = vhj[v][e];
      std::array<Vec3, 8> c;
      corners(h, c);
      c[j] = p;
      const unsigned dep = dependents[j];
      for (int k = 0; k < 9; ++k) {
        trial_samples[e][k] = dep >> k & 1u ? scaled_jacobian_sample(c, k) : samples[h][k];
        worst = std::min(worst, trial_samples[e][k]);
      }
      if (!with_sum && worst < floor) {
        trial_v = -1;
        return 0.0;
      }
    }
    trial_terms_set = false;
    if (!with_sum) return 0.0;
    set_trial_terms();
    double sum = 0;
    for (size_t e = 0; e < vhj[v].size(); ++e)
      for (int k = 0; k < 9; ++k) sum += trial_terms[e][k];
    return sum;
  };
  auto eval_here = [&](int v, double& worst) {
    double sum = 0;
    worst = 1e300;
    for (const auto& [h, j] : vhj[v]) {
      worst = std::min(worst, hex_worst[h]);
      for (double t : terms[h]) sum += t;
    }
    return sum;
  };
  // Edge ratio of hex h with its corner j at p.
  auto edge_ratio_at = [&](int h, int j, const Vec3& p) {
    double len[12];
    for (int i = 0; i < 12; ++i) {
      const auto& e = kHexEdges[i];
      const Vec3 a = e[0] == j ? p : Vec3(V.row(H(h, e[0])).transpose());
      const Vec3 b = e[1] == j ? p : Vec3(V.row(H(h, e[1])).transpose());
      len[i] = (a - b).norm();
    }
    return edge_ratio(len, 12);
  };
  // Per hex, its edge ratio at the current positions (for the edge-ratio guard; kept up to date by
  // `move`).
  std::vector<double> hex_ratio(max_edge_ratio > 0 ? H.rows() : 0);
  for (int h = 0; h < static_cast<int>(hex_ratio.size()); ++h)
    hex_ratio[h] = edge_ratio_at(h, 0, V.row(H(h, 0)).transpose());
  auto move = [&](int v, const Vec3& p) {
    V.row(v) = p.transpose();
    if (!hex_ratio.empty())
      for (const auto& [h, j] : vhj[v]) hex_ratio[h] = edge_ratio_at(h, j, p);
    if (trial_v != v || trial_p != p) {
      for (const auto& [h, j] : vhj[v]) refresh(h);
      return;
    }
    if (!trial_terms_set) set_trial_terms();
    for (size_t e = 0; e < vhj[v].size(); ++e) {
      const int h = vhj[v][e].first;
      samples[h] = trial_samples[e];
      terms[h] = trial_terms[e];
      set_worst(h);
    }
  };
  // Edge-ratio guard (the scaled Jacobian is 1 on a box however thin): a move may not take a hex
  // of v above max_edge_ratio (longest over shortest edge) unless it lowers that hex's ratio.
  auto thins = [&](int v, const Vec3& p) {
    if (!(max_edge_ratio > 0)) return false;
    for (const auto& [h, j] : vhj[v]) {
      const double after = edge_ratio_at(h, j, p);
      if (after > max_edge_ratio && after > hex_ratio[h]) return true;
    }
    return false;
  };
  // The largest edge ratio of v's hexes with v at p, and at its current position.
  auto max_ratio = [&](int v, const Vec3& p) {
    double m = 0;
    for (const auto& [h, j] : vhj[v]) m = std::max(m, edge_ratio_at(h, j, p));
    return m;
  };
  auto max_ratio_here = [&](int v) {
    double m = 0;
    for (const auto& [h, j] : vhj[v]) m = std::max(m, hex_ratio[h]);
    return m;
  };
  // Patch of every boundary vertex: that of its closest surface triangle at the start.
  std::vector<int> patch(n, -1);
  if (surface && surface_patch)
    for (int v = 0; v < n; ++v)
      if (boundary[v]) patch[v] = (*surface_patch)[surface->closest(V.row(v).transpose()).face];
  // Outward normal of boundary vertex v: sum of its boundary quads' vector areas.
  auto vertex_normal = [&](int v) {
    Vec3 nrm = Vec3::Zero();
    for (int q : vq[v]) {
      const Vec3 a = V.row(Q(q, 0)), b = V.row(Q(q, 1)), c = V.row(Q(q, 2)), d = V.row(Q(q, 3));
      nrm += (c - a).cross(d - b);
    }
    return nrm;
  };
  // Feature curves: the polyline through the positions at the call.
  const MatX3d V0 = V;
  auto on_curve = [&](int v) {
    return v < static_cast<int>(slide.size()) && slide[v][0] >= 0 && slide[v][1] >= 0;
  };
  auto place = [&](int v, Vec3 p, bool any_patch = false) {
    if (on_curve(v)) {
      const Vec3 x0 = V0.row(v).transpose();
      Vec3 best = x0;
      double bd = 1e300;
      for (int e : slide[v]) {
        const Vec3 a = V0.row(e).transpose(), ab = x0 - a;
        const double t = ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 1.0;
        const Vec3 q = a + t * ab;
        if ((q - p).squaredNorm() < bd) {
          bd = (q - p).squaredNorm();
          best = q;
        }
      }
      p = best;
    }
    if (!boundary[v]) return p;
    const Vec3 n = vertex_normal(v);
    if (any_patch) {
      const geometry::ClosestHit hit = surface->closest(p, &n);
      if (surface_patch) patch[v] = (*surface_patch)[hit.face];
      return hit.point;
    }
    return surface->closest(p, &n, surface_patch, patch[v]).point;
  };

  for (int sweep = 0; sweep < sweeps; ++sweep) {
    hooks.report("hex", 0.7 + 0.3 * sweep / sweeps);
    ++st.sweeps;
    int moves = 0;
    // 1. smart Laplacian
    for (int v = 0; v < n; ++v) {
      if (!movable[v]) continue;
      std::vector<int> curve_ring;
      if (on_curve(v)) curve_ring = {slide[v][0], slide[v][1]};
      const auto& ring = on_curve(v) ? curve_ring : boundary[v] ? bnb[v] : nb[v];
      if (ring.empty()) continue;
      Vec3 c = Vec3::Zero();
      for (int u : ring) c += V.row(u).transpose();
      c /= static_cast<double>(ring.size());
      const Vec3 x = V.row(v).transpose();
      double before, after;
      eval_here(v, before);
      // A sliver's vertex (a hex above max_edge_ratio) also takes a move that lowers the largest
      // ratio of its hexes by 10%+ while its worst hex stays at kGuardAbove (or where it was).
      const double ratio_before = max_edge_ratio > 0 ? max_ratio_here(v) : 0;
      const bool sliver = max_edge_ratio > 0 && ratio_before > max_edge_ratio;
      const double floor = sliver ? std::min(before, kGuardAbove) : before;
      for (double t : {1.0, 0.5, 0.25}) {
        const Vec3 p = place(v, x + t * (c - x));
        eval(v, p, after, false, floor);  // below `floor`: refused, whatever the rest
        if (((after > before + 1e-9 || (after >= before && after > 0.3)) && (before < kGuardAbove || !thins(v, p))) ||
            (sliver && after >= floor && max_ratio(v, p) < 0.9 * ratio_before)) {
          move(v, p);
          ++moves;
          ++st.laplacian_moves;
          break;
        }
      }
    }
    // 2. optimization of the vertices of poor hexes
    for (int v = 0; v < n; ++v) {
      if (!movable[v]) continue;
      const Vec3 x = V.row(v).transpose();
      double m0;
      const double f0 = eval_here(v, m0);
      if (m0 >= optimize_below) continue;
      double len = 0;
      for (int u : nb[v]) len += (V.row(u).transpose() - x).norm();
      len /= std::max<size_t>(1, nb[v].size());
      if (!(len > 0)) continue;
      // Gradient of the soft minimum: sum over the dependent samples of -k exp(-k sj) grad sj.
      Vec3 g = Vec3::Zero();
      for (const auto& [hx, j] : vhj[v]) {
        std::array<Vec3, 8> c;
        corners(hx, c);
        const unsigned dep = dependents[j];
        for (int k = 0; k < 9; ++k) {
          if (!(dep >> k & 1u)) continue;
          Vec3 gk;
          scaled_jacobian_sample_gradient(c, k, j, gk);
          g -= kSoftMin * terms[hx][k] * gk;
        }
      }
      if (boundary[v]) {
        Vec3 nrm = vertex_normal(v);
        if (nrm.norm() > 0) nrm.normalize();
        g -= g.dot(nrm) * nrm;
      }
      if (!(g.norm() > 0)) continue;
      const Vec3 d = -g.normalized();
      double step = 0.3 * len;
      for (int tries = 0; tries < 10; ++tries, step *= 0.5) {
        // A vertex of a poor hex may cross a sharp edge of the surface (to another patch) when
        // the polycube does not put a hex edge there.
        const Vec3 p = place(v, x + step * d, m0 < kCrossPatchBelow);
        double m;
        const double f = eval(v, p, m);
        if ((m > m0 + 1e-9 || (f < f0 && m >= m0)) && (m0 < kGuardAbove || !thins(v, p))) {
          move(v, p);
          ++moves;
          ++st.optimized_moves;
          break;
        }
      }
    }
    if (hooks.log) {
      double lo = 1e300, sum = 0;
      for (double w : hex_worst) lo = std::min(lo, w), sum += w;
      hooks.debug("hex optimization sweep " + std::to_string(sweep) + ": " + std::to_string(moves) +
                  " moves, worst sample min " + std::to_string(lo) + " mean " +
                  std::to_string(sum / std::max<Eigen::Index>(1, H.rows())));
    }
    if (moves == 0) break;
  }
  return st;
}

}  // namespace polycube::hex
