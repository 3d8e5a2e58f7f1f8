#include "polycube/geometry/surface_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace polycube::geometry {

namespace {

// Quad corners of the two triangles of quad q (faces 2q and 2q+1, split along the 0-2 diagonal).
constexpr int kTriCorner[2][3] = {{0, 1, 2}, {0, 2, 3}};

// The points of a quad measured to the surface (the other side of the distance): its centre and
// edge midpoints, as bilinear parameters (u, w); then its corners, which are measured too when they
// may leave the surface (SurfaceFitOptions::max_offset).
constexpr int kQuadPoints = 5, kQuadPointsWithCorners = 9;
constexpr double kQuadUV[kQuadPointsWithCorners][2] = {{0.5, 0.5}, {0.5, 0}, {1, 0.5}, {0.5, 1}, {0, 0.5},
                                                      {0, 0},     {1, 0},   {1, 1},   {0, 1}};

// Point k of quad q and the bilinear weights b of its four corners there.
Vec3 quad_point(const MatX3d& V, const MatX4i& Q, int q, int k, double b[4]) {
  const double u = kQuadUV[k][0], w = kQuadUV[k][1];
  b[0] = (1 - u) * (1 - w), b[1] = u * (1 - w), b[2] = u * w, b[3] = (1 - u) * w;
  Vec3 x = Vec3::Zero();
  for (int i = 0; i < 4; ++i) x += b[i] * V.row(Q(q, i)).transpose();
  return x;
}

MatX3i split_quads(const MatX4i& Q) {
  MatX3i F(2 * Q.rows(), 3);
  for (int q = 0; q < Q.rows(); ++q)
    for (int t = 0; t < 2; ++t)
      for (int k = 0; k < 3; ++k) F(2 * q + t, k) = Q(q, kTriCorner[t][k]);
  return F;
}

struct Near {
  double dist = 0;
  Vec3 residual = Vec3::Zero();  // sample - closest point
  double weight_of = 0;          // bilinear-like weight of the vertex asked about in the closest point
};

}  // namespace

SurfaceFitStats fit_to_surface(MatX3d& V, const MatX4i& Q, const SurfaceMesh& target, const TriangleTree& tree,
                               const std::vector<char>& free_vertex, const std::vector<int>* patch_of_face,
                               const std::function<double(int)>& worst, const SurfaceFitOptions& opt,
                               const std::function<bool(int, const Vec3&, Vec3&)>& slide,
                               const std::function<double(int)>& shape) {
  SurfaceFitStats st;
  const int n = static_cast<int>(V.rows());
  const int nq = static_cast<int>(Q.rows());
  if (nq == 0) return st;
  // Samples of the target: its vertices (those of its triangles) and triangle centroids.
  std::vector<Vec3> samples;
  samples.reserve(target.V.rows() + target.F.rows());
  std::vector<char> used(target.V.rows(), 0);
  for (int f = 0; f < target.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) used[target.F(f, k)] = 1;
  for (int i = 0; i < target.V.rows(); ++i)
    if (used[i]) samples.push_back(target.V.row(i).transpose());
  for (int f = 0; f < target.F.rows(); ++f)
    samples.push_back((target.V.row(target.F(f, 0)) + target.V.row(target.F(f, 1)) + target.V.row(target.F(f, 2)))
                          .transpose() / 3.0);
  for (int f = 0; opt.edge_samples && f < target.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (target.F(f, k) < target.F(f, (k + 1) % 3))
        samples.push_back(0.5 * (target.V.row(target.F(f, k)) + target.V.row(target.F(f, (k + 1) % 3))).transpose());
  int ns = static_cast<int>(samples.size());
  std::vector<int> vertex_sample(target.V.rows(), -1);
  {
    int k = 0;
    for (int i = 0; i < target.V.rows(); ++i)
      if (used[i]) vertex_sample[i] = k++;
  }
  const int centroid0 = static_cast<int>(std::count(used.begin(), used.end(), 1));
  std::vector<char> dense(opt.focus_dense > 1 ? target.F.rows() : 0, 0);

  std::vector<std::vector<int>> vq(n);
  for (int q = 0; q < nq; ++q)
    for (int j = 0; j < 4; ++j) vq[Q(q, j)].push_back(q);
  std::vector<int> patch(n, -1);
  if (patch_of_face)
    for (int v = 0; v < n; ++v)
      if (!vq[v].empty()) patch[v] = (*patch_of_face)[tree.closest(V.row(v).transpose()).face];
  const MatX3i QT = split_quads(Q);
  const bool offset = opt.max_offset > 0;
  const int quad_points = offset ? kQuadPointsWithCorners : kQuadPoints;
  // The default floor of a quality: its smallest value over the quads' vertices, or 0.5 if lower.
  auto default_floor = [&](const std::function<double(int)>& quality) {
    double m = 1e300;
    for (int v = 0; v < n; ++v)
      if (!vq[v].empty()) m = std::min(m, quality(v));
    return std::max(m, 0.5);
  };
  st.floor = opt.quality_floor >= 0 ? opt.quality_floor : default_floor(worst);
  const double shape_floor = shape ? default_floor(shape) : 0;

  // Closest point of sample p among the quads `quads` at the current V, and v's weight in it.
  auto nearest = [&](const Vec3& p, const std::vector<int>& quads, int v) {
    Near best;
    best.dist = 1e300;
    for (int q : quads)
      for (int t = 0; t < 2; ++t) {
        const int a = Q(q, kTriCorner[t][0]), b = Q(q, kTriCorner[t][1]), c = Q(q, kTriCorner[t][2]);
        const Vec3 pa = V.row(a).transpose(), pb = V.row(b).transpose(), pc = V.row(c).transpose();
        const Vec3 w = closest_point_barycentric(p, pa, pb, pc);
        const Vec3 x = w[0] * pa + w[1] * pb + w[2] * pc;
        const double d = (p - x).norm();
        if (d < best.dist) {
          best.dist = d;
          best.residual = p - x;
          best.weight_of = (a == v ? w[0] : 0) + (b == v ? w[1] : 0) + (c == v ? w[2] : 0);
        }
      }
    return best;
  };
  std::vector<double> sample_dist(ns, 0.0);
  auto measure = [&](double& mx, double& mean, std::vector<int>* owner) {
    const TriangleTree qt(V, QT);
    mx = mean = 0;
    if (owner) owner->assign(ns, -1);
    for (int s = 0; s < ns; ++s) {
      const ClosestHit h = qt.closest(samples[s]);
      const double d = std::sqrt(h.dist2);
      sample_dist[s] = d;
      mx = std::max(mx, d);
      mean += d;
      if (owner) (*owner)[s] = h.face / 2;
    }
    mean /= std::max(1, ns);
  };
  // Closest points of the quads' points on the surface, cached per quad point in two slots: the
  // last position measured before a move (slot 0) and the last trial (slot 1). A vertex's visit
  // measures its quads before and at up to three trial positions, and most of those points have
  // not moved since the last visit of a neighbour; a cached hit is used only for the very same
  // point, so the results are those of the query.
  const size_t n_cache = static_cast<size_t>(nq) * quad_points;
  std::array<std::vector<Vec3>, 2> cache_x;
  std::array<std::vector<ClosestHit>, 2> cache_hit;
  for (int slot = 0; slot < 2; ++slot) {
    cache_x[slot].assign(n_cache, Vec3::Constant(std::numeric_limits<double>::quiet_NaN()));
    cache_hit[slot].resize(n_cache);
  }
  auto closest_of_quad_point = [&](int q, int k, const Vec3& x, int slot) -> const ClosestHit& {
    const size_t i = static_cast<size_t>(q) * quad_points + k;
    for (int s = 0; s < 2; ++s)
      if (cache_x[s][i] == x) return cache_hit[s][i];
    cache_x[slot][i] = x;
    cache_hit[slot][i] = tree.closest(x);
    return cache_hit[slot][i];
  };
  // Largest distance to the surface of the points of quad q (the other side).
  auto quad_gap = [&](int q) {
    double m = 0, b[4];
    for (int k = 0; k < quad_points; ++k)
      m = std::max(m, closest_of_quad_point(q, k, quad_point(V, Q, q, k, b), 0).dist2);
    return std::sqrt(m);
  };

  std::vector<int> owner;
  measure(st.max_before, st.mean_before, &owner);
  double sample_max = st.max_before;  // largest sample-to-quads distance at the last measure
  const double p_exp = opt.power;
  // Focused rounds (after the full ones): only the vertices of quads within focus_ratio of the
  // largest distance, on either side, move.
  std::vector<char> active;
  int full_rounds_done = 0, focus_rounds_done = 0, focus_stalled = 0;
  double best_max = st.max_before;
  for (int round = 0;; ++round) {
    const bool focus = full_rounds_done >= opt.rounds;
    if (focus && (focus_rounds_done >= opt.focus_rounds || opt.rounds == 0)) break;
    if (round > 0) {
      double mean;
      measure(sample_max, mean, &owner);
      if (focus && !dense.empty()) {
        // Denser samples on the triangles whose samples are near the largest distance.
        const int before = ns, L = opt.focus_dense;
        for (int f = 0; f < target.F.rows(); ++f) {
          if (dense[f]) continue;
          double d = sample_dist[centroid0 + f];
          for (int k = 0; k < 3; ++k) d = std::max(d, sample_dist[vertex_sample[target.F(f, k)]]);
          if (d < opt.focus_ratio * sample_max) continue;
          dense[f] = 1;
          const Vec3 a = target.V.row(target.F(f, 0)), b = target.V.row(target.F(f, 1)), c = target.V.row(target.F(f, 2));
          for (int i = 0; i <= L; ++i)
            for (int j = 0; i + j <= L; ++j) {
              if (i == L || j == L || i + j == 0) continue;  // the vertices are samples already
              samples.push_back(a + (b - a) * (double(i) / L) + (c - a) * (double(j) / L));
            }
        }
        if (static_cast<int>(samples.size()) > before) {
          ns = static_cast<int>(samples.size());
          sample_dist.resize(ns);
          measure(sample_max, mean, &owner);
          best_max = std::max(best_max, sample_max);
          focus_stalled = 0;
        }
      }
      if (focus) {
        if (sample_max < best_max * (1 - 1e-3)) {
          focus_stalled = 0;
        } else if (++focus_stalled >= 3) {
          break;
        }
        best_max = std::min(best_max, sample_max);
      }
    }
    if (focus) {
      double mx = sample_max;
      std::vector<double> gap(nq);
      for (int q = 0; q < nq; ++q) mx = std::max(mx, gap[q] = opt.two_sided ? quad_gap(q) : 0.0);
      active.assign(n, 0);
      auto mark = [&](int q) {
        for (int j = 0; j < 4; ++j) active[Q(q, j)] = 1;
      };
      for (int s = 0; s < ns; ++s)
        if (sample_dist[s] >= opt.focus_ratio * mx) mark(owner[s]);
      for (int q = 0; q < nq; ++q)
        if (gap[q] >= opt.focus_ratio * mx) mark(q);
      // and their neighbours: a far sample's quad may need its neighbours to move first
      std::vector<char> grown = active;
      for (int q = 0; q < nq; ++q) {
        bool any = false;
        for (int j = 0; j < 4; ++j) any = any || active[Q(q, j)];
        if (any)
          for (int j = 0; j < 4; ++j) grown[Q(q, j)] = 1;
      }
      active.swap(grown);
      // Largest distances all over the surface (a sphere): nothing to focus on; the full rounds
      // have done what they can (unbounded, these rounds took sphere_coarse's mean quad scaled
      // Jacobian from 0.992 to 0.953 for a 1.7e-3 -> 0.94e-3 Hausdorff distance).
      int n_active = 0, n_mesh = 0;
      for (int v = 0; v < n; ++v) {
        if (vq[v].empty()) continue;
        ++n_mesh;
        n_active += active[v];
      }
      if (n_active > opt.focus_max_share * n_mesh) break;
      ++focus_rounds_done;
    } else {
      ++full_rounds_done;
    }
    ++st.rounds;
    // Samples per quad.
    std::vector<int> start(nq + 1, 0), list(ns);
    for (int s = 0; s < ns; ++s) ++start[owner[s] + 1];
    for (int q = 0; q < nq; ++q) start[q + 1] += start[q];
    {
      std::vector<int> fill(start.begin(), start.end() - 1);
      for (int s = 0; s < ns; ++s) list[fill[owner[s]]++] = s;
    }
    int moves = 0;
    std::vector<int> S;
    for (int v = 0; v < n; ++v) {
      if (vq[v].empty() || (focus && !active[v])) continue;
      const bool is_free = v < static_cast<int>(free_vertex.size()) && free_vertex[v];
      Vec3 on_edge;
      if (!is_free && !(slide && slide(v, V.row(v).transpose(), on_edge))) continue;
      S.clear();
      for (int q : vq[v]) S.insert(S.end(), list.begin() + start[q], list.begin() + start[q + 1]);
      if (S.empty()) continue;
      // Energy, largest distance and Gauss-Newton step over S at the current position.
      double e0 = 0, m0 = 0, den = 0;
      Vec3 num = Vec3::Zero();
      for (int s : S) {
        const Near nr = nearest(samples[s], vq[v], v);
        const double w = std::pow(std::max(nr.dist, 1e-300), p_exp - 2);
        e0 += std::pow(nr.dist, p_exp);
        m0 = std::max(m0, nr.dist);
        num += w * nr.weight_of * nr.residual;
        den += w * nr.weight_of * nr.weight_of;
      }
      // The other side: points of v's quads (centre, edge midpoints; corners with max_offset) to the surface.
      auto quad_side = [&](double& e, double& m, Vec3* num_out, double* den_out, int slot) {
        for (int q : vq[v]) {
          int j = 0;
          while (Q(q, j) != v) ++j;
          for (int k = 0; k < quad_points; ++k) {
            double b[4];  // v's weight there: b[j] (v is corner j)
            const Vec3 x = quad_point(V, Q, q, k, b);
            const ClosestHit& h = closest_of_quad_point(q, k, x, slot);
            const double d = std::sqrt(h.dist2);
            e += std::pow(d, p_exp);
            m = std::max(m, d);
            if (num_out && b[j] > 0) {
              const double ww = std::pow(std::max(d, 1e-300), p_exp - 2);
              *num_out += ww * b[j] * (h.point - x);  // the quad point moves towards the surface
              *den_out += ww * b[j] * b[j];
            }
          }
        }
      };
      if (opt.two_sided || offset) quad_side(e0, m0, &num, &den, 0);
      if (!(den > 0) || !(m0 > 0)) continue;
      Vec3 step = num / den;
      Vec3 nrm = Vec3::Zero();
      for (int q : vq[v]) {
        const Vec3 a = V.row(Q(q, 0)), b = V.row(Q(q, 1)), c = V.row(Q(q, 2)), d = V.row(Q(q, 3));
        nrm += (c - a).cross(d - b);
      }
      if (!(nrm.norm() > 0)) continue;
      nrm.normalize();
      if (!(offset && is_free)) step -= step.dot(nrm) * nrm;
      double len = 0;
      int count = 0;
      for (int q : vq[v])
        for (int j = 0; j < 4; ++j)
          if (Q(q, j) == v) {
            len += (V.row(Q(q, (j + 1) % 4)) - V.row(v)).norm() + (V.row(Q(q, (j + 3) % 4)) - V.row(v)).norm();
            count += 2;
          }
      len /= std::max(1, count);
      if (step.norm() > 0.5 * len) step *= 0.5 * len / step.norm();
      if (!(step.norm() > 1e-12 * len)) continue;
      const double q0 = worst(v), s0 = shape ? shape(v) : 0;
      const Vec3 x = V.row(v).transpose();
      for (double t : {1.0, 0.5, 0.25}) {
        Vec3 p;
        if (is_free) {
          const Vec3 y = x + t * step;
          p = tree.closest(y, &nrm, patch_of_face, patch[v]).point;
          if (offset) {
            // Off the surface by at most max_offset of the edge length, along the line to its closest point.
            Vec3 d = y - p;
            const double lim = opt.max_offset * len;
            if (d.norm() > lim) d *= lim / d.norm();
            p += d;
          }
        } else if (!slide(v, x + t * step, p)) {
          continue;
        }
        V.row(v) = p.transpose();
        double e1 = 0, m1 = 0;
        for (int s : S) {
          const double d = nearest(samples[s], vq[v], v).dist;
          e1 += std::pow(d, p_exp);
          m1 = std::max(m1, d);
        }
        if (opt.two_sided || offset) quad_side(e1, m1, nullptr, nullptr, 1);
        if (m1 <= m0 * (1 + 1e-12) && e1 < e0 * (1 - 1e-9) && worst(v) >= std::min(q0, st.floor) &&
            (!shape || shape(v) >= std::min(s0, shape_floor))) {
          ++moves;
          break;
        }
        V.row(v) = x.transpose();
      }
    }
    st.moves += moves;
    if (focus) {
      st.focus_rounds = focus_rounds_done;
      if (moves == 0) break;
    } else if (moves == 0) {
      full_rounds_done = opt.rounds;  // converged: on to the focused rounds
    }
  }
  measure(st.max_after, st.mean_after, nullptr);
  return st;
}

}  // namespace polycube::geometry
