#include "polycube/hex/quality.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <thread>

#include "polycube/core/parallel.h"
#include "polycube/geometry/closest_point.h"
#include "polycube/validate/surface.h"

namespace polycube::hex {

namespace {

// det[a, b, c] / (|a| |b| |c|); 0 when a vector has zero length.
double normalized_det(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double l = std::sqrt(a.squaredNorm() * b.squaredNorm() * c.squaredNorm());
  if (!(l > 0)) return 0;
  return a.dot(b.cross(c)) / l;
}

}  // namespace

namespace {
// Centre: the three principal axes (Verdict's calc_hex_efg 1, 2, 3), as signs of the corners.
constexpr double kXi[8] = {-1, 1, 1, -1, -1, 1, 1, -1}, kEt[8] = {-1, -1, 1, 1, -1, -1, 1, 1},
                 kZe[8] = {-1, -1, -1, -1, 1, 1, 1, 1};

// The three vectors whose normalized determinant is sample k (0..7: corner k's edges, 8: the
// centre's principal axes).
void sample_vectors(const std::array<Vec3, 8>& p, int k, Vec3& a, Vec3& b, Vec3& c) {
  if (k < 8) {
    const auto& q = kHexCorners[k];
    a = p[q[1]] - p[q[0]];
    b = p[q[2]] - p[q[0]];
    c = p[q[3]] - p[q[0]];
    return;
  }
  a = (p[1] - p[0]) + (p[2] - p[3]) + (p[5] - p[4]) + (p[6] - p[7]);
  b = (p[3] - p[0]) + (p[2] - p[1]) + (p[7] - p[4]) + (p[6] - p[5]);
  c = (p[4] - p[0]) + (p[5] - p[1]) + (p[6] - p[2]) + (p[7] - p[3]);
}
}  // namespace

double scaled_jacobian_sample(const std::array<Vec3, 8>& p, int k) {
  Vec3 a, b, c;
  sample_vectors(p, k, a, b, c);
  return normalized_det(a, b, c);
}

double scaled_jacobian_sample_gradient(const std::array<Vec3, 8>& p, int k, int j, Vec3& grad) {
  Vec3 a, b, c;
  sample_vectors(p, k, a, b, c);
  // d(a, b, c) / d p[j], each a multiple of the identity.
  double ca, cb, cc;
  if (k < 8) {
    const auto& q = kHexCorners[k];
    const double o = j == q[0] ? 1.0 : 0.0;
    ca = (j == q[1] ? 1.0 : 0.0) - o;
    cb = (j == q[2] ? 1.0 : 0.0) - o;
    cc = (j == q[3] ? 1.0 : 0.0) - o;
  } else {
    ca = kXi[j];
    cb = kEt[j];
    cc = kZe[j];
  }
  const double f = normalized_det(a, b, c);
  grad.setZero();
  const double a2 = a.squaredNorm(), b2 = b.squaredNorm(), c2 = c.squaredNorm();
  const double l = std::sqrt(a2 * b2 * c2);
  if (!(l > 0)) return f;
  // f = a.(b x c) / (|a| |b| |c|): df/da = (b x c) / l - f a / |a|^2, and cyclically.
  if (ca != 0) grad += ca * (b.cross(c) / l - f * a / a2);
  if (cb != 0) grad += cb * (c.cross(a) / l - f * b / b2);
  if (cc != 0) grad += cc * (a.cross(b) / l - f * c / c2);
  return f;
}

unsigned scaled_jacobian_dependents(int j) {
  unsigned m = 1u << 8;  // the centre
  for (int k = 0; k < 8; ++k)
    for (int i = 0; i < 4; ++i)
      if (kHexCorners[k][i] == j) m |= 1u << k;
  return m;
}

std::array<double, 9> scaled_jacobian_samples(const std::array<Vec3, 8>& p) {
  std::array<double, 9> s;
  for (int k = 0; k < 9; ++k) s[k] = scaled_jacobian_sample(p, k);
  return s;
}

double scaled_jacobian(const std::array<Vec3, 8>& p) {
  const std::array<double, 9> s = scaled_jacobian_samples(p);
  return *std::min_element(s.begin(), s.end());
}

double scaled_jacobian(const MatX3d& V, const MatX8i& H, int h) {
  std::array<Vec3, 8> p;
  for (int i = 0; i < 8; ++i) p[i] = V.row(H(h, i)).transpose();
  return scaled_jacobian(p);
}

QualityStats quality_stats(std::vector<double> values) {
  QualityStats q;
  q.count = static_cast<int>(values.size());
  if (!values.empty()) {
    q.sj_min = 1e300;
    q.sj_max = -1e300;
    double sum = 0;
    for (double s : values) {
      q.sj_min = std::min(q.sj_min, s);
      q.sj_max = std::max(q.sj_max, s);
      sum += s;
      if (s <= 0) ++q.inverted;
      if (s < 0.2) ++q.below_0_2;
      if (s < 0.5) ++q.below_0_5;
      ++q.histogram[std::clamp(static_cast<int>(std::floor((s + 1) * 10)), 0, 19)];
    }
    q.sj_mean = sum / values.size();
  }
  q.per_element = std::move(values);
  return q;
}

double edge_ratio(const double* lengths, int count) {
  double lo = 1e300, hi = 0;
  for (int i = 0; i < count; ++i) lo = std::min(lo, lengths[i]), hi = std::max(hi, lengths[i]);
  return lo > 0 ? std::min(hi / lo, 1e30) : 1e30;
}

void add_edge_ratios(QualityStats& q, const std::vector<double>& ratios) {
  q.edge_ratio_max = 0;
  q.edge_ratio_mean = 0;
  q.edge_ratio_above_10 = q.edge_ratio_above_100 = 0;
  int finite = 0;
  for (double r : ratios) {
    q.edge_ratio_max = std::max(q.edge_ratio_max, r);
    q.edge_ratio_above_10 += r > 10;
    q.edge_ratio_above_100 += r > kSliverEdgeRatio;
    if (r < 1e30) q.edge_ratio_mean += r, ++finite;
  }
  if (finite > 0) q.edge_ratio_mean /= finite;
}

HexQuality hex_quality(const MatX3d& V, const MatX8i& H) {
  std::vector<double> s(H.rows()), ratios(H.rows());
  for (int h = 0; h < H.rows(); ++h) {
    s[h] = scaled_jacobian(V, H, h);
    double len[12];
    for (int e = 0; e < 12; ++e) len[e] = (V.row(H(h, kHexEdges[e][0])) - V.row(H(h, kHexEdges[e][1]))).norm();
    ratios[h] = edge_ratio(len, 12);
  }
  QualityStats q = quality_stats(std::move(s));
  add_edge_ratios(q, ratios);
  return q;
}

MatX4i boundary_quads(const MatX8i& H, int* nonmanifold) {
  std::map<std::array<int, 4>, std::pair<int, int>> seen;  // sorted face -> (hex * 6 + local face, count)
  for (int h = 0; h < H.rows(); ++h)
    for (int f = 0; f < 6; ++f) {
      std::array<int, 4> k;
      for (int i = 0; i < 4; ++i) k[i] = H(h, kHexFaces[f][i]);
      std::sort(k.begin(), k.end());
      auto [it, inserted] = seen.try_emplace(k, h * 6 + f, 0);
      ++it->second.second;
    }
  std::vector<int> faces;
  if (nonmanifold) *nonmanifold = 0;
  for (const auto& [k, v] : seen) {
    if (v.second == 1) faces.push_back(v.first);
    if (v.second > 2 && nonmanifold) ++*nonmanifold;
  }
  std::sort(faces.begin(), faces.end());
  MatX4i Q(faces.size(), 4);
  for (size_t i = 0; i < faces.size(); ++i)
    for (int j = 0; j < 4; ++j) Q(i, j) = H(faces[i] / 6, kHexFaces[faces[i] % 6][j]);
  return Q;
}

MatX3i triangulate_quads(const MatX4i& Q) {
  MatX3i F(2 * Q.rows(), 3);
  for (int q = 0; q < Q.rows(); ++q) {
    F.row(2 * q) << Q(q, 0), Q(q, 1), Q(q, 2);
    F.row(2 * q + 1) << Q(q, 0), Q(q, 2), Q(q, 3);
  }
  return F;
}

namespace {

// Sample points of a surface: its vertices, then per triangle a number of points proportional to
// its area (at least the centroid), spread by the R2 low-discrepancy sequence (deterministic). Per
// point its weight in the area integrals: a triangle's points share its area, the vertices none.
struct Samples {
  std::vector<Vec3> pts;
  std::vector<double> weight;
};
Samples surface_samples(const MatX3d& V, const MatX3i& F, int samples) {
  Samples s;
  s.pts.reserve(V.rows() + F.rows() + samples);
  std::vector<char> used(V.rows(), 0);  // only the vertices of the surface (a volume mesh has others)
  for (int f = 0; f < F.rows(); ++f)
    for (int j = 0; j < 3; ++j) used[F(f, j)] = 1;
  for (int v = 0; v < V.rows(); ++v)
    if (used[v]) s.pts.push_back(V.row(v).transpose());
  s.weight.assign(s.pts.size(), 0.0);
  double total = 0;
  std::vector<double> area(F.rows());
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    area[f] = 0.5 * (b - a).cross(c - a).norm();
    total += area[f];
  }
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    const int n = total > 0 ? static_cast<int>(std::lround(samples * area[f] / total)) : 0;
    const double w = area[f] / (n + 1);
    s.pts.push_back((a + b + c) / 3);
    s.weight.push_back(w);
    for (int i = 1; i <= n; ++i) {
      double r1 = std::fmod(0.5 + i * 0.7548776662466927, 1.0), r2 = std::fmod(0.5 + i * 0.5698402909980532, 1.0);
      if (r1 + r2 > 1) {
        r1 = 1 - r1;
        r2 = 1 - r2;
      }
      s.pts.push_back(a + r1 * (b - a) + r2 * (c - a));
      s.weight.push_back(w);
    }
  }
  return s;
}

// Max, area-weighted mean and RMS distance from the samples to the surface, and the point of the
// max, on two threads.
struct OneSided {
  double max = 0, mean = 0, rms = 0;
  Vec3 at = Vec3::Zero();
};
OneSided one_sided(const Samples& s, const geometry::TriangleTree& tree) {
  const std::vector<Vec3>& pts = s.pts;
  const int nt = 2;
  std::vector<double> mx(nt, 0), sum(nt, 0), sum2(nt, 0), wsum(nt, 0);
  std::vector<size_t> arg(nt, 0);
  std::vector<std::thread> th;
  for (int t = 0; t < nt; ++t)
    th.emplace_back([&, t] {
      for (size_t i = t; i < pts.size(); i += nt) {
        const double d = std::sqrt(tree.closest(pts[i]).dist2);
        if (d > mx[t]) mx[t] = d, arg[t] = i;
        sum[t] += s.weight[i] * d;
        sum2[t] += s.weight[i] * d * d;
        wsum[t] += s.weight[i];
      }
    });
  for (auto& t : th) t.join();
  OneSided r;
  if (pts.empty()) return r;
  const int w = mx[1] > mx[0] ? 1 : 0;
  r.max = mx[w];
  r.at = pts[arg[w]];
  const double W = wsum[0] + wsum[1];
  if (W > 0) {
    r.mean = (sum[0] + sum[1]) / W;
    r.rms = std::sqrt((sum2[0] + sum2[1]) / W);
  }
  return r;
}

}  // namespace

Hausdorff hausdorff(const MatX3d& VA, const MatX3i& FA, const MatX3d& VB, const MatX3i& FB, int samples) {
  Hausdorff h;
  const geometry::TriangleTree ta(VA, FA), tb(VB, FB);
  const OneSided ab = one_sided(surface_samples(VA, FA, samples), tb);
  const OneSided ba = one_sided(surface_samples(VB, FB, samples), ta);
  h.a_to_b = ab.max;
  h.b_to_a = ba.max;
  h.mean_a_to_b = ab.mean;
  h.mean_b_to_a = ba.mean;
  h.rms_a_to_b = ab.rms;
  h.rms_b_to_a = ba.rms;
  h.a_to_b_at = ab.at;
  h.b_to_a_at = ba.at;
  h.max = std::max(ab.max, ba.max);
  return h;
}

double volume_outside(const MatX3d& V, const MatX8i& H, const MatX3d& SV, const MatX3i& SF) {
  std::vector<int> faces(SF.rows());
  for (int f = 0; f < SF.rows(); ++f) faces[f] = f;
  const int nh = static_cast<int>(H.rows());
  std::array<double, 2> total{0, 0}, outside{0, 0};
  run_pair([&](int part) {
    for (int h = part; h < nh; h += 2) {
      Vec3 c = Vec3::Zero();
      for (int i = 0; i < 8; ++i) c += V.row(H(h, i)).transpose();
      c /= 8;
      // The mean of the corners' parallelepiped volumes (exact for a parallelepiped).
      double vol = 0;
      for (const auto& k : kHexCorners) {
        const Vec3 o = V.row(H(h, k[0])).transpose();
        vol += (V.row(H(h, k[1])).transpose() - o)
                   .dot((V.row(H(h, k[2])).transpose() - o).cross(V.row(H(h, k[3])).transpose() - o));
      }
      vol = std::abs(vol) / 8;
      total[part] += vol;
      if (winding_number(SV, SF, faces, c) < 0.5) outside[part] += vol;
    }
  });
  const double all = total[0] + total[1];
  return all > 0 ? (outside[0] + outside[1]) / all : 0.0;
}

}  // namespace polycube::hex
