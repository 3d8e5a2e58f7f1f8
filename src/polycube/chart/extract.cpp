#include "polycube/chart/extract.h"

#include <algorithm>

#include "polycube/core/topology.h"

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
  return e;
}

}  // namespace polycube::chart
