// Hex stage: scaled Jacobian, Hausdorff distance, point location, snapping and extraction on
// shapes with known answers.
#include <random>
#include <set>

#include "polycube/chart/labeling.h"
#include "polycube/core/error.h"
#include "polycube/core/topology.h"
#include "polycube/geometry/closest_point.h"
#include "polycube/examples/examples.h"
#include "polycube/geometry/tet_locator.h"
#include "polycube/hex/extract.h"
#include "polycube/hex/grading.h"
#include "polycube/hex/quality.h"
#include "polycube/hex/optimize.h"
#include "polycube/hex/snap.h"
#include "polycube/hex/untangle.h"
#include "test_util.h"

using namespace polycube;
using namespace polycube::test;

namespace {

std::array<Vec3, 8> unit_hex() {
  return {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0),
          Vec3(0, 0, 1), Vec3(1, 0, 1), Vec3(1, 1, 1), Vec3(0, 1, 1)};
}

// Hex mesh of an exact polycube given as a tet mesh: the polycube map is the identity.
hex::HexResult hexes_of_polycube(const SurfaceMesh& s, const hex::HexOptions& o) {
  const TetMesh tm = tet_mesh_of(s.V, s.F);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  return hex::hex_mesh_from_polycube(tm.V, tm.T, tm.V, tm.boundary, labels, &s, o);
}

// Options for comparing grids: s cells per unit, no pillow layer, the paper's uniform grid.
hex::HexOptions plain_grid(double s) {
  hex::HexOptions o;
  o.cells_per_unit = s;
  o.pillow = "off";
  o.grading.strength = 0;
  return o;
}

// Two-sided Hausdorff distance between a hex mesh's boundary and the target.
double boundary_distance(const hex::HexResult& r, const SurfaceMesh& target) {
  return hex::hausdorff(r.V, hex::triangulate_quads(hex::boundary_quads(r.H)), target.V, target.F, 50000).max;
}

}  // namespace

TEST(Hex, ScaledJacobianKnownValues) {
  auto p = unit_hex();
  EXPECT_NEAR(hex::scaled_jacobian(p), 1.0, 1e-15);
  // A rectangular box: still 1 (the measure ignores edge-length ratios).
  for (auto& x : p) x = Vec3(3 * x.x(), 0.5 * x.y(), 7 * x.z());
  EXPECT_NEAR(hex::scaled_jacobian(p), 1.0, 1e-15);
  // Sheared: the top face moved by a along x; every corner and the centre give 1/sqrt(1+a^2).
  for (double a : {0.3, 1.0, 2.5}) {
    p = unit_hex();
    for (int i = 4; i < 8; ++i) p[i].x() += a;
    EXPECT_NEAR(hex::scaled_jacobian(p), 1 / std::sqrt(1 + a * a), 1e-14) << a;
  }
  // Inverted (top and bottom swapped): -1. Degenerate (collapsed edge): 0.
  p = unit_hex();
  std::array<Vec3, 8> q = {p[4], p[5], p[6], p[7], p[0], p[1], p[2], p[3]};
  EXPECT_NEAR(hex::scaled_jacobian(q), -1.0, 1e-15);
  p[1] = p[0];
  EXPECT_EQ(hex::scaled_jacobian(p), 0.0);
  // One corner pushed inside: negative at that corner only.
  p = unit_hex();
  p[6] = Vec3(0.2, 0.2, 0.2);
  const auto s = hex::scaled_jacobian_samples(p);
  EXPECT_LT(s[6], 0);
  EXPECT_GT(s[0], 0);
  EXPECT_EQ(hex::scaled_jacobian(p), *std::min_element(s.begin(), s.end()));
}

TEST(Hex, ScaledJacobianSamplesAloneAndTheirDependents) {
  // Each sample alone has the bits of the full set, and moving corner j changes exactly the
  // samples scaled_jacobian_dependents(j) names: corner j, its three edge neighbours, the centre.
  std::array<Vec3, 8> p = unit_hex();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  for (auto& x : p) x += Vec3(u(rng), u(rng), u(rng));
  const auto all = hex::scaled_jacobian_samples(p);
  for (int k = 0; k < 9; ++k) EXPECT_EQ(hex::scaled_jacobian_sample(p, k), all[k]);
  for (int j = 0; j < 8; ++j) {
    const unsigned dep = hex::scaled_jacobian_dependents(j);
    EXPECT_EQ(__builtin_popcount(dep), 5) << "corner " << j;
    auto q = p;
    q[j] += Vec3(0.05, -0.03, 0.04);
    const auto moved = hex::scaled_jacobian_samples(q);
    for (int k = 0; k < 9; ++k) {
      if (dep >> k & 1u)
        EXPECT_NE(moved[k], all[k]) << "corner " << j << ", sample " << k;
      else
        EXPECT_EQ(moved[k], all[k]) << "corner " << j << ", sample " << k;
    }
  }
}

TEST(Hex, ScaledJacobianSampleGradientMatchesFiniteDifferences) {
  // Against central differences of each sample with respect to each corner, on a distorted hex
  // and on a nearly flat one; the value has the bits of scaled_jacobian_sample.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  for (int shape = 0; shape < 2; ++shape) {
    std::array<Vec3, 8> p = unit_hex();
    for (auto& x : p) x += Vec3(u(rng), u(rng), u(rng));
    if (shape == 1)
      for (int i = 4; i < 8; ++i) p[i].z() = p[i - 4].z() + 0.02 + 0.01 * i;  // thin in z
    for (int j = 0; j < 8; ++j) {
      const unsigned dep = hex::scaled_jacobian_dependents(j);
      for (int k = 0; k < 9; ++k) {
        Vec3 g;
        const double f = hex::scaled_jacobian_sample_gradient(p, k, j, g);
        EXPECT_EQ(f, hex::scaled_jacobian_sample(p, k));
        if (!(dep >> k & 1u)) {
          EXPECT_EQ(g.norm(), 0.0) << "corner " << j << ", sample " << k;
          continue;
        }
        const double h = 1e-6;
        for (int d = 0; d < 3; ++d) {
          auto a = p, b = p;
          a[j][d] += h;
          b[j][d] -= h;
          const double fd = (hex::scaled_jacobian_sample(a, k) - hex::scaled_jacobian_sample(b, k)) / (2 * h);
          EXPECT_NEAR(g[d], fd, 1e-6 * std::max(1.0, std::abs(fd))) << "shape " << shape << ", corner " << j
                                                                      << ", sample " << k << ", axis " << d;
        }
      }
    }
  }
}

TEST(Hex, QualityStatisticsAndHistogram) {
  MatX3d V(12, 3);
  MatX8i H(2, 8);
  const auto u = unit_hex();
  for (int i = 0; i < 8; ++i) V.row(i) = u[i].transpose();
  for (int i = 0; i < 4; ++i) V.row(8 + i) = (u[4 + i] + Vec3(1, 0, 1)).transpose();  // sheared top, a = 1
  H << 0, 1, 2, 3, 4, 5, 6, 7, 4, 5, 6, 7, 8, 9, 10, 11;
  const hex::HexQuality q = hex::hex_quality(V, H);
  EXPECT_EQ(q.count, 2);
  EXPECT_NEAR(q.sj_max, 1.0, 1e-15);
  EXPECT_NEAR(q.sj_min, 1 / std::sqrt(2.0), 1e-14);
  EXPECT_NEAR(q.sj_mean, (1 + 1 / std::sqrt(2.0)) / 2, 1e-14);
  EXPECT_EQ(q.inverted, 0);
  EXPECT_EQ(q.below_0_5, 0);
  EXPECT_EQ(q.histogram[19], 1);  // [0.9, 1]
  EXPECT_EQ(q.histogram[17], 1);  // 0.707 in [0.7, 0.8)
}

TEST(Hex, BoundaryQuadsAreOutward) {
  // Two hexes side by side: 10 boundary quads, each facing away from the block's centre.
  MatX3d V(12, 3);
  for (int i = 0; i < 12; ++i) V.row(i) << i % 3, (i / 3) % 2, i / 6;
  auto id = [](int x, int y, int z) { return x + 3 * y + 6 * z; };
  MatX8i H(2, 8);
  for (int h = 0; h < 2; ++h)
    H.row(h) << id(h, 0, 0), id(h + 1, 0, 0), id(h + 1, 1, 0), id(h, 1, 0), id(h, 0, 1), id(h + 1, 0, 1),
        id(h + 1, 1, 1), id(h, 1, 1);
  const MatX4i Q = hex::boundary_quads(H);
  ASSERT_EQ(Q.rows(), 10);
  const Vec3 centre(1, 0.5, 0.5);
  for (int q = 0; q < Q.rows(); ++q) {
    const Vec3 a = V.row(Q(q, 0)), b = V.row(Q(q, 1)), c = V.row(Q(q, 2)), d = V.row(Q(q, 3));
    EXPECT_GT((c - a).cross(d - b).dot((a + b + c + d) / 4 - centre), 0) << q;
  }
  EXPECT_EQ(hex::triangulate_quads(Q).rows(), 20);
}

TEST(Hex, HausdorffKnownDistances) {
  // Unit square vs the same square lifted by 0.25: 0.25 both ways.
  MatX3d A(4, 3), B(4, 3), C(4, 3);
  A << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  B = A;
  B.col(2).setConstant(0.25);
  MatX3i F(2, 3);
  F << 0, 1, 2, 0, 2, 3;
  hex::Hausdorff h = hex::hausdorff(A, F, B, F, 1000);
  EXPECT_NEAR(h.a_to_b, 0.25, 1e-12);
  EXPECT_NEAR(h.b_to_a, 0.25, 1e-12);
  // Unit square vs its left half: 0.5 one way (the far edge), 0 the other.
  C = A;
  C(1, 0) = C(2, 0) = 0.5;
  h = hex::hausdorff(A, F, C, F, 1000);
  EXPECT_NEAR(h.a_to_b, 0.5, 1e-12);
  EXPECT_NEAR(h.b_to_a, 0.0, 1e-12);
  EXPECT_NEAR(h.max, 0.5, 1e-12);
  EXPECT_NEAR(h.a_to_b_at.x(), 1.0, 1e-12);  // reached on the far edge x = 1
  // Area-weighted like M.E.S.H.: from the unit square to its left half the distance is max(0, x - 1/2),
  // mean 1/8 and RMS sqrt(1/24) over the square (the vertices, two of them at 0.5, weigh nothing).
  EXPECT_NEAR(h.mean_a_to_b, 0.125, 2e-3);
  EXPECT_NEAR(h.rms_a_to_b, std::sqrt(1.0 / 24), 2e-3);
  EXPECT_NEAR(h.mean_b_to_a, 0.0, 1e-12);
  EXPECT_NEAR(h.rms_b_to_a, 0.0, 1e-12);
  // The lifted square: 0.25 everywhere, both ways.
  h = hex::hausdorff(A, F, B, F, 1000);
  EXPECT_NEAR(h.mean_a_to_b, 0.25, 1e-12);
  EXPECT_NEAR(h.rms_b_to_a, 0.25, 1e-12);
}

TEST(Hex, TetLocatorFindsTheContainingTet) {
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  const TetMesh tm = tet_mesh_of(s.V, s.F, 2000);
  const geometry::TetLocator loc(tm.V, tm.T);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 500; ++i) {
    const Vec3 p(u(rng), 2 * u(rng), 3 * u(rng));
    const geometry::TetHit h = loc.locate(p);
    ASSERT_GE(h.tet, 0);
    EXPECT_GE(h.min_bary, -1e-12);
    Vec3 q = Vec3::Zero();
    for (int j = 0; j < 4; ++j) q += h.bary[j] * tm.V.row(tm.T(h.tet, j)).transpose();
    EXPECT_NEAR((q - p).norm(), 0, 1e-12);
  }
  // Outside: found, with a negative min barycentric coordinate.
  EXPECT_LT(loc.locate(Vec3(1.5, 1, 1)).min_bary, -1e-3);
  // Two boxes far apart: a point halfway has no tet within the three rings of buckets searched
  // around it, and still gets one (the nearest by barycentric coordinates, in either box). (Their
  // surfaces are fine grids: the box above has a few dozen tets, and buckets of a third of the
  // whole extent.)
  const SurfaceMesh g = grid_box(8, Vec3(0, 0, 0), Vec3(1, 2, 3));
  const TetMesh fine = tet_mesh_of(g.V, g.F, 2000);
  ASSERT_GT(fine.T.rows(), 1000);
  MatX3d V2(2 * fine.V.rows(), 3);
  V2 << fine.V, (fine.V.rowwise() + Eigen::RowVector3d(20, 20, 20));
  MatX4i T2(2 * fine.T.rows(), 4);
  T2 << fine.T, (fine.T.array() + static_cast<int>(fine.V.rows())).matrix();
  const geometry::TetLocator loc2(V2, T2);
  const geometry::TetHit far = loc2.locate(Vec3(10.5, 11, 11.5));
  EXPECT_GE(far.tet, 0);
  EXPECT_LT(far.min_bary, -1);
  // Asked only whether it is inside (search_all false): no tet, without the scan of all of them;
  // points inside or near a box are found as before.
  EXPECT_EQ(loc2.locate(Vec3(10.5, 11, 11.5), false).tet, -1);
  for (const Vec3& p : {Vec3(0.5, 1, 1.5), Vec3(20.5, 21, 21.5), Vec3(1.05, 1, 1)}) {
    const geometry::TetHit a = loc2.locate(p), b = loc2.locate(p, false);
    EXPECT_EQ(a.tet, b.tet);
    EXPECT_EQ(a.min_bary, b.min_bary);
  }
  // Non-finite coordinates (a snapped polycube gone wrong) are refused, not bucketed out of range.
  MatX3d bad = tm.V;
  bad(3, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(geometry::TetLocator(bad, tm.T), Error);
}

TEST(Hex, SnappingKeepsPlanesApartAndInOrder) {
  // Two planes 0.01 apart keep one cell between them; the others round to the nearest integer.
  const auto n = hex::snap_heights({0.0, 0.01, 1.0, 1.02, 2.26}, 10);
  EXPECT_EQ(n, (std::vector<int>{0, 1, 10, 11, 23}));
  const auto m = hex::snap_heights({-1.0, 0.5}, 3);
  EXPECT_EQ(m, (std::vector<int>{0, 5}));
}

TEST(Hex, ConstrainedSnappingMergesOnlyPlanesThatDoNotFaceEachOther) {
  // Plane 1 is 0.01 above plane 0: merged unless they face each other.
  EXPECT_EQ(hex::snap_heights({0.0, 0.01, 1.0}, 10, {{}, {}, {}}), (std::vector<int>{0, 0, 10}));
  EXPECT_EQ(hex::snap_heights({0.0, 0.01, 1.0}, 10, {{1}, {}, {}}), (std::vector<int>{0, 1, 10}));
  EXPECT_EQ(hex::snap_heights({0.0, 0.01, 1.0}, 10, {{1}, {2}, {}}), (std::vector<int>{0, 1, 10}));
  // Two separate boxes whose tops are 0.01 apart: the tops share an integer; the plain sorted
  // snapping would put a cell between them. Every plane vertex lands on its integer, no tet inverts.
  const SurfaceMesh two = merge(box(Vec3(0, 0, 0), Vec3(1, 1, 1)), box(Vec3(2, 0, 0), Vec3(3, 1, 1.01)));
  const TetMesh tm = tet_mesh_of(two.V, two.F, 3000);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  const hex::Snapping c = hex::snap_polycube(tm.V, tm.T, tm.boundary, labels, 4, true);
  ASSERT_EQ(c.heights[2].size(), 3u);
  EXPECT_EQ(c.snapped[2], (std::vector<int>{0, 4, 4}));
  EXPECT_EQ(c.shared[2], 2);
  EXPECT_EQ(c.inverted, 0);
  for (int v = 0; v < tm.V.rows(); ++v) {
    if (tm.V(v, 2) > 0.99) {
      EXPECT_EQ(c.Y(v, 2), 4.0);
    }
  }
  const hex::Snapping p = hex::snap_polycube(tm.V, tm.T, tm.boundary, labels, 4, false);
  EXPECT_EQ(p.snapped[2], (std::vector<int>{0, 4, 5}));
  // Through the volume (x: 0 | 1, 2 | 3) planes keep their order and distance.
  EXPECT_EQ(c.snapped[0], (std::vector<int>{0, 4, 8, 12}));
}

namespace {
// The l_bracket example's tet mesh, and its vertices with the upright leg (z > 0.5) squashed to a
// hundredth of its height: a step of 0.015 above the foot.
TetMesh l_bracket_tets() {
  const MeshData l = examples::make("l_bracket", 0.1);
  return tet_mesh_of(l.V, l.F);
}
MatX3d squash_leg(const MatX3d& V) {
  MatX3d X = V;
  for (int v = 0; v < X.rows(); ++v)
    if (X(v, 2) > 0.5) X(v, 2) = 0.5 + 0.01 * (X(v, 2) - 0.5);
  return X;
}
}  // namespace

TEST(Hex, AThinStepLosesItsRiserInsteadOfGettingASquashedLayerOfHexes) {
  // The l_bracket with its upright leg squashed to 0.015 above the foot: a step of 0.06 cell at 4
  // cells per unit between the foot's top (z = 0.5) and the leg's (z = 0.515). The two planes face
  // no common line, so they may share an integer; kept a cell apart, the layer of hexes above the
  // foot would be squeezed into the 0.06-cell step.
  const TetMesh tm = l_bracket_tets();
  const MatX3d X = squash_leg(tm.V);
  ASSERT_EQ(measure_tets(X, tm.T).inverted, 0);
  ASSERT_EQ(measure_tets(X, tm.T).zero_volume, 0);
  const std::vector<int> labels = chart::label_by_normal(X, tm.boundary);
  const hex::Snapping merged = hex::snap_polycube(X, tm.T, tm.boundary, labels, 4, true, 0.25);
  ASSERT_EQ(merged.heights[2].size(), 3u);
  EXPECT_EQ(merged.snapped[2], (std::vector<int>{0, 2, 2}));
  EXPECT_EQ(merged.merged[2], 1);
  EXPECT_EQ(merged.merged[0] + merged.merged[1], 0);
  const hex::Snapping kept = hex::snap_polycube(X, tm.T, tm.boundary, labels, 4, true, 0.0);
  EXPECT_EQ(kept.snapped[2], (std::vector<int>{0, 2, 3}));
  EXPECT_NEAR(kept.min_slab_ratio, 0.06, 1e-9);
  // Stretching the step to a cell, the harmonic displacement turns tets over next to it; the local
  // untangling (planes kept at their integers) repairs every one.
  EXPECT_GT(kept.untangled, 0);
  EXPECT_EQ(kept.inverted, 0);
  for (int v = 0; v < X.rows(); ++v)
    if (std::abs(X(v, 2) - 0.515) < 1e-12) {
      EXPECT_EQ(kept.Y(v, 2), 3.0);
    }
  // Merged, the riser's tets are flat (zero volume), none turned over.
  EXPECT_LT(merged.inverted_volume, 1e-6);  // in cells
  // The hex mesh of that polycube (the map is the identity, the squashed shape the target).
  const SurfaceMesh target{X, tm.boundary};
  hex::HexOptions o;
  o.cells_per_unit = 4;
  o.pillow = "off";
  o.merge_thin_steps = 0.25;
  const hex::HexResult r = hex::hex_mesh_from_polycube(X, tm.T, X, tm.boundary, labels, &target, o);
  // Shortest hex edge (cells are 0.25 long; the scaled Jacobian does not see flat boxes).
  auto shortest_edge = [](const hex::HexResult& h) {
    static constexpr int e[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                     {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
    double m = 1e300;
    for (int c = 0; c < h.H.rows(); ++c)
      for (const auto& ab : e) m = std::min(m, (h.V.row(h.H(c, ab[0])) - h.V.row(h.H(c, ab[1]))).norm());
    return m;
  };
  EXPECT_EQ(r.merged_planes, 1);
  EXPECT_EQ(r.cells[2], 2);
  EXPECT_EQ(r.quality.inverted, 0);
  EXPECT_GT(r.quality.sj_min, 0.3);
  EXPECT_GT(shortest_edge(r), 0.1);
  o.merge_thin_steps = 0;
  const hex::HexResult q = hex::hex_mesh_from_polycube(X, tm.T, X, tm.boundary, labels, &target, o);
  EXPECT_EQ(q.merged_planes, 0);
  EXPECT_EQ(q.cells[2], 3);
  EXPECT_LT(shortest_edge(q), 0.02);
}

TEST(Hex, ThinStepRetriesMergeThickerStepsAndKeepTheBetterResult) {
  // The squashed l_bracket of the test above (a step of 0.06 cell), every step kept a cell apart.
  const TetMesh tm = l_bracket_tets();
  const MatX3d X = squash_leg(tm.V);
  const std::vector<int> labels = chart::label_by_normal(X, tm.boundary);
  const SurfaceMesh target{X, tm.boundary};
  hex::HexOptions o;
  o.cells_per_unit = 4;
  o.pillow = "off";
  o.merge_thin_steps = 0;
  const hex::HexResult kept = hex::hex_mesh_from_polycube(X, tm.T, X, tm.boundary, labels, &target, o);
  ASSERT_EQ(kept.quality.inverted, 0);
  ASSERT_NEAR(kept.min_slab_ratio, 0.06, 1e-9);
  // Its worst hex is above the default floor (0.3): no retry, the same mesh.
  ASSERT_GT(kept.quality.sj_min, o.thin_step_retry_below);
  std::vector<hex::ThinStepRetry> retries;
  double used = -1;
  hex::HexResult r = hex::hex_mesh_thin_step_retries(X, tm.T, X, tm.boundary, labels, &target, o, &retries, &used);
  EXPECT_TRUE(retries.empty());
  EXPECT_EQ(used, 0.0);
  EXPECT_EQ(r.quality.count, kept.quality.count);
  EXPECT_EQ(r.quality.sj_min, kept.quality.sj_min);
  // With a floor above every hex: the 0.05 retry is skipped (the slab is 0.06 cell), the 0.25 one
  // runs (the step's planes merged: 2 cells in z instead of 3) and is kept only if its worst hex
  // is higher by 0.05; either way the result is the better of the two.
  o.thin_step_retry_below = 1.01;
  hex::HexOptions m = o;
  m.merge_thin_steps = 0.25;
  const hex::HexResult merged = hex::hex_mesh_from_polycube(X, tm.T, X, tm.boundary, labels, &target, m);
  ASSERT_EQ(merged.cells[2], 2);
  r = hex::hex_mesh_thin_step_retries(X, tm.T, X, tm.boundary, labels, &target, o, &retries, &used);
  ASSERT_EQ(retries.size(), 1u);
  EXPECT_EQ(retries[0].thin_steps, 0.0);
  EXPECT_EQ(retries[0].sj_min, kept.quality.sj_min);
  const bool better = merged.quality.sj_min > kept.quality.sj_min + 0.05;
  EXPECT_EQ(retries[0].replaced, better);
  EXPECT_EQ(used, better ? 0.25 : 0.0);
  EXPECT_EQ(r.cells[2], better ? 2 : 3);
  EXPECT_EQ(r.quality.sj_min, std::max(kept.quality.sj_min, better ? merged.quality.sj_min : 0.0));
}

TEST(Hex, AnOverlappingPolycubeIsRefused) {
  // Two boxes, each a valid polycube, moved so that they overlap: every tet is positive, yet a line
  // along z meets two bottoms in a row. Snapping counts such lines and extraction refuses.
  const SurfaceMesh two = merge(box(Vec3(0, 0, 0), Vec3(1, 1, 1)), box(Vec3(3, 0, 0), Vec3(4, 1, 1)));
  const TetMesh tm = tet_mesh_of(two.V, two.F, 2000);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  MatX3d X = tm.V;
  for (int v = 0; v < X.rows(); ++v)
    if (X(v, 0) > 2) X.row(v) += Vec3(-2.5, 0, 0.3).transpose();  // second box now [0.5,1.5]x[0,1]x[0.3,1.3]
  const hex::Snapping sn = hex::snap_polycube(X, tm.T, tm.boundary, labels, 4, true);
  EXPECT_GT(sn.overlap_lines[2], 0);
  EXPECT_GT(sn.overlap_lines[0], 0);
  const hex::Snapping ok = hex::snap_polycube(tm.V, tm.T, tm.boundary, labels, 4, true);
  EXPECT_EQ(ok.overlap_lines, (std::array<int, 3>{0, 0, 0}));
  try {
    hex::hex_mesh_from_polycube(tm.V, tm.T, X, tm.boundary, labels, &two);
    FAIL() << "an overlapping polycube was meshed";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Polycube);
    EXPECT_NE(std::string(e.what()).find("overlaps itself"), std::string::npos) << e.what();
  }
}

TEST(Hex, BoxGivesTheExactGrid) {
  // A 1 x 2 x 3 box at 4 cells per unit: 4 x 8 x 12 hexes, every scaled Jacobian 1, the vertices
  // on the grid (the polycube map is the identity), pillowing not chosen by "auto".
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  hex::HexOptions o;
  o.target_hexes = 96 * 4;  // volume 6 -> 64 per unit volume -> 4 cells per unit
  const hex::HexResult r = hexes_of_polycube(s, o);
  EXPECT_NEAR(r.cells_per_unit, 4.0, 1e-9);
  EXPECT_EQ(r.cells, (std::array<int, 3>{4, 8, 12}));
  ASSERT_EQ(r.H.rows(), 4 * 8 * 12);
  EXPECT_EQ(r.V.rows(), 5 * 9 * 13);
  EXPECT_EQ(r.pillow_hexes, 0);
  EXPECT_EQ(r.quality.inverted, 0);
  EXPECT_NEAR(r.quality.sj_min, 1.0, 1e-9);
  for (int v = 0; v < r.V.rows(); ++v)
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(r.V(v, k), r.grid(v, k) / 4.0, 1e-9);
  // No repeated vertex inside a hex; every vertex used.
  std::vector<int> used(r.V.rows(), 0);
  for (int h = 0; h < r.H.rows(); ++h) {
    std::set<int> ids(r.H.row(h).data(), r.H.row(h).data() + 8);
    EXPECT_EQ(ids.size(), 8u);
    for (int i : ids) used[i] = 1;
  }
  EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0);
}

TEST(Hex, LBlockGivesTheExpectedCount) {
  // The l_bracket example: [0,2]x[0,1]x[0,0.5] united with [0,0.5]x[0,1]x[0,2], volume 1.75;
  // at 4 cells per unit: 112 hexes, all perfect.
  const MeshData l = examples::make("l_bracket", 0.1);
  hex::HexOptions o;
  o.target_hexes = 112;
  const hex::HexResult r = hexes_of_polycube({l.V, l.F}, o);
  EXPECT_EQ(r.heights[0].size(), 3u);
  EXPECT_EQ(r.snapped[0], (std::vector<int>{0, 2, 8}));
  EXPECT_EQ(r.H.rows(), 112);
  EXPECT_EQ(r.quality.inverted, 0);
  EXPECT_NEAR(r.quality.sj_min, 1.0, 1e-9);
}

TEST(Hex, PillowedBoxHasOneLayerMoreAndNoInvertedHex) {
  const SurfaceMesh s = box(Vec3(0, 0, 0), Vec3(1, 2, 3));
  hex::HexOptions o;
  o.target_hexes = 96 * 4;
  o.pillow = "on";
  const hex::HexResult r = hexes_of_polycube(s, o);
  const int boundary = 2 * (4 * 8 + 8 * 12 + 4 * 12);
  EXPECT_EQ(r.pillow_hexes, boundary);
  EXPECT_EQ(r.H.rows(), 4 * 8 * 12 + boundary);
  EXPECT_EQ(r.quality.inverted, 0);
  // Hexes along the sharp edges of a pillowed box are sheared: about 0.7 at best.
  EXPECT_GT(r.quality.sj_min, 0.4);
  // The boundary stays on the box.
  const MatX3i F = hex::triangulate_quads(hex::boundary_quads(r.H));
  EXPECT_LT(hex::hausdorff(r.V, F, s.V, s.F, 20000).max, 1e-9);
}

namespace {
// n x n x n unit hexes; vertex (i, j, k) has id i + (n + 1) (j + (n + 1) k).
void hex_grid(int n, MatX3d& V, MatX8i& H) {
  const int m = n + 1;
  V.resize(m * m * m, 3);
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) V.row(i + m * (j + m * k)) << i, j, k;
  H.resize(n * n * n, 8);
  int h = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i, ++h) {
        const int o = i + m * (j + m * k);
        H.row(h) << o, o + 1, o + 1 + m, o + m, o + m * m, o + 1 + m * m, o + 1 + m + m * m, o + m + m * m;
      }
}
}  // namespace

TEST(Hex, CornerTetsArePositiveExactlyWhereTheHexCornersAre) {
  MatX3d V;
  MatX8i H;
  hex_grid(1, V, H);
  const MatX4i T = hex::hex_corner_tets(H);
  ASSERT_EQ(T.rows(), 8);
  EXPECT_EQ(hex::inverted_hex_corners(V, H), 0);
  for (int j = 0; j < 8; ++j) {
    const Vec3 o = V.row(T(j, 0)).transpose();
    EXPECT_NEAR((V.row(T(j, 1)).transpose() - o).dot((V.row(T(j, 2)).transpose() - o).cross(V.row(T(j, 3)).transpose() - o)),
                1.0, 1e-12);
  }
  // Vertex 6 pushed through the opposite corner: corner 6 and the three next to it turn over.
  V.row(H(0, 6)) << -0.5, -0.5, -0.5;
  EXPECT_EQ(hex::inverted_hex_corners(V, H), 4);
  std::array<Vec3, 8> p;
  for (int i = 0; i < 8; ++i) p[i] = V.row(H(0, i)).transpose();
  const std::array<double, 9> sj = hex::scaled_jacobian_samples(p);
  for (int j = 0; j < 8; ++j) EXPECT_EQ(sj[j] > 0, j != 6 && j != 2 && j != 5 && j != 7) << j;
}

TEST(Hex, FoldedInteriorIsUntangledWhereTheLocalOptimizationStops) {
  // A 6^3 grid whose interior vertices are thrown about by up to 0.9 cells (hexes folded over
  // one another), and one vertex pushed two cells through its neighbours; the boundary fixed.
  MatX3d V;
  MatX8i H;
  const int n = 6, m = n + 1;
  hex_grid(n, V, H);
  std::vector<char> fixed(V.rows(), 0);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int v = i + m * (j + m * k);
        if (i == 0 || j == 0 || k == 0 || i == n || j == n || k == n) {
          fixed[v] = 1;
        } else {
          V.row(v) += Eigen::RowVector3d(u(rng), u(rng), u(rng));
        }
      }
  V.row(3 + m * (3 + m * 3)) << 4.9, 3.2, 2.8;
  const MatX3d V0 = V;
  const int before = hex::inverted_hex_corners(V, H);
  ASSERT_GT(before, 50);
  ASSERT_GT(hex::hex_quality(V, H).inverted, 20);

  // The local optimization alone (the boundary fixed, no surface) leaves hexes inverted.
  MatX3d Vo = V;
  const std::vector<std::array<int, 2>> slide(V.rows(), {-1, -1});
  hex::optimize_hexes(Vo, H, fixed, slide, nullptr, nullptr, 30, 0.9);
  const int optimized_only = hex::hex_quality(Vo, H).inverted;
  EXPECT_GT(optimized_only, 0);

  const hex::HexUntangleStats st = hex::untangle_hex_corners(V, H, fixed);
  EXPECT_EQ(st.corners_before, before);
  EXPECT_EQ(st.corners_after, 0);
  EXPECT_EQ(hex::inverted_hex_corners(V, H), 0);
  for (int v = 0; v < V.rows(); ++v) {
    if (fixed[v]) {
      EXPECT_EQ(V.row(v), V0.row(v)) << v;
    }
  }
  hex::optimize_hexes(V, H, fixed, slide, nullptr, nullptr, 30, 0.9);
  const hex::HexQuality q = hex::hex_quality(V, H);
  EXPECT_EQ(q.inverted, 0) << "the local optimization alone left " << optimized_only;
  EXPECT_GT(q.sj_min, 0.3);
  // A mesh without inverted corners is left alone.
  const MatX3d V1 = V;
  EXPECT_EQ(hex::untangle_hex_corners(V, H, fixed).sweeps, 0);
  EXPECT_EQ(V, V1);
}

TEST(Hex, AFoldedBoundaryQuadIsOpenedBySlidingOnTheSurface) {
  // A boundary vertex of a 5^3 grid pushed within its face (z = 0) past its neighbour: its
  // boundary quads fold over on the face, which no interior move can open.
  MatX3d V;
  MatX8i H;
  const int n = 5, m = n + 1;
  hex_grid(n, V, H);
  std::vector<char> fixed(V.rows(), 0), slide(V.rows(), 0);
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int v = i + m * (j + m * k);
        const bool border = i == 0 || j == 0 || k == 0 || i == n || j == n || k == n;
        fixed[v] = border;
        slide[v] = k == 0 && i > 0 && j > 0 && i < n && j < n;  // the inside of the bottom face
      }
  const int pushed = 2 + m * 2;
  V.row(pushed) << 3.6, 2.3, 0;
  const int before = hex::inverted_hex_corners(V, H);
  ASSERT_GT(before, 0);
  // Held, it stays folded.
  MatX3d Vh = V;
  EXPECT_GT(hex::untangle_hex_corners(Vh, H, fixed).corners_after, 0);
  // Sliding on the plane z = 0, it opens; the face's vertices stay on it.
  std::vector<char> hold = fixed;
  for (int v = 0; v < V.rows(); ++v)
    if (slide[v]) hold[v] = 0;
  int projections = 0;
  const hex::SurfaceProjection plane = [&](int, const Vec3& p, Vec3& normal) {
    ++projections;
    normal = -Vec3::UnitZ();
    return Vec3(p.x(), p.y(), 0);
  };
  const hex::HexUntangleStats st = hex::untangle_hex_corners(V, H, hold, 4, 200, 0.05, plane, &slide);
  EXPECT_EQ(st.corners_before, before);
  EXPECT_EQ(st.corners_after, 0);
  EXPECT_EQ(hex::inverted_hex_corners(V, H), 0);
  EXPECT_GT(projections, 0);
  for (int v = 0; v < V.rows(); ++v) {
    if (slide[v]) {
      EXPECT_EQ(V(v, 2), 0.0) << v;
    }
  }
  EXPECT_GT(hex::hex_quality(V, H).sj_min, 0);
}

TEST(Hex, VolumeOutsideACloseSurfaceIsMeasured) {
  // 4^3 unit hexes filling [0, 4]^3 against the box [0, 4] x [0, 4] x [0, 3]: a quarter outside;
  // against [0, 4]^3 itself (centres well inside): none.
  MatX3d V;
  MatX8i H;
  hex_grid(4, V, H);
  const SurfaceMesh low = box(Vec3(0, 0, 0), Vec3(4, 4, 3)), same = box(Vec3(0, 0, 0), Vec3(4, 4, 4));
  EXPECT_NEAR(hex::volume_outside(V, H, low.V, low.F), 0.25, 1e-12);
  EXPECT_NEAR(hex::volume_outside(V, H, same.V, same.F), 0.0, 1e-12);
}

TEST(Hex, TheTargetsUnusedVerticesAreNotTakenForSurfacePoints) {
  // Library users pass a tet mesh's V with its boundary as the target: the interior vertices
  // are no part of the surface and must not pull the fitting (spot in the bench: mean scaled
  // Jacobian 0.884 instead of the CLI's 0.947 while they were samples).
  const BentL bent = bent_l_block();  // the polycube is the L itself, the rest a bend of it
  const TetMesh& tm = bent.tm;
  const MatX3d& rest = bent.rest;
  ASSERT_TRUE(has_unreferenced_vertices(tm.V.rows(), tm.boundary)) << "the test needs interior vertices";
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  hex::HexOptions o;
  o.target_hexes = 800;
  const SurfaceMesh with_interior{rest, tm.boundary};
  const SurfaceMesh surface = compact_surface(rest, tm.boundary);
  const hex::HexResult a = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &with_interior, o);
  const hex::HexResult b = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &surface, o);
  EXPECT_GT(b.fit.moves, 0) << "the fitting should have work to do on the bent L";
  EXPECT_EQ(a.quality.inverted, 0);
  ASSERT_EQ(a.V.rows(), b.V.rows());
  EXPECT_EQ((a.V - b.V).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(a.quality.sj_mean, b.quality.sj_mean);
}

TEST(Hex, GradingWarpIsMonotoneAndInvertible) {
  hex::AxisWarp w;
  w.lo = -1;
  w.width = 0.5;
  w.at = {0, 0.5, 2, 2.25};
  for (double x : {-1.7, -1.0, -0.8, -0.5, 0.0, 0.3, 0.5, 0.9}) EXPECT_NEAR(w.inverse(w(x)), x, 1e-12);
  EXPECT_DOUBLE_EQ(w(-0.25), 1.25);  // midway through the second bin
  EXPECT_DOUBLE_EQ(w(1.0), 2.5);     // beyond the last breakpoint: the last slope
}

TEST(Hex, GradedGridFollowsTheCurvedPart) {
  // A 4 x 1 x 1 bar as its own polycube; the rest shape keeps x < 2 straight and bends x > 2 round
  // a circle of radius 1.5 (the bar's axis) by 76 degrees: only the bent half is curved, along x.
  const SurfaceMesh bar = grid_box(16, Vec3(0, 0, 0), Vec3(4, 1, 1));
  // (The bend has a kink at x = 2, which a sliver across it can turn over: at 4000 tets, since
  // target_tets counts the boundary tets' splits, one does.)
  const TetMesh tm = tet_mesh_of(bar.V, bar.F, 4400);
  const double Rc = 1.5;
  MatX3d rest = tm.V;
  for (int v = 0; v < rest.rows(); ++v) {
    const double x = tm.V(v, 0), z = tm.V(v, 2);
    if (x <= 2) continue;
    const double th = (x - 2) / Rc, r = Rc - (z - 0.5);
    rest(v, 0) = 2 + r * std::sin(th);
    rest(v, 2) = 0.5 + Rc - r * std::cos(th);
  }
  ASSERT_EQ(measure_tets(rest, tm.T).inverted, 0);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  const SurfaceMesh target{rest, tm.boundary};

  hex::GradingOptions go;
  go.strength = 1;
  const hex::Grading g = hex::grade_polycube(rest, tm.T, tm.V, tm.boundary, labels, 4, go);
  // y and z: nothing curves along them, the grid stays uniform; x: denser sheets in the bent half.
  for (int k : {1, 2}) EXPECT_DOUBLE_EQ(g.max_slope[k], g.min_slope[k]);
  auto slope = [&](double x) { return (g.warp[0](x + 0.05) - g.warp[0](x - 0.05)) / 0.1; };
  EXPECT_GT(slope(3.0), 1.5 * slope(0.5));
  EXPECT_NEAR(slope(0.25), slope(0.75), 1e-9);
  EXPECT_NEAR(slope(2.5), slope(3.5), 1e-9);
  EXPECT_EQ(g.left_inverted, 0);
  // The warped polycube is still the polycube: each chart on one plane, same volume.
  double volume = 0;
  for (int t = 0; t < tm.T.rows(); ++t)
    volume += tet_volume(g.Y.row(tm.T(t, 0)), g.Y.row(tm.T(t, 1)), g.Y.row(tm.T(t, 2)), g.Y.row(tm.T(t, 3)));
  EXPECT_NEAR(volume, 4.0, 1e-9);
  for (int f = 0; f < tm.boundary.rows(); ++f) {
    const int a = labels[f] / 2;
    EXPECT_DOUBLE_EQ(g.Y(tm.boundary(f, 0), a), g.Y(tm.boundary(f, 1), a));
    EXPECT_DOUBLE_EQ(g.Y(tm.boundary(f, 0), a), g.Y(tm.boundary(f, 2), a));
  }

  // Hexes at about the same count: the graded grid follows the bend more closely.
  hex::HexOptions o = plain_grid(3);
  const hex::HexResult uniform = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &target, o);
  o.grading.strength = 1;
  const hex::HexResult graded = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &target, o);
  EXPECT_EQ(uniform.quality.inverted, 0);
  EXPECT_EQ(graded.quality.inverted, 0);
  EXPECT_NEAR(static_cast<double>(graded.H.rows()) / uniform.H.rows(), 1.0, 0.2);
  EXPECT_LT(boundary_distance(graded, target), 0.8 * boundary_distance(uniform, target));
  EXPECT_DOUBLE_EQ(uniform.grading_max_slope[0], 0.0);
  EXPECT_GT(graded.grading_max_slope[0], graded.grading_min_slope[0]);

  // Boundary vertices allowed off the surface (HexOptions::fit.max_offset): the flat quads over the
  // bend cut it on both sides, the distances shrink, no hex inverts.
  o.grading.strength = 0;
  o.fit.max_offset = 0.3;
  const hex::HexResult off = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &target, o);
  EXPECT_EQ(off.quality.inverted, 0);
  ASSERT_EQ(off.H.rows(), uniform.H.rows());
  auto distances = [&](const hex::HexResult& r) {
    return hex::hausdorff(r.V, hex::triangulate_quads(hex::boundary_quads(r.H)), target.V, target.F, 50000);
  };
  const hex::Hausdorff on_surface = distances(uniform), off_surface = distances(off);
  EXPECT_LT(off_surface.mean(), 0.8 * on_surface.mean());
  EXPECT_LE(off_surface.max, on_surface.max);
  // Vertices do leave the surface (outwards over the convex side of the bend), by under 0.3 cell.
  const geometry::TriangleTree tree(target.V, target.F);
  const MatX4i Qb = hex::boundary_quads(off.H);
  double farthest = 0;
  for (int q = 0; q < Qb.rows(); ++q)
    for (int j = 0; j < 4; ++j)
      farthest = std::max(farthest, std::sqrt(tree.closest(off.V.row(Qb(q, j)).transpose()).dist2));
  EXPECT_GT(farthest, 1e-3);
  EXPECT_LT(farthest, 0.3 * 1.5 / 3);  // cells of 1/3 stretched by at most 1.5 over the bend
}

TEST(Hex, ACreaseNoGridLineFollowsIsCaptured) {
  // A unit box as its own polycube; the rest shape raises the top into a ridge along y at
  // x = 9/16 (slopes +-0.8 at the top: a 77-degree crease), which no grid line follows at 4 cells
  // per unit (lines at x = 0.5 and 0.75). The crease variant moves the row of boundary vertices
  // at x = 0.5 onto the ridge and is kept: closer to the input, no hex worse than 0.3.
  const SurfaceMesh box = grid_box(16);
  const TetMesh tm = tet_mesh_of(box.V, box.F, 3000);
  MatX3d rest = tm.V;
  for (int v = 0; v < rest.rows(); ++v)
    rest(v, 2) = tm.V(v, 2) * (1 + 0.8 * (0.4375 - std::abs(tm.V(v, 0) - 0.5625)));
  ASSERT_EQ(measure_tets(rest, tm.T).inverted, 0);
  const std::vector<int> labels = chart::label_by_normal(tm.V, tm.boundary);
  const SurfaceMesh target{rest, tm.boundary};
  hex::HexOptions o = plain_grid(4);
  const hex::HexResult plain = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &target, o);
  o.capture_creases = true;
  const hex::HexResult captured = hex::hex_mesh_from_polycube(rest, tm.T, tm.V, tm.boundary, labels, &target, o);
  EXPECT_EQ(plain.crease_runs, 0);  // not looked for
  EXPECT_GE(captured.crease_runs, 1);
  EXPECT_GE(captured.crease_captured, 1);
  EXPECT_EQ(captured.H.rows(), plain.H.rows());
  EXPECT_EQ(captured.quality.inverted, 0);
  EXPECT_GE(captured.quality.sj_min, std::min(0.3, plain.quality.sj_min));
  EXPECT_LT(boundary_distance(captured, target), 0.5 * boundary_distance(plain, target));
}
