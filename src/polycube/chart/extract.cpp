#include "polycube/chart/extract.h"

#include <algorithm>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <string>
#include <tuple>

#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/deform/energies.h"
#include "polycube/deform/solver.h"
#include "polycube/validate/tetmesh.h"

namespace polycube::chart {

namespace {

// Vertices appended to the work mesh at `at` (split_edges_for_collapse: midpoints of `parents`)
// inserted into a realization of it: after its first `at` vertices, before its own split ones.
void insert_split_vertices(RealizeResult& r, Eigen::Index at, const std::vector<std::pair<int, int>>& parents) {
  const Eigen::Index k = static_cast<Eigen::Index>(parents.size());
  auto grow = [&](MatX3d& P) {
    if (P.rows() < at) return;
    MatX3d Q(P.rows() + k, 3);
    Q.topRows(at) = P.topRows(at);
    for (Eigen::Index i = 0; i < k; ++i)  // a parent may be an earlier new vertex (below at + i)
      Q.row(at + i) = 0.5 * (Q.row(parents[i].first) + Q.row(parents[i].second));
    Q.bottomRows(P.rows() - at) = P.bottomRows(P.rows() - at);
    P = std::move(Q);
  };
  grow(r.X);
  grow(r.rest);
  for (int t = 0; t < r.T.rows(); ++t)
    for (int j = 0; j < 4; ++j)
      if (r.T(t, j) >= at) r.T(t, j) += static_cast<int>(k);
}

// Tets of a realization's state (r.T over r.rest and r.X) that are not positive.
std::vector<int> inverted_tets(const RealizeResult& r) {
  auto volume = [&](const MatX3d& P, int t) {
    return tet_volume(P.row(r.T(t, 0)).transpose(), P.row(r.T(t, 1)).transpose(), P.row(r.T(t, 2)).transpose(),
                      P.row(r.T(t, 3)).transpose());
  };
  std::vector<int> out;
  for (int t = 0; t < r.T.rows(); ++t)
    if (!(volume(r.rest, t) * volume(r.X, t) > 0)) out.push_back(t);
  return out;
}

}  // namespace

namespace {

// extract_polycube; `first`: the first realization of this labelling, when an earlier pass made
// it (the same inputs and options: its result is the same).
PolycubeExtraction extract(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                           const ExtractOptions& opt, const Hooks& hooks, const RealizeResult* first) {
  PolycubeExtraction e;
  e.labels = label_by_normal(deformed, B);
  e.initial_charts = build_charts(deformed, B, e.labels).count();
  const std::vector<int> raw = e.labels;
  const int collapsed = relabel_collapsed(rest, deformed, B, e.labels, opt.collapsed_ratio);
  e.cleanup = cleanup_labels(deformed, B, e.labels, opt.cleanup, hooks);
  e.cleanup.collapsed = collapsed;
  e.cleanup.collapsed_ratio = opt.collapsed_ratio;
  e.cleanup.relabelled_faces = 0;
  for (size_t f = 0; f < raw.size(); ++f) e.cleanup.relabelled_faces += raw[f] != e.labels[f];
  if (collapsed > 0) hooks.debug(std::to_string(collapsed) + " collapsed triangles took their neighbours' label");
  e.charts = check_charts(B, static_cast<int>(deformed.rows()), e.labels);
  hooks.debug("charts: " + std::to_string(e.initial_charts) + " labelled, " + std::to_string(e.charts.charts) +
              " after cleanup (" + std::to_string(e.cleanup.zigzags) + " zigzag triangles, " +
              std::to_string(e.cleanup.degree1 + e.cleanup.degree2 + e.cleanup.degree3) + " charts removed), " +
              std::to_string(e.charts.corners) + " corners");
  for (const auto& p : e.charts.problems) hooks.debug("chart graph: " + p);
  if (first) {
    e.realized = *first;
    hooks.debug("the first realization as in the pass before (" +
                std::string(first->success ? "realized" : first->failure) + ")");
  } else {
    e.realized = realize_polycube(rest, T, B, deformed, e.labels, opt.realize, hooks);
  }
  e.edge_order = e.realized.edge_order;
  // Kept for the second pass of retries, which only the warm retries can call for.
  std::optional<RealizeResult> first_realization;
  if (opt.warm_retries) first_realization = e.realized;
  // Surface mode: a few triangles still folded in their chart's plane. Edge flips inside a chart
  // (same vertices, another triangulation); then collapses of the folded triangles' edges (two
  // triangles fewer, one vertex merged into a neighbour) and a new realization, a few rounds.
  constexpr int kStallRounds = 5;
  // A triangle's vertices, sorted: its identity across edge flips of other triangles and collapses.
  auto sorted_key = [](const MatX3i& FF, int t) {
    std::array<int, 3> key{FF(t, 0), FF(t, 1), FF(t, 2)};
    std::sort(key.begin(), key.end());
    return key;
  };
  auto repair_surface = [&] {
    if (e.realized.success || e.realized.misoriented_faces == 0 ||
        e.realized.misoriented_faces > opt.max_flip_faces || e.realized.degenerate_border_edges > 0 ||
        e.realized.X.rows() == 0)
      return;
    MatX3i F = B;
    std::vector<int> L = e.labels;
    std::vector<int> merged(rest.rows(), -1);
    RealizeResult r = e.realized;
    int flips = 0, collapses = 0, relabels = 0, relabelled = 0, stall = 0;
    int fewest = std::numeric_limits<int>::max();
    std::map<std::array<int, 3>, std::set<int>> tried_labels;  // per triangle (sorted vertices)
    // Collapses exhausted or stalled: the folded triangles take the most frequent label of their
    // edge neighbours (then of the triangles around their vertices) that they have not had yet in
    // this repair (humanoid: a corner triangle went back and forth between +X and -Y, neither of
    // which realizes); the labels are cleaned again, and the layout is realized again from here
    // (blub: 12 charts realized this way). False when that changes nothing or the cleanup loses
    // over half the charts.
    auto relabel_folded = [&](const RealizeResult& rr, const MatX3i& FF, std::vector<int>& LL) {
      const double diag = (rr.X.colwise().maxCoeff() - rr.X.colwise().minCoeff()).norm();
      const MatX3i NF = face_adjacency(FF);
      std::vector<std::vector<int>> around(deformed.rows());
      for (int t = 0; t < FF.rows(); ++t)
        for (int j = 0; j < 3; ++j) around[FF(t, j)].push_back(t);
      std::vector<int> next = LL;
      int changed_here = 0;
      for (int t = 0; t < FF.rows(); ++t) {
        if (faces_label(rr.X, FF(t, 0), FF(t, 1), FF(t, 2), LL[t], diag)) continue;
        auto& tried = tried_labels[sorted_key(FF, t)];
        tried.insert(LL[t]);
        int votes[6] = {0, 0, 0, 0, 0, 0};
        for (int k = 0; k < 3; ++k)
          if (NF(t, k) >= 0) votes[LL[NF(t, k)]] += 1000;
        for (int j = 0; j < 3; ++j)
          for (int u : around[FF(t, j)]) votes[LL[u]] += 1;
        for (int l : tried) votes[l] = 0;
        const int best = static_cast<int>(std::max_element(votes, votes + 6) - votes);
        if (votes[best] > 0) next[t] = best, ++changed_here;
      }
      // Its pinches count for extract_polycube's choice of threshold, adopted or not.
      e.cleanup.smallest_pinch =
          std::min(e.cleanup.smallest_pinch, cleanup_labels(deformed, FF, next, opt.cleanup, hooks).smallest_pinch);
      if (next == LL || check_charts(FF, static_cast<int>(deformed.rows()), next).charts < e.charts.charts / 2)
        return false;
      ++relabels;
      relabelled += changed_here;
      LL = std::move(next);
      hooks.debug("relabelling the folded triangles of the collapsed layout; realizing again");
      return true;
    };
    // Merged vertices sit on the vertex they were merged into (followed through later merges).
    auto place_merged = [&](MatX3d& X) {
      for (int v = 0; v < static_cast<int>(merged.size()); ++v) {
        int w = v;
        while (merged[w] >= 0) w = merged[w];
        if (w != v) X.row(v) = X.row(w);
      }
    };
    for (int round = 0;; ++round) {
      const int f = flip_folded_edges(r.X, F, L);
      flips += f;
      check_faces(F, L, r);
      hooks.debug(std::to_string(f) + " edge flips leave " + std::to_string(r.misoriented_faces) + " folded triangles");
      if (r.misoriented_faces == 0 || round >= opt.collapse_rounds) break;
      {
        const double diag = (r.X.colwise().maxCoeff() - r.X.colwise().minCoeff()).norm();
        for (int t = 0; t < F.rows(); ++t)
          if (!faces_label(r.X, F(t, 0), F(t, 1), F(t, 2), L[t], diag))
            hooks.debug("folded triangle (" + std::to_string(F(t, 0)) + " " + std::to_string(F(t, 1)) + " " +
                        std::to_string(F(t, 2)) + ") label " + label_name(L[t]));
      }
      // Collapses that no longer reduce the folded triangles (kStallRounds rounds) give way to a
      // relabelling (fandisk, `--surface --quads 724`: 2 folded triangles for 3 rounds, then none).
      stall = r.misoriented_faces >= fewest ? stall + 1 : 0;
      fewest = std::min(fewest, r.misoriented_faces);
      const bool relabel_first = stall >= kStallRounds && relabels < opt.repair_relabels;
      int c = relabel_first ? 0 : collapse_folded_edges(rest, r.X, F, L, merged);
      const bool relabelled_now = c == 0 && relabels < opt.repair_relabels && relabel_folded(r, F, L);
      if (relabelled_now) stall = 0;
      else if (relabel_first) c = collapse_folded_edges(rest, r.X, F, L, merged);
      if (c == 0 && !relabelled_now) break;
      collapses += c;
      if (c > 0) hooks.debug("collapsing " + std::to_string(c) + " edges of folded triangles; realizing again");
      // From the layout at hand with the merged vertices on their partners (it keeps the planes:
      // the kept vertex gains none), untangled locally. (Realizing from the three starts again
      // did no better on fandisk and rocker, at the cost of a full realization per round.)
      MatX3d start = r.X;
      place_merged(start);
      r = realize_surface_polycube(rest, F, deformed, L, opt.realize, hooks, &start);
      hooks.debug("realization from the collapsed layout: " + std::to_string(r.misoriented_faces) + " folded");
      if (r.success || r.misoriented_faces > opt.max_flip_faces || r.degenerate_border_edges > 0) break;
    }
    if (!r.success && r.misoriented_faces == 0 && r.degenerate_border_edges == 0 && r.X.rows() > 0) {
      // Flips unfolded the last triangles of an untangled layout: finish it with the realization's
      // never-folding ARAP iterations (the untangling alone leaves large distortions).
      RealizeResult fin = realize_surface_polycube(rest, F, deformed, L, opt.realize, hooks, &r.X);
      if (fin.success) r = std::move(fin);
    }
    if (r.misoriented_faces == 0 && r.degenerate_border_edges == 0 && r.X.rows() > 0) {
      place_merged(r.X);
      if (!r.success) {
        r.success = true;
        r.failure.clear();
        r.arap = deform::surface_arap_energy(r.X, F, deform::SurfaceArapRest::build(rest, F), 1.0, nullptr, nullptr);
        r.isometric = isometric_distortion_surface(rest, r.X, F);
      }
      if (relabels > 0) {
        // The input triangles that the collapses left as they were take their repaired labels
        // (labels.txt); e.charts describes the repaired layout.
        std::map<std::array<int, 3>, int> row_of;
        for (int t = 0; t < B.rows(); ++t) row_of[sorted_key(B, t)] = t;
        for (int t = 0; t < F.rows(); ++t)
          if (auto it = row_of.find(sorted_key(F, t)); it != row_of.end()) e.labels[it->second] = L[t];
        e.charts = check_charts(F, static_cast<int>(deformed.rows()), L);
        e.cleanup.misoriented += relabelled;
      }
      e.realized = std::move(r);
      e.map_B = std::move(F);
      e.map_labels = std::move(L);
      e.edge_flips = flips;
      e.edge_collapses = collapses;
    } else if (collapses > 0) {
      e.realized.failure += " (after " + std::to_string(flips) + " edge flips and " + std::to_string(collapses) +
                            " edge collapses: " + std::to_string(r.misoriented_faces) + " still folded)";
    }
  };
  // Tet mode: a realization that leaves a few tets inverted where it pins two boundary vertices
  // joined by a boundary edge to one point (spot: a chart-border vertex 1.8e-4 from the corner of
  // its own polycube edge in the deformed mesh, pressed onto it) has no room for the tets between
  // them. The edge is collapsed (collapse_tet_edge: the slim-triangle collapse of Section 4, on
  // the rest and deformed meshes alike) and the polycube realized again, a few rounds. The
  // realization runs on the mesh without the merged vertices; its result is given back in the
  // input's numbering, each merged vertex on its partner.
  // The deformed mesh the retries start from: merged vertices may move (collapse_tet_edge).
  MatX3d cur_def = deformed;
  // The rest mesh the retries use: a kept vertex may move to the collapsed edge's midpoint.
  MatX3d cur_rest = T.rows() > 0 ? rest : MatX3d();
  auto realize_compact = [&](const MatX4i& CT, const MatX3i& CB, const std::vector<int>& CL,
                             const std::vector<int>& merged, const std::vector<int>& rows, const RealizeOptions& ro) {
    // The work mesh's vertices: the input's, then those of edges split for collapses.
    const int n = static_cast<int>(cur_rest.rows());
    MatX3d R = cur_rest, D = cur_def.topRows(n);
    MatX4i TT = CT;
    MatX3i BB = CB;
    const std::vector<int> o2n = drop_merged_vertices(merged, {&R, &D}, TT, BB);
    std::vector<int> n2o;
    for (int v = 0; v < n; ++v)
      if (o2n[v] >= 0) n2o.push_back(v);
    const int m = static_cast<int>(n2o.size());
    // Messages name vertices and triangles as in the work mesh (the input's numbering, then the
    // split vertices), not the compacted copy's.
    RealizeOptions named = ro;
    named.names.vertices = n2o;
    named.names.next_vertex = n;
    named.names.faces = rows;
    RealizeResult r = realize_polycube(R, TT, BB, D, CL, named, hooks);
    auto back = [&](int i) { return i < m ? n2o[i] : n + (i - m); };
    auto root = [&](int v) {
      while (merged[v] >= 0) v = merged[v];
      return v;
    };
    auto expand = [&](MatX3d& P, const MatX3d& dropped_at) {
      if (P.rows() < m) return;
      MatX3d full(n + (P.rows() - m), 3);
      for (int i = 0; i < P.rows(); ++i) full.row(back(i)) = P.row(i);
      for (int v = 0; v < n; ++v)
        if (merged[v] >= 0) {
          if (v < dropped_at.rows()) full.row(v) = dropped_at.row(v);
          else full.row(v) = full.row(root(v)).eval();
        }
      P = std::move(full);
    };
    expand(r.X, MatX3d());
    expand(r.rest, rest);
    for (int t = 0; t < r.T.rows(); ++t)
      for (int j = 0; j < 4; ++j) r.T(t, j) = back(r.T(t, j));
    return r;
  };
  // The tet-mode retries work on the current mesh: B and T less the collapsed edges (CB, CT), the
  // labels of CB's rows (CL), the row of B of each row of CB, and the vertex each merged one went into.
  MatX4i CT = T;
  MatX3i CB = B;
  std::vector<int> CL = e.labels;
  std::vector<int> cb_row(B.rows());
  std::iota(cb_row.begin(), cb_row.end(), 0);
  std::vector<int> merged(rest.rows(), -1);
  int collapses = 0, collapse_rounds = 0, split_edges = 0;
  auto realize_current = [&](const RealizeOptions& ro) {
    return collapses == 0 ? realize_polycube(rest, T, B, cur_def, CL, ro, hooks)
                          : realize_compact(CT, CB, CL, merged, cb_row, ro);
  };
  // Tet mode: of the failed realizations on their planes with tets inverted, the one with the
  // fewest (then the fewest triangles facing away), with the labels and triangles it was realized
  // with: returned instead of the last one when no polycube is realized, since the hexes may still
  // be extracted through it (PipelineOptions::hex_through_folds; octopus-low: the retries ended at
  // 1924 inverted tets after a state with 21).
  std::optional<PolycubeExtraction> best_failed;
  auto keep_if_best = [&] {
    const RealizeResult& r = e.realized;
    if (!is_folded(r)) return;
    if (best_failed && std::make_pair(best_failed->realized.inverted, best_failed->realized.misoriented_faces) <=
                           std::make_pair(r.inverted, r.misoriented_faces))
      return;
    best_failed = e;
    PolycubeExtraction& b = *best_failed;
    b.alternative.reset();
    for (size_t i = 0; i < cb_row.size(); ++i) b.labels[cb_row[i]] = CL[i];
    if (collapses > 0) {
      b.map_B = CB;
      b.map_labels = CL;
      b.edge_collapses = collapses;
      b.collapse_edge_splits = split_edges;
      b.charts = check_charts(CB, static_cast<int>(rest.rows()), CL);
    }
  };
  keep_if_best();
  // Whether row f of CB faces away from its label (or has no area) in the polycube X (diag: X's
  // bounding-box diagonal).
  auto faces_away = [&](const MatX3d& X, int f, double diag) {
    const Vec3 a = X.row(CB(f, 0)), b = X.row(CB(f, 1)), c = X.row(CB(f, 2));
    return !((b - a).cross(c - a).dot(label_direction(CL[f])) > 1e-14 * diag * diag);
  };
  // The boundary edges (rows of bedges, sorted) of r's inverted tets whose two ends r put at one
  // point: the collapse candidates.
  auto pinned_edges = [&](const RealizeResult& r, const std::vector<std::pair<int, int>>& bedges) {
    std::vector<std::pair<int, int>> cand;
    if (r.X.rows() == 0 || r.T.rows() == 0) return cand;
    const int n = static_cast<int>(cur_rest.rows());
    const double diag = (r.X.colwise().maxCoeff() - r.X.colwise().minCoeff()).norm();
    for (int t : inverted_tets(r)) {
      for (int a = 0; a < 4; ++a)
        for (int b = a + 1; b < 4; ++b) {
          const int u = std::min(r.T(t, a), r.T(t, b)), v = std::max(r.T(t, a), r.T(t, b));
          if (v >= n || (r.X.row(u) - r.X.row(v)).norm() > 1e-6 * diag) continue;
          if (std::binary_search(bedges.begin(), bedges.end(), std::make_pair(u, v))) cand.emplace_back(u, v);
        }
    }
    return cand;
  };
  // Collapses the boundary edges of inverted tets whose two ends the failed realization put at one
  // point (where admissible); returns how many.
  // With `folded` (the last resort, once relabelling has come to nothing): when no tet is inverted
  // but a few boundary triangles face away from their label, the shortest edge of each is
  // collapsed too (surface mode's repair of folded triangles; humanoid ended with one such
  // triangle, its relabelling undone by the cleanup).
  auto try_collapse = [&](bool folded = false) -> int {
    const RealizeResult& r = e.realized;
    const bool fold_case = folded && r.inverted == 0 && r.misoriented_faces > 0 &&
                           r.misoriented_faces <= opt.max_folded_collapses;
    if (T.rows() == 0 || r.success || (r.inverted == 0 && !fold_case) || r.inverted > opt.max_relabel_inverted ||
        r.X.rows() == 0 || r.T.rows() == 0 || collapse_rounds >= opt.tet_collapse_rounds)
      return 0;
    const int n = static_cast<int>(cur_rest.rows());
    const double diag = (r.X.colwise().maxCoeff() - r.X.colwise().minCoeff()).norm();
    const auto bedges = unique_edges(CB);
    std::vector<std::pair<int, int>> cand;
    std::set<std::pair<int, int>> of_folds;  // candidates that are the shortest edge of a folded triangle
    // The shortest edge of row f of CB in r.X, a candidate.
    auto add_shortest_edge = [&](int f, const char* which) {
      int best = 0;
      double shortest = std::numeric_limits<double>::infinity();
      for (int k = 0; k < 3; ++k) {
        const double len = (r.X.row(CB(f, k)) - r.X.row(CB(f, (k + 1) % 3))).norm();
        if (len < shortest) shortest = len, best = k;
      }
      const int u = CB(f, best), v = CB(f, (best + 1) % 3);
      cand.emplace_back(std::min(u, v), std::max(u, v));
      of_folds.insert(cand.back());
      hooks.debug("folded triangle " + std::to_string(cb_row[f]) + which + ": its shortest edge " +
                  std::to_string(u) + "-" + std::to_string(v) + " is a collapse candidate");
    };
    if (fold_case)
      for (int f = 0; f < CB.rows(); ++f)
        if (faces_away(r.X, f, diag)) add_shortest_edge(f, "");
    const auto pinned = pinned_edges(r, bedges);
    cand.insert(cand.end(), pinned.begin(), pinned.end());
    // Also in the last resort: a boundary face of an inverted tet that faces away from its label.
    // No move of the tet's interior vertex can turn the tet back over, so its shortest edge is a
    // candidate too (bumpy torus at 95k tets, beta 0: a corner and a chart vertex 4e-5 of the
    // diagonal apart, their triangle of area 1e-6 folded, the one tet on it left inverted by every
    // retry). Not before: as a candidate from the first retry on, it turned spot at 20k tets
    // (realized by the retries as they were) into a failure.
    if (folded && r.inverted > 0) {
      std::set<std::array<int, 3>> inverted_faces;
      for (int t : inverted_tets(r))
        for (int k = 0; k < 4; ++k) {
          std::array<int, 3> f{r.T(t, (k + 1) % 4), r.T(t, (k + 2) % 4), r.T(t, (k + 3) % 4)};
          std::sort(f.begin(), f.end());
          inverted_faces.insert(f);
        }
      for (int f = 0; f < CB.rows() && !inverted_faces.empty(); ++f) {
        std::array<int, 3> key{CB(f, 0), CB(f, 1), CB(f, 2)};
        std::sort(key.begin(), key.end());
        if (inverted_faces.count(key) && faces_away(r.X, f, diag)) add_shortest_edge(f, " of an inverted tet");
      }
    }
    std::sort(cand.begin(), cand.end());
    cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
    if (cand.empty()) return 0;
    // The vertex on more charts (the corner) is kept.
    std::vector<std::vector<int>> vlabels(n);
    for (int f = 0; f < CB.rows(); ++f)
      for (int j = 0; j < 3; ++j) {
        auto& l = vlabels[CB(f, j)];
        if (std::find(l.begin(), l.end(), CL[f]) == l.end()) l.push_back(CL[f]);
      }
    std::vector<char> touched(n, 0);
    int made = 0;
    for (auto [u, v] : cand) {
      if (touched[u] || touched[v]) continue;
      const bool keep_u = vlabels[u].size() >= vlabels[v].size();
      int keep = keep_u ? u : v, drop = keep_u ? v : u;
      std::string why;
      std::vector<int> rows;  // the rows of CB the collapse removes
      Vec3 at, rest_at;
      MatX3d untangled, rest_untangled;
      bool coincide = false;  // refused in some order because two tets would coincide
      auto attempt = [&]() -> bool {
        bool ok = collapse_tet_edge(cur_rest, cur_def, CT, CB, CL, keep, drop, &why, &rows, &at, &rest_at);
        coincide |= why == "two tets would coincide";
        if (!ok) {
          // The vertex on fewer charts kept instead.
          std::string why2;
          if (collapse_tet_edge(cur_rest, cur_def, CT, CB, CL, drop, keep, &why2, &rows, &at, &rest_at)) {
            std::swap(keep, drop);
            ok = true;
          }
          coincide |= why2 == "two tets would coincide";
        }
        // Valid at rest but no place for the merged vertex keeps its star positive in the deformed
        // mesh (humanoid: a chart-border vertex and a corner 0.025 apart there): the deformed mesh
        // is only where the realization starts, so the merged vertex goes to the midpoint and the
        // tets around it are untangled locally. Refused at rest (tet/hand: slivers at both ends):
        // the merged vertex goes to the edge's midpoint, on the input surface, and the rest mesh's
        // interior vertices around it are untangled (the input volume stays the same, only its
        // tetrahedralization moves). If either untangling fails, the collapse is undone.
        if (!ok && (why == "a tet would turn over in the deformed mesh" || why == "a tet would turn over at rest")) {
          const MatX4i CT0 = CT;
          const MatX3i CB0 = CB;
          const std::vector<int> CL0 = CL;
          if (collapse_tet_edge(cur_rest, cur_def, CT, CB, CL, keep, drop, &why, &rows, &at, &rest_at, true, true)) {
            MatX3d R = cur_rest;
            R.row(keep) = rest_at.transpose();
            int left_rest = 0;
            const TetQuality at_rest = measure_tets(R, CT);
            if (at_rest.inverted + at_rest.zero_volume > 0) {
              // Reference shape per tet: its rest shape before the collapse (every one positive).
              MatX3d soup(4 * CT.rows(), 3);
              MatX4i ST(CT.rows(), 4);
              Eigen::Index i = 0;
              for (int t = 0; t < CT0.rows(); ++t) {
                bool hk = false, hd = false;
                for (int j = 0; j < 4; ++j) hk |= CT0(t, j) == keep, hd |= CT0(t, j) == drop;
                if (hk && hd) continue;  // gone with the edge
                for (int j = 0; j < 4; ++j)
                  soup.row(4 * i + j) = cur_rest.row(CT0(t, j)), ST(i, j) = static_cast<int>(4 * i + j);
                ++i;
              }
              const deform::ArapRest reference = deform::ArapRest::build(soup, ST);
              std::array<std::vector<char>, 3> boundary;
              for (auto& f : boundary) f.assign(cur_rest.rows(), 0);
              for (int f = 0; f < CB.rows(); ++f)
                for (int j = 0; j < 3; ++j)
                  for (auto& b : boundary) b[CB(f, j)] = 1;
              untangle_tets_locally(reference, CT, boundary, R, left_rest);
              if (left_rest == 0) rest_untangled = R;
            }
            int left = 0;
            if (left_rest == 0) {
              std::array<std::vector<char>, 3> fixed;  // none: every vertex may move in the deformed start
              for (auto& f : fixed) f.assign(cur_rest.rows(), 0);
              untangled = cur_def;
              untangled.row(keep) = at.transpose();
              untangled.row(drop) = at.transpose();
              untangle_tets_locally(R, CT, fixed, untangled, left);
            }
            if (left_rest == 0 && left == 0) {
              ok = true;
              hooks.debug("boundary edge " + std::to_string(drop) + " -> " + std::to_string(keep) + ": " +
                          (rest_untangled.rows() > 0 ? "the rest mesh's interior untangled around the merged vertex"
                                                     : "the deformed mesh untangled around the merged vertex"));
            } else {
              CT = CT0;
              CB = CB0;
              CL = CL0;
              untangled.resize(0, 3);
              rest_untangled.resize(0, 3);
              why = left_rest > 0 ? "a tet would turn over at rest, and " + std::to_string(left_rest) +
                                        " stay inverted after untangling the rest mesh's interior"
                                  : "a tet would turn over in the deformed mesh, and " + std::to_string(left) +
                                        " stay inverted after local untangling";
            }
          }
        }
        coincide |= why == "two tets would coincide";  // the tangled collapse's reason included
        return ok;
      };
      bool ok = attempt();
      // Refused because the two ends share a vertex outside the edge's ring (tet/hand, humanoid: a
      // tet at each end on one triangle, which the collapse would make coincide): the interior
      // edges from `drop` to those vertices are split first (split_edges_for_collapse), then the
      // collapse is tried again; undone if it still fails.
      if (!ok && coincide) {
        const int keep0 = keep_u ? u : v, drop0 = keep_u ? v : u;
        const MatX4i CT0 = CT;
        const MatX3d rest0 = cur_rest, def0 = cur_def;
        const auto parents = split_edges_for_collapse(cur_rest, cur_def, CT, CB, keep0, drop0);
        if (!parents.empty()) {
          const Eigen::Index n0 = rest0.rows();
          merged.resize(cur_rest.rows(), -1);
          keep = keep0, drop = drop0;
          ok = attempt();
          if (ok) {
            // The failed realization gets the new vertices too (midpoints of their edges), after
            // the work mesh's vertices and before its own split vertices, so that the next one can
            // start from it.
            insert_split_vertices(e.realized, n0, parents);
            split_edges += static_cast<int>(parents.size());
            hooks.debug("boundary edge " + std::to_string(drop) + " -> " + std::to_string(keep) + ": " +
                        std::to_string(parents.size()) + " interior edges split first (the link condition)");
          } else {
            CT = CT0;
            cur_rest = rest0;
            cur_def = def0;
            merged.resize(n0);
            why = "after splitting " + std::to_string(parents.size()) + " interior edges for the link condition, " +
                  why;
          }
        } else {
          why += " (no interior edge to split: the shared vertices are joined to it by boundary edges)";
        }
      }
      if (!ok) {
        hooks.debug("boundary edge " + std::to_string(u) + "-" + std::to_string(v) +
                    " has both ends at one point of the polycube but cannot be collapsed: " + why);
        continue;
      }
      if (untangled.rows() > 0) {
        cur_def = std::move(untangled);  // the merged vertex where the untangling left it
      } else {
        cur_def.row(keep) = at.transpose();
      }
      if ((rest_at - Vec3(cur_rest.row(keep).transpose())).norm() > 0)
        hooks.debug("the merged vertex " + std::to_string(keep) + " moves at rest too, to " +
                    std::to_string((rest_at - Vec3(cur_rest.row(keep).transpose())).norm() /
                                   (cur_rest.row(drop) - cur_rest.row(keep)).norm()) +
                    " of the way to the other end");
      if (rest_untangled.rows() > 0) cur_rest = std::move(rest_untangled);
      cur_rest.row(keep) = rest_at.transpose();
      for (int i = static_cast<int>(rows.size()) - 1; i >= 0; --i) cb_row.erase(cb_row.begin() + rows[i]);
      merged[drop] = keep;
      touched[u] = touched[v] = 1;
      ++made;
      hooks.debug("collapsed boundary edge " + std::to_string(drop) + " -> " + std::to_string(keep) +
                  (of_folds.count({u, v}) ? ": the shortest edge of a folded triangle"
                                          : ": the polycube put both ends at one point"));
    }
    if (made > 0) {
      ++collapse_rounds;
      collapses += made;
    }
    return made;
  };
  auto sync_labels = [&] {
    for (size_t i = 0; i < cb_row.size(); ++i) e.labels[cb_row[i]] = CL[i];
  };
  int warm_kept = 0;  // failed retries from an earlier state kept as the next one's start
  // The retries from the deformed mesh keep to the continuation start, the one that got every tet
  // positive (when both starts were tried, the eq17 start mostly fails after a long untangling).
  auto realize_again_once = [&] {
    if (opt.warm_retries && T.rows() > 0 && e.realized.X.rows() >= cur_rest.rows()) {
      // From the failed realization's state (every vertex of the input numbering; a merged one
      // sits where its partner is).
      RealizeOptions ro = opt.realize;
      ro.start = "previous";
      MatX3d from_deformed = std::move(cur_def);
      cur_def = e.realized.X.topRows(cur_rest.rows());
      RealizeResult warm = realize_current(ro);
      cur_def = std::move(from_deformed);
      // Kept when it succeeds or leaves fewer tets inverted (or as many, and fewer triangles facing
      // away from their label) than before: the next retry starts from it. Otherwise the deformed
      // mesh is realized again.
      const bool better = warm.X.rows() > 0 && (warm.inverted < e.realized.inverted ||
                                                (warm.inverted == e.realized.inverted &&
                                                 warm.misoriented_faces < e.realized.misoriented_faces));
      // Also kept when its few inverted tets pin a boundary edge's ends to one point: the next
      // step collapses that edge, where a realization from the deformed mesh would mostly come
      // back to the same pinned edge after a much longer path (fandisk at 37.8k tets: 2 tets at
      // edge 214-223 either way, the cold path 60 s of continuation and untangling).
      const bool pinned = !better && T.rows() > 0 && warm.inverted > 0 &&
                          warm.inverted <= opt.max_relabel_inverted && collapse_rounds < opt.tet_collapse_rounds &&
                          !pinned_edges(warm, unique_edges(CB)).empty();
      if (warm.success || better || pinned) {
        if (pinned) hooks.debug("the previous one's state pins a boundary edge of its inverted tets: kept for its collapse");
        warm_kept += !warm.success;
        hooks.debug("realization from the previous one's state: " +
                    (warm.success ? std::string("success") : warm.failure));
        e.realized = std::move(warm);
        return;
      }
      hooks.debug("realization from the previous one's state: " + warm.failure + "; again from the deformed mesh");
    }
    RealizeOptions ro = opt.realize;
    if (ro.start == "auto" && e.realized.start == "continuation") ro.start = "continuation";
    e.realized = realize_current(ro);
  };
  auto realize_again = [&] {
    realize_again_once();
    keep_if_best();
  };
  auto realize_after_collapse = [&] {
    realize_again();
    hooks.debug("realization after " + std::to_string(collapses) + " edge collapses: " +
                (e.realized.success ? std::string("success") : e.realized.failure));
  };
  // Surface mode: flips and collapses first (the relabelling below mostly comes back to the same
  // folds there, at the cost of a realization per attempt).
  if (T.rows() == 0) repair_surface();
  // Surface mode: a later start realized the layout where the deformed surface's start left a few
  // triangles folded; that state, repaired, may be closer to the deformation (ExtractOptions::
  // repair_deformed_start): the lower ARAP distortion is kept.
  if (T.rows() == 0 && opt.repair_deformed_start && e.realized.success &&
      (e.realized.start == "surface_arap" || e.realized.start == "surface_harmonic")) {
    PolycubeExtraction later = e;
    RealizeOptions ro = opt.realize;
    ro.surface_starts = 1;
    e.realized = realize_polycube(rest, T, B, deformed, e.labels, ro, hooks);
    repair_surface();
    if (e.realized.success) e.realized.start = "surface_deformed_repaired";
    if (e.realized.success && e.realized.arap < later.realized.arap) {
      hooks.debug("the deformed start, repaired: ARAP " + std::to_string(e.realized.arap) + " against " +
                  std::to_string(later.realized.arap) + " from the " + later.realized.start + " start: kept");
      e.alternative = std::make_shared<const PolycubeExtraction>(std::move(later));
    } else {
      hooks.debug("the deformed start, repaired: " +
                  (e.realized.success ? "ARAP " + std::to_string(e.realized.arap) : e.realized.failure) + "; the " +
                  later.realized.start + " start's polycube kept (ARAP " + std::to_string(later.realized.arap) + ")");
      PolycubeExtraction deformed_start = std::move(e);
      e = std::move(later);
      if (deformed_start.realized.success)
        e.alternative = std::make_shared<const PolycubeExtraction>(std::move(deformed_start));
    }
  }
  bool retried = false;
  // A realization with every tet positive but some boundary triangles flipped or flattened in
  // their plane: those triangles sit where their chart cannot reach (typically a chart border
  // that folds back). They take the most frequent other label of their edge neighbours, the
  // labels are cleaned again, and the realization is retried.
  MatX3i N = face_adjacency(B);
  bool widen = false;
  // A realization that could not untangle every tet comes back with the state it reached: where a
  // few tets stay inverted, boundary triangles there face the wrong way too (a chart border that
  // doubles back along a polycube edge), and the same relabelling applies (fandisk at 37.7k tets:
  // 2 tets left inverted, 13 then 4 triangles relabelled, then realized).
  for (int attempt = 0; attempt < opt.relabel_attempts && !e.realized.success &&
                        (e.realized.inverted == 0 ||
                         (e.realized.inverted <= opt.max_relabel_inverted &&
                          e.realized.misoriented_faces <= opt.max_relabel_faces)) &&
                        (e.realized.misoriented_faces > 0 || e.realized.inverted > 0) && e.realized.X.rows() > 0;
       ++attempt) {
    // Tet mode: edges whose ends the realization pinned to one point are collapsed first (a
    // relabelling cannot give the tets between them room).
    if (try_collapse() > 0) {
      N = face_adjacency(CB);
      realize_after_collapse();
      --attempt;
      continue;
    }
    const MatX3d& X = e.realized.X;
    const double diag = (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
    // Misoriented triangles, relabelled by fronts from the others: each takes the most frequent
    // label, other than its own, of its settled neighbours (a folded strip is relabelled whole).
    std::vector<char> bad(CB.rows(), 0);
    int nbad = 0;
    for (int f = 0; f < CB.rows(); ++f) {
      if (!faces_away(X, f, diag)) continue;
      const Vec3 a = X.row(CB(f, 0)), b = X.row(CB(f, 1)), c = X.row(CB(f, 2));
      bad[f] = 1;
      ++nbad;
      hooks.debug("misoriented triangle " + std::to_string(cb_row[f]) + " (" + std::to_string(CB(f, 0)) + " " +
                  std::to_string(CB(f, 1)) + " " + std::to_string(CB(f, 2)) + ") label " + label_name(CL[f]) +
                  ", area " + std::to_string(0.5 * (b - a).cross(c - a).norm()));
    }
    // Where the relabelling came to nothing (no misoriented triangle, or the cleanup undid it) and
    // tets stay inverted, the triangles around their boundary vertices are relabelled instead:
    // there a border vertex is pressed onto a corner of its own polycube edge (spot: an edge of
    // zero length between two corners, the last tet left flat).
    if (widen && e.realized.inverted > 0 && e.realized.T.rows() > 0) {
      std::vector<char> at(X.rows(), 0);
      for (int t : inverted_tets(e.realized))
        for (int j = 0; j < 4; ++j) at[e.realized.T(t, j)] = 1;
      for (int f = 0; f < CB.rows(); ++f)
        if (!bad[f] && (at[CB(f, 0)] || at[CB(f, 1)] || at[CB(f, 2)])) bad[f] = 1, ++nbad;
      hooks.debug("relabelling the " + std::to_string(nbad) + " triangles around the inverted tets");
    }
    std::vector<int> next = CL;
    int changed = 0;
    for (bool progress = true; progress;) {
      progress = false;
      std::vector<std::pair<int, int>> set;
      for (int f = 0; f < CB.rows(); ++f) {
        if (bad[f] != 1) continue;
        int votes[6] = {0, 0, 0, 0, 0, 0};
        for (int k = 0; k < 3; ++k) {
          const int g = N(f, k);
          if (g >= 0 && bad[g] != 1 && next[g] != CL[f]) votes[next[g]]++;
        }
        const int best = static_cast<int>(std::max_element(votes, votes + 6) - votes);
        if (votes[best] > 0) set.emplace_back(f, best);
      }
      for (auto [f, l] : set) {
        next[f] = l;
        bad[f] = 2;
        ++changed;
        progress = true;
      }
    }
    const CleanupStats again = changed > 0 ? cleanup_labels(deformed, CB, next, opt.cleanup, hooks) : CleanupStats{};
    if (next == CL) {
      // Nothing changed, or the cleanup undid the relabelling (e.g. the triangles were zigzags).
      if (!widen && e.realized.inverted > 0) {
        widen = true;
        --attempt;
        continue;
      }
      hooks.debug("relabelling the misoriented triangles is undone by the cleanup; no retry");
      break;
    }
    // A local relabelling that the cleanup turns into a cascade of chart removals (humanoid in
    // surface mode: 35 charts -> 1) gives no better layout.
    if (const ChartReport after = check_charts(CB, static_cast<int>(deformed.rows()), next);
        after.charts < e.charts.charts / 2) {
      hooks.debug("relabelling the misoriented triangles leaves " + std::to_string(after.charts) + " of " +
                  std::to_string(e.charts.charts) + " charts after the cleanup; no retry");
      break;
    }
    CL = std::move(next);
    sync_labels();
    e.cleanup.zigzags += again.zigzags;
    e.cleanup.degenerate += again.degenerate;
    e.cleanup.degree1 += again.degree1;
    e.cleanup.degree2 += again.degree2;
    e.cleanup.degree3 += again.degree3;
    e.cleanup.opposite += again.opposite;
    e.cleanup.rims += again.rims;
    e.cleanup.pinches += again.pinches;
    e.cleanup.smallest_pinch = std::min(e.cleanup.smallest_pinch, again.smallest_pinch);
    e.cleanup.misoriented += changed;
    e.cleanup.relabelled_faces = 0;
    for (size_t f = 0; f < raw.size(); ++f) e.cleanup.relabelled_faces += raw[f] != e.labels[f];
    e.charts = check_charts(CB, static_cast<int>(deformed.rows()), CL);
    hooks.debug("retrying the realization with " + std::to_string(changed) +
                " misoriented triangles relabelled: " + std::to_string(e.charts.charts) + " charts, " +
                std::to_string(e.charts.corners) + " corners");
    realize_again();
    retried = true;
  }
  if (T.rows() == 0 && retried) repair_surface();
  // Tet mode: the relabelling may end (or not start: too many misoriented triangles) in a state
  // with pinned edges too.
  while (try_collapse(true) > 0) realize_after_collapse();
  if (collapses > 0) {
    sync_labels();
    e.edge_collapses = collapses;
    e.collapse_edge_splits = split_edges;
    // The triangles the state was realized with (also on failure: hexes may be extracted through
    // a folded state, PipelineOptions::hex_through_folds).
    e.map_B = CB;
    e.map_labels = CL;
    e.charts = check_charts(CB, static_cast<int>(rest.rows()), CL);
    if (!e.realized.success) {
      e.realized.failure += " (after " + std::to_string(collapses) +
                            " collapses of boundary edges whose ends it pinned to one point)";
    }
  }
  if (!e.realized.success && warm_kept > 0) {
    // The retries from earlier states took a path that ended without a polycube (humanoid, from
    // the CLI's deformation: stuck at an edge that cannot be collapsed); the retries from the
    // deformed mesh may take another.
    hooks.debug("no polycube after " + std::to_string(warm_kept) +
                " retries kept from earlier realizations' states; the retries again, each from the deformed mesh");
    ExtractOptions cold = opt;
    cold.warm_retries = false;
    // Its first realization is this pass's (spot at 20k tets, same polycube: 25.1 -> 20.9 s).
    PolycubeExtraction again = extract(rest, T, B, deformed, cold, hooks, &*first_realization);
    if (again.realized.success || !best_failed) return again;
    e = std::move(again);
  }
  if (!e.realized.success && best_failed) {
    // The best failed state instead of the last, if better (or the last is no folded state).
    const RealizeResult& r = e.realized;
    const RealizeResult& b = best_failed->realized;
    if (!is_folded(r) || std::make_pair(b.inverted, b.misoriented_faces) < std::make_pair(r.inverted, r.misoriented_faces)) {
      const std::string why = r.failure.substr(0, r.failure.find("; kept: ")) + "; kept: the state with " +
                              std::to_string(b.inverted) +
                              " tets inverted and " + std::to_string(b.misoriented_faces) +
                              " boundary triangles facing away";
      e = std::move(*best_failed);
      e.realized.failure = why;
    }
  }
  return e;
}

// extract_polycube without the unflat charts' diagnostic.
PolycubeExtraction extract_both_modes(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                                      const ExtractOptions& opt, const Hooks& hooks) {
  if (T.rows() > 0) {
    ExtractOptions o = opt;
    if (opt.corner_splits == "on") o.realize.split_corner_edges = true;
    PolycubeExtraction e = extract(rest, T, B, deformed, o, hooks, nullptr);
    if (e.realized.success || opt.corner_splits != "auto" || o.realize.split_corner_edges) return e;
    // A polycube corner whose star has no free vertex near it can keep a tet inverted that no
    // retry opens (tet/hand); splitting its interior edges makes room, but changes the realization
    // of shapes realized without (spot), so it is the retry.
    hooks.warn("no valid polycube (" + e.realized.failure +
               "); extracting again with the interior edges from the corners split");
    o.realize.split_corner_edges = true;
    PolycubeExtraction again = extract(rest, T, B, deformed, o, hooks, nullptr);
    CornerSplitRetry c;
    c.tried = true;
    c.reason = e.realized.failure;
    c.success = again.realized.success;
    c.inverted = again.realized.inverted;
    c.kept = again.realized.success || (is_folded(again.realized) &&
                                        (!is_folded(e.realized) || again.realized.inverted < e.realized.inverted));
    PolycubeExtraction& kept = c.kept ? again : e;
    kept.corner_split_retry = c;
    return std::move(kept);
  }
  ExtractOptions surface = opt;
  surface.cleanup.pinch_above = opt.cleanup.pinch_above_surface;
  surface.collapsed_ratio = opt.collapsed_ratio_surface;
  PolycubeExtraction e = extract(rest, T, B, deformed, surface, hooks, nullptr);
  // The pinches opened below the volume threshold can leave a layout no start realizes
  // (humanoid, 2026-11-28): the volume threshold's layout is tried before giving up, unless no
  // such pinch was opened (the same labels, the same failure).
  if (e.realized.success || !(e.cleanup.smallest_pinch <= opt.cleanup.pinch_above)) return e;
  hooks.debug("no polycube realized with the pinches of charts above " + std::to_string(opt.cleanup.pinch_above_surface) +
              " of the area opened (" + e.realized.failure + "); extracting again with only those above " +
              std::to_string(opt.cleanup.pinch_above));
  ExtractOptions coarser = surface;
  coarser.cleanup.pinch_above = opt.cleanup.pinch_above;
  PolycubeExtraction again = extract(rest, T, B, deformed, coarser, hooks, nullptr);
  return again.realized.success ? again : e;
}

}  // namespace

PolycubeExtraction extract_polycube(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                                    const ExtractOptions& opt, const Hooks& hooks) {
  PolycubeExtraction e = extract_both_modes(rest, T, B, deformed, opt, hooks);
  if (opt.unflat_above > 0 && deformed.rows() > 0 && static_cast<int>(e.labels.size()) == B.rows()) {
    const double diagonal = (deformed.colwise().maxCoeff() - deformed.colwise().minCoeff()).norm();
    e.unflat = unflat_charts(deformed, B, e.labels, opt.unflat_above * diagonal);
    for (UnflatChart& u : e.unflat) {
      const int f = u.farthest;
      u.at = (rest.row(B(f, 0)) + rest.row(B(f, 1)) + rest.row(B(f, 2))).transpose() / 3.0;
    }
  }
  return e;
}

int flip_folded_edges(const MatX3d& X, MatX3i& F, const std::vector<int>& labels) {
  const double diag = (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
  auto faces = [&](int a, int b, int c, int label) { return faces_label(X, a, b, c, label, diag); };
  int flips = 0;
  for (int pass = 0; pass < 5; ++pass) {
    std::map<std::pair<int, int>, int> face_of;  // directed edge -> face
    for (int f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) face_of[{F(f, k), F(f, (k + 1) % 3)}] = f;
    int done = 0;
    for (int t = 0; t < F.rows(); ++t) {
      if (faces(F(t, 0), F(t, 1), F(t, 2), labels[t])) continue;
      for (int k = 0; k < 3; ++k) {
        const int a = F(t, k), b = F(t, (k + 1) % 3), c = F(t, (k + 2) % 3);
        const auto it = face_of.find({b, a});
        if (it == face_of.end()) continue;
        const int u = it->second;
        if (labels[u] != labels[t]) continue;
        int d = -1;
        for (int j = 0; j < 3; ++j)
          if (F(u, j) != a && F(u, j) != b) d = F(u, j);
        if (d < 0 || face_of.count({c, d}) || face_of.count({d, c})) continue;
        // (a, b, c) + (b, a, d) -> (c, a, d) + (c, d, b)
        if (!faces(c, a, d, labels[t]) || !faces(c, d, b, labels[t])) continue;
        for (int j = 0; j < 3; ++j) {
          face_of.erase({F(t, j), F(t, (j + 1) % 3)});
          face_of.erase({F(u, j), F(u, (j + 1) % 3)});
        }
        F.row(t) << c, a, d;
        F.row(u) << c, d, b;
        for (int j = 0; j < 3; ++j) {
          face_of[{F(t, j), F(t, (j + 1) % 3)}] = t;
          face_of[{F(u, j), F(u, (j + 1) % 3)}] = u;
        }
        ++done;
        break;
      }
    }
    flips += done;
    if (done == 0) break;
  }
  return flips;
}

int collapse_folded_edges(const MatX3d& rest, const MatX3d& X, MatX3i& F, std::vector<int>& labels,
                          std::vector<int>& merged_into) {
  const int nv = static_cast<int>(rest.rows());
  if (static_cast<int>(merged_into.size()) != nv) merged_into.assign(nv, -1);
  const double diag = (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
  std::vector<char> folded(F.rows(), 0), on_border(nv, 0);
  for (int f = 0; f < F.rows(); ++f) folded[f] = !faces_label(X, F(f, 0), F(f, 1), F(f, 2), labels[f], diag);
  for (const auto& loop : border_loops(F))
    for (const auto& e : loop) on_border[e[0]] = on_border[e[1]] = 1;
  std::vector<std::vector<int>> vf(nv);
  for (int f = 0; f < F.rows(); ++f)
    for (int j = 0; j < 3; ++j) vf[F(f, j)].push_back(f);
  // Candidates: the edges of folded triangles, those between two folded triangles first (a chart
  // border segment running the wrong way folds both its triangles), then the shortest at rest.
  std::vector<std::tuple<double, int, int>> cand;
  for (int f = 0; f < F.rows(); ++f) {
    if (!folded[f]) continue;
    for (int k = 0; k < 3; ++k) {
      const int a = std::min(F(f, k), F(f, (k + 1) % 3)), b = std::max(F(f, k), F(f, (k + 1) % 3));
      int folded_sides = 0;
      for (int g : vf[a])
        if (folded[g] && (F(g, 0) == b || F(g, 1) == b || F(g, 2) == b)) ++folded_sides;
      cand.emplace_back((folded_sides >= 2 ? 0.0 : 1.0) * diag + (rest.row(a) - rest.row(b)).norm(), a, b);
    }
  }
  std::sort(cand.begin(), cand.end());
  cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  std::vector<char> removed(F.rows(), 0), touched(nv, 0);
  int collapses = 0;
  auto live_faces = [&](int v) {
    std::vector<int> out;
    for (int g : vf[v])
      if (!removed[g] && (F(g, 0) == v || F(g, 1) == v || F(g, 2) == v)) out.push_back(g);
    return out;
  };
  auto ring = [&](int v) {
    std::set<int> out;
    for (int g : live_faces(v))
      for (int j = 0; j < 3; ++j)
        if (F(g, j) != v) out.insert(F(g, j));
    return out;
  };
  for (const auto& [score, a, b] : cand) {
    if (touched[a] || touched[b] || on_border[a] || on_border[b]) continue;
    std::vector<int> shared;  // the edge's two triangles
    for (int g : live_faces(a))
      if (F(g, 0) == b || F(g, 1) == b || F(g, 2) == b) shared.push_back(g);
    if (shared.size() != 2) continue;
    // Link condition: a and b have exactly the two opposite vertices as common neighbours.
    const std::set<int> ra = ring(a), rb = ring(b);
    int common = 0;
    for (int v : ra) common += rb.count(v) > 0;
    if (common != 2) continue;
    // The kept vertex must not gain a plane: the labels of both ends' remaining triangles must be
    // among the kept one's labels before the collapse (so a corner of three charts whose triangle
    // at the corner folded can absorb its neighbours on the chart edges).
    auto label_set = [&](int v, bool with_shared) {
      std::set<int> out;
      for (int g : live_faces(v))
        if (with_shared || (g != shared[0] && g != shared[1])) out.insert(labels[g]);
      return out;
    };
    std::set<int> after = label_set(a, false);
    for (int l : label_set(b, false)) after.insert(l);
    const std::set<int> la = label_set(a, true), lb = label_set(b, true);
    const bool keep_a = std::includes(la.begin(), la.end(), after.begin(), after.end());
    const bool keep_b = std::includes(lb.begin(), lb.end(), after.begin(), after.end());
    int gone = -1, kept = -1;
    if (keep_b && (!keep_a || lb.size() >= la.size())) gone = a, kept = b;
    else if (keep_a) gone = b, kept = a;
    else continue;
    // No triangle of the rest surface turns over.
    bool ok = true;
    const std::vector<int> moved = live_faces(gone);
    for (int g : moved) {
      if (g == shared[0] || g == shared[1]) continue;
      const Vec3 p0 = rest.row(F(g, 0)), p1 = rest.row(F(g, 1)), p2 = rest.row(F(g, 2));
      const Vec3 n0 = (p1 - p0).cross(p2 - p0);
      Vec3 q[3] = {p0, p1, p2};
      for (int j = 0; j < 3; ++j)
        if (F(g, j) == gone) q[j] = rest.row(kept).transpose();
      if ((q[1] - q[0]).cross(q[2] - q[0]).dot(n0) <= 0) ok = false;
    }
    if (!ok) continue;
    for (int g : moved)
      for (int j = 0; j < 3; ++j)
        if (F(g, j) == gone) F(g, j) = kept, vf[kept].push_back(g);
    removed[shared[0]] = removed[shared[1]] = 1;
    merged_into[gone] = kept;
    for (int v : ra) touched[v] = 1;
    for (int v : rb) touched[v] = 1;
    touched[a] = touched[b] = 1;
    ++collapses;
  }
  if (collapses == 0) return 0;
  MatX3i F2(F.rows() - 2 * collapses, 3);
  std::vector<int> l2;
  for (int f = 0; f < F.rows(); ++f)
    if (!removed[f]) {
      F2.row(static_cast<Eigen::Index>(l2.size())) = F.row(f);
      l2.push_back(labels[f]);
    }
  F = std::move(F2);
  labels = std::move(l2);
  return collapses;
}

}  // namespace polycube::chart

namespace polycube::chart {

int collapse_slim_triangles(MatX3d& rest, MatX3d& X, MatX4i& T, MatX3i& B, double min_angle_deg,
                            std::vector<int>& merged_into, int max_rounds, int* refused, const Hooks& hooks) {
  const int n = static_cast<int>(rest.rows());
  merged_into.assign(n, -1);
  const double slim_cos = std::cos(min_angle_deg * M_PI / 180.0);
  int made = 0;
  std::vector<int> labels;
  for (int round = 0; round < max_rounds; ++round) {
    std::vector<std::pair<double, std::array<int, 3>>> slim;
    for (int f = 0; f < B.rows(); ++f) {
      const double c = deform::smallest_angle_cos(X, B(f, 0), B(f, 1), B(f, 2));
      if (c > slim_cos) slim.push_back({-c, {B(f, 0), B(f, 1), B(f, 2)}});
    }
    std::sort(slim.begin(), slim.end());
    // Neighbours at the round's start: a collapse changes nothing outside its ends' neighbourhoods.
    std::vector<std::vector<int>> near(n);
    for (int t = 0; t < T.rows(); ++t)
      for (int k = 0; k < 4; ++k)
        for (int j = 0; j < 4; ++j) near[T(t, k)].push_back(T(t, j));
    std::vector<char> touched(n, 0);
    int round_made = 0, left = 0;
    for (const auto& [c, f] : slim) {
      if (touched[f[0]] || touched[f[1]] || touched[f[2]]) {
        ++left;
        continue;
      }
      int best = 0;
      double shortest = std::numeric_limits<double>::infinity();
      for (int k = 0; k < 3; ++k) {
        const double len = (X.row(f[k]) - X.row(f[(k + 1) % 3])).norm();
        if (len < shortest) shortest = len, best = k;
      }
      int keep = f[best], drop = f[(best + 1) % 3];
      // Both ends' stars are touched either way (the tets around them are checked or changed).
      for (int v : {keep, drop})
        for (int u : near[v]) touched[u] = 1;
      labels.assign(B.rows(), 0);
      // At rest the merged vertex is one of the two input vertices (the rest boundary stays made of
      // input vertices, on the input surface); in X it may move along the edge or inwards.
      Vec3 at;
      std::string why;
      // A collapse is kept only if no tet around the merged vertex k, at `at`, is left nearly flat in
      // X (under kCrushedRatio of its rest volume): such tets block the resumed deformation.
      auto crushes = [&](int k) {
        auto x = [&](int v) -> Vec3 { return v == k ? at : Vec3(X.row(v).transpose()); };
        for (int t = 0; t < T.rows(); ++t) {
          if (T(t, 0) != k && T(t, 1) != k && T(t, 2) != k && T(t, 3) != k) continue;
          const Vec3 a = rest.row(T(t, 0)), b = rest.row(T(t, 1)), c = rest.row(T(t, 2)), d = rest.row(T(t, 3));
          const Vec3 p = x(T(t, 0)), q = x(T(t, 1)), r = x(T(t, 2)), u = x(T(t, 3));
          const double vr = (b - a).dot((c - a).cross(d - a)), vx = (q - p).dot((r - p).cross(u - p));
          if (vx < deform::DeformResult::kCrushedRatio * vr) return true;
        }
        return false;
      };
      // Collapses (k, d), undone if it crushes a tet; `reason` says why it was not made.
      const MatX4i T0 = T;
      const MatX3i B0 = B;
      auto attempt = [&](int k, int d, std::string& reason) {
        if (!collapse_tet_edge(rest, X, T, B, labels, k, d, &reason, nullptr, &at)) return false;
        if (!crushes(k)) return true;
        reason = "a tet would be left nearly flat in the deformed mesh";
        T = T0;
        B = B0;
        labels.assign(B.rows(), 0);
        return false;
      };
      bool ok = attempt(keep, drop, why);
      if (!ok) {
        std::string why2;
        ok = attempt(drop, keep, why2);
        if (ok)
          std::swap(keep, drop);
        else
          why += "; the other way: " + why2;
      }
      if (!ok) {
        ++left;
        hooks.debug("slim triangle " + std::to_string(f[0]) + "-" + std::to_string(f[1]) + "-" + std::to_string(f[2]) +
                    " not collapsed: " + why);
        continue;
      }
      X.row(keep) = at.transpose();
      merged_into[drop] = keep;
      ++round_made;
    }
    made += round_made;
    if (refused) *refused = left;
    if (round_made == 0) break;
  }
  // Merged vertices hold their partner's positions (through chains of merges).
  for (int v = 0; v < n; ++v) {
    int k = merged_into[v];
    if (k < 0) continue;
    while (merged_into[k] >= 0) k = merged_into[k];
    merged_into[v] = k;
    rest.row(v) = rest.row(k);
    X.row(v) = X.row(k);
  }
  return made;
}

std::vector<int> drop_merged_vertices(const std::vector<int>& merged_into, std::initializer_list<MatX3d*> positions,
                                      MatX4i& T, MatX3i& B) {
  const int n = static_cast<int>(merged_into.size());
  std::vector<int> o2n(n, -1);
  int m = 0;
  for (int v = 0; v < n; ++v)
    if (merged_into[v] < 0) o2n[v] = m++;
  for (MatX3d* P : positions) {
    for (int v = 0; v < n; ++v)
      if (o2n[v] >= 0 && o2n[v] != v) P->row(o2n[v]) = P->row(v);  // o2n[v] <= v: in place
    P->conservativeResize(m, 3);
  }
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) T(t, k) = o2n[T(t, k)];
  for (Eigen::Index f = 0; f < B.rows(); ++f)
    for (int k = 0; k < 3; ++k) B(f, k) = o2n[B(f, k)];
  return o2n;
}

bool collapse_tet_edge(const MatX3d& rest, const MatX3d& deformed, MatX4i& T, MatX3i& B, std::vector<int>& labels,
                       int keep, int drop, std::string* why, std::vector<int>* removed, Vec3* deformed_at,
                       Vec3* rest_at, bool deformed_may_tangle, bool rest_may_tangle) {
  auto refuse = [&](const char* reason) {
    if (why) *why = reason;
    return false;
  };
  if (keep == drop) return refuse("the same vertex");
  auto has = [](auto row, int v) {
    for (int j = 0; j < row.size(); ++j)
      if (row[j] == v) return true;
    return false;
  };
  // Boundary: the edge's two triangles go, the others of `drop` move to `keep`.
  std::vector<int> gone_faces, moved_faces, keep_faces;
  for (int f = 0; f < B.rows(); ++f) {
    const bool hk = has(B.row(f), keep), hd = has(B.row(f), drop);
    if (hk && hd) gone_faces.push_back(f);
    else if (hd) moved_faces.push_back(f);
    else if (hk) keep_faces.push_back(f);
  }
  if (gone_faces.size() != 2) return refuse("not an edge of the boundary");
  std::vector<int> gone_tets, star;  // star: the tets of `keep` after the collapse
  for (int t = 0; t < T.rows(); ++t) {
    const bool hk = has(T.row(t), keep), hd = has(T.row(t), drop);
    if (hk && hd) gone_tets.push_back(t);
    else if (hk || hd) star.push_back(t);
  }
  if (gone_tets.empty()) return refuse("not an edge of the tets");
  auto tet_after = [&](int t) {
    std::array<int, 4> q{T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
    for (int& v : q)
      if (v == drop) v = keep;
    return q;
  };
  // Positive at rest and deformed (oriented as the tet was at rest).
  auto volume = [](const MatX3d& P, const std::array<int, 4>& q) {
    return tet_volume(P.row(q[0]).transpose(), P.row(q[1]).transpose(), P.row(q[2]).transpose(),
                      P.row(q[3]).transpose());
  };
  // At rest the merged vertex stays where `keep` is or, with rest_at, may take the edge's midpoint,
  // `drop`'s position or a quarter point (the first that keeps every tet positive): it stays on
  // the input surface's edge.
  auto positive_with = [&](const MatX3d& P, const Vec3& p) {
    for (int t : star) {
      const double sign = volume(rest, {T(t, 0), T(t, 1), T(t, 2), T(t, 3)}) > 0 ? 1.0 : -1.0;
      const auto q = tet_after(t);
      Vec3 c[4];
      for (int j = 0; j < 4; ++j) c[j] = q[j] == keep ? p : Vec3(P.row(q[j]).transpose());
      if (!(sign * tet_volume(c[0], c[1], c[2], c[3]) > 0)) return false;
    }
    return true;
  };
  // The first of `at` that keeps the star positive in P (written to *out), else, with may_tangle,
  // the edge's midpoint in P (the caller untangles there).
  auto place = [&](const MatX3d& P, const std::vector<Vec3>& at, Vec3* out, bool may_tangle) {
    for (const Vec3& p : at)
      if (positive_with(P, p)) {
        if (out) *out = p;
        return true;
      }
    if (!may_tangle || !out) return false;
    *out = 0.5 * (P.row(keep) + P.row(drop)).transpose();
    return true;
  };
  {
    std::vector<Vec3> at{rest.row(keep).transpose()};
    if (rest_at) {
      const Vec3 k = rest.row(keep).transpose(), d = rest.row(drop).transpose();
      at.push_back(0.5 * (k + d));
      at.push_back(d);
      at.push_back(0.75 * k + 0.25 * d);
      at.push_back(0.25 * k + 0.75 * d);
    }
    if (!place(rest, at, rest_at, rest_may_tangle)) return refuse("a tet would turn over at rest");
  }
  // In the deformed mesh (only the start of the realization) the merged vertex may sit at either
  // end, the midpoint, the quarter points, or off the edge towards the centroid of the star's other
  // vertices (humanoid: a chart-border vertex and a corner 0.025 apart in the deformed mesh, whose
  // merged vertex turned a tet over at both ends and the midpoint).
  {
    std::vector<Vec3> at{deformed.row(keep).transpose()};
    if (deformed_at) {
      const Vec3 k = deformed.row(keep).transpose(), d = deformed.row(drop).transpose(), mid = 0.5 * (k + d);
      at.push_back(d);
      at.push_back(mid);
      at.push_back(0.75 * k + 0.25 * d);
      at.push_back(0.25 * k + 0.75 * d);
      Vec3 centroid = Vec3::Zero();
      int count = 0;
      for (int t : star)
        for (int j = 0; j < 4; ++j)
          if (T(t, j) != keep && T(t, j) != drop) centroid += deformed.row(T(t, j)).transpose(), ++count;
      if (count > 0) {
        centroid /= count;
        for (double w : {0.25, 0.5, 0.75, 1.0}) at.push_back((1 - w) * mid + w * centroid);
      }
    }
    if (!place(deformed, at, deformed_at, deformed_may_tangle))
      return refuse("a tet would turn over in the deformed mesh");
  }
  // Link of `keep`: the triangle opposite it in each star tet.
  std::map<std::pair<int, int>, int> edge_count;
  std::map<int, std::vector<std::array<int, 3>>> around;  // link vertex -> link triangles at it
  std::set<std::array<int, 3>> tris;
  int nlt = 0;
  for (int t : star) {
    const auto q = tet_after(t);
    std::array<int, 3> o{};
    int m = 0;
    for (int v : q)
      if (v != keep) o[m++] = v;
    if (m != 3) return refuse("a tet would keep both ends");
    std::array<int, 3> s = o;
    std::sort(s.begin(), s.end());
    if (!tris.insert(s).second) return refuse("two tets would coincide");
    ++nlt;
    for (int a = 0; a < 3; ++a) {
      const int u = s[a], v = s[(a + 1) % 3];
      edge_count[{std::min(u, v), std::max(u, v)}]++;
      around[s[a]].push_back(s);
    }
  }
  // Its border edges must be the edges opposite `keep` in the boundary triangles around it.
  std::set<std::pair<int, int>> border, expected;
  for (const auto& [e, c] : edge_count) {
    if (c > 2) return refuse("a face would be shared by three tets");
    if (c == 1) border.insert(e);
  }
  for (const std::vector<int>* list : {&moved_faces, &keep_faces})
    for (int f : *list) {
      std::array<int, 3> q{B(f, 0), B(f, 1), B(f, 2)};
      int o[2], m = 0;
      for (int v : q)
        if (v != keep && v != drop) o[m++] = v;
      if (m != 2) return refuse("a boundary triangle would keep both ends");
      if (!expected.insert({std::min(o[0], o[1]), std::max(o[0], o[1])}).second)
        return refuse("two boundary triangles would coincide");
    }
  if (border != expected) return refuse("the boundary would not match the tets (link condition)");
  // A disk: connected, Euler characteristic 1, and a manifold at each vertex (the link
  // triangles at a vertex are one fan).
  const int nle = static_cast<int>(edge_count.size());
  const int nlv = static_cast<int>(around.size());
  if (nlv - nle + nlt != 1) return refuse("the star of the kept vertex would not be a ball (link condition)");
  {
    std::map<std::array<int, 3>, int> id;
    for (const auto& s : tris) id.emplace(s, static_cast<int>(id.size()));
    UnionFind all(id.size());
    for (const auto& [v, list] : around) {
      UnionFind fan(list.size());
      for (size_t i = 0; i < list.size(); ++i)
        for (size_t j = i + 1; j < list.size(); ++j) {
          int shared = 0;
          for (int a : list[i])
            for (int b : list[j]) shared += a == b;
          if (shared == 2) {
            fan.unite(static_cast<int>(i), static_cast<int>(j));
            all.unite(id[list[i]], id[list[j]]);
          }
        }
      int roots = 0;
      for (size_t i = 0; i < list.size(); ++i) roots += fan.find(static_cast<int>(i)) == static_cast<int>(i);
      if (roots != 1) return refuse("the star of the kept vertex would be pinched (link condition)");
    }
    int roots = 0;
    for (size_t i = 0; i < id.size(); ++i) roots += all.find(static_cast<int>(i)) == static_cast<int>(i);
    if (roots != 1) return refuse("the star of the kept vertex would fall apart (link condition)");
  }
  // Apply.
  for (int t : star)
    for (int j = 0; j < 4; ++j)
      if (T(t, j) == drop) T(t, j) = keep;
  for (int f : moved_faces)
    for (int j = 0; j < 3; ++j)
      if (B(f, j) == drop) B(f, j) = keep;
  auto remove_rows = [](auto& M, const std::vector<int>& rows) {
    std::vector<char> gone(M.rows(), 0);
    for (int r : rows) gone[r] = 1;
    int w = 0;
    for (int r = 0; r < M.rows(); ++r)
      if (!gone[r]) M.row(w++) = M.row(r);
    M.conservativeResize(w, Eigen::NoChange);
  };
  remove_rows(T, gone_tets);
  remove_rows(B, gone_faces);
  for (int i = static_cast<int>(gone_faces.size()) - 1; i >= 0; --i) labels.erase(labels.begin() + gone_faces[i]);
  if (removed) *removed = gone_faces;
  return true;
}

}  // namespace polycube::chart

namespace polycube::chart {

std::vector<std::pair<int, int>> split_edges_for_collapse(MatX3d& rest, MatX3d& deformed, MatX4i& T,
                                                          const MatX3i& B, int keep, int drop) {
  using Edge = std::pair<int, int>;
  auto ordered = [](int a, int b) { return a < b ? Edge(a, b) : Edge(b, a); };
  std::set<Edge> boundary_edges;
  for (int f = 0; f < B.rows(); ++f)
    for (int j = 0; j < 3; ++j) boundary_edges.insert(ordered(B(f, j), B(f, (j + 1) % 3)));
  // Splits edge (a, b) at its midpoint: every tet of the edge is halved (orientation kept).
  std::vector<Edge> parents;
  auto split = [&](int a, int b) {
    const int m = static_cast<int>(rest.rows());
    rest.conservativeResize(m + 1, Eigen::NoChange);
    deformed.conservativeResize(m + 1, Eigen::NoChange);
    rest.row(m) = 0.5 * (rest.row(a) + rest.row(b));
    deformed.row(m) = 0.5 * (deformed.row(a) + deformed.row(b));
    std::vector<int> edge_tets;
    for (int t = 0; t < T.rows(); ++t) {
      bool ha = false, hb = false;
      for (int j = 0; j < 4; ++j) ha |= T(t, j) == a, hb |= T(t, j) == b;
      if (ha && hb) edge_tets.push_back(t);
    }
    Eigen::Index next = T.rows();
    T.conservativeResize(next + static_cast<Eigen::Index>(edge_tets.size()), Eigen::NoChange);
    for (int t : edge_tets) {
      T.row(next) = T.row(t);
      for (int j = 0; j < 4; ++j) {
        if (T(t, j) == b) T(t, j) = m;        // the half at a
        if (T(next, j) == a) T(next, j) = m;  // the half at b
      }
      ++next;
    }
    parents.emplace_back(a, b);
  };
  // A few rounds: vertices first (the edge from `drop` split), then one edge of both links outside
  // the edge's ring (a chord between two of their vertices) per round.
  for (int round = 0; round < 8; ++round) {
    std::set<int> nk, nd, ring;
    std::set<Edge> ek, ed, ering;
    std::set<std::array<int, 3>> opposite_drop;  // triangles opposite `drop` in its tets without `keep`
    std::vector<std::array<int, 3>> opposite_keep;
    for (int t = 0; t < T.rows(); ++t) {
      bool hk = false, hd = false;
      for (int j = 0; j < 4; ++j) hk |= T(t, j) == keep, hd |= T(t, j) == drop;
      if (!hk && !hd) continue;
      std::array<int, 3> o{};
      int m = 0;
      for (int j = 0; j < 4; ++j)
        if (T(t, j) != keep && T(t, j) != drop) o[m++] = T(t, j);
      for (int i = 0; i < m; ++i) {
        if (hk) nk.insert(o[i]);
        if (hd) nd.insert(o[i]);
        if (hk && hd) ring.insert(o[i]);
        for (int j = i + 1; j < m; ++j) {
          const Edge e = ordered(o[i], o[j]);
          if (hk && hd) ering.insert(e);
          else if (hk) ek.insert(e);
          else ed.insert(e);
        }
      }
      if (m == 3) {
        std::sort(o.begin(), o.end());
        if (hd) opposite_drop.insert(o);
        else opposite_keep.push_back(o);
      }
    }
    // Vertices of both stars outside the edge's ring, and the vertices of triangles with a tet at
    // each end (their tets would coincide even where the three are on the ring). Boundary edges
    // are never split (that would change the surface).
    std::set<int> split_to;
    for (int w : nd)
      if (nk.count(w) && !ring.count(w)) split_to.insert(w);
    for (const auto& o : opposite_keep)
      if (opposite_drop.count(o)) split_to.insert(o.begin(), o.end());
    // Where the edge from `drop` is a boundary edge, the one from `keep` (humanoid: a boundary
    // triangle of `drop` would land on an interior face of `keep`'s star).
    std::vector<Edge> to;
    for (int w : split_to)
      if (!boundary_edges.count(ordered(drop, w))) to.emplace_back(drop, w);
      else if (!boundary_edges.count(ordered(keep, w))) to.emplace_back(keep, w);
    if (!to.empty()) {
      for (const Edge& e : to) split(e.first, e.second);
      continue;
    }
    // A chord (u, v) leaves `drop`'s link when the edge from `drop` to u or v is split (then only
    // the new vertex, on the ring or in neither star, is joined to it), else `keep`'s from the edge
    // to u or v, else it is split itself; one split per round, the stars are measured again.
    bool made = false;
    for (const Edge& e : ek) {
      if (!ed.count(e) || ering.count(e)) continue;
      for (const Edge& s : {ordered(drop, e.first), ordered(drop, e.second), ordered(keep, e.first),
                            ordered(keep, e.second), e})
        if (!boundary_edges.count(s)) {
          split(s.first, s.second);
          made = true;
          break;
        }
      if (made) break;
    }
    if (!made) break;
  }
  return parents;
}

PolycubeExtraction polycube_from_map(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& X_in,
                                     double tolerance, int max_inverted) {
  Stopwatch sw;
  if (X_in.rows() != rest.rows())
    throw Error(ErrorKind::InvalidMesh, "the polycube map has " + std::to_string(X_in.rows()) +
                                            " vertices where the tet mesh has " + std::to_string(rest.rows()));
  PolycubeExtraction ex;
  RealizeResult& r = ex.realized;
  r.rest = rest;
  r.T = T;
  r.X = X_in;
  r.start = "given";
  Eigen::AlignedBox3d box;
  for (int v = 0; v < X_in.rows(); ++v) box.extend(X_in.row(v).transpose());
  const double diag = box.diagonal().norm();
  // Labels: the dominant axis of each triangle's normal.
  ex.labels.resize(B.rows());
  for (int f = 0; f < B.rows(); ++f) {
    const Vec3 n = deform::area_normal(X_in, B(f, 0), B(f, 1), B(f, 2));
    int k = 0;
    n.cwiseAbs().maxCoeff(&k);
    if (!(n.norm() > 1e-14 * diag * diag))
      throw Error(ErrorKind::InvalidMesh, "polycube map: boundary triangle " + std::to_string(f) + " (vertices " +
                                              std::to_string(B(f, 0)) + " " + std::to_string(B(f, 1)) + " " +
                                              std::to_string(B(f, 2)) + ") has zero area");
    ex.labels[f] = 2 * k + (n[k] < 0 ? 1 : 0);
  }
  // Planes: per axis, the vertices of touching triangles of that axis share one coordinate.
  int worst_v = -1, worst_k = 0;
  double worst_h = 0;
  for (int k = 0; k < 3; ++k) {
    UnionFind uf(static_cast<int>(X_in.rows()));
    for (int f = 0; f < B.rows(); ++f)
      if (ex.labels[f] / 2 == k) uf.unite(B(f, 0), B(f, 1)), uf.unite(B(f, 0), B(f, 2));
    std::vector<double> sum(X_in.rows(), 0.0);
    std::vector<int> count(X_in.rows(), 0);
    std::vector<char> on(X_in.rows(), 0);
    for (int f = 0; f < B.rows(); ++f)
      if (ex.labels[f] / 2 == k)
        for (int j = 0; j < 3; ++j) on[B(f, j)] = 1;
    for (int v = 0; v < X_in.rows(); ++v)
      if (on[v]) sum[uf.find(v)] += X_in(v, k), ++count[uf.find(v)];
    for (int v = 0; v < X_in.rows(); ++v) {
      if (!on[v]) continue;
      const double h = sum[uf.find(v)] / count[uf.find(v)];
      const double off = std::abs(X_in(v, k) - h) / std::max(diag, 1e-300);
      if (off > r.planarity_error) r.planarity_error = off, worst_v = v, worst_k = k, worst_h = h;
      r.X(v, k) = h;
    }
  }
  if (r.planarity_error > tolerance)
    throw Error(ErrorKind::InvalidMesh, "polycube map: vertex " + std::to_string(worst_v) + " is " +
                                            std::to_string(r.planarity_error) + " of the bbox diagonal off the " +
                                            std::string(1, "xyz"[worst_k]) + " plane of its charts (at " +
                                            std::to_string(worst_h) + "): not an axis-aligned polycube");
  // Every tet positive, every triangle facing its label.
  int first = -1;
  for (int t = 0; t < T.rows(); ++t) {
    const Vec3 a = r.X.row(T(t, 0)), b = r.X.row(T(t, 1)), c = r.X.row(T(t, 2)), d = r.X.row(T(t, 3));
    if (!((b - a).dot((c - a).cross(d - a)) > 0) && r.inverted++ == 0) first = t;
  }
  const std::string inverted_why = std::to_string(r.inverted) + " tets are inverted or flat in the polycube (first: tet " +
                                   std::to_string(first) + ")";
  if (r.inverted > max_inverted) throw Error(ErrorKind::InvalidMesh, "polycube map: " + inverted_why);
  check_faces(B, ex.labels, r);
  if (r.misoriented_faces > 0)
    throw Error(ErrorKind::InvalidMesh, "polycube map: " + std::to_string(r.misoriented_faces) +
                                            " boundary triangles do not face their plane's direction once planar");
  for (int k = 0; k < 3; ++k) {
    std::vector<double> h;
    for (int f = 0; f < B.rows(); ++f)
      if (ex.labels[f] / 2 == k) h.push_back(r.X(B(f, 0), k));
    std::sort(h.begin(), h.end());
    r.planes[k] = static_cast<int>(std::unique(h.begin(), h.end()) - h.begin());
  }
  r.arap = deform::arap_energy(r.X, T, deform::ArapRest::build(rest, T), 1.0, nullptr, nullptr);
  r.isometric = isometric_distortion(rest, r.X, T);
  ex.charts = check_charts(B, static_cast<int>(X_in.rows()), ex.labels);
  ex.initial_charts = ex.charts.charts;
  r.success = r.inverted == 0;
  if (!r.success) r.failure = inverted_why;
  r.seconds = sw.seconds();
  return ex;
}

}  // namespace polycube::chart
