#include "polycube/chart/extract.h"

#include <algorithm>
#include <map>

#include "polycube/core/topology.h"
#include "polycube/deform/energies.h"

namespace polycube::chart {

PolycubeExtraction extract_polycube(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                                    const ExtractOptions& opt, const Hooks& hooks) {
  PolycubeExtraction e;
  e.labels = label_by_normal(deformed, B);
  e.initial_charts = build_charts(deformed, B, e.labels).count();
  const std::vector<int> raw = e.labels;
  const int collapsed = relabel_collapsed(rest, deformed, B, e.labels, opt.collapsed_ratio);
  e.cleanup = cleanup_labels(deformed, B, e.labels, opt.cleanup);
  e.cleanup.collapsed = collapsed;
  e.cleanup.relabelled_faces = 0;
  for (size_t f = 0; f < raw.size(); ++f) e.cleanup.relabelled_faces += raw[f] != e.labels[f];
  if (collapsed > 0) hooks.debug(std::to_string(collapsed) + " collapsed triangles took their neighbours' label");
  e.charts = check_charts(B, static_cast<int>(deformed.rows()), e.labels);
  hooks.debug("charts: " + std::to_string(e.initial_charts) + " labelled, " + std::to_string(e.charts.charts) +
              " after cleanup (" + std::to_string(e.cleanup.zigzags) + " zigzag triangles, " +
              std::to_string(e.cleanup.degree1 + e.cleanup.degree2 + e.cleanup.degree3) + " charts removed), " +
              std::to_string(e.charts.corners) + " corners");
  for (const auto& p : e.charts.problems) hooks.debug("chart graph: " + p);
  e.realized = realize_polycube(rest, T, B, deformed, e.labels, opt.realize, hooks);
  // A realization with every tet positive but some boundary triangles flipped or flattened in
  // their plane: those triangles sit where their chart cannot reach (typically a chart border
  // that folds back). They take the most frequent other label of their edge neighbours, the
  // labels are cleaned again, and the realization is retried.
  const MatX3i N = face_adjacency(B);
  for (int attempt = 0; attempt < opt.relabel_attempts && !e.realized.success && e.realized.inverted == 0 &&
                        e.realized.misoriented_faces > 0 && e.realized.X.rows() > 0;
       ++attempt) {
    const MatX3d& X = e.realized.X;
    const double diag = (X.colwise().maxCoeff() - X.colwise().minCoeff()).norm();
    // Misoriented triangles, relabelled by fronts from the others: each takes the most frequent
    // label, other than its own, of its settled neighbours (a folded strip is relabelled whole).
    std::vector<char> bad(B.rows(), 0);
    int nbad = 0;
    for (int f = 0; f < B.rows(); ++f) {
      const Vec3 a = X.row(B(f, 0)), b = X.row(B(f, 1)), c = X.row(B(f, 2));
      if ((b - a).cross(c - a).dot(label_direction(e.labels[f])) > 1e-14 * diag * diag) continue;
      bad[f] = 1;
      ++nbad;
      hooks.debug("misoriented triangle " + std::to_string(f) + " (" + std::to_string(B(f, 0)) + " " +
                  std::to_string(B(f, 1)) + " " + std::to_string(B(f, 2)) + ") label " + label_name(e.labels[f]) +
                  ", area " + std::to_string(0.5 * (b - a).cross(c - a).norm()));
    }
    std::vector<int> next = e.labels;
    int changed = 0;
    for (bool progress = true; progress;) {
      progress = false;
      std::vector<std::pair<int, int>> set;
      for (int f = 0; f < B.rows(); ++f) {
        if (bad[f] != 1) continue;
        int votes[6] = {0, 0, 0, 0, 0, 0};
        for (int k = 0; k < 3; ++k) {
          const int g = N(f, k);
          if (g >= 0 && bad[g] != 1 && next[g] != e.labels[f]) votes[next[g]]++;
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
    if (changed == 0) break;
    const CleanupStats again = cleanup_labels(deformed, B, next, opt.cleanup);
    if (next == e.labels) {
      // The cleanup undid the relabelling (e.g. the triangles were zigzags): nothing new to try.
      hooks.debug("relabelling the misoriented triangles is undone by the cleanup; no retry");
      break;
    }
    e.labels = std::move(next);
    e.cleanup.zigzags += again.zigzags;
    e.cleanup.degenerate += again.degenerate;
    e.cleanup.degree1 += again.degree1;
    e.cleanup.degree2 += again.degree2;
    e.cleanup.degree3 += again.degree3;
    e.cleanup.opposite += again.opposite;
    e.cleanup.misoriented += changed;
    e.cleanup.relabelled_faces = 0;
    for (size_t f = 0; f < raw.size(); ++f) e.cleanup.relabelled_faces += raw[f] != e.labels[f];
    e.charts = check_charts(B, static_cast<int>(deformed.rows()), e.labels);
    hooks.debug("retrying the realization with " + std::to_string(changed) +
                " misoriented triangles relabelled: " + std::to_string(e.charts.charts) + " charts, " +
                std::to_string(e.charts.corners) + " corners");
    // The retries keep to the continuation start, the one that got every tet positive (when
    // both starts were tried, the eq17 start mostly fails after a long untangling).
    RealizeOptions ro = opt.realize;
    if (ro.start == "auto" && e.realized.start == "continuation") ro.start = "continuation";
    e.realized = realize_polycube(rest, T, B, deformed, e.labels, ro, hooks);
  }
  if (T.rows() == 0 && !e.realized.success && e.realized.misoriented_faces > 0 &&
      e.realized.misoriented_faces <= opt.max_flip_faces && e.realized.degenerate_border_edges == 0 &&
      e.realized.X.rows() > 0) {
    MatX3i F = B;
    const int flips = flip_folded_edges(e.realized.X, F, e.labels);
    RealizeResult r = e.realized;
    check_faces(F, e.labels, r);
    hooks.debug(std::to_string(flips) + " edge flips leave " + std::to_string(r.misoriented_faces) +
                " folded triangles");
    if (flips > 0 && r.misoriented_faces == 0) {
      r.success = true;
      r.failure.clear();
      r.arap = deform::surface_arap_energy(r.X, F, deform::SurfaceArapRest::build(rest, F), 1.0, nullptr, nullptr);
      r.isometric = isometric_distortion_surface(rest, r.X, F);
      e.realized = std::move(r);
      e.flipped_B = std::move(F);
      e.edge_flips = flips;
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

}  // namespace polycube::chart
