#include "polycube/chart/extract.h"

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
  return e;
}

}  // namespace polycube::chart
