#include "polycube/hex/untangle.h"

#include <algorithm>
#include <cmath>

#include "polycube/deform/energies.h"
#include "polycube/deform/untangle.h"
#include "polycube/hex/quality.h"

namespace polycube::hex {

MatX4i hex_corner_tets(const MatX8i& H) {
  MatX4i T(8 * H.rows(), 4);
  for (int h = 0; h < H.rows(); ++h)
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 4; ++i) T(8 * h + j, i) = H(h, kHexCorners[j][i]);
  return T;
}

namespace {
// Whether corner j of hex h is flat or inverted in V.
bool corner_inverted(const MatX3d& V, const MatX8i& H, int h, int j) {
  const auto& c = kHexCorners[j];
  const Vec3 o = V.row(H(h, c[0])).transpose();
  const double d = (V.row(H(h, c[1])).transpose() - o)
                       .dot((V.row(H(h, c[2])).transpose() - o).cross(V.row(H(h, c[3])).transpose() - o));
  return !(d > 0);
}
}  // namespace

int inverted_hex_corners(const MatX3d& V, const MatX8i& H) {
  int n = 0;
  for (int h = 0; h < H.rows(); ++h)
    for (int j = 0; j < 8; ++j) n += corner_inverted(V, H, h, j);
  return n;
}

std::vector<char> hexes_with_inverted_corners(const MatX3d& V, const MatX8i& H) {
  std::vector<char> bad(H.rows(), 0);
  for (int h = 0; h < H.rows(); ++h)
    for (int j = 0; j < 8 && !bad[h]; ++j) bad[h] = corner_inverted(V, H, h, j);
  return bad;
}

namespace {

// Rest shapes: each corner tet a right corner (three orthogonal edges) of its hex's mean edge
// length in V, weighted by that length cubed.
deform::ArapRest right_corners(const MatX3d& V, const MatX8i& H) {
  deform::ArapRest rest;
  const int nt = static_cast<int>(8 * H.rows());
  rest.Dm_inv.resize(nt);
  rest.w.resize(nt);
  double total = 0;
  for (int h = 0; h < H.rows(); ++h) {
    double len = 0;
    for (const auto& e : kHexEdges) len += (V.row(H(h, e[0])) - V.row(H(h, e[1]))).norm();
    len = std::max(len / 12, 1e-300);
    for (int j = 0; j < 8; ++j) {
      rest.Dm_inv[8 * h + j] = Eigen::Matrix3d::Identity() / len;
      rest.w[8 * h + j] = len * len * len;
      total += len * len * len;
    }
  }
  for (double& w : rest.w) w /= std::max(total, 1e-300);
  return rest;
}

}  // namespace

HexUntangleStats untangle_hex_corners(MatX3d& V, const MatX8i& H, const std::vector<char>& fixed, int rings,
                                      int max_sweeps, double open_below, const SurfaceProjection& project,
                                      const std::vector<char>* slide) {
  HexUntangleStats st;
  const MatX4i T = hex_corner_tets(H);
  const deform::ArapRest rest = right_corners(V, H);
  const auto held = [&](int v, int) { return v < static_cast<int>(fixed.size()) && fixed[v] != 0; };
  const auto sliding = [&](int v) {
    return project && slide && v < static_cast<int>(slide->size()) && (*slide)[v] && !held(v, 0);
  };
  // Sliding vertices: the tangent plane at their point of the surface.
  deform::MoveDirections directions;
  std::function<void(int, MatX3d&)> after_move;
  if (project && slide) {
    directions = [&](int v, const MatX3d& X, Eigen::Matrix3d& B) {
      if (!sliding(v)) return -1;
      Vec3 n;
      project(v, X.row(v).transpose(), n);
      const Vec3 a = std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
      B.col(0) = n.cross(a).normalized();
      B.col(1) = n.cross(B.col(0)).normalized();
      return 2;
    };
    after_move = [&](int v, MatX3d& X) {
      if (!sliding(v)) return;
      Vec3 n;
      X.row(v) = project(v, X.row(v).transpose(), n).transpose();
    };
  }
  st.corners_before = st.corners_after = deform::count_inverted(V, T, rest);
  int left = 0;
  if (st.corners_before > 0) {
    // In runs of kChunk sweeps, keeping the state with the fewest inverted corners (the count
    // goes up and down on the way); stopped after two runs without a new best.
    constexpr int kChunk = 20;
    MatX3d X = V;
    int stale = 0;
    for (int done = 0; done < max_sweeps && st.corners_after > 0 && stale < 2;) {
      const int chunk = std::min(kChunk, max_sweeps - done);
      const int sweeps = deform::untangle_locally(T, rest, held, X, left, rings, chunk, 0, {}, directions, after_move);
      st.sweeps += sweeps;
      done += chunk;
      const int now = deform::count_inverted(X, T, rest);
      if (now < st.corners_after) {
        V = X;
        st.corners_after = now;
        stale = 0;
      } else {
        ++stale;
      }
      if (sweeps < chunk) break;  // none left in its region
    }
  }
  if (open_below > 0 && st.corners_after == 0)
    st.sweeps += deform::untangle_locally(T, rest, held, V, left, rings, max_sweeps, open_below, {}, directions,
                                          after_move);
  return st;
}

}  // namespace polycube::hex
