// Finite-difference checks of every gradient and exact Hessian, PSD checks of the Hessian
// approximations, and known values, on small meshes built in code.
#include <algorithm>
#include <Eigen/Eigenvalues>
#include <random>

#include "polycube/core/lbfgs.h"
#include "polycube/deform/contact.h"
#include "polycube/deform/energies.h"
#include "polycube/validate/tetmesh.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::deform;
using namespace polycube::test;

namespace {

// Two tets glued on a face, then jittered: a closed boundary of 6 triangles, 5 vertices.
struct Small {
  MatX3d X0, X;
  MatX4i T;
  MatX3i F;
};
Small small_mesh(unsigned seed = 1) {
  Small s;
  s.X0.resize(5, 3);
  s.X0 << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.4, 0.4, -0.9;
  s.T.resize(2, 4);
  s.T << 0, 1, 2, 3, 0, 2, 1, 4;
  s.F = tet_boundary(s.T);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  s.X = s.X0;
  for (int i = 0; i < s.X.rows(); ++i)
    for (int k = 0; k < 3; ++k) s.X(i, k) += u(rng);
  return s;
}

using EnergyFn = std::function<double(const MatX3d&, Eigen::VectorXd*, HessianSink*)>;

Eigen::VectorXd fd_gradient(const EnergyFn& E, const MatX3d& X, double h = 1e-6) {
  Eigen::VectorXd g(X.size());
  for (int i = 0; i < X.rows(); ++i)
    for (int k = 0; k < 3; ++k) {
      MatX3d Xp = X, Xm = X;
      Xp(i, k) += h;
      Xm(i, k) -= h;
      g(3 * i + k) = (E(Xp, nullptr, nullptr) - E(Xm, nullptr, nullptr)) / (2 * h);
    }
  return g;
}

Eigen::VectorXd analytic_gradient(const EnergyFn& E, const MatX3d& X) {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(X.size());
  E(X, &g, nullptr);
  return g;
}

Eigen::MatrixXd hessian(const EnergyFn& E, const MatX3d& X) {
  DenseHessian H(static_cast<int>(X.rows()));
  E(X, nullptr, &H);
  return H.H;
}

Eigen::MatrixXd fd_hessian(const EnergyFn& E, const MatX3d& X, double h = 1e-5) {
  Eigen::MatrixXd H(X.size(), X.size());
  for (int i = 0; i < X.rows(); ++i)
    for (int k = 0; k < 3; ++k) {
      MatX3d Xp = X, Xm = X;
      Xp(i, k) += h;
      Xm(i, k) -= h;
      H.col(3 * i + k) = (analytic_gradient(E, Xp) - analytic_gradient(E, Xm)) / (2 * h);
    }
  return H;
}

void expect_gradient(const EnergyFn& E, const MatX3d& X) {
  Eigen::VectorXd g = analytic_gradient(E, X), f = fd_gradient(E, X);
  EXPECT_LE((g - f).norm(), 1e-6 * std::max(1.0, f.norm())) << "analytic\n" << g.transpose() << "\nfd\n" << f.transpose();
}

void expect_psd(const Eigen::MatrixXd& H) {
  EXPECT_LE((H - H.transpose()).norm(), 1e-12 * std::max(1.0, H.norm()));
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (H + H.transpose()));
  EXPECT_GE(es.eigenvalues().minCoeff(), -1e-10 * std::max(1.0, es.eigenvalues().maxCoeff()));
}

}  // namespace

TEST(Energies, FacePairsOfClosedSurface) {
  Small s = small_mesh();
  auto pairs = face_pairs(s.F);
  EXPECT_EQ(pairs.size(), 9u);  // 6 triangles, 9 edges
  for (const FacePair& p : pairs) {
    EXPECT_NE(p.c, p.d);
    EXPECT_NE(p.f, p.g);
  }
}

TEST(Energies, L1GradientAndHessian) {
  Small s = small_mesh();
  for (double eps : {0.5, 0.05, 0.01}) {
    EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) { return l1_energy(X, s.F, eps, 1.3, g, H); };
    expect_gradient(E, s.X);
    Eigen::MatrixXd H = hessian(E, s.X);
    expect_psd(H);
    // The exact (unprojected) Hessian matches finite differences of the gradient.
    EnergyFn Ex = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
      return l1_energy(X, s.F, eps, 1.3, g, H, false);
    };
    Eigen::MatrixXd Hfd = fd_hessian(Ex, s.X), Hx = hessian(Ex, s.X);
    EXPECT_LE((Hx - Hfd).norm(), 1e-5 * Hfd.norm());
    // Projection only removes negative curvature: H - Hx is PSD.
    expect_psd(H - Hx);
  }
}

// The l1 Hessian with the area constraint's curvature (weight E1 + lambda x area, projected).
TEST(Energies, L1LagrangianHessian) {
  Small s = small_mesh();
  // Exact Hessian of weight E1 + lambda A by finite differences of its gradient.
  auto lagrangian = [](const MatX3i& F, double eps, double weight, double lambda) -> EnergyFn {
    return [&F, eps, weight, lambda](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
      const double E = l1_energy(X, F, eps, weight, g, H, true, lambda);
      Eigen::VectorXd ga = Eigen::VectorXd::Zero(X.size());
      const double A = area_constraint(X, F, 0.0, g ? &ga : nullptr);
      if (g) *g += lambda * ga;
      return E + lambda * A;
    };
  };
  for (double eps : {0.5, 0.05}) {
    for (double lambda : {-2.0, -0.5, 0.7}) {
      EnergyFn L = lagrangian(s.F, eps, 1.3, lambda);
      expect_gradient(L, s.X);
      expect_psd(hessian(L, s.X));
    }
  }
  // One triangle in the plane z = 0: dE1/dN = (sqrt(1 + eps) + 2 sqrt(eps)) n, so at
  // lambda = -weight (sqrt(1 + eps) + 2 sqrt(eps)) the second-derivative term of N vanishes and
  // the N-space Hessian is PSD: nothing is clamped, and the Hessian is the exact one.
  MatX3d X(3, 3);
  X << 0, 0, 0, 1.1, 0.2, 0, 0.3, 0.9, 0;
  MatX3i F(1, 3);
  F << 0, 1, 2;
  for (double eps : {0.5, 0.25, 0.05}) {
    const double weight = 1.3, lambda = -weight * (std::sqrt(1 + eps) + 2 * std::sqrt(eps));
    EnergyFn L = lagrangian(F, eps, weight, lambda);
    const Eigen::MatrixXd H = hessian(L, X), Hfd = fd_hessian(L, X);
    EXPECT_LE((H - Hfd).norm(), 1e-6 * Hfd.norm()) << H << "\n\n" << Hfd;
    // Without the multiplier the same Hessian is larger (the constraint's curvature is negative).
    EnergyFn E = [&](const MatX3d& Y, Eigen::VectorXd* g, HessianSink* Hs) { return l1_energy(Y, F, eps, weight, g, Hs); };
    expect_psd(hessian(E, X) - H);
    EXPECT_GT((hessian(E, X) - H).norm(), 0.1 * H.norm());
  }
}

TEST(Energies, L1OfAxisAlignedBoxIsItsArea) {
  auto b = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  double l1, area;
  l1_measure(b.V, b.F, l1, area);
  EXPECT_NEAR(l1, area, 1e-12);
  EXPECT_NEAR(area, 2 * (2 + 3 + 6), 1e-12);
  // Smoothed: each face has one component 1 and two 0: sqrt(1+eps) + 2 sqrt(eps).
  const double eps = 0.01;
  EXPECT_NEAR(l1_energy(b.V, b.F, eps, 1.0, nullptr, nullptr), area * (std::sqrt(1 + eps) + 2 * std::sqrt(eps)), 1e-12);
}

TEST(Energies, ArapGradientHessianAndZeroAtRest) {
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) { return arap_energy(X, s.T, rest, 0.7, g, H); };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
  // Rest state and any rigid motion of it: zero energy.
  EXPECT_NEAR(E(s.X0, nullptr, nullptr), 0, 1e-14);
  Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  MatX3d Xr = (s.X0 * R.transpose()).rowwise() + Eigen::RowVector3d(3, -1, 2);
  EXPECT_NEAR(E(Xr, nullptr, nullptr), 0, 1e-14);
  // Uniform scaling by s: delta = 0.5 * 3 (s-1)^2 for every tet.
  EXPECT_NEAR(E(1.5 * s.X0, nullptr, nullptr), 0.7 * 0.5 * 3 * 0.25, 1e-12);
}

// The SQP solver computes arap_energy's two halves on threads of its own (arap_energy_half) and
// relies on getting arap_energy's result to the last bit, so that runs do not depend on where
// each half ran: energy weight (E0 + E1), the first half's gradient added into the caller's
// vector, the second half's summed apart and added after.
TEST(Energies, ArapHalvesRecombineToTheSameBits) {
  const SurfaceMesh b = sphere(3);
  const TetMesh tm = tet_mesh_of(b.V, b.F, 6000);
  ASSERT_GE(tm.T.rows(), kArapSplitTets) << "the mesh must be large enough for arap_energy to split";
  const ArapRest rest = ArapRest::build(tm.V, tm.T);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0, 0.01);
  MatX3d X = tm.V;
  for (int v = 0; v < X.rows(); ++v)
    for (int k = 0; k < 3; ++k) X(v, k) = 1.3 * X(v, k) + noise(rng);
  const double w = 0.7;
  // A gradient that already holds other terms, as the solver's does.
  Eigen::VectorXd base(X.size());
  for (int i = 0; i < base.size(); ++i) base[i] = noise(rng);
  Eigen::VectorXd g_whole = base;
  const double E_whole = arap_energy(X, tm.T, rest, w, &g_whole, nullptr);
  Eigen::VectorXd g_halves = base, g_second = Eigen::VectorXd::Zero(X.size());
  const double E0 = arap_energy_half(X, tm.T, rest, w, 0, &g_halves);
  const double E1 = arap_energy_half(X, tm.T, rest, w, 1, &g_second);
  g_halves += g_second;
  EXPECT_EQ(E_whole, w * (E0 + E1));
  EXPECT_TRUE(g_whole == g_halves) << "largest difference " << (g_whole - g_halves).cwiseAbs().maxCoeff();
  EXPECT_GT(E0, 0);
  EXPECT_GT(E1, 0);
  // Energy only: the same sum.
  EXPECT_EQ(arap_energy(X, tm.T, rest, w, nullptr, nullptr),
            w * (arap_energy_half(X, tm.T, rest, w, 0, nullptr) + arap_energy_half(X, tm.T, rest, w, 1, nullptr)));
}

TEST(Energies, AreaBarrierGradientHessianAndKnownValues) {
  Small s = small_mesh();
  SurfaceArapRest rest = SurfaceArapRest::build(s.X0, s.F);
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return area_barrier_energy(X, s.F, rest, 0.3, g, H);
  };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
  EXPECT_NEAR(E(s.X0, nullptr, nullptr), 0, 1e-14);
  // Uniform scaling by 2 multiplies every area by 4: -0.3 log 4 (the fractions sum to 1).
  EXPECT_NEAR(E(2.0 * s.X0, nullptr, nullptr), -0.3 * std::log(4.0), 1e-12);
  // A triangle flattened to a segment: infinite.
  MatX3d Y = s.X0;
  const int a = s.F(0, 0), b = s.F(0, 1), c = s.F(0, 2);
  Y.row(c) = 0.5 * (Y.row(a) + Y.row(b));
  EXPECT_TRUE(std::isinf(E(Y, nullptr, nullptr)));
}

TEST(Energies, GapPairsAcrossTheOutsideBetweenTwoParts) {
  // Two unit boxes one above the other with a gap of 0.04 between them: the exterior pairs join
  // the lower box's top face to the upper box's bottom face across the gap (the boxes are thick:
  // no interior pair), and a gap closed or passed through counts as crushed.
  const SurfaceMesh lower = grid_box(4), upper = grid_box(4, Vec3(0, 0, 1.04), Vec3(1, 1, 2.04));
  SurfaceMesh two;
  two.V.resize(lower.V.rows() + upper.V.rows(), 3);
  two.V << lower.V, upper.V;
  two.F.resize(lower.F.rows() + upper.F.rows(), 3);
  two.F << lower.F, (upper.F.array() + static_cast<int>(lower.V.rows())).matrix();
  const double diag = std::sqrt(2.0 + 2.04 * 2.04);
  EXPECT_TRUE(thickness_pairs(two.V, two.F, 0.05 * diag).empty());
  const std::vector<ThicknessPair> gaps = thickness_pairs(two.V, two.F, 0.05 * diag, true);
  // Every vertex of the two facing faces but their corners (whose normals lean out by the
  // triangulation, some beyond the 60 degrees) has its pair, and only those vertices.
  std::vector<char> paired(two.V.rows(), 0);
  for (const ThicknessPair& p : gaps) paired[p.v] = 1;
  for (int v = 0; v < two.V.rows(); ++v) {
    const bool on_gap = two.V(v, 2) == 1.0 || two.V(v, 2) == 1.04;
    const bool corner = (two.V(v, 0) == 0 || two.V(v, 0) == 1) && (two.V(v, 1) == 0 || two.V(v, 1) == 1);
    if (on_gap && !corner) {
      EXPECT_TRUE(paired[v]) << two.V.row(v);
    }
    if (!on_gap) {
      EXPECT_FALSE(paired[v]) << two.V.row(v);
    }
  }
  EXPECT_GE(static_cast<int>(gaps.size()), 2 * (25 - 4));
  for (const ThicknessPair& p : gaps) {
    EXPECT_TRUE(p.exterior);
    EXPECT_NEAR(p.d0, 0.04, 1e-12);
    const Vec3 q = p.bary[0] * two.V.row(two.F(p.f, 0)) + p.bary[1] * two.V.row(two.F(p.f, 1)) +
                   p.bary[2] * two.V.row(two.F(p.f, 2));
    EXPECT_NEAR(std::abs(q.z() - two.V(p.v, 2)), 0.04, 1e-12);
  }
  auto lowered = [&](double dz) {  // the upper box moved down by dz
    MatX3d X = two.V;
    for (int v = static_cast<int>(lower.V.rows()); v < X.rows(); ++v) X(v, 2) -= dz;
    return X;
  };
  double w = 0;
  for (const ThicknessPair& p : gaps) w += p.w;
  EXPECT_EQ(crushed_fraction(lowered(0.01), two.F, gaps, 0.5), 0.0);  // 0.03 left: open
  EXPECT_NEAR(crushed_fraction(lowered(0.03), two.F, gaps, 0.5), w, 1e-12);  // 0.01 left
  // Passed through each other by 0.04: as far apart as at rest, but on the wrong sides.
  EXPECT_NEAR(crushed_fraction(lowered(0.08), two.F, gaps, 0.5), w, 1e-12);
  EXPECT_EQ(thickness_energy(two.V, two.F, gaps, 0.5, 1.0, nullptr, nullptr), 0.0);
  EXPECT_GT(thickness_energy(lowered(0.03), two.F, gaps, 0.5, 1.0, nullptr, nullptr), 0.0);
}

TEST(Energies, ThicknessPairsAndBarrierOfAThinPlate) {
  // A 1 x 1 x 0.04 plate: the vertices inside its top face see the bottom face 0.04 below them
  // (well under 5% of the diagonal), and the other way round.
  const SurfaceMesh plate = grid_box(4, Vec3(0, 0, 0), Vec3(1, 1, 0.04));
  const double diag = std::sqrt(2.0 + 0.04 * 0.04);
  const std::vector<ThicknessPair> pairs = thickness_pairs(plate.V, plate.F, 0.05 * diag);
  int faces = 0;
  for (int v = 0; v < plate.V.rows(); ++v) faces += plate.V(v, 2) == 0 || plate.V(v, 2) == 0.04;
  // Every vertex of the top and bottom faces (their rims too: their normals are mostly +-Z); the
  // side faces' inner vertices look across the whole plate: no pair.
  ASSERT_EQ(static_cast<int>(pairs.size()), faces);
  double w = 0;
  for (const ThicknessPair& p : pairs) {
    EXPECT_NEAR(p.d0, 0.04, 1e-12);
    const Vec3 q = p.bary[0] * plate.V.row(plate.F(p.f, 0)) + p.bary[1] * plate.V.row(plate.F(p.f, 1)) +
                   p.bary[2] * plate.V.row(plate.F(p.f, 2));
    EXPECT_NEAR(std::abs(q.z() - plate.V(p.v, 2)), 0.04, 1e-12);
    EXPECT_NEAR(q.x(), plate.V(p.v, 0), 1e-12);
    w += p.w;
  }
  EXPECT_GT(w, 0.5);  // most of the plate's area is its two faces
  EXPECT_LT(w, 1.0);
  // Pairs with a larger limit only: a thick box has none under 5%.
  EXPECT_TRUE(thickness_pairs(grid_box(4).V, grid_box(4).F, 0.05 * std::sqrt(3.0)).empty());

  const double keep = 0.5;
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return thickness_energy(X, plate.F, pairs, keep, 0.7, g, H);
  };
  auto squashed = [&](double f) {
    MatX3d X = plate.V;
    X.col(2) *= f;
    return X;
  };
  EXPECT_EQ(E(plate.V, nullptr, nullptr), 0.0);                 // at rest
  EXPECT_EQ(E(squashed(0.6), nullptr, nullptr), 0.0);           // still above half its thickness
  EXPECT_EQ(crushed_fraction(squashed(0.6), plate.F, pairs, keep), 0.0);
  // At 30% every pair is at r = 0.3 / 0.5: 0.7 * sum w (r - 1 - log r).
  const double r = 0.6;
  EXPECT_NEAR(E(squashed(0.3), nullptr, nullptr), 0.7 * w * (r - 1 - std::log(r)), 1e-12);
  EXPECT_NEAR(crushed_fraction(squashed(0.3), plate.F, pairs, keep), w, 1e-12);
  EXPECT_TRUE(std::isinf(E(squashed(0.0), nullptr, nullptr)));  // folded flat
  // Gaps across (pair_gap, flattened_parts): at rest 0.04 for every pair; pressed to 60% not
  // flattened, to 30% flattened (ratio 0.3); pressed to 30% with the top face slid 0.1 along x, each
  // pair is farther apart than half its rest distance (sqrt(0.012^2 + 0.1^2)), which the barrier's
  // plain distance takes for open, while the gap across says 0.3; turned inside out (the top
  // below the bottom), the ratio is negative.
  for (const ThicknessPair& p : pairs) EXPECT_NEAR(pair_gap(plate.V, plate.F, p), 0.04, 1e-12);
  const Flattened none = flattened_parts(plate.V, squashed(0.6), plate.F, pairs, keep);
  EXPECT_EQ(none.fraction, 0.0);
  EXPECT_EQ(none.vertex(), -1);
  const Flattened pressed = flattened_parts(plate.V, squashed(0.3), plate.F, pairs, keep);
  EXPECT_NEAR(pressed.fraction, w, 1e-12);
  EXPECT_NEAR(pressed.ratio, 0.3, 1e-12);
  EXPECT_GE(pressed.vertex(), 0);
  ASSERT_FALSE(pressed.places.empty());
  EXPECT_EQ(pressed.places.front(), pressed.vertex());
  EXPECT_LE(static_cast<int>(pressed.places.size()), 5);
  for (size_t a = 0; a < pressed.places.size(); ++a)  // each place 0.1 or more from the others
    for (size_t b = a + 1; b < pressed.places.size(); ++b)
      EXPECT_GT((plate.V.row(pressed.places[a]) - plate.V.row(pressed.places[b])).norm(), 0.1);
  // The plate pressed all over: several places across its 1 x 1 faces, none with a larger spacing
  // than the plate allows.
  EXPECT_GE(pressed.places.size(), 2u);
  EXPECT_EQ(flattened_parts(plate.V, squashed(0.3), plate.F, pairs, keep, 2.0).places.size(), 1u);
  MatX3d slid = squashed(0.3);
  for (int v = 0; v < slid.rows(); ++v)
    if (plate.V(v, 2) == 0.04) slid(v, 0) += 0.1;
  EXPECT_EQ(crushed_fraction(slid, plate.F, pairs, keep), 0.0);
  EXPECT_EQ(E(slid, nullptr, nullptr), 0.0);
  for (const ThicknessPair& p : pairs) EXPECT_NEAR(pair_gap(slid, plate.F, p), 0.012, 1e-12);
  const Flattened slid_flat = flattened_parts(plate.V, slid, plate.F, pairs, keep);
  EXPECT_NEAR(slid_flat.fraction, w, 1e-12);
  EXPECT_NEAR(slid_flat.ratio, 0.3, 1e-12);
  EXPECT_LT(flattened_parts(plate.V, squashed(-0.5), plate.F, pairs, keep).ratio, 0.0);
  // Gradient and Gauss-Newton Hessian in the active range, jittered.
  MatX3d X = squashed(0.3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.002, 0.002);
  for (int i = 0; i < X.rows(); ++i)
    for (int k = 0; k < 3; ++k) X(i, k) += u(rng);
  expect_gradient(E, X);
  expect_psd(hessian(E, X));
}

TEST(Energies, ContactBarrierSeesThePlateSidesSlidingAlongEachOther) {
  // The 1 x 1 x 0.04 plate of the test above: every vertex of its top and bottom faces is 0.04 from
  // the other face, so its contact distance is half that (keep 0.5).
  const SurfaceMesh plate = grid_box(4, Vec3(0, 0, 0), Vec3(1, 1, 0.04));
  const double diag = std::sqrt(2.0 + 0.04 * 0.04), keep = 0.5;
  const ContactRest rest = ContactRest::build(plate.V, plate.F, keep, 0.05 * diag);
  int faces = 0;
  for (int v = 0; v < plate.V.rows(); ++v) {
    const bool on_face = plate.V(v, 2) == 0 || plate.V(v, 2) == 0.04;
    faces += on_face;
    EXPECT_NEAR(rest.dhat[v], on_face ? 0.02 : 0.0, 1e-12) << plate.V.row(v);
  }
  EXPECT_EQ(rest.vertices, faces);
  EXPECT_NEAR(rest.dhat_max, 0.02, 1e-12);
  // Thresholds: none with the vertex's own triangles or triangles of its side (same normal), the
  // contact distance with the face across.
  for (int f = 0; f < plate.F.rows(); ++f) {
    const Vec3 n = area_normal(plate.V, plate.F(f, 0), plate.F(f, 1), plate.F(f, 2)).normalized();
    for (int v = 0; v < plate.V.rows(); ++v) {
      if (!(rest.dhat[v] > 0)) continue;
      const bool top = plate.V(v, 2) == 0.04;
      const bool incident = plate.F(f, 0) == v || plate.F(f, 1) == v || plate.F(f, 2) == v;
      const bool same_side = top ? n.z() > 0.5 : n.z() < -0.5;
      if (incident || same_side) {
        EXPECT_EQ(rest.threshold(v, f), 0.0);
      }
      if (!incident && n.z() < -0.5 && top) {
        EXPECT_NEAR(rest.threshold(v, f), 0.02, 1e-12);
      }
    }
  }
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return contact_energy(X, rest, 0.7, g, H);
  };
  auto squashed = [&](double f) {
    MatX3d X = plate.V;
    X.col(2) *= f;
    return X;
  };
  EXPECT_EQ(E(plate.V, nullptr, nullptr), 0.0);
  EXPECT_EQ(E(squashed(0.6), nullptr, nullptr), 0.0);  // 0.024 across: above the contact distance
  // At 30% (0.012 across, r = 0.6 of the contact distance) each face vertex lies right over a vertex
  // of the face across, as close to its six triangles: one contact each, not six.
  int active = 0;
  const double pressed = contact_energy(squashed(0.3), rest, 0.7, nullptr, nullptr, &active);
  EXPECT_EQ(active, faces);
  const double r = 0.6;
  double w = 0;
  for (int v = 0; v < plate.V.rows(); ++v) w += rest.dhat[v] > 0 ? rest.w[v] : 0.0;
  EXPECT_NEAR(pressed, 0.7 * w * -(r - 1) * (r - 1) * std::log(r), 1e-12);
  // Measured the same way (contact_flattened): nothing at rest or at 60%, all of it at 30%.
  EXPECT_EQ(contact_flattened(plate.V, rest).fraction, 0.0);
  EXPECT_EQ(contact_flattened(squashed(0.6), rest).vertex(), -1);
  const Flattened flat = contact_flattened(squashed(0.3), rest);
  EXPECT_NEAR(flat.fraction, w, 1e-12);
  EXPECT_NEAR(flat.ratio, 0.3, 1e-12);
  EXPECT_GE(flat.places.size(), 2u);
  // The same pressed plate with its top face slid 0.1 along x: the fixed pairs of the thickness
  // barrier are then 0.1 apart and see nothing (ThicknessPairsAndBarrierOfAThinPlate); the contact
  // barrier sees the face across as close as before (but at the rims that slid past each other).
  MatX3d slid = squashed(0.3);
  for (int v = 0; v < slid.rows(); ++v)
    if (plate.V(v, 2) == 0.04) slid(v, 0) += 0.1;
  const std::vector<ThicknessPair> pairs = thickness_pairs(plate.V, plate.F, 0.05 * diag);
  EXPECT_EQ(thickness_energy(slid, plate.F, pairs, keep, 0.7, nullptr, nullptr), 0.0);
  EXPECT_GT(E(slid, nullptr, nullptr), 0.6 * pressed);
  EXPECT_LT(E(slid, nullptr, nullptr), pressed);
  EXPECT_TRUE(std::isinf(E(squashed(0.0), nullptr, nullptr)));  // the two faces on each other
  // Gradient (exact) and Hessian (Gauss-Newton, block-diagonal: PSD) in the active range, jittered.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.002, 0.002);
  for (int i = 0; i < slid.rows(); ++i)
    for (int k = 0; k < 3; ++k) slid(i, k) += u(rng);
  expect_gradient(E, slid);
  const Eigen::MatrixXd H = hessian(E, slid);
  expect_psd(H);
  EXPECT_GT(H.diagonal().maxCoeff(), 0.0);
  for (int i = 0; i < slid.rows(); ++i)  // nothing outside the 3 x 3 diagonal blocks
    for (int j = 0; j < slid.rows(); ++j)
      if (i != j) {
        EXPECT_EQ(H.block(3 * i, 3 * j, 3, 3).norm(), 0.0);
      }
}

TEST(Energies, ContactStepBoundStopsAtTheTriangleAcrossNotAlongIt) {
  const SurfaceMesh plate = grid_box(4, Vec3(0, 0, 0), Vec3(1, 1, 0.04));
  const double diag = std::sqrt(2.0 + 0.04 * 0.04);
  const ContactRest rest = ContactRest::build(plate.V, plate.F, 0.5, 0.05 * diag);
  auto top_moved = [&](const Vec3& d) {
    MatX3d D = MatX3d::Zero(plate.V.rows(), 3);
    for (int v = 0; v < plate.V.rows(); ++v)
      if (plate.V(v, 2) == 0.04) D.row(v) = d.transpose();
    return D;
  };
  // The top face pushed down by 0.08 reaches the bottom face halfway: 0.8 of that.
  EXPECT_NEAR(contact_step_bound(plate.V, top_moved(Vec3(0, 0, -0.08)), rest), 0.4, 1e-9);
  EXPECT_NEAR(contact_step_bound(plate.V, top_moved(Vec3(0, 0, -0.4)), rest), 0.08, 1e-9);
  // Pushed down slanted: it meets the bottom face (or its rim) at the same height.
  EXPECT_NEAR(contact_step_bound(plate.V, top_moved(Vec3(0.3, 0.2, -0.08)), rest), 0.4, 1e-9);
  // Slid along the bottom face, or lifted off it: no limit.
  EXPECT_EQ(contact_step_bound(plate.V, top_moved(Vec3(0.5, 0.3, 0)), rest), 1.0);
  EXPECT_EQ(contact_step_bound(plate.V, top_moved(Vec3(0, 0, 0.5)), rest), 1.0);
  const MatX3d still = MatX3d::Zero(plate.V.rows(), 3);
  EXPECT_EQ(contact_step_bound(plate.V, still, rest), 1.0);
  // No thin part: no bound whatever the motion.
  const SurfaceMesh box = grid_box(4);
  const ContactRest thick = ContactRest::build(box.V, box.F, 0.5, 0.05 * std::sqrt(3.0));
  EXPECT_EQ(thick.vertices, 0);
  MatX3d D = MatX3d::Zero(box.V.rows(), 3);
  D.col(2).setConstant(-5.0);
  D(0, 2) = 5.0;
  EXPECT_EQ(contact_step_bound(box.V, D, thick), 1.0);
}

TEST(Energies, SurfaceArapGradientHessianAndZeroAtRest) {
  Small s = small_mesh();
  SurfaceArapRest rest = SurfaceArapRest::build(s.X0, s.F);
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return surface_arap_energy(X, s.F, rest, 0.7, g, H);
  };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
  EXPECT_NEAR(E(s.X0, nullptr, nullptr), 0, 1e-14);
  Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  MatX3d Xr = (s.X0 * R.transpose()).rowwise() + Eigen::RowVector3d(3, -1, 2);
  EXPECT_NEAR(E(Xr, nullptr, nullptr), 0, 1e-14);
  // Uniform scaling by s: delta = 0.5 * 2 (s-1)^2 for every triangle (two singular values).
  EXPECT_NEAR(E(1.5 * s.X0, nullptr, nullptr), 0.7 * 0.5 * 2 * 0.25, 1e-12);
  // Stretching a unit right triangle in the plane by 2 along x: singular values 2 and 1.
  MatX3d T0(3, 3), T1(3, 3);
  T0 << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  T1 << 0, 0, 0, 2, 0, 0, 0, 1, 0;
  MatX3i F1(1, 3);
  F1 << 0, 1, 2;
  SurfaceArapRest r1 = SurfaceArapRest::build(T0, F1);
  EXPECT_NEAR(surface_arap_energy(T1, F1, r1, 1.0, nullptr, nullptr), 0.5, 1e-12);
  // Bending: two triangles of a unit square folded by 90 degrees along their diagonal keep every
  // edge length, so one rotation per triangle would cost nothing; shared vertex rotations do.
  MatX3d Q0(4, 3), Q1(4, 3);
  Q0 << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  MatX3i F2(2, 3);
  F2 << 0, 1, 2, 0, 2, 3;
  const Vec3 d = Vec3(1, 1, 0).normalized(), m(0.5, 0.5, 0);
  Q1 = Q0;
  Q1.row(3) = (m + (Vec3(0, 1, 0) - m).dot(Vec3(-1, 1, 0).normalized()) * Vec3(0, 0, 1)).transpose();
  EXPECT_NEAR((Q1.row(3) - Q1.row(0)).norm(), 1.0, 1e-12);
  SurfaceArapRest r2 = SurfaceArapRest::build(Q0, F2);
  EXPECT_GT(surface_arap_energy(Q1, F2, r2, 1.0, nullptr, nullptr), 0.01);
  (void)d;
}

TEST(Energies, BorderL1GradientPsdAndKnownValues) {
  // An open strip: the two triangles of a square, border = its 4 sides.
  MatX3i F(2, 3);
  F << 0, 1, 2, 0, 2, 3;
  const auto edges = border_edges(F);
  ASSERT_EQ(edges.size(), 4u);
  EXPECT_TRUE(border_edges(small_mesh().F).empty());
  MatX3d X(4, 3);
  X << 0, 0, 0, 1, 0.1, 0.2, 1.1, 0.9, -0.1, -0.2, 1.2, 0.3;
  for (double eps : {0.5, 0.01}) {
    EnergyFn E = [&](const MatX3d& Y, Eigen::VectorXd* g, HessianSink* H) {
      return border_l1_energy(Y, edges, 0.8, eps, 1.3, g, H);
    };
    expect_gradient(E, X);
    expect_psd(hessian(E, X));
  }
  // Axis-aligned square, any size and smoothing: zero.
  MatX3d S(4, 3);
  S << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  for (double eps : {0.0, 0.1}) {
    EXPECT_NEAR(border_l1_energy(S, edges, 2.0, eps, 1.0, nullptr, nullptr), 0, 1e-12);
    EXPECT_NEAR(border_l1_energy(3.0 * S, edges, 2.0, eps, 1.0, nullptr, nullptr), 0, 1e-12);
  }
  // Rotated by 45 degrees in its plane: each side |e|_1 - |e| = sqrt(2) - 1; h scales it.
  MatX3d S2(4, 3);
  const double c = std::sqrt(0.5);
  S2 << 0, 0, 0, c, c, 0, 0, 2 * c, 0, -c, c, 0;
  EXPECT_NEAR(border_l1_energy(S2, edges, 0.5, 0.0, 1.0, nullptr, nullptr), 0.5 * 4 * (std::sqrt(2.0) - 1), 1e-12);
  EXPECT_GT(border_l1_energy(S2, edges, 0.5, 0.1, 1.0, nullptr, nullptr), 0);
}

TEST(Energies, VolumeBarrierGradientAndPsd) {
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  for (bool neutral : {true, false}) {
    SCOPED_TRACE(neutral ? "J - 1 - log J" : "-log J");
    EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
      return volume_barrier_energy(X, s.T, rest, 0.3, g, H, nullptr, neutral);
    };
    expect_gradient(E, s.X);
    expect_psd(hessian(E, s.X));
    EXPECT_NEAR(E(s.X0, nullptr, nullptr), 0, 1e-14);
    // Uniform scaling by 2: J = 8 in every tet (the weights sum to 1).
    EXPECT_NEAR(E(2.0 * s.X0, nullptr, nullptr), 0.3 * ((neutral ? 7.0 : 0.0) - std::log(8.0)), 1e-12);
    // At rest the neutral form pulls on nothing; the log form pushes every tet to grow.
    Eigen::VectorXd g = Eigen::VectorXd::Zero(s.X0.size());
    E(s.X0, &g, nullptr);
    if (neutral) {
      EXPECT_LT(g.cwiseAbs().maxCoeff(), 1e-13);
    } else {
      EXPECT_GT(g.cwiseAbs().maxCoeff(), 1e-3);
      // Growing every tet lowers it: the gradient points against a uniform dilation about the centroid.
      const Eigen::RowVector3d c = s.X0.colwise().mean();
      MatX3d D = s.X0.rowwise() - c;
      EXPECT_LT(g.dot(Eigen::Map<const Eigen::VectorXd>(D.data(), D.size())), -1e-3);
    }
  }
  // The default is the -log J form.
  EXPECT_NEAR(volume_barrier_energy(2.0 * s.X0, s.T, rest, 0.3, nullptr, nullptr), -0.3 * std::log(8.0), 1e-12);
}

TEST(Energies, VolumeBarrierPerTetMultipliers) {
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  std::vector<double> boost(s.T.rows(), 1.0);
  boost[0] = 100.0;
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return volume_barrier_energy(X, s.T, rest, 0.3, g, H, &boost);
  };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
  // Uniform scaling by 2: every tet contributes w_t b_t (-log 8); tet 0 now 100 times.
  const double expected = -0.3 * std::log(8.0) * (1.0 + 99.0 * rest.w[0]);
  EXPECT_NEAR(E(2.0 * s.X0, nullptr, nullptr), expected, 1e-12);
  // All multipliers 1 is the plain barrier.
  std::fill(boost.begin(), boost.end(), 1.0);
  EXPECT_NEAR(E(s.X, nullptr, nullptr), volume_barrier_energy(s.X, s.T, rest, 0.3, nullptr, nullptr), 1e-14);
}

TEST(Energies, CrushGuardActsOnlyUnderItsRatioWithEqualWeights) {
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  // A ratio between the smallest and largest J of the test state, so that some tets are under it
  // and some above (the gradient check then crosses both branches).
  std::vector<double> J;
  for (int t = 0; t < s.T.rows(); ++t) {
    Eigen::Matrix3d Ds;
    for (int m = 0; m < 3; ++m) Ds.col(m) = (s.X.row(s.T(t, m + 1)) - s.X.row(s.T(t, 0))).transpose();
    J.push_back((Ds * rest.Dm_inv[t]).determinant());
  }
  std::sort(J.begin(), J.end());
  ASSERT_GT(J.front(), 0);
  ASSERT_LT(J.front(), J.back());
  const double j0 = 0.5 * (J[J.size() / 2] + J[J.size() / 2 - 1]);
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return crush_guard_energy(X, s.T, rest, j0, 0.7, g, H);
  };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
  EXPECT_GT(E(s.X, nullptr, nullptr), 0);
  // At rest (J = 1 > j0) nothing, gradient included.
  EXPECT_EQ(crush_guard_energy(s.X0, s.T, rest, 0.5, 0.7, nullptr, nullptr), 0);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(s.X0.size());
  crush_guard_energy(s.X0, s.T, rest, 0.5, 0.7, &g, nullptr);
  EXPECT_EQ(g.cwiseAbs().maxCoeff(), 0);
  // Scaled by 1/2: J = 1/8 in every tet, r = 1/2 with j0 = 1/4; each tet weighs 1/#tets whatever
  // its volume, so the sum is psi(1/2) = 1/2 - 1 + log 2.
  EXPECT_NEAR(crush_guard_energy(0.5 * s.X0, s.T, rest, 0.25, 0.7, nullptr, nullptr),
              0.7 * (std::log(2.0) - 0.5), 1e-12);
  // An inverted tet: +inf.
  MatX3d M = s.X0;
  M.col(2) *= -1;
  EXPECT_TRUE(std::isinf(crush_guard_energy(M, s.T, rest, 0.25, 0.7, nullptr, nullptr)));
}

TEST(Energies, UntangleGradientAlsoOnInvertedTets) {
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  for (double eps : {1e-1, 1e-3}) {
    EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink*) {
      return untangle_energy(X, s.T, rest, eps, 1.3, 0.5, g);
    };
    expect_gradient(E, s.X);
    // Mirrored: every tet inverted, the energy stays finite and its gradient exact (checked at
    // the larger eps: at 1e-3 the energy is so stiff that central differences lose 5 digits).
    MatX3d M = s.X;
    M.col(0) *= -1;
    if (eps > 1e-2) expect_gradient(E, M);
    EXPECT_GT(E(M, nullptr, nullptr), E(s.X, nullptr, nullptr));
  }
  // At the rest shape scaled by `scale` (J = I) with eps -> 0: (1 - theta) 3 + theta 2.
  const double e0 = untangle_energy(1.3 * s.X0, s.T, rest, 1e-12, 1.3, 0.5, nullptr);
  EXPECT_NEAR(e0, 0.5 * 3 + 0.5 * 2, 1e-9);
}

TEST(Energies, UntangleTetTermsSumToTheEnergy) {
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  MatX3d M = s.X;
  M.row(0) *= -1;  // some tets inverted
  Eigen::VectorXd g = Eigen::VectorXd::Zero(M.size()), gs = Eigen::VectorXd::Zero(M.size());
  const double E = untangle_energy(M, s.T, rest, 1e-2, 1.1, 0.5, &g);
  double sum = 0;
  for (int t = 0; t < s.T.rows(); ++t) {
    Eigen::Matrix<double, 12, 1> ge;
    sum += untangle_tet_energy(M, s.T, rest, t, 1e-2, 1.1, 0.5, &ge);
    for (int j = 0; j < 4; ++j) gs.segment<3>(3 * s.T(t, j)) += ge.segment<3>(3 * j);
  }
  EXPECT_NEAR(sum, E, 1e-12 * std::abs(E));
  EXPECT_LT((g - gs).norm(), 1e-12 * g.norm());
}

TEST(Energies, UntangleCornerGradientAndHessianAreExact) {
  // Per corner: the energy and gradient equal the tet term's, and the Hessian matches central
  // differences of that gradient; on valid and inverted tets.
  Small s = small_mesh();
  ArapRest rest = ArapRest::build(s.X0, s.T);
  MatX3d M = s.X;
  M.row(0) *= -1;  // some tets inverted
  for (const MatX3d* X : {&s.X, &M})
    for (double eps : {1e-1, 1e-2})
      for (int t = 0; t < s.T.rows(); ++t)
        for (int j = 0; j < 4; ++j) {
          Eigen::Matrix<double, 12, 1> ge;
          const double e = untangle_tet_energy(*X, s.T, rest, t, eps, 1.1, 0.5, &ge);
          Vec3 g;
          Eigen::Matrix3d H;
          EXPECT_NEAR(untangle_tet_corner(*X, s.T, rest, t, j, eps, 1.1, 0.5, &g, &H), e, 1e-13 * std::abs(e));
          EXPECT_LT((g - ge.segment<3>(3 * j)).norm(), 1e-10 * std::max(1.0, g.norm()));
          const double h = 1e-6;
          for (int k = 0; k < 3; ++k) {
            MatX3d P = *X, Q = *X;
            P(s.T(t, j), k) += h;
            Q(s.T(t, j), k) -= h;
            Vec3 gp, gq;
            untangle_tet_corner(P, s.T, rest, t, j, eps, 1.1, 0.5, &gp, nullptr);
            untangle_tet_corner(Q, s.T, rest, t, j, eps, 1.1, 0.5, &gq, nullptr);
            const Vec3 col = (gp - gq) / (2 * h);
            EXPECT_LT((H.col(k) - col).norm(), 1e-5 * std::max(1.0, col.norm()))
                << "tet " << t << ", corner " << j << ", axis " << k << ", eps " << eps;
          }
          EXPECT_LT((H - H.transpose()).norm(), 1e-12 * std::max(1.0, H.norm()));
        }
}

TEST(Lbfgs, BoundedFirstStepStillReachesTheMinimum) {
  // f(z) = 0.5 (z - c)^T A (z - c), A diagonal and badly scaled; start 10 away from c.
  const Eigen::Vector3d a(1.0, 100.0, 1e4), c(1.0, -2.0, 3.0);
  auto f = [&](const Eigen::VectorXd& z, Eigen::VectorXd* g) {
    const Eigen::VectorXd d = z - c;
    if (g) *g = a.cwiseProduct(d);
    return 0.5 * d.dot(a.cwiseProduct(d));
  };
  auto identity = [](const Eigen::VectorXd& q) { return q; };
  for (double limit : {0.0, 0.5}) {
    Eigen::VectorXd z = c + Eigen::Vector3d(10, 10, 10);
    LbfgsOptions o;
    o.max_change = limit;
    o.max_iterations = 1;
    double E = 0;
    const Eigen::VectorXd z0 = z;
    ASSERT_EQ(lbfgs_minimize(z, f, identity, o, E), 1);
    // With the limit, the first accepted step moves no unknown further than it.
    if (limit > 0) {
      EXPECT_LE((z - z0).lpNorm<Eigen::Infinity>(), limit * (1 + 1e-12));
    }
    o.max_iterations = 500;
    o.decrease_tol = 0;
    lbfgs_minimize(z, f, identity, o, E);
    EXPECT_LT((z - c).norm(), 1e-6) << "limit " << limit;
  }
}

TEST(Energies, BarrierGradientAndPsd) {
  Small s = small_mesh();
  auto pairs = face_pairs(s.F);
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return barrier_energy(X, s.F, pairs, 0.01, g, H);
  };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
}

TEST(Energies, ComplexityGradientAndPsd) {
  // The gamma edge areas are held constant in the derivatives (as in the paper), so the check
  // freezes them by comparing against finite differences of the energy with frozen weights:
  // on a mesh with equal face areas the weights are constant to first order only, so we use a
  // relative tolerance on the directional derivative instead.
  Small s = small_mesh();
  auto pairs = face_pairs(s.F);
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return complexity_energy(X, s.F, pairs, 2.0, g, H);
  };
  expect_psd(hessian(E, s.X));
  Eigen::VectorXd g = analytic_gradient(E, s.X), f = fd_gradient(E, s.X);
  EXPECT_GT(g.dot(f), 0.8 * g.norm() * f.norm());  // same descent direction
  // Zero on a flat pair configuration: a box has n_f = n_g on its 6 face diagonals.
  auto b = box();
  auto bp = face_pairs(b.F);
  EXPECT_GT(complexity_energy(b.V, b.F, bp, 1.0, nullptr, nullptr), 0);  // 12 box edges contribute
}

TEST(Energies, EdgeGradientAndPsd) {
  Small s = small_mesh();
  auto pairs = face_pairs(s.F);
  std::vector<EdgeConstraint> edges = {{0, true, 3.0}, {4, false, 1.5}, {7, true, 0.5}};
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink* H) {
    return edge_energy(X, s.F, pairs, edges, 1.0, g, H);
  };
  expect_gradient(E, s.X);
  expect_psd(hessian(E, s.X));
}

TEST(Energies, AreaConstraintGradient) {
  Small s = small_mesh();
  EnergyFn E = [&](const MatX3d& X, Eigen::VectorXd* g, HessianSink*) {
    if (g) {
      Eigen::VectorXd gg = Eigen::VectorXd::Zero(X.size());
      double c = area_constraint(X, s.F, 2.0, &gg);
      *g += gg;
      return c;
    }
    return area_constraint(X, s.F, 2.0, nullptr);
  };
  expect_gradient(E, s.X);
}
