// The l1 polycube deformation on shapes with known answers.
#include <algorithm>
#include <array>
#include <memory>
#include <random>

#include "polycube/chart/labeling.h"
#include "polycube/core/error.h"
#include "polycube/deform/solver.h"
#include "polycube/deform/sparse_system.h"
#include "polycube/examples/examples.h"
#include "polycube/tetra/tetrahedralize.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {

// Charts: connected sets of boundary triangles with the same dominant normal axis and sign.
int count_charts(const MatX3d& X, const MatX3i& F) { return chart::build_charts(X, F, chart::label_by_normal(X, F)).count(); }

double boundary_area(const MatX3d& X, const MatX3i& F) {
  double l1, a;
  deform::l1_measure(X, F, l1, a);
  return a;
}

// The SQP system over a sphere's tet mesh (tm receives the mesh): ARAP's Gauss-Newton Hessian plus
// a volume barrier (couples the coordinates), not yet made definite.
std::unique_ptr<deform::SparseSystem> sphere_system(int subdivisions, int tets, TetMesh& tm) {
  auto s = sphere(subdivisions);
  tm = tet_mesh_of(s.V, s.F, tets);
  std::vector<std::vector<int>> elements;
  for (int t = 0; t < tm.T.rows(); ++t) elements.push_back({tm.T(t, 0), tm.T(t, 1), tm.T(t, 2), tm.T(t, 3)});
  auto sys = std::make_unique<deform::SparseSystem>(static_cast<int>(tm.V.rows()), elements);
  sys->cache_elements(elements);
  const deform::ArapRest rest = deform::ArapRest::build(tm.V, tm.T);
  deform::arap_energy(tm.V, tm.T, rest, 1.0, nullptr, sys.get());
  deform::volume_barrier_energy(tm.V, tm.T, rest, 0.1, nullptr, sys.get());
  return sys;
}

// Two vectors of standard normal entries (drawn alternately, from one generator).
std::array<Eigen::VectorXd, 2> random_pair(int size, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01;
  std::array<Eigen::VectorXd, 2> v{Eigen::VectorXd(size), Eigen::VectorXd(size)};
  for (int i = 0; i < size; ++i) {
    v[0][i] = N01(rng);
    v[1][i] = N01(rng);
  }
  return v;
}

}  // namespace

TEST(Deform, CubeStaysACube) {
  auto b = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  TetMesh tm = tet_mesh_of(b.V, b.F);
  auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_EQ(r.iterations, 0);
  EXPECT_NEAR(r.l1_quality, 0, 1e-12);
  EXPECT_NEAR(r.arap, 0, 1e-12);
  EXPECT_LE((r.X - tm.V).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Deform, SphereBecomesASixChartPolycube) {
  auto s = sphere(3, Vec3(5, -3, 2), 4.0);  // off-centre and scaled: result must not depend on it
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_TRUE(r.converged);
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_EQ(r.inverted, 0);
  EXPECT_EQ(count_charts(r.X, tm.boundary), 6);
  EXPECT_LT(r.arap, 0.15);
  // The area constraint holds.
  EXPECT_NEAR(boundary_area(r.X, tm.boundary) / boundary_area(tm.V, tm.boundary), 1.0, 1e-6);
  // Output at the input's position and scale.
  EXPECT_LT((Vec3(r.X.colwise().mean()) - Vec3(tm.V.colwise().mean())).norm(), 0.01 * 8);
  // A convergence record per iteration, with decreasing error over the run.
  ASSERT_EQ(static_cast<int>(r.history.size()), r.iterations);
  EXPECT_LT(r.history.back().l1_quality, r.history.front().l1_quality);
}

TEST(Deform, TheSqpConvergenceTestEndsScheduleStepsEarlierWithTheSameResult) {
  // A schedule step ends when a full SQP step barely lowers the energy (DeformOptions::
  // sqp_tolerance), not only after five small changes of the error (the paper's test, 0 here).
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  deform::DeformOptions paper;
  paper.sqp_tolerance = 0;
  const auto a = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, paper);
  const auto b = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  ASSERT_TRUE(a.converged);
  ASSERT_TRUE(b.converged);
  EXPECT_EQ(a.alpha_steps, b.alpha_steps);
  EXPECT_LT(b.iterations, 0.8 * a.iterations);
  // Some schedule step ended after fewer than five iterations, which the error test alone cannot do.
  std::vector<int> per_step(b.alpha_steps, 0);
  for (const auto& h : b.history) ++per_step[h.alpha_step];
  EXPECT_LT(*std::min_element(per_step.begin(), per_step.end() - 1), 5);
  EXPECT_EQ(b.inverted, 0);
  EXPECT_EQ(count_charts(b.X, tm.boundary), count_charts(a.X, tm.boundary));
  EXPECT_NEAR(b.arap, a.arap, 0.02 * a.arap);
}

TEST(Deform, TheNeutralVolumeBarrierDoesNotRoundTheShape) {
  // A rounded cube (the sphere pushed out to |x|^4 + |y|^4 + |z|^4 = 1) through the first schedule
  // step only (alpha 0.05): the l1 term pulls towards the cube. The plain -log J barrier pushes every
  // tet to grow, which under the constant boundary area rounds the shape off instead; the neutral
  // J - 1 - log J (DeformOptions::neutral_volume_barrier) does not.
  auto s = sphere(3);
  for (int v = 0; v < s.V.rows(); ++v) s.V.row(v) /= std::pow(s.V.row(v).array().pow(4).sum(), 0.25);
  TetMesh tm = tet_mesh_of(s.V, s.F, 3000);
  double l1, area;
  deform::l1_measure(tm.V, tm.boundary, l1, area);
  const double q0 = l1 / area - 1;
  deform::DeformOptions one_step;
  one_step.max_alpha_steps = 1;
  const auto log_form = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, one_step);
  one_step.neutral_volume_barrier = true;
  const auto neutral = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, one_step);
  // Measured: q0 0.299, neutral 0.297 (ARAP 1.1e-5), -log J 0.336 (ARAP 7.6e-4).
  EXPECT_LT(neutral.l1_quality, q0);
  EXPECT_GT(log_form.l1_quality, q0 + 0.02);
  EXPECT_LT(neutral.arap, 0.1 * log_form.arap);
  EXPECT_EQ(neutral.inverted, 0);
}

TEST(Deform, TheStallRescueRunsAgainOnlyWhenTheTargetIsMissedAndKeepsTheBetter) {
  // A target no schedule reaches (1e-7) makes the first run miss it: the deformation runs again,
  // solved more exactly from the rescue's step on, and keeps the better of the two. The first run
  // is the deformation without the rescue, to the bit; runs that reach the target, or whose
  // schedule was cut short before the rescue's step, are not run again.
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 3000);
  deform::DeformOptions o;
  o.target_quality = 1e-7;
  o.max_alpha_steps = 11;
  o.rescue_from_step = 8;
  const auto rescued = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, o);
  ASSERT_GT(rescued.rescue_from_quality, 0) << "the target was missed: the rescue should have run";
  EXPECT_EQ(rescued.inverted, 0);
  if (rescued.rescued)
    EXPECT_LT(rescued.l1_quality, rescued.rescue_from_quality);
  else
    EXPECT_EQ(rescued.l1_quality, rescued.rescue_from_quality);
  deform::DeformOptions off = o;
  off.rescue_cg_tolerance = 0;
  const auto first = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, off);
  EXPECT_EQ(first.rescue_from_quality, -1);
  EXPECT_FALSE(first.rescued);
  EXPECT_EQ(first.l1_quality, rescued.rescue_from_quality) << "the first run changed";
  if (!rescued.rescued) {
    EXPECT_EQ((rescued.X - first.X).cwiseAbs().maxCoeff(), 0.0) << "the first run's result is kept";
  }
  deform::DeformOptions short_schedule = o;
  short_schedule.max_alpha_steps = 9;  // ends one step after the rescue's start: no second run
  EXPECT_EQ(deform::deform_to_polycube(tm.V, tm.T, tm.boundary, short_schedule).rescue_from_quality, -1);
  const auto reached = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, deform::DeformOptions{});
  EXPECT_TRUE(reached.converged);
  EXPECT_EQ(reached.rescue_from_quality, -1);
}

TEST(Deform, TheCrushGuardKeepsTetsFromBeingPressedFlat) {
  // A sphere to a cube presses the tets under the cube's edges and corners. The crush guard acts on
  // the tets under its ratio only, each with the weight of a tet of mean volume: with it no tet ends
  // far under that ratio, and the distortion elsewhere hardly changes.
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 4000);
  const deform::ArapRest rest = deform::ArapRest::build(tm.V, tm.T);
  auto ratios = [&](const MatX3d& X) {
    std::vector<double> J;
    for (int t = 0; t < tm.T.rows(); ++t) {
      Eigen::Matrix3d Ds;
      for (int m = 0; m < 3; ++m) Ds.col(m) = (X.row(tm.T(t, m + 1)) - X.row(tm.T(t, 0))).transpose();
      J.push_back((Ds * rest.Dm_inv[t]).determinant());
    }
    std::sort(J.begin(), J.end());
    return J;
  };
  deform::DeformOptions opt;
  const auto plain = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, opt);
  opt.crush_guard_weight = 10;
  opt.crush_guard_ratio = 0.3;
  const auto guarded = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, opt);
  const auto J0 = ratios(plain.X), J1 = ratios(guarded.X);
  const auto under = [](const std::vector<double>& J, double r) {
    return std::lower_bound(J.begin(), J.end(), r) - J.begin();
  };
  EXPECT_EQ(guarded.inverted, 0);
  EXPECT_LT(guarded.l1_quality, 1e-3);
  EXPECT_EQ(count_charts(guarded.X, tm.boundary), 6);
  EXPECT_GT(J1.front(), J0.front());
  // Measured: smallest ratio 0.074 -> 0.290; under 0.2: some -> none; ARAP 0.1141 -> 0.1143.
  EXPECT_GT(under(J0, 0.2), 0);
  EXPECT_EQ(under(J1, 0.2), 0);
  EXPECT_LT(guarded.arap, 1.05 * plain.arap);
}

TEST(Deform, AResumedScheduleEndsWhereTheWholeOneDoes) {
  // The pipeline's slim-triangle collapse stops a deformation and resumes it from the state it
  // reached at the same schedule step (DeformOptions::start, first_alpha_step).
  auto s = sphere(3, Vec3(1, 2, 3), 2.0);
  TetMesh tm = tet_mesh_of(s.V, s.F, 3000);
  deform::DeformOptions first;
  first.max_alpha_steps = 4;
  const auto a = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, first);
  EXPECT_EQ(a.alpha_steps, 4);
  EXPECT_FALSE(a.converged);
  deform::DeformOptions rest_of_it;
  rest_of_it.start = a.X;
  rest_of_it.first_alpha_step = 4;
  const auto b = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, rest_of_it);
  EXPECT_TRUE(b.converged);
  EXPECT_EQ(b.inverted, 0);
  EXPECT_EQ(count_charts(b.X, tm.boundary), 6);
  // Its first record is at alpha0 x 2^4, and it starts from where the first run ended.
  ASSERT_FALSE(b.history.empty());
  EXPECT_NEAR(b.history.front().alpha, first.alpha0 * 16, 1e-12);
  EXPECT_LT(b.history.front().l1_quality, a.history.front().l1_quality);
  // The whole schedule in one run reaches the same layout.
  const auto whole = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_EQ(count_charts(whole.X, tm.boundary), 6);
  // Start positions that do not fit the mesh are an error.
  rest_of_it.start = a.X.topRows(10);
  EXPECT_THROW(deform::deform_to_polycube(tm.V, tm.T, tm.boundary, rest_of_it), Error);
}

TEST(Deform, TheSlimStallStopsOnlyWithSlimTriangles) {
  // With stop_at_slim_stall, a run either ends as usual or stops at a line search cut short by the
  // barrier while slim triangles exist, with a valid state at that step.
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 3000);
  deform::DeformOptions o;
  o.stop_at_slim_stall = true;
  o.slim_angle_deg = 30;  // many triangles count as slim
  const auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, o);
  EXPECT_EQ(r.inverted, 0);
  if (r.slim_stall) {
    EXPECT_GT(r.slim_triangles, 0);
    EXPECT_GE(r.stall_step, 0);
    EXPECT_EQ(r.alpha_steps, r.stall_step + 1);
    EXPECT_FALSE(r.converged);
  } else {
    EXPECT_TRUE(r.converged);
  }
  o.slim_angle_deg = 0.1;  // nothing is that slim on a sphere: the run is the usual one
  const auto plain = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  const auto r2 = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, o);
  EXPECT_FALSE(r2.slim_stall);
  EXPECT_EQ(r2.iterations, plain.iterations);
  EXPECT_EQ(r2.X, plain.X);
}

TEST(Deform, TorusConverges) {
  auto t = torus(1.0, 0.4, 32, 16);
  TetMesh tm = tet_mesh_of(t.V, t.F, 4000);
  auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_EQ(r.inverted, 0);
}

TEST(Deform, RotatedLBracketFindsItsFrame) {
  // The same L-shaped block under three random rotations ends as the same 8-chart polycube.
  MeshData l = examples::make("l_bracket", 0.08);
  const auto rotations = random_rotations(7, 3);
  for (int k = 0; k < 3; ++k) {
    MatX3d V = l.V * rotations[k].transpose();
    TetMesh tm = tet_mesh_of(V, l.F);
    auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
    EXPECT_LT(r.l1_quality, 1e-3) << "rotation " << k;
    EXPECT_EQ(count_charts(r.X, tm.boundary), 8) << "rotation " << k;
    EXPECT_LT(r.arap, 0.01) << "a rotated polycube needs almost no deformation";
  }
}

TEST(Deform, BestRotationAlignsARotatedBox) {
  auto b = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Vec3(1, 2, 0.5).normalized()).toRotationMatrix();
  MatX3d V = b.V * R.transpose();
  Eigen::Matrix3d Q = deform::best_rotation(V, b.F, 0.01);
  MatX3d W = V * Q.transpose();
  double l1, a;
  deform::l1_measure(W, b.F, l1, a);
  EXPECT_LT(l1 / a - 1, 1e-4);  // from 0.2 before the rotation
}

// The SQP system: solves on two threads (each with its own CHOLMOD workspace) give what one
// thread gives, and CG preconditioned by an older factorization reaches its tolerance.
TEST(SparseSystem, SolvesSideBySideMatchOneByOne) {
  TetMesh tm;
  auto system = sphere_system(2, 3000, tm);
  deform::SparseSystem& sys = *system;
  const int n = static_cast<int>(tm.V.rows());
  const deform::ArapRest rest = deform::ArapRest::build(tm.V, tm.T);
  sys.add_diagonal(1e-6);
  ASSERT_TRUE(sys.factorize());
  const auto [b0, b1] = random_pair(3 * n, 7);
  Eigen::VectorXd x0, x1;
  sys.solve_pair(b0, x0, b1, x1);
  const Eigen::VectorXd y0 = sys.solve(b0), y1 = sys.solve(b1);
  EXPECT_LE((x0 - y0).norm(), 1e-12 * y0.norm());
  EXPECT_LE((x1 - y1).norm(), 1e-12 * y1.norm());
  EXPECT_LE((sys.multiply(x0) - b0).norm(), 1e-8 * b0.norm());

  // New values (a stronger barrier), the old factorization as preconditioner.
  deform::volume_barrier_energy(tm.V, tm.T, rest, 0.5, nullptr, &sys);
  const auto its = sys.solve_pcg_pair(b0, x0, b1, x1, 1e-6, 200);
  EXPECT_GT(its[0], 1);  // the factorization is not of these values: CG has work to do
  EXPECT_GT(its[1], 1);
  // CG's test: the residual below 1e-6 of b in the 2-norm or in the preconditioner's energy norm.
  auto converged = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& b) {
    const Eigen::VectorXd r = b - sys.multiply(x);
    return r.norm() <= 1e-6 * b.norm() || r.dot(sys.precondition(r)) <= 1e-12 * b.dot(sys.precondition(b));
  };
  EXPECT_TRUE(converged(x0, b0));
  EXPECT_TRUE(converged(x1, b1));
  // One by one: the same solution to the CG tolerance (the BLAS may round differently with more
  // threads outside the pair, so not bit for bit).
  Eigen::VectorXd z0;
  EXPECT_GT(sys.solve_pcg(b0, z0, 1e-6, 200), 1);
  EXPECT_TRUE(converged(z0, b0));
  EXPECT_LE((z0 - x0).norm(), 1e-4 * x0.norm());
  // Against the exact solutions of the new values.
  ASSERT_TRUE(sys.factorize());
  const Eigen::VectorXd e0 = sys.solve(b0), e1 = sys.solve(b1);
  EXPECT_LE((x0 - e0).norm(), 1e-4 * e0.norm());
  EXPECT_LE((x1 - e1).norm(), 1e-4 * e1.norm());
}

// The cached value positions (tets, boundary triangles and boundary pairs, with the next
// element's values fetched ahead) add exactly what the index search adds, in the order given
// and out of it; a rank-1 Hessian added without forming it, exactly what the formed one adds.
TEST(SparseSystem, CachedAssemblyMatchesTheIndexSearchBitForBit) {
  const auto s = sphere(2);
  const TetMesh tm = tet_mesh_of(s.V, s.F, 3000);
  const MatX3i& F = tm.boundary;
  const std::vector<deform::FacePair> pairs = deform::face_pairs(F);
  std::vector<std::vector<int>> elements;
  for (int t = 0; t < tm.T.rows(); ++t) elements.push_back({tm.T(t, 0), tm.T(t, 1), tm.T(t, 2), tm.T(t, 3)});
  for (int f = 0; f < F.rows(); ++f) elements.push_back({F(f, 0), F(f, 1), F(f, 2)});
  for (const deform::FacePair& fp : pairs) elements.push_back({fp.a, fp.b, fp.c, fp.d});
  const int n = static_cast<int>(tm.V.rows());
  deform::SparseSystem searched(n, elements), cached(n, elements);
  cached.cache_elements(elements);
  // A deformed state (so that every term has a Hessian of its own), and the triangles reversed.
  MatX3d X = tm.V;
  for (int v = 0; v < n; ++v) X(v, 0) *= 1.0 + 0.2 * X(v, 1) * X(v, 1);
  const MatX3i Frev = F.colwise().reverse();
  const deform::ArapRest rest = deform::ArapRest::build(tm.V, tm.T);
  std::vector<double> side(cached.values().size(), 0.0), side_searched(side.size(), 0.0);
  deform::SparseSystem::Buffer buffer(cached, side), buffer_searched(searched, side_searched);
  for (deform::SparseSystem* sys : {&searched, &cached}) {
    deform::arap_energy(X, tm.T, rest, 1.0, nullptr, sys);
    deform::l1_energy(X, F, 0.05, 10.0, nullptr, sys);
    deform::barrier_energy(X, F, pairs, 0.01, nullptr, sys);
    deform::complexity_energy(X, F, pairs, 1.0, nullptr, sys);
    deform::l1_energy(X, Frev, 0.05, 3.0, nullptr, sys);  // out of order
  }
  deform::volume_barrier_energy(X, tm.T, rest, 0.1, nullptr, &buffer);
  deform::volume_barrier_energy(X, tm.T, rest, 0.1, nullptr, &buffer_searched);
  EXPECT_TRUE(searched.values() == cached.values());
  EXPECT_TRUE(side == side_searched);
  EXPECT_GT(*std::max_element(side.begin(), side.end()), 0.0);

  // A rank-1 element Hessian added without forming it (add_outer) rounds as Eigen's outer product.
  deform::SparseSystem outer(n, elements), formed(n, elements);
  outer.cache_elements(elements);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int t = 0; t < tm.T.rows(); t += 7) {
    const int v[4] = {tm.T(t, 0), tm.T(t, 1), tm.T(t, 2), tm.T(t, 3)};
    Eigen::Matrix<double, 12, 1> u;
    for (int i = 0; i < 12; ++i) u[i] = U(rng);
    const double c = 0.1 * U(rng) / 3.0;
    outer.add_outer(v, 4, c, u.data());
    formed.add(v, 4, Eigen::Matrix<double, 12, 12>(c * u * u.transpose()));
  }
  for (int f = 0; f < F.rows(); f += 5) {
    const int v[3] = {F(f, 0), F(f, 1), F(f, 2)};
    Eigen::Matrix<double, 9, 1> u;
    for (int i = 0; i < 9; ++i) u[i] = U(rng);
    const double c = U(rng) / 7.0;
    outer.add_outer(v, 3, c, u.data());
    formed.add(v, 3, Eigen::Matrix<double, 9, 9>(c * u * u.transpose()));
  }
  EXPECT_TRUE(outer.values() == formed.values());
}

// The preconditioner's single-precision copy of a supernodal factor solves the system to float
// accuracy, CG with it reaches a tight tolerance, and a simplicial factor falls back to CHOLMOD.
TEST(SparseSystem, FloatPreconditionerMatchesTheDoubleSolve) {
  TetMesh tm;
  auto system = sphere_system(3, 8000, tm);
  deform::SparseSystem& sys = *system;
  const int n = static_cast<int>(tm.V.rows());
  sys.add_diagonal(1e-3 * sys.mean_diagonal());
  ASSERT_TRUE(sys.factorize());
  ASSERT_TRUE(sys.factor_ptr()->is_super) << "CHOLMOD chose a simplicial factor: the test needs a larger mesh";
  deform::FloatFactor f;
  ASSERT_TRUE(f.assign(sys.factor_ptr()));
  std::mt19937 rng(11);
  std::normal_distribution<double> N01;
  Eigen::VectorXd b(3 * n);
  for (int i = 0; i < 3 * n; ++i) b[i] = N01(rng);
  const Eigen::VectorXd xd = sys.solve(b), xf = sys.precondition(b);
  EXPECT_GT((xf - xd).norm(), 0.0);  // float, not the double solve
  EXPECT_LE((xf - xd).norm(), 1e-4 * xd.norm());
  // Two right-hand sides at once, on two threads over their own subtrees: the same solutions to
  // float accuracy, and bit for bit the same from one call to the next.
  Eigen::VectorXd b2(3 * n);
  for (int i = 0; i < 3 * n; ++i) b2[i] = N01(rng);
  std::vector<float> work;
  Eigen::VectorXd y0(3 * n), y1(3 * n), z0(3 * n), z1(3 * n);
  f.solve2(b.data(), b2.data(), y0.data(), y1.data(), work);
  f.set_parallel_entries(0);  // two threads whatever the size
  f.solve2(b.data(), b2.data(), z0.data(), z1.data(), work);
  EXPECT_EQ((y0 - z0).norm(), 0.0);
  EXPECT_EQ((y1 - z1).norm(), 0.0);
  const Eigen::VectorXd xd2 = sys.solve(b2);
  EXPECT_LE((y0 - xd).norm(), 1e-4 * xd.norm());
  EXPECT_LE((y1 - xd2).norm(), 1e-4 * xd2.norm());
  Eigen::VectorXd x;
  const int its = sys.solve_pcg(b, x, 1e-10, 50);
  EXPECT_GT(its, 0);
  EXPECT_LE(its, 6);
  EXPECT_LE((sys.multiply(x) - b).norm(), 1e-10 * b.norm());

  // A tiny system gets a simplicial factor: no float copy, the preconditioner is the double solve.
  const int m = 8;
  std::vector<std::vector<int>> chain;
  for (int i = 0; i + 3 < m; ++i) chain.push_back({i, i + 1, i + 2, i + 3});
  deform::SparseSystem small(m, chain);
  Eigen::Matrix<double, 12, 12> K = Eigen::Matrix<double, 12, 12>::Identity();
  for (const auto& e : chain) small.add(e.data(), 4, K);
  ASSERT_TRUE(small.factorize());
  EXPECT_FALSE(f.assign(small.factor_ptr()));
  EXPECT_TRUE(f.empty());
  const Eigen::VectorXd c = Eigen::VectorXd::LinSpaced(3 * m, 1, 2);
  EXPECT_EQ((small.precondition(c) - small.solve(c)).norm(), 0.0);
}

// DeformOptions::float_factorization: on a mesh whose factor is supernodal the deformation
// factorizes in float and converges as with CHOLMOD's double factorizations (off, the default).
TEST(Deform, FloatFactorizationConvergesAsTheDoubleOne) {
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 8000);
  deform::DeformOptions on, off;
  on.float_factorization = true;
  const auto a = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, on);
  const auto b = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, off);
  EXPECT_GT(a.float_factorizations, 0);
  EXPECT_EQ(b.float_factorizations, 0);
  for (const auto* r : {&a, &b}) {
    EXPECT_TRUE(r->converged);
    EXPECT_LT(r->l1_quality, 1e-3);
    EXPECT_EQ(r->inverted, 0);
  }
  EXPECT_NEAR(a.arap, b.arap, 0.05 * b.arap);
}

// The float supernodal factorization (SparseSystem::set_float_factorization): its solves match the
// double factorization's to float accuracy, the same bits from one factorization to the next, the
// SQP's pair of solves refined by CG on it; a matrix that is not positive definite fails in float
// (after the shifted tries) and in double alike.
TEST(SparseSystem, FloatFactorizationMatchesTheDoubleOne) {
  TetMesh tm, tm2;
  auto dsys = sphere_system(3, 8000, tm);
  auto fsys = sphere_system(3, 8000, tm2);
  ASSERT_EQ(tm.T.rows(), tm2.T.rows());
  ASSERT_TRUE(dsys->values() == fsys->values());
  dsys->add_diagonal(1e-3 * dsys->mean_diagonal());
  fsys->add_diagonal(1e-3 * fsys->mean_diagonal());
  fsys->set_float_factorization(true);
  ASSERT_TRUE(dsys->factorize());
  ASSERT_TRUE(dsys->factor_ptr()->is_super) << "CHOLMOD chose a simplicial factor: the test needs a larger mesh";
  ASSERT_TRUE(fsys->factorize());
  EXPECT_EQ(fsys->float_factorizations(), 1);
  EXPECT_EQ(fsys->float_breakdowns(), 0);
  const int n = static_cast<int>(tm.V.rows());
  const auto [b, b2] = random_pair(3 * n, 5);
  const Eigen::VectorXd xd = dsys->solve(b), xd2 = dsys->solve(b2);
  const Eigen::VectorXd xf = fsys->precondition(b);
  EXPECT_GT((xf - xd).norm(), 0.0);  // float arithmetic, not a copy of the double factor
  EXPECT_LE((xf - xd).norm(), 1e-4 * xd.norm());
  ASSERT_TRUE(fsys->factorize());
  EXPECT_EQ((fsys->precondition(b) - xf).norm(), 0.0);
  Eigen::VectorXd x0, x1;
  fsys->solve_pair(b, x0, b2, x1);
  EXPECT_LE((x0 - xd).norm(), 1e-4 * xd.norm());
  EXPECT_LE((x1 - xd2).norm(), 1e-4 * xd2.norm());
  EXPECT_GT(fsys->refinement_iterations(), 0);
  // The subtrees on two threads (the top part after them): the same solution to float accuracy,
  // and the same bits from one factorization to the next.
  fsys->set_float_parallel_entries(0);
  ASSERT_TRUE(fsys->factorize());
  const Eigen::VectorXd xp = fsys->precondition(b);
  EXPECT_LE((xp - xd).norm(), 1e-4 * xd.norm());
  ASSERT_TRUE(fsys->factorize());
  EXPECT_EQ((fsys->precondition(b) - xp).norm(), 0.0);
  // Not positive definite: the float factorization breaks down, and so does the double one made
  // then; the next factorizations are in double.
  const double mean = fsys->mean_diagonal();
  fsys->add_diagonal(-10 * mean);
  EXPECT_FALSE(fsys->factorize());
  EXPECT_EQ(fsys->float_breakdowns(), 1);
  const int in_float = fsys->float_factorizations();
  fsys->add_diagonal(20 * mean);
  ASSERT_TRUE(fsys->factorize());
  EXPECT_EQ(fsys->float_factorizations(), in_float);
  EXPECT_EQ(fsys->solve(b).size(), b.size());
}

// DeformOptions::locality_order: the solver works on renumbered interior vertices and sorted tets,
// and gives the result back in the input's numbering (a wrong mapping would scramble the boundary).
TEST(Deform, LocalityOrderGivesTheResultInTheInputNumbering) {
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 5000);
  deform::DeformOptions opt;
  opt.locality_order = true;
  const auto r = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, opt);
  EXPECT_LT(r.l1_quality, 1e-3);
  EXPECT_EQ(r.inverted, 0);
  // Measured again here on the input's numbering: the boundary is a polycube, no tet inverted.
  double l1 = 0, l2 = 0;
  for (int f = 0; f < tm.boundary.rows(); ++f) {
    const Vec3 a = r.X.row(tm.boundary(f, 0)), b = r.X.row(tm.boundary(f, 1)), c = r.X.row(tm.boundary(f, 2));
    const Vec3 N = (b - a).cross(c - a);
    l1 += N.cwiseAbs().sum();
    l2 += N.norm();
  }
  EXPECT_LT(l1 / l2 - 1, 1e-3);
  for (int t = 0; t < tm.T.rows(); ++t) {
    const Vec3 p0 = r.X.row(tm.T(t, 0)), p1 = r.X.row(tm.T(t, 1)), p2 = r.X.row(tm.T(t, 2)), p3 = r.X.row(tm.T(t, 3));
    ASSERT_GT((p1 - p0).dot((p2 - p0).cross(p3 - p0)), 0) << "tet " << t;
  }
  // The interior was renumbered: the run is not the default one to the last digit, but alike.
  const auto d = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_GT((r.X - d.X).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_NEAR(r.arap, d.arap, 0.2 * d.arap);
}

TEST(Deform, TwoRunsGiveTheSameResultBitForBit) {
  // Reproducibility with the threads of the solver (solves side by side, ARAP gradient on its own
  // thread above 4000 tets): nothing may depend on which thread finishes first.
  auto s = sphere(3);
  TetMesh tm = tet_mesh_of(s.V, s.F, 5000);
  ASSERT_GE(tm.T.rows(), 4000);
  const auto a = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  const auto b = deform::deform_to_polycube(tm.V, tm.T, tm.boundary, {});
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.factorizations, b.factorizations);
  EXPECT_EQ((a.X - b.X).cwiseAbs().maxCoeff(), 0.0);
}
