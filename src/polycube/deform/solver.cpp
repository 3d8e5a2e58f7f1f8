#include "polycube/deform/solver.h"

#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>

#include "polycube/core/error.h"
#include "polycube/core/parallel.h"
#include "polycube/deform/contact.h"
#include "polycube/deform/untangle.h"
#include "polycube/deform/sparse_system.h"
#include "polycube/validate/tetmesh.h"

namespace polycube::deform {

namespace {

Eigen::Matrix3d skew(const Vec3& w) {
  Eigen::Matrix3d S;
  S << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return S;
}

Eigen::Matrix3d exp_rotation(const Vec3& w) {
  const double th = w.norm();
  if (th < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(th, w / th).toRotationMatrix();
}

Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& M) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1;
  return U * svd.matrixV().transpose();
}

// Smoothed l1 of a set of area normals: sum_f sum_k sqrt(N_k^2 + eps |N|^2), with gradient and
// Gauss-Newton Hessian with respect to an infinitesimal rotation w (N -> N + w x N).
double rotation_objective(const std::vector<Vec3>& N, double eps, Vec3* grad, Eigen::Matrix3d* hess) {
  double h = 0;
  if (grad) grad->setZero();
  if (hess) hess->setZero();
  for (const Vec3& n : N) {
    Vec3 dg;
    Eigen::Matrix3d Hg;
    h += smoothed_l1(n, eps, grad || hess ? &dg : nullptr, hess ? &Hg : nullptr);
    if (grad) *grad += n.cross(dg);  // d/dw g(N + w x N) = N x dg
    if (hess) {
      const Eigen::Matrix3d Jn = -skew(n);  // d(w x N)/dw = -[N]x
      *hess += Jn.transpose() * Hg * Jn;
    }
  }
  return h;
}

struct Problem {
  const MatX4i& T;
  const MatX3i& B;
  std::vector<FacePair> pairs;
  ArapRest rest;
  double area0 = 1;
  const DeformOptions& opt;
  double volume_weight = 0;  // current volume-barrier weight (raised when tets block the line search)
  std::vector<double> boost;  // per-tet multiplier of the volume barrier (raised on tets that block steps)
  // Surface mode (no tets): surface ARAP on B, and the border l1 term of open surfaces.
  bool surface = false;
  SurfaceArapRest srest;
  std::vector<std::array<int, 2>> border;
  double border_h = 0;  // length weighting the border edges (see border_l1_energy)
  double area_weight = 0;  // surface mode: weight of the triangle-area barrier (area_barrier_energy)
  // Closed surfaces in surface mode: the two sides of thin parts; volume mode: of gaps between parts.
  std::vector<ThicknessPair> thickness;
  // Per kind of evaluation (energy only, with the Hessian) and per thread of evaluate's split: the
  // seconds its own terms took last time (where the ARAP's second half goes; timing only).
  mutable std::array<std::array<double, 2>, 2> side_seconds{};
  // Surface mode with DeformOptions::thickness_contact: the contact barrier (instead of the pairs
  // in `thickness`).
  std::shared_ptr<const ContactRest> contact;

  double distortion(const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) const {
    return surface ? surface_arap_energy(X, B, srest, 1.0, g, H) : arap_energy(X, T, rest, 1.0, g, H);
  }
};

struct Energies {
  double total = 0, e1 = 0, arap = 0, barrier = 0, complexity = 0, edges = 0, volume = 0;
};

// The terms on the boundary (total included): l1, anti-foldover barrier, complexity, user edges.
Energies evaluate_boundary_terms(const Problem& p, const MatX3d& X, double alpha, double eps, Eigen::VectorXd* g,
                                 HessianSink* H, double lambda) {
  Energies e;
  e.barrier = barrier_energy(X, p.B, p.pairs, p.opt.barrier_weight / std::max<size_t>(1, p.pairs.size()), g, H);
  if (!std::isfinite(e.barrier)) {
    e.total = std::numeric_limits<double>::infinity();
    return e;
  }
  e.e1 = l1_energy(X, p.B, eps, alpha / p.area0, g, H, true, lambda);
  if (!p.border.empty()) e.e1 += border_l1_energy(X, p.border, p.border_h, eps, alpha / p.area0, g, H);
  if (p.opt.beta > 0) e.complexity = complexity_energy(X, p.B, p.pairs, p.opt.beta, g, H);
  if (!p.opt.edges.empty()) e.edges = edge_energy(X, p.B, p.pairs, p.opt.edges, 1.0, g, H);
  e.total = e.e1 + e.barrier + e.complexity + e.edges;
  return e;
}

// The terms over the tets (or surface triangles): the distortion, and the volume barrier (its
// Hessian into H if given; the distortion's only when with_arap_hessian, else it is the constant
// part the caller keeps).
Energies evaluate_volume_terms(const Problem& p, const MatX3d& X, Eigen::VectorXd* g, HessianSink* H,
                               bool with_arap_hessian, bool arap_first_half = false) {
  Energies e;
  if (p.surface && p.area_weight > 0) {
    e.volume = area_barrier_energy(X, p.B, p.srest, p.area_weight, g, H);
    if (!std::isfinite(e.volume)) {
      e.total = std::numeric_limits<double>::infinity();
      return e;
    }
  }
  if (p.contact) {
    e.volume += contact_energy(X, *p.contact, p.opt.thickness_weight, g, H);
    if (!std::isfinite(e.volume)) {
      e.total = std::numeric_limits<double>::infinity();
      return e;
    }
  }
  if (!p.thickness.empty()) {
    e.volume += thickness_energy(X, p.B, p.thickness, p.opt.thickness_keep,
                                 p.surface ? p.opt.thickness_weight : p.opt.gap_weight, g, H);
    if (!std::isfinite(e.volume)) {
      e.total = std::numeric_limits<double>::infinity();
      return e;
    }
  }
  if (p.volume_weight > 0) {
    e.volume += volume_barrier_energy(X, p.T, p.rest, p.volume_weight, g, H, p.boost.empty() ? nullptr : &p.boost,
                                      p.opt.neutral_volume_barrier);
    if (!std::isfinite(e.volume)) {
      e.total = std::numeric_limits<double>::infinity();
      return e;
    }
  }
  if (!p.surface && p.opt.crush_guard_weight > 0) {
    e.volume += crush_guard_energy(X, p.T, p.rest, p.opt.crush_guard_ratio, p.opt.crush_guard_weight, g, H);
    if (!std::isfinite(e.volume)) {
      e.total = std::numeric_limits<double>::infinity();
      return e;
    }
  }
  // (arap_first_half: the caller adds the second half, see evaluate)
  e.arap = arap_first_half ? arap_energy_half(X, p.T, p.rest, 1.0, 0, g)
                           : p.distortion(X, g, with_arap_hessian ? H : nullptr);
  e.total = e.volume + e.arap;
  return e;
}

// The merit energy with its gradient (g) and Hessian approximation (H), all terms. On large meshes
// the boundary terms and the volume terms are assembled side by side on two threads, the latter
// into their own gradient and into H_side (same layout as H; the caller adds it to H after), in
// the same arithmetic with one core or two, so results do not depend on the core count.
// Measured (fandisk, 37.8k tets): assembly 5.2-5.6 s with only the ARAP gradient on the second
// thread, 4.0-4.4 s with the volume barrier beside it.
// prepare(k), if given, runs first on thread k (0: the boundary terms', 1: the volume terms'): the
// caller's setting of H's and H_side's values, one on each thread (both are large arrays).
Energies evaluate(const Problem& p, const MatX3d& X, double alpha, double eps, Eigen::VectorXd* g, HessianSink* H,
                  bool with_arap_hessian, HessianSink* H_side = nullptr, double lambda = 0,
                  const std::function<void(int)>& prepare = {}) {
  Eigen::VectorXd gv;
  if (g) gv = Eigen::VectorXd::Zero(g->size());
  Energies eb, ev;
  const bool side_by_side =
      !with_arap_hessian && (!H || H_side) && (p.surface ? p.B.rows() / 2 : p.T.rows()) >= 4000;
  if (side_by_side) {
    // Volume mode: the ARAP distortion's second half (see arap_energy_half) goes after the terms
    // of the thread whose own terms took less time at the last evaluation of this kind, rather than
    // to a third thread started by arap_energy (two threads on two cores, the arithmetic the same
    // wherever it runs). Rocker at beta 1 (132k tets), per evaluation: with the Hessian, boundary
    // terms 144 ms, volume terms 80 ms, the half 21 ms; energy only 7, 23 and 17 ms.
    const bool split_arap = !p.surface && p.T.rows() >= kArapSplitTets;
    auto& last = p.side_seconds[H ? 1 : 0];
    const int second_on = last[0] <= last[1] ? 0 : 1;
    Eigen::VectorXd ga;
    if (split_arap && g) ga = Eigen::VectorXd::Zero(g->size());
    double arap_second = 0;
    run_pair([&](int k) {
      if (prepare) prepare(k);
      Stopwatch sw;
      if (k == 0)
        eb = evaluate_boundary_terms(p, X, alpha, eps, g, H, lambda);
      else
        ev = evaluate_volume_terms(p, X, g ? &gv : nullptr, H_side, false, split_arap);
      last[k] = sw.seconds();
      if (split_arap && k == second_on) arap_second = arap_energy_half(X, p.T, p.rest, 1.0, 1, g ? &ga : nullptr);
    });
    if (split_arap && std::isfinite(ev.total)) {  // as arap_energy sums its halves
      if (g) gv += ga;
      ev.arap = 1.0 * (ev.arap + arap_second);
      ev.total = ev.volume + ev.arap;
    }
  } else {
    if (prepare) {
      prepare(0);
      prepare(1);
    }
    eb = evaluate_boundary_terms(p, X, alpha, eps, g, H, lambda);
    if (std::isfinite(eb.total)) ev = evaluate_volume_terms(p, X, g ? &gv : nullptr, H, with_arap_hessian);
  }
  Energies e = eb;
  if (!std::isfinite(eb.total) || !std::isfinite(ev.total)) {
    e.total = std::numeric_limits<double>::infinity();
    return e;
  }
  if (g) *g += gv;
  e.volume = ev.volume;
  e.arap = ev.arap;
  e.total = eb.total + ev.total;
  return e;
}

// True if a tet of X is inverted or flat; `which` (optional) receives all such tets.
bool any_inverted(const MatX3d& X, const MatX4i& T, std::vector<int>* which = nullptr) {
  bool found = false;
  for (int t = 0; t < T.rows(); ++t) {
    const Vec3 a = X.row(T(t, 0)), b = X.row(T(t, 1)), c = X.row(T(t, 2)), d = X.row(T(t, 3));
    if ((b - a).dot((c - a).cross(d - a)) <= 0) {
      if (!which) return true;
      found = true;
      which->push_back(t);
    }
  }
  return found;
}

// sum|e|_1 / sum|e|_2 - 1 over the border edges (0 without any).
double border_l1_quality(const MatX3d& X, const std::vector<std::array<int, 2>>& border) {
  double b1 = 0, b2 = 0;
  for (const auto& e : border) {
    const Vec3 d = (X.row(e[1]) - X.row(e[0])).transpose();
    b1 += d.lpNorm<1>();
    b2 += d.norm();
  }
  return b2 > 0 ? b1 / b2 - 1.0 : 0.0;
}

// Scales X about its boundary centroid so that the boundary area is area0 (the constraint C = 0).
void restore_area(MatX3d& X, const MatX3i& B, double area0) {
  double l1, a;
  l1_measure(X, B, l1, a);
  const Eigen::RowVector3d c = X.colwise().mean();
  X = ((X.rowwise() - c) * std::sqrt(area0 / a)).rowwise() + c;
}

}  // namespace

Eigen::Matrix3d best_rotation(const MatX3d& X, const MatX3i& B, double eps) {
  std::vector<Vec3> N(B.rows());
  for (int f = 0; f < B.rows(); ++f) N[f] = area_normal(X, B(f, 0), B(f, 1), B(f, 2));
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  std::vector<Vec3> cur = N;
  double h = rotation_objective(cur, eps, nullptr, nullptr);
  for (int it = 0; it < 6; ++it) {
    Vec3 g;
    Eigen::Matrix3d H;
    rotation_objective(cur, eps, &g, &H);
    if (g.norm() < 1e-9 * h) break;
    const double scale = std::max(1e-12, H.trace() / 3);
    Vec3 w = -(H + 1e-9 * scale * Eigen::Matrix3d::Identity()).ldlt().solve(g);
    bool improved = false;
    for (int ls = 0; ls < 30 && !improved; ++ls, w *= 0.5) {
      const Eigen::Matrix3d dR = exp_rotation(w);
      std::vector<Vec3> trial(N.size());
      for (size_t f = 0; f < N.size(); ++f) trial[f] = dR * cur[f];
      const double ht = rotation_objective(trial, eps, nullptr, nullptr);
      if (ht < h - 1e-14 * std::abs(h)) {
        h = ht;
        cur.swap(trial);
        R = dR * R;
        improved = true;
      }
    }
    if (!improved || w.norm() < 1e-10) break;
  }
  return closest_rotation(R);
}

namespace {

// watch_thickness (surface mode, closed surfaces): after each schedule step, measure how much of the
// area thin parts pressed under thickness_keep of their thickness carry (res.thin_crushed), and
// stop once that passes thickness_retry_above.
DeformResult deform(const MatX3d& V, const MatX4i& T, const MatX3i& B, const DeformOptions& opt, const Hooks& hooks,
                    bool watch_thickness = false) {
  Stopwatch clock;
  DeformResult res;
  // Normalize: centred, unit bounding-box diagonal.
  const Eigen::RowVector3d centre = V.colwise().mean();
  const double scale = (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
  POLYCUBE_ASSERT(scale > 0, "empty or flat mesh");
  MatX3d X = (V.rowwise() - centre) / scale;
  POLYCUBE_ASSERT(!any_inverted(X, T), "the tet mesh given to the deformation has inverted tets");
  const bool resumed = opt.start.rows() > 0;
  POLYCUBE_ASSERT(!resumed || opt.start.rows() == V.rows(), "the start positions do not match the mesh");

  Problem p{T, B, face_pairs(B), ArapRest::build(X, T), 1.0, opt, opt.volume_barrier_weight, {}, false, {}, {}, 0, 0, {}, {}, {}};
  if (opt.volume_boost_factor > 1 && p.volume_weight > 0 && T.rows() > 0) p.boost.assign(T.rows(), 1.0);
  double l1 = 0;
  l1_measure(X, B, l1, p.area0);
  if (T.rows() == 0) {
    p.surface = true;
    p.volume_weight = 0;
    p.srest = SurfaceArapRest::build(X, B);
    p.area_weight = opt.volume_barrier_weight;
    p.border = border_edges(B);
    if (!p.border.empty()) {
      double len = 0;
      for (const auto& e : p.border) len += (X.row(e[1]) - X.row(e[0])).norm();
      // h: the border edges of a surface of area A and border length L weigh like a band of
      // width h = weight * A / L along it, so that the term's share does not depend on the resolution.
      p.border_h = opt.border_weight * p.area0 / std::max(1e-300, len);
    }
    if (p.border.empty() && opt.thickness_weight > 0) {
      if (opt.thickness_contact)
        p.contact = std::make_shared<const ContactRest>(
            ContactRest::build(X, B, opt.thickness_keep, opt.thickness_max));
      else
        p.thickness = thickness_pairs(X, B, opt.thickness_max);
    }
  } else if (opt.gap_weight > 0) {
    p.thickness = thickness_pairs(X, B, opt.thickness_max, true);  // the gaps between parts
  }
  const std::vector<ThicknessPair> watch =
      watch_thickness && p.border.empty() ? thickness_pairs(X, B, opt.thickness_max, !p.surface)
                                          : std::vector<ThicknessPair>{};
  // The schedule's measure: sum|N|_1 / sum|N|_2 - 1 over the normals and, on open surfaces, the
  // larger of that and the same over the border edges.
  // (s, a: sum|N|_1 and the area of Y, from l1_measure.)
  auto quality = [&](const MatX3d& Y, double s, double a) {
    return std::max(s / a - 1.0, border_l1_quality(Y, p.border));
  };
  for (const EdgeConstraint& e : opt.edges)
    POLYCUBE_ASSERT(e.pair >= 0 && e.pair < static_cast<int>(p.pairs.size()), "edge constraint out of range");

  // Sparsity: tets, boundary triangles (faces of tets in volume mode: listed for the cache of
  // value positions) and the 4 vertices of each adjacent boundary pair.
  std::vector<std::vector<int>> elements;
  elements.reserve(T.rows() + B.rows() + p.pairs.size() + p.thickness.size());
  for (int t = 0; t < T.rows(); ++t) elements.push_back({T(t, 0), T(t, 1), T(t, 2), T(t, 3)});
  for (int f = 0; f < B.rows(); ++f) elements.push_back({B(f, 0), B(f, 1), B(f, 2)});
  for (const FacePair& fp : p.pairs) elements.push_back({fp.a, fp.b, fp.c, fp.d});
  for (const ThicknessPair& tp : p.thickness) elements.push_back({tp.v, B(tp.f, 0), B(tp.f, 1), B(tp.f, 2)});
  SparseSystem sys(static_cast<int>(X.rows()), elements);
  // The symbolic analysis reads only the pattern: on the second thread while the elements'
  // positions are cached and the constant ARAP Hessian G^T G is assembled (fandisk, 35.6k tets:
  // 0.18-0.23 s beside 0.18 s).
  sys.set_float_factorization(opt.float_factorization);
  run_pair([&](int k) {
    if (k == 1) {
      sys.analyze();
      return;
    }
    sys.cache_elements(elements);
    sys.set_zero();
    p.distortion(X, nullptr, &sys);
  });
  const std::vector<double> arap_values = sys.values();
  std::vector<double> side_values(arap_values.size(), 0.0);  // the volume terms' Hessian (see evaluate)
  SparseSystem::Buffer side(sys, side_values);
  const double arap_diag = sys.mean_diagonal();
  // Every term is invariant under translations: the damping mu (1e-8 of the ARAP diagonal, below)
  // alone holds those three directions, far under float's resolution. The float factorizations
  // get 1e-5 of it on the diagonal instead (see DeformOptions::float_factorization).
  sys.set_float_factorization(opt.float_factorization, 1e-5 * arap_diag);
  std::vector<double> assembled;  // the merit energy's Hessian approximation, before the damping

  double t_rot = 0, t_asm = 0, t_fac = 0, t_ls = 0, t_numfac = 0;
  int n_ls = 0, factorizations = 0, cg_iterations = 0, cg_failures = 0, cg_failed_iterations = 0;
  bool factor_valid = false, stalled = false;
  int last_cg = 0, prev_cg = 0;
  double alpha = opt.alpha0 * (p.surface ? opt.surface_alpha_scale : 1.0), eps = opt.eps0;
  for (int k = 0; k < opt.first_alpha_step; ++k) {
    alpha *= opt.alpha_factor;
    eps = std::max(opt.eps_min, eps / opt.eps_factor);
  }
  if (resumed) {
    X = (opt.start.rowwise() - centre) / scale;
    POLYCUBE_ASSERT(!any_inverted(X, T), "the start positions of the deformation have inverted tets");
  }
  // Boundary triangles with an angle under slim_angle_deg in Y.
  const double slim_cos = std::cos(opt.slim_angle_deg * M_PI / 180.0);
  auto count_slim = [&](const MatX3d& Y) {
    int n = 0;
    for (int f = 0; f < B.rows(); ++f) n += smallest_angle_cos(Y, B(f, 0), B(f, 1), B(f, 2)) > slim_cos;
    return n;
  };
  Eigen::Matrix3d R_total = Eigen::Matrix3d::Identity();
  const double sqp_tolerance = opt.sqp_tolerance_for(p.surface);
  int total_iterations = 0;
  // The area constraint's multiplier at the last SQP step: its curvature belongs in the SQP
  // Hessian (the Lagrangian's), see DeformOptions::lagrangian_hessian.
  double lambda_prev = 0;
  double q = quality(X, l1, p.area0);
  if (resumed) {
    double s0 = 0, a0 = 0;
    l1_measure(X, B, s0, a0);
    q = quality(X, s0, a0);
  }
  for (int step = opt.first_alpha_step; step < opt.max_alpha_steps && q >= opt.target_quality && !stalled; ++step) {
    res.alpha_steps = step + 1;
    const double d0 = q;
    std::vector<double> changes;
    double d_prev = q;
    double mu = 1e-8 * arap_diag;
    // alpha and eps changed: the last factorization stays as CG's preconditioner until CG needs too
    // many iterations (a fresh one at every schedule step: fandisk 37.8k tets 19 factorizations
    // and 1397 CG iterations, 22.8 s; reused: 10 and 2053, 20.6 s, the same l1_quality and ARAP).
    for (int it = 0; it < opt.max_inner_iterations; ++it) {
      Stopwatch sw_rot;
      if (opt.global_rotation && (it == 0 || (opt.rotation_interval > 0 && it % opt.rotation_interval == 0))) {
        const Eigen::Matrix3d R = best_rotation(X, B, eps);
        const Eigen::RowVector3d c = X.colwise().mean();
        X = ((X.rowwise() - c) * R.transpose()).rowwise() + c;
        R_total = closest_rotation(R * R_total);
      }
      t_rot += sw_rot.seconds();
      Stopwatch sw_asm;
      // Gradient and Hessian approximation of the merit energy; constraint and its gradient.
      Eigen::VectorXd g = Eigen::VectorXd::Zero(X.size());
      // The system's values start from the constant ARAP Hessian, the volume terms' from zero: set
      // on the two threads of evaluate, like the sum below (memory-bound copies of the whole
      // system; rocker, 2.7M nonzeros: about a fifth of the assembly when done on one thread).
      const auto prepare = [&](int k) {
        if (k == 0)
          sys.values() = arap_values;
        else
          std::fill(side_values.begin(), side_values.end(), 0.0);
      };
      const Energies e0 =
          evaluate(p, X, alpha, eps, &g, &sys, false, &side, opt.lagrangian_hessian ? lambda_prev : 0.0, prepare);
      {
        // The volume terms added, and the sum kept (the damping below changes the diagonal).
        std::vector<double>& v = sys.values();
        assembled.resize(v.size());
        const size_t m = v.size(), mid = m / 2;
        run_pair([&](int k) {
          for (size_t i = k ? mid : 0, end = k ? m : mid; i < end; ++i) assembled[i] = v[i] += side_values[i];
        });
      }
      Eigen::VectorXd gc = Eigen::VectorXd::Zero(X.size());
      const double C = area_constraint(X, B, p.area0, &gc);
      t_asm += sw_asm.seconds();
      Stopwatch sw_fac;
      // The Hessian changes slowly within a schedule step: reuse the last factorization as a
      // preconditioner for conjugate gradients, and factorize anew only when that gets slow.
      Eigen::VectorXd Hg, Hc;  // H^-1 g and H^-1 grad C
      bool solved = false;
      // On large meshes a factorization costs many CG iterations (O(n^2) against O(n^4/3) in
      // 3D): allow CG up to a tenth of a factorization's cost per solve, at least cg_max_iterations
      // (fandisk, 49k tets: 44 s with 0.1, 52 s with 0.25).
      // The ratio comes from CHOLMOD's flop counts, not from timings, so that runs are reproducible.
      const int limit =
          factor_valid ? std::clamp(static_cast<int>(0.1 * sys.factor_to_cg_cost()), opt.cg_max_iterations, 100) : 0;
      // A solve count that has grown past a fraction of the limit: the next one would likely fail.
      // Only where the limit is above its floor (large meshes): there a failed solve costs more than
      // the factorization made early; at the floor it makes no difference in time but changes the
      // path (spot at 20k tets then ended unrealized).
      if (factor_valid && opt.cg_refactor_fraction > 0 && limit > opt.cg_max_iterations &&
          last_cg > opt.cg_refactor_fraction * limit && last_cg > prev_cg)
        factor_valid = false;
      if (factor_valid) {
        sys.add_diagonal(mu);  // (the values are still the assembled ones)
        const double tolerance =
            opt.cg_tolerance_late > 0 && step >= opt.cg_late_from_step ? opt.cg_tolerance_late : opt.cg_tolerance;
        const auto [i1, i2] = sys.solve_pcg_pair(g, Hg, gc, Hc, tolerance, limit);
        solved = i1 > 0 && i2 > 0;
        prev_cg = last_cg;
        last_cg = solved ? std::max(i1, i2) : 0;
        if (solved) {
          cg_iterations += i1 + i2;
        } else {
          ++cg_failures;
          cg_failed_iterations += (i1 > 0 ? i1 : limit) + (i2 > 0 ? i2 : limit);
        }
      }
      if (!solved) {
        bool ok = false;
        for (int tries = 0; tries < 8 && !ok; ++tries) {
          sys.values() = assembled;
          sys.add_diagonal(mu);
          Stopwatch sw_f;
          ok = sys.factorize();
          t_numfac += sw_f.seconds();
          if (!ok) mu *= 100;
        }
        if (!ok) {
          // Numerically singular (typically slim boundary triangles at a huge alpha): keep the
          // current state, which is valid, and stop.
          hooks.warn("the SQP system became numerically singular; stopping the deformation early");
          stalled = true;
          break;
        }
        ++factorizations;
        factor_valid = true;
        last_cg = prev_cg = 0;
        sys.solve_pair(g, Hg, gc, Hc);
      }
      const double lambda = (-gc.dot(Hg) + C) / gc.dot(Hc);
      lambda_prev = lambda;
      const Eigen::VectorXd dx = -Hg - lambda * Hc;
      const Eigen::Map<const MatX3d> D(dx.data(), X.rows(), 3);
      t_fac += sw_fac.seconds();
      Stopwatch sw_ls;
      // Backtracking: no inverted tet, finite barrier, decrease of the energy on the constraint.
      // The contact barrier's continuous collision check: no step through a triangle.
      double t = p.contact ? contact_step_bound(X, D, *p.contact) : 1.0, accepted = 0;
      res.contact_step_cuts += t < 1.0;
      int inverted_trials = 0, infinite_trials = 0;
      MatX3d Xt;
      Energies et;
      std::vector<int> blocking;  // tets the full step inverts
      // The energy still above e0 at a step under 2^-12: the SQP has converged for this alpha as
      // far as its inexact directions allow (bumpy torus, 95k tets: six schedule steps ended in a
      // step of about 1e-9 after some 30 trials of 60 ms each, then stopped as converged anyway).
      bool exhausted = false;
      for (int ls = 0; ls < 40; ++ls, t *= 0.5) {
        Xt = X + t * D;
        restore_area(Xt, B, p.area0);
        if (any_inverted(Xt, T, ls == 0 && !p.boost.empty() ? &blocking : nullptr)) {
          ++inverted_trials;
          continue;
        }
        et = evaluate(p, Xt, alpha, eps, nullptr, nullptr, false);
        ++n_ls;
        if (!std::isfinite(et.total)) ++infinite_trials;
        if (et.total < e0.total) {
          accepted = t;
          break;
        }
        if (t < 1.0 / 4096) {
          exhausted = true;
          break;
        }
      }
      if (!exhausted) ++total_iterations;  // an exhausted search made no step: not an iteration
      t_ls += sw_ls.seconds();
      // Steps cut short by tets about to invert: the volume barrier is too weak for this shape.
      if (inverted_trials >= 3 && p.volume_weight > 0 && p.volume_weight < opt.volume_barrier_max) {
        p.volume_weight = std::min(opt.volume_barrier_max, 4 * p.volume_weight);
        factor_valid = false;
      }
      // The tets the full step would invert get a stronger barrier, so that the next directions
      // keep them open: the volume-weighted barrier barely holds slivers, and one flattened sliver
      // cuts the whole step short (fandisk, 38k tets: steps of 1e-3 from alpha 12.8 on,
      // l1_quality stuck at 1.3e-2). Raised as soon as they halve the step (waiting for 1/8, as
      // for the global weight above, left fandisk stalled); the reused factorization stays, CG
      // absorbs the change (a new factorization after each raise: same result, 26 -> 30 s).
      for (int tt : blocking) p.boost[tt] = std::min(opt.volume_boost_max, p.boost[tt] * opt.volume_boost_factor);
      // The paper's trigger for the slim-triangle collapse: a large step cut short by the barrier.
      if (opt.stop_at_slim_stall && !p.surface && (exhausted || accepted < 1.0 / 16) &&
          inverted_trials + infinite_trials > 0) {
        const int slim = count_slim(accepted > 0 ? Xt : X);
        if (slim > 0) {
          if (accepted > 0) X = Xt;
          res.slim_stall = true;
          res.slim_triangles = slim;
          res.stall_step = step;
          stalled = true;
          std::ostringstream os;
          os << "line search cut short by the barrier (step " << accepted << ") with " << slim
             << " slim boundary triangles: stopping for their collapse";
          hooks.debug(os.str());
          break;
        }
      }
      if (exhausted) break;  // next schedule step
      if (accepted == 0) {
        // No progress along the SQP direction: stronger damping, or stop this schedule step.
        mu *= 10;
        factor_valid = false;
        if (mu > 1e3 * arap_diag) break;
        continue;
      }
      if (mu > 1e-8 * arap_diag) factor_valid = false;  // keep mu fixed while a factorization is reused
      mu = std::max(1e-8 * arap_diag, mu * 0.3);
      const double move = (Xt - X).rowwise().norm().maxCoeff();
      X = Xt;
      double s1, a1;
      l1_measure(X, B, s1, a1);
      q = quality(X, s1, a1);
      IterationRecord r;
      r.alpha_step = step;
      r.iteration = total_iterations;
      r.alpha = alpha;
      r.eps = eps;
      r.e1 = s1 / p.area0;
      r.e_arap = et.arap;
      r.error_d = (s1 - p.area0) * scale * scale;
      r.l1_quality = q;
      r.step = accepted;
      r.seconds = clock.seconds();
      res.history.push_back(r);
      hooks.report("deform", std::min(1.0, std::log(std::max(q, 1e-12) / std::max(d0, 1e-12)) /
                                               std::log(opt.target_quality / std::max(d0, 1e-12))));
      // Paper's test: the error stopped decreasing (last five changes sum < d0 / 100), or SQP converged.
      changes.push_back(std::abs(q - d_prev));
      d_prev = q;
      if (changes.size() >= 5) {
        double sum = 0;
        for (size_t k = changes.size() - 5; k < changes.size(); ++k) sum += changes[k];
        if (sum < d0 / 100) break;
      }
      // ... or the SQP converged for this alpha: a full step that barely lowers the merit energy.
      if (it >= 1 && accepted == 1.0 && e0.total - et.total < sqp_tolerance * std::abs(e0.total)) break;
      if (move < 1e-9 || q < opt.target_quality) break;
    }
    {
      std::ostringstream os;
      os << "schedule step " << step + 1 << ": alpha " << alpha << ", eps " << eps << ", l1_quality " << q
         << ", iterations " << total_iterations;
      hooks.debug(os.str());
    }
    // Without the thickness barrier (first pass): stop as soon as thin parts are pressed flat
    // (surface mode) or gaps closed (volume mode); the caller deforms again with the barrier.
    if (!watch.empty()) {
      res.thin_crushed = crushed_fraction(X, B, watch, opt.thickness_keep);
      if (res.thin_crushed > opt.thickness_retry_above) break;
    }
    alpha *= opt.alpha_factor;
    lambda_prev *= opt.alpha_factor;  // the multiplier grows with alpha (E1 dominates the gradient)
    eps = std::max(opt.eps_min, eps / opt.eps_factor);
  }
  {
    std::ostringstream os;
    os << "deformation time: rotation " << t_rot << " s, assembly " << t_asm << " s, factorization+solve " << t_fac
       << " s (numeric factorizations " << t_numfac << " s), line search " << t_ls << " s (" << n_ls << " energy evaluations); " << factorizations
       << " factorizations (" << sys.float_factorizations() << " in float, " << sys.float_breakdowns()
       << " float breakdowns, " << sys.refinement_iterations() << " CG iterations refining their solves), " << cg_iterations << " preconditioned CG iterations (and " << cg_failed_iterations
       << " in " << cg_failures << " solves over the limit); system " << sys.values().size() << " nonzeros, factor "
       << sys.factor_nonzeros() << " nonzeros, " << sys.factor_flops() << " flops";
    hooks.debug(os.str());
  }
  // Back to input units, centred where the input was.
  const Eigen::RowVector3d c = X.colwise().mean();
  res.X = ((X.rowwise() - c) * scale).rowwise() + centre;
  res.rotation = R_total;
  double s1, a1;
  l1_measure(X, B, s1, a1);
  res.l1_quality = s1 / a1 - 1.0;
  res.error_d = (s1 - p.area0) * scale * scale;
  res.arap = p.distortion(X, nullptr, nullptr);
  res.border_quality = border_l1_quality(X, p.border);
  res.iterations = total_iterations;
  res.inverted = measure_tets(res.X, T).inverted;
  res.converged = q < opt.target_quality;
  res.seconds = clock.seconds();
  res.thickness_pairs = p.contact ? p.contact->vertices : static_cast<int>(p.thickness.size());
  if (p.contact) contact_energy(X, *p.contact, 1.0, nullptr, nullptr, &res.contact_active);
  if (!p.thickness.empty()) res.thin_crushed_after = crushed_fraction(X, B, p.thickness, opt.thickness_keep);
  if (p.surface && p.border.empty()) {
    const MatX3d rest = (V.rowwise() - centre) / scale;
    const std::vector<ThicknessPair> built = !p.contact && p.thickness.empty() && watch.empty()
                                                 ? thickness_pairs(rest, B, opt.thickness_max)
                                                 : std::vector<ThicknessPair>{};
    res.thin_flattened =
        p.contact ? contact_flattened(X, *p.contact)
                  : flattened_parts(rest, X, B, !p.thickness.empty() ? p.thickness : !watch.empty() ? watch : built,
                                    opt.thickness_keep);
  }
  res.factorizations = factorizations;
  res.float_factorizations = sys.float_factorizations();
  res.volume_barrier_weight = p.volume_weight;
  res.boosted_tets = static_cast<int>(std::count_if(p.boost.begin(), p.boost.end(), [](double b) { return b > 1; }));
  if (!p.surface)
    for (int t = 0; t < p.T.rows(); ++t) res.crushed_tets += volume_ratio(X, p.T, p.rest, t) < DeformResult::kCrushedRatio;
  return res;
}

// 21 bits of x spread to every third bit.
inline uint64_t spread_bits(uint64_t x) {
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffULL;
  x = (x | x << 16) & 0x1f0000ff0000ffULL;
  x = (x | x << 8) & 0x100f00f00f00f00fULL;
  x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

// DeformOptions::locality_order: new id per vertex (the identity on the boundary; the interior
// vertices' ids handed out again in Morton order of their positions).
std::vector<int> locality_permutation(const MatX3d& V, const MatX3i& B) {
  const int n = static_cast<int>(V.rows());
  std::vector<char> on_boundary(n, 0);
  for (int f = 0; f < B.rows(); ++f)
    for (int k = 0; k < 3; ++k) on_boundary[B(f, k)] = 1;
  const Vec3 lo = V.colwise().minCoeff().transpose();
  const double extent = std::max(1e-300, (V.colwise().maxCoeff().transpose() - lo).maxCoeff());
  std::vector<int> interior;
  std::vector<uint64_t> code(n, 0);
  for (int v = 0; v < n; ++v) {
    if (on_boundary[v]) continue;
    interior.push_back(v);
    for (int a = 0; a < 3; ++a) {
      const double t = std::clamp((V(v, a) - lo[a]) / extent, 0.0, 1.0);
      code[v] |= spread_bits(static_cast<uint64_t>(t * 2097151.0)) << a;
    }
  }
  std::vector<int> sorted = interior;
  std::stable_sort(sorted.begin(), sorted.end(), [&](int a, int b) { return code[a] < code[b]; });
  std::vector<int> perm(n);
  for (int v = 0; v < n; ++v) perm[v] = v;
  for (size_t k = 0; k < interior.size(); ++k) perm[sorted[k]] = interior[k];
  return perm;
}

}  // namespace

namespace {

// The shape is deformed without its mode's barrier first (surface mode: across thin parts; volume
// mode: across the gaps between parts). On most shapes nothing is pressed, and the barrier's
// elements would only change the factorizations' rounding and so the SQP path. It is deformed
// again from rest with the barrier when the first pass, which stops at the end of the schedule step
// where that shows (spot in surface mode: after step 8 of 14), pressed them (homer's legs pressed
// into each other in volume mode).
DeformResult deform_with_barrier_if_pressed(const MatX3d& V, const MatX4i& T, const MatX3i& B,
                                            const DeformOptions& opt, const Hooks& hooks) {
  const bool surface = T.rows() == 0;
  DeformOptions plain = opt;
  double& weight = surface ? plain.thickness_weight : plain.gap_weight;
  const bool watch = weight > 0 && (!surface || border_edges(B).empty());
  weight = 0;
  DeformResult r = deform(V, T, B, plain, hooks, watch);
  if (!watch || r.thin_crushed <= opt.thickness_retry_above) return r;
  {
    std::ostringstream os;
    os << (surface ? "thin parts were pressed flat (" : "gaps between parts were closed (") << 100 * r.thin_crushed
       << "% of the area under " << opt.thickness_keep
       << (surface ? " of its thickness); deforming again with the thickness barrier"
                   : " of its distance across the gap); deforming again with the gap barrier");
    hooks.info(os.str());
  }
  const double first_seconds = r.seconds, crushed = r.thin_crushed;
  r = deform(V, T, B, opt, hooks);
  r.thin_crushed = crushed;
  r.seconds += first_seconds;
  return r;
}

// Volume mode: deform_with_barrier_if_pressed, then the stall rescue (DeformOptions::rescue_cg_tolerance).
DeformResult deform_volume(const MatX3d& V, const MatX4i& T, const MatX3i& B, const DeformOptions& opt,
                           const Hooks& hooks) {
  DeformResult r = deform_with_barrier_if_pressed(V, T, B, opt, hooks);
  if (r.slim_stall) return r;  // the caller collapses slim triangles and resumes
  // Only a schedule that went at least two steps past the rescue's start (not one cut short by
  // max_alpha_steps for a quick look) is run again.
  if (r.converged || !(opt.rescue_cg_tolerance > 0) || !(opt.rescue_cg_tolerance < opt.cg_tolerance) ||
      r.alpha_steps < opt.rescue_from_step + 2)
    return r;
  {
    std::ostringstream os;
    os << "the deformation stopped at l1_quality " << r.l1_quality << ", above the target " << opt.target_quality
       << ": deforming again with the SQP systems solved to " << opt.rescue_cg_tolerance << " from schedule step "
       << opt.rescue_from_step + 1 << " on";
    hooks.info(os.str());
  }
  DeformOptions tight = opt;
  tight.cg_tolerance_late = opt.rescue_cg_tolerance;
  tight.cg_late_from_step = opt.rescue_from_step;
  DeformResult r2 = deform_with_barrier_if_pressed(V, T, B, tight, hooks);
  const double first_quality = r.l1_quality, seconds = r.seconds + r2.seconds;
  const bool better = r2.inverted == 0 && r2.l1_quality < r.l1_quality;
  {
    std::ostringstream os;
    os << "deformed again: l1_quality " << r2.l1_quality << " (" << r.l1_quality << " before), "
       << (better ? "kept" : "not kept");
    hooks.debug(os.str());
  }
  if (better) {
    r = std::move(r2);
    r.rescued = true;
  }
  r.rescue_from_quality = first_quality;
  r.seconds = seconds;
  return r;
}

}  // namespace

DeformResult deform_to_polycube(const MatX3d& V, const MatX4i& T, const MatX3i& B, const DeformOptions& opt,
                                const Hooks& hooks) {
  POLYCUBE_ASSERT(T.rows() > 0, "deform_to_polycube needs tets (deform_surface_to_polycube for a surface)");
  if (!opt.locality_order) return deform_volume(V, T, B, opt, hooks);
  const std::vector<int> perm = locality_permutation(V, B);
  MatX3d V2(V.rows(), 3);
  for (int v = 0; v < V.rows(); ++v) V2.row(perm[v]) = V.row(v);
  DeformOptions opt2 = opt;
  if (opt.start.rows() > 0)
    for (int v = 0; v < V.rows(); ++v) opt2.start.row(perm[v]) = opt.start.row(v);
  // Tets in order of their smallest new vertex id (stable: ties keep the input order).
  std::vector<int> smallest(T.rows()), order(T.rows());
  for (int t = 0; t < T.rows(); ++t) {
    smallest[t] = std::min({perm[T(t, 0)], perm[T(t, 1)], perm[T(t, 2)], perm[T(t, 3)]});
    order[t] = t;
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return smallest[a] < smallest[b]; });
  MatX4i T2(T.rows(), 4);
  for (int t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) T2(t, k) = perm[T(order[t], k)];
  DeformResult r = deform_volume(V2, T2, B, opt2, hooks);  // boundary ids are unchanged
  MatX3d X(V.rows(), 3);
  for (int v = 0; v < V.rows(); ++v) X.row(v) = r.X.row(perm[v]);
  r.X = std::move(X);
  return r;
}

DeformResult deform_surface_to_polycube(const MatX3d& V, const MatX3i& F, const DeformOptions& opt,
                                        const Hooks& hooks) {
  return deform_with_barrier_if_pressed(V, MatX4i(0, 4), F, opt, hooks);
}

}  // namespace polycube::deform
