// polycube command-line tool: a thin layer over the library (src/polycube/pipeline).
#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "polycube/core/error.h"
#include "polycube/core/parallel.h"
#include "polycube/examples/examples.h"
#include "polycube/pipeline/measure.h"
#include "polycube/pipeline/pipeline.h"

using namespace polycube;

namespace {

// A one-line progress bar on stderr, drawn only when stderr is a terminal.
struct ProgressBar {
  bool enabled = false;
  std::string stage;
  void update(const std::string& s, double f) {
    if (!enabled) return;
    const int width = 30;
    int n = static_cast<int>(f * width + 0.5);
    std::fprintf(stderr, "\r%-8s [%s%s] %3d%%", s.c_str(), std::string(n, '#').c_str(),
                 std::string(width - n, ' ').c_str(), static_cast<int>(f * 100 + 0.5));
    if (f >= 1) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }
};

// spdlog pattern flag: the seconds since the logger's formatter was made (the run's start).
class ElapsedFlag : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    const double s = std::chrono::duration<double>(msg.time - start_).count();
    const std::string text = fmt::format("{:.1f}s", s);
    dest.append(text.data(), text.data() + text.size());
  }
  std::unique_ptr<custom_flag_formatter> clone() const override { return std::make_unique<ElapsedFlag>(*this); }

 private:
  spdlog::log_clock::time_point start_ = spdlog::log_clock::now();
};

}  // namespace

// `polycube measure FILE [--ref SURFACE]`: quality of any hex mesh, as JSON on stdout.
int measure_main(int argc, char** argv) {
  CLI::App app{"polycube measure: scaled Jacobian (Verdict convention) of a hex mesh, or of a quad mesh when the\n"
               "file has no hexahedra (.mesh, .vtk, .msh), and, with --ref, the two-sided Hausdorff distance\n"
               "of its boundary (or of the quads) to a reference surface.\n"
               "Prints JSON on stdout. Exit codes: 0 ok, 2 usage, 3 unreadable input, 4 invalid mesh."};
  MeasureOptions mo;
  app.add_option("mesh", mo.path, "Hex or quad mesh to measure")->required();
  app.add_option("--ref", mo.reference, "Reference surface (OBJ, OFF, STL, PLY, or a volume mesh's boundary)");
  app.add_option("--samples", mo.samples, "Hausdorff sample points per surface")
      ->capture_default_str()->check(CLI::Range(0, 100000000));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    std::printf("%s\n", measure_mesh(mo).dump(2).c_str());
    return 0;
  } catch (const Error& e) {
    std::fprintf(stderr, "[error] %s\n", e.what());
    return exit_code(e.kind());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] internal error: %s\n", e.what());
    return 70;
  }
}

int main(int argc, char** argv) {
  reexec_with_portable_blas(argv);  // the same bits on every AVX2 machine (core/parallel.h)
  if (argc >= 2 && std::string(argv[1]) == "measure") return measure_main(argc - 1, argv + 1);
  CLI::App app{
      "polycube: l1-based polycube maps of 3D shapes and hex/quad remeshing.\n"
      "Reads a closed triangle surface (OBJ, OFF, STL, PLY; open ones with --surface), a tet or hex mesh\n"
      "(MEDIT .mesh, VTK, Gmsh .msh)\n"
      "or a CAD model (STEP, IGES, BREP), validates it, tetrahedralizes it and writes the results and\n"
      "report.json into the output folder. Lengths are relative to the input's bounding-box diagonal.\n"
      "Exit codes: 0 ok, 2 usage, 3 unreadable input, 4 invalid mesh, 5 tetrahedralization failed,\n"
      "6 output not writable, 7 no valid polycube or hex mesh, 70 internal error.\n"
      "Also: polycube measure HEXMESH [--ref SURFACE] (see polycube measure --help)."};
  app.set_version_flag("--version", POLYCUBE_VERSION);

  PipelineOptions opt;
  std::string until = to_string(Stage::Polycube);
  std::string out_dir;
  bool quiet = false, verbose = false;
  app.add_option("input", opt.input, "Input mesh or CAD file");
  app.add_option("-o,--output", out_dir, "Output folder (default: out/<input name>)");
  app.add_option("--example", opt.example, "Run on a built-in example instead of a file; 'list' lists them");
  app.add_option("--example-size", opt.example_mesh_size,
                 "Surface edge length of the built-in examples, fraction of the bbox diagonal")
      ->capture_default_str()
      ->check(CLI::Range(1e-3, 0.5));
  app.add_option("--until", until, "Stop after this stage: load, tet, deform, polycube, then hex or quad")
      ->capture_default_str();
  app.add_option("--remove-spikes", opt.tet.spike_height,
                 "Before tetrahedralizing: remove the surface's spikes (vertices with three neighbours) lower than "
                 "this fraction of the bounding-box diagonal, which the deformation crushes (0 = keep them; the "
                 "map reaches their vertices by closest point)")
      ->capture_default_str()->check(CLI::Range(0.0, 0.1));
  app.add_option("--edge-length", opt.tet.edge_length,
                 "Remesh the surface before tetrahedralization to this edge length, fraction of the bbox "
                 "diagonal (0 = keep the input triangles)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.5));
  app.add_option("--max-size", opt.tet.max_size,
                 "Largest tet edge inside the volume, fraction of the bbox diagonal (0 = grow from the boundary)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--tets", opt.tet.target_tets,
                 "Approximate number of tets (sets the interior size; the kept input surface sets a minimum); 0 = off")
      ->capture_default_str()
      ->check(CLI::Range(0, 100000000));
  app.add_option("--tet-algorithm", opt.tet.algorithm, "Gmsh 3D algorithm: delaunay or hxt (parallel)")
      ->capture_default_str()
      ->check(CLI::IsMember({"delaunay", "hxt"}));
  app.add_option("--cad-size", opt.cad.mesh_size,
                 "Surface edge length for CAD input (STEP/IGES/BREP), fraction of the bbox diagonal")
      ->capture_default_str()
      ->check(CLI::Range(1e-4, 0.5));
  auto& d = opt.deform;
  app.add_option("--alpha0", d.alpha0, "Polycube deformation: initial weight of the l1 energy (doubled at each schedule step)")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--eps0", d.eps0, "Polycube deformation: initial smoothing eps of |c| ~ sqrt(c^2+eps) (divided by sqrt 2 per step)")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--eps-min", d.eps_min, "Polycube deformation: smallest eps")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--beta", d.beta,
                 "Polycube deformation: complexity penalty weight (Eq. 10): larger = fewer polycube corners and "
                 "charts, at more distortion (the paper uses 0.1-4; 0 = off)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  std::vector<double> beta_sweep;
  app.add_option("--beta-sweep", beta_sweep,
                 "Run once per beta (comma-separated, e.g. 0,0.5,2) into OUTDIR/beta_<b>/ and write a summary table "
                 "OUTDIR/beta_sweep.tsv (corners, charts, ARAP distortion)")
      ->delimiter(',');
  app.add_option("--constraints", opt.constraints_file,
                 "JSON file of sharp/flat edge and region constraints (Eqs. 12-13; format in the README)")
      ->check(CLI::ExistingFile);
  app.add_option("--features", opt.features,
                 "auto: input edges sharper than --feature-angle become sharp constraints; off")
      ->capture_default_str()->check(CLI::IsMember({"auto", "off"}));
  app.add_option("--feature-angle", opt.feature_angle,
                 "Angle between adjacent normals above which an edge is a feature (degrees)")
      ->capture_default_str()->check(CLI::Range(1.0, 179.0));
  app.add_option("--export-features", opt.export_features,
                 "Write the detected features to this file in the constraint format (with --features auto)");
  app.add_option("--constraint-weight", opt.constraint.weight,
                 "Default weight omega of a constrained edge (Eqs. 12-13), relative to the normalized energies")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--barrier-weight", d.barrier_weight, "Polycube deformation: anti-foldover barrier weight (Eq. 11)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--volume-barrier", d.volume_barrier_weight,
                 "Polycube deformation: weight of the log barrier on tet volumes, or on triangle areas in surface "
                 "mode (0 = off, as in the paper)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option_function<std::string>(
         "--volume-barrier-form",
         [&d](const std::string& form) { d.neutral_volume_barrier = form == "neutral"; },
         "Polycube deformation: log = -w log J per tet (default), which pushes every tet to grow and rounds "
         "the shape at small alpha; neutral = w (J - 1 - log J), no pull on tets of unchanged volume")
      ->default_str(d.neutral_volume_barrier ? "neutral" : "log")
      ->check(CLI::IsMember({"neutral", "log"}));
  app.add_flag("--locality-order", d.locality_order,
               "Polycube deformation (volume): renumber the interior vertices along a Morton curve and sort the "
               "tets inside the solver, for faster assembly and solves on large meshes (changes the last digits, "
               "hence the SQP path; the output keeps the input's numbering)");
  app.add_option("--thickness", d.thickness_weight,
                 "Surface mode, closed surfaces: weight of the barrier that keeps the two sides of thin parts "
                 "apart (0 = off)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option_function<std::string>(
         "--thickness-form", [&d](const std::string& form) { d.thickness_contact = form == "contact"; },
         "Surface mode: pairs = each vertex of a thin part held against one point across, fixed at rest; "
         "contact = against every triangle across that comes near it in the current shape (with a collision "
         "check in the line search), which the two sides sliding along each other do not fool")
      ->default_str(d.thickness_contact ? "contact" : "pairs")
      ->check(CLI::IsMember({"pairs", "contact"}));
  app.add_option("--gap-barrier", d.gap_weight,
                 "Polycube deformation (volume): weight of the barrier that keeps the gaps between parts (legs, an "
                 "arm and the body) open, narrower than --thickness-max, at least --thickness-keep of their width; "
                 "applied in a second deformation when a first one without it closed them (0 = off)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--thickness-keep", d.thickness_keep,
                 "The fraction of their rest distance thin parts (surface mode) or gaps (volume mode) keep at least")
      ->capture_default_str()->check(CLI::Range(0.01, 0.99));
  app.add_option("--thickness-max", d.thickness_max,
                 "Parts (surface mode) or gaps (volume mode) narrower than this fraction of the bounding-box "
                 "diagonal are held by the thickness barrier")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--volume-boost", d.volume_boost_factor,
                 "Polycube deformation: per tet, the volume barrier is multiplied by this whenever the full SQP step "
                 "would invert the tet (1 = off)")
      ->capture_default_str()->check(CLI::Range(1.0, 1e3));
  app.add_option("--crush-guard", d.crush_guard_weight,
                 "Polycube deformation (volume): weight of the barrier that keeps tets from being pressed under "
                 "--crush-guard-ratio of their rest volume, each such tet weighing as a tet of mean volume (0 = off)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--crush-guard-ratio", d.crush_guard_ratio,
                 "Polycube deformation (volume): the volume ratio under which the crush guard acts")
      ->capture_default_str()->check(CLI::Range(1e-6, 0.9));
  app.add_option("--rescue-cg-tolerance", d.rescue_cg_tolerance,
                 "Polycube deformation (volume): when the schedule ends above --target-quality, deform again from "
                 "rest with the SQP systems solved to this relative residual from schedule step --rescue-from-step on, "
                 "and keep the better result (0 = off)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  int rescue_step = d.rescue_from_step + 1;
  app.add_option("--rescue-from-step", rescue_step,
                 "Polycube deformation (volume): the schedule step (1 = the first) from which the stall rescue solves "
                 "more exactly")
      ->capture_default_str()->check(CLI::Range(1, 100));
  bool plain_hessian = false;
  app.add_flag("--no-lagrangian-hessian", plain_hessian,
               "Polycube deformation: leave the area constraint's curvature out of the SQP Hessian (slower "
               "convergence; for comparison)");
  app.add_flag("--float-factorization", d.float_factorization,
               "Polycube deformation (volume and surface mode, where the factor is supernodal): factorize the SQP "
               "systems in single precision and refine the solves by CG (about twice as fast per factorization; it "
               "changes the SQP path, hence the polycube extraction's)");
  app.add_option("--alpha-steps", d.max_alpha_steps, "Polycube deformation: schedule steps (alpha doublings) at most")
      ->capture_default_str()->check(CLI::Range(1, 100));
  app.add_option("--sqp-tolerance", d.sqp_tolerance,
                 "Polycube deformation: a schedule step also ends when a full SQP step lowers the energy by less "
                 "than this fraction (0 = the paper's error test alone; -1: 3e-5 for volumes, 0 in surface mode)")
      ->capture_default_str()->check(CLI::Range(-1.0, 1.0));
  app.add_option("--max-iterations", d.max_inner_iterations, "Polycube deformation: SQP iterations per schedule step at most")
      ->capture_default_str()->check(CLI::Range(1, 10000));
  app.add_option("--target-quality", d.target_quality,
                 "Polycube deformation: stop when l1_quality = sum|N|_1/sum|N|_2 - 1 is below this")
      ->capture_default_str()->check(CLI::PositiveNumber);
  auto& rz = opt.polycube.realize;
  app.add_option("--realize-start", rz.start,
                 "Polycube realization start: continuation (the deformed mesh moved onto the planes in steps that "
                 "keep tets positive), eq17 (the paper's relaxation, then untangling), auto (both, the lower "
                 "ARAP distortion wins) or penalty (the penalty path alone, see --penalty-path)")
      ->capture_default_str()->check(CLI::IsMember({"auto", "continuation", "eq17", "penalty"}));
  app.add_option("--realize-tolerance", rz.volume_tolerance,
                 "Polycube realization (volume): the ARAP Newton iterations stop when a step lowers the energy by "
                 "less than this, relatively (1e-6, the earlier default: rocker's extraction 90 s against 71 s, the same "
                 "polycube to 1e-5)")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--realize-folded-tolerance", rz.folded_tolerance,
                 "Polycube realization (volume): the same, for a start that lands on the planes with boundary "
                 "triangles facing away from their chart (it fails whatever its ARAP iterations do; its state starts "
                 "the retries)")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--eq17-budget", rz.eq17_budget,
                 "Polycube realization, --realize-start auto: elliptic untangling iterations within which the eq17 "
                 "start competes with a successful continuation start (beyond: abandoned once the continuation "
                 "succeeds); -1 = no budget")
      ->capture_default_str();
  app.add_option("--untangle-patience", rz.untangle_patience,
                 "Polycube realization: elliptic untangling rounds in a row without fewer inverted tets before it "
                 "gives up (the edge collapses and relabellings take over)")
      ->capture_default_str()->check(CLI::Range(1, 1000));
  app.add_option("--relax", rz.relax_iterations,
                 "Surface mode: after the realization's ARAP, N L-BFGS iterations on the map's elliptic energy "
                 "(shape and area distortion, a barrier against crushed triangles; 0 = off)")
      ->capture_default_str()->check(CLI::Range(0, 1000000));
  app.add_option("--local-first", rz.local_first,
                 "Polycube realization: after landing on the planes (or the relaxation of Eq. 17), the local "
                 "untangling runs first; when it leaves at most N tets inverted the elliptic untangling is "
                 "skipped (surface mode: triangles folded, the global untangling rounds skipped); -1 = off (the elliptic "
                 "untangling first)")
      ->capture_default_str()->check(CLI::Range(-1, 1000000));
  app.add_option("--surface-untangle-rounds", rz.surface_untangle_rounds,
                 "Surface mode: global untangling rounds (L-BFGS over the whole surface) after a local untangling "
                 "that left more than --local-first triangles folded (0 = none: the next start takes over)")
      ->capture_default_str()->check(CLI::Range(0, 1000));
  app.add_option("--continuation-retries", rz.continuation_retries,
                 "Polycube realization: when the continuation start stalls, retries with a 10x stronger barrier "
                 "(each) before landing on the planes and untangling")
      ->capture_default_str()->check(CLI::Range(0, 6));
  app.add_option("--stall-repeats", rz.stall_repeats,
                 "Polycube realization: past t = 0.75 of the continuation, this many failed steps blocked again "
                 "by tets that already blocked one end it as stalled (such a run creeps towards t = 1 and "
                 "reaches its 60-step limit anyway); 0 = off")
      ->capture_default_str()->check(CLI::Range(0, 1000));
  app.add_flag("--penalty-path,!--no-penalty-path", rz.penalty_path,
               "Polycube realization: when the continuation start stalls, first try the penalty path (plane "
               "heights free, gaps penalized ever more strongly, every tet kept positive) before landing on the "
               "planes by force");
  app.add_option("--realize-iterations", rz.max_iterations, "Polycube realization: ARAP iterations at most")
      ->capture_default_str()->check(CLI::Range(0, 100000));
  app.add_option("--polycube-map", opt.polycube_map,
                 "Skip the deformation and extraction: build on this polycube tet mesh, which has the input tet "
                 "mesh's vertices and tets (e.g. OUTDIR/polycube.mesh with OUTDIR/tetmesh.mesh as the input, or "
                 "another tool's polycube map)")
      ->check(CLI::ExistingFile);
  app.add_option("--deformed", opt.deformed,
                 "Skip the deformation: extract the polycube from this deformed tet mesh, which has the input tet "
                 "mesh's vertices and tets (e.g. OUTDIR/deformed.mesh with OUTDIR/tetmesh.mesh as the input), to try "
                 "other extraction or hex options")
      ->check(CLI::ExistingFile);
  bool no_cleanup = false;
  app.add_flag("--no-cleanup", no_cleanup, "Polycube labels: skip the topological cleanup (for inspection)");
  double pinch_above = -1;
  app.add_option("--pinch-above", pinch_above,
                 "Polycube labels: a chart of degree 2 or 3 pinched between opposite neighbours gets its missing "
                 "side opened (instead of being relabelled whole) when its area is above this fraction of the total "
                 "(default 0.01, 0.002 in surface mode)")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--max-pinches", opt.polycube.cleanup.max_pinches, "Polycube labels: pinches opened at most per cleanup")
      ->capture_default_str()->check(CLI::Range(0, 100000));
  double collapsed_ratio = -1;
  app.add_option("--collapsed-ratio", collapsed_ratio,
                 "Polycube labels: boundary triangles whose deformed area is below this fraction of the median "
                 "deformed/rest area ratio take their neighbours' label (their normal is unreliable); 0 = off "
                 "(default 0.001, 0 in surface mode)")
      ->check(CLI::Range(0.0, 0.5));
  bool no_rotation = false;
  app.add_flag("--no-rotation", no_rotation, "Polycube deformation: keep the input orientation (no global rotation, Eq. 3)");
  bool run_hex = false;
  app.add_flag("--hex", run_hex, "Run through to the all-hex mesh (same as --until hex)");
  auto& hx = opt.hex;
  app.add_option("--hexes", hx.target_hexes,
                 "Hex mesh: approximate number of grid hexes (pillowing adds a boundary layer)")
      ->capture_default_str()->check(CLI::Range(1, 100000000));
  app.add_option("--hex-size", hx.hex_size,
                 "Hex mesh: edge length, fraction of the bbox diagonal; overrides --hexes (0 = off)")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--pillow", hx.pillow,
                 "Hex mesh: one layer of hexes along the boundary: on, off, or auto (both tried, the higher min "
                 "scaled Jacobian wins)")
      ->capture_default_str()->check(CLI::IsMember({"auto", "on", "off"}));
  app.add_option("--thin-steps", hx.merge_thin_steps,
                 "Hex mesh and surface-mode quads: planes of a step closer than this many cells share one integer "
                 "(the step's riser vanishes instead of getting a layer of flat hexes or a row of sliver quads); "
                 "0 = every step keeps a cell")
      ->capture_default_str()->check(CLI::Range(0.0, 0.9));
  app.add_option("--max-edge-ratio", hx.max_edge_ratio,
                 "Hex mesh: the optimization may not take a hex above this edge ratio (longest over shortest edge) "
                 "unless it lowers it, where the hexes are at scaled Jacobian 0.5 or more (0 = no limit: a little "
                 "higher worst scaled Jacobian, and pillow hexes squeezed to slivers)")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  app.add_flag("--hex-untangle,!--no-hex-untangle", hx.untangle,
               "Hex mesh: hexes still inverted after the optimization have their inverted corners untangled (the "
               "elliptic energy on every hex's corner tets, boundary held; then, around what is left, boundary "
               "vertices sliding on the input) and are optimized again, kept when fewer stay inverted "
               "(default on)");
  app.add_option("--thin-step-retry", hx.thin_step_retry_below,
                 "Hex mesh: a result whose worst hex is under this scaled Jacobian next to planes closer than 0.05 "
                 "(then 0.25) cells is extracted again with those steps merged, kept when better (0 = only when "
                 "hexes are inverted). Surface-mode quads are extracted again the same way when some have an edge "
                 "ratio over 100 (0 = not)")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--hex-through-folds", opt.hex_through_folds,
                 "Hex mesh (and quads in volume mode): when no valid polycube is realized but the best state "
                 "reached lies on its planes with at most this many tets inverted, extract the hexes through that "
                 "folded map anyway, kept only if none is inverted and they are within 5% of the bbox diagonal of "
                 "the input (no polycube.* or map.obj is written; 0 = fail instead)")
      ->capture_default_str()->check(CLI::Range(0, 1000000));
  app.add_option("--quad-polycube", opt.quad_polycube,
                 "Quads in volume mode (--quad without --surface): the polycube they come from. auto: the volume's, "
                 "and when no valid polycube map of the volume is realized (and no folded map carries them, or its quads are "
                 "refused), the "
                 "deformed boundary's labels realized as a surface polycube (report polycube.surface_fallback); "
                 "surface: that surface polycube straight away (the tet realization skipped); volume: the volume's "
                 "only (fails with exit code 7 where it is not realized)")
      ->capture_default_str()->check(CLI::IsMember({"auto", "surface", "volume"}));
  app.add_option("--slim-collapse", opt.slim_collapse_rounds,
                 "Volume mode: the paper's slim-triangle collapse. When the deformation's line search is cut short by "
                 "the barrier while boundary triangles have an angle under --slim-angle degrees, their shortest edges are "
                 "collapsed (tet mesh and deformed mesh alike) and the deformation resumes, at most N times (0 = off)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--slim-angle", opt.deform.slim_angle_deg, "Angle (degrees) under which a boundary triangle is slim")
      ->capture_default_str()->check(CLI::Range(0.1, 30.0));
  app.add_flag("--write-failed", opt.write_failed,
               "When no valid polycube is realized, write the state reached to OUTDIR/failed_polycube.vtk "
               "(cell fields label and inverted) for inspection; the run still fails (exit code 7)");
  app.add_option("--grading", hx.grading.strength,
                 "Hex mesh (and surface-mode quads when given): sheets of hexes denser where cells would cut the "
                 "curved surface more (exponent on the measure: 0 = uniform grid, as the paper's; 1 = full)")
      ->capture_default_str()->check(CLI::Range(0.0, 2.0));
  app.add_option("--grading-measure", hx.grading.measure, "Hex mesh: what the grading follows: chord or stretch")
      ->capture_default_str()->check(CLI::IsMember({"chord", "stretch"}));
  app.add_option("--grading-max", hx.grading.max_ratio, "Hex mesh: the grading's largest density ratio")
      ->capture_default_str()->check(CLI::Range(1.0, 100.0));
  app.add_flag("--hex-creases,!--no-hex-creases", hx.capture_creases,
               "Hex mesh: a variant with paths of boundary vertices moved onto the creases no boundary edge "
               "follows, kept when closer to the input with no worse a worst hex (under 0.3)");
  app.add_option("--hex-smooth", hx.smooth_iterations, "Hex mesh: smoothing sweeps (0 = off)")
      ->capture_default_str()->check(CLI::Range(0, 10000));
  int fit_rounds = hx.fit.rounds;
  double fit_floor = hx.fit.quality_floor;
  double fit_offset = hx.fit.max_offset;
  app.add_option("--fit-offset", fit_offset,
                 "Hex mesh: the fitting may take a boundary vertex off the input surface by up to this fraction "
                 "of its edge length (0 = on the surface), so that flat quads over curved parts cut the surface "
                 "on both sides (mean distance about a third lower)")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--fit-rounds", fit_rounds,
                 "Hex and quad meshes: rounds of fitting to the input surface (boundary vertices slide on it "
                 "so that it comes closer to the mesh; 0 = off)")
      ->capture_default_str()->check(CLI::Range(0, 1000));
  app.add_option("--fit-floor", fit_floor,
                 "Hex and quad meshes: the fitting never takes an element around a moved vertex below this "
                 "scaled Jacobian (or below its value before, if lower); -1: the worst element of the mesh "
                 "before the fitting, or 0.5 if lower (the fitting keeps the minimum)")
      ->capture_default_str()->check(CLI::Range(-1.0, 1.0));
  app.add_flag("--surface", opt.surface,
               "Surface mode (paper Sec. 5.3): no tets; the surface deforms with a surface ARAP distortion and "
               "quads come straight from the surface polycube. Accepts open surfaces (borders become "
               "axis-aligned and are kept). Not with --hex");
  bool run_quad = false;
  app.add_flag("--quad", run_quad, "Run through to the quad mesh of the surface (same as --until quad)");
  app.add_option("--corner-splits", opt.polycube.corner_splits,
                 "Polycube realization (volume): split the interior edges from the polycube's corners to free "
                 "vertices first, giving each corner's star room: auto (extract again with them when no valid "
                 "polycube is realized without; kept if realized or fewer tets stay inverted), on (from the "
                 "start), off")
      ->capture_default_str()->check(CLI::IsMember({"auto", "on", "off"}));
  app.add_option("--surface-retry", opt.surface_retry_barrier,
                 "Surface mode: if no valid polycube is realized, deform again with the anti-foldover barrier "
                 "weight times this (<= 1: no retry)")
      ->capture_default_str();
  app.add_option("--quads", opt.target_quads, "Quad mesh: approximate number of quads (0 = the hex grid's resolution; 2000 with --surface)")
      ->capture_default_str()->check(CLI::Range(0, 100000000));
  app.add_option("--quad-smooth", opt.quad.smooth_iterations, "Quad mesh: smoothing sweeps on the surface (0 = off)")
      ->capture_default_str()->check(CLI::Range(0, 10000));
  app.add_option("--quad-shape-sweeps", opt.quad.shape_sweeps,
                 "Quad mesh: sweeps of the shape pass around quads with an edge ratio over 10 (their free vertices "
                 "move on the surface to lower their corners' squared condition numbers, which see the thin "
                 "rectangles the scaled Jacobian takes for perfect); 0 = off")
      ->capture_default_str()->check(CLI::Range(0, 10000));
  app.add_option("--sharp-angle", hx.sharp_angle_deg,
                 "Hex and quad meshes: dihedral angle (degrees) above which an input edge is a sharp feature that "
                 "boundary vertices keep to and slide along")
      ->capture_default_str()->check(CLI::Range(1.0, 179.0));
  app.add_option("--crease-angle", opt.quad.capture_angle_deg,
                 "Quad mesh: a chain of sharp edges is a crease to capture (quad edges moved onto it) when one "
                 "of its edges is sharper than this (degrees)")
      ->capture_default_str()->check(CLI::Range(1.0, 179.0));
  bool no_creases = false;
  app.add_flag("--no-crease-capture", no_creases,
               "Quad mesh: do not move quad edges onto the creases of the input that no polycube edge follows");
  app.add_flag("--compare-starts,!--no-compare-starts", opt.quad.compare_starts,
               "Surface mode, quads: when two realization starts both give a polycube, extract quads from both and "
               "keep the better (closer to the surface at a similar quality)")
      ->capture_default_str();
  int threads = 0;
  app.add_option("--threads", threads,
                 "Cores to use, 1 or 2 (default: the machine's, at most 2, or the environment's POLYCUBE_THREADS). "
                 "The two counts round differently, so results repeat bit for bit at one count; 1 is faster when "
                 "other jobs share a 2-core machine (OpenBLAS's threads spin while waiting)")
      ->check(CLI::Range(1, 2));
  app.add_flag("--vtk-binary", opt.vtk_binary, "Write VTK files in BINARY instead of ASCII");
  app.add_flag("-q,--quiet", quiet, "Only warnings and errors");
  app.add_flag("-v,--verbose", verbose, "Debug messages");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }

  if (threads > 0) set_thread_limit(threads);
  if (no_rotation) opt.deform.global_rotation = false;
  if (plain_hessian) opt.deform.lagrangian_hessian = false;
  opt.deform.rescue_from_step = rescue_step - 1;
  if (no_creases) opt.quad.capture_creases = false;
  opt.quad.sharp_angle_deg = hx.sharp_angle_deg;
  opt.quad.merge_thin_steps = hx.merge_thin_steps;
  opt.quad.thin_step_retries = hx.thin_step_retry_below > 0;
  // Surface-mode quads are graded only on request (hexes by default).
  if (app.count("--grading") > 0) opt.quad.grading = hx.grading;
  hx.fit.rounds = opt.quad.fit.rounds = fit_rounds;
  hx.fit.quality_floor = opt.quad.fit.quality_floor = fit_floor;
  hx.fit.max_offset = fit_offset;  // not for quads: their later passes assume vertices on the surface
  // A resolution given alone asks for that mesh: --quads N runs to the quads, --hexes / --hex-size
  // to the hexes.
  if (!run_hex && !run_quad && app.count("--until") == 0) {
    const bool quads = app.count("--quads") > 0, hexes = app.count("--hexes") + app.count("--hex-size") > 0;
    if (quads && !hexes) run_quad = true;
    if (hexes && !quads) run_hex = true;
  }
  if (run_hex && run_quad) {
    std::fprintf(stderr, "[error] give --hex or --quad, not both\n");
    return 2;
  }
  if (run_quad) {
    if (app.count("--until") > 0 && until != "quad") {
      std::fprintf(stderr, "[error] --quad contradicts --until %s\n", until.c_str());
      return 2;
    }
    until = "quad";
  }
  if (run_hex) {
    if (app.count("--until") > 0 && until != "hex") {
      std::fprintf(stderr, "[error] --hex contradicts --until %s\n", until.c_str());
      return 2;
    }
    until = "hex";
  }
  if (no_cleanup) opt.polycube.cleanup = {false, false, false, false};
  if (pinch_above >= 0) opt.polycube.cleanup.pinch_above = opt.polycube.cleanup.pinch_above_surface = pinch_above;
  if (collapsed_ratio >= 0) opt.polycube.collapsed_ratio = opt.polycube.collapsed_ratio_surface = collapsed_ratio;
  auto logger = spdlog::stderr_color_mt("polycube");
  if (verbose) {
    // With -v, each line gives the seconds since the start: where a long run spends its time.
    auto formatter = std::make_unique<spdlog::pattern_formatter>();
    formatter->add_flag<ElapsedFlag>('*').set_pattern("%^[%l %*]%$ %v");
    logger->set_formatter(std::move(formatter));
  } else {
    logger->set_pattern("%^[%l]%$ %v");
  }
  logger->set_level(quiet ? spdlog::level::warn : verbose ? spdlog::level::debug : spdlog::level::info);

  if (opt.example == "list") {
    for (const auto& e : examples::list()) std::printf("%-16s %s\n", e.name.c_str(), e.description.c_str());
    return 0;
  }
  if (!opt.example.empty() && !opt.input.empty()) {
    logger->error("give either an input file or --example, not both");
    return 2;
  }
  if (opt.example.empty() && opt.input.empty()) {
    logger->error("no input: give an input file or --example NAME (see --help)");
    return 2;
  }

  ProgressBar bar;
  bar.enabled = !quiet && isatty(fileno(stderr));
  Hooks hooks;
  hooks.log = [&](LogLevel l, const std::string& m) {
    if (bar.enabled) std::fprintf(stderr, "\r\033[K");
    switch (l) {
      case LogLevel::Debug: logger->debug(m); break;
      case LogLevel::Info: logger->info(m); break;
      case LogLevel::Warn: logger->warn(m); break;
    }
  };
  hooks.progress = [&](const std::string& s, double f) { bar.update(s, f); };

  try {
    opt.until = parse_stage(until);
    if (out_dir.empty()) {
      std::string stem = opt.example;
      if (stem.empty()) {
        stem = opt.input;
        size_t sl = stem.find_last_of("/\\");
        if (sl != std::string::npos) stem = stem.substr(sl + 1);
        size_t dot = stem.find_last_of('.');
        if (dot != std::string::npos && dot > 0) stem = stem.substr(0, dot);
      }
      out_dir = "out/" + stem;
    }
    opt.out_dir = out_dir;
    if (!beta_sweep.empty()) {
      if (opt.until < Stage::Polycube) opt.until = Stage::Polycube;
      const auto summary = run_beta_sweep(opt, beta_sweep, hooks);
      int code = 0;
      std::printf("%8s  %-6s %8s %7s %10s %10s %10s %8s\n", "beta", "status", "corners", "charts", "arap_def",
                  "arap_poly", "l1", "seconds");
      for (const auto& r : summary["beta_sweep"]) {
        auto num = [&](const char* k) { return r.contains(k) ? r[k].get<double>() : -1.0; };
        std::printf("%8g  %-6s %8.0f %7.0f %10.4f %10.4f %10.2e %8.1f\n", r["beta"].get<double>(),
                    r["status"].get<std::string>().c_str(), num("corners"), num("charts"),
                    num("deformed_arap_distortion"), num("arap_distortion"), num("l1_quality"), num("seconds"));
        if (code == 0 && r.contains("exit_code")) code = r["exit_code"].get<int>();
      }
      logger->info("beta sweep written to {}/beta_sweep.tsv", out_dir);
      return code;
    }
    auto report = run_pipeline(opt, hooks);
    logger->info("done in {:.2f} s; results in {}/ (report.json)", report["timings"]["total"].get<double>(), out_dir);
    return 0;
  } catch (const Error& e) {
    logger->error("{}", e.what());
    return exit_code(e.kind());
  } catch (const std::bad_alloc&) {
    logger->error("out of memory");
    return 70;
  } catch (const std::exception& e) {
    logger->error("internal error: {}", e.what());
    return 70;
  }
}
