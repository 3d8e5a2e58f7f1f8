#include "polycube/chart/labeling.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <sstream>
#include <unordered_map>

#include "polycube/core/topology.h"

namespace polycube::chart {

namespace {

int axis_of(int label) { return label / 2; }


double edge_length(const MatX3d& X, int a, int b) { return (X.row(a) - X.row(b)).norm(); }

constexpr int kMaxProblems = 20;

void add_problem(ChartReport& r, const std::string& s) {
  if (static_cast<int>(r.problems.size()) < kMaxProblems) r.problems.push_back(s);
}

}  // namespace

int label_of(const Vec3& n) {
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (std::abs(n[k]) > std::abs(n[axis])) axis = k;
  return 2 * axis + (n[axis] < 0 ? 1 : 0);
}

Vec3 label_direction(int label) {
  Vec3 d = Vec3::Zero();
  d[axis_of(label)] = label % 2 ? -1.0 : 1.0;
  return d;
}

const char* label_name(int label) {
  static const char* names[6] = {"+X", "-X", "+Y", "-Y", "+Z", "-Z"};
  return label >= 0 && label < 6 ? names[label] : "?";
}

std::vector<int> label_by_normal(const MatX3d& X, const MatX3i& F) {
  std::vector<int> l(F.rows());
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 a = X.row(F(f, 0)), b = X.row(F(f, 1)), c = X.row(F(f, 2));
    l[f] = label_of((b - a).cross(c - a));
  }
  return l;
}

Charts build_charts(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels) {
  const MatX3i N = face_adjacency(F);
  Charts c;
  c.of_face.assign(F.rows(), -1);
  std::vector<int> stack;
  for (int f0 = 0; f0 < F.rows(); ++f0) {
    if (c.of_face[f0] >= 0) continue;
    const int id = c.count();
    c.label.push_back(labels[f0]);
    c.faces.push_back(0);
    c.area.push_back(0);
    c.of_face[f0] = id;
    stack.assign(1, f0);
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      c.faces[id]++;
      const Vec3 a = X.row(F(f, 0)), b = X.row(F(f, 1)), cc = X.row(F(f, 2));
      c.area[id] += 0.5 * (b - a).cross(cc - a).norm();
      for (int k = 0; k < 3; ++k) {
        const int g = N(f, k);
        if (g >= 0 && c.of_face[g] < 0 && labels[g] == labels[f0]) {
          c.of_face[g] = id;
          stack.push_back(g);
        }
      }
    }
  }
  std::vector<std::map<int, double>> nb(c.count());
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int g = N(f, k);
      if (g < 0 || c.of_face[g] == c.of_face[f]) continue;
      nb[c.of_face[f]][c.of_face[g]] += edge_length(X, F(f, k), F(f, (k + 1) % 3));
    }
  c.neighbors.resize(c.count());
  for (int i = 0; i < c.count(); ++i) c.neighbors[i].assign(nb[i].begin(), nb[i].end());
  c.border_runs.assign(c.count(), 0);
  for (const auto& loop : border_loops(F)) {
    const size_t n = loop.size();
    bool one_chart = true;
    for (size_t i = 0; i < n; ++i) {
      const int here = c.of_face[loop[i][2]], before = c.of_face[loop[(i + n - 1) % n][2]];
      if (here != before) {
        c.border_runs[here]++;
        one_chart = false;
      }
    }
    if (one_chart && n > 0) c.border_runs[c.of_face[loop[0][2]]]++;
  }
  return c;
}

namespace {

// Step 1: zigzag straightening, until stable. Returns triangles relabelled.
int straighten(const MatX3i& N, std::vector<int>& labels) {
  int changed = 0;
  for (int pass = 0; pass < 100; ++pass) {
    int here = 0;
    for (int f = 0; f < N.rows(); ++f) {
      int l[3];
      for (int k = 0; k < 3; ++k) l[k] = N(f, k) >= 0 ? labels[N(f, k)] : -1;
      for (int k = 0; k < 3; ++k) {
        const int y = l[k];
        if (y < 0 || y == labels[f]) continue;
        if (y == l[(k + 1) % 3] || y == l[(k + 2) % 3]) {
          labels[f] = y;
          ++here;
          break;
        }
      }
    }
    changed += here;
    if (here == 0) break;
  }
  return changed;
}

// Per vertex: the charts of its triangles, each with how many of them it holds (its fan there).
std::vector<std::vector<std::pair<int, int>>> vertex_charts(const MatX3i& F, const Charts& c, int nv) {
  std::vector<std::vector<std::pair<int, int>>> vc(nv);
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      auto& v = vc[F(f, k)];
      auto it = std::find_if(v.begin(), v.end(), [&](const auto& p) { return p.first == c.of_face[f]; });
      if (it == v.end()) v.emplace_back(c.of_face[f], 1);
      else ++it->second;
    }
  return vc;
}

// Step 2: a triangle whose three vertices all touch one edge-adjacent chart of another axis.
int fix_degenerate(const MatX3d& X, const MatX3i& F, const MatX3i& N, std::vector<int>& labels) {
  const Charts c = build_charts(X, F, labels);
  const auto vcharts = vertex_charts(F, c, static_cast<int>(X.rows()));
  int changed = 0;
  for (int f = 0; f < F.rows(); ++f) {
    const int own = c.of_face[f];
    for (int k = 0; k < 3; ++k) {
      const int g = N(f, k);
      if (g < 0) continue;
      const int other = c.of_face[g];
      if (other == own || axis_of(c.label[other]) == axis_of(labels[f])) continue;
      bool all = true;
      for (int j = 0; j < 3 && all; ++j) {
        const auto& v = vcharts[F(f, j)];
        all = std::any_of(v.begin(), v.end(), [&](const auto& p) { return p.first == other; });
      }
      if (all) {
        labels[f] = c.label[other];
        ++changed;
        break;
      }
    }
  }
  return changed;
}

// Step 2b: a border vertex whose fan in a chart is one triangle, nearly flat there (angle over
// 150 degrees in X): on the polycube the chart's angle at that vertex is 180 (a straight border)
// or 270 degrees (a reflex corner), which one triangle cannot span, so the tets under it must
// invert (tet/hand: corner 4155 of a +X chart, 179.9 degrees). The triangle takes the label that
// most of its edge neighbours of other charts have.
int fix_wide_fans(const MatX3d& X, const MatX3i& F, const MatX3i& N, std::vector<int>& labels) {
  const Charts c = build_charts(X, F, labels);
  const auto vcharts = vertex_charts(F, c, static_cast<int>(X.rows()));
  auto fan = [&](int v, int chart) {
    for (const auto& [ch, count] : vcharts[v])
      if (ch == chart) return count;
    return 0;
  };
  const double wide = std::cos(150.0 * M_PI / 180.0);
  int changed = 0;
  for (int f = 0; f < F.rows(); ++f)
    for (int j = 0; j < 3; ++j) {
      const int v = F(f, j);
      if (vcharts[v].size() < 2 || fan(v, c.of_face[f]) != 1) continue;
      const Vec3 a = (X.row(F(f, (j + 1) % 3)) - X.row(v)).transpose();
      const Vec3 b = (X.row(F(f, (j + 2) % 3)) - X.row(v)).transpose();
      if (!(a.dot(b) < wide * a.norm() * b.norm())) continue;
      int votes[6] = {0, 0, 0, 0, 0, 0};
      for (int k = 0; k < 3; ++k)
        if (N(f, k) >= 0 && labels[N(f, k)] != labels[f]) votes[labels[N(f, k)]]++;
      const int best = static_cast<int>(std::max_element(votes, votes + 6) - votes);
      if (votes[best] == 0) continue;
      labels[f] = best;
      ++changed;
      break;
    }
  return changed;
}

// Step 4 for a large chart: opposite charts meet along a knife edge (a sheet folded flat, which
// surface mode's in-plane ARAP leaves unpenalized). Relabelling the whole smaller chart would
// remove a large part of the layout (and start a cascade of removals: humanoid in surface mode went
// from 34 charts to 1); instead its triangles at the meeting vertices form a rim, each taking the
// perpendicular label of the outward direction there (the sum, over the triangles around each
// meeting vertex, of centroid -> vertex, projected off the charts' axis). require_fold: only where
// both sides face their labels at the meeting vertices (otherwise the contact is a vertex or a
// mislabelled patch, and the caller decides). Returns the triangles relabelled.
using VertexCharts = std::vector<std::vector<std::pair<int, int>>>;  // vertex_charts

int open_rim(const MatX3d& X, const MatX3i& F, const Charts& c, const VertexCharts& vcharts, int small,
             bool require_fold, std::vector<int>& labels) {
  const int axis = axis_of(c.label[small]);
  const int nv = static_cast<int>(X.rows());
  std::vector<char> meeting(nv, 0);
  for (int v = 0; v < nv; ++v) {
    const auto& l = vcharts[v];
    const bool has_small = std::any_of(l.begin(), l.end(), [&](const auto& p) { return p.first == small; });
    const bool has_opposite =
        std::any_of(l.begin(), l.end(), [&](const auto& p) { return c.label[p.first] == (c.label[small] ^ 1); });
    meeting[v] = has_small && has_opposite;
  }
  // Only a fold: the triangles of both sides at the meeting vertices face their own labels (a
  // patch labelled against its normals, e.g. by an earlier step, is relabelled whole instead).
  Vec3 n_small = Vec3::Zero(), n_opposite = Vec3::Zero();
  for (int f = 0; f < F.rows(); ++f) {
    const int l = c.label[c.of_face[f]];
    if (l != c.label[small] && l != (c.label[small] ^ 1)) continue;
    if (!meeting[F(f, 0)] && !meeting[F(f, 1)] && !meeting[F(f, 2)]) continue;
    const Vec3 a = X.row(F(f, 0)), b = X.row(F(f, 1)), cc = X.row(F(f, 2));
    (c.of_face[f] == small ? n_small : n_opposite) += (b - a).cross(cc - a);
  }
  const double kFacing = 0.5;
  if (require_fold && (!(n_small.dot(label_direction(c.label[small])) > kFacing * n_small.norm()) ||
                       !(n_opposite.dot(label_direction(c.label[small] ^ 1)) > kFacing * n_opposite.norm())))
    return 0;
  std::vector<Vec3> out(nv, Vec3::Zero());
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 centroid = (X.row(F(f, 0)) + X.row(F(f, 1)) + X.row(F(f, 2))).transpose() / 3.0;
    for (int j = 0; j < 3; ++j)
      if (meeting[F(f, j)]) out[F(f, j)] += X.row(F(f, j)).transpose() - centroid;
  }
  int changed = 0;
  for (int f = 0; f < F.rows(); ++f) {
    if (c.of_face[f] != small) continue;
    Vec3 o = Vec3::Zero();
    for (int j = 0; j < 3; ++j)
      if (meeting[F(f, j)]) o += out[F(f, j)];
    o[axis] = 0;
    if (!(o.squaredNorm() > 0)) continue;
    labels[f] = label_of(o);
    ++changed;
  }
  return changed;
}

// Step 3 for a large chart of degree 2 or 3: two of its neighbours a and b have opposite labels
// and meet at its border, so the chart's side between them (along the third axis) has length zero;
// relabelling the chart whole removes a large part of the layout and starts a cascade (homer in
// surface mode: 111 charts down to 6). Instead the triangles of the three charts around the
// vertices where they meet, and of a and b along the rest of their contact from there, take the
// label of the third axis that points from the chart to the pinch (the sum, over the chart's triangles
// around it, of centroid -> vertex), opening the missing side. Returns the triangles relabelled
// (0: no such pair, or no direction).
int open_pinch(const MatX3d& X, const MatX3i& F, const Charts& c, const VertexCharts& vcharts, int chart,
               std::vector<int>& labels) {
  const int nv = static_cast<int>(X.rows());
  auto touches = [&](int v, int ch) {
    return std::any_of(vcharts[v].begin(), vcharts[v].end(), [&](const auto& p) { return p.first == ch; });
  };
  std::vector<std::vector<int>> adj;  // vertex -> next vertices around its triangles, built once if needed
  for (const auto& na : c.neighbors[chart])
    for (const auto& nb : c.neighbors[chart]) {
      const int a = na.first, b = nb.first;  // two neighbour charts
      if (!(a < b) || c.label[a] != (c.label[b] ^ 1)) continue;
      const int third = 3 - axis_of(c.label[chart]) - axis_of(c.label[a]);
      if (third < 0 || third > 2 || third == axis_of(c.label[chart])) continue;
      // The pinch: vertices of the chart where a and b meet; then the whole contact of a and b
      // that runs on from there (a and b may meet along edges beyond the chart: the missing side
      // must separate them there too, or it is left with three sides itself).
      std::vector<char> sel(nv, 0);
      std::vector<int> stack;
      for (int v = 0; v < nv; ++v)
        if (touches(v, chart) && touches(v, a) && touches(v, b)) {
          sel[v] = 1;
          stack.push_back(v);
        }
      if (stack.empty()) continue;
      const std::vector<char> at_pinch = sel;
      if (adj.empty()) {
        adj.resize(nv);
        for (int f = 0; f < F.rows(); ++f)
          for (int k = 0; k < 3; ++k) adj[F(f, k)].push_back(F(f, (k + 1) % 3));
      }
      while (!stack.empty()) {
        const int v = stack.back();
        stack.pop_back();
        for (int w : adj[v])
          if (!sel[w] && touches(w, a) && touches(w, b)) {
            sel[w] = 1;
            stack.push_back(w);
          }
      }
      double out = 0;
      for (int f = 0; f < F.rows(); ++f) {
        if (c.of_face[f] != chart) continue;
        const Vec3 centroid = (X.row(F(f, 0)) + X.row(F(f, 1)) + X.row(F(f, 2))).transpose() / 3.0;
        for (int j = 0; j < 3; ++j)
          if (at_pinch[F(f, j)]) out += X(F(f, j), third) - centroid[third];
      }
      if (!(std::abs(out) > 0)) continue;
      const int to = 2 * third + (out > 0 ? 0 : 1);
      int changed = 0;
      for (int f = 0; f < F.rows(); ++f) {
        const int ch = c.of_face[f];
        if (ch != chart && ch != a && ch != b) continue;
        if (!sel[F(f, 0)] && !sel[F(f, 1)] && !sel[F(f, 2)]) continue;
        labels[f] = to;
        ++changed;
      }
      if (changed > 0) return changed;
    }
  return 0;
}

// Charts meeting a chart of the opposite label (along an edge or at a vertex), each the smaller
// of such a pair, by increasing area (equal areas: in the order the vertices first show them).
std::vector<int> smaller_of_opposite_pairs(const Charts& c, const VertexCharts& vcharts) {
  std::vector<int> out;
  std::vector<char> seen(c.count(), 0);
  for (const auto& l : vcharts)
    for (auto [a, fa] : l)
      for (auto [b, fb] : l)
        if (c.label[a] == (c.label[b] ^ 1)) {
          const int small = c.area[a] <= c.area[b] ? a : b;
          if (!seen[small]) out.push_back(small);
          seen[small] = 1;
        }
  std::stable_sort(out.begin(), out.end(), [&](int a, int b) { return c.area[a] < c.area[b]; });
  return out;
}

}  // namespace

int relabel_collapsed(const MatX3d& rest, const MatX3d& deformed, const MatX3i& F, std::vector<int>& labels,
                      double ratio) {
  const int nf = static_cast<int>(F.rows());
  if (nf == 0 || !(ratio > 0)) return 0;
  auto area = [&](const MatX3d& X, int f) {
    const Vec3 a = X.row(F(f, 0)), b = X.row(F(f, 1)), c = X.row(F(f, 2));
    return 0.5 * (b - a).cross(c - a).norm();
  };
  std::vector<double> r(nf);
  for (int f = 0; f < nf; ++f) r[f] = area(deformed, f) / std::max(area(rest, f), 1e-300);
  std::vector<double> sorted = r;
  std::nth_element(sorted.begin(), sorted.begin() + nf / 2, sorted.end());
  const double threshold = ratio * sorted[nf / 2];
  std::vector<char> unreliable(nf, 0);
  int count = 0;
  for (int f = 0; f < nf; ++f)
    if (r[f] < threshold) unreliable[f] = 1, ++count;
  if (count == 0) return 0;
  const MatX3i N = face_adjacency(F);
  int changed = 0;
  // Fronts: each pass labels the unreliable triangles that touch a reliable one.
  for (int left = count; left > 0;) {
    std::vector<std::pair<int, int>> set;
    for (int f = 0; f < nf; ++f) {
      if (!unreliable[f]) continue;
      int votes[6] = {0, 0, 0, 0, 0, 0};
      for (int k = 0; k < 3; ++k) {
        const int g = N(f, k);
        if (g >= 0 && !unreliable[g]) votes[labels[g]]++;
      }
      const int best = static_cast<int>(std::max_element(votes, votes + 6) - votes);
      if (votes[best] > 0) set.emplace_back(f, best);
    }
    if (set.empty()) break;  // a component with no reliable triangle keeps its labels
    for (auto [f, l] : set) {
      changed += labels[f] != l;
      labels[f] = l;
      unreliable[f] = 0;
    }
    left -= static_cast<int>(set.size());
  }
  return changed;
}

CleanupStats cleanup_labels(const MatX3d& X, const MatX3i& F, std::vector<int>& labels, const CleanupOptions& opt,
                            const Hooks& hooks) {
  // A whole large chart relabelled changes the layout's structure: said, for -v.
  auto tell = [&](const Charts& c, int chart, int to, const char* why) {
    const double total = std::accumulate(c.area.begin(), c.area.end(), 0.0);
    if (!(c.area[chart] > 0.05 * total)) return;
    hooks.debug("cleanup: chart " + std::to_string(chart) + " (" + label_name(c.label[chart]) + ", " +
                std::to_string(c.faces[chart]) + " triangles, " +
                std::to_string(static_cast<int>(std::lround(100 * c.area[chart] / total))) + "% of the area, degree " +
                std::to_string(c.degree(chart)) + ") relabelled " + label_name(c.label[to]) + ": " + why);
  };
  CleanupStats s;
  s.pinch_above = opt.pinch_above;
  const std::vector<int> initial = labels;
  const MatX3i N = face_adjacency(F);
  for (s.rounds = 0; s.rounds < opt.max_rounds; ++s.rounds) {
    bool changed = false;
    if (opt.straighten) {
      const int z = straighten(N, labels);
      s.zigzags += z;
      changed |= z > 0;
    }
    if (opt.fix_degenerate) {
      const int d = fix_degenerate(X, F, N, labels) + fix_wide_fans(X, F, N, labels);
      s.degenerate += d;
      changed |= d > 0;
    }
    // The charts of the labels after steps 1-2; steps 3 and 4 below change labels only as the
    // last thing they do, so each sees these charts as they are.
    const Charts c = build_charts(X, F, labels);
    const VertexCharts vcharts =
        opt.separate_opposite ? vertex_charts(F, c, static_cast<int>(X.rows())) : VertexCharts{};
    bool rim_opened = false;
    if (opt.separate_opposite && s.rims < opt.max_rims) {
      // Step 4 for folds, before the low-degree removal: a large chart meeting its opposite along
      // a fold gets a rim (open_rim). Removing low-degree charts first could strip the fold of
      // what surrounds it (a thin wedge's two triangular ends have degree 3, and their removal
      // cascades until one chart is left).
      const double total = std::accumulate(c.area.begin(), c.area.end(), 0.0);
      for (int small : smaller_of_opposite_pairs(c, vcharts)) {
        if (!(c.area[small] > opt.rim_above * total)) continue;
        if (const int r = open_rim(X, F, c, vcharts, small, true, labels); r > 0) {
          hooks.debug("cleanup: rim of " + std::to_string(r) + " triangles on chart " + std::to_string(small) + " (" +
                      label_name(c.label[small]) + ", " + std::to_string(c.faces[small]) +
                      " triangles) where it folds onto its opposite");
          s.rims++;
          changed = rim_opened = true;
          break;
        }
      }
    }
    if (opt.remove_low_degree && !rim_opened) {
      // Remove the smallest chart of the lowest degree <= 3, then start over.
      // Degree 1: the surrounding chart; degree 2 and 3: the neighbour with the longest border,
      // avoiding, when another choice exists, the opposite label and a label whose opposite is
      // another neighbour's (the merged chart would meet it). safe: a neighbour of neither kind.
      auto target = [&](int i, bool& safe) {
        int to = -1;
        double len = -1;
        safe = false;
        for (auto [n, l] : c.neighbors[i]) {
          const bool opposite = (c.label[n] ^ 1) == c.label[i];
          const bool meets_opposite = std::any_of(c.neighbors[i].begin(), c.neighbors[i].end(),
                                                  [&](const auto& m) { return c.label[m.first] == (c.label[n] ^ 1); });
          safe |= !opposite && !meets_opposite;
          const double score = opposite ? l * 1e-6 : meets_opposite ? l * 1e-3 : l;
          if (score > len) {
            len = score;
            to = n;
          }
        }
        return to;
      };
      int best = -1, best_deg = 4;
      for (int i = 0; i < c.count(); ++i) {
        const int deg = c.degree(i);
        if (deg < best_deg || (deg == best_deg && best >= 0 && c.area[i] < c.area[best])) {
          // Once a rim is open, a chart of degree 2 or 3 with no safe neighbour stays (a rim
          // between the two sides of a fold would go back into one of them and the fold close
          // again, until the rims run out and a side is relabelled whole).
          bool safe = true;
          if (s.rims > 0 && deg >= 2) target(i, safe);
          if (!safe) continue;
          best = i;
          best_deg = deg;
        }
      }
      bool pinched = false;
      const double total = std::accumulate(c.area.begin(), c.area.end(), 0.0);
      if (best >= 0 && best_deg >= 2 && s.pinches < opt.max_pinches && opt.separate_opposite &&
          c.area[best] > opt.pinch_above * total)
        if (const int r = open_pinch(X, F, c, vcharts, best, labels); r > 0) {
          s.smallest_pinch = std::min(s.smallest_pinch, c.area[best] / total);
          hooks.debug("cleanup: side of " + std::to_string(r) + " triangles opened at a pinch of chart " +
                      std::to_string(best) + " (" + label_name(c.label[best]) + ", " + std::to_string(c.faces[best]) +
                      " triangles, degree " + std::to_string(best_deg) + ")");
          s.pinches++;
          changed = pinched = true;
        }
      if (!pinched && best >= 0 && best_deg >= 1 && !c.neighbors[best].empty()) {
        bool safe;
        const int to = target(best, safe);
        tell(c, best, to, "low degree");
        for (int f = 0; f < F.rows(); ++f)
          if (c.of_face[f] == best) labels[f] = c.label[to];
        (best_deg == 1 ? s.degree1 : best_deg == 2 ? s.degree2 : s.degree3)++;
        changed = true;
      }
    }
    if (!changed && opt.separate_opposite) {
      // Opposite charts meeting (along an edge or at a vertex) would give the polycube zero
      // thickness: the smaller one takes the label of its longest-bordered non-opposite neighbour.
      const auto pairs = smaller_of_opposite_pairs(c, vcharts);
      int worst = pairs.empty() ? -1 : pairs.front();
      // A large chart that faces its label (where it meets its opposite only at a vertex or along
      // a short border: humanoid in surface mode had a +X chart of 21% of the area relabelled
      // whole, which started a cascade of removals) only loses its triangles at the contact.
      if (worst >= 0 && s.rims < opt.max_rims) {
        const double total = std::accumulate(c.area.begin(), c.area.end(), 0.0);
        Vec3 normal = Vec3::Zero();
        for (int f = 0; f < F.rows(); ++f)
          if (c.of_face[f] == worst) {
            const Vec3 a = X.row(F(f, 0)), b = X.row(F(f, 1)), cc = X.row(F(f, 2));
            normal += (b - a).cross(cc - a);
          }
        int r = 0;
        if (c.area[worst] > opt.rim_above * total &&
            normal.dot(label_direction(c.label[worst])) > 0.5 * normal.norm() &&
            (r = open_rim(X, F, c, vcharts, worst, false, labels)) > 0) {
          hooks.debug("cleanup: rim of " + std::to_string(r) + " triangles on chart " + std::to_string(worst) + " (" +
                      label_name(c.label[worst]) + ", " + std::to_string(c.faces[worst]) +
                      " triangles) where it meets its opposite");
          s.rims++;
          changed = true;
          worst = -1;
        }
      }
      if (worst >= 0) {
        int to = -1;
        double len = -1;
        for (auto [n, l] : c.neighbors[worst])
          if ((c.label[n] ^ 1) != c.label[worst] && l > len) {
            len = l;
            to = n;
          }
        if (to >= 0) {
          tell(c, worst, to, "meets its opposite");
          for (int f = 0; f < F.rows(); ++f)
            if (c.of_face[f] == worst) labels[f] = c.label[to];
          s.opposite++;
          changed = true;
        }
      }
    }
    if (!changed) break;
  }
  for (size_t f = 0; f < labels.size(); ++f) s.relabelled_faces += labels[f] != initial[f];
  return s;
}

std::vector<UnflatChart> unflat_charts(const MatX3d& X, const MatX3i& F, const std::vector<int>& labels,
                                       double above) {
  const Charts c = build_charts(X, F, labels);
  const int nf = static_cast<int>(F.rows());
  std::vector<double> height(nf), area(nf);
  std::vector<std::vector<int>> faces(c.count());
  for (int f = 0; f < nf; ++f) {
    const Vec3 a = X.row(F(f, 0)), b = X.row(F(f, 1)), cc = X.row(F(f, 2));
    height[f] = (a + b + cc)[axis_of(c.label[c.of_face[f]])] / 3.0;
    area[f] = 0.5 * (b - a).cross(cc - a).norm();
    faces[c.of_face[f]].push_back(f);
  }
  std::vector<UnflatChart> out;
  for (int i = 0; i < c.count(); ++i) {
    const auto [lo, hi] = std::minmax_element(faces[i].begin(), faces[i].end(),
                                              [&](int a, int b) { return height[a] < height[b]; });
    if (!(height[*hi] - height[*lo] > above)) continue;
    std::vector<int> sorted = faces[i];
    std::sort(sorted.begin(), sorted.end(), [&](int a, int b) { return height[a] < height[b]; });
    double total = 0;
    for (int f : sorted) total += area[f];
    double median = height[sorted.front()];
    for (double acc = 0; int f : sorted)
      if ((acc += area[f]) >= 0.5 * total) {
        median = height[f];
        break;
      }
    UnflatChart u;
    u.chart = i;
    u.label = c.label[i];
    u.faces = c.faces[i];
    u.spread = height[*hi] - height[*lo];
    u.farthest = median - height[*lo] > height[*hi] - median ? *lo : *hi;
    out.push_back(u);
  }
  std::stable_sort(out.begin(), out.end(), [](const UnflatChart& a, const UnflatChart& b) { return a.spread > b.spread; });
  return out;
}

ChartReport check_charts(const MatX3i& F, int nv, const std::vector<int>& labels) {
  ChartReport r;
  const MatX3i N = face_adjacency(F);
  // Charts by connectivity only (positions are not needed here).
  const Charts c = build_charts(MatX3d::Zero(nv, 3), F, labels);
  r.charts = c.count();

  // Border edges (each once, from the face with the smaller id) and vertex valence = number of
  // border edges at the vertex (= chart changes around its fan).
  struct Border {
    int u, v, c1, c2;
  };
  std::vector<Border> border;
  std::vector<int> valence(nv, 0);
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int g = N(f, k);
      if (g < 0 || g < f || c.of_face[g] == c.of_face[f]) continue;
      const int u = F(f, k), v = F(f, (k + 1) % 3);
      border.push_back({u, v, c.of_face[f], c.of_face[g]});
      valence[u]++;
      valence[v]++;
    }
  for (int v = 0; v < nv; ++v)
    if (valence[v] >= 3) {
      r.corners++;
      if (static_cast<int>(r.corner_valence.size()) <= valence[v]) r.corner_valence.resize(valence[v] + 1, 0);
      r.corner_valence[valence[v]]++;
      if (valence[v] > 3) {
        r.high_valence_corners++;
        add_problem(r, "vertex " + std::to_string(v) + " is a corner of valence " + std::to_string(valence[v]) +
                           " (polycube corners have 3 charts)");
      }
    }

  // Corners pinned to one point: charts of one axis that meet at a vertex lie in one plane, so a
  // corner sits where its three charts' planes cross; two corners on the same three planes would
  // coincide (a chart edge of zero length, or the polycube touching itself there).
  {
    const auto vcharts = vertex_charts(F, c, nv);
    UnionFind planes(c.count());
    for (const auto& around : vcharts)
      for (size_t a = 0; a < around.size(); ++a)
        for (size_t b = a + 1; b < around.size(); ++b)
          if (axis_of(c.label[around[a].first]) == axis_of(c.label[around[b].first]))
            planes.unite(around[a].first, around[b].first);
    std::map<std::array<int, 3>, int> seen;  // planes (x, y, z) -> first corner
    for (int v = 0; v < nv; ++v) {
      if (valence[v] != 3) continue;
      std::array<int, 3> key{-1, -1, -1};
      for (auto [ch, fan] : vcharts[v]) key[axis_of(c.label[ch])] = planes.find(ch);
      if (key[0] < 0 || key[1] < 0 || key[2] < 0) continue;
      auto [it, fresh] = seen.emplace(key, v);
      if (fresh) continue;
      r.coincident_corners++;
      add_problem(r, "corners " + std::to_string(it->second) + " and " + std::to_string(v) +
                         " lie on the same three planes (charts " + std::to_string(key[0]) + ", " +
                         std::to_string(key[1]) + ", " + std::to_string(key[2]) +
                         " and those they touch): the polycube would put them at one point");
    }
  }

  // Opposite labels side by side.
  for (int i = 0; i < c.count(); ++i)
    for (auto [n, len] : c.neighbors[i])
      if (n > i && (c.label[n] ^ 1) == c.label[i]) {
        r.opposite_adjacent++;
        add_problem(r, "charts " + std::to_string(i) + " (" + label_name(c.label[i]) + ") and " + std::to_string(n) +
                           " (" + label_name(c.label[n]) + ") are adjacent with opposite labels");
      }

  // Chart edges: border edges joined at non-corner vertices, per chart pair.
  {
    UnionFind uf(border.size());
    std::unordered_map<long long, int> first;  // (vertex, chart pair) -> border edge
    for (size_t e = 0; e < border.size(); ++e) {
      const auto& b = border[e];
      const long long pair = static_cast<long long>(std::min(b.c1, b.c2)) * r.charts + std::max(b.c1, b.c2);
      for (int v : {b.u, b.v}) {
        if (valence[v] >= 3) continue;
        const long long key = pair * nv + v;
        auto [it, fresh] = first.emplace(key, static_cast<int>(e));
        if (!fresh) uf.unite(static_cast<int>(e), it->second);
      }
    }
    for (size_t e = 0; e < border.size(); ++e) r.chart_edges += uf.find(static_cast<int>(e)) == static_cast<int>(e);
  }

  // Topology of each chart: Euler characteristic and boundary loops (with their corners).
  {
    std::vector<int> cv(r.charts, 0), ce(r.charts, 0), cf(r.charts, 0);
    std::unordered_map<long long, int> id;  // (chart, vertex) -> dense id
    auto key_of = [&](int ch, int v) { return static_cast<long long>(ch) * nv + v; };
    for (int f = 0; f < F.rows(); ++f) {
      const int ch = c.of_face[f];
      cf[ch]++;
      for (int k = 0; k < 3; ++k) {
        if (id.emplace(key_of(ch, F(f, k)), static_cast<int>(id.size())).second) cv[ch]++;
        const int g = N(f, k);
        // Count each chart-interior edge once (from the smaller face), border edges once per side.
        if (g < 0 || c.of_face[g] != ch || g > f) ce[ch]++;
      }
    }
    UnionFind uf(id.size());
    std::vector<char> has_border(id.size(), 0);
    for (const auto& b : border)
      for (int ch : {b.c1, b.c2}) {
        const int iu = id.at(key_of(ch, b.u)), iv = id.at(key_of(ch, b.v));
        uf.unite(iu, iv);
        has_border[iu] = has_border[iv] = 1;
      }
    // Loops per chart and corners per loop.
    std::unordered_map<int, std::pair<int, int>> loop;  // root -> (chart, corners)
    for (const auto& [key, i] : id) {
      if (!has_border[i]) continue;
      const int ch = static_cast<int>(key / nv), v = static_cast<int>(key % nv);
      auto& l = loop[uf.find(i)];
      l.first = ch;
      l.second += valence[v] >= 3;
    }
    std::vector<int> loops(r.charts, 0);
    for (const auto& [root, l] : loop) {
      loops[l.first]++;
      if (l.second < 4) {
        r.loops_with_few_corners++;
        add_problem(r, "chart " + std::to_string(l.first) + " (" + label_name(c.label[l.first]) +
                           ") has a boundary loop with " + std::to_string(l.second) + " corners (at least 4 needed)");
      }
    }
    for (int ch = 0; ch < r.charts; ++ch) {
      const int chi = cv[ch] - ce[ch] + cf[ch];
      const int b = loops[ch];
      const int twice_genus = 2 - chi - b;
      if (b == 1 && twice_genus == 0) continue;
      if (b == 0 || twice_genus != 0) {
        r.invalid_topology_charts++;
        add_problem(r, "chart " + std::to_string(ch) + " (" + label_name(c.label[ch]) + ", " +
                           std::to_string(c.faces[ch]) + " triangles) is not a planar region (Euler characteristic " +
                           std::to_string(chi) + ", " + std::to_string(b) + " boundary loops)");
      } else {
        r.non_disk_charts++;
      }
    }
  }
  r.valid = r.opposite_adjacent == 0 && r.high_valence_corners == 0 && r.invalid_topology_charts == 0 &&
            r.loops_with_few_corners == 0 && r.coincident_corners == 0;
  return r;
}

}  // namespace polycube::chart
