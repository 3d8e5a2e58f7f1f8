#include "polycube/hex/extract.h"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>

#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/geometry/closest_point.h"
#include "polycube/geometry/feature_capture.h"
#include "polycube/geometry/features.h"
#include "polycube/geometry/tet_locator.h"
#include "polycube/hex/grading.h"
#include "polycube/hex/optimize.h"
#include "polycube/hex/snap.h"
#include "polycube/hex/untangle.h"

namespace polycube::hex {

namespace {

// Per-axis piecewise-linear map between polycube heights and snapped integers.
struct AxisMap {
  std::vector<double> h;  // sorted heights
  std::vector<int> n;     // their integers
  // Polycube coordinate of grid coordinate g (exact at the breakpoints).
  double inverse(double g) const {
    if (h.size() == 1) return h[0];
    auto it = std::upper_bound(n.begin(), n.end(), g);
    size_t i = it == n.begin() ? 0 : static_cast<size_t>(it - n.begin()) - 1;
    i = std::min(i, n.size() - 2);
    if (g == n[i]) return h[i];
    if (g == n[i + 1]) return h[i + 1];
    const double t = (g - n[i]) / static_cast<double>(n[i + 1] - n[i]);
    return h[i] + t * (h[i + 1] - h[i]);
  }
};

double tet_volume(const MatX3d& X, const MatX4i& T, int t) {
  const Vec3 a = X.row(T(t, 0)), b = X.row(T(t, 1)), c = X.row(T(t, 2)), d = X.row(T(t, 3));
  return (b - a).dot((c - a).cross(d - a)) / 6;
}

// Crease runs are kept when their hexes are at least this good (or as good as the worst elsewhere).
constexpr double kCaptureFloor = 0.3;
// Pillow auto: a variant with inverted hexes is not untangled when the other has none and its
// worst hex at this or more (see Published in hex_mesh_from_polycube).
constexpr double kSkipUntangleAbove = 0.3;
// The hex untangling opens corners under this fraction of the mean corner volume ratio.
constexpr double kOpenCorners = 0.05;

struct GridKeyHash {
  size_t operator()(const std::array<int, 3>& k) const {
    return (static_cast<size_t>(k[0]) * 73856093u) ^ (static_cast<size_t>(k[1]) * 19349663u) ^
           (static_cast<size_t>(k[2]) * 83492791u);
  }
};


}  // namespace

HexResult hex_mesh_from_polycube(const MatX3d& rest, const MatX4i& T, const MatX3d& X_in, const MatX3i& B,
                                 const std::vector<int>& labels, const SurfaceMesh* target_in, const HexOptions& opt,
                                 const Hooks& hooks) {
  Stopwatch sw;
  HexResult r;
  // Vertices no triangle of the target uses (e.g. a tet mesh's interior when its V and boundary are
  // passed) would be taken for surface points by the fitting's samples: keep the triangles' alone.
  SurfaceMesh compacted;
  const SurfaceMesh* target = target_in ? &surface_alone(*target_in, compacted) : nullptr;
  POLYCUBE_ASSERT(static_cast<int>(labels.size()) == B.rows(), "one label per boundary triangle");
  POLYCUBE_ASSERT(rest.rows() == X_in.rows(), "rest and polycube positions differ in size");

  // ---- planes and scale ------------------------------------------------------------------
  double volume = 0;
  for (int t = 0; t < T.rows(); ++t) volume += tet_volume(X_in, T, t);
  if (!(volume > 0)) throw Error(ErrorKind::Polycube, "the polycube has no volume: no hex mesh can be built");
  Eigen::AlignedBox3d rest_box;
  for (int v = 0; v < rest.rows(); ++v) rest_box.extend(rest.row(v).transpose());
  const double diag = rest_box.diagonal().norm();
  double s = 0;
  if (opt.cells_per_unit > 0) {
    s = opt.cells_per_unit;
  } else if (opt.hex_size > 0) {
    s = 1 / (opt.hex_size * diag);
  } else {
    if (opt.target_hexes <= 0) throw Error(ErrorKind::Usage, "give a positive hex count or hex size");
    s = std::cbrt(opt.target_hexes / volume);
  }
  r.cells_per_unit = s;
  // Graded grid (grading.h): the snapping and the extraction work on the polycube warped per axis.
  Grading graded;
  const bool grade = opt.grading.strength > 0;
  if (grade) {
    GradingOptions go = opt.grading;
    go.sharp_angle_deg = opt.sharp_angle_deg;
    graded = grade_polycube(rest, T, X_in, B, labels, s, go);
    std::string densities;
    for (int k = 0; k < 3; ++k) {
      r.grading_max_slope[k] = graded.max_slope[k];
      r.grading_min_slope[k] = graded.min_slope[k];
      densities += (k ? ", " : "") + std::to_string(graded.min_slope[k]) + "-" + std::to_string(graded.max_slope[k]);
    }
    hooks.debug("grading: sheet density per axis " + densities + "; " + std::to_string(graded.turned_over) +
                " tets turned over, " + std::to_string(graded.left_inverted) + " left after untangling");
  }
  const MatX3d& X = grade ? graded.Y : X_in;
  // Snapping: planes that face each other keep their order and a cell between them, the others may
  // share an integer; the polycube deformed to the snapped planes (Y, grid units) must keep every
  // tet positive, else the plain sorted snapping is tried, and last the per-axis piecewise-linear
  // map of the sorted snapping (exact, but it stretches slabs between planes that do not interact).
  Snapping sn = snap_polycube(X, T, B, labels, s, true, opt.merge_thin_steps);
  r.snapping = "constrained";
  if (sn.untangled > 0)
    hooks.debug("constrained snapping: " + std::to_string(sn.untangled) + " tets turned over by the harmonic displacement untangled (" +
                std::to_string(sn.untangle_sweeps) + " sweeps)");
  if (const std::array<int, 3> o = sn.overlap_lines; o[0] + o[1] + o[2] > 0) {
    const std::string lines = std::to_string(o[0]) + "/" + std::to_string(o[1]) + "/" + std::to_string(o[2]);
    if (!opt.folded_map)
      throw Error(ErrorKind::Polycube,
                  "the polycube overlaps itself (lines along x/y/z meeting two faces of the same orientation in a "
                  "row: " + lines + "), although every tet is positive: a hex grid needs an embedded polycube");
    // Around the inverted tets of a folded map: the order constraints read from those lines are
    // not to be trusted, every plane gets its own integer.
    hooks.debug("the folded map overlaps itself (lines along x/y/z: " + lines + "): sorted snapping");
    sn = snap_polycube(X, T, B, labels, s, false);
    r.snapping = "sorted";
  }
  // A few inverted slivers of negligible volume (in cells) do not matter to point location.
  const double kNegligible = 0.05;
  if (sn.inverted_volume > kNegligible && r.snapping == "constrained") {
    hooks.debug("constrained snapping inverts " + std::to_string(sn.inverted) + " tets (" + std::to_string(sn.inverted_volume) + " cells); trying sorted snapping");
    sn = snap_polycube(X, T, B, labels, s, false);
    r.snapping = "sorted";
  }
  std::array<AxisMap, 3> maps;
  // (Through a folded map the snapping's harmonic displacement may come out non-finite: homer with
  // --gap-barrier 1, a crash in the point location before.)
  const bool piecewise = sn.inverted_volume > kNegligible || !sn.Y.allFinite();
  if (piecewise) {
    hooks.debug("sorted snapping inverts " + std::to_string(sn.inverted) + " tets" +
                (sn.Y.allFinite() ? "" : " (non-finite coordinates)") + "; using the piecewise-linear map");
    r.snapping = "piecewise_linear";
  }
  for (int k = 0; k < 3; ++k) {
    maps[k].h = sn.heights[k];
    maps[k].n = sn.snapped[k];
    r.heights[k] = sn.heights[k];
    if (grade)
      for (double& h : r.heights[k]) h = graded.warp[k].inverse(h);
    r.snapped[k] = sn.snapped[k];
    r.cells[k] = *std::max_element(sn.snapped[k].begin(), sn.snapped[k].end());
    r.shared_planes += sn.shared[k];
    r.merged_planes += sn.merged[k];
  }
  r.min_slab_ratio = sn.min_slab_ratio;
  const long long bbox_cells = 1LL * r.cells[0] * r.cells[1] * r.cells[2];
  if (bbox_cells > 200000000LL)
    throw Error(ErrorKind::Usage, "the hex grid would have " + std::to_string(bbox_cells) +
                                      " cells in its bounding box: use a larger hex size or fewer hexes");
  hooks.info("hex grid: " + std::to_string(r.cells[0]) + " x " + std::to_string(r.cells[1]) + " x " +
             std::to_string(r.cells[2]) + " cells, " + std::to_string(maps[0].h.size()) + "/" +
             std::to_string(maps[1].h.size()) + "/" + std::to_string(maps[2].h.size()) + " planes, " +
             r.snapping + " snapping");

  // ---- cells inside the snapped polycube ------------------------------------------------
  // (A non-finite snapping took the piecewise-linear map above: only X is left to check.)
  if (piecewise && !X.allFinite())
    throw Error(ErrorKind::Polycube, "the polycube has non-finite coordinates (through a folded map?): no hex grid");
  const geometry::TetLocator loc(piecewise ? X : sn.Y, T);
  auto query = [&](double gx, double gy, double gz, bool search_all = true) {
    return piecewise ? loc.locate(Vec3(maps[0].inverse(gx), maps[1].inverse(gy), maps[2].inverse(gz)), search_all)
                     : loc.locate(Vec3(gx, gy, gz), search_all);
  };
  std::vector<std::array<int, 3>> cells;
  for (int i = 0; i < r.cells[0]; ++i) {
    hooks.report("hex", 0.4 * i / r.cells[0]);
    for (int j = 0; j < r.cells[1]; ++j)
      for (int k = 0; k < r.cells[2]; ++k) {
        const geometry::TetHit hit = query(i + 0.5, j + 0.5, k + 0.5, false);  // inside or not
        if (hit.tet >= 0 && hit.min_bary >= -1e-9) cells.push_back({i, j, k});
      }
  }
  if (cells.empty()) throw Error(ErrorKind::Polycube, "no hex-grid cell lies inside the polycube");

  // ---- vertices and hexes ---------------------------------------------------------------
  std::unordered_map<std::array<int, 3>, int, GridKeyHash> vid;
  std::vector<std::array<int, 3>> gv;
  static constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                        {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  MatX8i H(cells.size(), 8);
  for (size_t c = 0; c < cells.size(); ++c)
    for (int i = 0; i < 8; ++i) {
      const std::array<int, 3> g{cells[c][0] + kCorner[i][0], cells[c][1] + kCorner[i][1], cells[c][2] + kCorner[i][2]};
      auto [it, inserted] = vid.try_emplace(g, static_cast<int>(gv.size()));
      if (inserted) gv.push_back(g);
      H(c, i) = it->second;
    }
  const int nv = static_cast<int>(gv.size());
  MatX3d V(nv, 3);
  r.grid.resize(nv, 3);
  for (int v = 0; v < nv; ++v) {
    if (v % 4096 == 0) hooks.report("hex", 0.4 + 0.2 * v / nv);
    r.grid.row(v) << gv[v][0], gv[v][1], gv[v][2];
    const geometry::TetHit hit = query(gv[v][0], gv[v][1], gv[v][2]);
    if (hit.tet < 0)
      throw Error(ErrorKind::Polycube, "hex-grid vertex (" + std::to_string(gv[v][0]) + ", " + std::to_string(gv[v][1]) +
                                           ", " + std::to_string(gv[v][2]) + ") lies in no tet of the polycube (every tet flat)");
    if (hit.min_bary < -1e-6) ++r.max_locate_outside;
    Eigen::Vector4d b = hit.bary.cwiseMax(0.0);
    b /= b.sum();
    Vec3 p = Vec3::Zero();
    for (int j = 0; j < 4; ++j) p += b[j] * rest.row(T(hit.tet, j)).transpose();
    V.row(v) = p.transpose();
  }
  r.grid_hexes = static_cast<int>(H.rows());

  // ---- boundary: polycube-edge vertices (fixed), projection --------------------------------
  MatX4i Q = boundary_quads(H);
  std::vector<int> axes_mask(nv, 0);  // bit k: the vertex is on a boundary quad normal to axis k
  for (int q = 0; q < Q.rows(); ++q) {
    int axis = 0;
    for (int k = 0; k < 3; ++k)
      if (gv[Q(q, 0)][k] == gv[Q(q, 1)][k] && gv[Q(q, 0)][k] == gv[Q(q, 2)][k] && gv[Q(q, 0)][k] == gv[Q(q, 3)][k]) axis = k;
    for (int j = 0; j < 4; ++j) axes_mask[Q(q, j)] |= 1 << axis;
  }
  std::unique_ptr<geometry::TriangleTree> tree;
  if (target && opt.project && target->F.rows() > 0) tree = std::make_unique<geometry::TriangleTree>(target->V, target->F);
  std::vector<char> on_boundary(nv, 0);
  for (int q = 0; q < Q.rows(); ++q)
    for (int j = 0; j < 4; ++j) on_boundary[Q(q, j)] = 1;
  if (tree)
    for (int v = 0; v < nv; ++v)
      if (on_boundary[v]) V.row(v) = tree->closest(V.row(v).transpose()).point.transpose();

  // ---- features -----------------------------------------------------------------------
  // Vertices on polycube edges that lie on a sharp edge of the target slide along the polycube
  // edge (between their two edge neighbours); such polycube corners stay. Elsewhere (the target
  // is smooth there) they move on the surface like the other boundary vertices.
  std::vector<char> feature(nv, 0);
  for (int v = 0; v < nv; ++v) feature[v] = on_boundary[v] && (axes_mask[v] & (axes_mask[v] - 1)) != 0;
  std::vector<Vec3> target_corners;
  double corner_tol = 0;
  std::vector<int> patch;  // per target triangle
  if (tree) {
    const std::vector<unsigned char> sharp = geometry::sharp_edges(*target, opt.sharp_angle_deg);
    const MatX3i adj = face_adjacency(target->F);
    double elen = 0;
    for (int h = 0; h < r.grid_hexes; ++h) elen += (V.row(H(h, 0)) - V.row(H(h, 6))).norm() / std::sqrt(3.0);
    elen /= std::max(1, r.grid_hexes);
    for (int v = 0; v < nv; ++v)
      if (feature[v] && !geometry::near_sharp_edge(*target, sharp, adj, *tree, V.row(v).transpose(), 0.05 * elen)) feature[v] = 0;
    // Corners of the target: vertices where three or more sharp edges meet.
    std::vector<int> sharp_count(target->V.rows(), 0);
    for (int f = 0; f < target->F.rows(); ++f)
      for (int k = 0; k < 3; ++k)
        if (sharp[f] >> k & 1) {
          ++sharp_count[target->F(f, k)];  // each edge seen from both sides: counts twice
          ++sharp_count[target->F(f, (k + 1) % 3)];
        }
    for (int i = 0; i < target->V.rows(); ++i)
      if (sharp_count[i] >= 6) target_corners.push_back(target->V.row(i).transpose());
    corner_tol = 0.05 * elen;
    patch = geometry::smooth_patches(*target, sharp);
  }
  std::vector<std::array<int, 2>> slide(nv, {-1, -1});
  for (int v = 0; v < nv; ++v) {
    if (!feature[v] || __builtin_popcount(axes_mask[v]) != 2) continue;
    const int c = axes_mask[v] == 3 ? 2 : axes_mask[v] == 5 ? 1 : 0;  // the edge's direction
    std::array<int, 2> e{-1, -1};
    for (int side = 0; side < 2; ++side) {
      std::array<int, 3> g = gv[v];
      g[c] += side ? 1 : -1;
      auto it = vid.find(g);
      if (it != vid.end() && on_boundary[it->second] && (axes_mask[it->second] & axes_mask[v]) == axes_mask[v])
        e[side] = it->second;
    }
    if (e[0] >= 0 && e[1] >= 0) {
      slide[v] = e;
      feature[v] = 0;
    }
  }
  // Polycube corners stay only on corners of the target: elsewhere (a polycube edge turning along a
  // straight sharp edge of the input) a fixed corner would keep a flat hex corner (block, mambo_B9).
  for (int v = 0; v < nv; ++v) {
    if (feature[v] && opt.free_corners) {
      bool on_corner = false;
      for (const Vec3& c : target_corners) on_corner = on_corner || (c - V.row(v).transpose()).norm() <= corner_tol;
      if (!on_corner) feature[v] = 0;
    }
    r.sharp_vertices += feature[v] || slide[v][0] >= 0;
  }

  // Creases of the target no boundary quad edge follows (a chamfer round a hole, a crease fading
  // out inside a face): a variant moves the nearest path of boundary vertices onto each and keeps
  // it there (HexOptions::capture_creases; judged below).
  MatX3d V_cap;
  std::vector<geometry::FeatureCaptureStats::Run> runs;
  if (tree && opt.capture_creases) {
    const std::vector<unsigned char> creases =
        geometry::crease_edges(*target, opt.sharp_angle_deg, opt.capture_angle_deg);
    std::vector<char> locked(nv, 0), snapped;
    for (int v = 0; v < nv; ++v) locked[v] = feature[v] || slide[v][0] >= 0;
    V_cap = V;
    geometry::FeatureCaptureStats fc = geometry::capture_sharp_edges(V_cap, Q, *target, creases, locked, snapped);
    r.crease_runs = fc.runs;
    runs = std::move(fc.captured_runs);
  }

  // ---- pillowing and optimization -----------------------------------------------------------
  struct Candidate {
    MatX3d V;
    MatX8i H;
    HexQuality extracted, quality;
    int pillow_hexes = 0, moves = 0, captured = 0;
    int untangle_before = 0, untangle_after = -1;
    bool untangle_skipped = false;  // the other variant was valid and good enough (see Published)
    geometry::SurfaceFitStats fit;
    bool refitted = false;  // fitted again after the untangling
    double hausdorff_before_refit = -1;  // the Hausdorff distance before that (-1: not tried)
    std::vector<char> fixed;
    std::vector<std::array<int, 2>> slide;
  };
  // Runs on its own thread when both variants are tried: reports progress only when `report`.
  // Two-sided Hausdorff distance between the boundary of hexes (P, Hc) and the target, as the
  // report measures it.
  const auto boundary_distance = [&](const MatX3d& P, const MatX8i& Hc) {
    return hausdorff(P, triangulate_quads(boundary_quads(Hc)), target->V, target->F).max;
  };
  // Pillow auto: the two variants run side by side and publish their state after the fitting
  // (final unless hexes are inverted); a variant with inverted hexes looks at the other's before
  // untangling, and skips that when the other has none and its worst hex at kSkipUntangleAbove
  // or more: the untangling (with its optimization and fitting again) took 19 of fandisk's 27 s
  // and 10 of the bumpy torus' 26 s of hex stage, for a variant whose worst hex came out at
  // 7e-5 and 0.011, against 0.44 and 0.53 with the pillow layer. The rule depends on the other
  // variant's published state only, not on which thread is faster.
  struct Published {
    bool done = false;
    int inverted = 0;
    double sj_min = 0;
  };
  std::array<Published, 2> published;
  std::mutex published_mutex;
  std::condition_variable published_cv;
  auto finish = [&](bool pillow, bool report, bool capture = false, int slot = -1) {
    const MatX3d& VS = capture ? V_cap : V;  // the grid vertices (with the crease runs moved)
    Candidate c;
    c.V = VS;
    c.H = H;
    std::vector<char> fixed = feature;
    if (capture)
      for (const auto& run : runs)
        for (int v : run.vertices) fixed[v] = 1;
    std::vector<std::array<int, 2>> sl = slide;
    if (pillow) {
      // Inner copies: each boundary vertex moves a fraction of the way to the mean centroid of its
      // hexes, so the layer's thickness follows the local hex size (thin parts included) and
      // every inner copy starts inside the hexes it came from.
      std::vector<Vec3> centre(nv, Vec3::Zero());
      std::vector<int> count(nv, 0);
      for (int h = 0; h < H.rows(); ++h) {
        Vec3 m = Vec3::Zero();
        for (int i = 0; i < 8; ++i) m += VS.row(H(h, i)).transpose();
        m /= 8;
        for (int i = 0; i < 8; ++i) {
          centre[H(h, i)] += m;
          ++count[H(h, i)];
        }
      }
      std::vector<int> inner(nv, -1);
      int next = nv;
      for (int v = 0; v < nv; ++v)
        if (on_boundary[v]) inner[v] = next++;
      c.V.conservativeResize(next, 3);
      for (int v = 0; v < nv; ++v)
        if (inner[v] >= 0)
          c.V.row(inner[v]) = VS.row(v) + opt.pillow_thickness * (centre[v] / count[v] - VS.row(v).transpose()).transpose();
      c.H.resize(H.rows() + Q.rows(), 8);
      for (int h = 0; h < H.rows(); ++h)
        for (int i = 0; i < 8; ++i) c.H(h, i) = inner[H(h, i)] >= 0 ? inner[H(h, i)] : H(h, i);
      for (int q = 0; q < Q.rows(); ++q) {
        const int h = static_cast<int>(H.rows()) + q;
        for (int j = 0; j < 4; ++j) {
          c.H(h, j) = inner[Q(q, j)];
          c.H(h, 4 + j) = Q(q, j);
        }
      }
      c.pillow_hexes = static_cast<int>(Q.rows());
      fixed.resize(next, 0);
      sl.resize(next, {-1, -1});
    }
    c.extracted = hex_quality(c.V, c.H);
    Hooks quiet;
    const OptimizeStats os = optimize_hexes(c.V, c.H, fixed, sl, tree.get(), patch.empty() ? nullptr : &patch,
                                            opt.smooth_iterations, opt.optimize_below, opt.max_edge_ratio,
                                            report ? hooks : quiet);
    c.moves = os.laplacian_moves + os.optimized_moves;
    if (capture) {
      // Runs whose hexes stay under min(0.3, the worst elsewhere) are undone (their vertices back
      // where the extraction put them, free again), then the mesh is optimized again.
      std::vector<std::vector<int>> vh(c.V.rows());
      for (int h = 0; h < c.H.rows(); ++h)
        for (int i = 0; i < 8; ++i) vh[c.H(h, i)].push_back(h);
      std::vector<char> in_run(c.V.rows(), 0);
      for (const auto& run : runs)
        for (int v : run.vertices) in_run[v] = 1;
      double elsewhere = 1;
      for (int h = 0; h < c.H.rows(); ++h) {
        bool touches = false;
        for (int i = 0; i < 8; ++i) touches = touches || in_run[c.H(h, i)];
        if (!touches) elsewhere = std::min(elsewhere, scaled_jacobian(c.V, c.H, h));
      }
      int undone = 0;
      for (const auto& run : runs) {
        double m = 1;
        for (int v : run.vertices)
          for (int h : vh[v]) m = std::min(m, scaled_jacobian(c.V, c.H, h));
        if (m >= std::min(kCaptureFloor, elsewhere)) {
          ++c.captured;
          continue;
        }
        ++undone;
        for (int v : run.vertices) {
          c.V.row(v) = V.row(v);
          fixed[v] = feature[v];
        }
      }
      if (undone > 0) {
        const OptimizeStats again = optimize_hexes(c.V, c.H, fixed, sl, tree.get(), patch.empty() ? nullptr : &patch,
                                                   opt.smooth_iterations, opt.optimize_below, opt.max_edge_ratio,
                                                   quiet);
        c.moves += again.laplacian_moves + again.optimized_moves;
      }
    }
    // Boundary vertices fitted to the target (they slide on it), then the inner ones follow.
    auto fit_boundary = [&](MatX3d& W) {
      const MatX4i Qb = boundary_quads(c.H);
      const int n = static_cast<int>(W.rows());
      std::vector<std::vector<int>> vh(n);
      for (int h = 0; h < c.H.rows(); ++h)
        for (int i = 0; i < 8; ++i) vh[c.H(h, i)].push_back(h);
      std::vector<char> free_vertex(n, 0);
      for (int q = 0; q < Qb.rows(); ++q)
        for (int j = 0; j < 4; ++j) {
          const int v = Qb(q, j);
          free_vertex[v] = !fixed[v] && sl[v][0] < 0;
        }
      auto worst = [&](int v) {
        double m = 1e300;
        for (int h : vh[v]) m = std::min(m, scaled_jacobian(W, c.H, h));
        return m;
      };
      const geometry::SurfaceFitStats f = geometry::fit_to_surface(W, Qb, *target, *tree, free_vertex,
                                                                   patch.empty() ? nullptr : &patch, worst, opt.fit);
      // The inner vertices follow the fitted boundary (it stays where it is).
      if (f.moves > 0 && opt.smooth_iterations > 0)
        optimize_hexes(W, c.H, fixed, sl, nullptr, nullptr, std::min(opt.smooth_iterations, 10), opt.optimize_below,
                       opt.max_edge_ratio, quiet);
      return f;
    };
    if (tree && opt.fit.rounds > 0) c.fit = fit_boundary(c.V);
    c.quality = hex_quality(c.V, c.H);
    if (slot >= 0) {
      {
        std::lock_guard<std::mutex> lock(published_mutex);
        published[slot] = {true, c.quality.inverted, c.quality.sj_min};
      }
      published_cv.notify_all();
    }
    // (Not when the optimization is off: the quad stage takes the grid's boundary as extracted.)
    const bool untangle = opt.untangle && opt.smooth_iterations > 0 && c.quality.inverted > 0;
    if (slot >= 0 && untangle) {
      std::unique_lock<std::mutex> lock(published_mutex);
      published_cv.wait(lock, [&] { return published[1 - slot].done; });
      const Published& other = published[1 - slot];
      if (other.inverted == 0 && other.sj_min >= kSkipUntangleAbove) c.untangle_skipped = true;
    }
    if (untangle && !c.untangle_skipped) {
      // The local optimization stops at folds that need a move making one hex worse first: the
      // inverted corners are untangled with the boundary and features held, then optimized again.
      const MatX4i Qc = boundary_quads(c.H);
      std::vector<char> hold = fixed;
      hold.resize(c.V.rows(), 0);
      for (int q = 0; q < Qc.rows(); ++q)
        for (int j = 0; j < 4; ++j) hold[Qc(q, j)] = 1;
      for (size_t v = 0; v < sl.size(); ++v)
        if (sl[v][0] >= 0) hold[v] = 1;
      MatX3d U = c.V;
      HexUntangleStats us = untangle_hex_corners(U, c.H, hold, 4, 200, kOpenCorners);
      if (us.corners_after > 0 && tree) {
        // A corner on the boundary whose two boundary edges fold over (a quad folded on the
        // surface) cannot be opened from inside: the boundary vertices of the hexes with inverted
        // corners and of the hexes next to them slide on the target (on their smooth patch).
        const std::vector<char> bad_hex = hexes_with_inverted_corners(U, c.H);
        std::vector<char> bad_vertex(U.rows(), 0), release(U.rows(), 0);
        for (int h = 0; h < c.H.rows(); ++h)
          if (bad_hex[h])
            for (int i = 0; i < 8; ++i) bad_vertex[c.H(h, i)] = 1;
        for (int h = 0; h < c.H.rows(); ++h) {
          bool near = false;
          for (int i = 0; i < 8; ++i) near = near || bad_vertex[c.H(h, i)];
          if (near)
            for (int i = 0; i < 8; ++i) release[c.H(h, i)] = 1;
        }
        std::vector<char> hold_slide = hold, slides(U.rows(), 0);
        std::vector<int> patch_of(U.rows(), -1);
        int freed = 0;
        for (int v = 0; v < U.rows(); ++v)
          if (release[v] && hold[v] && !(v < static_cast<int>(fixed.size()) && fixed[v]) && sl[v][0] < 0) {
            hold_slide[v] = 0;
            slides[v] = 1;
            if (!patch.empty()) patch_of[v] = patch[tree->closest(U.row(v).transpose()).face];
            ++freed;
          }
        if (freed > 0) {
          const SurfaceProjection onto = [&](int v, const Vec3& p, Vec3& normal) {
            const geometry::ClosestHit hit =
                patch_of[v] >= 0 ? tree->closest(p, nullptr, &patch, patch_of[v]) : tree->closest(p);
            const Vec3 a = target->V.row(target->F(hit.face, 0)), b = target->V.row(target->F(hit.face, 1)),
                       cc = target->V.row(target->F(hit.face, 2));
            normal = (b - a).cross(cc - a).normalized();
            return hit.point;
          };
          const HexUntangleStats slid = untangle_hex_corners(U, c.H, hold_slide, 4, 200, kOpenCorners, onto, &slides);
          us.sweeps += slid.sweeps;
          us.corners_after = slid.corners_after;
          if (report)
            hooks.debug("hex untangling with " + std::to_string(freed) + " boundary vertices sliding on the input: " +
                        std::to_string(slid.corners_before) + " -> " + std::to_string(slid.corners_after) +
                        " inverted corners");
        }
      }
      c.untangle_before = c.quality.inverted;
      if (us.corners_after < us.corners_before) {
        optimize_hexes(U, c.H, fixed, sl, tree.get(), patch.empty() ? nullptr : &patch, opt.smooth_iterations,
                       opt.optimize_below, opt.max_edge_ratio, quiet);
        const HexQuality q = hex_quality(U, c.H);
        if (report)
          hooks.debug("hex untangling: " + std::to_string(us.corners_before) + " -> " +
                      std::to_string(us.corners_after) + " inverted corners in " + std::to_string(us.sweeps) +
                      " sweeps; inverted hexes " + std::to_string(c.quality.inverted) + " -> " +
                      std::to_string(q.inverted) + " after optimizing again (min scaled Jacobian " +
                      std::to_string(q.sj_min) + ")");
        if (q.inverted < c.quality.inverted) {
          c.V = std::move(U);
          c.quality = q;
          c.untangle_after = q.inverted;
          // Its optimization let the boundary slide for quality alone, undoing much of the fitting
          // (rocker, 31.6k hexes: Hausdorff 2.02e-3 after the fitting, 2.41e-3 after the
          // untangling): fitted again, kept when no hex gets worse than the worst before and the
          // Hausdorff distance (as the report measures it: the fitting's samples are sparser, and
          // its largest distance fell while the measured one rose on a folded torus map) drops.
          if (tree && opt.fit.rounds > 0) {
            MatX3d W = c.V;
            const geometry::SurfaceFitStats f = fit_boundary(W);
            const HexQuality q2 = hex_quality(W, c.H);
            const bool better = q2.inverted <= q.inverted && q2.sj_min >= q.sj_min - 1e-9;
            c.hausdorff_before_refit = boundary_distance(c.V, c.H);
            const double d2 = better ? boundary_distance(W, c.H) : c.hausdorff_before_refit;
            if (report)
              hooks.debug("hex fitting after the untangling: Hausdorff " + std::to_string(c.hausdorff_before_refit) +
                          " -> " + std::to_string(d2) + ", min scaled Jacobian " + std::to_string(q.sj_min) + " -> " +
                          std::to_string(q2.sj_min) + ", " + std::to_string(q2.inverted) + " inverted");
            if (better && d2 < c.hausdorff_before_refit) {
              c.V = std::move(W);
              c.quality = q2;
              c.fit.rounds += f.rounds;
              c.fit.focus_rounds += f.focus_rounds;
              c.fit.moves += f.moves;
              c.fit.max_after = f.max_after;
              c.fit.mean_after = f.mean_after;
              c.refitted = true;
            }
          }
        }
      }
    }
    c.fixed = fixed;
    c.slide = sl;
    return c;
  };
  std::vector<bool> tries;
  if (opt.pillow != "on") tries.push_back(false);
  if (opt.pillow != "off") tries.push_back(true);
  // Both cores: the two variants are independent.
  std::vector<Candidate> cands(tries.size());
  {
    std::vector<std::thread> th;
    const bool both = tries.size() == 2;
    for (size_t i = 1; i < tries.size(); ++i)
      th.emplace_back([&, i] { cands[i] = finish(tries[i], false, false, both ? static_cast<int>(i) : -1); });
    cands[0] = finish(tries[0], true, false, both ? 0 : -1);
    for (auto& t : th) t.join();
  }
  Candidate best;
  bool have = false;
  for (size_t i = 0; i < tries.size(); ++i) {
    const bool p = tries[i];
    Candidate& c = cands[i];
    hooks.debug(std::string(p ? "with" : "without") + " pillowing: scaled Jacobian min " +
                std::to_string(c.quality.sj_min) + ", mean " + std::to_string(c.quality.sj_mean));
    if (c.untangle_skipped)
      hooks.debug(std::string(p ? "with" : "without") + " pillowing: " + std::to_string(c.quality.inverted) +
                  " hexes inverted, not untangled (the other variant has none)");
    r.tried.push_back({p ? "pillow" : "no_pillow", c.quality.sj_min, c.quality.sj_mean, c.untangle_skipped});
    // Better: higher worst scaled Jacobian (beyond round-off), then higher mean.
    if (!have || c.quality.sj_min > best.quality.sj_min + 1e-3 ||
        (c.quality.sj_min > best.quality.sj_min - 1e-3 && c.quality.sj_mean > best.quality.sj_mean)) {
      best = std::move(c);
      have = true;
    }
  }
  if (!runs.empty()) {
    // The crease variant of the chosen one, kept when its boundary is closer to the target (the
    // two-sided Hausdorff distance, as the report measures it) and its worst hex is at least
    // min(0.3, the worst without); a worse worst hex only for a smaller distance.
    Candidate cap = finish(best.pillow_hexes > 0, false, true);
    const double d_base = boundary_distance(best.V, best.H),
                 d_cap = cap.captured > 0 ? boundary_distance(cap.V, cap.H) : 1e300;
    const bool keep = cap.captured > 0 && d_cap < d_base &&
                      cap.quality.sj_min >= std::min(kCaptureFloor, best.quality.sj_min) - 1e-9;
    hooks.debug("hex crease capture: " + std::to_string(runs.size()) + " runs, " + std::to_string(cap.captured) +
                " kept after the optimization; Hausdorff " + std::to_string(d_cap) + " (" + std::to_string(d_base) +
                " without), worst hex " + std::to_string(cap.quality.sj_min) + " (" +
                std::to_string(best.quality.sj_min) + " without): " + (keep ? "kept" : "not kept"));
    if (keep) best = std::move(cap);
  }
  r.crease_captured = best.captured;
  V = std::move(best.V);
  H = std::move(best.H);
  r.pillow_hexes = best.pillow_hexes;
  r.extracted = best.extracted;
  r.smooth_moves = best.moves;
  r.untangle_inverted_before = best.untangle_before;
  r.untangle_inverted_after = best.untangle_after;
  r.fit = best.fit;
  r.refitted_after_untangling = best.refitted;
  r.hausdorff_before_refit = best.hausdorff_before_refit;
  r.grid.conservativeResize(V.rows(), 3);
  for (int v = nv; v < V.rows(); ++v) r.grid.row(v).setConstant(-1);
  {
    // The three worst hexes, for -v: per-sample scaled Jacobians and what kind their vertices are.
    std::vector<std::pair<double, int>> w;
    for (int h = 0; h < H.rows(); ++h) w.push_back({best.quality.per_element[h], h});
    const int nw = std::min<int>(3, static_cast<int>(w.size()));
    std::partial_sort(w.begin(), w.begin() + nw, w.end());
    const MatX4i Qb = boundary_quads(H);
    std::vector<char> bnd(V.rows(), 0);
    for (int q = 0; q < Qb.rows(); ++q)
      for (int j = 0; j < 4; ++j) bnd[Qb(q, j)] = 1;
    for (int i = 0; i < nw; ++i) {
      std::string m = "worst hex " + std::to_string(w[i].second) + (w[i].second >= r.grid_hexes ? " (pillow)" : "") +
                      ": scaled Jacobian at its corners and centre";
      std::array<Vec3, 8> c;
      for (int j = 0; j < 8; ++j) c[j] = V.row(H(w[i].second, j)).transpose();
      for (double x : scaled_jacobian_samples(c)) m += " " + std::to_string(x).substr(0, 5);
      m += "; vertices";
      for (int j = 0; j < 8; ++j) {
        const int v = H(w[i].second, j);
        m += best.fixed[v] ? " fixed" : best.slide[v][0] >= 0 ? " sliding" : bnd[v] ? " boundary" : " inner";
      }
      hooks.debug(m);
    }
  }
  r.V = std::move(V);
  r.H = std::move(H);
  r.quality = best.quality;
  r.seconds = sw.seconds();
  hooks.report("hex", 1);
  return r;
}

HexResult hex_mesh_thin_step_retries(const MatX3d& rest, const MatX4i& T, const MatX3d& X, const MatX3i& B,
                                     const std::vector<int>& labels, const SurfaceMesh* target, const HexOptions& opt,
                                     std::vector<ThinStepRetry>* retries,
                                     double* used_thin_steps, const Hooks& hooks) {
  HexOptions ho = opt;
  HexResult hr = hex_mesh_from_polycube(rest, T, X, B, labels, target, ho, hooks);
  double used = ho.merge_thin_steps;
  for (double t : {0.05, 0.25}) {
    const bool inverted = hr.quality.inverted > 0;
    if (!inverted && !(hr.quality.sj_min < opt.thin_step_retry_below)) break;
    if (t <= used || !(hr.min_slab_ratio < t)) continue;
    hooks.warn((inverted ? std::to_string(hr.quality.inverted) + " hexes inverted"
                         : "worst hex at scaled Jacobian " + std::to_string(hr.quality.sj_min)) +
               " next to planes " + std::to_string(hr.min_slab_ratio) +
               " of a cell apart; merging the planes of steps under " + std::to_string(t) +
               " cells and extracting again");
    ThinStepRetry rec{used, hr.quality.inverted, hr.quality.sj_min, false};
    ho.merge_thin_steps = t;
    HexResult again = hex_mesh_from_polycube(rest, T, X, B, labels, target, ho, hooks);
    rec.replaced = again.quality.inverted < hr.quality.inverted ||
                   (again.quality.inverted == hr.quality.inverted && again.quality.sj_min > hr.quality.sj_min + 0.05);
    hooks.debug("thin steps " + std::to_string(t) + ": " + std::to_string(again.quality.inverted) +
                " inverted, worst hex " + std::to_string(again.quality.sj_min) + (rec.replaced ? ", kept" : ", not kept"));
    if (rec.replaced) {
      hr = std::move(again);
      used = t;
    }
    if (retries) retries->push_back(rec);
  }
  if (used_thin_steps) *used_thin_steps = used;
  return hr;
}

}  // namespace polycube::hex
