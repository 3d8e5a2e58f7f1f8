// The whole job: load and validate an input, tetrahedralize it, deform it into a polycube, extract
// the exact polycube and its map, build the hex mesh or the quad mesh of the surface, write the outputs and report.json.
//
// Output protocol: files are written to OUTDIR/.staging and moved into OUTDIR only when every
// stage asked for has succeeded; outputs of an earlier run are removed first. On failure OUTDIR
// holds only report.json with "status": "error" and the message.
#pragma once
#include <nlohmann/json.hpp>
#include <string>

#include "polycube/chart/extract.h"
#include "polycube/constraints/constraints.h"
#include "polycube/core/log.h"
#include "polycube/deform/solver.h"
#include "polycube/hex/extract.h"
#include "polycube/quad/quad.h"
#include "polycube/io/readers.h"
#include "polycube/tetra/tetrahedralize.h"
#include "polycube/validate/surface.h"

namespace polycube {

/// Pipeline stages, in order. Only those marked available run today.
enum class Stage { Load, Tet, Deform, Polycube, Hex, Quad };

/// "load", "tet", ... / parse (throws Error(Usage) listing the names).
const char* to_string(Stage s);
Stage parse_stage(const std::string& name);
/// Last stage implemented so far.
Stage last_available_stage();

struct PipelineOptions {
  std::string input;           ///< input file; empty when `example` is set
  std::string example;         ///< built-in example name (see examples::list())
  double example_mesh_size = 0.04;  ///< example surface edge length, fraction of the bbox diagonal
  std::string out_dir = "out";  ///< output folder, created if missing
  /// Surface mode (paper Section 5.3): no tetrahedralization; the surface deforms with the surface
  /// ARAP distortion, the polycube is a surface polycube, and the quads come straight from it.
  /// Open surfaces are accepted (their borders become axis-aligned and stay in the quad mesh).
  /// Hexes need the volume: Stage::Hex is refused.
  bool surface = false;
  /// Surface mode: when no valid polycube is realized, deform again with the anti-foldover
  /// barrier weight times this and extract again (values <= 1: no retry).
  double surface_retry_barrier = 10;
  Stage until = Stage::Tet;    ///< stop after this stage
  /// Volume mode with Stage::Hex (or Stage::Quad: the quads the same way): when no valid polycube
  /// is realized but the state the realization reached lies on its planes (planarity 1e-9) with at
  /// most this many tets inverted, the hexes are extracted through that folded map anyway (the
  /// snapping's untangling, the hex untangling and optimization follow) and kept only if none is
  /// inverted and their Hausdorff distance to the input is under 5% of its bbox diagonal (a map
  /// that also overlaps itself may leave a part out of the grid); the polycube outputs
  /// (polycube.*, map.obj) are not written and report.json says polycube.map_valid false with the
  /// inverted tets. 0 = off (such runs fail with exit code 7, as with Stage::Polycube). Measured
  /// (2026-11-28): tet/hand, 1 tet left inverted: 15019 hexes, scaled Jacobian 0.580 / 0.943,
  /// Hausdorff 4.5e-3 of the diagonal; homer (2 inverted, the state overlapping itself widely) and
  /// octopus-low (its best state crushed) still fail.
  int hex_through_folds = 100;
  /// Volume mode with Stage::Quad, the polycube the quads come from: "auto" (default) the volume's
  /// (the tet mesh realized, chart::extract_polycube), and when no valid polycube map of the volume
  /// is realized and no folded map carries the quads (none within hex_through_folds, or its quads
  /// refused: the stage then runs a second time from the same volume extraction), the labels cleaned
  /// and realized again on the deformed boundary alone, as in surface mode
  /// (chart::realize_surface_polycube: no tets to invert), the quads then coming from that surface
  /// polycube as with `surface`; "surface": that surface polycube straight away (no tet
  /// realization, which can take minutes before it fails); "volume": the volume's only (such runs
  /// fail with exit code 7). The volume deformation keeps thin parts (fins, limbs) that the
  /// surface ARAP presses flat, so the layout keeps them too. report.json:
  /// polycube.surface_fallback; polycube.* is then the surface polycube (no tets), tetmesh.* and
  /// deformed.* the volume deformed.
  std::string quad_polycube = "auto";
  /// Volume mode: when no valid polycube is realized (and no hexes come through a folded map),
  /// write the state the realization reached to OUTDIR/failed_polycube.vtk for inspection: its
  /// tets and boundary triangles, cell fields `label` (triangles, -1 on tets) and `inverted` (1 on
  /// the inverted tets). A diagnosis, not a result: the run still fails (exit code 7), the file is
  /// named as such and removed by the next run in that folder. Off by default.
  bool write_failed = false;
  /// Volume mode, the paper's slim-triangle collapse (Section 4): when the deformation's line
  /// search is cut short by the barrier while boundary triangles have an angle under
  /// deform.slim_angle_deg (DeformOptions::stop_at_slim_stall), their shortest edges are
  /// collapsed in the tet mesh, at rest and in the deformed mesh alike
  /// (chart::collapse_slim_triangles), and the deformation resumes from that state at the same
  /// schedule step, at most this many times (0 = off; off as well with edge constraints, which
  /// name boundary triangle pairs). The tet mesh then has fewer vertices and triangles than the
  /// input surface: tetmesh.* is written again, and labels.txt and map.obj reach the input's
  /// triangles and vertices through the closest point at rest.
  int slim_collapse_rounds = 0;
  bool vtk_binary = false;     ///< VTK outputs in BINARY instead of ASCII
  io::CadOptions cad;
  ValidateOptions validate;
  TetOptions tet;
  deform::DeformOptions deform;
  /// User control (constraints/constraints.h): a constraint file (ids into the validated input
  /// surface, OUTDIR/surface.mesh), automatic sharp features ("auto": edges whose normals differ
  /// by more than feature_angle degrees become sharp constraints; "off"), and a path to write the
  /// detected features to in the constraint format (empty = none).
  std::string constraints_file;
  std::string features = "off";
  double feature_angle = 30;
  std::string export_features;
  constraints::ConstraintOptions constraint;
  chart::ExtractOptions polycube;
  /// A polycube map to build on instead of deforming and extracting: a tet mesh file with the
  /// input's tets (same vertices, same tets; e.g. an earlier run's polycube.mesh for its
  /// tetmesh.mesh, or another tool's polycube tet mesh) whose boundary is an axis-aligned polycube.
  /// The input must then be the tet mesh. Empty: off.
  std::string polycube_map;
  /// A deformed tet mesh to extract the polycube from instead of deforming: a tet mesh file with
  /// the input's tets (e.g. an earlier run's deformed.mesh for its tetmesh.mesh), in the frame the
  /// deformation left it (axis-aligned charts). The input must then be the tet mesh; the
  /// extraction's options may differ from the earlier run's. Empty: off.
  std::string deformed;
  hex::HexOptions hex;
  /// Quad stage: approximate quad count (0 = the hex stage's resolution; in surface mode 2000) and smoothing.
  int target_quads = 0;
  quad::QuadOptions quad;
};

/// Names of every file the pipeline may write into the output folder.
const std::vector<std::string>& output_files();

/// Writes a failed realization's state (PipelineOptions::write_failed) as a VTK file: tets T over
/// X and the boundary triangles F, cell fields `label` (one per triangle, -1 on tets) and
/// `inverted` (1 on tets whose volume ratio to their rest tet is not positive, as
/// RealizeResult::inverted counts them; 0 elsewhere). Returns the inverted tet count.
int write_failed_polycube(const std::string& path, const MatX3d& rest, const MatX3d& X, const MatX4i& T,
                          const MatX3i& F, const std::vector<int>& labels, bool binary = false);

/// Runs the pipeline and returns the report (also written to OUTDIR/report.json).
/// Throws polycube::Error after writing the error report.
nlohmann::json run_pipeline(const PipelineOptions& opt, const Hooks& hooks = {});

/// The complexity trade-off (paper Fig. 17): runs the pipeline once per beta into
/// OUTDIR/beta_<value>/ and writes OUTDIR/beta_sweep.json and OUTDIR/beta_sweep.tsv, one row per
/// beta: status, corners, charts, ARAP distortion (deformed and polycube), l1_quality, seconds.
/// A failing run is recorded in its row (status, exit_code, message) and the sweep goes on.
nlohmann::json run_beta_sweep(const PipelineOptions& opt, const std::vector<double>& betas, const Hooks& hooks = {});

}  // namespace polycube
