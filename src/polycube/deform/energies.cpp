#include "polycube/deform/energies.h"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "polycube/core/error.h"
#include "polycube/core/parallel.h"
#include "polycube/geometry/closest_point.h"

namespace polycube::deform {

void DenseHessian::add(const int* v, int nv, const Eigen::Ref<const Eigen::MatrixXd>& h) {
  for (int p = 0; p < nv; ++p)
    for (int q = 0; q < nv; ++q) H.block<3, 3>(3 * v[p], 3 * v[q]) += h.block<3, 3>(3 * p, 3 * q);
}

std::vector<FacePair> face_pairs(const MatX3i& F) {
  std::map<std::pair<int, int>, std::pair<int, int>> half;  // directed edge -> (face, opposite vertex)
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) half[{F(f, k), F(f, (k + 1) % 3)}] = {f, F(f, (k + 2) % 3)};
  std::vector<FacePair> out;
  for (auto& [e, fc] : half) {
    auto it = half.find({e.second, e.first});
    if (it == half.end() || fc.first > it->second.first) continue;
    out.push_back({fc.first, it->second.first, e.first, e.second, fc.second, it->second.second});
  }
  return out;
}

namespace {

inline Eigen::Matrix3d skew(const Vec3& w) {
  Eigen::Matrix3d S;
  S << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return S;
}

// dN/dx for N = (xb - xa) x (xc - xa) / 2: a 3 x 9 matrix over (xa, xb, xc).
inline Eigen::Matrix<double, 3, 9> normal_jacobian(const Vec3& xa, const Vec3& xb, const Vec3& xc) {
  const Vec3 u = xb - xa, v = xc - xa;
  Eigen::Matrix<double, 3, 9> J;
  J.block<3, 3>(0, 3) = -0.5 * skew(v);  // d(u x v)/du = -[v]x
  J.block<3, 3>(0, 6) = 0.5 * skew(u);   // d(u x v)/dv = [u]x
  J.block<3, 3>(0, 0) = -(J.block<3, 3>(0, 3) + J.block<3, 3>(0, 6));
  return J;
}

// sum_k w_k d^2 N_k / dx^2 (constant in x): off-diagonal blocks -/+ [w]x / 2.
inline Eigen::Matrix<double, 9, 9> normal_second(const Vec3& w) {
  Eigen::Matrix<double, 9, 9> H = Eigen::Matrix<double, 9, 9>::Zero();
  const Eigen::Matrix3d S = 0.5 * skew(w);
  const int pairs[3][2] = {{0, 1}, {1, 2}, {2, 0}};  // (a,b), (b,c), (c,a)
  for (auto& p : pairs) {
    H.block<3, 3>(3 * p[0], 3 * p[1]) -= S;
    H.block<3, 3>(3 * p[1], 3 * p[0]) += S;
  }
  return H;
}

// The PSD part (H2 + |H2|) / 2 of H2 = normal_second(w): H2 is C (x) [w/2]x with C the cyclic 3x3
// antisymmetric matrix, eigenvalues +-(sqrt3/2)|w| (twice each) and 0, and |H2| = (sqrt3/2)|w|
// P1 (x) Pw with P1, Pw the projectors orthogonal to (1,1,1) and to w.
inline Eigen::Matrix<double, 9, 9> clamped_normal_second(const Vec3& w) {
  const Eigen::Matrix<double, 9, 9> H2 = normal_second(w);
  const double len = w.norm();
  if (!(len > 0)) return H2;
  const Eigen::Matrix3d P1 = Eigen::Matrix3d::Identity() - Eigen::Matrix3d::Constant(1.0 / 3);
  const Eigen::Matrix3d Pw = Eigen::Matrix3d::Identity() - w * w.transpose() / (len * len);
  Eigen::Matrix<double, 9, 9> A;
  for (int p = 0; p < 3; ++p)
    for (int q = 0; q < 3; ++q) A.block<3, 3>(3 * p, 3 * q) = P1(p, q) * Pw;
  return 0.5 * (H2 + (std::sqrt(3.0) / 2) * len * A);
}

inline Vec3 row(const MatX3d& X, int i) { return X.row(i).transpose(); }

// Rotation part of the polar decomposition of F (closest rotation, never a reflection). Closed-form
// eigen-decomposition of F^T F in the common well-conditioned case, SVD otherwise.
inline Eigen::Matrix3d closest_rotation(const Eigen::Matrix3d& F) {
  if (F.determinant() > 0) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(F.transpose() * F);
    const Vec3 l = es.eigenvalues();  // ascending
    if (l[0] > 1e-8 * l[2]) {
      const Eigen::Matrix3d& V = es.eigenvectors();
      const Vec3 inv_s(1 / std::sqrt(l[0]), 1 / std::sqrt(l[1]), 1 / std::sqrt(l[2]));
      const Eigen::Matrix3d R = F * V * inv_s.asDiagonal() * V.transpose();
      if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-8) return R;
    }
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1;
  return U * svd.matrixV().transpose();
}

// Unit normal of a face and its derivative dn/dx (3 x 9; left unset without `derivative`).
struct UnitNormal {
  Vec3 n;
  double area;
  Eigen::Matrix<double, 3, 9> dn;
};
inline UnitNormal unit_normal(const MatX3d& X, int a, int b, int c, bool derivative = true) {
  UnitNormal u;
  const Vec3 xa = row(X, a), xb = row(X, b), xc = row(X, c);
  const Vec3 N = 0.5 * (xb - xa).cross(xc - xa);
  u.area = N.norm();
  u.n = u.area > 0 ? Vec3(N / u.area) : Vec3::Zero();
  if (!derivative) return u;
  const Eigen::Matrix<double, 3, 9> J = normal_jacobian(xa, xb, xc);
  u.dn = u.area > 0 ? Eigen::Matrix<double, 3, 9>((Eigen::Matrix3d::Identity() - u.n * u.n.transpose()) / u.area * J)
                    : Eigen::Matrix<double, 3, 9>::Zero();
  return u;
}

// Scatters the 9-vector derivative of face (a,b,c) and the 9-vector of face (b,a,d) (sharing edge
// a-b) into the 12-vector over (a, b, c, d).
inline Eigen::Matrix<double, 3, 12> pair_jac_f(const Eigen::Matrix<double, 3, 9>& df) {
  Eigen::Matrix<double, 3, 12> J = Eigen::Matrix<double, 3, 12>::Zero();
  J.leftCols<9>() = df;
  return J;
}
inline Eigen::Matrix<double, 3, 12> pair_jac_g(const Eigen::Matrix<double, 3, 9>& dg) {
  // g's local order is (b, a, d).
  Eigen::Matrix<double, 3, 12> J = Eigen::Matrix<double, 3, 12>::Zero();
  J.block<3, 3>(0, 3) = dg.block<3, 3>(0, 0);
  J.block<3, 3>(0, 0) = dg.block<3, 3>(0, 3);
  J.block<3, 3>(0, 9) = dg.block<3, 3>(0, 6);
  return J;
}

template <int N>
inline void scatter_grad(Eigen::VectorXd& g, const int* v, const Eigen::Matrix<double, N, 1>& gl) {
  for (int p = 0; p < N / 3; ++p) g.segment<3>(3 * v[p]) += gl.template segment<3>(3 * p);
}

}  // namespace

Vec3 area_normal(const MatX3d& X, int a, int b, int c) {
  return 0.5 * (row(X, b) - row(X, a)).cross(row(X, c) - row(X, a));
}

double smallest_angle_cos(const MatX3d& X, int a, int b, int c) {
  const int v[3] = {a, b, c};
  double worst = -1;
  for (int k = 0; k < 3; ++k) {
    const Vec3 p = row(X, v[k]), u = row(X, v[(k + 1) % 3]) - p, w = row(X, v[(k + 2) % 3]) - p;
    const double lu = u.norm(), lw = w.norm();
    worst = std::max(worst, lu > 0 && lw > 0 ? u.dot(w) / (lu * lw) : 1.0);
  }
  return worst;
}

double l1_energy(const MatX3d& X, const MatX3i& F, double eps, double weight, Eigen::VectorXd* grad,
                 HessianSink* hess, bool project, double area_multiplier) {
  double E = 0;
  for (int f = 0; f < F.rows(); ++f) {
    const int v[3] = {F(f, 0), F(f, 1), F(f, 2)};
    const Vec3 xa = row(X, v[0]), xb = row(X, v[1]), xc = row(X, v[2]);
    const Vec3 N = 0.5 * (xb - xa).cross(xc - xa);
    const double N2 = N.squaredNorm();
    Vec3 dg = Vec3::Zero();                                   // dE/dN
    Eigen::Matrix3d Hg = Eigen::Matrix3d::Zero();             // d2E/dN2
    for (int k = 0; k < 3; ++k) {
      const double s = std::sqrt(N[k] * N[k] + eps * N2);
      E += s;
      if (s <= 0) continue;
      Vec3 q = eps * N;
      q[k] += N[k];  // (e_k e_k^T + eps I) N
      dg += q / s;
      if (hess) {
        Eigen::Matrix3d M = eps * Eigen::Matrix3d::Identity();
        M(k, k) += 1;
        Hg += M / s - q * q.transpose() / (s * s * s);
      }
    }
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 3, 9> J = normal_jacobian(xa, xb, xc);
    if (grad) scatter_grad<9>(*grad, v, Eigen::Matrix<double, 9, 1>(weight * J.transpose() * dg));
    if (hess) {
      // Eq. 5: the first term J^T Hg J is PSD (g is convex in N); the second, sum_k dg_k d2N_k =
      // normal_second(dg), is indefinite and clamped to its PSD part (clamped_normal_second).
      // H = scale (J^T M J + second term of d): without the multiplier M = Hg, d = dg, scale = weight.
      Eigen::Matrix3d M = Hg;
      Vec3 d = dg;
      double scale = weight;
      const double a = std::sqrt(N2);
      if (area_multiplier != 0 && project && a > 0) {
        // With the area constraint's curvature (the Lagrangian's Hessian): the N-space Hessian
        // weight Hg + lambda (I - n n^T) / |N| projected to PSD (its eigenvalues clamped), and the
        // second term of the combined gradient d = weight dg + lambda n, clamped like dg's.
        const Vec3 n = N / a;
        d = weight * dg + area_multiplier * n;
        M = weight * Hg + (area_multiplier / a) * (Eigen::Matrix3d::Identity() - n * n.transpose());
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(M);
        const Vec3 ev = es.eigenvalues().cwiseMax(0.0);
        M = es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
        scale = 1.0;
      }
      Eigen::Matrix<double, 9, 9> H = J.transpose() * M * J;
      H += project ? clamped_normal_second(d) : normal_second(d);
      hess->add(v, 3, Eigen::Matrix<double, 9, 9>(scale * H));
    }
  }
  return weight * E;
}

void l1_measure(const MatX3d& X, const MatX3i& F, double& l1, double& area) {
  l1 = area = 0;
  for (int f = 0; f < F.rows(); ++f) {
    Vec3 N = area_normal(X, F(f, 0), F(f, 1), F(f, 2));
    l1 += N.cwiseAbs().sum();
    area += N.norm();
  }
}

ArapRest ArapRest::build(const MatX3d& X, const MatX4i& T) {
  ArapRest r;
  r.Dm_inv.resize(T.rows());
  r.w.resize(T.rows());
  double total = 0;
  for (int t = 0; t < T.rows(); ++t) {
    Eigen::Matrix3d Dm;
    for (int m = 0; m < 3; ++m) Dm.col(m) = row(X, T(t, m + 1)) - row(X, T(t, 0));
    r.Dm_inv[t] = Dm.inverse();
    r.w[t] = Dm.determinant() / 6.0;
    total += r.w[t];
  }
  for (double& w : r.w) w /= total;
  return r;
}

namespace {
// The terms of tets [begin, end): sum_t w_t delta_t (unweighted); weight x their gradient into g,
// weight x their Hessian into hess, delta_t into per_tet (each if given), tet after tet.
double arap_range(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight, int begin, int end,
                  Eigen::VectorXd* g, HessianSink* hess, std::vector<double>* per_tet) {
  double E = 0;
  for (int t = begin; t < end; ++t) {
    const int v[4] = {T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
    Eigen::Matrix3d Ds;
    for (int m = 0; m < 3; ++m) Ds.col(m) = row(X, v[m + 1]) - row(X, v[0]);
    const Eigen::Matrix3d& Di = rest.Dm_inv[t];
    const Eigen::Matrix3d Fm = Ds * Di;
    const Eigen::Matrix3d R = closest_rotation(Fm);
    const double delta = 0.5 * (Fm - R).squaredNorm();
    if (per_tet) (*per_tet)[t] = delta;
    E += rest.w[t] * delta;
    const Eigen::Matrix<double, 4, 3> B = shape_gradients(Di);
    if (g) {
      const Eigen::Matrix3d P = (Fm - R);  // dDelta/dF
      for (int p = 0; p < 4; ++p) g->segment<3>(3 * v[p]) += weight * rest.w[t] * P * B.row(p).transpose();
    }
    if (hess) {
      const Eigen::Matrix4d K = B * B.transpose();
      Eigen::Matrix<double, 12, 12> H = Eigen::Matrix<double, 12, 12>::Zero();
      for (int p = 0; p < 4; ++p)
        for (int q = 0; q < 4; ++q) H.block<3, 3>(3 * p, 3 * q) = K(p, q) * Eigen::Matrix3d::Identity();
      hess->add(v, 4, Eigen::Matrix<double, 12, 12>(weight * rest.w[t] * H));
    }
  }
  return E;
}

// Half 0 or 1 of the split that arap_energy_half documents.
double arap_half(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight, int half,
                 Eigen::VectorXd* g, std::vector<double>* per_tet) {
  const int n = static_cast<int>(T.rows());
  return half == 0 ? arap_range(X, T, rest, weight, 0, n / 2, g, nullptr, per_tet)
                   : arap_range(X, T, rest, weight, n / 2, n, g, nullptr, per_tet);
}
}  // namespace

double arap_energy_half(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight, int half,
                        Eigen::VectorXd* grad) {
  return arap_half(X, T, rest, weight, half, grad, nullptr);
}

double arap_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight, Eigen::VectorXd* grad,
                   HessianSink* hess, std::vector<double>* per_tet) {
  if (per_tet) per_tet->resize(T.rows());
  const int n = static_cast<int>(T.rows());
  if (hess || n < kArapSplitTets) return weight * arap_range(X, T, rest, weight, 0, n, grad, hess, per_tet);
  // Energy and gradient only (the realization's energies, the final measures): split over two
  // threads (the persistent worker of core/parallel.h: a thread started per call cost 0.2-0.3 ms),
  // as arap_energy_half documents.
  Eigen::VectorXd g2;
  if (grad) g2 = Eigen::VectorXd::Zero(grad->size());
  double E1 = 0, E2 = 0;
  run_pair([&](int k) {
    if (k == 0)
      E1 = arap_half(X, T, rest, weight, 0, grad, per_tet);
    else
      E2 = arap_half(X, T, rest, weight, 1, grad ? &g2 : nullptr, per_tet);
  });
  if (grad) *grad += g2;
  return weight * (E1 + E2);
}

SurfaceArapRest SurfaceArapRest::build(const MatX3d& X, const MatX3i& F) {
  SurfaceArapRest r;
  r.grad.resize(F.rows());
  r.normal.resize(F.rows());
  r.w.resize(F.rows());
  double total = 0;
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 e1 = row(X, F(f, 1)) - row(X, F(f, 0)), e2 = row(X, F(f, 2)) - row(X, F(f, 0));
    const Vec3 n = e1.cross(e2);
    const double a2 = n.norm();
    Eigen::Matrix<double, 3, 2> Dm;
    Dm << e1, e2;
    Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
    if (a2 > 0) {
      const Eigen::Matrix<double, 2, 3> pinv = (Dm.transpose() * Dm).inverse() * Dm.transpose();
      G.row(1) = pinv.row(0);
      G.row(2) = pinv.row(1);
      G.row(0) = -(G.row(1) + G.row(2));
    }
    r.grad[f] = G;
    r.normal[f] = a2 > 0 ? Vec3(n / a2) : Vec3::Zero();
    r.w[f] = 0.5 * a2;
    total += r.w[f];
  }
  r.area = r.w;
  for (double& w : r.w) w /= total > 0 ? total : 1.0;
  return r;
}

double surface_arap_energy(const MatX3d& X, const MatX3i& F, const SurfaceArapRest& rest, double weight,
                           Eigen::VectorXd* grad, HessianSink* hess, std::vector<double>* per_face) {
  if (per_face) per_face->assign(F.rows(), 0.0);
  // Jacobians F_t = sum_p x_p g_p^T (3 x 3, zero on the rest normal), then per vertex the rotation
  // closest to the area-weighted sum of its triangles' Jacobians.
  const int nf = static_cast<int>(F.rows());
  std::vector<Eigen::Matrix3d> J(nf);
  int nv = 0;
  for (int f = 0; f < nf; ++f) nv = std::max(nv, F.row(f).maxCoeff() + 1);
  std::vector<Eigen::Matrix3d> S(nv, Eigen::Matrix3d::Zero());
  for (int f = 0; f < nf; ++f) {
    J[f].setZero();
    for (int p = 0; p < 3; ++p) J[f] += row(X, F(f, p)) * rest.grad[f].row(p);
    for (int p = 0; p < 3; ++p) S[F(f, p)] += rest.w[f] * J[f];
  }
  std::vector<Eigen::Matrix3d> R(nv);
  for (int v = 0; v < nv; ++v) R[v] = closest_rotation(S[v]);
  double E = 0;
  for (int f = 0; f < nf; ++f) {
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - rest.normal[f] * rest.normal[f].transpose();
    double delta = 0;
    Eigen::Matrix3d Rbar = Eigen::Matrix3d::Zero();
    for (int p = 0; p < 3; ++p) {
      delta += (0.5 / 3.0) * (J[f] - R[F(f, p)] * P).squaredNorm();
      Rbar += R[F(f, p)] / 3.0;
    }
    if (per_face) (*per_face)[f] = delta;
    E += rest.w[f] * delta;
    const Eigen::Matrix3d& G = rest.grad[f];
    if (grad) {
      // Each R_i minimizes its own terms, so the gradient holds them fixed (envelope theorem).
      const Eigen::Matrix3d D = J[f] - Rbar * P;
      for (int p = 0; p < 3; ++p) grad->segment<3>(3 * F(f, p)) += weight * rest.w[f] * D * G.row(p).transpose();
    }
    if (hess) {
      const Eigen::Matrix3d K = G * G.transpose();
      Eigen::Matrix<double, 9, 9> H = Eigen::Matrix<double, 9, 9>::Zero();
      for (int p = 0; p < 3; ++p)
        for (int q = 0; q < 3; ++q) H.block<3, 3>(3 * p, 3 * q) = K(p, q) * Eigen::Matrix3d::Identity();
      const int v[3] = {F(f, 0), F(f, 1), F(f, 2)};
      hess->add(v, 3, Eigen::Matrix<double, 9, 9>(weight * rest.w[f] * H));
    }
  }
  return weight * E;
}

double smoothed_l1(const Vec3& v, double eps, Vec3* grad, Eigen::Matrix3d* hess) {
  const double v2 = v.squaredNorm();
  double h = 0;
  if (grad) grad->setZero();
  if (hess) hess->setZero();
  for (int k = 0; k < 3; ++k) {
    const double s = std::sqrt(v[k] * v[k] + eps * v2);
    h += s;
    if (s <= 0 || (!grad && !hess)) continue;
    Vec3 q = eps * v;
    q[k] += v[k];
    if (grad) *grad += q / s;
    if (hess) {
      Eigen::Matrix3d M = eps * Eigen::Matrix3d::Identity();
      M(k, k) += 1;
      *hess += M / s - q * q.transpose() / (s * s * s);
    }
  }
  return h;
}

double border_l1_energy(const MatX3d& X, const std::vector<std::array<int, 2>>& edges, double h, double eps,
                        double weight, Eigen::VectorXd* grad, HessianSink* hess) {
  double E = 0;
  const double ceps = std::sqrt(1 + eps) + 2 * std::sqrt(eps);
  for (const auto& ab : edges) {
    const Vec3 e = row(X, ab[1]) - row(X, ab[0]);
    Vec3 dg;
    Eigen::Matrix3d Hg;
    E += smoothed_l1(e, eps, &dg, &Hg);
    // Minus c_eps |e|, the value for an axis-aligned edge: zero when aligned, and shrinking the
    // border no longer pays. Its Hessian (negative) is left out of the approximation.
    const double len = e.norm();
    E -= ceps * len;
    if (len > 0) dg -= ceps * e / len;
    const double c = weight * h;
    if (grad) {
      grad->segment<3>(3 * ab[0]) -= c * dg;
      grad->segment<3>(3 * ab[1]) += c * dg;
    }
    if (hess) {
      Eigen::Matrix<double, 6, 6> H;
      H << Hg, -Hg, -Hg, Hg;
      const int v[2] = {ab[0], ab[1]};
      hess->add(v, 2, Eigen::Matrix<double, 6, 6>(c * H));
    }
  }
  return weight * h * E;
}

std::vector<std::array<int, 2>> border_edges(const MatX3i& F) {
  std::map<std::pair<int, int>, int> count;
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) ++count[{F(f, k), F(f, (k + 1) % 3)}];
  std::vector<std::array<int, 2>> out;
  for (const auto& [e, n] : count)
    if (!count.count({e.second, e.first})) out.push_back({e.first, e.second});
  return out;
}

// The volume ratio J = det F of one tet (v its vertices, Di its inverse rest edge matrix) and, on
// demand, its gradient over the tet's 12 coordinates: dJ/dF = cof(F) = J F^-T, dF/dx_p = row p of
// B as in arap_energy. Shared by the volume barrier and the crush guard.
namespace {
struct TetVolume {
  const Eigen::Matrix3d& Di;
  Eigen::Matrix3d Fm;
  double J;
  TetVolume(const MatX3d& X, const int (&v)[4], const Eigen::Matrix3d& Dinv) : Di(Dinv) {
    Eigen::Matrix3d Ds;
    for (int m = 0; m < 3; ++m) Ds.col(m) = row(X, v[m + 1]) - row(X, v[0]);
    Fm = Ds * Di;
    J = Fm.determinant();
  }
  Eigen::Matrix<double, 12, 1> gradient() const {
    const Eigen::Matrix3d dJdF = J * Fm.inverse().transpose();
    const Eigen::Matrix<double, 4, 3> B = shape_gradients(Di);
    Eigen::Matrix<double, 12, 1> dJ;
    for (int p = 0; p < 4; ++p) dJ.segment<3>(3 * p) = dJdF * B.row(p).transpose();
    return dJ;
  }
};
}  // namespace

double volume_barrier_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double weight,
                             Eigen::VectorXd* grad, HessianSink* hess, const std::vector<double>* boost, bool neutral) {
  POLYCUBE_ASSERT(!boost || boost->size() == static_cast<size_t>(T.rows()), "one barrier multiplier per tet");
  double E = 0;
  for (int t = 0; t < T.rows(); ++t) {
    const double wt = boost ? rest.w[t] * (*boost)[t] : rest.w[t];
    const int v[4] = {T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
    const TetVolume tv(X, v, rest.Dm_inv[t]);
    const double J = tv.J;
    if (!(J > 0)) return std::numeric_limits<double>::infinity();
    if (neutral)
      E += wt * (J - 1.0 - std::log(J));
    else
      E -= wt * std::log(J);
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 12, 1> dJ = tv.gradient();
    if (grad) {
      // phi'(J) times the weights (the -log J form in its original order of operations).
      const double dphi = neutral ? weight * wt * (1.0 - 1.0 / J) : -weight * wt / J;
      scatter_grad<12>(*grad, v, Eigen::Matrix<double, 12, 1>(dphi * dJ));
    }
    if (hess) hess->add_outer(v, 4, weight * wt / (J * J), dJ.data());
  }
  return weight * E;
}

double crush_guard_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double j0, double weight,
                          Eigen::VectorXd* grad, HessianSink* hess) {
  if (T.rows() == 0 || !(j0 > 0)) return 0;
  const double wt = 1.0 / static_cast<double>(T.rows());
  double E = 0;
  for (int t = 0; t < T.rows(); ++t) {
    const int v[4] = {T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
    const TetVolume tv(X, v, rest.Dm_inv[t]);
    const double J = tv.J;
    if (!(J > 0)) return std::numeric_limits<double>::infinity();
    if (J >= j0) continue;
    const double r = J / j0;
    E += wt * (r - 1.0 - std::log(r));
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 12, 1> dJ = tv.gradient();
    // d psi / dJ = 1/j0 - 1/J; d2 psi / dJ2 = 1/J^2.
    if (grad) scatter_grad<12>(*grad, v, Eigen::Matrix<double, 12, 1>(weight * wt * (1.0 / j0 - 1.0 / J) * dJ));
    if (hess) hess->add_outer(v, 4, weight * wt / (J * J), dJ.data());
  }
  return weight * E;
}

double area_barrier_energy(const MatX3d& X, const MatX3i& F, const SurfaceArapRest& rest, double weight,
                           Eigen::VectorXd* grad, HessianSink* hess) {
  double E = 0;
  for (int f = 0; f < F.rows(); ++f) {
    if (!(rest.area[f] > 0)) continue;
    const int v[3] = {F(f, 0), F(f, 1), F(f, 2)};
    const Vec3 xa = row(X, v[0]), xb = row(X, v[1]), xc = row(X, v[2]);
    const Vec3 N = 0.5 * (xb - xa).cross(xc - xa);
    const double A = N.norm();
    if (!(A > 0)) return std::numeric_limits<double>::infinity();
    E -= rest.w[f] * std::log(A / rest.area[f]);
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 9, 1> dA = normal_jacobian(xa, xb, xc).transpose() * (N / A);
    if (grad) scatter_grad<9>(*grad, v, Eigen::Matrix<double, 9, 1>(-weight * rest.w[f] / A * dA));
    if (hess) hess->add_outer(v, 3, weight * rest.w[f] / (A * A), dA.data());
  }
  return weight * E;
}

std::vector<ThicknessPair> thickness_pairs(const MatX3d& X, const MatX3i& F, double max_thickness, bool exterior) {
  std::vector<ThicknessPair> pairs;
  const int n = static_cast<int>(X.rows());
  std::vector<Vec3> vn(n, Vec3::Zero());
  std::vector<double> va(n, 0.0);
  double total = 0;
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 N = area_normal(X, F(f, 0), F(f, 1), F(f, 2));
    total += N.norm();
    for (int k = 0; k < 3; ++k) {
      vn[F(f, k)] += N;
      va[F(f, k)] += N.norm() / 3;
    }
  }
  if (!(total > 0)) return pairs;
  const geometry::TriangleTree tree(X, F);
  for (int v = 0; v < n; ++v) {
    if (!(vn[v].norm() > 0)) continue;  // no triangle (or none with area) at v
    const Vec3 nv = vn[v].normalized(), x = X.row(v).transpose();
    const Vec3 against = -nv;
    const geometry::ClosestHit h = tree.closest(x, &against);
    if (h.face < 0) continue;
    bool incident = false;
    for (int k = 0; k < 3; ++k) incident = incident || F(h.face, k) == v;
    const Vec3 nf = area_normal(X, F(h.face, 0), F(h.face, 1), F(h.face, 2));
    const Vec3 d = h.point - x;
    const double d0 = d.norm();
    const Vec3 towards = exterior ? nv : Vec3(-nv);
    if (incident || !(nf.dot(nv) < 0) || !(d0 > 0) || d0 >= max_thickness || d.dot(towards) < 0.5 * d0) continue;
    ThicknessPair p;
    p.v = v;
    p.f = h.face;
    p.bary = h.bary;
    p.d0 = d0;
    p.w = va[v] / total;
    p.exterior = exterior;
    pairs.push_back(p);
  }
  return pairs;
}

namespace {
// From the point across the part to v, in X.
Vec3 across(const MatX3d& X, const MatX3i& F, const ThicknessPair& p) {
  return row(X, p.v) - (p.bary[0] * row(X, F(p.f, 0)) + p.bary[1] * row(X, F(p.f, 1)) + p.bary[2] * row(X, F(p.f, 2)));
}
}  // namespace

double crushed_fraction(const MatX3d& X, const MatX3i& F, const std::vector<ThicknessPair>& pairs, double keep) {
  std::vector<Vec3> vn;  // area-weighted vertex normals, for the exterior pairs' side test
  for (const ThicknessPair& p : pairs)
    if (p.exterior) {
      vn.assign(X.rows(), Vec3::Zero());
      for (int f = 0; f < F.rows(); ++f) {
        const Vec3 N = area_normal(X, F(f, 0), F(f, 1), F(f, 2));
        for (int k = 0; k < 3; ++k) vn[F(f, k)] += N;
      }
      break;
    }
  double c = 0;
  for (const ThicknessPair& p : pairs) {
    const Vec3 d = across(X, F, p);
    // (d points from the point across to v: outside v's side while -d . n_v > 0.)
    if (d.norm() < keep * p.d0 || (p.exterior && !(-d.dot(vn[p.v]) > 0))) c += p.w;
  }
  return c;
}

double pair_gap(const MatX3d& X, const MatX3i& F, const ThicknessPair& p) {
  const Vec3 N = area_normal(X, F(p.f, 0), F(p.f, 1), F(p.f, 2));
  const double A = N.norm();
  if (!(A > 0)) return 0;
  // across() points from the point across to v: against f's outward normal across a part, along
  // it across a gap outside.
  return (p.exterior ? 1.0 : -1.0) * across(X, F, p).dot(N) / A;
}

Flattened pressed_places(const MatX3d& R, std::vector<std::pair<double, int>> pressed, double fraction,
                         double spacing, int max_places) {
  Flattened out;
  out.fraction = fraction;
  std::stable_sort(pressed.begin(), pressed.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  if (!pressed.empty()) out.ratio = pressed.front().first;
  for (const auto& [ratio, v] : pressed) {
    if (static_cast<int>(out.places.size()) >= max_places) break;
    bool apart = true;
    for (int u : out.places) apart = apart && (R.row(v) - R.row(u)).norm() > spacing;
    if (apart) out.places.push_back(v);
  }
  return out;
}

Flattened flattened_parts(const MatX3d& R, const MatX3d& X, const MatX3i& F, const std::vector<ThicknessPair>& pairs,
                          double keep, double spacing, int max_places) {
  std::vector<std::pair<double, int>> pressed;  // (ratio, v), for the places
  double fraction = 0;
  for (const ThicknessPair& p : pairs) {
    const double rest = pair_gap(R, F, p);
    if (!(rest >= 0.5 * across(R, F, p).norm()) || !(rest > 0)) continue;
    const double ratio = pair_gap(X, F, p) / rest;
    if (!(ratio < keep)) continue;
    fraction += p.w;
    pressed.emplace_back(ratio, p.v);
  }
  return pressed_places(R, std::move(pressed), fraction, spacing, max_places);
}

double thickness_energy(const MatX3d& X, const MatX3i& F, const std::vector<ThicknessPair>& pairs, double keep,
                        double weight, Eigen::VectorXd* grad, HessianSink* hess) {
  double E = 0;
  for (const ThicknessPair& p : pairs) {
    const int v[4] = {p.v, F(p.f, 0), F(p.f, 1), F(p.f, 2)};
    const Vec3 d = across(X, F, p);
    const double len = d.norm(), scale = keep * p.d0;
    const double r = len / scale;
    if (r >= 1) continue;
    if (!(r > 0)) return std::numeric_limits<double>::infinity();
    E += p.w * (r - 1 - std::log(r));
    if (!grad && !hess) continue;
    // dr/dx_v = u / scale, dr/dx_fi = -bary_i u / scale, u = d / len.
    const Vec3 u = d / (len * scale);
    Eigen::Matrix<double, 12, 1> dr;
    dr.segment<3>(0) = u;
    for (int i = 0; i < 3; ++i) dr.segment<3>(3 + 3 * i) = -p.bary[i] * u;
    if (grad) scatter_grad<12>(*grad, v, Eigen::Matrix<double, 12, 1>(weight * p.w * (1 - 1 / r) * dr));
    if (hess) hess->add_outer(v, 4, weight * p.w / (r * r), dr.data());
  }
  return weight * E;
}

namespace {
// The quantities of one tet's untangling term: J = F / scale, D = det J, sqrt(eps^2 + D^2),
// chi(D), chi^(2/3), |J|^2, the two parts f and g, and the cofactor matrix dD/dJ (any sign of D).
struct UntangleTerms {
  Eigen::Matrix3d J, cof;
  double D, root, chi, chi23, S, f, g;
};
UntangleTerms untangle_terms(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t, double eps,
                             double scale, bool cofactors) {
  UntangleTerms u;
  const int v[4] = {T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
  Eigen::Matrix3d Ds;
  for (int m = 0; m < 3; ++m) Ds.col(m) = row(X, v[m + 1]) - row(X, v[0]);
  u.J = Ds * rest.Dm_inv[t] / scale;
  u.D = u.J.determinant();
  u.root = std::sqrt(eps * eps + u.D * u.D);
  u.chi = 0.5 * (u.D + u.root);
  u.chi23 = std::cbrt(u.chi * u.chi);
  u.S = u.J.squaredNorm();
  u.f = u.S / u.chi23;
  u.g = (u.D * u.D + 1) / u.chi;
  if (cofactors) {
    u.cof.col(0) = u.J.col(1).cross(u.J.col(2));
    u.cof.col(1) = u.J.col(2).cross(u.J.col(0));
    u.cof.col(2) = u.J.col(0).cross(u.J.col(1));
  }
  return u;
}
}  // namespace

double untangle_tet_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t, double eps, double scale,
                           double theta, Eigen::Matrix<double, 12, 1>* grad) {
  const UntangleTerms u = untangle_terms(X, T, rest, t, eps, scale, grad != nullptr);
  const Eigen::Matrix3d& J = u.J;
  const Eigen::Matrix3d& cof = u.cof;
  const double D = u.D, root = u.root, chi = u.chi, chi23 = u.chi23, f = u.f, g = u.g;
  const Eigen::Matrix3d& Di = rest.Dm_inv[t];
  if (grad) {
    const double dchi = chi / root;  // chi'(D)
    const Eigen::Matrix3d dEdF = rest.w[t] / scale *
                                 ((1 - theta) * (2 * J / chi23 - (2.0 / 3.0) * f / chi * dchi * cof) +
                                  theta * ((2 * D - g * dchi) / chi) * cof);
    const Eigen::Matrix<double, 4, 3> B = shape_gradients(Di);
    for (int p = 0; p < 4; ++p) grad->segment<3>(3 * p) = dEdF * B.row(p).transpose();
  }
  return rest.w[t] * ((1 - theta) * f + theta * g);
}

double untangle_tet_corner(const MatX3d& X, const MatX4i& T, const ArapRest& rest, int t, int j, double eps,
                           double scale, double theta, Vec3* grad, Eigen::Matrix3d* hess, double* wall) {
  const bool derivatives = grad || hess;
  const UntangleTerms u = untangle_terms(X, T, rest, t, eps, scale, derivatives);
  const Eigen::Matrix3d& J = u.J;
  const Eigen::Matrix3d& cof = u.cof;
  const double D = u.D, root = u.root, chi = u.chi, chi23 = u.chi23, S = u.S, g = u.g;
  const double E = rest.w[t] * ((1 - theta) * u.f + theta * g);
  if (!derivatives) return E;
  // J = J0 + (x - x0) b^T / scale with b the corner's shape gradient, so along x:
  // dS = s = 2 J b / scale, d2S = 2 |b|^2 / scale^2 I, dD = d = cof b / scale, d2D = 0.
  const Vec3 b = shape_gradients(rest.Dm_inv[t]).row(j).transpose();
  const Vec3 sv = 2 * J * b / scale, d = cof * b / scale;
  if (wall) *wall = d.norm() / root;
  const double c1 = chi / root;                        // chi'(D)
  const double c2 = chi * (root - D) / (root * root * root);  // chi''(D)
  const double chi53 = chi23 * chi;                    // chi^(5/3)
  // f = S chi^(-2/3): f_S = chi^(-2/3), f_D = -(2/3) S chi^(-5/3) chi'.
  const double fD = -(2.0 / 3.0) * S / chi53 * c1;
  // g = (D^2 + 1) / chi.
  const double gD = (2 * D - g * c1) / chi;
  const double a = rest.w[t] * (1 - theta), c = rest.w[t] * theta;
  if (grad) *grad = a * (sv / chi23 + fD * d) + c * gD * d;
  if (hess) {
    const double fSD = -(2.0 / 3.0) / chi53 * c1;
    const double fDD = S * ((10.0 / 9.0) / (chi53 * chi) * c1 * c1 - (2.0 / 3.0) / chi53 * c2);
    const double gDD = 2 / chi - 4 * D * c1 / (chi * chi) - (D * D + 1) * c2 / (chi * chi) +
                       2 * (D * D + 1) * c1 * c1 / (chi * chi * chi);
    const double sigma = 2 * b.squaredNorm() / (scale * scale);
    *hess = a * (sigma / chi23 * Eigen::Matrix3d::Identity() + fSD * (sv * d.transpose() + d * sv.transpose()) +
                 fDD * d * d.transpose()) +
            c * gDD * d * d.transpose();
  }
  return E;
}

double untangle_energy(const MatX3d& X, const MatX4i& T, const ArapRest& rest, double eps, double scale,
                       double theta, Eigen::VectorXd* grad) {
  double E = 0;
  Eigen::Matrix<double, 12, 1> ge;
  for (int t = 0; t < T.rows(); ++t) {
    E += untangle_tet_energy(X, T, rest, t, eps, scale, theta, grad ? &ge : nullptr);
    if (!grad) continue;
    const int v[4] = {T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
    scatter_grad<12>(*grad, v, ge);
  }
  return E;
}

namespace {
// Per pair: the derivative of n_f and n_g over (a, b, c, d) (left unset without `derivatives`:
// the energy alone, in the line search, costs a third as much).
struct PairNormals {
  Vec3 nf, ng;
  double af, ag;
  Eigen::Matrix<double, 3, 12> Jf, Jg;
};
PairNormals pair_normals(const MatX3d& X, const MatX3i& F, const FacePair& p, bool derivatives) {
  PairNormals r;
  const UnitNormal nf = unit_normal(X, F(p.f, 0), F(p.f, 1), F(p.f, 2), derivatives);
  const UnitNormal ng = unit_normal(X, p.b, p.a, p.d, derivatives);
  r.nf = nf.n;
  r.ng = ng.n;
  r.af = nf.area;
  r.ag = ng.area;
  if (!derivatives) return r;
  Eigen::Matrix<double, 3, 9> dnf;
  for (int k = 0; k < 3; ++k) {
    int id = F(p.f, k);
    int slot = id == p.a ? 0 : id == p.b ? 1 : 2;
    dnf.block<3, 3>(0, 3 * slot) = nf.dn.block<3, 3>(0, 3 * k);
  }
  r.Jf = pair_jac_f(dnf);
  r.Jg = pair_jac_g(ng.dn);
  return r;
}
}  // namespace

double barrier_energy(const MatX3d& X, const MatX3i& F, const std::vector<FacePair>& pairs, double weight,
                      Eigen::VectorXd* grad, HessianSink* hess) {
  double E = 0;
  for (const FacePair& p : pairs) {
    const int v[4] = {p.a, p.b, p.c, p.d};
    const PairNormals pn = pair_normals(X, F, p, grad || hess);
    const double D = 1.0 + pn.nf.dot(pn.ng);
    if (!(D > 0)) return std::numeric_limits<double>::infinity();
    E -= std::log(D);
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 1, 12> dD = pn.ng.transpose() * pn.Jf + pn.nf.transpose() * pn.Jg;
    if (grad) scatter_grad<12>(*grad, v, Eigen::Matrix<double, 12, 1>(-weight / D * dD.transpose()));
    if (hess) hess->add_outer(v, 4, weight / (D * D), dD.data());
  }
  return weight * E;
}


double complexity_energy(const MatX3d& X, const MatX3i& F, const std::vector<FacePair>& pairs, double weight,
                         Eigen::VectorXd* grad, HessianSink* hess) {
  // Face areas and the sum of neighbour areas per face (Eq. 9).
  std::vector<double> area(F.rows()), nsum(F.rows(), 0.0);
  double total = 0;
  for (int f = 0; f < F.rows(); ++f) {
    area[f] = area_normal(X, F(f, 0), F(f, 1), F(f, 2)).norm();
    total += area[f];
  }
  for (const FacePair& p : pairs) {
    nsum[p.f] += area[p.g];
    nsum[p.g] += area[p.f];
  }
  double E = 0;
  for (const FacePair& p : pairs) {
    const int v[4] = {p.a, p.b, p.c, p.d};
    const double gfg = nsum[p.f] > 0 ? area[p.g] / nsum[p.f] : 0, ggf = nsum[p.g] > 0 ? area[p.f] / nsum[p.g] : 0;
    const double Ae = (gfg * area[p.f] + ggf * area[p.g]) / total;
    const PairNormals pn = pair_normals(X, F, p, grad || hess);
    const Vec3 r = pn.nf - pn.ng;
    E += Ae * r.squaredNorm();
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 3, 12> Jr = pn.Jf - pn.Jg;
    if (grad) scatter_grad<12>(*grad, v, Eigen::Matrix<double, 12, 1>(2 * weight * Ae * Jr.transpose() * r));
    if (hess) hess->add(v, 4, Eigen::Matrix<double, 12, 12>(2 * weight * Ae * Jr.transpose() * Jr));
  }
  return weight * E;
}

double edge_energy(const MatX3d& X, const MatX3i& F, const std::vector<FacePair>& pairs,
                   const std::vector<EdgeConstraint>& edges, double weight, Eigen::VectorXd* grad, HessianSink* hess) {
  double E = 0;
  for (const EdgeConstraint& e : edges) {
    const FacePair& p = pairs[e.pair];
    const int v[4] = {p.a, p.b, p.c, p.d};
    const PairNormals pn = pair_normals(X, F, p, grad || hess);
    const double r = pn.nf.dot(pn.ng) - (e.sharp ? 0.0 : 1.0);
    E += e.omega * r * r;
    if (!grad && !hess) continue;
    const Eigen::Matrix<double, 1, 12> dr = pn.ng.transpose() * pn.Jf + pn.nf.transpose() * pn.Jg;
    if (grad) scatter_grad<12>(*grad, v, Eigen::Matrix<double, 12, 1>(2 * weight * e.omega * r * dr.transpose()));
    if (hess) hess->add_outer(v, 4, 2 * weight * e.omega, dr.data());
  }
  return weight * E;
}

double area_constraint(const MatX3d& X, const MatX3i& F, double area0, Eigen::VectorXd* grad) {
  double A = 0;
  for (int f = 0; f < F.rows(); ++f) {
    const int v[3] = {F(f, 0), F(f, 1), F(f, 2)};
    const Vec3 xa = row(X, v[0]), xb = row(X, v[1]), xc = row(X, v[2]);
    const Vec3 N = 0.5 * (xb - xa).cross(xc - xa);
    const double a = N.norm();
    A += a;
    if (grad && a > 0)
      scatter_grad<9>(*grad, v, Eigen::Matrix<double, 9, 1>(normal_jacobian(xa, xb, xc).transpose() * (N / a)));
  }
  return A - area0;
}

}  // namespace polycube::deform
