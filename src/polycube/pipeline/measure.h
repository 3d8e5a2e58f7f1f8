// `polycube measure`: the quality figures of any hex mesh, or of a quad mesh when the file has no
// hexahedra (ours or another tool's), measured the same way as the hex and quad stages do: Verdict scaled Jacobian, and with a reference surface the
// sampled two-sided Hausdorff distance, absolute and relative to the reference's bbox diagonal.
#pragma once
#include <nlohmann/json.hpp>
#include <string>

#include "polycube/core/log.h"
#include "polycube/hex/quality.h"

namespace polycube {

struct MeasureOptions {
  std::string path;       ///< hex or quad mesh: MEDIT .mesh, VTK, Gmsh .msh
  std::string reference;  ///< optional surface (any input format; a volume mesh gives its boundary)
  int samples = 200000;   ///< Hausdorff samples per surface
};

/// {"input", "hex": {count, sj_min, sj_mean, sj_max, inverted, below_0_2, below_0_5, sj_histogram,
/// hausdorff, hausdorff_rel, ...}} (or "quad": {...} for a quad mesh). Throws Error(InvalidMesh) when
/// the file has neither hexahedra nor quadrilaterals.
nlohmann::json measure_mesh(const MeasureOptions& opt, const Hooks& hooks = {});

/// Adds the Hausdorff figures of mesh `key` ("hex", "quad") against the input to j: hausdorff,
/// hausdorff_rel (/ diag), hausdorff_KEY_to_input, hausdorff_input_to_KEY, the points where those
/// are reached (..._at), mean_distance_rel (the two one-sided area-weighted means, averaged),
/// rms_distance_rel (the larger one-sided RMS) and `distance` {KEY_to_input, input_to_KEY: {max_rel,
/// mean_rel, rms_rel}} (the figures Metro, M.E.S.H. and MeshLab print). Shared by `polycube measure`
/// and the hex and quad stages.
void add_hausdorff(nlohmann::json& j, const hex::Hausdorff& d, double diag, const std::string& key);
/// {"max", "mean", "above_10", "above_100"} of the elements' edge ratios (hex::QualityStats).
nlohmann::json edge_ratio_json(const hex::QualityStats& q);

}  // namespace polycube
