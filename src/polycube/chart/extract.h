// The polycube stage as one call: label the deformed boundary, clean the labels up, check the
// chart graph, realize the exact polycube (labeling.h, realize.h).
#pragma once
#include <vector>

#include "polycube/chart/labeling.h"
#include "polycube/chart/realize.h"
#include "polycube/core/log.h"

namespace polycube::chart {

struct ExtractOptions {
  /// Surface mode: when the realization leaves at most this many triangles folded, edge flips
  /// inside their charts are tried (see PolycubeExtraction::flipped_B); 0 = off.
  int max_flip_faces = 20;
  /// Triangles whose deformed area is below this fraction of the median deformed/rest area ratio
  /// take their neighbours' label before cleanup (relabel_collapsed); 0 = off.
  double collapsed_ratio = 1e-3;
  /// When the realization leaves boundary triangles facing away from their label (every tet
  /// positive), relabel them from their neighbours and retry, at most this many times.
  int relabel_attempts = 4;
  CleanupOptions cleanup;
  RealizeOptions realize;
};

struct PolycubeExtraction {
  std::vector<int> labels;   ///< per boundary triangle (row of B), after cleanup
  int initial_charts = 0;    ///< charts of the raw labelling
  CleanupStats cleanup;
  ChartReport charts;        ///< the cleaned chart graph
  RealizeResult realized;    ///< realized.success tells whether an exact polycube was built
  /// Surface mode: the triangles of the polycube map, B with `edge_flips` edges flipped (empty when
  /// none was): a triangle left folded in its chart's plane is repaired by flipping an edge it
  /// shares with a triangle of the same chart when both new triangles face the label. The vertices
  /// (and their positions on both sides of the map) are unchanged; only the triangulation differs.
  MatX3i flipped_B;
  int edge_flips = 0;
};

/// rest/T/B: tet mesh and outward boundary triangles; deformed: the deformation's result.
PolycubeExtraction extract_polycube(const MatX3d& rest, const MatX4i& T, const MatX3i& B, const MatX3d& deformed,
                                    const ExtractOptions& opt = {}, const Hooks& hooks = {});

/// Flips edges of F shared by a triangle not facing its label in X (folded in its chart's plane)
/// and a triangle of the same label when both new triangles face it; repeated while it helps.
/// Returns the flips made.
int flip_folded_edges(const MatX3d& X, MatX3i& F, const std::vector<int>& labels);

}  // namespace polycube::chart
