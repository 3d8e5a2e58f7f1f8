#include "polycube/pipeline/pipeline.h"

#include <algorithm>
#include <numeric>
#include <array>
#include <filesystem>
#include <map>
#include <fstream>
#include <optional>
#include <sstream>
#include <cmath>

#include "polycube/core/error.h"
#include "polycube/core/parallel.h"
#include "polycube/core/topology.h"
#include "polycube/examples/examples.h"
#include "polycube/geometry/closest_point.h"
#include "polycube/hex/extract.h"
#include "polycube/hex/snap.h"
#include "polycube/io/writers.h"
#include "polycube/pipeline/measure.h"
#include "polycube/validate/tetmesh.h"

namespace polycube {

namespace fs = std::filesystem;
using nlohmann::json;

const char* to_string(Stage s) {
  switch (s) {
    case Stage::Load: return "load";
    case Stage::Tet: return "tet";
    case Stage::Deform: return "deform";
    case Stage::Polycube: return "polycube";
    case Stage::Hex: return "hex";
    case Stage::Quad: return "quad";
  }
  return "?";
}

Stage last_available_stage() { return Stage::Quad; }

Stage parse_stage(const std::string& name) {
  for (Stage s : {Stage::Load, Stage::Tet, Stage::Deform, Stage::Polycube, Stage::Hex, Stage::Quad})
    if (name == to_string(s)) {
      if (static_cast<int>(s) > static_cast<int>(last_available_stage()))
        throw Error(ErrorKind::Usage, std::string("stage '") + name + "' is not implemented yet");
      return s;
    }
  throw Error(ErrorKind::Usage, "unknown stage '" + name + "' (stages: load, tet, deform, polycube, hex, quad)");
}

const std::vector<std::string>& output_files() {
  static const std::vector<std::string> f = {"report.json", "surface.mesh", "surface.vtk", "tetmesh.mesh", "tetmesh.vtk",
                                             "deformed.mesh", "deformed.vtk", "labels.txt", "polycube.mesh",
                                             "polycube.vtk", "polycube_surface.obj", "map.obj", "hex.mesh",
                                             "hex.vtk", "quad.obj", "quad.mesh", "quad.vtk",
                                             "failed_polycube.vtk"};
  return f;
}

namespace {

/// The fitting to the surface (geometry/surface_fit.h), distances relative to the bbox diagonal.
json fit_json(const geometry::SurfaceFitStats& f, double diag) {
  return {{"rounds", f.rounds},
          {"focus_rounds", f.focus_rounds},
          {"moves", f.moves},
          {"quality_floor", f.floor},
          {"max_distance_before_rel", f.max_before / diag},
          {"max_distance_after_rel", f.max_after / diag},
          {"mean_distance_before_rel", f.mean_before / diag},
          {"mean_distance_after_rel", f.mean_after / diag}};
}

/// A mesh (A) whose Hausdorff distance to the input (B) exceeds this share of the bbox diagonal
/// misses part of the shape (blub in surface mode: 0.26, a part the polycube crushed) or bulges out
/// of it: a success all the same (the mesh is valid), but said, with the place.
constexpr double kFarFromInput = 0.05;
/// Hexes through a folded map: the largest fraction of their volume allowed outside the input.
constexpr double kOutsideInput = 0.005;
void warn_if_far(const Hooks& hooks, const hex::Hausdorff& d, double diag, const std::string& what,
                 const std::string& hint = "") {
  if (!(d.max > kFarFromInput * diag)) return;
  const bool input_side = d.b_to_a >= d.a_to_b;
  const Vec3& at = input_side ? d.b_to_a_at : d.a_to_b_at;
  std::ostringstream os;
  os << "the " << what << " is far from the input: Hausdorff distance " << d.max / diag
     << " of the bbox diagonal, reached at the " << (input_side ? "input" : what) << "'s point (" << at[0] << ", "
     << at[1] << ", " << at[2] << ")"
     << (input_side ? ": part of the shape is missing (crushed by the polycube map?)" : "") << hint;
  hooks.warn(os.str());
}

/// Slivers (edge ratio over hex::kSliverEdgeRatio) are valid (the scaled Jacobian of a thin
/// rectangle is 1) but useless to most solvers: said, with their count.
void warn_if_slivers(const Hooks& hooks, const hex::QualityStats& q, const std::string& what) {
  if (q.edge_ratio_above_100 == 0) return;
  std::ostringstream os;
  os << q.edge_ratio_above_100 << " " << what << " are slivers (longest edge over " << hex::kSliverEdgeRatio
     << " x the shortest; worst " << (q.edge_ratio_max >= 1e30 ? std::string("an edge of zero length")
                                                                : std::to_string(q.edge_ratio_max))
     << "): valid, but too thin for most solvers, and the scaled Jacobian does not show them (a thin "
        "step kept a cell wide, or a part the polycube map squeezes)";
  hooks.warn(os.str());
}

void write_json(const fs::path& p, const json& j) {
  std::ofstream o(p);
  if (!o) throw Error(ErrorKind::Output, p.string() + ": cannot open for writing");
  o << j.dump(2) << "\n";
  o.close();
  if (!o) throw Error(ErrorKind::Output, p.string() + ": write failed");
}

json bbox_json(const MatX3d& V) {
  Vec3 lo = V.colwise().minCoeff(), hi = V.colwise().maxCoeff();
  return {{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}, {"diagonal", (hi - lo).norm()}};
}

// Boundary quads of hexes (outward for the convention of types.h), split into triangles.
MeshData hex_boundary_surface(const MeshData& m) {
  int nonmanifold = 0;
  const MatX3i F = hex::triangulate_quads(hex::boundary_quads(m.H, &nonmanifold));
  if (nonmanifold > 0)
    throw Error(ErrorKind::InvalidMesh, m.path + ": " + std::to_string(nonmanifold) + " hex faces are shared by more than two hexes");
  MeshData s = make_mesh_data(m.V, F, m.format);
  s.path = m.path;
  return s;
}

json surface_json(const SurfaceReport& r) {
  return {{"vertices", r.vertices},
          {"triangles", r.triangles},
          {"components", r.components},
          {"genus", r.genus},
          {"closed", r.closed},
          {"border_loops", r.border_loops},
          {"border_edges", r.border_edges},
          {"repaired", r.repaired()},
          {"repairs",
           {{"faces_flipped", r.faces_flipped},
            {"components_reversed", r.components_reversed},
            {"unreferenced_vertices_removed", r.unreferenced_removed},
            {"stl_vertices_welded", r.welded_vertices}}}};
}

json tet_json(const TetMesh& tm, const TetQuality& q) {
  return {{"vertices", tm.V.rows()},
          {"tets", tm.T.rows()},
          {"boundary_triangles", tm.boundary.rows()},
          {"inverted", q.inverted},
          {"zero_volume", q.zero_volume},
          {"min_dihedral_deg", q.min_dihedral_deg},
          {"max_dihedral_deg", q.max_dihedral_deg}};
}

}  // namespace

json run_pipeline(const PipelineOptions& opt, const Hooks& hooks) {
  Stopwatch total;
  json report;
  // OpenBLAS's thread count rounds its factorizations differently (set_blas_threads), and some
  // stages factorize before any set_blas_threads call (the realization's own CHOLMOD solves): set
  // it now, so that a stage gives the same bits whatever ran before it in the process (an
  // extraction from a saved deformation at one thread differed from the full run's in the tenth
  // digit of its ARAP: OpenBLAS's default of two threads against the deformation's one).
  set_blas_threads(hardware_threads());
  // The BLAS kernels set the rounding, hence the bits of the results (reexec_with_portable_blas).
  report["tool"] = {{"name", "polycube"},
                    {"version", POLYCUBE_VERSION},
                    {"blas_core", blas_core()},
                    {"threads", hardware_threads()}};
  report["status"] = "running";
  report["timings"] = json::object();
  const fs::path out(opt.out_dir);
  const fs::path staging = out / ".staging";

  // Prepare the output folder: nothing from an earlier run may pass for this run's result.
  {
    std::error_code ec;
    fs::create_directories(out, ec);
    if (ec || !fs::is_directory(out))
      throw Error(ErrorKind::Output, opt.out_dir + ": cannot create output folder (" + ec.message() + ")");
    for (const auto& f : output_files()) fs::remove(out / f, ec);
    fs::remove_all(staging, ec);
    fs::create_directories(staging, ec);
    if (ec) throw Error(ErrorKind::Output, staging.string() + ": cannot create (" + ec.message() + ")");
  }
  std::vector<std::string> written;
  auto stage_path = [&](const std::string& name) {
    if (std::find(written.begin(), written.end(), name) == written.end()) written.push_back(name);
    return (staging / name).string();
  };
  auto write_mesh = [&](const std::string& stem, const MeshData& m) {
    io::write_medit(stage_path(stem + ".mesh"), m);
    io::write_vtk(stage_path(stem + ".vtk"), m, opt.vtk_binary);
  };
  // tetmesh.mesh/.vtk: a tet mesh with its boundary triangles.
  auto write_tetmesh = [&](const MatX3d& V, const MatX4i& T, const MatX3i& F) {
    MeshData m;
    m.V = V;
    m.T = T;
    m.F = F;
    write_mesh("tetmesh", m);
  };

  try {
    // ---- load ---------------------------------------------------------------------------
    Stopwatch sw;
    hooks.report("load", 0);
    MeshData in;
    if (!opt.example.empty()) {
      hooks.info("building example '" + opt.example + "'");
      in = examples::make(opt.example, opt.example_mesh_size);
    } else {
      if (opt.input.empty()) throw Error(ErrorKind::Usage, "no input file given (or use --example NAME)");
      hooks.info("reading " + opt.input);
      in = io::read_mesh(opt.input, opt.cad);
    }
    report["input"] = {{"path", opt.input}, {"format", in.format}};
    report["mode"] = opt.surface ? "surface" : "volume";
    if (opt.surface && opt.until == Stage::Hex)
      throw Error(ErrorKind::Usage, "hex meshes need the volume: drop --surface (surface mode builds quads)");
    if (opt.quad_polycube != "auto" && opt.quad_polycube != "surface" && opt.quad_polycube != "volume")
      throw Error(ErrorKind::Usage, "quad polycube must be auto, surface or volume, not '" + opt.quad_polycube + "'");
    if (opt.quad_polycube != "auto" && (opt.until != Stage::Quad || opt.surface))
      hooks.warn("--quad-polycube " + opt.quad_polycube + " ignored: it applies to quads in volume mode (--quad without "
                 "--surface)");
    if (!opt.surface && opt.polycube.realize.relax_iterations > 0)
      throw Error(ErrorKind::Usage, "--relax relaxes the surface polycube map: it needs --surface");
    if (!opt.example.empty()) report["input"]["example"] = opt.example;
    if (in.T.rows() > 0 && in.H.rows() > 0)
      throw Error(ErrorKind::InvalidMesh, in.path + ": mixed tetrahedral and hexahedral meshes are not supported");

    SurfaceMesh surface;
    SurfaceLayout layout;
    TetMesh tm;
    bool have_tets = false;
    // Tet vertex of every surface vertex while the tet boundary is the input surface (empty once
    // the surface is remeshed): the polycube map then needs no transfer.
    std::vector<int> surf_to_tet;
    bool input_closed = true;
    const bool given_map = !opt.polycube_map.empty();
    if (given_map && in.T.rows() == 0)
      throw Error(ErrorKind::Usage, "--polycube-map needs the map's tet mesh as the input (e.g. an earlier run's "
                                    "tetmesh.mesh with its polycube.mesh), not a " +
                                        std::string(in.H.rows() > 0 ? "hex mesh" : "surface"));
    if (given_map && opt.surface) throw Error(ErrorKind::Usage, "--polycube-map takes a tet mesh polycube: drop --surface");
    const bool given_deformed = !opt.deformed.empty();
    if (given_deformed && in.T.rows() == 0)
      throw Error(ErrorKind::Usage, "--deformed needs the deformed mesh's tet mesh as the input (e.g. an earlier run's "
                                    "tetmesh.mesh with its deformed.mesh), not a " +
                                        std::string(in.H.rows() > 0 ? "hex mesh" : "surface"));
    if (given_deformed && (opt.surface || given_map))
      throw Error(ErrorKind::Usage, "--deformed takes a deformed tet mesh: not with --surface or --polycube-map");
    const bool given_tets = given_map || given_deformed;  // the input's tets are kept as they are
    std::vector<int> tet_vertex_map;  // tet input: new index of every vertex of the file
    if (in.T.rows() > 0) {
      // Tet mesh input: checked, its boundary validated like a surface input.
      report["input"]["kind"] = "tet";
      TetInputReport tr;
      tm = prepare_tet_input(in, tr);
      tet_vertex_map = tr.vertex_map;
      std::vector<int> back;
      const SurfaceMesh bs = compact_surface(tm.V, tm.boundary, &back);
      MeshData bm = make_mesh_data(bs.V, bs.F, in.format);
      bm.path = in.path.empty() ? "input" : in.path + " (boundary of the tet mesh)";
      ValidateOptions vo = opt.validate;
      SurfaceReport sr = validate_surface(bm, layout, vo);
      report["input"].update(surface_json(sr));
      report["input"]["vertices"] = tm.V.rows();
      report["input"]["tets"] = tm.T.rows();
      report["input"]["repairs"]["unreferenced_vertices_removed"] = tr.unreferenced_removed;
      report["input"]["repairs"]["tets_reoriented"] = tr.tets_reoriented;
      report["input"]["boundary_order"] = tr.boundary_in_file_order ? "file_triangles" : "tets";
      if (tr.tets_reoriented) report["input"]["repaired"] = true;
      surface.V = bm.V;
      surface.F = bm.F;
      // --tets, --max-size or --edge-length ask for another tet mesh: the input's boundary is
      // tetrahedralized again (a coarse input, e.g. tentacles one tet thick, cannot bend into a
      // polycube without inverting tets). Otherwise the input's tets are the tet mesh.
      const bool retet = !given_tets && !opt.surface &&
                         (opt.tet.target_tets > 0 || opt.tet.max_size > 0 || opt.tet.edge_length > 0);
      if (retet) {
        report["input"]["tets_replaced"] = true;
        hooks.info("tet input: its " + std::to_string(tm.T.rows()) +
                   " tets are replaced by a tetrahedralization of its boundary (--tets, --max-size or --edge-length given)");
        tm = TetMesh();
        input_closed = sr.closed;
      } else {
        surf_to_tet = back;
        have_tets = true;
      }
    } else {
      MeshData s = in.H.rows() > 0 ? hex_boundary_surface(in) : in;
      report["input"]["kind"] = in.H.rows() > 0 ? "hex" : "surface";
      if (in.H.rows() > 0) report["input"]["hexes"] = in.H.rows();
      ValidateOptions vo = opt.validate;
      vo.allow_open = vo.allow_open || opt.surface;
      SurfaceReport sr = validate_surface(s, layout, vo);
      input_closed = sr.closed;
      report["input"].update(surface_json(sr));
      if (sr.repaired())
        hooks.warn("input repaired: " + std::to_string(sr.faces_flipped) + " faces flipped, " +
                   std::to_string(sr.components_reversed) + " components reversed, " +
                   std::to_string(sr.unreferenced_removed) + " unreferenced vertices removed");
      surface.V = s.V;
      surface.F = s.F;
    }
    report["input"]["bbox"] = bbox_json(surface.V);
    hooks.info("input: " + std::to_string(surface.V.rows()) + " vertices, " + std::to_string(surface.F.rows()) +
               " triangles, " + std::to_string(layout.num_components()) + " component(s), genus " +
               report["input"]["genus"].dump());
    write_mesh("surface", make_mesh_data(surface.V, surface.F));
    report["timings"]["load"] = sw.seconds();
    hooks.report("load", 1);

    // ---- tet ----------------------------------------------------------------------------
    if (static_cast<int>(opt.until) >= static_cast<int>(Stage::Tet)) {
      Stopwatch st;
      hooks.report("tet", 0);
      json tj;
      // --edge-length: the surface remeshed (and validated again) first; `used_layout` follows it.
      SurfaceMesh used = surface;
      SurfaceLayout used_layout = layout;
      const double diag = (surface.V.colwise().maxCoeff() - surface.V.colwise().minCoeff()).norm();
      const double el = opt.tet.edge_length * diag;
      if (el > 0 && !have_tets) {
        if (!input_closed)
          throw Error(ErrorKind::Usage, "--edge-length remeshes closed surfaces only; this one has " +
                                            std::to_string(report["input"]["border_loops"].get<int>()) +
                                            " border loops (remesh it beforehand, or drop --edge-length)");
        hooks.info("remeshing the surface to edge length " + std::to_string(el));
        used = remesh_surface(surface, layout, el);
        MeshData rm = make_mesh_data(used.V, used.F, "remeshed");
        rm.path = "remeshed surface";
        validate_surface(rm, used_layout, opt.validate);
        used.V = rm.V;
        used.F = rm.F;
      }
      int spikes = 0;
      if (opt.tet.spike_height > 0 && (opt.surface || have_tets || !input_closed))
        hooks.warn("--remove-spikes ignored: it applies to closed surfaces tetrahedralized here, not to " +
                   std::string(opt.surface ? "surface mode" : have_tets ? "a tet mesh input" : "open surfaces"));
      if (opt.tet.spike_height > 0 && !opt.surface && !have_tets && input_closed) {
        spikes = remove_spikes(used, opt.tet.spike_height * diag);
        if (spikes > 0) {
          hooks.info("removed " + std::to_string(spikes) + " spikes of the surface lower than " +
                     std::to_string(opt.tet.spike_height) + " x diagonal");
          MeshData rm = make_mesh_data(used.V, used.F, "despiked");
          rm.path = "surface without its spikes";
          validate_surface(rm, used_layout, opt.validate);
          used.V = rm.V;
          used.F = rm.F;
        }
      }
      if (opt.surface) {
        // Surface mode: no tets; the (possibly remeshed) surface is the mesh that deforms.
        if (el <= 0) {
          surf_to_tet.resize(surface.V.rows());
          std::iota(surf_to_tet.begin(), surf_to_tet.end(), 0);
        }
        tm.V = used.V;
        tm.T.resize(0, 4);
        tm.boundary = used.F;
        tj = {{"source", "none (surface mode)"}, {"vertices", tm.V.rows()}, {"triangles", tm.boundary.rows()},
              {"tets", 0}, {"remeshed", el > 0}};
      } else if (have_tets) {
        check_tet_mesh(tm, nullptr, in.path);
        tj = tet_json(tm, measure_tets(tm.V, tm.T));
        tj["source"] = "input";
      } else {
        TetStats stats;
        hooks.info("tetrahedralizing (" + opt.tet.algorithm + ")");
        tm = tetrahedralize(used, used_layout, opt.tet, hooks, &stats);
        tj = tet_json(tm, stats.quality);
        tj["source"] = "gmsh-" + stats.algorithm;
        tj["remeshed"] = el > 0;
        tj["spikes_removed"] = spikes;
        if (el <= 0 && spikes == 0) {
          surf_to_tet.resize(surface.V.rows());
          std::iota(surf_to_tet.begin(), surf_to_tet.end(), 0);  // tetrahedralize keeps them first
        }
        tj["surface_vertices"] = stats.surface_vertices;
        tj["gmsh_runs"] = stats.attempts;
      }
      // Tets with four boundary vertices would have to flatten on polycube faces: split them.
      // (Not when a polycube map or a deformed mesh is given: its tets are those of the input.)
      const int split = opt.surface || given_tets ? 0 : split_boundary_tets(tm);
      if (split > 0) {
        check_tet_mesh(tm, nullptr, "split tet mesh");
        const TetQuality sq = measure_tets(tm.V, tm.T);
        tj["vertices"] = tm.V.rows();
        tj["tets"] = tm.T.rows();
        tj["min_dihedral_deg"] = sq.min_dihedral_deg;
        tj["max_dihedral_deg"] = sq.max_dihedral_deg;
        hooks.debug("split " + std::to_string(split) + " tets with four boundary vertices");
      }
      tj["boundary_tets_split"] = split;
      report["tetmesh"] = tj;
      if (!opt.surface) write_tetmesh(tm.V, tm.T, tm.boundary);
      report["timings"]["tet"] = st.seconds();
      if (!opt.surface) hooks.info("tet mesh: " + std::to_string(tm.V.rows()) + " vertices, " + std::to_string(tm.T.rows()) +
                 " tets, min dihedral " + std::to_string(tj["min_dihedral_deg"].get<double>()) + " deg");
      hooks.report("tet", 1);
    }

    // ---- deform -------------------------------------------------------------------------
    deform::DeformResult dr;
    auto deformed_mesh = [&] {
      MeshData dm;
      dm.V = dr.X;
      dm.F = tm.boundary;
      dm.T = tm.T;
      return dm;
    };
    // deformed.vtk: boundary faces carry their unit normal (and, once known, their label).
    auto write_deformed_vtk = [&](const io::CellFields& fields) {
      const MeshData dm = deformed_mesh();
      MatX3d normals = MatX3d::Zero(dm.F.rows() + dm.T.rows(), 3);
      for (int f = 0; f < dm.F.rows(); ++f)
        normals.row(f) = deform::area_normal(dm.V, dm.F(f, 0), dm.F(f, 1), dm.F(f, 2)).normalized().transpose();
      io::write_vtk(stage_path("deformed.vtk"), dm, opt.vtk_binary, fields, {{"normal", normals}});
    };
    // ---- user constraints (sharp / flat edges) --------------------------------------------
    std::vector<constraints::Constraint> user;
    if (!opt.export_features.empty() && opt.features != "auto")
      throw Error(ErrorKind::Usage, "--export-features needs --features auto");
    if (!opt.constraints_file.empty()) {
      user = constraints::read_constraints(opt.constraints_file);
      constraints::resolve_groups(user, in.face_group.size() == static_cast<size_t>(surface.F.rows())
                                            ? in.face_group
                                            : std::vector<std::string>{});
      for (size_t i = 0; i < user.size(); ++i) constraints::constraint_edges(user[i], surface, static_cast<int>(i));  // ids
      hooks.info("read " + std::to_string(user.size()) + " constraints from " + opt.constraints_file);
    }
    if (opt.features == "auto") {
      auto found = constraints::detect_features(surface, opt.feature_angle);
      hooks.info("detected " + std::to_string(found.size()) + " sharp feature curves (angle > " +
                 std::to_string(opt.feature_angle) + " deg)");
      if (!opt.export_features.empty()) constraints::write_constraints(opt.export_features, found);
      user.insert(user.end(), found.begin(), found.end());
    } else if (opt.features != "off") {
      throw Error(ErrorKind::Usage, "--features must be auto or off, not '" + opt.features + "'");
    }
    const std::vector<deform::FacePair> pairs =
        user.empty() || static_cast<int>(opt.until) < static_cast<int>(Stage::Deform) ? std::vector<deform::FacePair>{}
                                                                                       : deform::face_pairs(tm.boundary);
    constraints::Mapped mapped;
    json cj;
    if (!user.empty()) {
      int sharp = 0;
      for (const auto& c : user) sharp += c.sharp;
      cj = {{"count", user.size()}, {"sharp", sharp}, {"flat", static_cast<int>(user.size()) - sharp},
            {"weight", opt.constraint.weight}, {"features", opt.features}};
      if (opt.features == "auto") cj["feature_angle_deg"] = opt.feature_angle;
      if (!pairs.empty()) {
        mapped = constraints::map_to_boundary(user, surface, tm.V, tm.boundary, pairs, opt.constraint);
        int unmapped = 0;
        for (size_t i = 0; i < user.size(); ++i) unmapped += mapped.mapped_edges[i] == 0;
        cj["edges"] = mapped.terms.size();
        cj["unmapped_constraints"] = unmapped;
        if (unmapped > 0)
          hooks.warn(std::to_string(unmapped) + " constraints found no edge of the tet boundary (see report.json)");
      }
      report["constraints"] = cj;
    }

    // The deformation stage (report["polycube"] with its figures, deformed.* written), with the
    // anti-foldover barrier weight given.
    auto run_deform = [&](double barrier_weight) {
      Stopwatch sd;
      hooks.report("deform", 0);
      hooks.info(opt.surface ? "deforming the surface towards a polycube (" + std::to_string(tm.boundary.rows()) +
                                   " triangles, surface ARAP)"
                             : "deforming towards a polycube (" + std::to_string(tm.T.rows()) + " tets)");
      deform::DeformOptions dopt = opt.deform;
      dopt.barrier_weight = barrier_weight;
      dopt.edges.insert(dopt.edges.end(), mapped.terms.begin(), mapped.terms.end());
      dopt.stop_at_slim_stall = !opt.surface && opt.slim_collapse_rounds > 0 && dopt.edges.empty();
      dr = opt.surface ? deform::deform_surface_to_polycube(tm.V, tm.boundary, dopt, hooks)
                       : deform::deform_to_polycube(tm.V, tm.T, tm.boundary, dopt, hooks);
      // The paper's slim-triangle collapse: collapse, then resume at the same schedule step.
      json slim = json::array();
      const TetMesh tm_before = dr.slim_stall ? tm : TetMesh{};
      const std::vector<int> surf_to_tet_before = dr.slim_stall ? surf_to_tet : std::vector<int>{};
      for (int round = 0; dr.slim_stall; ++round) {
        MatX3d rest = tm.V, X = dr.X;
        MatX4i T = tm.T;
        MatX3i B = tm.boundary;
        std::vector<int> merged;
        int left = 0;
        const int made = chart::collapse_slim_triangles(rest, X, T, B, dopt.slim_angle_deg, merged, 10, &left, hooks);
        slim.push_back({{"schedule_step", dr.stall_step + 1}, {"iteration", dr.iterations},
                        {"slim_triangles", dr.slim_triangles}, {"collapsed", made}, {"left", left}});
        {
          std::ostringstream os;
          os << "slim-triangle collapse at schedule step " << dr.stall_step + 1 << ": " << made << " edges of "
             << dr.slim_triangles << " slim boundary triangles collapsed";
          hooks.info(os.str());
        }
        if (made > 0) {
          // Merged vertices leave the mesh; the others keep their order.
          const std::vector<int> o2n = chart::drop_merged_vertices(merged, {&rest, &X}, T, B);
          for (int& v : surf_to_tet) v = v >= 0 ? o2n[v] : -1;
          tm.V = std::move(rest);
          tm.T = std::move(T);
          tm.boundary = std::move(B);
        }
        deform::DeformOptions resume = dopt;
        resume.start = X;
        resume.first_alpha_step = dr.stall_step;
        // It stops again while collapses are made (homer stopped 7 times when it also stopped for
        // new slim triangles after a round that collapsed nothing, and its deformation then stalled
        // at l1_quality 9.8e-3).
        resume.stop_at_slim_stall = made > 0 && round + 1 < opt.slim_collapse_rounds;
        deform::DeformResult next = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, resume, hooks);
        // One record of the whole deformation.
        next.iterations += dr.iterations;
        next.factorizations += dr.factorizations;
        next.float_factorizations += dr.float_factorizations;
        next.seconds += dr.seconds;
        next.rotation = next.rotation * dr.rotation;
        for (auto& h : next.history) {
          h.iteration += dr.iterations;
          h.seconds += dr.seconds;
        }
        next.history.insert(next.history.begin(), dr.history.begin(), dr.history.end());
        dr = std::move(next);
      }
      if (!slim.empty() && !dr.converged) {
        // The collapsed mesh did not reach the target: the deformation without the collapse, from
        // rest on the input's tet mesh, and the better of the two is kept.
        hooks.info("the deformation with the slim-triangle collapse stopped at l1_quality " +
                   std::to_string(dr.l1_quality) + ": deforming again without it");
        deform::DeformOptions plain = dopt;
        plain.stop_at_slim_stall = false;
        deform::DeformResult again = deform::deform_to_polycube(tm_before.V, tm_before.T, tm_before.boundary, plain, hooks);
        const bool better = again.inverted == 0 && again.l1_quality < dr.l1_quality;
        slim.push_back({{"undone", better}, {"l1_quality_with", dr.l1_quality}, {"l1_quality_without", again.l1_quality}});
        if (better) {
          again.seconds += dr.seconds;
          dr = std::move(again);
          tm = tm_before;
          surf_to_tet = surf_to_tet_before;
        }
      }
      if (!slim.empty()) {
        // tetmesh.* and deformed.* stay a pair.
        write_tetmesh(tm.V, tm.T, tm.boundary);
        report["tetmesh"]["vertices"] = tm.V.rows();
        report["tetmesh"]["tets"] = tm.T.rows();
        report["tetmesh"]["boundary_triangles"] = tm.boundary.rows();
      }
      if (!mapped.terms.empty()) {
        // Final normal angle per constrained edge (90 for a polycube edge, 0 inside a face).
        const std::vector<double> ang = constraints::normal_angles_deg(mapped, dr.X, tm.boundary, pairs);
        json per = json::array();
        double worst = 0;
        for (size_t i = 0; i < user.size(); ++i) {
          double mn = 180, mx = 0, mean = 0, err = 0;
          int n = 0;
          for (size_t t = 0; t < ang.size(); ++t) {
            if (mapped.owner[t] != static_cast<int>(i)) continue;
            mn = std::min(mn, ang[t]);
            mx = std::max(mx, ang[t]);
            mean += ang[t];
            err = std::max(err, std::abs(ang[t] - (user[i].sharp ? 90.0 : 0.0)));
            ++n;
          }
          json e = {{"name", user[i].name}, {"type", user[i].sharp ? "sharp" : "flat"},
                    {"input_edges", mapped.input_edges[i]}, {"edges", n}};
          if (n > 0) {
            e["angle_deg"] = {{"min", mn}, {"mean", mean / n}, {"max", mx}};
            e["worst_error_deg"] = err;
            worst = std::max(worst, err);
          }
          per.push_back(e);
        }
        report["constraints"]["worst_dihedral_error_deg"] = worst;
        report["constraints"]["per_constraint"] = per;
      }
      json pj = {{"l1_quality", dr.l1_quality},
                 {"error_d", dr.error_d},
                 {"arap_distortion", dr.arap},
                 {"iterations", dr.iterations},
                 {"alpha_steps", dr.alpha_steps},
                 {"inverted_tets", dr.inverted},
                 {"converged", dr.converged},
                 {"seconds", dr.seconds},
                 {"factorizations", dr.factorizations},
                 {"float_factorizations", dr.float_factorizations},
                 {"distortion", opt.surface ? "surface_arap" : "volume_arap"},
                 {"volume_barrier_weight", dr.volume_barrier_weight},
                 {"boosted_tets", dr.boosted_tets},
                 {"crushed_tets", dr.crushed_tets},
                 {"stall_rescue", {{"ran", dr.rescue_from_quality >= 0},
                                   {"l1_quality_before", dr.rescue_from_quality},
                                   {"kept", dr.rescued}}},
                 {"slim_collapse", slim},
                 {"thickness_pairs", dr.thickness_pairs},
                 {"thin_crushed", dr.thin_crushed},
                 {"thin_crushed_after", dr.thin_crushed_after},
                 {"thickness_form", opt.deform.thickness_contact ? "contact" : "pairs"},
                 {"contact_active", dr.contact_active},
                 {"contact_step_cuts", dr.contact_step_cuts}};
      pj["rotation"] = json::array();
      for (int r = 0; r < 3; ++r) pj["rotation"].push_back({dr.rotation(r, 0), dr.rotation(r, 1), dr.rotation(r, 2)});
      json hist = json::array();
      for (const auto& h : dr.history)
        hist.push_back({{"alpha_step", h.alpha_step}, {"iteration", h.iteration}, {"alpha", h.alpha}, {"eps", h.eps},
                        {"e1", h.e1}, {"e_arap", h.e_arap}, {"error_d", h.error_d}, {"l1_quality", h.l1_quality},
                        {"step", h.step}, {"seconds", h.seconds}});
      pj["history"] = hist;
      if (!input_closed) pj["border_l1_quality"] = dr.border_quality;
      pj["options"] = {{"alpha0", opt.deform.alpha0}, {"eps0", opt.deform.eps0}, {"eps_min", opt.deform.eps_min},
                       {"beta", opt.deform.beta}, {"barrier_weight", barrier_weight},
                       {"volume_barrier", opt.deform.volume_barrier_weight},
                       {"volume_barrier_form", opt.deform.neutral_volume_barrier ? "neutral" : "log"},
                       {"locality_order", opt.deform.locality_order},
                       {"volume_boost", opt.deform.volume_boost_factor},
                       {"slim_collapse_rounds", opt.slim_collapse_rounds},
                       {"slim_angle_deg", opt.deform.slim_angle_deg},
                       {"crush_guard", opt.deform.crush_guard_weight},
                       {"crush_guard_ratio", opt.deform.crush_guard_ratio},
                       {"rescue_cg_tolerance", opt.deform.rescue_cg_tolerance},
                       {"rescue_from_step", opt.deform.rescue_from_step},
                       {"thickness", opt.deform.thickness_weight},
                       {"thickness_keep", opt.deform.thickness_keep},
                       {"gap_barrier", opt.deform.gap_weight},
                       {"max_alpha_steps", opt.deform.max_alpha_steps},
                       {"max_inner_iterations", opt.deform.max_inner_iterations},
                       {"target_quality", opt.deform.target_quality},
                       {"sqp_tolerance", opt.deform.sqp_tolerance_for(opt.surface)}};
      if (opt.surface && input_closed) {
        // Thin parts the surface deformation pressed flat (their gap across measured along the
        // normal, deform::flattened_parts; with the contact barrier, their distance across,
        // deform::contact_flattened): the polycube flattens or loses them (cow's hind legs).
        const deform::Flattened& fl = dr.thin_flattened;
        json places = json::array();
        for (int v : fl.places) places.push_back({tm.V(v, 0), tm.V(v, 1), tm.V(v, 2)});
        pj["thin_flattened"] = {{"fraction", fl.fraction},
                                {"thinnest_ratio", fl.ratio},
                                {"at", places.empty() ? json(nullptr) : places.front()},
                                {"places", places}};
        if (fl.fraction > opt.deform.thickness_retry_above && !fl.places.empty()) {
          const int worst = fl.vertex();
          std::ostringstream os;
          os << "the surface deformation pressed thin parts flat: " << 100 * fl.fraction
             << "% of the area lies on parts whose two sides came within " << opt.deform.thickness_keep
             << " of their rest gap across; the worst, where they "
             << (fl.ratio > 0 ? "are " + std::to_string(fl.ratio) + " of it apart," : std::string("crossed,"))
             << " near the input's point (" << tm.V(worst, 0) << ", " << tm.V(worst, 1) << ", "
             << tm.V(worst, 2) << ")"
             << (fl.places.size() > 1 ? " (" + std::to_string(fl.places.size()) +
                                            " places apart, in the report's polycube.thin_flattened.places)"
                                      : std::string())
             << ": the polycube flattens or loses such parts (the volume pipeline, --quad without --surface, "
                "deforms the inside too and usually keeps them"
             << (opt.deform.thickness_contact
                     ? ")"
                     : "; --thickness-form contact holds the two sides apart also where they slide along each other)");
          hooks.warn(os.str());
        }
      }
      report["polycube"] = pj;
      if (dr.inverted > 0)
        throw Error(ErrorKind::Internal, "the deformation produced " + std::to_string(dr.inverted) + " inverted tets");
      io::write_medit(stage_path("deformed.mesh"), deformed_mesh());
      write_deformed_vtk({});
      report["timings"]["deform"] = report["timings"].value("deform", 0.0) + sd.seconds();  // both runs on a retry
      hooks.info("polycube deformation: l1_quality " + std::to_string(dr.l1_quality) + ", ARAP " +
                 std::to_string(dr.arap) + ", " + std::to_string(dr.iterations) + " iterations, " +
                 std::to_string(dr.seconds) + " s" + (dr.converged ? "" : " (target not reached)"));
      if (!dr.converged)
        hooks.warn("l1_quality " + std::to_string(dr.l1_quality) + " is above the target " +
                   std::to_string(opt.deform.target_quality));
      hooks.report("deform", 1);
    };
    // A polycube map or a deformed mesh given: the file's tets must be the input's, vertex for
    // vertex. Returns its positions in the tet mesh's numbering.
    auto read_same_tets = [&](const std::string& path, const std::string& kind) {
      hooks.info("reading the " + kind + " " + path);
      const MeshData P = io::read_mesh(path, opt.cad);
      const std::string what = path + ": a " + kind + " must have the tet mesh's vertices and tets (" +
                               std::to_string(tet_vertex_map.size()) + " and " + std::to_string(in.T.rows()) +
                               " in " + (opt.input.empty() ? std::string("the input") : opt.input) + ")";
      // (A run's polycube stage rewrites tetmesh.mesh when the realization split or collapsed edges,
      // so that it matches polycube.mesh: deformed.mesh matches the tetmesh.mesh of --until deform.)
      const std::string hint = kind == "deformed mesh" ? " (use the tetmesh.mesh of a --until deform run: the polycube "
                                                         "stage rewrites it when the realization splits or collapses edges)"
                                                       : "";
      if (P.V.rows() != static_cast<Eigen::Index>(tet_vertex_map.size()) || P.T.rows() != in.T.rows())
        throw Error(ErrorKind::InvalidMesh, what + ", it has " + std::to_string(P.V.rows()) + " vertices and " +
                                                std::to_string(P.T.rows()) + " tets" + hint);
      for (int t = 0; t < P.T.rows(); ++t) {
        std::array<int, 4> a{P.T(t, 0), P.T(t, 1), P.T(t, 2), P.T(t, 3)}, b{in.T(t, 0), in.T(t, 1), in.T(t, 2), in.T(t, 3)};
        std::sort(a.begin(), a.end());
        std::sort(b.begin(), b.end());
        if (a != b)
          throw Error(ErrorKind::InvalidMesh, what + "; its tet " + std::to_string(t) + " has other vertices" + hint);
      }
      MatX3d X(tm.V.rows(), 3);
      for (size_t i = 0; i < tet_vertex_map.size(); ++i)
        if (tet_vertex_map[i] >= 0) X.row(tet_vertex_map[i]) = P.V.row(static_cast<Eigen::Index>(i));
      return X;
    };
    auto read_given_map = [&] {
      // A few tets inverted pass when hexes or quads are asked for (they may be extracted through the folds).
      return chart::polycube_from_map(tm.V, tm.T, tm.boundary, read_same_tets(opt.polycube_map, "polycube map"), 1e-6,
                                       opt.until == Stage::Hex || opt.until == Stage::Quad ? opt.hex_through_folds : 0);
    };
    if (static_cast<int>(opt.until) >= static_cast<int>(Stage::Deform) && given_deformed) {
      // The extraction starts from the given deformation: its figures are measured, nothing is written.
      dr.X = read_same_tets(opt.deformed, "deformed mesh");
      const TetQuality q = measure_tets(dr.X, tm.T);
      if (q.inverted + q.zero_volume > 0)
        throw Error(ErrorKind::InvalidMesh, opt.deformed + ": " + std::to_string(q.inverted + q.zero_volume) +
                                                " tets are inverted or flat in the deformed mesh (e.g. tet " +
                                                std::to_string(q.bad.empty() ? -1 : q.bad[0]) + ")");
      double s1 = 0, s2 = 0;
      deform::l1_measure(dr.X, tm.boundary, s1, s2);
      dr.l1_quality = s2 > 0 ? s1 / s2 - 1 : 0;
      const deform::ArapRest ar = deform::ArapRest::build(tm.V, tm.T);
      dr.arap = deform::arap_energy(dr.X, tm.T, ar, 1.0, nullptr, nullptr);
      report["polycube"] = {{"source", opt.deformed}, {"l1_quality", dr.l1_quality}};  // its ARAP: deformed_arap_distortion
      hooks.info("given deformation: l1_quality " + std::to_string(dr.l1_quality) + ", ARAP " + std::to_string(dr.arap));
    } else if (static_cast<int>(opt.until) >= static_cast<int>(Stage::Deform) && !given_map) {
      run_deform(opt.deform.barrier_weight);
    }

    // ---- polycube -----------------------------------------------------------------------
    if (static_cast<int>(opt.until) >= static_cast<int>(Stage::Polycube)) {
      // Volume-mode quads (PipelineOptions::quad_polycube "auto"): when the quads through a folded
      // map are refused (a map that overlaps itself: the grid fills a gap, or parts are missing), the
      // stage runs again from the same volume extraction with the deformed boundary's surface polycube.
      std::optional<chart::PolycubeExtraction> volume_extraction;
      std::string folded_refusal;  // set on the second pass
      bool folded_quads = false;
      auto polycube_stage = [&] {
        Stopwatch sp;
        hooks.report("polycube", 0);
        hooks.info("extracting the polycube");
        // Volume-mode quads from the deformed boundary's surface polycube straight away
        // (PipelineOptions::quad_polycube "surface"): the volume is not realized.
        const bool surface_polycube_only =
            !opt.surface && !given_map && opt.until == Stage::Quad && opt.quad_polycube == "surface";
        chart::PolycubeExtraction ex;
        if (!folded_refusal.empty())
          ex = std::move(*volume_extraction);  // the second pass (see polycube_stage)
        else if (surface_polycube_only)
          ex.realized.failure = "not realized (--quad-polycube surface)";
        else
          ex = given_map ? read_given_map() : chart::extract_polycube(tm.V, tm.T, tm.boundary, dr.X, opt.polycube, hooks);
        if (ex.corner_split_retry.tried) {
          const chart::CornerSplitRetry& c = ex.corner_split_retry;
          report["polycube"]["corner_split_retry"] = {
              {"reason", c.reason}, {"success", c.success}, {"inverted", c.inverted}, {"kept", c.kept}};
        }
        if (given_map) report["polycube"]["source"] = opt.polycube_map;
        if (!ex.realized.success && opt.surface && opt.surface_retry_barrier > 1) {
          // Surface mode: nothing but the anti-foldover barrier keeps the surface from folding into
          // thin fins (triangles of opposite normals pressed together at a corner), which no
          // polycube realizes; deform again with a stronger barrier (rocker, before the collapse
          // rounds: 3 folds left at 0.01, an exact polycube at 0.1; not the default because spot
          // fails at 0.1).
          const double w = opt.deform.barrier_weight * opt.surface_retry_barrier;
          const std::string first = ex.realized.failure;
          hooks.warn("no valid polycube (" + first + "); deforming again with the anti-foldover barrier at " +
                     std::to_string(w));
          run_deform(w);
          ex = chart::extract_polycube(tm.V, tm.T, tm.boundary, dr.X, opt.polycube, hooks);
          report["polycube"]["retry"] = {{"reason", first}, {"barrier_weight", w}};
        }
        // Volume-mode quads without a volume map (PipelineOptions::quad_polycube): the labels
        // cleaned and realized again on the deformed boundary alone; from here on the run is in surface
        // mode (tm: that boundary, no tets), and deformed.vtk keeps the volume with its labels.
        bool surface_mode = opt.surface;
        bool deformed_written = false;
        const bool fallback_allowed =
            !opt.surface && opt.until == Stage::Quad && opt.quad_polycube == "auto" && !given_map && input_closed;
        const bool folded_within = chart::is_folded(ex.realized) && ex.realized.inverted <= opt.hex_through_folds;
        if (fallback_allowed && !ex.realized.success && folded_within && folded_refusal.empty())
          volume_extraction = ex;  // for the second pass, should the quads through the folds be refused
        if (surface_polycube_only || !folded_refusal.empty() ||
            (fallback_allowed && !ex.realized.success && !folded_within)) {
          const std::string reason = ex.realized.failure;
          if (surface_polycube_only)
            hooks.info("realizing the polycube of the deformed boundary alone for the quads (--quad-polycube surface)");
          else
            hooks.warn("no valid polycube map of the volume (" + reason +
                       "); realizing the polycube of the deformed boundary alone for the quads (surface mode from here; "
                       "--quad-polycube surface goes there without trying the volume)");
          if (!folded_refusal.empty()) {
            deformed_written = true;  // by the first pass, with the same volume labels
          } else if (!given_deformed) {
            io::CellFields df;
            df["label"] = ex.labels;
            df["label"].resize(tm.boundary.rows() + tm.T.rows(), -1);
            write_deformed_vtk(df);
            deformed_written = true;
          }
          if (!folded_refusal.empty()) {
            // The first pass may have rewritten tetmesh.* with the realization's splits and
            // collapses: back to the volume that deformed.* deforms.
            write_tetmesh(tm.V, tm.T, tm.boundary);
            report["tetmesh"]["vertices"] = tm.V.rows();
            report["tetmesh"]["tets"] = tm.T.rows();
            for (const char* k : {"realization_edges_split", "realization_faces_split"}) report["tetmesh"].erase(k);
          }
          std::vector<int> kept;
          const SurfaceMesh bs = compact_surface(tm.V, tm.boundary, &kept);
          MatX3d Xs(bs.V.rows(), 3);
          for (int i = 0; i < bs.V.rows(); ++i) Xs.row(i) = dr.X.row(kept[i]);
          const Stopwatch sf;
          chart::PolycubeExtraction sx = chart::extract_polycube(bs.V, MatX4i(0, 4), bs.F, Xs, opt.polycube, hooks);
          report["polycube"]["surface_fallback"] = {{"volume_failure", reason},
                                                    {"volume_tried", !surface_polycube_only},
                                                    {"success", sx.realized.success},
                                                    {"seconds", sf.seconds()}};
          if (!folded_refusal.empty()) report["polycube"]["surface_fallback"]["folded_quads_refused"] = folded_refusal;
          if (!surface_polycube_only)
            report["polycube"]["surface_fallback"].update({{"volume_inverted", ex.realized.inverted},
                                                           {"volume_charts", ex.charts.charts},
                                                           {"volume_corners", ex.charts.corners}});
          if (!sx.realized.success)
            throw Error(ErrorKind::Polycube, "no valid polycube could be realized: " + reason +
                                                 "; nor on the deformed boundary alone: " + sx.realized.failure);
          std::vector<int> to_surface(tm.V.rows(), -1);
          for (size_t i = 0; i < kept.size(); ++i) to_surface[kept[i]] = static_cast<int>(i);
          for (int& v : surf_to_tet) v = v >= 0 ? to_surface[v] : -1;
          tm.V = bs.V;
          tm.T.resize(0, 4);
          tm.boundary = bs.F;
          dr.X = Xs;
          ex = std::move(sx);
          surface_mode = true;
          report["mode"] = "volume deformation, surface polycube";
        }
        // Charts the cleanup left far from planar on the deformed shape (chart::unflat_charts); not
        // for a given polycube map (no labelling of a deformation).
        if (!given_map) {
          json unflat = json::array();
          Eigen::AlignedBox3d dbox;
          for (int v = 0; v < dr.X.rows(); ++v) dbox.extend(dr.X.row(v).transpose());
          const double ddiag = std::max(1e-300, dbox.diagonal().norm());
          for (size_t i = 0; i < ex.unflat.size() && i < 10; ++i) {
            const chart::UnflatChart& u = ex.unflat[i];
            unflat.push_back({{"label", chart::label_name(u.label)}, {"triangles", u.faces},
                              {"spread_rel", u.spread / ddiag}, {"at", {u.at[0], u.at[1], u.at[2]}}});
          }
          report["polycube"]["unflat_charts"] = {{"count", ex.unflat.size()},
                                                 {"above_rel", opt.polycube.unflat_above},
                                                 {"widest", unflat}};
          if (!ex.unflat.empty()) {
            const chart::UnflatChart& u = ex.unflat.front();
            std::ostringstream os;
            os << ex.unflat.size() << " chart(s) of the labelling join parts of the deformed shape at different "
               << "heights into one polycube face; the widest, " << chart::label_name(u.label) << " (" << u.faces
               << " triangles), spans " << u.spread / ddiag << " of the diagonal along its axis, its farthest "
               << "triangle near the input's point (" << u.at[0] << ", " << u.at[1] << ", " << u.at[2]
               << "): the polycube flattens what it joins there (distortion, or a part pressed away)";
            hooks.warn(os.str());
          }
        }
        // Surface quads are extracted here, before the polycube is written: when the extraction holds
        // two polycubes (another start's, PolycubeExtraction::alternative), the one whose quads are
        // better is kept and written (quad::surface_quads_best_start).
        std::vector<quad::StartQuads> surface_quads;
        double surface_quad_seconds = 0;
        if (surface_mode && opt.until == Stage::Quad && ex.realized.success) {
          const Stopwatch sq;
          hooks.info("extracting the quad mesh from the surface polycube");
          const int target = opt.target_quads > 0 ? opt.target_quads : 2000;
          surface_quads = quad::surface_quads_best_start(ex, tm.V, tm.boundary, target, surface, opt.quad, hooks);
          if (surface_quads.size() > 1) {
            json compared = json::array();
            Eigen::AlignedBox3d box;
            for (int v = 0; v < surface.V.rows(); ++v) box.extend(surface.V.row(v).transpose());
            for (const quad::StartQuads& c : surface_quads)
              compared.push_back({{"start", c.start},
                                  {"polycube_arap", c.polycube_arap},
                                  {"quads", c.quads.quality.count},
                                  {"sj_min", c.quads.quality.sj_min},
                                  {"sj_mean", c.quads.quality.sj_mean},
                                  {"inverted", c.quads.quality.inverted},
                                  {"hausdorff_rel", c.distance.max / box.diagonal().norm()},
                                  {"kept", c.kept}});
            report["polycube"]["starts_compared"] = compared;
          }
          if (surface_quads.size() > 1 && surface_quads[1].kept) {
            hooks.info("the " + surface_quads[1].start + " start's polycube gives the better quads: kept");
            chart::PolycubeExtraction alternative = *ex.alternative;
            ex = std::move(alternative);
          }
          surface_quad_seconds = sq.seconds();
        }
        const chart::RealizeResult& rr = ex.realized;
        json& pj = report["polycube"];
        if (!given_map) {
          pj["deformed_arap_distortion"] = dr.arap;
          const chart::Distortion di = surface_mode ? chart::isometric_distortion_surface(tm.V, dr.X, tm.boundary)
                                                   : chart::isometric_distortion(tm.V, dr.X, tm.T);
          pj["deformed_isometric_distortion"] = {{"min", di.min}, {"mean", di.mean}, {"max", di.max}};
        }
        pj["charts"] = ex.charts.charts;
        pj["corners"] = ex.charts.corners;
        pj["chart_edges"] = ex.charts.chart_edges;
        json valence = json::object();
        for (size_t k = 3; k < ex.charts.corner_valence.size(); ++k)
          if (ex.charts.corner_valence[k]) valence[std::to_string(k)] = ex.charts.corner_valence[k];
        pj["corner_valence"] = valence;
        pj["initial_charts"] = ex.initial_charts;
        pj["cleanup"] = {{"zigzags", ex.cleanup.zigzags},       {"degenerate", ex.cleanup.degenerate},
                         {"degree1", ex.cleanup.degree1},       {"degree2", ex.cleanup.degree2},
                         {"degree3", ex.cleanup.degree3},       {"opposite", ex.cleanup.opposite}, {"rims", ex.cleanup.rims}, {"pinches", ex.cleanup.pinches},
                         {"collapsed", ex.cleanup.collapsed},   {"misoriented", ex.cleanup.misoriented},
                         {"relabelled_faces", ex.cleanup.relabelled_faces},
                         {"collapsed_ratio", ex.cleanup.collapsed_ratio},
                         {"pinch_above", ex.cleanup.pinch_above},
                         {"max_pinches", opt.polycube.cleanup.max_pinches}};
        pj["realize_options"] = {{"start", opt.polycube.realize.start},
                                 {"corner_splits", opt.polycube.corner_splits},
                                 {"eq17_budget", opt.polycube.realize.eq17_budget},
                                 {"untangle_patience", opt.polycube.realize.untangle_patience},
                                 {"local_first", opt.polycube.realize.local_first},
                                 {"surface_untangle_rounds", opt.polycube.realize.surface_untangle_rounds},
                                 {"relax_iterations", opt.polycube.realize.relax_iterations},
                                 {"continuation_retries", opt.polycube.realize.continuation_retries},
                                 {"stall_repeats", opt.polycube.realize.stall_repeats},
                                 {"volume_tolerance", opt.polycube.realize.volume_tolerance},
                                 {"folded_tolerance", opt.polycube.realize.folded_tolerance},
                                 {"penalty_path", opt.polycube.realize.penalty_path}};
        if (!mapped.terms.empty() && report["constraints"].contains("per_constraint")) {
          // In the polycube: a sharp edge is satisfied when its triangles lie on charts of different
          // axes (a polycube edge), a flat one when they share the label.
          std::vector<int> ok(user.size(), 0);
          int all_ok = 0;
          for (size_t t = 0; t < mapped.terms.size(); ++t) {
            const auto& pr = pairs[mapped.terms[t].pair];
            const int lf = ex.labels[pr.f], lg = ex.labels[pr.g];
            const bool sat = mapped.terms[t].sharp ? lf / 2 != lg / 2 : lf == lg;
            ok[mapped.owner[t]] += sat;
            all_ok += sat;
          }
          auto& per = report["constraints"]["per_constraint"];
          for (size_t i = 0; i < user.size(); ++i)
            if (per[i]["edges"].get<int>() > 0) per[i]["polycube_satisfied"] = ok[i] / per[i]["edges"].get<double>();
          report["constraints"]["polycube_satisfied"] = all_ok / static_cast<double>(mapped.terms.size());
        }
        pj["chart_graph"] = {{"valid", ex.charts.valid},
                             {"opposite_adjacent", ex.charts.opposite_adjacent},
                             {"high_valence_corners", ex.charts.high_valence_corners},
                             {"non_disk_charts", ex.charts.non_disk_charts},
                             {"invalid_topology_charts", ex.charts.invalid_topology_charts},
                             {"loops_with_few_corners", ex.charts.loops_with_few_corners},
                             {"coincident_corners", ex.charts.coincident_corners},
                             {"problems", ex.charts.problems}};
        pj["realization"] = {{"success", rr.success},
                             {"start", rr.start},
                             {"split_edges", rr.split_edges},
                             {"split_faces", rr.split_faces},
                             {"untangle_iterations", rr.untangle_iterations},
                             {"arap_iterations", rr.iterations},
                             {"planes", {rr.planes[0], rr.planes[1], rr.planes[2]}},
                             {"seconds", rr.seconds}};
        if (!rr.success) pj["realization"]["failure"] = rr.failure;
        // Hexes (or volume-mode quads) asked for and no polycube: the realization's best state may
        // still carry them when it is on the planes with a few tets inverted
        // (PipelineOptions::hex_through_folds).
        const bool folded_map = (opt.until == Stage::Hex || opt.until == Stage::Quad) && !surface_mode &&
                                chart::is_folded(rr) && rr.inverted <= opt.hex_through_folds;
        folded_quads = folded_map && opt.until == Stage::Quad;
        if (!rr.success && !folded_map) {
          std::string where =
              " (rerun with --write-failed, PipelineOptions::write_failed, to get the state reached in "
              "OUTDIR/failed_polycube.vtk)";
          if (opt.write_failed && rr.X.rows() > 0 && rr.T.rows() > 0) {
            // A diagnosis, not a result: written straight into the output folder under its own name
            // (the staged outputs are dropped on failure), through a temporary file.
            const fs::path tmp = out / "failed_polycube.vtk.tmp", dst = out / "failed_polycube.vtk";
            std::error_code ec;
            try {  // the realization's failure stays the error reported, whatever happens here
              write_failed_polycube(tmp.string(), rr.rest, rr.X, rr.T, ex.map_triangles(tm.boundary),
                                    ex.map_triangle_labels(), opt.vtk_binary);
              fs::rename(tmp, dst, ec);
              where = ec ? " (failed_polycube.vtk could not be moved into place: " + ec.message() + ")"
                         : " (the state reached, with its inverted tets marked, is in " + dst.string() + ")";
            } catch (const Error& e) {
              ec = std::make_error_code(std::errc::io_error);
              where = std::string(" (failed_polycube.vtk could not be written: ") + e.what() + ")";
            }
            if (ec) fs::remove(tmp, ec);
          } else if (rr.X.rows() == 0 || rr.T.rows() == 0) {
            where.clear();  // failed before any state: nothing to show
          }
          // Vertices of polycube edges past a corner (see chart::EdgeOrder): where chart borders run
          // on past their corners, which the realization cannot undo without flattening tets.
          const std::string order =
              ex.edge_order.past_corner > 0
                  ? "; the deformed mesh has " + std::to_string(ex.edge_order.past_corner) +
                        " vertices of polycube edges past a corner along their edge (e.g. " + ex.edge_order.example +
                        "), where chart borders run on past their corners"
                  : std::string();
          // Volume mode short of quads: quads of the surface need no volume map (quad_polycube).
          const std::string quads_hint =
              !opt.surface && !given_map && opt.until != Stage::Quad && input_closed
                  ? "; quads of the surface are still possible: --quad (its fallback realizes the deformed boundary "
                    "alone as a surface polycube; --quad-polycube surface goes there at once)"
                  : "";
          throw Error(ErrorKind::Polycube, "no valid polycube could be realized: " + rr.failure + order + where + quads_hint);
        }
        pj["map_valid"] = rr.success;
        if (folded_map) {
          // Its figures, which the realization leaves unset on failure (over every tet, the inverted
          // ones by their singular values).
          ex.realized.arap = deform::arap_energy(rr.X, rr.T, deform::ArapRest::build(rr.rest, rr.T), 1.0, nullptr, nullptr);
          ex.realized.isometric = chart::isometric_distortion(rr.rest, rr.X, rr.T);
          hooks.warn((given_map ? "the polycube map given is folded (" + rr.failure + ")"
                                : "no valid polycube could be realized (" + rr.failure + "); its best state is on the "
                                  "planes with " + std::to_string(rr.inverted) + " tets inverted") +
                     ": extracting the " + std::string(opt.until == Stage::Hex ? "hexes" : "quads") +
                     " through that folded map (polycube.* and map.obj are not written; "
                     "--hex-through-folds 0 turns this off)");
        }
        pj["arap_distortion"] = rr.arap;
        pj["inverted_tets"] = rr.inverted;
        pj["planarity_error"] = rr.planarity_error;
        pj["misoriented_faces"] = rr.misoriented_faces;
        if (!surface_mode)
          pj["edge_order"] = {{"vertices", ex.edge_order.vertices},
                              {"out_of_order", ex.edge_order.out_of_order},
                              {"past_corner", ex.edge_order.past_corner}};
        if (surface_mode) pj["edge_flips"] = ex.edge_flips;
        pj["edge_collapses"] = ex.edge_collapses;
        pj["collapse_edge_splits"] = ex.collapse_edge_splits;
        pj["isometric_distortion"] = {{"min", rr.isometric.min},
                                      {"mean", rr.isometric.mean},
                                      {"max", rr.isometric.max},
                                      {"nearly_flat", rr.isometric.nearly_flat}};
        if (rr.isometric.nearly_flat > 0 && !folded_map)
          hooks.warn("the polycube map is nearly degenerate at " + std::to_string(rr.isometric.nearly_flat) +
                     (surface_mode ? " triangles" : " tets") + " (isometric distortion above " +
                     std::to_string(static_cast<int>(chart::kNearlyFlat)) + ", max " + std::to_string(rr.isometric.max) +
                     "): valid, but elements mapped through them are crushed");
        if (input_closed) {
          // Every tet positive does not make the polycube embedded: count lines meeting two faces of
          // the same orientation in a row (the polycube overlaps itself there).
          const std::array<int, 3> o = hex::overlap_lines(rr.X, ex.map_triangles(tm.boundary), ex.map_triangle_labels());
          pj["self_overlap_lines"] = {o[0], o[1], o[2]};
          if (o[0] + o[1] + o[2] > 0)
            hooks.warn("the polycube overlaps itself (" + std::to_string(o[0] + o[1] + o[2]) +
                       " sample lines meet two faces of the same orientation in a row): it is not embedded");
        }
        if (!ex.charts.valid)
          hooks.warn("the polycube is exact and has no inverted tet, but its chart graph has problems: " +
                     (ex.charts.problems.empty() ? std::string("see report.json") : ex.charts.problems.front()));

        // Labels of the input triangles and polycube positions of the input vertices.
        const MatX3i& B = tm.boundary;
        // The polycube's triangles: B, or in surface mode B with folded triangles' edges flipped or
        // collapsed (PL: their labels).
        const MatX3i& PB = ex.map_triangles(B);
        const std::vector<int>& PL = ex.map_triangle_labels();
        bool direct = static_cast<int>(surf_to_tet.size()) == surface.V.rows() && B.rows() == surface.F.rows();
        for (int f = 0; direct && f < B.rows(); ++f) {
          std::array<int, 3> a{surf_to_tet[surface.F(f, 0)], surf_to_tet[surface.F(f, 1)], surf_to_tet[surface.F(f, 2)]};
          std::array<int, 3> b{B(f, 0), B(f, 1), B(f, 2)};
          std::sort(a.begin(), a.end());
          std::sort(b.begin(), b.end());
          direct = a == b;
        }
        std::vector<int> labels(surface.F.rows());
        MatX3d map_V(surface.V.rows(), 3);
        if (direct) {
          labels = ex.labels;
          for (int v = 0; v < surface.V.rows(); ++v) map_V.row(v) = rr.X.row(surf_to_tet[v]);
          pj["map_transfer"] = "identity";
        } else {
          // Remeshed surface: closest point on the tet boundary at rest, barycentric transfer.
          geometry::TriangleTree tree(tm.V, B);
          double worst = 0;
          for (int v = 0; v < surface.V.rows(); ++v) {
            const geometry::ClosestHit h = tree.closest(surface.V.row(v).transpose());
            worst = std::max(worst, h.dist2);
            map_V.row(v).setZero();
            for (int j = 0; j < 3; ++j) map_V.row(v) += h.bary[j] * rr.X.row(B(h.face, j));
          }
          for (int f = 0; f < surface.F.rows(); ++f) {
            const Vec3 c = (surface.V.row(surface.F(f, 0)) + surface.V.row(surface.F(f, 1)) + surface.V.row(surface.F(f, 2))) / 3;
            labels[f] = ex.labels[tree.closest(c).face];
          }
          pj["map_transfer"] = "closest_point";
          pj["map_transfer_max_distance"] = std::sqrt(worst);
        }
        {
          std::ofstream lf(stage_path("labels.txt"));
          for (int l : labels) lf << l << "\n";
          lf.close();
          if (!lf) throw Error(ErrorKind::Output, (out / "labels.txt").string() + ": write failed");
        }
        MeshData pm;
        pm.V = rr.X;
        pm.F = PB;
        pm.T = rr.T;
        io::CellFields pf;
        pf["label"] = PL;
        pf["label"].resize(PB.rows() + rr.T.rows(), -1);
        if (!folded_map) {  // a folded map is no polycube map: only the hexes built through it are a result
          io::write_medit(stage_path("polycube.mesh"), pm);
          io::write_vtk(stage_path("polycube.vtk"), pm, opt.vtk_binary, pf);
        }
        io::CellFields df;
        df["label"] = ex.labels;
        df["label"].resize(B.rows() + tm.T.rows(), -1);
        if (!given_map && !given_deformed && !deformed_written) write_deformed_vtk(df);
        if (!folded_map) {
          const SurfaceMesh ps = compact_surface(rr.X, PB);  // the polycube's boundary alone
          io::write_obj(stage_path("polycube_surface.obj"), ps.V, ps.F);
          io::write_obj(stage_path("map.obj"), map_V, surface.F);
        }
        // Labels on the input surface and the deformed mesh too.
        io::write_vtk(stage_path("surface.vtk"), make_mesh_data(surface.V, surface.F), opt.vtk_binary, {{"label", labels}});
        if ((rr.rest.rows() != tm.V.rows() || rr.T.rows() != tm.T.rows() || rr.T != tm.T) &&
            !(surface_mode && !opt.surface)) {
          // The tet mesh gained midpoints or lost the tets of collapsed edges: rewrite it so that
          // tetmesh.* and polycube.* stay a map. (Not after the surface fallback: tetmesh.* stays
          // the volume that deformed.* deforms; the surface map is map.obj.)
          write_tetmesh(rr.rest, rr.T, B);
          report["tetmesh"]["vertices"] = rr.rest.rows();
          report["tetmesh"]["tets"] = rr.T.rows();
          report["tetmesh"]["realization_edges_split"] = rr.split_edges;
          report["tetmesh"]["realization_faces_split"] = rr.split_faces;
        }
        report["timings"]["polycube"] = sp.seconds() - surface_quad_seconds;
        hooks.info("polycube: " + std::to_string(ex.charts.charts) + " charts, " + std::to_string(ex.charts.corners) +
                   " corners, ARAP " + std::to_string(rr.arap) + ", max isometric distortion " +
                   std::to_string(rr.isometric.max) + ", " + std::to_string(rr.seconds) + " s");
        hooks.report("polycube", 1);

        // Surface area of the polycube (a quad count sets the grid so that it holds that many unit squares).
        auto polycube_area = [&] {
          double a = 0, l1;
          deform::l1_measure(rr.X, B, l1, a);
          return a;
        };
        // Hexes through a folded map (or the grid of volume-mode quads): the share of their volume
        // outside the input, refused over kOutsideInput. A map that overlaps itself can fill a gap
        // between two parts pressed together by the folds, at a distance no larger than the gap.
        // Measured: homer, whose folded map closed the gap between the legs, 2.4%; valid meshes
        // (rod, bumpy torus, humanoid, the hand through its folds) 0.02-0.03%.
        auto outside_or_refuse = [&](const hex::HexResult& hr, const std::string& what) {
          const double outside = hex::volume_outside(hr.V, hr.H, surface.V, surface.F);
          if (outside > kOutsideInput)
            throw Error(ErrorKind::Polycube,
                        what + " put " + std::to_string(100 * outside) + "% of the volume outside the input (over " +
                            std::to_string(100 * kOutsideInput) +
                            "%): the folded map fills a gap between parts of the shape (no valid polycube: " +
                            rr.failure + ")");
          return outside;
        };
        // quad.mesh/.obj/.vtk and report.json "quad" (both modes).
        // seconds_before: the quad stage's so far; known: the quads' distance to the surface if
        // measured already (else measured here).
        auto write_quads = [&](const quad::QuadResult& qr, int corners, const Stopwatch& sq, double seconds_before,
                               const hex::Hausdorff* known, const json& grid, const json& extra) {
          if (qr.quality.inverted > 0)
            throw Error(ErrorKind::Polycube, std::to_string(qr.quality.inverted) +
                                                 " quads are folded or degenerate (min scaled Jacobian " +
                                                 std::to_string(qr.quality.sj_min) + "); try another --quads");
          MeshData qm;
          qm.V = qr.V;
          qm.Q = qr.Q;
          io::write_medit(stage_path("quad.mesh"), qm);
          io::write_vtk(stage_path("quad.vtk"), qm, opt.vtk_binary, {}, {}, {{"scaled_jacobian", qr.quality.per_element}});
          io::write_obj_quads(stage_path("quad.obj"), qr.V, qr.Q);
          const hex::Hausdorff hd =
              known ? *known : hex::hausdorff(qr.V, hex::triangulate_quads(qr.Q), surface.V, surface.F);
          Eigen::AlignedBox3d box;
          for (int v = 0; v < surface.V.rows(); ++v) box.extend(surface.V.row(v).transpose());
          if (folded_map && hd.max > kFarFromInput * box.diagonal().norm())  // as for hexes
            throw Error(ErrorKind::Polycube, "the quads extracted through a folded map are " +
                                                 std::to_string(hd.max / box.diagonal().norm()) +
                                                 " of the bbox diagonal from the input (over " +
                                                 std::to_string(kFarFromInput) + "): part of the shape is missing (no "
                                                 "valid polycube: " + rr.failure + ")");
          json hist = json::array();
          for (int c : qr.quality.histogram) hist.push_back(c);
          report["quad"] = {{"count", qr.quality.count},
                            {"vertices", qr.V.rows()},
                            {"irregular_vertices", qr.irregular_vertices},
                            {"corners", corners},
                            {"feature_vertices", qr.feature_vertices},
                            {"sj_min", qr.quality.sj_min},
                            {"sj_mean", qr.quality.sj_mean},
                            {"sj_max", qr.quality.sj_max},
                            {"inverted", qr.quality.inverted},
                            {"below_0_5", qr.quality.below_0_5},
                            {"sj_histogram", hist},
                            {"edge_ratio", edge_ratio_json(qr.quality)},
                            {"hausdorff", hd.max},
                            {"hausdorff_rel", hd.max / box.diagonal().norm()},
                            {"extracted", {{"sj_min", qr.extracted.sj_min}, {"sj_mean", qr.extracted.sj_mean}}},
                            {"smooth_moves", qr.smooth_moves},
                            {"search_moves", qr.search_moves},
                            {"shape_moves", qr.shape_moves},
                            {"fit", fit_json(qr.fit, box.diagonal().norm())},
                            {"options", {{"sharp_angle_deg", opt.quad.sharp_angle_deg},
                                         {"crease_angle_deg", opt.quad.capture_angle_deg},
                                         {"capture_creases", opt.quad.capture_creases},
                                         {"smooth_iterations", opt.quad.smooth_iterations},
                                         {"fit_rounds", opt.quad.fit.rounds},
                                         {"fit_floor", opt.quad.fit.quality_floor},
                                         {"max_edge_ratio", opt.quad.max_edge_ratio},
                                         {"widen_slivers", opt.quad.widen_slivers},
                                         {"shape_sweeps", opt.quad.shape_sweeps}}},
                            {"creases", {{"runs", qr.crease_runs},
                                         {"captured", qr.crease_captured},
                                         {"moved_vertices", qr.crease_moved},
                                         {"followed_before", qr.creases_before.followed},
                                         {"followed_after", qr.creases_after.followed},
                                         {"max_gap_before_rel", qr.creases_before.max_gap / box.diagonal().norm()},
                                         {"max_gap_after_rel", qr.creases_after.max_gap / box.diagonal().norm()}}},
                            {"grid", grid},
                            {"seconds", seconds_before + sq.seconds()}};
          report["quad"].update(extra);
          report["quad"]["through_folded_map"] = folded_map;
          report["timings"]["quad"] = seconds_before + sq.seconds();
          hooks.info("quad mesh: " + std::to_string(qr.quality.count) + " quads, scaled Jacobian min " +
                     std::to_string(qr.quality.sj_min) + " mean " + std::to_string(qr.quality.sj_mean) +
                     ", Hausdorff " + std::to_string(hd.max / box.diagonal().norm()) + " (RMS " +
                     std::to_string(hd.rms() / box.diagonal().norm()) +
                     ") of the bbox diagonal");
          add_hausdorff(report["quad"], hd, box.diagonal().norm(), "quad");
          // Surface mode: the surface ARAP lets developable parts be pressed flat, and the layout then
          // loses them; the volume's does not (humanoid, 2000 quads: Hausdorff 141e-3 in surface mode,
          // 8.8e-3 through the volume).
          warn_if_far(hooks, hd, box.diagonal().norm(), "quad mesh",
                      opt.surface && input_closed
                          ? "; the volume pipeline (--quad without --surface) keeps the parts the surface mode's layout "
                            "loses (with --quad-polycube surface, its deformed boundary gives the quads without a tet "
                            "realization)"
                          : "");
          warn_if_slivers(hooks, qr.quality, "quads");
          hooks.report("quad", 1);
        };

        // ---- hex --------------------------------------------------------------------------
        if (opt.until == Stage::Hex) {
          Stopwatch sh;
          hooks.report("hex", 0);
          hooks.info("extracting hexes");
          hex::HexOptions ho = opt.hex;
          ho.folded_map = folded_map;
          // Hexes inverted or poor next to planes far closer than a cell (a riser kept a cell
          // wide): the planes of thicker steps merged, extracted again, kept when better.
          std::vector<hex::ThinStepRetry> tries;
          hex::HexResult hr = hex::hex_mesh_thin_step_retries(rr.rest, rr.T, rr.X, PB, PL, &surface, ho, &tries,
                                                              &ho.merge_thin_steps, hooks);
          json retries = json::array();
          for (const auto& t : tries)
            retries.push_back({{"thin_steps", t.thin_steps}, {"inverted", t.inverted}, {"sj_min", t.sj_min},
                               {"replaced", t.replaced}});
          if (hr.quality.inverted > 0) {
            std::string why = "; try more hexes (--hexes)";
            if (hr.min_slab_ratio < 0.05)
              why = "; the polycube has planes " + std::to_string(hr.min_slab_ratio) +
                    " of a cell apart that must stay a cell apart (a slab or step far thinner than a hex: a higher "
                    "--thin-steps merges a step's planes unless they face each other), which stretches the map there";
            throw Error(ErrorKind::Polycube, std::to_string(hr.quality.inverted) +
                                                 " hexes are inverted or degenerate after optimization (min scaled "
                                                 "Jacobian " + std::to_string(hr.quality.sj_min) + ")" +
                                                 (folded_map ? " through a folded map (no valid polycube: " +
                                                                   rr.failure + ")"
                                                             : why));
          }
          const MatX3i hexF = hex::triangulate_quads(hex::boundary_quads(hr.H));
          const hex::Hausdorff hd = hex::hausdorff(hr.V, hexF, surface.V, surface.F);
          Eigen::AlignedBox3d box;
          for (int v = 0; v < surface.V.rows(); ++v) box.extend(surface.V.row(v).transpose());
          const double diag = box.diagonal().norm();
          // Through a folded map that also overlaps itself, a part may be missing from the grid: such
          // hexes are no result.
          if (folded_map && hd.max > kFarFromInput * diag)
            throw Error(ErrorKind::Polycube, "the hexes extracted through a folded map are " + std::to_string(hd.max / diag) +
                                                 " of the bbox diagonal from the input (over " +
                                                 std::to_string(kFarFromInput) + "): part of the shape is missing (no "
                                                 "valid polycube: " + rr.failure + ")");
          // ...nor are hexes filling a gap of the input.
          const double outside = folded_map ? outside_or_refuse(hr, "the hexes extracted through a folded map") : 0.0;
          MeshData hm;
          hm.V = hr.V;
          hm.H = hr.H;
          io::write_medit(stage_path("hex.mesh"), hm);
          io::write_vtk(stage_path("hex.vtk"), hm, opt.vtk_binary, {}, {}, {{"scaled_jacobian", hr.quality.per_element}});
          auto quality_json = [](const hex::HexQuality& q) {
            json hist = json::array();
            for (int c : q.histogram) hist.push_back(c);
            return json{{"count", q.count},         {"sj_min", q.sj_min},         {"sj_mean", q.sj_mean},
                        {"sj_max", q.sj_max},       {"inverted", q.inverted},     {"below_0_2", q.below_0_2},
                        {"below_0_5", q.below_0_5}, {"sj_histogram", hist},         {"edge_ratio", edge_ratio_json(q)}};
          };
          json hj = quality_json(hr.quality);
          add_hausdorff(hj, hd, diag, "hex");
          hj["vertices"] = hr.V.rows();
          hj["grid"] = {{"cells", hr.cells}, {"cells_per_unit", hr.cells_per_unit},
                        {"planes", {hr.heights[0].size(), hr.heights[1].size(), hr.heights[2].size()}},
                        {"hexes", hr.grid_hexes}, {"snapping", hr.snapping}, {"shared_planes", hr.shared_planes},
                        {"merged_planes", hr.merged_planes}, {"thin_steps", ho.merge_thin_steps},
                        {"min_slab_ratio", hr.min_slab_ratio},
                        {"grading_density_min", hr.grading_min_slope}, {"grading_density_max", hr.grading_max_slope}};
          hj["pillow_hexes"] = hr.pillow_hexes;
          hj["retries"] = retries;
          hj["sharp_vertices"] = hr.sharp_vertices;
          hj["creases"] = {{"runs", hr.crease_runs}, {"captured", hr.crease_captured}};
          hj["variants"] = json::array();
          for (const auto& t : hr.tried)
            hj["variants"].push_back({{"variant", t.variant},
                                      {"sj_min", t.sj_min},
                                      {"sj_mean", t.sj_mean},
                                      {"untangle_skipped", t.untangle_skipped}});
          hj["extracted"] = quality_json(hr.extracted);
          hj["extracted"].erase("sj_histogram");
          hj["smooth_moves"] = hr.smooth_moves;
          hj["untangled"] = {{"inverted_before", hr.untangle_inverted_before},
                             {"inverted_after", hr.untangle_inverted_after},
                             {"refitted", hr.refitted_after_untangling},
                             {"hausdorff_before_refit_rel",
                              hr.hausdorff_before_refit < 0 ? -1.0 : hr.hausdorff_before_refit / diag}};
          hj["fit"] = fit_json(hr.fit, diag);
          hj["options"] = {{"target_hexes", opt.hex.target_hexes}, {"hex_size", opt.hex.hex_size},
                           {"pillow", opt.hex.pillow}, {"smooth_iterations", opt.hex.smooth_iterations},
                           {"thin_steps", opt.hex.merge_thin_steps},
                           {"thin_step_retry_below", opt.hex.thin_step_retry_below},
                           {"max_edge_ratio", opt.hex.max_edge_ratio}, {"fit_rounds", opt.hex.fit.rounds},
                           {"fit_floor", opt.hex.fit.quality_floor}, {"fit_offset", opt.hex.fit.max_offset},
                           {"sharp_angle_deg", opt.hex.sharp_angle_deg},
                           {"capture_creases", opt.hex.capture_creases},
                           {"grading", opt.hex.grading.strength}, {"grading_measure", opt.hex.grading.measure},
                           {"grading_max", opt.hex.grading.max_ratio}};
          hj["through_folded_map"] = folded_map;
          if (folded_map) hj["volume_outside_rel"] = outside;
          hj["seconds"] = sh.seconds();
          report["hex"] = hj;
          report["timings"]["hex"] = sh.seconds();
          hooks.info("hex mesh: " + std::to_string(hr.quality.count) + " hexes, scaled Jacobian min " +
                     std::to_string(hr.quality.sj_min) + " mean " + std::to_string(hr.quality.sj_mean) +
                     ", Hausdorff " + std::to_string(hd.max / diag) + " (RMS " +
                     std::to_string(hd.rms() / diag) + ") of the bbox diagonal");
          warn_if_far(hooks, hd, diag, "hex mesh");
          warn_if_slivers(hooks, hr.quality, "hexes");
          hooks.report("hex", 1);
        }

        // ---- quad -------------------------------------------------------------------------
        if (opt.until == Stage::Quad && surface_mode) {
          Stopwatch sq;
          hooks.report("quad", 0);
          const auto kept = std::find_if(surface_quads.begin(), surface_quads.end(),
                                         [](const quad::StartQuads& c) { return c.kept; });
          if (kept == surface_quads.end()) throw Error(ErrorKind::Internal, "surface mode: no quads were extracted");
          const quad::QuadResult& qr = kept->quads;
          json retries = json::array();
          double thin_steps = opt.quad.merge_thin_steps;  // of the quads kept
          const double diag = (surface.V.colwise().maxCoeff() - surface.V.colwise().minCoeff()).norm();
          for (const quad::QuadThinStepRetry& t : kept->retries) {
            if (t.replaced) thin_steps = t.thin_steps;
            retries.push_back({{"thin_steps", t.thin_steps},
                               {"merged_planes", t.merged_planes},
                               {"edge_ratio_over_10", t.over_10},
                               {"edge_ratio_max", t.ratio_max},
                               {"sj_min", t.sj_min},
                               {"hausdorff_rel", t.hausdorff / diag},
                               {"replaced", t.replaced}});
          }
          write_quads(qr, ex.charts.corners, sq, surface_quad_seconds, &kept->distance,
                      {{"cells", qr.cells}, {"cells_per_unit", qr.cells_per_unit}, {"planes", qr.planes},
                       {"snapping", "sorted_piecewise_linear"}, {"merged_planes", qr.merged_planes},
                       {"thin_steps", thin_steps}, {"grading", opt.quad.grading.strength},
                       {"grading_density_min", qr.grading_min}, {"grading_density_max", qr.grading_max}},
                      json{{"border_loops", qr.border_loops}, {"border_vertices", qr.border_vertices},
                           {"thin_step_retries", retries}});
        }
        if (opt.until == Stage::Quad && !surface_mode) {
          Stopwatch sq;
          hooks.report("quad", 0);
          hooks.info("extracting the quad mesh of the surface");
          hex::HexOptions ho = opt.hex;
          ho.pillow = "off";
          ho.smooth_iterations = 0;
          ho.fit.rounds = 0;  // the quads are fitted to the surface themselves
          ho.folded_map = folded_map;
          bool report_grid_optimized = false;
          if (opt.target_quads > 0) ho.cells_per_unit = std::sqrt(opt.target_quads / polycube_area());
          hex::HexResult hr = hex::hex_mesh_from_polycube(rr.rest, rr.T, rr.X, PB, PL, &surface, ho, hooks);
          // Through a folded map, as for hexes: a grid filling a gap of the input gives quads
          // spanning it (the hand's grid at 2000 quads: 0.01%).
          const double grid_outside =
              folded_map ? outside_or_refuse(hr, "the hex grid the quads would come from, through a folded map,") : 0.0;
          quad::QuadResult qr = quad::quad_mesh_from_hexes(hr.V, hr.H, surface, opt.quad, hooks);
          if (qr.quality.inverted > 0 && opt.hex.smooth_iterations > 0) {
            // Grid faces straddling a sharp edge the polycube has no edge along can fold when
            // projected: untangle the grid with the hex optimization (boundary kept on the surface
            // and its features) and take its boundary.
            hooks.info(std::to_string(qr.quality.inverted) + " quads fold on the projected grid; optimizing the grid first");
            ho.smooth_iterations = opt.hex.smooth_iterations;
            hr = hex::hex_mesh_from_polycube(rr.rest, rr.T, rr.X, PB, PL, &surface, ho, hooks);
            qr = quad::quad_mesh_from_hexes(hr.V, hr.H, surface, opt.quad, hooks);
            report_grid_optimized = true;
          }
          write_quads(qr, ex.charts.corners, sq, 0, nullptr,
                      {{"cells", hr.cells}, {"cells_per_unit", hr.cells_per_unit}, {"snapping", hr.snapping},
                       {"optimized", report_grid_optimized}},
                      folded_map ? json{{"grid_volume_outside_rel", grid_outside}} : json::object());
        }
      };
      try {
        polycube_stage();
      } catch (const Error& e) {
        if (e.kind() != ErrorKind::Polycube || !folded_quads || !volume_extraction) throw;
        folded_refusal = e.what();
        hooks.warn("the quads through the folded map were refused (" + folded_refusal +
                   "); taking the deformed boundary's surface polycube instead");
        polycube_stage();
      }
    }

    // ---- publish ------------------------------------------------------------------------
    report["status"] = "ok";
    report["stopped_after"] = to_string(opt.until);
    report["timings"]["total"] = total.seconds();
    report["outputs"] = written;
    for (const auto& f : written) {
      std::error_code ec;
      fs::rename(staging / f, out / f, ec);
      if (ec) throw Error(ErrorKind::Output, (out / f).string() + ": cannot move into place (" + ec.message() + ")");
    }
    std::error_code ec;
    fs::remove_all(staging, ec);
    write_json(out / "report.json", report);
    return report;
  } catch (const Error& e) {
    std::error_code ec;
    for (const auto& f : written) fs::remove(out / f, ec);
    fs::remove_all(staging, ec);
    report["status"] = "error";
    report["error"] = {{"kind", to_string(e.kind())}, {"message", e.what()}, {"exit_code", exit_code(e.kind())}};
    report["timings"]["total"] = total.seconds();
    report.erase("outputs");
    try {
      write_json(out / "report.json", report);
    } catch (...) {
    }
    throw;
  }
}

int write_failed_polycube(const std::string& path, const MatX3d& rest, const MatX3d& X, const MatX4i& T,
                          const MatX3i& F, const std::vector<int>& labels, bool binary) {
  MeshData m;
  m.V = X;
  m.F = F;
  m.T = T;
  io::CellFields fields;
  fields["label"] = labels;
  fields["label"].resize(F.rows() + T.rows(), -1);
  fields["inverted"].assign(F.rows() + T.rows(), 0);
  int inverted = 0;
  for (int t = 0; t < T.rows(); ++t) {
    // As RealizeResult::inverted: the volume ratio to the rest tet is not positive.
    const double v = tet_volume(X.row(T(t, 0)), X.row(T(t, 1)), X.row(T(t, 2)), X.row(T(t, 3)));
    const double r = tet_volume(rest.row(T(t, 0)), rest.row(T(t, 1)), rest.row(T(t, 2)), rest.row(T(t, 3)));
    const bool bad = !(v / r > 0);
    fields["inverted"][F.rows() + t] = bad;
    inverted += bad;
  }
  io::write_vtk(path, m, binary, fields);
  return inverted;
}

json run_beta_sweep(const PipelineOptions& opt, const std::vector<double>& betas, const Hooks& hooks) {
  if (betas.empty()) throw Error(ErrorKind::Usage, "the beta sweep needs at least one value");
  for (double b : betas)
    if (!(b >= 0) || !std::isfinite(b)) throw Error(ErrorKind::Usage, "beta must be >= 0, not " + std::to_string(b));
  std::error_code ec;
  fs::create_directories(opt.out_dir, ec);
  if (ec) throw Error(ErrorKind::Output, opt.out_dir + ": cannot create the output folder (" + ec.message() + ")");
  // Results of an earlier sweep in this folder go first (only what a sweep writes).
  for (const auto& entry : fs::directory_iterator(opt.out_dir, ec)) {
    const std::string n = entry.path().filename().string();
    if ((entry.is_directory() && n.rfind("beta_", 0) == 0) || n == "beta_sweep.json" || n == "beta_sweep.tsv")
      fs::remove_all(entry.path(), ec);
  }
  json rows = json::array();
  for (double b : betas) {
    PipelineOptions o = opt;
    o.deform.beta = b;
    std::ostringstream name;
    name << "beta_" << b;
    o.out_dir = (fs::path(opt.out_dir) / name.str()).string();
    hooks.info("beta sweep: beta = " + name.str().substr(5) + " -> " + o.out_dir);
    json row = {{"beta", b}, {"folder", name.str()}};
    try {
      const json r = run_pipeline(o, hooks);
      row["status"] = "ok";
      if (r.contains("polycube")) {
        const json& p = r["polycube"];
        for (const char* k : {"corners", "charts", "arap_distortion", "deformed_arap_distortion", "l1_quality"})
          if (p.contains(k)) row[k] = p[k];
      }
      row["seconds"] = r["timings"]["total"];
    } catch (const Error& e) {
      row["status"] = "error";
      row["exit_code"] = exit_code(e.kind());
      row["message"] = e.what();
      hooks.warn("beta " + name.str().substr(5) + ": " + e.what());
    }
    rows.push_back(row);
  }
  const json summary = {{"beta_sweep", rows}};
  {
    std::ofstream f(fs::path(opt.out_dir) / "beta_sweep.json");
    f << summary.dump(1) << "\n";
    if (!f) throw Error(ErrorKind::Output, opt.out_dir + "/beta_sweep.json: write failed");
  }
  std::ofstream t(fs::path(opt.out_dir) / "beta_sweep.tsv");
  t << "beta\tstatus\tcorners\tcharts\tarap_deformed\tarap_polycube\tl1_quality\tseconds\n";
  auto cell = [](const json& r, const char* k) { return r.contains(k) ? r[k].dump() : std::string("-"); };
  for (const json& r : rows)
    t << r["beta"].get<double>() << "\t" << r["status"].get<std::string>() << "\t" << cell(r, "corners") << "\t"
      << cell(r, "charts") << "\t" << cell(r, "deformed_arap_distortion") << "\t" << cell(r, "arap_distortion") << "\t"
      << cell(r, "l1_quality") << "\t" << cell(r, "seconds") << "\n";
  if (!t) throw Error(ErrorKind::Output, opt.out_dir + "/beta_sweep.tsv: write failed");
  return summary;
}

}  // namespace polycube
